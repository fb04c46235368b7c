//! Short bursts of outliers (2 to 8 samples) taken out of a wall's displacement track before it
//! is differentiated: the clicks that `despike`'s one-sample test cannot see.
//!
//! On a damaged groove the fine fits of a few neighbouring samples can land off together (a
//! flake's rim read as the land border for a sample or five), and since all of those samples'
//! borders move together the robust combination cannot see it. The displacement then carries a
//! bump a few samples wide, well within the groove's slope limit (`plausible`), which the
//! differentiator turns into a click many times the sound; on the accuracy suite's damaged
//! speech a single one held 15 % of the fused decoder's error energy.
//!
//! For each burst length `L` (2 to [`MAX_BURST`]) and start `j`, the track is compared with
//! the cubic through its two samples before and two after the burst, at nodes `−2, −1, L,
//! L + 1`. What is measured is the burst's **mean** distance from that cubic, which a bump
//! carries and zero-mean noise does not. Both the comparison and the replacement read the
//! track lightly smoothed (`[1, 2, 1]/4`), so a stretch of sample-to-sample jitter that the
//! decoders' low-pass or the fusion already remove neither starts a burst nor bends the curve
//! through its nodes. A burst counts where its mean distance exceeds `sigmas` times the
//! larger of two scales:
//! - the robust scale (1.4826·median |·|) of the same measure over its block of
//!   [`BLOCK`] samples and the blocks on each side, which grows with what the cubic cannot
//!   follow of real sound (a loud high tone), so real sound does not count;
//! - the local noise, from the one-sample residuals (`despike`) of the 16 samples beyond the
//!   burst's nodes on each side, times the measure's noise gain for white displacement noise,
//!   so a burst in a noisy stretch must stand out of that stretch.
//!
//! The strongest burst wins where several overlap (their nodes included). It is put on the
//! cubic through its nodes, the two next to it smoothed with the curve's ends in place of its
//! own outlying samples, and taken only where the track then settles: every one-sample
//! residual within four samples of it at most 5 local σ. One whose nodes sit on a longer
//! outlier, or in a jittery stretch, does not settle and is left. A block with more than
//! [`MAX_PER_BLOCK`] bursts is motion the cubic does not follow and is left alone, as in
//! `despike`. Taking one burst can uncover another beside it, so the search runs up to three
//! times.

use std::ops::Range;

use super::despike::{BLOCK, MAX_PER_BLOCK, MIN_SCALE_UM, block_scales, residuals};

/// Longest burst (samples).
pub const MAX_BURST: usize = 8;

/// Most rounds of the search.
const ROUNDS: usize = 3;

/// The burst measure for one length: the cubic's weights and the noise gain of the mean.
struct Measure {
    len: usize,
    /// Lagrange weights of the nodes `−2, −1, len, len + 1` at each sample of the burst.
    weights: Vec<[f64; 4]>,
    /// Each node's weight in the burst's mean of the cubic.
    mean_weights: [f64; 4],
    /// Standard deviation of the burst's mean distance for white displacement noise of σ 1.
    noise_gain: f64,
}

impl Measure {
    fn new(len: usize) -> Self {
        let l = len as f64;
        let nodes = [-2.0, -1.0, l, l + 1.0];
        // Each node's Lagrange weight at each sample: the cubic through it alone.
        let weights: Vec<[f64; 4]> = (0..len)
            .map(|i| {
                std::array::from_fn(|k| {
                    let unit = std::array::from_fn::<_, 4, _>(|m| (nodes[m], f64::from(m == k)));
                    crate::pipeline::lagrange(&unit, i as f64)
                })
            })
            .collect();
        let mean_weights: [f64; 4] =
            std::array::from_fn(|k| weights.iter().map(|w| w[k]).sum::<f64>() / l);
        let noise_gain = (1.0 / l + mean_weights.iter().map(|c| c * c).sum::<f64>()).sqrt();
        Self {
            len,
            weights,
            mean_weights,
            noise_gain,
        }
    }

    /// The nodes of the burst starting at `j`.
    fn nodes(&self, s: &[f64], j: usize) -> [f64; 4] {
        [s[j - 2], s[j - 1], s[j + self.len], s[j + self.len + 1]]
    }

    /// The burst at `j` of `x` put on its curve: the cubic through its nodes on `s` (`x`
    /// smoothed), where the two next to the burst are smoothed with the curve's own ends in
    /// place of the burst's outlying first and last samples.
    fn replacement(&self, x: &[f64], s: &[f64], j: usize) -> Vec<f64> {
        let l = self.len;
        let mut y = self.nodes(s, j);
        for _ in 0..NODE_PASSES {
            let first = dot(&self.weights[0], &y);
            let last = dot(&self.weights[l - 1], &y);
            y[1] = 0.25 * x[j - 2] + 0.5 * x[j - 1] + 0.25 * first;
            y[2] = 0.25 * last + 0.5 * x[j + l] + 0.25 * x[j + l + 1];
        }
        self.weights.iter().map(|w| dot(w, &y)).collect()
    }

    /// The mean distance from the cubic of the burst at `j` of `s` (NaN where it, its nodes
    /// or two more samples on each side are missing or past an end; `unseen` is `s`'s).
    fn mean_distance(&self, s: &[f64], unseen: &Unseen, j: usize) -> f64 {
        let (Some(lo), hi) = (j.checked_sub(4), j + self.len + 4) else {
            return f64::NAN;
        };
        if hi > s.len() || unseen.any(lo..hi) {
            return f64::NAN;
        }
        let y = self.nodes(s, j);
        let cubic: f64 = self.mean_weights.iter().zip(&y).map(|(w, v)| w * v).sum();
        s[j..j + self.len].iter().sum::<f64>() / self.len as f64 - cubic
    }
}

/// Where a track is not finite, as counts before each sample, so that every measure at every
/// start asks in one step whether its stretch holds a gap (counted modulo 2³², which a
/// stretch's difference survives).
struct Unseen(Vec<u32>);

impl Unseen {
    fn new(s: &[f64]) -> Self {
        let mut before = Vec::with_capacity(s.len() + 1);
        let mut count = 0u32;
        before.push(0);
        for v in s {
            count = count.wrapping_add(u32::from(!v.is_finite()));
            before.push(count);
        }
        Self(before)
    }

    /// Whether `range` (within the track) holds a sample that is not finite.
    fn any(&self, range: Range<usize>) -> bool {
        self.0[range.end].wrapping_sub(self.0[range.start]) != 0
    }
}

/// Passes that take the burst's own samples out of the smoothing of its inner nodes (each
/// leaves a quarter of the last one's error).
const NODE_PASSES: usize = 3;

fn dot(w: &[f64; 4], y: &[f64; 4]) -> f64 {
    w.iter().zip(y).map(|(a, b)| a * b).sum()
}

/// Largest one-sample residual, in local noise σs, that the track around a burst may keep
/// once the burst is on its curve.
const SETTLE_SIGMAS: f64 = 5.0;

/// Whether the track `x` is smooth around the burst at `j` once it holds `values`: every
/// one-sample residual of the smoothed track within four samples of the burst at most
/// `limit` (false where that reaches past an end or a gap). A burst whose nodes sit on a
/// longer outlier, or in a jittery stretch, does not settle.
fn settles(x: &[f64], j: usize, values: &[f64], limit: f64) -> bool {
    let len = values.len();
    let (Some(lo), hi) = (j.checked_sub(7), j + len + 7) else {
        return false;
    };
    if hi > x.len() {
        return false;
    }
    let mut t = x[lo..hi].to_vec();
    t[7..7 + len].copy_from_slice(values);
    residuals(&smoothed(&t))[3..len + 11]
        .iter()
        .all(|r| r.abs() <= limit)
}

/// `x` smoothed by `[1, 2, 1]/4` (the end samples kept; NaN spreads to its neighbours).
fn smoothed(x: &[f64]) -> Vec<f64> {
    let n = x.len();
    (0..n)
        .map(|j| {
            if j == 0 || j + 1 >= n {
                x[j]
            } else {
                0.25 * x[j - 1] + 0.5 * x[j] + 0.25 * x[j + 1]
            }
        })
        .collect()
}

/// Samples beyond a burst's nodes on each side whose one-sample residuals give its local
/// noise.
const LOCAL_HALF: usize = 16;

/// The one-sample residual of white displacement noise of σ is `√(1 + 34/36)·σ`.
const RESIDUAL_GAIN: f64 = 1.394_433_377_556_792_5;

/// Robust σ of the displacement noise around the burst `j..j + len` from the one-sample
/// residuals `r1` of the [`LOCAL_HALF`] samples beyond its nodes on each side (read only for
/// the few bursts the block's scale lets through).
fn local_noise(r1: &[f64], j: usize, len: usize) -> f64 {
    let before = j.saturating_sub(2 + LOCAL_HALF)..j.saturating_sub(2);
    let after_start = (j + len + 2).min(r1.len());
    let after = after_start..(after_start + LOCAL_HALF).min(r1.len());
    let local: Vec<f64> = r1[before].iter().chain(&r1[after]).copied().collect();
    crate::pipeline::robust_sigma(&local, MIN_SCALE_UM * RESIDUAL_GAIN) / RESIDUAL_GAIN
}

/// Puts the short bursts of outliers of `x` (µm, NaN = gap) on the cubic through the samples
/// around them, as the module doc says; returns the bursts replaced, in order. `sigmas` ≤ 0
/// does nothing.
pub fn despike_bursts(x: &mut [f64], sigmas: f64) -> Vec<Range<usize>> {
    let mut bursts: Vec<Range<usize>> = Vec::new();
    if sigmas <= 0.0 {
        return bursts;
    }
    let measures: Vec<Measure> = (2..=MAX_BURST).map(Measure::new).collect();
    let blocks = x.len().div_ceil(BLOCK);
    // Bursts taken per block, and the blocks found to hold too many.
    let mut taken_in_block = vec![0usize; blocks];
    let mut left_alone = vec![false; blocks];
    for _ in 0..ROUNDS {
        let s = smoothed(x);
        let r1 = residuals(&s);
        let unseen = Unseen::new(&s);
        // (score, start, index into `measures`, local noise)
        let mut candidates: Vec<(f64, usize, usize, f64)> = Vec::new();
        for (m, measure) in measures.iter().enumerate() {
            let means: Vec<f64> = (0..s.len())
                .map(|j| measure.mean_distance(&s, &unseen, j))
                .collect();
            let scales = block_scales(&means);
            for (j, &mean) in means.iter().enumerate() {
                // The block's scale alone is cheap and rules out nearly every sample; the
                // local noise is read only for the rest.
                if !mean.is_finite() || mean.abs() <= sigmas * scales[j / BLOCK] {
                    continue;
                }
                let noise = local_noise(&r1, j, measure.len);
                let z = mean.abs() / (measure.noise_gain * noise).max(scales[j / BLOCK]);
                if z > sigmas {
                    candidates.push((z, j, m, noise));
                }
            }
        }
        // Strongest first (position and length break ties, so the result is one order).
        candidates.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
        let mut round: Vec<(usize, usize, Vec<f64>)> = Vec::new();
        // The samples under the spans (a burst and its nodes) taken this round: a candidate
        // whose span meets one is passed over. A mask, not a search of the taken ones, so a
        // side's merge with a hundred thousand bursts stays linear.
        let mut spanned = vec![false; x.len()];
        for &(_, j, m, noise) in &candidates {
            let span = j - 2..j + measures[m].len + 2;
            if spanned[span.clone()].iter().any(|&t| t) {
                continue;
            }
            let values = measures[m].replacement(x, &s, j);
            if settles(x, j, &values, SETTLE_SIGMAS * RESIDUAL_GAIN * noise) {
                spanned[span].fill(true);
                round.push((j, m, values));
            }
        }
        let mut per_block = vec![0usize; blocks];
        for (j, _, _) in &round {
            per_block[j / BLOCK] += 1;
        }
        for b in 0..blocks {
            if taken_in_block[b] + per_block[b] > MAX_PER_BLOCK {
                left_alone[b] = true;
            } else {
                taken_in_block[b] += per_block[b];
            }
        }
        round.retain(|(j, _, _)| !left_alone[j / BLOCK]);
        if round.is_empty() {
            break;
        }
        for (j, _, values) in round {
            x[j..j + values.len()].copy_from_slice(&values);
            bursts.push(j..j + values.len());
        }
    }
    bursts.sort_by_key(|b| b.start);
    bursts
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // tests may panic
    use super::super::despike::tests::{noisy_tone, tone};
    use super::*;

    #[test]
    fn the_measure_is_exact_for_a_cubic_and_its_noise_gain_is_what_white_noise_gives() {
        let cubic = |t: f64| 0.3 + 1.7 * t - 0.2 * t * t + 0.01 * t * t * t;
        let x: Vec<f64> = (0..40).map(|j| cubic(j as f64)).collect();
        for len in 2..=MAX_BURST {
            let m = Measure::new(len);
            assert!(
                m.mean_distance(&x, &Unseen::new(&x), 10).abs() < 1e-9,
                "len {len}"
            );
            // The mean distance is linear in the samples: its variance for white noise of
            // σ 1 is the sum of its coefficients' squares.
            let mut coefs = vec![0.0; len + 4];
            for (k, c) in [0, 1, len + 2, len + 3].into_iter().zip(m.mean_weights) {
                coefs[k] -= c;
            }
            for c in &mut coefs[2..len + 2] {
                *c += 1.0 / len as f64;
            }
            let var: f64 = coefs.iter().map(|c| c * c).sum();
            assert!((var.sqrt() - m.noise_gain).abs() < 1e-12, "len {len}");
        }
        assert!((RESIDUAL_GAIN - (1.0_f64 + 34.0 / 36.0).sqrt()).abs() < 1e-12);
    }

    #[test]
    fn a_five_sample_bump_on_a_noisy_tone_is_put_back_on_the_curve() {
        let clean = tone(2000, 700.0 / 44_100.0, 15.9);
        let n = clean.len();
        let mut x = noisy_tone(n, 700.0 / 44_100.0, 15.9, 0.02);
        let noisy = x.clone();
        // A bump of up to 3 µm over five samples, as a flake's rim read for a moment.
        for (k, d) in [1.0, 2.5, 3.0, 2.2, 0.8].into_iter().enumerate() {
            x[900 + k] += d;
        }
        let found = despike_bursts(&mut x, 8.0);
        assert_eq!(found.len(), 1, "{found:?}");
        let b = &found[0];
        assert!(b.start <= 900 && b.end >= 905, "{b:?}");
        for j in b.clone() {
            assert!(
                (x[j] - clean[j]).abs() < 0.1,
                "{j}: {} vs {}",
                x[j],
                clean[j]
            );
        }
        // Nothing outside it moved.
        let moved = (0..n)
            .filter(|&j| x[j] != noisy[j] && !b.contains(&j))
            .count();
        assert_eq!(moved, 0);
    }

    #[test]
    fn a_jittery_stretch_and_a_clean_track_are_left_alone() {
        // (Tones: `despike::tests::tones_pass_untouched`.) Eight samples of sample-to-sample jitter, ten times the track's noise: zero-mean,
        // which the low-pass removes, so no burst.
        let n = 1000;
        let mut x = noisy_tone(n, 0.01, 5.0, 0.02);
        for k in 0..8 {
            x[500 + k] += if k % 2 == 0 { 0.2 } else { -0.2 };
        }
        let b = despike_bursts(&mut x, 8.0);
        assert!(b.is_empty(), "jitter: {b:?}");
        let mut ramp: Vec<f64> = (0..500).map(|j| 0.37 * j as f64).collect();
        assert!(despike_bursts(&mut ramp, 8.0).is_empty());
    }

    #[test]
    fn gaps_ends_off_and_crowded_blocks_are_left_alone() {
        let n = 1000;
        let base = noisy_tone(n, 0.01, 3.0, 0.01);
        let bump = |x: &mut Vec<f64>, at: usize| {
            for k in 0..4 {
                x[at + k] += 2.0;
            }
        };
        let mut x = base.clone();
        bump(&mut x, 1); // at the start
        x[300] = f64::NAN;
        bump(&mut x, 302); // beside a gap
        bump(&mut x, n - 5); // at the end
        let before = x.clone();
        let b = despike_bursts(&mut x, 8.0);
        assert!(b.is_empty(), "ends and gaps: {b:?}");
        assert_eq!(format!("{x:?}"), format!("{before:?}"));
        // Off.
        let mut x = base.clone();
        bump(&mut x, 500);
        assert!(despike_bursts(&mut x, 0.0).is_empty());
        let found = despike_bursts(&mut x, 8.0);
        assert!(
            found.len() == 1 && found[0].start <= 500 && found[0].end >= 504,
            "{found:?}"
        );
        assert!((500..504).all(|j| (x[j] - base[j]).abs() < 0.05));
        // Five bumps in one block are motion, not outliers.
        let mut x = base.clone();
        for at in [520, 540, 560, 580, 600] {
            bump(&mut x, at);
        }
        assert!(despike_bursts(&mut x, 8.0).is_empty());
    }
}
