//! How much more the borders scatter from sample to sample than their fits' standard errors say: the factor by which the fused decoder may raise the edge noise level.
//!
//! The combined displacement's variance comes from the border fits' standard errors, which
//! understate the edges' noise on a blurred, textured camera (the small dual-focus camera's
//! speech reads far noisier edges than those errors say). The borders' disagreement about the
//! combined solution measures it, but not all of it: borders read through different blurs
//! disagree slowly and in step with a loud passage, and that part is not noise in the combined
//! displacement. So each border's residual is taken as its second difference,
//! `(r_j − (r_{j−1} + r_{j+1})/2)/√1.5` (for white residuals the same variance, for a slow
//! disagreement nearly zero), and each sample's reduced χ² of those over the borders the robust
//! solve keeps (relative weight at least [`KEPT_WEIGHT`]) is averaged over
//! ±[`HALF_WINDOW`] samples and floored at 1. A border that glitches for a few samples raises
//! the stretch around it.

/// A border counts in the scatter only where the robust solve keeps at least this share of
/// its plain weight (a rejected border's disagreement is not in the combined displacement).
pub const KEPT_WEIGHT: f64 = 0.5;
/// Samples on each side over which the reduced χ² is averaged.
pub const HALF_WINDOW: usize = 16;

/// The scatter factor of each of `n` samples (1 where nothing says more). `residual(b, j)` is
/// border `b`'s residual about sample `j`'s solution (µm, NaN where not seen), `weight(b, j)`
/// its weight `1/se²` in the solve and `rel[j][b]` its relative weight after the robust
/// reweighting; `params` is the number of unknowns each sample solves for (1 laterally, else 2).
pub fn scatter_factors(
    n: usize,
    residual: &dyn Fn(usize, usize) -> f64,
    weight: &dyn Fn(usize, usize) -> Option<f64>,
    rel: &[[f64; 4]],
    params: usize,
) -> Vec<f64> {
    let row = |j: usize| -> [f64; 4] { std::array::from_fn(|b| residual(b, j)) };
    let mut chi = vec![f64::NAN; n];
    // Each sample's residuals are read once, three rows held at a time (a whole side's clip
    // has tens of millions of samples).
    if n >= 3 {
        let (mut prev, mut here) = (row(0), row(1));
        for (j, c) in chi.iter_mut().enumerate().take(n - 1).skip(1) {
            let next = row(j + 1);
            let (mut sum, mut kept) = (0.0, 0usize);
            for b in 0..4 {
                let (Some(w), Some(r)) = (weight(b, j), rel.get(j).map(|r| r[b])) else {
                    continue;
                };
                let s = (here[b] - 0.5 * (prev[b] + next[b])) / 1.5f64.sqrt();
                if s.is_finite() && r >= KEPT_WEIGHT {
                    sum += w * r * s * s;
                    kept += 1;
                }
            }
            if kept > params {
                *c = sum / (kept - params) as f64;
            }
            (prev, here) = (here, next);
        }
    }
    // At least 1; where no sample nearby has a χ² (a NaN mean), 1.
    let mut factors = crate::pipeline::finite_window_means(&chi, HALF_WINDOW);
    for f in &mut factors {
        *f = f.max(1.0);
    }
    factors
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Four equally weighted borders (weight 1/σ², σ = 0.1 µm) whose residuals are `r(b, j)`.
    fn factors(r: &dyn Fn(usize, usize) -> f64, n: usize) -> Vec<f64> {
        let rel = vec![[1.0; 4]; n];
        scatter_factors(n, r, &|_, _| Some(100.0), &rel, 1)
    }

    #[test]
    fn white_scatter_at_its_stated_level_reads_one_and_ten_times_it_reads_about_a_hundred() {
        let mut rng = crate::synth::noise::Rng::new(7);
        let noise: Vec<f64> = (0..4 * 4000).map(|_| rng.gaussian()).collect();
        // Each border's residual about the mean of the four (what a lateral solve leaves).
        let resid = |scale: f64| {
            let noise = noise.clone();
            move |b: usize, j: usize| {
                let mean: f64 = (0..4).map(|k| noise[4 * j + k]).sum::<f64>() / 4.0;
                scale * (noise[4 * j + b] - mean)
            }
        };
        let at = |f: &[f64]| f.iter().sum::<f64>() / f.len() as f64;
        let stated = factors(&resid(0.1), 4000);
        assert!(at(&stated) < 1.2, "{}", at(&stated));
        let ten = factors(&resid(1.0), 4000);
        assert!((70.0..130.0).contains(&at(&ten)), "{}", at(&ten));
    }

    #[test]
    fn a_slow_disagreement_does_not_count_and_a_glitch_raises_only_its_stretch() {
        // Borders that disagree by 1 µm (10 σ), slowly (a 200-sample period).
        let slow = |b: usize, j: usize| {
            let s = (j as f64 * std::f64::consts::TAU / 200.0).sin();
            if b < 2 { s } else { -s }
        };
        assert!(factors(&slow, 1000).iter().all(|&f| f < 1.01));
        // One border off by 5 µm (50 σ) at sample 500.
        let glitch = |b: usize, j: usize| if b == 0 && j == 500 { 5.0 } else { 0.0 };
        let f = factors(&glitch, 1000);
        assert!(f[500] > 20.0 && f[500 - HALF_WINDOW] > 20.0, "{}", f[500]);
        assert_eq!(f[500 - HALF_WINDOW - 2], 1.0);
        assert_eq!(f[500 + HALF_WINDOW + 2], 1.0);
        // Where the robust solve rejects that border, its glitch does not count.
        let rel: Vec<[f64; 4]> = (0..1000)
            .map(|j| {
                if (499..=501).contains(&j) {
                    [0.2, 1.0, 1.0, 1.0]
                } else {
                    [1.0; 4]
                }
            })
            .collect();
        let g = scatter_factors(1000, &glitch, &|_, _| Some(100.0), &rel, 1);
        assert!(g.iter().all(|&x| x == 1.0));
    }
}
