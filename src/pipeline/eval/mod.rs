//! Evaluation against a reference sound: Pearson r (best lag), peak-envelope r and SNR after best gain.
//!
//! Lag convention: `reference[i] ≈ g · recovered[i + lag]`, so a positive lag means the
//! recovered signal is late by `lag` samples. All lags within ±`max_lag` are scored at once:
//! the cross-correlation comes from FFTs of blocks, and the per-lag means and energies of the
//! overlapping parts from sums kept only near where an overlap can start or end, so the
//! search costs O(N log max_lag) in time and O(max_lag) in memory beside the two signals (a
//! whole side scores in the memory of a clip; a window as wide as the signals costs one FFT
//! of both). The best whole-sample lag is then refined to a fraction of a sample, and every
//! score is measured there (`eval::fraction`): a sub-sample delay is not noise.

use serde::{Deserialize, Serialize};

use super::dsp::lag_cross_correlation;

mod fraction;

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
/// Or how much less of the reference (as unexplained variance, 1 − r²) the recovered signal
/// must leave unexplained inverted than upright, both at their refined lags.
const INVERTED_RESIDUAL_SHARE: f64 = 0.5;
/// ... and by at least this share of the reference's variance (two near-perfect fits, as of a
/// pure tone either way, differ by nothing that matters).
const INVERTED_RESIDUAL_GAIN: f64 = 0.01;
/// SNR reported when the residual is exactly zero (keeps the score finite for JSON).
const MAX_SNR_DB: f64 = 300.0;

/// Scores of a recovered signal against its reference.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Scores {
    /// Pearson r of the waveforms at the refined lag (negative when the recovered signal is
    /// inverted; the lag maximises the signed r, so a polarity error shows).
    pub r: f64,
    /// Pearson r of the peak envelopes at the refined lag (see [`peak_envelope`]); `None` when
    /// the overlap is shorter than 10 envelope blocks (50 ms) or the reference's envelope is
    /// steady (a tone: within 1 % of its peak).
    pub envelope_r: Option<f64>,
    /// SNR (dB) of the recovered signal after best gain, at the refined lag:
    /// 10·log10(Σref² / Σ(ref − g·rec)²) with the least-squares g. For rec = ref + noise this
    /// reads 10·log10(1 + S/N), within 0.05 dB of the true S/N above 20 dB.
    pub snr_db: f64,
    /// Best whole-sample lag: `reference[i] ≈ g·recovered[i + lag]` (positive: recovered is
    /// late).
    pub lag_samples: i64,
    /// That lag refined to a fraction of a sample (within one sample of it): the scores are
    /// measured at it, the reference read between its samples (see the module docs).
    pub lag_refined_samples: f64,
    /// Samples compared (the overlap at the refined lag).
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

    /// The refined lag with `decimals` decimals (a lag that rounds to zero reads `0.000`, not
    /// `-0.000`).
    #[must_use]
    pub fn lag_text(&self, decimals: usize) -> String {
        let scale = 10f64.powi(i32::try_from(decimals).unwrap_or(9).min(9));
        // Adding +0 turns a rounded −0 into 0.
        let lag = (self.lag_refined_samples * scale).round() / scale + 0.0;
        format!("{lag:.decimals$}")
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
    // Exact scores at the lag refined to a fraction of a sample (direct sums, not differences
    // of running sums).
    let aligned = fraction::refine(reference, recovered, lag, m)?;
    // A steady tone correlates inverted at half a period about as well as upright at its lag:
    // only a clear margin in r, or inverted leaving a clearly smaller residual once both are
    // refined (a chord or a few partials: upright matches only at some lag that nearly
    // repeats them), says anything about polarity.
    let inverted = most_negative
        .filter(|&(nr, nlag)| {
            // The refined comparison (a second refine) only where inverted already reads
            // stronger at whole lags: upright wins almost every clip.
            -nr > best_r.max(0.0) + INVERTED_MARGIN
                || (-nr > best_r && inverted_fits_better(reference, recovered, aligned.r, nlag, m))
        })
        .map(|(r, lag_samples)| Inverted { r, lag_samples });

    let rec_part = recovered.get(aligned.lo..aligned.hi)?;
    let ref_part = aligned.reference.as_slice();
    let (len, r) = (rec_part.len(), aligned.r);
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
        lag_refined_samples: aligned.lag,
        samples: len,
        inverted,
    })
}

/// True when `recovered` turned over and refined about `lag` leaves at most
/// [`INVERTED_RESIDUAL_SHARE`] of the unexplained variance (1 − r²) that it leaves upright at
/// its own refined r, `upright_r`, and [`INVERTED_RESIDUAL_GAIN`] less.
fn inverted_fits_better(
    reference: &[f32],
    recovered: &[f32],
    upright_r: f64,
    lag: i64,
    max_lag: i64,
) -> bool {
    let turned: Vec<f32> = recovered.iter().map(|v| -v).collect();
    fraction::refine(reference, &turned, lag, max_lag).is_some_and(|inv| {
        let (upright_left, inverted_left) = (1.0 - upright_r * upright_r, 1.0 - inv.r * inv.r);
        inv.r > upright_r.max(0.0)
            && inverted_left <= INVERTED_RESIDUAL_SHARE * upright_left
            && upright_left - inverted_left >= INVERTED_RESIDUAL_GAIN
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests unwrap known-good results
mod tests;
