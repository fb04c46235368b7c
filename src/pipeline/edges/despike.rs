//! Isolated one-sample outliers taken out of a wall's displacement track before it is
//! differentiated.
//!
//! A fine fit that lands off for one sample (all of a sample's borders can move together, so the
//! robust combination of the four cannot see it) puts a step up and a step down into the
//! displacement; the differentiator turns that into a pair of opposite clicks, and on the
//! paper's optics a handful of them held most of a clip's error energy. Real groove motion is
//! smooth from sample to sample: the cutting stylus cannot move one sample and back.
//!
//! Each sample `x_j` is compared with the cubic through its two neighbours on each side,
//! `p_j = (−x_{j−2} + 4·x_{j−1} + 4·x_{j+1} − x_{j+2}) / 6`, whose response to a tone at ω
//! radians a sample is `(4·cos ω − cos 2ω)/3`: within 4% of the tone's displacement at 0.11 of
//! the sample rate (5 kHz at 44.1 kHz), so music leaves only a small residual, and that residual
//! is spread over every sample of a block. A spike of height δ leaves `r_j = x_j − p_j = δ` at
//! itself and −2δ/3 and δ/6 one and two samples away. So a sample is a spike where `|r_j|` is
//! the largest within two samples and exceeds `sigmas` times the robust scale
//! (1.4826·median |r|) of the residuals in its block of [`BLOCK`] samples and the blocks on
//! each side; it is replaced by `p_j`. A block with more than [`MAX_PER_BLOCK`] such samples is
//! left alone (the cubic does not follow a loud tone past about a fifth of the sample rate, and
//! that is sound, not outliers). Samples within four of a gap or an end are not checked.

/// Samples per block of the robust scale.
pub const BLOCK: usize = 128;

/// Smallest robust scale (µm): a noiseless track (synthetic, or a bridged stretch) has
/// residuals of rounding size only, which are not spikes.
pub(super) const MIN_SCALE_UM: f64 = 1e-3;

/// Most spikes a block may hold; more are not isolated outliers.
pub const MAX_PER_BLOCK: usize = 4;

/// The cubic prediction's residual at every sample (NaN where a neighbour is missing).
pub(super) fn residuals(x: &[f64]) -> Vec<f64> {
    let mut r = vec![f64::NAN; x.len()];
    for j in 2..x.len().saturating_sub(2) {
        let p = (-x[j - 2] + 4.0 * x[j - 1] + 4.0 * x[j + 1] - x[j + 2]) / 6.0;
        r[j] = x[j] - p;
    }
    r
}

/// The robust scale of the residuals per block: their robust σ over the block and its two
/// neighbours, floored at [`MIN_SCALE_UM`].
pub(super) fn block_scales(r: &[f64]) -> Vec<f64> {
    (0..r.len().div_ceil(BLOCK))
        .map(|b| {
            let lo = b.saturating_sub(1) * BLOCK;
            let hi = ((b + 2) * BLOCK).min(r.len());
            crate::pipeline::robust_sigma(&r[lo..hi], MIN_SCALE_UM)
        })
        .collect()
}

/// Replaces the isolated one-sample outliers of `x` (µm, NaN = gap) by the cubic through their
/// neighbours, as the module doc says; returns the samples replaced. `sigmas` ≤ 0 does nothing.
pub fn despike(x: &mut [f64], sigmas: f64) -> Vec<usize> {
    if sigmas <= 0.0 {
        return Vec::new();
    }
    let r = residuals(x);
    let scales = block_scales(&r);
    let candidates: Vec<usize> = (0..r.len())
        .filter(|&j| {
            // All five residuals within two samples must be known (a spike next to a gap shows
            // as its neighbour's), and the largest of them (the first of equals) is the centre.
            let near = j.saturating_sub(2)..(j + 3).min(r.len());
            near.len() == 5
                && near.clone().all(|k| r[k].is_finite())
                && near
                    .clone()
                    .reduce(|best, k| if r[k].abs() > r[best].abs() { k } else { best })
                    == Some(j)
                && r[j].abs() > sigmas * scales[j / BLOCK]
        })
        .collect();
    // A block with many is motion the cubic does not follow (a loud tone near the band's top),
    // not isolated outliers: it is left alone.
    let mut per_block = vec![0usize; scales.len()];
    for &j in &candidates {
        per_block[j / BLOCK] += 1;
    }
    let spikes: Vec<usize> = candidates
        .into_iter()
        .filter(|&j| per_block[j / BLOCK] <= MAX_PER_BLOCK)
        .collect();
    for &j in &spikes {
        x[j] -= r[j];
    }
    spikes
}

#[cfg(test)]
pub(super) mod tests {
    #![allow(clippy::unwrap_used)] // tests may panic
    use super::*;

    pub(crate) fn tone(n: usize, cycles_per_sample: f64, amp: f64) -> Vec<f64> {
        (0..n)
            .map(|j| amp * (std::f64::consts::TAU * cycles_per_sample * j as f64).sin())
            .collect()
    }

    /// A tone with [`noise`] of `a` on it.
    pub(crate) fn noisy_tone(n: usize, cycles_per_sample: f64, amp: f64, a: f64) -> Vec<f64> {
        tone(n, cycles_per_sample, amp)
            .iter()
            .zip(noise(n, a))
            .map(|(c, e)| c + e)
            .collect()
    }

    /// Deterministic noise in [−a, a].
    pub(crate) fn noise(n: usize, a: f64) -> Vec<f64> {
        let mut s = 0x9E37_79B9_7F4A_7C15_u64;
        (0..n)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                a * ((s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0)
            })
            .collect()
    }

    #[test]
    fn a_spike_on_a_noisy_tone_is_found_and_put_back_on_the_curve() {
        let n = 2000;
        let clean = tone(n, 500.0 / 44_100.0, 15.9);
        let mut x = noisy_tone(n, 500.0 / 44_100.0, 15.9, 0.02);
        let noisy = x.clone();
        for (j, d) in [(300, 0.4), (301 + 700, -0.3), (1500, 0.25)] {
            x[j] += d;
        }
        let found = despike(&mut x, 6.0);
        assert_eq!(found, [300, 1001, 1500]);
        for j in found {
            assert!(
                (x[j] - clean[j]).abs() < 0.03,
                "{j}: {} vs {}",
                x[j],
                clean[j]
            );
        }
        // Nothing else moved.
        let moved = (0..n).filter(|&j| x[j] != noisy[j]).count();
        assert_eq!(moved, 3);
    }

    #[test]
    fn tones_pass_untouched() {
        // Neither despike touches a tone up to 0.3 of the sample rate.
        for f in [0.01, 0.05, 0.113, 0.2, 0.25, 0.3] {
            let n = 3000;
            let mut x = noisy_tone(n, f, 2.0, 0.01);
            let before = x.clone();
            assert_eq!(despike(&mut x, 6.0), Vec::<usize>::new(), "f = {f}");
            // Nor are they short bursts.
            let bursts = super::super::bursts::despike_bursts(&mut x, 8.0);
            assert!(bursts.is_empty(), "f = {f}: {bursts:?}");
            assert_eq!(x, before);
        }
    }

    #[test]
    fn gaps_ends_and_a_clean_ramp_are_left_alone() {
        let mut ramp: Vec<f64> = (0..500).map(|j| 0.37 * j as f64).collect();
        assert!(despike(&mut ramp, 4.0).is_empty());
        let mut x = tone(400, 0.01, 3.0);
        x[3] += 5.0; // within four of the start
        x[200] = f64::NAN;
        x[202] += 5.0; // within four of a gap
        x[396] += 5.0; // and of the end
        let before = x.clone();
        assert!(despike(&mut x, 4.0).is_empty());
        assert_eq!(format!("{x:?}"), format!("{before:?}"));
        assert!(despike(&mut x, 0.0).is_empty());
    }
}
