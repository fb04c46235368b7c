//! The two estimators' noise spectra from the spectrum of their difference: edge noise flat in
//! displacement (so `a·ω²` in velocity); flow error flat in velocity (`b`) plus a share of the
//! signal itself (`c·|S|²`).
//!
//! Both methods read the same groove, so their difference holds only their errors:
//! `E|F − E|² = N_flow + N_edge(ω)` with the two independent. Measured on the paper's optics,
//! the flow's error is not flat: it rises where the signal is, because the tilt reading
//! under-reads and smears the wall's motion (its window and the robust fit low-pass it), while
//! the edges' scale is fixed by the pixel pitch and a differentiator within 0.3 dB of iω. So
//! the model is `N = b + a·ω² + c·|S(ω)|²` (ω in radians per sample, `|S|²` the smoothed
//! geometric mean of the two estimates' periodograms, which counts either one's noise at half
//! its decibels), and disagreement that follows the signal counts as flow error. The
//! three levels are the weighted least squares fit to the smoothed periodogram of the
//! difference, each bin weighted by `1/model²` (a periodogram's spread grows with its mean) and
//! by a Lorentzian of its relative residual, none negative (the best fit over the subsets of
//! levels held at zero). The crossover is where the flat parts are equal, `ω_c = √(b/a)`.

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
    /// Flow error power per unit of signal power (its signal-following part).
    pub flow_gain: f64,
}

impl NoiseModel {
    /// Edge noise power at `omega`.
    #[must_use]
    pub fn edge_at(&self, omega: f64) -> f64 {
        self.edge * omega * omega
    }

    /// Flow error power at a bin of signal power `signal`.
    #[must_use]
    pub fn flow_at(&self, signal: f64) -> f64 {
        self.flow + self.flow_gain * signal
    }

    /// The Wiener weight of the edge estimate at `omega` where the signal power is `signal`:
    /// `N_flow/(N_flow + N_edge)` (0.5 when both are zero).
    #[must_use]
    pub fn edge_weight(&self, omega: f64, signal: f64) -> f64 {
        let (f, e) = (self.flow_at(signal), self.edge_at(omega));
        if f + e > 0.0 { f / (f + e) } else { 0.5 }
    }

    /// Crossover frequency (rad/sample) where the flat flow noise and the edge noise are equal;
    /// 0 when edges never win, π when flow never wins (capped at Nyquist).
    #[must_use]
    pub fn crossover_rad(&self) -> f64 {
        if self.edge <= 0.0 {
            std::f64::consts::PI
        } else {
            (self.flow / self.edge).sqrt().min(std::f64::consts::PI)
        }
    }
}

/// Weighted least squares of `p ≈ Σ levels[k]·basis[k]` over the levels in `active` (the
/// others held at zero); None when singular.
fn solve(rows: &[([f64; 3], f64, f64)], active: [bool; 3]) -> Option<[f64; 3]> {
    let idx: Vec<usize> = (0..3).filter(|&k| active[k]).collect();
    let m = idx.len();
    let mut a = [[0.0; 4]; 3];
    for (basis, p, w) in rows {
        for (i, &ki) in idx.iter().enumerate() {
            for (j, &kj) in idx.iter().enumerate() {
                a[i][j] += w * basis[ki] * basis[kj];
            }
            a[i][3] += w * basis[ki] * p;
        }
    }
    // Gauss–Jordan with partial pivoting on the m×m system.
    for col in 0..m {
        let piv = (col..m).max_by(|&x, &y| a[x][col].abs().total_cmp(&a[y][col].abs()))?;
        if a[piv][col].abs() < 1e-300 {
            return None;
        }
        a.swap(col, piv);
        for row in 0..m {
            if row != col {
                let f = a[row][col] / a[col][col];
                let pivot_row = a[col];
                for (v, p) in a[row].iter_mut().zip(pivot_row).skip(col) {
                    *v -= f * p;
                }
            }
        }
    }
    let mut out = [0.0; 3];
    for (i, &k) in idx.iter().enumerate() {
        out[k] = a[i][3] / a[i][i];
    }
    Some(out)
}

/// The best non-negative levels: every subset of the free levels tried (`fixed` ones held at
/// zero; the caller took their part out of the powers), the feasible fit with the least
/// weighted squared residual kept.
fn fit_levels(rows: &[([f64; 3], f64, f64)], fixed: [bool; 3]) -> [f64; 3] {
    let mut best: Option<([f64; 3], f64)> = None;
    for mask in 1..8u8 {
        let active = [mask & 1 != 0, mask & 2 != 0, mask & 4 != 0];
        if (0..3).any(|k| active[k] && fixed[k]) {
            continue;
        }
        let Some(levels) = solve(rows, active) else {
            continue;
        };
        if levels.iter().any(|&l| l < 0.0 || !l.is_finite()) {
            continue;
        }
        let cost: f64 = rows
            .iter()
            .map(|(b, p, w)| {
                let m: f64 = b.iter().zip(&levels).map(|(x, l)| x * l).sum();
                w * (p - m).powi(2)
            })
            .sum();
        if best.is_none_or(|(_, c)| cost < c) {
            best = Some((levels, cost));
        }
    }
    best.map_or([0.0; 3], |b| b.0)
}

/// Fits the model to a difference power spectrum `power[k]` at `omega[k]`, with the signal
/// power `signal[k]` there (the caller's estimate) (bins with a zero or non-finite power are skipped). With
/// `edge` given (the edge noise level `a`, known from the border fits' standard errors) only the
/// flow's levels are fitted, to what the edge noise leaves of the difference: a rising
/// difference is then the flow's. None when fewer than three bins are usable.
#[must_use]
pub fn fit_noise(
    omega: &[f64],
    power: &[f64],
    signal: &[f64],
    edge: Option<f64>,
) -> Option<NoiseModel> {
    let known = edge.filter(|a| a.is_finite() && *a >= 0.0);
    let bins: Vec<([f64; 3], f64)> = omega
        .iter()
        .zip(power)
        .zip(signal)
        .filter(|((w, p), s)| w.is_finite() && p.is_finite() && **p > 0.0 && s.is_finite())
        .map(|((&w, &p), &s)| ([1.0, w * w, s.max(0.0)], p))
        .collect();
    if bins.len() < 3 {
        return None;
    }
    let mean_power = bins.iter().map(|b| b.1).sum::<f64>() / bins.len() as f64;
    let mut weights = vec![1.0; bins.len()];
    let mut model = NoiseModel {
        flow: 0.0,
        edge: 0.0,
        flow_gain: 0.0,
    };
    for round in 0..ROUNDS {
        let rows: Vec<([f64; 3], f64, f64)> = bins
            .iter()
            .zip(&weights)
            .map(|(&(b, p), &w)| (b, p, w))
            .collect();
        let [b, a, c] = match known {
            Some(a) => {
                let rest: Vec<([f64; 3], f64, f64)> = rows
                    .iter()
                    .map(|&(basis, p, w)| (basis, p - a * basis[1], w))
                    .collect();
                let [b, _, c] = fit_levels(&rest, [false, true, false]);
                [b, a, c]
            }
            None => fit_levels(&rows, [false; 3]),
        };
        model = NoiseModel {
            flow: b,
            edge: a,
            flow_gain: c,
        };
        if round + 1 == ROUNDS {
            break;
        }
        for (w, (basis, p)) in weights.iter_mut().zip(&bins) {
            let m = (model.flow + model.edge * basis[1] + model.flow_gain * basis[2])
                .max(1e-12 * mean_power);
            // Lorentzian on the relative residual: a bin far above the model stops counting.
            *w = lorentzian_weight(p / m - 1.0, REL_SIGMA) / (m * m);
        }
    }
    // With the edge level known, a fit that leaves the flow no noise at all says the difference
    // is smaller than the edge noise alone would make it: the fits' standard errors overstate
    // it here, and this block cannot split the two.
    if known.is_some() && model.flow <= 0.0 && model.flow_gain <= 0.0 {
        return None;
    }
    Some(model)
}

/// [`fit_noise`] with the edge level known twice: `fitted` from the border fits' standard
/// errors, `scattered` raised by how much more the borders scatter from sample to sample. The
/// fit takes the scattered level where the model with the fitted one leaves the flow's flat
/// noise at or below the edges' at Nyquist (the two readings are within reach of each other
/// somewhere in the band), else the fitted one. Where the edges win at every frequency by
/// their fits' own errors (the sharp optics, where the flow reads 15–25 dB worse), a stretch
/// where a border glitches would otherwise hand the flow bands it reads far worse
/// (docs/ACCURACY.md).
#[must_use]
pub fn fit_with_scatter(
    omega: &[f64],
    power: &[f64],
    signal: &[f64],
    fitted: Option<f64>,
    scattered: Option<f64>,
) -> Option<NoiseModel> {
    let plain = fit_noise(omega, power, signal, fitted);
    let (Some(model), Some(raised)) = (plain, scattered) else {
        return plain;
    };
    let nyquist = std::f64::consts::PI;
    if raised <= model.edge || model.flow > model.edge_at(nyquist) {
        return plain;
    }
    fit_noise(omega, power, signal, Some(raised)).or(plain)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;

    /// The angular frequencies (rad/sample) of bins 1 to `n − 1` of a `2n`-point spectrum.
    fn bin_frequencies(n: usize) -> Vec<f64> {
        (1..n)
            .map(|k| std::f64::consts::PI * k as f64 / n as f64)
            .collect()
    }

    #[test]
    fn recovers_both_levels_and_ignores_a_tone_peak() {
        let omega = bin_frequencies(128);
        let mut power: Vec<f64> = omega
            .iter()
            .enumerate()
            .map(|(k, w)| {
                // A deterministic ±30% ripple, as a smoothed periodogram has.
                let ripple = 1.0 + 0.3 * ((k * 37 % 11) as f64 / 5.0 - 1.0);
                (2.0 + 8.0 * w * w) * ripple
            })
            .collect();
        power[20] *= 500.0; // a stray bin
        let signal = vec![0.0; omega.len()];
        let m = fit_noise(&omega, &power, &signal, None).unwrap();
        assert!((m.flow - 2.0).abs() < 0.4, "{m:?}");
        assert!((m.edge - 8.0).abs() < 1.6, "{m:?}");
        let wc = m.crossover_rad();
        assert!((wc - 0.5).abs() < 0.1, "{wc}");
        assert!((m.edge_weight(wc, 0.0) - 0.5).abs() < 1e-9);
        assert!(m.edge_weight(0.01, 0.0) > 0.99 && m.edge_weight(3.0, 0.0) < 0.1);
    }

    #[test]
    fn disagreement_that_follows_the_signal_is_the_flows() {
        // A tone at bin 20 that the flow reads 10% low: its difference power is 1% of the
        // signal's there, on top of both noises.
        let omega = bin_frequencies(128);
        let mut signal = vec![0.5; omega.len()];
        signal[20] = 1e6;
        let power: Vec<f64> = omega
            .iter()
            .zip(&signal)
            .map(|(w, s)| 2.0 + 8.0 * w * w + 0.01 * s)
            .collect();
        let m = fit_noise(&omega, &power, &signal, None).unwrap();
        assert!((m.flow_gain - 0.01).abs() < 1e-3, "{m:?}");
        assert!(
            (m.flow - 2.0).abs() < 0.3 && (m.edge - 8.0).abs() < 1.0,
            "{m:?}"
        );
        // At the tone the edges win outright; away from it the flat levels decide.
        assert!(m.edge_weight(omega[20], signal[20]) > 0.999);
        assert!(m.edge_weight(3.0, signal[100]) < 0.2);
        // With the edge level known, a difference that rises is the flow's.
        let rising: Vec<f64> = omega.iter().map(|w| 0.1 * w * w + 5.0 * w * w).collect();
        let none = vec![0.0; omega.len()];
        let k = fit_noise(&omega, &rising, &none, Some(0.1)).unwrap();
        assert!((k.edge - 0.1).abs() < 1e-12 && k.flow > 1.0, "{k:?}");
        assert!(k.edge_weight(3.0, 0.0) > 0.7, "{k:?}");
    }

    #[test]
    fn the_scattered_edge_level_is_taken_only_where_the_flow_is_within_reach() {
        let omega = bin_frequencies(128);
        let none = vec![0.0; omega.len()];
        let spectrum =
            |flat: f64| -> Vec<f64> { omega.iter().map(|w| flat + 2.0 * w * w).collect() };
        // The edges' noise is twice what their fits say, and the flow's flat noise (1) is below
        // the edges' at Nyquist: the scattered level is taken, and the flow's is what is left.
        let near = fit_with_scatter(&omega, &spectrum(1.0), &none, Some(1.0), Some(2.0)).unwrap();
        assert!(
            (near.edge - 2.0).abs() < 1e-12 && (near.flow - 1.0).abs() < 0.05,
            "{near:?}"
        );
        let plain = fit_noise(&omega, &spectrum(1.0), &none, Some(1.0)).unwrap();
        assert!(plain.flow > 2.0, "{plain:?}");
        // A flow 30 times noisier: by the fits' own level the edges win at every frequency, so
        // their level stays.
        let far = fit_with_scatter(&omega, &spectrum(30.0), &none, Some(1.0), Some(2.0)).unwrap();
        assert!((far.edge - 1.0).abs() < 1e-12, "{far:?}");
        // No scatter above the fitted level, or none known: the plain fit.
        for scattered in [Some(0.5), Some(1.0), None] {
            let m = fit_with_scatter(&omega, &spectrum(1.0), &none, Some(1.0), scattered);
            assert_eq!(m, Some(plain));
        }
    }

    #[test]
    fn one_sided_noise_gives_a_clean_choice() {
        let omega: Vec<f64> = (1..64).map(|k| k as f64 * 0.05).collect();
        let flat: Vec<f64> = omega.iter().map(|_| 3.0).collect();
        let none = vec![0.0; omega.len()];
        let m = fit_noise(&omega, &flat, &none, None).unwrap();
        assert!(m.edge < 1e-6 && (m.flow - 3.0).abs() < 1e-6, "{m:?}");
        assert_eq!(m.crossover_rad(), std::f64::consts::PI);
        assert!(fit_noise(&omega[..2], &flat[..2], &none[..2], None).is_none());
    }
}
