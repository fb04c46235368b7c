//! Tests of the scores: lag search, SNR, envelopes, polarity and the sub-sample refinement.

use super::*;
use crate::test_support::delayed_chord;
use std::f64::consts::PI;

const FS: u32 = 44_100;

/// A deterministic broadband test signal: an amplitude-modulated chord.
fn music(n: usize) -> Vec<f32> {
    (0..n)
        .map(|i| {
            let t = i as f64 / f64::from(FS);
            let env = 0.6 + 0.4 * (2.0 * PI * 3.0 * t).sin();
            (env * (0.5 * (2.0 * PI * 440.0 * t).sin()
                + 0.3 * (2.0 * PI * 1234.5 * t).sin()
                + 0.2 * (2.0 * PI * 97.0 * t).sin())) as f32
        })
        .collect()
}

/// Deterministic white-ish noise (xorshift), zero mean, unit variance.
fn noise(n: usize, seed: u64) -> Vec<f32> {
    let mut s = seed.max(1);
    (0..n)
        .map(|_| {
            // Sum of 4 uniforms ≈ Gaussian; variance 4/12 → scale by √3.
            let mut acc = 0.0;
            for _ in 0..4 {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                acc += (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
            }
            (acc * 3f64.sqrt()) as f32
        })
        .collect()
}

fn energy(s: &[f32]) -> f64 {
    s.iter().map(|&v| f64::from(v).powi(2)).sum()
}

#[test]
fn identical_signals_score_perfectly() {
    let x = music(22_050);
    let s = evaluate(&x, &x, 100, FS).unwrap();
    assert!((s.r - 1.0).abs() < 1e-9, "{s:?}");
    assert!((s.envelope_r.unwrap() - 1.0).abs() < 1e-9, "{s:?}");
    assert!(s.snr_db > 100.0, "{s:?}");
    assert_eq!(s.lag_samples, 0);
    assert_eq!(s.samples, x.len());
}

#[test]
fn a_delay_is_found_with_its_sign() {
    let x = music(22_050);
    for d in [7usize, 1, 33] {
        // Recovered is late by d samples.
        let mut late = vec![0.0f32; d];
        late.extend_from_slice(&x);
        let s = evaluate(&late, &x, 50, FS).unwrap();
        assert_eq!(s.lag_samples, d as i64, "{s:?}");
        assert!(s.r > 0.999_999 && s.snr_db > 100.0, "{s:?}");
        // Recovered is early by d samples.
        let s = evaluate(&x[d..], &x, 50, FS).unwrap();
        assert_eq!(s.lag_samples, -(d as i64), "{s:?}");
        assert!(s.r > 0.999_999, "{s:?}");
    }
    // A delay outside the search range is not found.
    let mut late = vec![0.0f32; 60];
    late.extend_from_slice(&x);
    let s = evaluate(&late, &x, 50, FS).unwrap();
    assert!(s.r < 0.99, "{s:?}");
}

#[test]
fn a_fraction_of_a_sample_is_found_and_not_scored_as_noise() {
    // At the whole-sample lag alone, 0.37 of a sample reads as noise (this chord: 22.7 dB).
    let x = delayed_chord(8_820, 0.0);
    for delay in [0.37, -0.5, 2.25, -3.9] {
        let late = delayed_chord(8_820, delay);
        let s = evaluate(&late, &x, 20, FS).unwrap();
        assert!(
            (s.lag_refined_samples - delay).abs() < 2e-3,
            "{delay}: {s:?}"
        );
        assert!(
            (s.lag_refined_samples - s.lag_samples as f64).abs() <= 1.0,
            "{s:?}"
        );
        assert!(s.snr_db > 60.0 && s.r > 0.999_99, "{delay}: {s:?}");
        assert_eq!(s.samples as i64 + s.lag_samples.abs(), 8_820, "{s:?}");
    }
}

#[test]
fn the_lag_reads_with_its_fraction_and_no_negative_zero() {
    let mut s = evaluate(&music(4_000), &music(4_000), 10, FS).unwrap();
    for (lag, text) in [(-0.00001, "0.000"), (3.1675, "3.168"), (-11.15, "-11.150")] {
        s.lag_refined_samples = lag;
        assert_eq!(s.lag_text(3), text);
    }
}

#[test]
fn a_short_tone_half_a_sample_late_scores_clean_to_its_ends() {
    // 10 ms of 5 kHz: the interpolator's stencil slides inward at each end instead of
    // reaching past the clip, and the one position past the end is extrapolated.
    let tone = |delay: f64| -> Vec<f32> {
        (0..441)
            .map(|i| (2.0 * PI * 5000.0 * (i as f64 - delay) / f64::from(FS) + 0.3).sin() as f32)
            .collect()
    };
    // (A window of a few samples: a steady tone correlates as well a period away.)
    let s = evaluate(&tone(0.5), &tone(0.0), 4, FS).unwrap();
    assert!((s.lag_refined_samples - 0.5).abs() < 2e-3, "{s:?}");
    assert!(s.snr_db > 55.0, "{s:?}");
    assert_eq!(s.samples as i64 + s.lag_samples.abs(), 441, "{s:?}");
}

#[test]
fn known_snr_is_measured() {
    let x = music(44_100);
    let e = energy(&x) / x.len() as f64;
    for target_db in [10.0, 20.0, 30.0] {
        let nz = noise(x.len(), 7);
        let en = energy(&nz) / nz.len() as f64;
        let k = (e / en / 10f64.powf(target_db / 10.0)).sqrt() as f32;
        let rec: Vec<f32> = x.iter().zip(&nz).map(|(a, b)| 2.5 * (a + k * b)).collect();
        let s = evaluate(&rec, &x, 20, FS).unwrap();
        // The sub-sample search must not trim the noise: reading the recovered signal
        // between samples (a gentle low-pass) read 10 dB as 11.5.
        // (rec = ref + noise reads 10·log10(1 + S/N).)
        let expected_db = 10.0 * (1.0 + 10f64.powf(target_db / 10.0)).log10();
        assert!(
            (s.snr_db - expected_db).abs() < 0.05,
            "{target_db}: {} ({s:?})",
            s.snr_db
        );
        assert_eq!(s.lag_samples, 0);
        assert!(s.lag_refined_samples.abs() < 0.05, "{s:?}");
        let expected_r = (1.0 / (1.0 + 10f64.powf(-target_db / 10.0))).sqrt();
        assert!((s.r - expected_r).abs() < 0.01, "{s:?} vs {expected_r}");
    }
}

#[test]
fn inverted_and_scaled_signals() {
    let x = music(10_000);
    let inv: Vec<f32> = x.iter().map(|v| -0.3 * v + 0.1).collect();
    // The lag maximises the signed r: a polarity error shows as a poor score rather than
    // hiding behind a half-period lag on tonal material.
    let s = evaluate(&inv, &x, 30, FS).unwrap();
    assert!(s.r < 0.5, "{s:?}");
    // ... and is named: inverted, the recovered signal reads r = −1 at lag 0.
    let inverted = s.inverted.unwrap();
    assert!(
        (inverted.r + 1.0).abs() < 1e-6 && inverted.lag_samples == 0,
        "{s:?}"
    );
    assert!(
        s.line().contains("polarity is likely reversed"),
        "{}",
        s.line()
    );
    assert_eq!(evaluate(&x, &x, 30, FS).unwrap().inverted, None);
    // A tone at a fractional lag, upright, searched over more than a period: inverted at
    // half a period it correlates about as well, which says nothing about polarity.
    for f in [500.0, 2000.0, 5000.0] {
        let w = 2.0 * PI * f / f64::from(FS);
        let tone = |shift: f64| -> Vec<f32> {
            (0..4410)
                .map(|i| (w * (i as f64 + shift)).sin() as f32)
                .collect()
        };
        let s = evaluate(&tone(0.37), &tone(0.0), 220, FS).unwrap();
        assert_eq!(s.inverted, None, "{f} Hz: {s:?}");
    }
    // Two partials, turned over: upright they match only at a lag that nearly repeats both
    // (r 0.97 within ±5 ms), inverted at lag 0 exactly; named. Upright (at a fractional lag)
    // they are not.
    let (w1, w2) = (
        2.0 * PI * 440.0 / f64::from(FS),
        2.0 * PI * 1234.0 / f64::from(FS),
    );
    let chord = |shift: f64, sign: f64| -> Vec<f32> {
        (0..22_050)
            .map(|i| {
                let t = i as f64 + shift;
                (sign * (0.5 * (w1 * t).sin() + 0.3 * (w2 * t + 0.3).sin())) as f32
            })
            .collect()
    };
    let s = evaluate(&chord(0.0, -1.0), &chord(0.0, 1.0), 220, FS).unwrap();
    let inverted = s.inverted.expect("two partials turned over are named");
    assert!(inverted.lag_samples == 0 && inverted.r < -0.999, "{s:?}");
    assert_eq!(
        evaluate(&chord(0.37, 1.0), &chord(0.0, 1.0), 220, FS)
            .unwrap()
            .inverted,
        None
    );
    assert!((pearson(&inv, &x) + 1.0).abs() < 1e-9);
    // The gain-only SNR does not remove a DC offset: it counts as noise.
    assert!(s.snr_db < 20.0, "{s:?}");
    let scaled: Vec<f32> = x.iter().map(|v| 0.3 * v).collect();
    let s = evaluate(&scaled, &x, 30, FS).unwrap();
    assert!(s.snr_db > 100.0, "{s:?}");
    assert!(s.envelope_r.unwrap() > 0.999, "{s:?}");
}

#[test]
fn unrelated_signals_score_low() {
    let a = noise(20_000, 1);
    let b = noise(20_000, 99);
    let s = evaluate(&a, &b, 40, FS).unwrap();
    assert!(s.r.abs() < 0.05, "{s:?}");
    assert!(s.snr_db < 0.1, "{s:?}");
}

#[test]
fn clips_under_fifty_ms_get_no_envelope_r() {
    let tone = |ms: usize| -> Vec<f32> {
        (0..44_100 * ms / 1000)
            .map(|i| (i as f32 * 0.07).sin() * (1.0 + (i as f32 * 0.002).sin()))
            .collect()
    };
    let short = tone(30);
    let s = evaluate(&short, &short, 0, 44_100).unwrap();
    assert!(s.r > 0.999 && s.envelope_r.is_none(), "{s:?}");
    assert_eq!(s.envelope_r_text(3), "n/a (< 50 ms or steady)");
    let long = tone(60);
    let s = evaluate(&long, &long, 0, 44_100).unwrap();
    assert!(s.envelope_r.is_some_and(|e| e > 0.999), "{s:?}");
    assert_eq!(s.envelope_r_text(2), "1.00");
}

#[test]
fn a_steady_tone_gets_no_envelope_r_and_a_fading_one_does() {
    let tone = |fade: f32| -> Vec<f32> {
        (0..48_000)
            .map(|i| (i as f32 * 0.0916).sin() * (1.0 - fade * i as f32 / 48_000.0))
            .collect()
    };
    let steady = tone(0.0);
    let s = evaluate(&steady, &steady, 0, 48_000).unwrap();
    assert!(s.r > 0.999 && s.envelope_r.is_none(), "{s:?}");
    let fading = tone(0.5);
    let s = evaluate(&fading, &fading, 0, 48_000).unwrap();
    assert!(s.envelope_r.is_some_and(|e| e > 0.999), "{s:?}");
}

#[test]
fn envelope_r_tracks_loudness_not_waveform() {
    // Same envelope, different carrier: waveform r is low, envelope r high.
    let n = 44_100;
    let env = |t: f64| 0.5 + 0.45 * (2.0 * PI * 2.0 * t).sin();
    let a: Vec<f32> = (0..n)
        .map(|i| {
            let t = i as f64 / f64::from(FS);
            (env(t) * (2.0 * PI * 500.0 * t).sin()) as f32
        })
        .collect();
    let b: Vec<f32> = (0..n)
        .map(|i| {
            let t = i as f64 / f64::from(FS);
            (env(t) * (2.0 * PI * 733.0 * t).sin()) as f32
        })
        .collect();
    let s = evaluate(&a, &b, 10, FS).unwrap();
    assert!(s.r.abs() < 0.1, "{s:?}");
    assert!(s.envelope_r.unwrap() > 0.98, "{s:?}");
}

#[test]
fn too_short_or_empty_is_none() {
    assert!(evaluate(&[1.0; 10], &[1.0; 10], 2, FS).is_none());
    assert!(evaluate(&[], &[1.0; 100], 2, FS).is_none());
    // Constant inputs: defined, r = 0 (no variance), no panic.
    let s = evaluate(&[1.0; 100], &[1.0; 100], 5, FS).unwrap();
    assert_eq!(s.r, 0.0);
}

#[test]
fn fft_search_matches_direct_search() {
    // Equal and unequal lengths either way, the recovered sound late or early, a window
    // wider than both signals (one FFT of both whole), and signals long enough to be
    // correlated block by block; the reference is the recovered sound's source.
    let source = music(50_000);
    let noisy: Vec<f32> = source
        .iter()
        .zip(noise(50_000, 5))
        .map(|(a, b)| 0.7 * a + 0.5 * b)
        .collect();
    for (n_ref, n_rec, shift, max_lag) in [
        (3000, 3000, 0, 40usize),
        (3000, 1700, 25, 40),
        (1700, 3000, -30, 40),
        (400, 2500, 7, 3000),
        (2500, 400, 900, 3000),
        (45_000, 41_000, -12, 40),
    ] {
        let x = &source[1000..1000 + n_ref];
        let start = (1000 + shift) as usize;
        let y = &noisy[start..start + n_rec];
        let s = evaluate(y, x, max_lag, FS).unwrap();
        // Direct O(n·lag) search with pearson().
        let min_overlap = (n_ref.min(n_rec) / 2).max(16);
        let mut best = (f64::NEG_INFINITY, 0i64);
        for lag in -(max_lag as i64)..=max_lag as i64 {
            let (lo, hi) = overlap(x.len(), y.len(), lag);
            if hi - lo < min_overlap {
                continue;
            }
            let ylo = (lo as i64 + lag) as usize;
            let r = pearson(&y[ylo..ylo + hi - lo], &x[lo..hi]);
            if r > best.0 + 1e-12 {
                best = (r, lag);
            }
        }
        let case = format!("{n_ref} / {n_rec}, shift {shift}, window {max_lag}");
        assert_eq!(s.lag_samples, best.1, "{case}");
        // The scores' r is taken at that lag refined to a fraction: never below it.
        assert!(s.r >= best.0 - 1e-9, "{case}: {} vs {}", s.r, best.0);
        assert!(
            (s.lag_refined_samples - best.1 as f64).abs() <= 1.0,
            "{case}: {s:?}"
        );
    }
}

#[test]
fn pearson_basics() {
    assert!((pearson(&[1.0, 2.0, 3.0], &[2.0, 4.0, 6.5]) - 0.9986).abs() < 1e-3);
    assert!((pearson(&[1.0, 2.0, 3.0], &[3.0, 2.0, 1.0]) + 1.0).abs() < 1e-12);
    assert_eq!(pearson(&[1.0], &[1.0]), 0.0);
    assert_eq!(pearson(&[1.0, 1.0, 1.0], &[1.0, 2.0, 3.0]), 0.0);
}

#[test]
fn the_refined_lag_stays_within_the_lags_searched() {
    let x = music(8_000);
    // Late by 2.4 samples, searched only at lag 0 and then within one sample.
    let late: Vec<f32> = (0..x.len())
        .map(|i| {
            if i >= 3 {
                0.6 * x[i - 2] + 0.4 * x[i - 3]
            } else {
                0.0
            }
        })
        .collect();
    let s = evaluate(&x, &late, 0, FS).unwrap();
    assert!(s.lag_samples == 0 && s.lag_refined_samples == 0.0, "{s:?}");
    let s = evaluate(&x, &late, 1, FS).unwrap();
    assert!(s.lag_refined_samples.abs() <= 1.0, "{s:?}");
    let s = evaluate(&x, &late, 5, FS).unwrap();
    assert!((s.lag_refined_samples.abs() - 2.4).abs() < 0.1, "{s:?}");
}
