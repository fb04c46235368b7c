//! Evaluation against a reference sound: Pearson r (best lag), peak-envelope r and SNR after best gain.
//!
//! Lag convention: `reference[i] ≈ g · recovered[i + lag]`, so a positive lag means the
//! recovered signal is late by `lag` samples. All lags within ±`max_lag` are scored at once:
//! the cross-correlation comes from FFTs of blocks, and the per-lag means and energies of the
//! overlapping parts from sums kept only near where an overlap can start or end, so the
//! search costs O(N log max_lag) in time and O(max_lag) in memory beside the two signals (a
//! whole side scores in the memory of a clip; a window as wide as the signals costs one FFT
//! of both).

use serde::{Deserialize, Serialize};

use super::dsp::lag_cross_correlation;

/// Fewest overlapping samples for any score.
const MIN_OVERLAP_SAMPLES: usize = 16;
/// Peak-envelope window (s): the peak of |x| over each 5 ms block.
const ENVELOPE_WINDOW_S: f64 = 0.005;
/// Blocks on each side averaged when smoothing the block peaks (1 → a 3-block moving mean).
const ENVELOPE_SMOOTH_BLOCKS: usize = 1;
/// Fewest envelope blocks for an envelope r (10 blocks = 50 ms): over a handful of smoothed
/// block peaks the correlation means nothing, so shorter clips get none.
const MIN_ENVELOPE_BLOCKS: usize = 10;
/// A reference whose whole blocks' peaks spread by less than this share of the highest is
/// steady (a tone): its envelope r would only correlate ripple, so it gets none.
const STEADY_ENVELOPE_SPREAD: f32 = 0.01;
/// How much more strongly (in r) the recovered signal must correlate inverted than upright for
/// [`Scores::inverted`].
const INVERTED_MARGIN: f64 = 0.2;
/// SNR reported when the residual is exactly zero (keeps the score finite for JSON).
const MAX_SNR_DB: f64 = 300.0;

/// Scores of a recovered signal against its reference.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Scores {
    /// Pearson r of the waveforms at the best lag (negative when the recovered signal is
    /// inverted; the lag maximises the signed r, so a polarity error shows).
    pub r: f64,
    /// Pearson r of the peak envelopes at the best lag (see [`peak_envelope`]); `None` when
    /// the overlap is shorter than 10 envelope blocks (50 ms) or the reference's envelope is
    /// steady (a tone: within 1 % of its peak).
    pub envelope_r: Option<f64>,
    /// SNR (dB) of the recovered signal after best gain and lag:
    /// 10·log10(Σref² / Σ(ref − g·rec)²) with the least-squares g. For rec = ref + noise this
    /// reads 10·log10(1 + S/N), within 0.05 dB of the true S/N above 20 dB.
    pub snr_db: f64,
    /// Best lag in samples: `reference[i] ≈ g·recovered[i + lag]` (positive: recovered is late).
    pub lag_samples: i64,
    /// Samples compared (the overlap at the best lag).
    pub samples: usize,
    /// Where the recovered signal correlates more strongly inverted than upright (its most
    /// negative r beats `r` in size): that r and its lag. Its polarity is likely reversed (a
    /// still read from a mirrored image, a wiring or sign slip); `r` and the SNR stay the
    /// upright scores.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub inverted: Option<Inverted>,
}

/// The recovered signal's strongest inverted correlation ([`Scores::inverted`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Inverted {
    /// Its Pearson r (negative).
    pub r: f64,
    /// Its lag, as [`Scores::lag_samples`].
    pub lag_samples: i64,
}

impl Scores {
    /// The envelope r with `decimals` decimals, or "n/a (< 50 ms or steady)" when the clip was
    /// too short (50 ms is the shortest that gets one) or its reference too steady to measure it.
    #[must_use]
    pub fn envelope_r_text(&self, decimals: usize) -> String {
        self.envelope_r.map_or_else(
            || {
                let ms = MIN_ENVELOPE_BLOCKS as f64 * ENVELOPE_WINDOW_S * 1000.0;
                format!("n/a (< {ms:.0} ms or steady)")
            },
            |e| format!("{e:.decimals$}"),
        )
    }

    /// The scores on one line: `r = 0.973, envelope r = 0.991, SNR = 12.7 dB`, and what an
    /// inverted polarity reads.
    #[must_use]
    pub fn line(&self) -> String {
        let inverted = self.inverted.map_or_else(String::new, |i| {
            format!(
                "; inverted it reads r = {:.3} at lag {}: its polarity is likely reversed",
                i.r, i.lag_samples
            )
        });
        format!(
            "r = {:.3}, envelope r = {}, SNR = {:.1} dB{inverted}",
            self.r,
            self.envelope_r_text(3),
            self.snr_db
        )
    }
}

/// Pearson correlation of `a` and `b` over their common length (the shorter one's). 0 when it
/// is undefined (fewer than 2 samples or a constant input). Non-finite samples count as 0.
#[must_use]
pub fn pearson(a: &[f32], b: &[f32]) -> f64 {
    let n = a.len().min(b.len());
    if n < 2 {
        return 0.0;
    }
    let val = |v: f32| if v.is_finite() { f64::from(v) } else { 0.0 };
    #[allow(clippy::cast_precision_loss)] // lengths ≤ 2^52
    let nf = n as f64;
    let ma = a[..n].iter().map(|&v| val(v)).sum::<f64>() / nf;
    let mb = b[..n].iter().map(|&v| val(v)).sum::<f64>() / nf;
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (&x, &y) in a[..n].iter().zip(&b[..n]) {
        let (dx, dy) = (val(x) - ma, val(y) - mb);
        sab += dx * dy;
        saa += dx * dx;
        sbb += dy * dy;
    }
    let den = (saa * sbb).sqrt();
    if den > 0.0 && den.is_finite() {
        (sab / den).clamp(-1.0, 1.0)
    } else {
        0.0
    }
}

/// Peak |x| over consecutive blocks of `block` samples (the last block may be shorter),
/// non-finite samples left out: one value per block.
#[must_use]
pub fn block_peaks(samples: &[f32], block: usize) -> Vec<f32> {
    samples
        .chunks(block.max(1))
        .map(|c| {
            c.iter().fold(
                0.0_f32,
                |m, v| if v.is_finite() { m.max(v.abs()) } else { m },
            )
        })
        .collect()
}

/// Peak envelope used by [`Scores::envelope_r`]: the [`block_peaks`] of blocks of `window`
/// samples, each replaced by the mean of itself and its neighbour blocks (a 3-block moving
/// average). One value per block.
#[must_use]
pub fn peak_envelope(samples: &[f32], window: usize) -> Vec<f32> {
    let peaks = block_peaks(samples, window);
    let n = peaks.len();
    (0..n)
        .map(|k| {
            let lo = k.saturating_sub(ENVELOPE_SMOOTH_BLOCKS);
            let hi = (k + ENVELOPE_SMOOTH_BLOCKS + 1).min(n);
            let slice = &peaks[lo..hi];
            #[allow(clippy::cast_precision_loss)] // a handful of blocks
            let mean = slice.iter().sum::<f32>() / slice.len() as f32;
            mean
        })
        .collect()
}

/// Whether `samples` are steady: the peaks of their whole blocks of `window` samples lie
/// within [`STEADY_ENVELOPE_SPREAD`] of the highest (a silent stretch is steady too).
fn is_steady(samples: &[f32], window: usize) -> bool {
    let whole = samples.len() - samples.len() % window.max(1);
    let peaks = block_peaks(&samples[..whole], window);
    let (lo, hi) = peaks.iter().fold((f32::INFINITY, 0.0_f32), |(lo, hi), &v| {
        (lo.min(v), hi.max(v))
    });
    hi <= 0.0 || hi - lo < STEADY_ENVELOPE_SPREAD * hi
}

/// Overlap of reference indices for a lag: `i ∈ [lo, hi)` with `i + lag` inside `recovered`.
fn overlap(n_ref: usize, n_rec: usize, lag: i64) -> (usize, usize) {
    let (Ok(n_ref_i), Ok(n_rec_i)) = (i64::try_from(n_ref), i64::try_from(n_rec)) else {
        return (0, 0);
    };
    let lo = (-lag).clamp(0, n_ref_i);
    let hi = (n_rec_i - lag).clamp(lo, n_ref_i);
    (
        usize::try_from(lo).unwrap_or(0),
        usize::try_from(hi).unwrap_or(0),
    )
}

/// Sums of a signal's first `k` samples and of their squares, kept for the `k` of a few
/// stretches only (where the lag search's overlaps start and end).
struct HeadSums {
    /// Per stretch: its first `k`, then `(Σ v, Σ v²)` for `k`, `k + 1`, ….
    stretches: Vec<(usize, Vec<(f64, f64)>)>,
}

impl HeadSums {
    /// The sums of `value(s[i])` over `i < k` for every `k` in `stretches` (cut to
    /// `0..=s.len()`), in one pass, summed in index order.
    fn new(
        s: &[f32],
        value: impl Fn(f32) -> f64,
        stretches: &[std::ops::RangeInclusive<usize>],
    ) -> Self {
        let spans: Vec<(usize, usize)> = stretches
            .iter()
            .map(|r| (*r.start(), (*r.end()).min(s.len())))
            .filter(|(a, b)| a <= b)
            .collect();
        let mut kept: Vec<(usize, Vec<(f64, f64)>)> = spans
            .iter()
            .map(|&(a, b)| (a, Vec::with_capacity(b - a + 1)))
            .collect();
        let (mut sum, mut sum_sq) = (0.0, 0.0);
        for k in 0..=s.len() {
            for (&(a, b), (_, sums)) in spans.iter().zip(&mut kept) {
                if (a..=b).contains(&k) {
                    sums.push((sum, sum_sq));
                }
            }
            if let Some(&v) = s.get(k) {
                let v = value(v);
                sum += v;
                sum_sq += v * v;
            }
        }
        Self { stretches: kept }
    }

    /// `(Σ v, Σ v²)` over `lo..hi` (both inside a stretch of [`HeadSums::new`]).
    fn between(&self, lo: usize, hi: usize) -> Option<(f64, f64)> {
        let at = |k: usize| {
            self.stretches
                .iter()
                .find_map(|(first, sums)| sums.get(k.checked_sub(*first)?).copied())
        };
        let ((s_lo, q_lo), (s_hi, q_hi)) = (at(lo)?, at(hi)?);
        Some((s_hi - s_lo, q_hi - q_lo))
    }
}

/// One lag's overlap: reference indices `lo..hi`, recovered indices from `ylo`.
fn lag_overlap(n_ref: usize, n_rec: usize, lag: i64) -> Option<(usize, usize, usize)> {
    let (lo, hi) = overlap(n_ref, n_rec, lag);
    let ylo = lo.checked_add_signed(isize::try_from(lag).ok()?)?;
    Some((lo, hi, ylo))
}

/// Compares `recovered` with `reference` (same rate), searching lags within ±`max_lag` for the
/// largest signed Pearson r. Lags whose overlap is shorter than half the shorter signal are not
/// considered (a few samples can correlate by chance). Non-finite samples count as 0.
/// `None` when fewer than 16 samples overlap.
#[must_use]
pub fn evaluate(
    recovered: &[f32],
    reference: &[f32],
    max_lag: usize,
    sample_rate_hz: u32,
) -> Option<Scores> {
    let val = |v: &f32| if v.is_finite() { f64::from(*v) } else { 0.0 };
    let (n_ref, n_rec) = (reference.len(), recovered.len());
    let min_overlap = MIN_OVERLAP_SAMPLES.max(n_ref.min(n_rec) / 2);
    if n_ref.min(n_rec) < MIN_OVERLAP_SAMPLES {
        return None;
    }
    let max_lag = max_lag.min(n_ref.max(n_rec));
    // Remove the global means first: Pearson is shift-invariant and this avoids cancellation.
    #[allow(clippy::cast_precision_loss)]
    let mean = |s: &[f32]| s.iter().map(val).sum::<f64>() / s.len() as f64;
    let (m_ref, m_rec) = (mean(reference), mean(recovered));
    let x_of = |v: f32| val(&v) - m_ref;
    let y_of = |v: f32| val(&v) - m_rec;
    let m = i64::try_from(max_lag).ok()?;
    // Where a lag's overlap (reference lo..hi, recovered ylo..ylo + hi − lo) can start and
    // end: lo = max(−lag, 0), hi = min(n_rec − lag, n_ref), ylo = max(lag, 0) and
    // ylo + hi − lo = min(n_ref + lag, n_rec), so within max_lag of 0, n_ref or n_rec.
    let near = |k: usize| k.saturating_sub(max_lag)..=k.saturating_add(max_lag);
    let (x_sums, y_sums) = (
        HeadSums::new(reference, x_of, &[near(0), near(n_rec), n_ref..=n_ref]),
        HeadSums::new(recovered, y_of, &[near(0), near(n_ref), n_rec..=n_rec]),
    );
    let xcorr = lag_cross_correlation(reference, recovered, max_lag, x_of, y_of);

    let mut best: Option<(f64, i64)> = None;
    let mut most_negative: Option<(f64, i64)> = None;
    for (lag, &sxy) in (-m..=m).zip(&xcorr) {
        let Some((lo, hi, ylo)) = lag_overlap(n_ref, n_rec, lag) else {
            continue;
        };
        let len = hi - lo;
        if len < min_overlap {
            continue;
        }
        #[allow(clippy::cast_precision_loss)]
        let nf = len as f64;
        let (sx, sxx) = x_sums.between(lo, hi)?;
        let (sy, syy) = y_sums.between(ylo, ylo + len)?;
        let cov = sxy - sx * sy / nf;
        let vx = sxx - sx * sx / nf;
        let vy = syy - sy * sy / nf;
        let den = (vx * vy).sqrt();
        let r = if den > 0.0 && den.is_finite() {
            (cov / den).clamp(-1.0, 1.0)
        } else {
            0.0
        };
        let better = match best {
            None => true,
            Some((br, bl)) => r > br + 1e-12 || ((r - br).abs() <= 1e-12 && lag.abs() < bl.abs()),
        };
        if better {
            best = Some((r, lag));
        }
        if most_negative.is_none_or(|(nr, nl)| {
            r < nr - 1e-12 || ((r - nr).abs() <= 1e-12 && lag.abs() < nl.abs())
        }) {
            most_negative = Some((r, lag));
        }
    }
    let (best_r, lag) = best?;
    // A steady tone correlates inverted at half a period about as well as upright at its lag:
    // only a clear margin says anything about polarity.
    let inverted = most_negative
        .filter(|&(nr, _)| -nr > best_r.max(0.0) + INVERTED_MARGIN)
        .map(|(r, lag_samples)| Inverted { r, lag_samples });

    // Exact scores on the aligned overlap (direct sums, not differences of running sums).
    let (lo, hi, ylo) = lag_overlap(n_ref, n_rec, lag)?;
    let len = hi - lo;
    let ref_part = reference.get(lo..hi)?;
    let rec_part = recovered.get(ylo..ylo + len)?;
    let r = pearson(rec_part, ref_part);
    let (mut srr, mut sry, mut syy) = (0.0, 0.0, 0.0);
    for (a, b) in ref_part.iter().zip(rec_part) {
        let (a, b) = (val(a), val(b));
        srr += a * a;
        sry += a * b;
        syy += b * b;
    }
    let gain = if syy > 0.0 { sry / syy } else { 0.0 };
    let noise: f64 = ref_part
        .iter()
        .zip(rec_part)
        .map(|(a, b)| (val(a) - gain * val(b)).powi(2))
        .sum();
    let snr_db = if noise > 0.0 && srr > 0.0 {
        (10.0 * (srr / noise).log10()).min(MAX_SNR_DB)
    } else if srr > 0.0 {
        MAX_SNR_DB
    } else {
        0.0
    };
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // a few hundred samples
    let window = (f64::from(sample_rate_hz) * ENVELOPE_WINDOW_S)
        .round()
        .max(1.0) as usize;
    let (env_rec, env_ref) = (
        peak_envelope(rec_part, window),
        peak_envelope(ref_part, window),
    );
    let envelope_r = (env_rec.len() >= MIN_ENVELOPE_BLOCKS && !is_steady(ref_part, window))
        .then(|| pearson(&env_rec, &env_ref));
    Some(Scores {
        r,
        envelope_r,
        snr_db,
        lag_samples: lag,
        samples: len,
        inverted,
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests unwrap known-good results
mod tests {
    use super::*;
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
    fn known_snr_is_measured() {
        let x = music(44_100);
        let e = energy(&x) / x.len() as f64;
        for target_db in [10.0, 20.0, 30.0] {
            let nz = noise(x.len(), 7);
            let en = energy(&nz) / nz.len() as f64;
            let k = (e / en / 10f64.powf(target_db / 10.0)).sqrt() as f32;
            let rec: Vec<f32> = x.iter().zip(&nz).map(|(a, b)| 2.5 * (a + k * b)).collect();
            let s = evaluate(&rec, &x, 20, FS).unwrap();
            assert!(
                (s.snr_db - target_db).abs() < 0.5,
                "{target_db}: {} ({s:?})",
                s.snr_db
            );
            assert_eq!(s.lag_samples, 0);
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
            assert!((s.r - best.0).abs() < 1e-9, "{case}: {} vs {}", s.r, best.0);
        }
    }

    #[test]
    fn pearson_basics() {
        assert!((pearson(&[1.0, 2.0, 3.0], &[2.0, 4.0, 6.5]) - 0.9986).abs() < 1e-3);
        assert!((pearson(&[1.0, 2.0, 3.0], &[3.0, 2.0, 1.0]) + 1.0).abs() < 1e-12);
        assert_eq!(pearson(&[1.0], &[1.0]), 0.0);
        assert_eq!(pearson(&[1.0, 1.0, 1.0], &[1.0, 2.0, 3.0]), 0.0);
    }
}
