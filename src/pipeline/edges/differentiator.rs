//! The designed differentiator that turns border displacement into velocity: least-squares FIR
//! filters, centred inside a track and one-sided next to its ends and gaps.
//!
//! A filter `y_j = Σ_n c_n·x_{j+n}` (taps `n ∈ [−a, b]`) has the response `H(ω) = Σ c_n·e^{iωn}`
//! (ω in radians per sample). It is designed to approach `D(ω) = iω / A(ω)` over the band
//! `0 < ω ≤ band·π`, where `A(ω) = sin(ωq/2)/(ωq/2)` is the response of the box average over
//! `q` samples that each border sample already is (`aperture_samples`; 0 = none): weighted least
//! squares of `|H − D|²/ω` over `DESIGN_POINTS` frequencies (the `1/ω` weight spends the taps
//! on the relative error, which is what a dB bar measures), with a small ridge `ridge·Σc²`,
//! subject to `Σc = 0` and `Σn·c_n = 1` (no response to a constant, the exact slope of a
//! ramp). With `a = b` the solution is antisymmetric: a pure, zero-delay differentiator. A
//! one-sided filter cannot reach as high: its band shrinks to
//! `band·(2·min(a, b) + 2)/(2·half_taps + 1)`, above which it rolls off instead of ringing.
//! A border's noise is flat in displacement, so the filter's noise gain `Σc²` ([`noise_gain`])
//! sets the velocity noise.

use std::sync::{Mutex, PoisonError};

use serde::{Deserialize, Serialize};

use crate::pipeline::{StageError, check_range};

/// Frequencies of the design grid over the band.
const DESIGN_POINTS: usize = 160;

/// Knobs of the differentiator.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DifferentiatorParams {
    #[doc = knob!("edges.differentiator.half_taps")]
    pub half_taps: usize,
    #[doc = knob!("edges.differentiator.band")]
    pub band: f64,
    #[doc = knob!("edges.differentiator.aperture_samples")]
    pub aperture_samples: f64,
    #[doc = knob!("edges.differentiator.ridge")]
    pub ridge: f64,
    #[doc = knob!("edges.differentiator.min_run")]
    pub min_run: usize,
}

impl Default for DifferentiatorParams {
    fn default() -> Self {
        Self {
            half_taps: 6,
            band: 0.8,
            aperture_samples: 1.0,
            ridge: 1e-4,
            min_run: 3,
        }
    }
}

impl DifferentiatorParams {
    /// Checks every knob; `prefix` names the TOML table.
    ///
    /// # Errors
    /// [`StageError::InvalidParam`] naming the first bad key.
    pub fn validate(&self, prefix: &str) -> Result<(), StageError> {
        let key = |k: &str| format!("{prefix}.{k}");
        if !(1..=32).contains(&self.half_taps) {
            return Err(StageError::InvalidParam {
                name: key("half_taps"),
                problem: format!("{} is not in [1, 32]", self.half_taps),
            });
        }
        check_range(&key("band"), self.band, 0.05, 0.99)?;
        check_range(&key("aperture_samples"), self.aperture_samples, 0.0, 4.0)?;
        check_range(&key("ridge"), self.ridge, 0.0, 1e6)?;
        if self.min_run < 2 {
            return Err(StageError::InvalidParam {
                name: key("min_run"),
                problem: format!(
                    "{} is below 2 (a derivative needs two samples)",
                    self.min_run
                ),
            });
        }
        Ok(())
    }
}

/// A designed filter: taps for offsets `−before ..= after`.
#[derive(Clone, Debug, PartialEq)]
pub struct Taps {
    /// Samples read before the output sample.
    pub before: usize,
    /// Samples read after it.
    pub after: usize,
    /// `c_{−before}, …, c_{after}`.
    pub coefficients: Vec<f64>,
}

impl Taps {
    /// The complex response at `omega` (rad/sample): (re, im).
    #[must_use]
    pub fn response(&self, omega: f64) -> (f64, f64) {
        let mut re = 0.0;
        let mut im = 0.0;
        for (k, &c) in self.coefficients.iter().enumerate() {
            let n = k as f64 - self.before as f64;
            re += c * (omega * n).cos();
            im += c * (omega * n).sin();
        }
        (re, im)
    }
}

/// The box average's response `sin(ωq/2)/(ωq/2)`.
fn aperture(omega: f64, q: f64) -> f64 {
    let x = 0.5 * omega * q;
    if x.abs() < 1e-9 { 1.0 } else { x.sin() / x }
}

/// Solves `a·x = b` (n×n, row-major) by Gaussian elimination with partial pivoting.
fn solve(mut a: Vec<f64>, mut b: Vec<f64>, n: usize) -> Option<Vec<f64>> {
    for col in 0..n {
        let pivot =
            (col..n).max_by(|&i, &j| a[i * n + col].abs().total_cmp(&a[j * n + col].abs()))?;
        if a[pivot * n + col].abs() < 1e-300 {
            return None;
        }
        if pivot != col {
            for k in 0..n {
                a.swap(col * n + k, pivot * n + k);
            }
            b.swap(col, pivot);
        }
        for row in col + 1..n {
            let f = a[row * n + col] / a[col * n + col];
            if f != 0.0 {
                for k in col..n {
                    a[row * n + k] -= f * a[col * n + k];
                }
                b[row] -= f * b[col];
            }
        }
    }
    let mut x = vec![0.0; n];
    for row in (0..n).rev() {
        let mut s = b[row];
        for k in row + 1..n {
            s -= a[row * n + k] * x[k];
        }
        x[row] = s / a[row * n + row];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// Designs the filter with taps `−before ..= after` (see the module docs).
#[must_use]
pub fn design(before: usize, after: usize, params: &DifferentiatorParams) -> Option<Taps> {
    let n = before + after + 1;
    if n < 2 {
        return None;
    }
    let offsets: Vec<f64> = (0..n).map(|k| k as f64 - before as f64).collect();
    // The normal equations bordered by the two constraints (a KKT system of n + 2 unknowns).
    let m = n + 2;
    let mut kkt = vec![0.0; m * m];
    let mut rhs = vec![0.0; m];
    let shortest = before.min(after);
    let band = if before == after {
        params.band
    } else {
        params.band * (2 * shortest + 2) as f64 / (2 * params.half_taps + 1) as f64
    };
    let top = band.min(params.band) * std::f64::consts::PI;
    for i in 1..=DESIGN_POINTS {
        let omega = top * i as f64 / DESIGN_POINTS as f64;
        let target = omega / aperture(omega, params.aperture_samples);
        let weight = 1.0 / omega;
        // Real part: Σ c cos(ωn) → 0; imaginary part: Σ c sin(ωn) → target.
        let cos: Vec<f64> = offsets.iter().map(|&o| (omega * o).cos()).collect();
        let sin: Vec<f64> = offsets.iter().map(|&o| (omega * o).sin()).collect();
        for r in 0..n {
            for c in 0..n {
                kkt[r * m + c] += weight * (cos[r] * cos[c] + sin[r] * sin[c]);
            }
            rhs[r] += weight * sin[r] * target;
        }
    }
    let ridge = params.ridge * DESIGN_POINTS as f64 / top;
    for (r, &o) in offsets.iter().enumerate() {
        kkt[r * m + r] += ridge;
        kkt[r * m + n] = 1.0;
        kkt[n * m + r] = 1.0;
        kkt[r * m + n + 1] = o;
        kkt[(n + 1) * m + r] = o;
    }
    rhs[n + 1] = 1.0;
    let mut solution = solve(kkt, rhs, m)?;
    solution.truncate(n);
    Some(Taps {
        before,
        after,
        coefficients: solution,
    })
}

/// Σc², the factor by which the filter multiplies white input noise power.
#[must_use]
pub fn noise_gain(taps: &Taps) -> f64 {
    taps.coefficients.iter().map(|c| c * c).sum()
}

/// What a design depends on: the taps before and after, and the bits of the params' design
/// knobs (`half_taps`, `band`, `aperture_samples`, `ridge`).
type DesignKey = (usize, usize, usize, u64, u64, u64);

/// Designs made so far in this process. A design is a pure function of its key and every group
/// of a scan asks for the same few (the centred filter and the one-sided ones at run ends), so
/// each is solved once; the list is cleared if it ever holds [`MAX_KEPT_DESIGNS`].
static DESIGNS: Mutex<Vec<(DesignKey, Option<Taps>)>> = Mutex::new(Vec::new());

/// Most designs [`DESIGNS`] keeps (all one-sided variants of a few parameter sets).
const MAX_KEPT_DESIGNS: usize = 4096;

/// [`design`], remembered in [`DESIGNS`].
fn remembered_design(before: usize, after: usize, params: &DifferentiatorParams) -> Option<Taps> {
    let key = (
        before,
        after,
        params.half_taps,
        params.band.to_bits(),
        params.aperture_samples.to_bits(),
        params.ridge.to_bits(),
    );
    {
        let kept = DESIGNS.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some((_, taps)) = kept.iter().find(|(k, _)| *k == key) {
            return taps.clone();
        }
    }
    let taps = design(before, after, params);
    let mut kept = DESIGNS.lock().unwrap_or_else(PoisonError::into_inner);
    if kept.len() >= MAX_KEPT_DESIGNS {
        kept.clear();
    }
    if !kept.iter().any(|(k, _)| *k == key) {
        kept.push((key, taps.clone()));
    }
    taps
}

/// The derivative (per sample) of `track` at every sample: the centred filter where it fits
/// inside the run of finite samples, else the one-sided filter the run allows. NaN samples,
/// and runs shorter than `min_run`, give NaN.
#[must_use]
pub fn differentiate(track: &[f64], params: &DifferentiatorParams) -> Vec<f64> {
    let m = params.half_taps;
    let mut cache: Vec<((usize, usize), Option<Taps>)> = Vec::new();
    let mut out = vec![f64::NAN; track.len()];
    let mut start = 0;
    while start < track.len() {
        if !track[start].is_finite() {
            start += 1;
            continue;
        }
        let end = track[start..]
            .iter()
            .position(|v| !v.is_finite())
            .map_or(track.len(), |p| start + p);
        if end - start >= params.min_run.max(2) {
            for j in start..end {
                let key = ((j - start).min(m), (end - 1 - j).min(m));
                let idx = match cache.iter().position(|(k, _)| *k == key) {
                    Some(i) => i,
                    None => {
                        cache.push((key, remembered_design(key.0, key.1, params)));
                        cache.len() - 1
                    }
                };
                if let Some((_, Some(taps))) = cache.get(idx) {
                    let lo = j - taps.before;
                    out[j] = taps
                        .coefficients
                        .iter()
                        .zip(&track[lo..=j + taps.after])
                        .map(|(c, x)| c * x)
                        .sum();
                }
            }
        }
        start = end;
    }
    out
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;
    use std::f64::consts::PI;

    fn plain() -> DifferentiatorParams {
        DifferentiatorParams {
            aperture_samples: 0.0,
            ..DifferentiatorParams::default()
        }
    }

    /// The brief's bar: the centred filter is within 0.5 dB of the ideal iω up to 0.8 × Nyquist,
    /// with a zero real part (no delay).
    #[test]
    fn a_remembered_design_is_the_design() {
        let p = DifferentiatorParams::default();
        for (before, after) in [(6, 6), (2, 6), (6, 0), (3, 3), (0, 1)] {
            for _ in 0..2 {
                assert_eq!(
                    remembered_design(before, after, &p),
                    design(before, after, &p)
                );
            }
        }
        let other = DifferentiatorParams {
            ridge: 1e-2,
            ..p.clone()
        };
        assert_ne!(remembered_design(6, 6, &other), remembered_design(6, 6, &p));
    }

    #[test]
    fn centred_response_is_within_half_a_db_of_ideal() {
        let p = plain();
        let taps = design(p.half_taps, p.half_taps, &p).unwrap();
        let mut worst = 0.0f64;
        for i in 1..=400 {
            let omega = 0.8 * PI * i as f64 / 400.0;
            let (re, im) = taps.response(omega);
            assert!(re.abs() < 1e-9, "real part {re} at {omega}");
            worst = worst.max((20.0 * (im / omega).log10()).abs());
        }
        assert!(worst < 0.5, "worst deviation {worst} dB");
        // Antisymmetric taps.
        let c = &taps.coefficients;
        for k in 0..c.len() {
            assert!((c[k] + c[c.len() - 1 - k]).abs() < 1e-12);
        }
    }

    #[test]
    fn aperture_compensation_restores_the_box_averaged_derivative() {
        let p = DifferentiatorParams::default();
        let taps = design(p.half_taps, p.half_taps, &p).unwrap();
        let mut worst = 0.0f64;
        for i in 1..=400 {
            let omega = 0.8 * PI * i as f64 / 400.0;
            let (_, im) = taps.response(omega);
            let combined = im * aperture(omega, 1.0);
            worst = worst.max((20.0 * (combined / omega).log10()).abs());
        }
        assert!(worst < 0.5, "worst deviation {worst} dB");
    }

    #[test]
    fn a_sampled_sine_differentiates_to_its_cosine() {
        let p = plain();
        let f = 0.17; // cycles per sample (0.34 × Nyquist)
        let x: Vec<f64> = (0..80).map(|j| (2.0 * PI * f * j as f64).sin()).collect();
        let d = differentiate(&x, &p);
        for (j, &dj) in d.iter().enumerate().take(74).skip(6) {
            let want = 2.0 * PI * f * (2.0 * PI * f * j as f64).cos();
            assert!(
                (dj - want).abs() < 0.02 * 2.0 * PI * f,
                "{j}: {dj} vs {want}"
            );
        }
        // The ends use one-sided filters, good at low frequencies (they roll off higher up).
        let f = 0.03;
        let x: Vec<f64> = (0..80).map(|j| (2.0 * PI * f * j as f64).sin()).collect();
        let d = differentiate(&x, &p);
        for j in [0, 1, 2, 3, 4, 5, 74, 75, 76, 77, 78, 79] {
            let want = 2.0 * PI * f * (2.0 * PI * f * j as f64).cos();
            assert!(
                (d[j] - want).abs() < 0.05 * 2.0 * PI * f,
                "{j}: {} vs {want}",
                d[j]
            );
        }
    }

    #[test]
    fn gaps_split_the_track() {
        let p = plain();
        let mut x: Vec<f64> = (0..30).map(|j| 0.5 * j as f64).collect();
        x[10] = f64::NAN;
        x[20] = f64::NAN;
        x[21] = f64::NAN;
        x[23] = f64::NAN; // leaves a 1-sample run at 22
        let d = differentiate(&x, &p);
        for (j, v) in d.iter().enumerate() {
            match j {
                10 | 20 | 21 | 22 | 23 => assert!(v.is_nan(), "{j}: {v}"),
                _ => assert!((v - 0.5).abs() < 1e-3, "{j}: {v}"),
            }
        }
        assert!(differentiate(&[], &p).is_empty());
    }

    #[test]
    fn noise_gain_is_near_the_ideal_band_limited_one() {
        // An ideal differentiator up to 0.8π and nothing above has Σc² = (0.8π)³/(3π) ≈ 1.68;
        // the filter's response runs on past the band, so a little more.
        let p = plain();
        let g = noise_gain(&design(6, 6, &p).unwrap());
        assert!((1.68..3.0).contains(&g), "{g}");
        // The one-sided end filters roll off early instead of amplifying noise.
        let end = noise_gain(&design(0, 6, &p).unwrap());
        assert!(end < 2.0 * g, "{end} vs {g}");
        assert!(p.validate("edges.differentiator").is_ok());
        let bad = DifferentiatorParams { min_run: 1, ..p };
        assert!(bad.validate("edges.differentiator").is_err());
    }
}
