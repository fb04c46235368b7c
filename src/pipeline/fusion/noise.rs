//! The two estimators' noise spectra from the spectrum of their difference: edge noise flat in
//! displacement (so `a·ω²` in velocity), flow noise flat in velocity (`b`).
//!
//! Both methods read the same groove, so their difference holds only their noises:
//! `E|F − E|² = N_flow + N_edge(ω)` with the two independent. With the model
//! `N = b + a·ω²` (ω in radians per sample) the two levels are the weighted least squares fit to
//! the smoothed periodogram of the difference, each bin weighted by `1/model²` (a periodogram's
//! spread grows with its mean) and by a Lorentzian of its relative residual, so bins where the
//! two methods differ in the signal itself (a tone both read with slightly different gain) do
//! not pass for noise. The crossover is where the two noises are equal, `ω_c = √(b/a)`.

use crate::pipeline::edges::profile::lorentzian_weight;

/// Reweighting rounds of the fit.
const ROUNDS: usize = 6;
/// Lorentzian σ of a bin's relative residual `p/model − 1` (a smoothed periodogram's spread is
/// below 1).
const REL_SIGMA: f64 = 1.0;

/// The noise levels of one analysis block.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NoiseModel {
    /// Flow noise power per bin (flat).
    pub flow: f64,
    /// Edge noise power per bin at ω = 1 rad/sample (it grows as ω²).
    pub edge: f64,
}

impl NoiseModel {
    /// Edge noise power at `omega`.
    #[must_use]
    pub fn edge_at(&self, omega: f64) -> f64 {
        self.edge * omega * omega
    }

    /// The Wiener weight of the edge estimate at `omega`: `N_flow/(N_flow + N_edge)`
    /// (0.5 when both are zero).
    #[must_use]
    pub fn edge_weight(&self, omega: f64) -> f64 {
        let (f, e) = (self.flow, self.edge_at(omega));
        if f + e > 0.0 { f / (f + e) } else { 0.5 }
    }

    /// Crossover frequency (rad/sample) where both noises are equal; 0 when edges never win,
    /// π when flow never wins (capped at Nyquist).
    #[must_use]
    pub fn crossover_rad(&self) -> f64 {
        if self.edge <= 0.0 {
            std::f64::consts::PI
        } else {
            (self.flow / self.edge).sqrt().min(std::f64::consts::PI)
        }
    }
}

/// Fits the model to a difference power spectrum `power[k]` at `omega[k]` (bins with a zero or
/// non-finite power are skipped). None when fewer than three bins are usable.
#[must_use]
pub fn fit_noise(omega: &[f64], power: &[f64]) -> Option<NoiseModel> {
    let bins: Vec<(f64, f64)> = omega
        .iter()
        .zip(power)
        .filter(|(w, p)| w.is_finite() && p.is_finite() && **p > 0.0)
        .map(|(&w, &p)| (w * w, p))
        .collect();
    if bins.len() < 3 {
        return None;
    }
    let mut model = NoiseModel {
        flow: 0.0,
        edge: 0.0,
    };
    let mut weights = vec![1.0; bins.len()];
    let mean_power = bins.iter().map(|b| b.1).sum::<f64>() / bins.len() as f64;
    for round in 0..ROUNDS {
        // Weighted least squares of p ≈ b + a·x with x = ω².
        let (mut s00, mut s01, mut s11, mut t0, mut t1) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for (&(x, p), &w) in bins.iter().zip(&weights) {
            s00 += w;
            s01 += w * x;
            s11 += w * x * x;
            t0 += w * p;
            t1 += w * x * p;
        }
        let det = s00 * s11 - s01 * s01;
        let (mut b, mut a) = if det > 1e-300 {
            ((t0 * s11 - t1 * s01) / det, (t1 * s00 - t0 * s01) / det)
        } else {
            (t0 / s00.max(1e-300), 0.0)
        };
        // Both levels are powers: refit with one of them at zero when the other goes negative.
        if a < 0.0 {
            a = 0.0;
            b = t0 / s00.max(1e-300);
        }
        if b < 0.0 {
            b = 0.0;
            a = t1 / s11.max(1e-300);
        }
        model = NoiseModel {
            flow: b.max(0.0),
            edge: a.max(0.0),
        };
        if round + 1 == ROUNDS {
            break;
        }
        for (w, &(x, p)) in weights.iter_mut().zip(&bins) {
            let m = (model.flow + model.edge * x).max(1e-12 * mean_power);
            // Lorentzian on the relative residual: a bin far above the model stops counting.
            *w = lorentzian_weight(p / m - 1.0, REL_SIGMA) / (m * m);
        }
    }
    Some(model)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;

    #[test]
    fn recovers_both_levels_and_ignores_a_tone_peak() {
        let n = 128;
        let omega: Vec<f64> = (1..n)
            .map(|k| std::f64::consts::PI * k as f64 / n as f64)
            .collect();
        let mut power: Vec<f64> = omega
            .iter()
            .enumerate()
            .map(|(k, w)| {
                // A deterministic ±30% ripple, as a smoothed periodogram has.
                let ripple = 1.0 + 0.3 * ((k * 37 % 11) as f64 / 5.0 - 1.0);
                (2.0 + 8.0 * w * w) * ripple
            })
            .collect();
        power[20] *= 500.0; // a tone the two methods read differently
        let m = fit_noise(&omega, &power).unwrap();
        assert!((m.flow - 2.0).abs() < 0.4, "{m:?}");
        assert!((m.edge - 8.0).abs() < 1.6, "{m:?}");
        let wc = m.crossover_rad();
        assert!((wc - 0.5).abs() < 0.1, "{wc}");
        assert!((m.edge_weight(wc) - 0.5).abs() < 1e-9);
        assert!(m.edge_weight(0.01) > 0.99 && m.edge_weight(3.0) < 0.1);
    }

    #[test]
    fn one_sided_noise_gives_a_clean_choice() {
        let omega: Vec<f64> = (1..64).map(|k| k as f64 * 0.05).collect();
        let flat: Vec<f64> = omega.iter().map(|_| 3.0).collect();
        let m = fit_noise(&omega, &flat).unwrap();
        assert!(m.edge < 1e-6 && (m.flow - 3.0).abs() < 1e-6, "{m:?}");
        assert_eq!(m.crossover_rad(), std::f64::consts::PI);
        assert!(fit_noise(&omega[..2], &flat[..2]).is_none());
    }
}
