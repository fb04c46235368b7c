//! Tests of the sound stage: channels by cut, gaps, seamless stitching, exact resampling, output level.

use super::*;
use crate::image::Image;
use crate::pipeline::dsp::magnitude_spectrum;
use crate::pipeline::orientation::{PlaneFit, StopReason, WallOrientation};
use crate::pipeline::test_support::assert_each_edit_is_refused;
use std::f64::consts::PI;

const VT_MM_S: f64 = 939.0;

fn fit() -> PlaneFit {
    PlaneFit {
        a: 0.0,
        b: 1.0,
        c: 0.0,
        iterations: 1,
        outlier_fraction: 0.0,
        residual_um: 0.0,
        stop: StopReason::LeastSquares,
    }
}

fn wall(side: WallSide, xs: &[f32], tans: &[f64]) -> WallOrientation {
    WallOrientation {
        side,
        samples: xs
            .iter()
            .zip(tans)
            .map(|(&x_px, &tan_theta)| OrientationSample {
                x_px,
                tan_theta,
                fit: tan_theta.is_finite().then(fit),
            })
            .collect(),
    }
}

fn orientation(walls: Vec<WallOrientation>) -> Orientation {
    Orientation {
        walls,
        weight_map: Image::zeros(1, 1),
        outlier_fraction: 0.0,
        rejected_fits: 0,
    }
}

#[test]
fn lateral_motion_reads_the_same_from_one_or_both_walls() {
    let d = [0.02, -0.05, 0.1]; // d′ = lateral slope
    let t: Vec<f64> = d.iter().map(|v| v / SQRT_2).collect();
    let xs = [100.0f32, 155.0, 210.0];
    let both = orientation(vec![
        wall(WallSide::Left, &xs, &t),
        wall(WallSide::Right, &xs, &t),
    ]);
    let left = orientation(vec![wall(WallSide::Left, &xs, &t)]);
    let right = orientation(vec![wall(WallSide::Right, &xs, &t)]);
    for o in [&both, &left, &right] {
        let g = group_signal(3, o, Cut::Lateral, 1000.0, 0.39, VT_MM_S).unwrap();
        assert_eq!(g.channels.len(), 1);
        for (v, dv) in g.channels[0].iter().zip(d) {
            assert!(
                (f64::from(*v) - VT_MM_S * dv).abs() < 1e-3,
                "{v} vs {}",
                VT_MM_S * dv
            );
        }
        assert_eq!(g.group, 3);
        assert!((g.positions_um[1] - (1000.0 + 155.0 * 0.39)).abs() < 1e-9);
    }
    // Pure lateral motion has no vertical component.
    let g = group_signal(0, &both, Cut::Vertical, 0.0, 0.39, VT_MM_S).unwrap();
    assert!(g.channels[0].iter().all(|v| v.abs() < 1e-4));
}

#[test]
fn vertical_and_stereo_channels() {
    // Vertical motion h′: the walls tilt oppositely, tanθ_R = −tanθ_L = h′/√2.
    let h = [0.03, -0.07];
    let xs = [10.0f32, 60.0];
    let tr: Vec<f64> = h.iter().map(|v| v / SQRT_2).collect();
    let tl: Vec<f64> = tr.iter().map(|v| -v).collect();
    let o = orientation(vec![
        wall(WallSide::Right, &xs, &tr),
        wall(WallSide::Left, &xs, &tl),
    ]);
    let g = group_signal(0, &o, Cut::Vertical, 0.0, 1.0, VT_MM_S).unwrap();
    for (v, hv) in g.channels[0].iter().zip(h) {
        assert!((f64::from(*v) - VT_MM_S * hv).abs() < 1e-3);
    }
    for one in [
        orientation(vec![wall(WallSide::Left, &xs, &tl)]),
        orientation(vec![wall(WallSide::Right, &xs, &tr)]),
    ] {
        let g = group_signal(0, &one, Cut::Vertical, 0.0, 1.0, VT_MM_S).unwrap();
        for (v, hv) in g.channels[0].iter().zip(h) {
            assert!((f64::from(*v) - VT_MM_S * hv).abs() < 1e-3);
        }
    }
    // Stereo: left wall → ch0, right wall → ch1; a missing wall is a NaN channel.
    let g = group_signal(0, &o, Cut::Stereo, 0.0, 1.0, VT_MM_S).unwrap();
    assert!((f64::from(g.channels[0][0]) - VT_MM_S * tl[0]).abs() < 1e-3);
    assert!((f64::from(g.channels[1][1]) - VT_MM_S * tr[1]).abs() < 1e-3);
    let one = orientation(vec![wall(WallSide::Right, &xs, &tr)]);
    let g = group_signal(0, &one, Cut::Stereo, 0.0, 1.0, VT_MM_S).unwrap();
    assert!(g.channels[0].iter().all(|v| v.is_nan()));
    assert!(g.channels[1].iter().all(|v| v.is_finite()));
}

#[test]
fn gaps_columns_and_errors() {
    // Walls sampled at different columns, unsorted, with a gap.
    let l = wall(
        WallSide::Left,
        &[200.0, 100.0, 300.0],
        &[0.1, 0.1, f64::NAN],
    );
    let r = wall(WallSide::Right, &[150.0, 250.0], &[0.1, 0.1]);
    let g = group_signal(0, &orientation(vec![l, r]), Cut::Lateral, 0.0, 1.0, 1.0).unwrap();
    assert_eq!(g.positions_um, vec![100.0, 150.0, 200.0, 250.0, 300.0]);
    // Column 300: left is a gap, right has no sample there → right... outside its track → NaN.
    let expected = [
        SQRT_2 * 0.1,
        2.0 * 0.1 / SQRT_2,
        2.0 * 0.1 / SQRT_2,
        SQRT_2 * 0.1,
    ];
    for (v, e) in g.channels[0].iter().zip(expected) {
        assert!((f64::from(*v) - e).abs() < 1e-6, "{v} vs {e}");
    }
    assert!(g.channels[0][4].is_nan());
    // A sample without a fit is a gap even if tan θ is finite.
    let mut w = wall(WallSide::Left, &[0.0, 1.0], &[0.1, 0.1]);
    w.samples[1].fit = None;
    let g = group_signal(0, &orientation(vec![w]), Cut::Lateral, 0.0, 1.0, 1.0).unwrap();
    assert!(g.channels[0][0].is_finite() && g.channels[0][1].is_nan());
    // Errors.
    assert!(group_signal(0, &orientation(vec![]), Cut::Lateral, 0.0, 1.0, 1.0).is_err());
    let twice = orientation(vec![
        wall(WallSide::Left, &[0.0], &[0.0]),
        wall(WallSide::Left, &[0.0], &[0.0]),
    ]);
    assert!(group_signal(0, &twice, Cut::Lateral, 0.0, 1.0, 1.0).is_err());
    let ok = orientation(vec![wall(WallSide::Left, &[0.0], &[0.0])]);
    assert!(group_signal(0, &ok, Cut::Lateral, f64::NAN, 1.0, 1.0).is_err());
    assert!(group_signal(0, &ok, Cut::Lateral, 0.0, 0.0, 1.0).is_err());
    assert!(group_signal(0, &ok, Cut::Lateral, 0.0, 1.0, -939.0).is_err());
}

/// Groups like real ones: `per_group` samples `sample_um` apart, each group starting
/// `step_um` after the previous plus a fraction of a sample that differs per group.
fn groups_of(
    count: usize,
    per_group: usize,
    sample_um: f64,
    step_um: f64,
    velocity: impl Fn(f64) -> f64,
    bias: impl Fn(usize) -> f64,
) -> Vec<GroupSignal> {
    (0..count)
        .map(|k| {
            // A low-discrepancy fraction in [0, 1).
            let frac = (k as f64 * 0.618_034).fract();
            let start = 5.0 + k as f64 * step_um + frac * sample_um;
            let positions_um: Vec<f64> = (0..per_group)
                .map(|j| start + j as f64 * sample_um)
                .collect();
            GroupSignal::mono_from_fn(k, positions_um, VT_MM_S, |p| (velocity(p) + bias(k)) as f32)
        })
        .collect()
}

/// Sine velocity of `freq_hz` at Vt (wavelength Vt/f along the groove), amplitude 50 mm/s.
fn sine(freq_hz: f64) -> impl Fn(f64) -> f64 {
    let wavelength_um = VT_MM_S * 1000.0 / freq_hz;
    move |p: f64| 50.0 * (2.0 * PI * p / wavelength_um).sin()
}

#[test]
fn stitched_sine_matches_within_1e_3() {
    // Paper-like numbers: 21.3 µm samples, 24 per group (≈ 490 µm), 460 µm group step.
    let spacing = VT_MM_S * 1000.0 / 44_100.0;
    for (freq, tol) in [(1000.0, 1e-3), (2000.0, 1e-3), (3000.0, 2e-3)] {
        let groups = groups_of(60, 24, 21.3, 460.0, sine(freq), |_| 0.0);
        let s = stitch(&groups, spacing).unwrap();
        assert!(s.gaps.is_empty(), "{:?}", s.gaps);
        assert!((s.native_rate_hz - 44_100.0).abs() < 1e-6);
        let f = sine(freq);
        let mut worst = 0.0f64;
        for (k, &v) in s.channels[0].iter().enumerate() {
            let p = s.start_um + k as f64 * spacing;
            worst = worst.max((f64::from(v) - f(p)).abs() / 50.0);
        }
        assert!(worst < tol, "{freq} Hz: worst relative error {worst}");
    }
}

/// Peak level (dB) over the median of its neighbourhood, around each harmonic of
/// `period_samples`, ignoring bins near `skip_hz`.
fn seam_line_db(x: &[f32], rate: f64, period_samples: f64, skip_hz: f64) -> f64 {
    let spec = magnitude_spectrum(x, rate);
    let bin_hz = spec[1].0;
    let mut worst = f64::MIN;
    for h in 1..=4 {
        let f = h as f64 * rate / period_samples;
        if f >= rate / 2.0 - 200.0 {
            break;
        }
        let centre = (f / bin_hz).round() as usize;
        let peak = spec[centre - 2..=centre + 2]
            .iter()
            .map(|b| b.1)
            .fold(f64::MIN, f64::max);
        let mut floor: Vec<f64> = spec[centre.saturating_sub(60)..(centre + 60).min(spec.len())]
            .iter()
            .filter(|b| (b.0 - f).abs() > 6.0 * bin_hz && (b.0 - skip_hz).abs() > 200.0)
            .map(|b| b.1)
            .collect();
        floor.sort_by(f64::total_cmp);
        worst = worst.max(peak - floor[floor.len() / 2]);
    }
    worst
}

#[test]
fn per_group_bias_makes_no_seam_buzz() {
    let spacing = VT_MM_S * 1000.0 / 44_100.0;
    let step_um = 460.0;
    // Common tilt bias plus a small random part per group (as real groups have).
    let bias = |k: usize| 4.0 + 1.5 * ((k as f64 * 12.9898).sin() * 43_758.545).fract();
    let groups = groups_of(400, 24, 21.3, step_um, sine(1000.0), bias);
    let s = stitch(&groups, spacing).unwrap();
    assert!(s.gaps.is_empty());
    let period = step_um / spacing; // ≈ 21.6 samples: the buzz a bad stitch makes
    let mean =
        s.channels[0].iter().map(|&v| f64::from(v)).sum::<f64>() / s.channels[0].len() as f64;
    let x: Vec<f32> = s.channels[0]
        .iter()
        .map(|&v| (f64::from(v) - mean) as f32)
        .collect();
    let line = seam_line_db(&x, s.native_rate_hz, period, 1000.0);
    assert!(line < 10.0, "seam line {line} dB above the floor");
    // Control: a one-sample click of the bias size at every seam shows up far above the bar.
    let mut clicky = x.clone();
    for g in &groups[1..] {
        let k = ((g.positions_um[0] - s.start_um) / spacing).round() as usize;
        clicky[k] += 4.0;
    }
    let line = seam_line_db(&clicky, s.native_rate_hz, period, 1000.0);
    assert!(line > 20.0, "control click line only {line} dB");
}

#[test]
fn missing_group_is_silence_and_a_gap() {
    let spacing = 20.0;
    let mut groups = groups_of(5, 25, 20.0, 460.0, |_| 1.0, |_| 0.0);
    groups.remove(2);
    let s = stitch(&groups, spacing).unwrap();
    assert_eq!(s.gaps.len(), 1, "{:?}", s.gaps);
    let gap = s.gaps[0].clone();
    // Group 1 ends near 5 + 460 + 0.24·20 + 480; group 3 starts near 5 + 1380 + ...
    let end1 = groups[1].positions_um.last().copied().unwrap();
    let start3 = groups[2].positions_um[0];
    let expected = (((end1 - s.start_um) / spacing).floor() as usize + 1)
        ..(((start3 - s.start_um) / spacing).ceil() as usize);
    assert_eq!(gap, expected);
    assert!(s.channels[0][gap.clone()].iter().all(|&v| v == 0.0));
    assert!(
        s.channels[0][..gap.start]
            .iter()
            .all(|&v| (v - 1.0).abs() < 1e-6)
    );
    assert!(
        s.channels[0][gap.end..]
            .iter()
            .all(|&v| (v - 1.0).abs() < 1e-6)
    );
    // A group of NaN (no fit) is a gap too, and other groups' overlap still fills its edges.
    let mut groups = groups_of(3, 25, 20.0, 460.0, |_| 1.0, |_| 0.0);
    groups[1].channels[0].iter_mut().for_each(|v| *v = f32::NAN);
    let s = stitch(&groups, spacing).unwrap();
    assert_eq!(s.gaps.len(), 1);
    assert!(s.gaps[0].len() > 15 && s.gaps[0].len() < 23, "{:?}", s.gaps);
}

#[test]
fn stereo_gap_in_one_channel_is_listed() {
    let mut groups = groups_of(3, 25, 20.0, 460.0, |_| 1.0, |_| 0.0);
    for g in &mut groups {
        let c = g.channels[0].clone();
        g.channels.push(c);
    }
    groups[1].channels[1].iter_mut().for_each(|v| *v = f32::NAN);
    let s = stitch(&groups, 20.0).unwrap();
    assert_eq!(s.gaps.len(), 1);
    let r = s.gaps[0].clone();
    assert!(
        s.channels[0][r.clone()]
            .iter()
            .all(|&v| (v - 1.0).abs() < 1e-6)
    );
    assert!(s.channels[1][r].iter().all(|&v| v == 0.0));
}

#[test]
fn stitch_rejects_bad_input() {
    let g = groups_of(2, 5, 20.0, 80.0, |_| 0.0, |_| 0.0);
    assert!(stitch(&[], 20.0).is_err());
    assert!(stitch(&g, 0.0).is_err());
    assert!(stitch(&g, f64::NAN).is_err());
    assert!(stitch(&g, 1e-9).is_err()); // absurd sample count
    let mut two = g.clone();
    let extra = two[1].channels[0].clone();
    two[1].channels.push(extra);
    assert!(stitch(&two, 20.0).is_err());
    let mut nan = g.clone();
    nan[0].positions_um[1] = f64::NAN;
    assert!(stitch(&nan, 20.0).is_err());
    let mut short = g;
    short[0].channels[0].pop();
    assert!(stitch(&short, 20.0).is_err());
}

fn tone(n: usize, freq: f64, rate: f64, amp: f64) -> Vec<f32> {
    (0..n)
        .map(|i| (amp * (2.0 * PI * freq * i as f64 / rate).sin()) as f32)
        .collect()
}

/// Least-squares amplitude and phase of `freq` in `x` at `rate`, over `range`.
fn fit_sine(x: &[f32], freq: f64, rate: f64, range: Range<usize>) -> (f64, f64, f64) {
    let (a, b) = crate::pipeline::test_support::two_gains(range.clone().map(|i| {
        let (s, c) = (2.0 * PI * freq * i as f64 / rate).sin_cos();
        ((s, c), f64::from(x[i]))
    }));
    let mut resid = 0.0f64;
    for i in range {
        let (s, c) = (2.0 * PI * freq * i as f64 / rate).sin_cos();
        resid = resid.max((f64::from(x[i]) - a * s - b * c).abs());
    }
    ((a * a + b * b).sqrt(), b.atan2(a), resid)
}

#[test]
fn resampled_tone_keeps_frequency_amplitude_and_timing() {
    let (from, to) = (43_800.0, 44_100u32);
    let x = tone(43_800, 1000.0, from, 0.5);
    let y = resample(&x, from, to).unwrap();
    assert_eq!(y.len(), 44_100);
    // Fit a 1 kHz sine at the output rate, away from the ends: amplitude within 1%, phase 0
    // (no delay), and a tiny residual (a wrong frequency would leave a large one).
    let (amp, phase, resid) = fit_sine(&y, 1000.0, f64::from(to), 2000..42_000);
    assert!((amp - 0.5).abs() < 0.005, "amplitude {amp}");
    assert!(phase.abs() < 0.003, "phase {phase} rad");
    assert!(resid < 0.005, "residual {resid}");
    // Frequency from zero crossings over the interior: within 1%.
    let crossings: Vec<usize> = (2001..42_000)
        .filter(|&i| y[i - 1] < 0.0 && y[i] >= 0.0)
        .collect();
    let per = (crossings[crossings.len() - 1] - crossings[0]) as f64 / (crossings.len() - 1) as f64;
    let f = f64::from(to) / per;
    assert!((f - 1000.0).abs() < 10.0, "{f} Hz");
}

#[test]
fn large_upsampling_stays_in_phase_and_pads_little() {
    // Upsampling by 36 and by about 4,800 (a still whose settings give 9.2 samples a second):
    // the leading zeros are bounded, and a tone at an eighth of the input rate still comes out
    // in phase to within 1/200 of an input sample.
    for &(from, to) in &[(1_234.5, 44_100u32), (9.2, 44_100)] {
        let ratio = f64::from(to) / from;
        let padding_out = super::resample::pad_search_len(ratio) as f64 * ratio;
        assert!(padding_out <= super::resample::DELAY_PAD_MAX_OUTPUT + ratio);
        let f = from / 8.0;
        let (amp, shift_out) = resampled_tone(120, f, from, to);
        let shift_in = shift_out / ratio;
        assert!(
            shift_in.abs() < 0.005,
            "{from}->{to}: {shift_in} input samples"
        );
        assert!((amp - 1.0).abs() < 0.01, "{from}->{to}: amplitude {amp}");
    }
}

/// Resamples `n` samples of a unit tone of `f` Hz from `from` to `to` Hz, checks the output
/// length, and returns the output's amplitude and phase shift (output samples) over its middle
/// half.
fn resampled_tone(n: usize, f: f64, from: f64, to: u32) -> (f64, f64) {
    let y = resample(&tone(n, f, from, 1.0), from, to).unwrap();
    assert_eq!(y.len(), (n as f64 * f64::from(to) / from).round() as usize);
    let m = y.len();
    let (amp, phase, _) = fit_sine(&y, f, f64::from(to), m / 4..3 * m / 4);
    (amp, phase / (2.0 * PI * f) * f64::from(to))
}

#[test]
fn resampler_delay_is_exact() {
    // Several ratios, up and down: a 500 Hz tone must come out in phase to < 1/100 sample.
    for &(from, to) in &[
        (44_714.285, 44_100u32),
        (43_800.0, 48_000),
        (96_000.0, 44_100),
        (200_000.0, 44_100),
    ] {
        let (amp, shift_samples) = resampled_tone((from * 0.5) as usize, 500.0, from, to);
        assert!(
            shift_samples.abs() < 0.01,
            "{from}->{to}: {shift_samples} samples"
        );
        assert!((amp - 1.0).abs() < 0.005, "{from}->{to}: amplitude {amp}");
    }
}

/// SNR (dB) of `y` against `truth(k)` over all of `y`, its ends included.
fn whole_clip_snr_db(y: &[f32], truth: impl Fn(usize) -> f64) -> f64 {
    let (mut sig, mut err) = (0.0, 0.0);
    for (k, &v) in y.iter().enumerate() {
        sig += truth(k).powi(2);
        err += (f64::from(v) - truth(k)).powi(2);
    }
    10.0 * (sig / err).log10()
}

#[test]
fn a_short_clip_is_resampled_clean_to_its_ends() {
    // 8 ms tones (a short clip or its reference), 48 → 44.1 kHz and 43.8 → 44.1 kHz, scored
    // over every output sample: continued past its ends by silence, the filter rang through
    // both ends (the 500 Hz tone read 47.1 dB, the first to fail); continued by the clip's
    // odd reflection, every one reads above 50 dB.
    for (from, to) in [(48_000.0, 44_100u32), (43_800.0, 44_100)] {
        for f in [500.0, 1000.0, 2000.0, 3000.0] {
            let n = (from * 0.008) as usize;
            let x: Vec<f32> = (0..n)
                .map(|i| (2.0 * PI * f * i as f64 / from + 0.3).sin() as f32)
                .collect();
            let y = resample(&x, from, to).unwrap();
            let snr = whole_clip_snr_db(&y, |k| {
                (2.0 * PI * f * k as f64 / f64::from(to) + 0.3).sin()
            });
            assert!(snr > 50.0, "{from} -> {to}, {f} Hz: {snr:.1} dB");
        }
    }
}

#[test]
fn a_noisy_end_sample_is_not_the_first_output_sample() {
    // A still's border fits give about 8 noisy lines an output sample (348 kHz → 44.1 kHz).
    // Reflected about the end samples themselves, the first and last output samples took
    // those samples' noise whole: the ends' error was 2.25 times the clip's (0.245 against
    // 0.109 rms); about their level over one output sample's span of input, 1.5 times.
    let from = 348_018.65;
    let f = 2000.0;
    let (mut ends, mut middle) = (0.0, 0.0);
    let mut seed: u64 = 12_345;
    for step in 0..8 {
        let phase = f64::from(step) * PI / 4.0;
        let x: Vec<f32> = (0..4001)
            .map(|i| {
                seed = seed
                    .wrapping_mul(6_364_136_223_846_793_005)
                    .wrapping_add(1_442_695_040_888_963_407);
                let uniform = (seed >> 11) as f64 / (1_u64 << 53) as f64 - 0.5;
                ((2.0 * PI * f * i as f64 / from + phase).sin() + 1.04 * uniform) as f32
            })
            .collect();
        let y = resample(&x, from, 44_100).unwrap();
        let rms = |r: std::ops::Range<usize>| {
            let n = r.len() as f64;
            let e: f64 = r
                .map(|k| {
                    let truth = (2.0 * PI * f * k as f64 / 44_100.0 + phase).sin();
                    (f64::from(y[k]) - truth).powi(2)
                })
                .sum();
            (e / n).sqrt()
        };
        ends += rms(0..4).max(rms(y.len() - 4..y.len())) / 8.0;
        middle += rms(100..400) / 8.0;
    }
    assert!(
        ends < 1.75 * middle,
        "ends {ends:.4} rms, middle {middle:.4}"
    );
}

#[test]
fn read_from_reads_past_the_end_by_reflection() {
    // 300 samples of 2 kHz read from 3.37 on: the last 32 reach past the end, where the
    // reflection stands in for the missing samples (silence there rang: 32.2 dB).
    let rate = 44_100.0;
    let x: Vec<f32> = (0..300)
        .map(|i| (2.0 * PI * 2000.0 * i as f64 / rate + 0.3).sin() as f32)
        .collect();
    let y = read_from(&x, 3.37);
    let snr = whole_clip_snr_db(&y, |k| {
        (2.0 * PI * 2000.0 * (k as f64 + 3.37) / rate + 0.3).sin()
    });
    assert!(snr > 40.0, "{snr:.1} dB");
}

#[test]
fn read_from_a_fractional_start_is_the_band_limited_value_there() {
    // A 2 kHz tone at 44.1 kHz read from 10.37 samples on: within −60 dB of the true tone there
    // (away from the ends); a whole start is an exact slice.
    let rate = 44_100.0;
    let x = tone(2000, 2000.0, rate, 1.0);
    let y = read_from(&x, 10.37);
    assert_eq!(y.len(), x.len() - 10);
    let (mut err, mut sig) = (0.0, 0.0);
    for (k, &v) in y.iter().enumerate().take(1900).skip(100) {
        let t = (10.37 + k as f64) / rate;
        let truth = (2.0 * PI * 2000.0 * t).sin();
        err += (f64::from(v) - truth).powi(2);
        sig += truth * truth;
    }
    assert!(
        10.0 * (sig / err).log10() > 60.0,
        "{} dB",
        10.0 * (sig / err).log10()
    );
    assert_eq!(read_from(&x, 7.0), x[7..].to_vec());
    assert!(read_from(&x, 5000.0).is_empty());
}

#[test]
fn downsampling_removes_what_does_not_fit() {
    // 1 kHz + 30 kHz at 200 kHz to 44.1 kHz: the 30 kHz tone must not alias to 14.1 kHz.
    let from = 200_000.0;
    let n = 100_000;
    let x: Vec<f32> = tone(n, 1000.0, from, 0.5)
        .iter()
        .zip(tone(n, 30_000.0, from, 0.5))
        .map(|(a, b)| a + b)
        .collect();
    let y = resample(&x, from, 44_100).unwrap();
    let m = y.len();
    let (amp, _, _) = fit_sine(&y, 14_100.0, 44_100.0, m / 4..3 * m / 4);
    assert!(amp < 1e-3, "alias amplitude {amp}");
    let (amp, _, _) = fit_sine(&y, 1000.0, 44_100.0, m / 4..3 * m / 4);
    assert!((amp - 0.5).abs() < 0.005, "{amp}");
}

#[test]
fn orientation_to_output_rate_end_to_end() {
    // A lateral 1 kHz tone read from both walls of 80 groups (1280 px frames, 0.39 µm/px,
    // a sample every 40 px, 1180 px group step), stitched on a 15 µm grid and resampled to
    // 44.1 kHz: it must line up with the analytic tone sample for sample.
    let um_per_px = 0.39;
    let wavelength_um = VT_MM_S * 1000.0 / 1000.0;
    let slope = |p_um: f64| 0.05 * (2.0 * PI * p_um / wavelength_um).cos(); // d′(X)
    let groups: Vec<GroupSignal> = (0..80)
        .map(|k| {
            let column0_um = k as f64 * 1180.0 * um_per_px;
            let xs: Vec<f32> = (0..32).map(|i| 7.0 + 40.0 * i as f32).collect();
            let t: Vec<f64> = xs
                .iter()
                .map(|&x| slope(column0_um + f64::from(x) * um_per_px) / SQRT_2)
                .collect();
            let o = orientation(vec![
                wall(WallSide::Left, &xs, &t),
                wall(WallSide::Right, &xs, &t),
            ]);
            group_signal(k, &o, Cut::Lateral, column0_um, um_per_px, VT_MM_S).unwrap()
        })
        .collect();
    let s = stitch(&groups, 15.0).unwrap();
    assert!(s.gaps.is_empty());
    let y = resample(&s.channels[0], s.native_rate_hz, 44_100).unwrap();
    let expected: Vec<f32> = (0..y.len())
        .map(|k| {
            let p = s.start_um + k as f64 * VT_MM_S * 1000.0 / 44_100.0;
            (VT_MM_S * slope(p)) as f32
        })
        .collect();
    // Skip the resampler's edge transients.
    let scores = crate::pipeline::eval::evaluate(
        &y[200..y.len() - 200],
        &expected[200..y.len() - 200],
        10,
        44_100,
    )
    .unwrap();
    assert_eq!(scores.lag_samples, 0, "{scores:?}");
    assert!(scores.r > 0.999_999 && scores.snr_db > 60.0, "{scores:?}");
}

#[test]
fn output_level_and_checks() {
    let p = SoundParams::default();
    assert!(p.validate().is_ok());
    let edits: [fn(&mut SoundParams); 3] = [
        |p| p.native_spacing_um = -1.0,
        |p| p.output_rate_hz = 0,
        |p| p.full_scale_mm_s = f64::NAN,
    ];
    assert_each_edit_is_refused(&edits, SoundParams::validate);

    let mut ch = vec![vec![10.0f32, -40.0], vec![f32::NAN, 20.0]];
    let g = p.scale_to_output(&mut ch).unwrap();
    assert_eq!(g, f64::from(0.89_f32 / 40.0));
    assert!((ch[0][1] + 0.89).abs() < 1e-6 && ch[1][0] == 0.0);
    let raw = SoundParams {
        normalize_peak: 0.0,
        full_scale_mm_s: 50.0,
        ..SoundParams::default()
    };
    let mut ch = vec![vec![25.0f32]];
    assert!((raw.scale_to_output(&mut ch).unwrap() - 0.02).abs() < 1e-9);
    assert!((ch[0][0] - 0.5).abs() < 1e-6);
    let mut silent = vec![vec![0.0f32; 4]];
    assert_eq!(p.scale_to_output(&mut silent).unwrap(), 1.0);
    let nan = SoundParams {
        normalize_peak: f32::NAN,
        ..SoundParams::default()
    };
    assert!(nan.scale_to_output(&mut silent).is_err());
    let zero_fs = SoundParams {
        normalize_peak: 0.0,
        full_scale_mm_s: 0.0,
        ..SoundParams::default()
    };
    assert!(zero_fs.scale_to_output(&mut silent).is_err());
}

#[test]
fn resample_lengths_and_errors() {
    for n in [1usize, 2, 7, 100, 4095, 4096, 4097, 10_007] {
        let x = vec![0.25f32; n];
        let y = resample(&x, 43_000.0, 44_100).unwrap();
        assert_eq!(
            y.len(),
            (n as f64 * 44_100.0 / 43_000.0).round() as usize,
            "n = {n}"
        );
        assert!(y.iter().all(|v| v.is_finite()));
    }
    assert!(resample(&[], 43_000.0, 44_100).unwrap().is_empty());
    assert_eq!(
        resample(&[1.0, f32::NAN], 44_100.0, 44_100).unwrap(),
        vec![1.0, 0.0]
    );
    assert!(resample(&[1.0], 0.0, 44_100).is_err());
    assert!(resample(&[1.0], -1.0, 44_100).is_err());
    assert!(resample(&[1.0], f64::NAN, 44_100).is_err());
    assert!(resample(&[1.0], f64::INFINITY, 44_100).is_err());
    assert!(resample(&[1.0], 44_100.0, 0).is_err());
}
