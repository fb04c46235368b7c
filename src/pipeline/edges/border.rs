//! The border model: sub-pixel position of a step between two grey levels in a 1-D profile,
//! by a least-squares fit of an edge-spread profile.
//!
//! The model is a blurred step, `v(x) = low + (high − low)·Φ((x − μ)/w)`, with `Φ` the standard
//! normal CDF (an optical edge spread: a step seen through a Gaussian point spread of σ = `w`).
//! [`fit_border`] fits its four parameters to weighted points `(x, v)` by Levenberg–Marquardt on
//! the weighted squared residuals, starting from a seed; [`find_border`] takes a plain profile
//! (one value per sample), seeds the fit at its strongest gradient of the asked polarity and fits
//! the points within `fit_half_window_px` of it, so that other borders in the profile do not pull
//! the fit.
//!
//! The position's standard error comes from the fit's covariance, `s²·(JᵀWJ)⁻¹`, with the noise
//! variance `s²` estimated from the weighted residuals (the weights are taken as relative inverse
//! variances, e.g. pixel counts of binned points). Widths are kept within
//! `[min_width_px, max_width_px]`: an unblurred, pixel-sampled step has no measurable width, and
//! a floor of about a pixel's own aperture (σ ≈ 0.3 px) keeps the fit's position derivative alive.

use serde::{Deserialize, Serialize};

use crate::pipeline::{StageError, check_range};

pub use super::erf::{erf, normal_cdf, normal_pdf};

/// Levenberg–Marquardt damping at the start, and its factor per accepted/rejected step.
const LM_DAMPING_START: f64 = 1e-3;
/// Factor by which the damping shrinks after an accepted step and grows after a rejected one.
const LM_DAMPING_FACTOR: f64 = 10.0;
/// Damping beyond which the fit gives up improving (the seed or last accepted step stays).
const LM_DAMPING_MAX: f64 = 1e10;
/// Fewest points a fit needs (four parameters and one degree of freedom for the noise).
pub const MIN_FIT_POINTS: usize = 5;

/// Which way the grey level steps along the profile.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Polarity {
    /// Dark to bright with increasing position.
    Rising,
    /// Bright to dark with increasing position.
    Falling,
    /// Whichever gradient is strongest.
    #[default]
    Either,
}

/// Knobs of the border fit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BorderParams {
    #[doc = knob!("edges.border.fit_half_window_px")]
    pub fit_half_window_px: f64,
    #[doc = knob!("edges.border.min_width_px")]
    pub min_width_px: f64,
    #[doc = knob!("edges.border.max_width_px")]
    pub max_width_px: f64,
    #[doc = knob!("edges.border.min_contrast")]
    pub min_contrast: f64,
    #[doc = knob!("edges.border.max_iterations")]
    pub max_iterations: u32,
    #[doc = knob!("edges.border.tolerance_px")]
    pub tolerance_px: f64,
}

impl Default for BorderParams {
    fn default() -> Self {
        Self {
            fit_half_window_px: 6.0,
            min_width_px: 0.3,
            max_width_px: 4.0,
            min_contrast: 0.02,
            max_iterations: 30,
            tolerance_px: 1e-5,
        }
    }
}

impl BorderParams {
    /// Checks every knob; `prefix` names the TOML table (e.g. `edges.border`).
    ///
    /// # Errors
    /// [`StageError::InvalidParam`] naming the first bad key.
    pub fn validate(&self, prefix: &str) -> Result<(), StageError> {
        let key = |k: &str| format!("{prefix}.{k}");
        check_range(
            &key("fit_half_window_px"),
            self.fit_half_window_px,
            1.0,
            1e4,
        )?;
        check_range(&key("min_width_px"), self.min_width_px, 1e-3, 1e3)?;
        check_range(
            &key("max_width_px"),
            self.max_width_px,
            self.min_width_px,
            1e4,
        )?;
        check_range(&key("min_contrast"), self.min_contrast, 0.0, 1e6)?;
        check_range(&key("tolerance_px"), self.tolerance_px, 0.0, 1.0)?;
        if self.max_iterations == 0 {
            return Err(StageError::InvalidParam {
                name: key("max_iterations"),
                problem: "must be at least 1".into(),
            });
        }
        Ok(())
    }
}

/// One weighted point of a profile: grey level `value` at position `x_px`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProfilePoint {
    /// Position along the profile (px).
    pub x_px: f64,
    /// Grey level.
    pub value: f64,
    /// Relative inverse variance (e.g. the number of pixels averaged); ≤ 0 ignores the point.
    pub weight: f64,
}

/// Where the fit starts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BorderSeed {
    /// Starting position (px).
    pub position_px: f64,
    /// Starting edge-spread σ (px).
    pub width_px: f64,
}

/// A border found in a profile.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Border {
    /// Sub-pixel position μ (px, in the profile's coordinates).
    pub position_px: f64,
    /// Standard error of the position (px), from the fit's covariance.
    pub std_error_px: f64,
    /// Fitted level before the border (smaller positions).
    pub low: f64,
    /// Fitted level after the border.
    pub high: f64,
    /// Fitted edge-spread σ (px).
    pub width_px: f64,
    /// Root mean square of the weighted residuals (grey level).
    pub residual_rms: f64,
    /// Points the fit read.
    pub points: usize,
    /// Iterations run.
    pub iterations: u32,
}

impl Border {
    /// `high − low`: positive for a rising border, negative for a falling one.
    #[must_use]
    pub fn contrast(&self) -> f64 {
        self.high - self.low
    }

    /// The fitted model's value at `x_px`.
    #[must_use]
    pub fn model_at(&self, x_px: f64) -> f64 {
        self.low + (self.high - self.low) * normal_cdf((x_px - self.position_px) / self.width_px)
    }

    /// The model's slope dv/dx at `x_px` (grey level per px).
    #[must_use]
    pub fn slope_at(&self, x_px: f64) -> f64 {
        let z = (x_px - self.position_px) / self.width_px;
        (self.high - self.low) * normal_pdf(z) / self.width_px
    }
}

/// Model parameters: low, high, position, width.
type Theta = [f64; 4];

/// Each point's Φ((x − μ)/w) into `cdf`, which [`cost_at`], [`normal_equations`] and
/// [`linear_levels`] at the same μ and w share.
fn cdfs_at(points: &[ProfilePoint], mu: f64, w: f64, cdf: &mut Vec<f64>) {
    cdf.clear();
    cdf.extend(points.iter().map(|p| normal_cdf((p.x_px - mu) / w)));
}

/// Weighted cost Σ w·r² of `theta` over `points`, given their Φ at its μ and w.
fn cost_at(points: &[ProfilePoint], theta: &Theta, cdf: &[f64]) -> f64 {
    let [lo, hi, _, _] = *theta;
    points
        .iter()
        .zip(cdf)
        .map(|(p, &phi)| {
            let r = p.value - (lo + (hi - lo) * phi);
            p.weight * r * r
        })
        .sum()
}

/// Weighted cost Σ w·r² of `theta` over `points`; `cdf` receives each point's Φ((x − μ)/w),
/// which [`normal_equations`] at the same `theta` reuses.
fn cost(points: &[ProfilePoint], theta: &Theta, cdf: &mut Vec<f64>) -> f64 {
    cdfs_at(points, theta[2], theta[3], cdf);
    cost_at(points, theta, cdf)
}

/// JᵀWJ (upper triangle used) and JᵀW·r of `theta`, given each point's Φ from [`cost`] at the
/// same `theta`.
fn normal_equations(
    points: &[ProfilePoint],
    theta: &Theta,
    cdfs: &[f64],
) -> ([[f64; 4]; 4], [f64; 4]) {
    let [lo, hi, mu, w] = *theta;
    let c = hi - lo;
    let mut a = [[0.0; 4]; 4];
    let mut g = [0.0; 4];
    for (p, &cdf) in points.iter().zip(cdfs) {
        let z = (p.x_px - mu) / w;
        let pdf = normal_pdf(z);
        let r = p.value - (lo + c * cdf);
        let j = [1.0 - cdf, cdf, -c * pdf / w, -c * pdf * z / w];
        for (row, &ji) in j.iter().enumerate() {
            g[row] += p.weight * ji * r;
            for (col, &jk) in j.iter().enumerate().skip(row) {
                a[row][col] += p.weight * ji * jk;
            }
        }
    }
    for row in 1..4 {
        let upper: [f64; 4] = std::array::from_fn(|col| a[col][row]);
        a[row][..row].copy_from_slice(&upper[..row]);
    }
    (a, g)
}

/// Solves the symmetric positive 4×4 system `a·x = b` by Cholesky; None when not positive definite.
#[allow(clippy::needless_range_loop)] // triangular index arithmetic reads clearest as indices
fn solve4(a: &[[f64; 4]; 4], b: &[f64; 4]) -> Option<[f64; 4]> {
    let mut l = [[0.0; 4]; 4];
    for i in 0..4 {
        for j in 0..=i {
            let mut s = a[i][j];
            for k in 0..j {
                s -= l[i][k] * l[j][k];
            }
            if i == j {
                if s.is_nan() || s <= 0.0 {
                    return None;
                }
                l[i][i] = s.sqrt();
            } else {
                l[i][j] = s / l[j][j];
            }
        }
    }
    let mut y = [0.0; 4];
    for i in 0..4 {
        let mut s = b[i];
        for k in 0..i {
            s -= l[i][k] * y[k];
        }
        y[i] = s / l[i][i];
    }
    let mut x = [0.0; 4];
    for i in (0..4).rev() {
        let mut s = y[i];
        for k in i + 1..4 {
            s -= l[k][i] * x[k];
        }
        x[i] = s / l[i][i];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// The (2, 2) entry of the inverse of `a` (the position's variance factor), via a solve.
fn position_variance_factor(a: &[[f64; 4]; 4]) -> Option<f64> {
    solve4(a, &[0.0, 0.0, 1.0, 0.0]).map(|x| x[2])
}

/// Best `low` and `high` for a fixed position and width, given each point's Φ((x − μ)/w) there:
/// the 2-parameter weighted linear least squares. None when the points do not straddle the
/// border.
fn linear_levels(points: &[ProfilePoint], cdfs: &[f64]) -> Option<(f64, f64)> {
    let (mut saa, mut sab, mut sbb, mut sav, mut sbv) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for (p, &b) in points.iter().zip(cdfs) {
        let a = 1.0 - b;
        saa += p.weight * a * a;
        sab += p.weight * a * b;
        sbb += p.weight * b * b;
        sav += p.weight * a * p.value;
        sbv += p.weight * b * p.value;
    }
    let det = saa * sbb - sab * sab;
    if det.is_nan() || det <= 1e-12 * saa * sbb {
        return None;
    }
    Some(((sav * sbb - sbv * sab) / det, (sbv * saa - sav * sab) / det))
}

/// Fits the border model to weighted points, starting from `seed` (levels solved linearly at
/// the seed). Points with non-positive or non-finite weight, or non-finite values, are ignored.
///
/// None when fewer than [`MIN_FIT_POINTS`] usable points remain, the points do not straddle
/// the seed, the fitted contrast is below `min_contrast`, or the position leaves the points'
/// span.
#[must_use]
pub fn fit_border(
    points: &[ProfilePoint],
    seed: BorderSeed,
    params: &BorderParams,
) -> Option<Border> {
    let usable: Vec<ProfilePoint> = points
        .iter()
        .copied()
        .filter(|p| {
            p.weight > 0.0 && p.weight.is_finite() && p.value.is_finite() && p.x_px.is_finite()
        })
        .collect();
    fit_usable(&usable, seed, params)
}

fn fit_usable(points: &[ProfilePoint], seed: BorderSeed, params: &BorderParams) -> Option<Border> {
    if points.len() < MIN_FIT_POINTS || !seed.position_px.is_finite() {
        return None;
    }
    let (x_lo, x_hi) = points
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
            (a.min(p.x_px), b.max(p.x_px))
        });
    let clamp_w = |w: f64| w.clamp(params.min_width_px, params.max_width_px);
    let w0 = clamp_w(if seed.width_px.is_finite() {
        seed.width_px
    } else {
        1.0
    });
    let (mut cdf, mut trial_cdf) = (Vec::new(), Vec::new());
    cdfs_at(points, seed.position_px, w0, &mut cdf);
    let (lo0, hi0) = linear_levels(points, &cdf)?;
    let mut theta: Theta = [lo0, hi0, seed.position_px, w0];
    let mut current = cost_at(points, &theta, &cdf);
    let mut damping = LM_DAMPING_START;
    let mut iterations = 0;
    let mut normal = normal_equations(points, &theta, &cdf);
    while iterations < params.max_iterations {
        iterations += 1;
        let (a, g) = &normal;
        let mut damped = *a;
        for (i, row) in damped.iter_mut().enumerate() {
            row[i] += damping * a[i][i].max(1e-12);
        }
        let mut step = solve4(&damped, g);
        let (at_min, at_max) = (
            theta[3] <= params.min_width_px,
            theta[3] >= params.max_width_px,
        );
        if step.is_some_and(|s| (at_max && s[3] > 0.0) || (at_min && s[3] < 0.0)) {
            // The width sits on its bound and the step would push it beyond: step the levels
            // and position alone, the width held. Clamping the full step instead would keep a
            // position step solved for a width change that never happens, and the fit would
            // zigzag until `max_iterations` (as it did on every blurred or sharp border).
            let mut held = damped;
            let mut g_held = *g;
            for row in &mut held {
                row[3] = 0.0;
            }
            held[3] = [0.0, 0.0, 0.0, 1.0];
            g_held[3] = 0.0;
            step = solve4(&held, &g_held);
        }
        let Some(step) = step else {
            damping *= LM_DAMPING_FACTOR;
            if damping > LM_DAMPING_MAX {
                break;
            }
            continue;
        };
        let mut next = theta;
        for (t, s) in next.iter_mut().zip(step) {
            *t += s;
        }
        next[3] = clamp_w(next[3]);
        let trial = cost(points, &next, &mut trial_cdf);
        if trial.is_finite() && trial <= current {
            // Position and width both settled (the levels follow them linearly).
            let moved = (next[2] - theta[2]).abs().max((next[3] - theta[3]).abs());
            theta = next;
            let settled = current - trial <= 1e-12 * current.max(f64::MIN_POSITIVE);
            current = trial;
            damping = (damping / LM_DAMPING_FACTOR).max(1e-12);
            std::mem::swap(&mut cdf, &mut trial_cdf);
            normal = normal_equations(points, &theta, &cdf);
            if moved < params.tolerance_px || settled {
                break;
            }
        } else {
            damping *= LM_DAMPING_FACTOR;
            if damping > LM_DAMPING_MAX {
                break;
            }
        }
    }
    let [low, high, mu, w] = theta;
    if !(mu >= x_lo && mu <= x_hi) || (high - low).abs() < params.min_contrast {
        return None;
    }
    let weight_sum: f64 = points.iter().map(|p| p.weight).sum();
    let dof = (points.len() - 4) as f64;
    let s2 = current / dof;
    let mean_weight = weight_sum / points.len() as f64;
    let var_factor = position_variance_factor(&normal.0)?;
    let std_error_px = (s2 * var_factor.max(0.0)).sqrt();
    Some(Border {
        position_px: mu,
        std_error_px,
        low,
        high,
        width_px: w,
        residual_rms: (current / weight_sum.max(f64::MIN_POSITIVE)).sqrt(),
        points: points.len(),
        iterations,
    })
    .filter(|b| b.std_error_px.is_finite() && mean_weight > 0.0)
}

/// Strongest gradient of the asked polarity in `profile` (central differences, points with a
/// zero weight skipped): its sub-pixel position (a parabola through the peak) and sign.
fn strongest_gradient(
    profile: &[f32],
    weights: Option<&[f32]>,
    polarity: Polarity,
) -> Option<(f64, f64)> {
    let ok = |i: usize| {
        profile.get(i).is_some_and(|v| v.is_finite())
            && weights.is_none_or(|w| w.get(i).is_some_and(|&v| v > 0.0))
    };
    let grad = |i: usize| -> Option<f64> {
        let (a, b) = (i.checked_sub(1)?, i + 1);
        (ok(a) && ok(b)).then(|| 0.5 * (f64::from(profile[b]) - f64::from(profile[a])))
    };
    let score = |g: f64| match polarity {
        Polarity::Rising => g,
        Polarity::Falling => -g,
        Polarity::Either => g.abs(),
    };
    let mut best: Option<(usize, f64)> = None;
    for i in 1..profile.len().saturating_sub(1) {
        if let Some(g) = grad(i)
            && score(g) > 0.0
            && best.is_none_or(|(_, b)| score(g) > score(b))
        {
            best = Some((i, g));
        }
    }
    let (i, g) = best?;
    let (gm, gp) = (
        i.checked_sub(1).and_then(grad).map_or(0.0, score),
        grad(i + 1).map_or(0.0, score),
    );
    let g0 = score(g);
    let den = gm - 2.0 * g0 + gp;
    let offset = if den < 0.0 {
        (0.5 * (gm - gp) / den).clamp(-0.5, 0.5)
    } else {
        0.0
    };
    Some((i as f64 + offset, g))
}

/// Finds the border in a profile (one value per px, sample `i` at position `i`): seeded at the
/// strongest gradient of the asked polarity, fitted over the samples within
/// `fit_half_window_px` of the seed. `weights` (same length) are per-sample relative inverse
/// variances; a zero weight skips a sample. None when no border of enough contrast is found.
#[must_use]
pub fn find_border(
    profile: &[f32],
    weights: Option<&[f32]>,
    polarity: Polarity,
    params: &BorderParams,
) -> Option<Border> {
    if weights.is_some_and(|w| w.len() != profile.len()) {
        return None;
    }
    let (seed, _) = strongest_gradient(profile, weights, polarity)?;
    let lo = (seed - params.fit_half_window_px).floor().max(0.0) as usize;
    let hi =
        ((seed + params.fit_half_window_px).ceil() as usize).min(profile.len().saturating_sub(1));
    let points: Vec<ProfilePoint> = (lo..=hi)
        .filter_map(|i| {
            let value = f64::from(*profile.get(i)?);
            let weight = weights.map_or(Some(1.0), |w| w.get(i).map(|&v| f64::from(v)))?;
            Some(ProfilePoint {
                x_px: i as f64,
                value,
                weight,
            })
        })
        .collect();
    let border = fit_border(
        &points,
        BorderSeed {
            position_px: seed,
            width_px: 1.0,
        },
        params,
    )?;
    let sign_ok = match polarity {
        Polarity::Rising => border.contrast() > 0.0,
        Polarity::Falling => border.contrast() < 0.0,
        Polarity::Either => true,
    };
    sign_ok.then_some(border)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests;
