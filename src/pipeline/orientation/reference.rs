//! A plain reference of the robust plane fit, written straight from [`fit_plane`]'s docs: the Lorentzian IRLS with an annealed σ, each round's weighted normal equations solved as a 3×3 system about the points' mean; the fast fit is tested against it.

use super::*;

/// The weighted least-squares plane Z = a·X + b·Y + c through `points` with weights `w`:
/// the 3×3 normal equations Σw·h·hᵀ·(a, b, c) = Σw·z·h (h = (X, Y, 1)) by Cramer's rule;
/// None when they are singular.
fn weighted_plane(points: &[[f64; 3]], w: &[f64]) -> Option<[f64; 3]> {
    let mut m = [[0.0_f64; 3]; 3];
    let mut rhs = [0.0_f64; 3];
    for (&[x, y, z], &wi) in points.iter().zip(w) {
        let h = [x, y, 1.0];
        for i in 0..3 {
            for j in 0..3 {
                m[i][j] += wi * h[i] * h[j];
            }
            rhs[i] += wi * z * h[i];
        }
    }
    let det3 = |m: &[[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let det = det3(&m);
    if !(det.is_finite() && det.abs() > 0.0) {
        return None;
    }
    let solve = |col: usize| {
        let mut mc = m;
        for (row, &r) in mc.iter_mut().zip(&rhs) {
            row[col] = r;
        }
        det3(&mc) / det
    };
    Some([solve(0), solve(1), solve(2)])
}

/// A finished round: its plane, the weights and σ it was fitted with, and its residual.
type Round = ([f64; 3], Vec<f64>, Option<f64>, f64);

/// The residual z − a·X − b·Y − c of every point.
fn residuals(points: &[[f64; 3]], [a, b, c]: [f64; 3]) -> Vec<f64> {
    points
        .iter()
        .map(|&[x, y, z]| z - a * x - b * y - c)
        .collect()
}

/// Σw·|r| / Σw.
fn weighted_mean_abs(r: &[f64], w: &[f64]) -> f64 {
    let swr: f64 = r.iter().zip(w).map(|(r, w)| w * r.abs()).sum();
    swr / w.iter().sum::<f64>()
}

/// [`fit_plane`] done plainly: round 1 is least squares (unit weights); each later round
/// weighs every point by the Lorentzian ψ(r)/r = 1/(1 + r²/(2σ²)) of its residual to the
/// last plane, σ starting at `sigma_start_um` and shrinking by `sigma_decay` per round to
/// `sigma_min_um`, and solves the weighted normal equations again. Before each new round the
/// residual of the current plane under the weights it was fitted with decides: below
/// `residual_tolerance_um` it has converged; above `divergence_factor` times the last one (or
/// not finite) it has diverged and the last plane is kept; with σ at its floor for both and a
/// change of at most `STALL_RATIO`, converged; after `max_iterations` rounds it stops. The
/// outlier share counts residuals beyond `outlier_sigmas`·σ (σ of the final weights, or the
/// RMS residual for least squares, at least `sigma_min_um`).
pub(super) fn fit_plane_reference(
    points: &[[f64; 3]],
    params: &OrientationParams,
) -> Option<PlaneFit> {
    let n = points.len();
    // About the points' mean, which keeps the normal equations well conditioned; the offset
    // moves back at the end.
    let mean: [f64; 3] =
        std::array::from_fn(|k| points.iter().map(|p| p[k]).sum::<f64>() / n as f64);
    let centred: Vec<[f64; 3]> = points
        .iter()
        .map(|p| std::array::from_fn(|k| p[k] - mean[k]))
        .collect();
    let points = &centred[..];
    let unit = vec![1.0; n];
    let finish = |plane: [f64; 3], w: &[f64], sigma: Option<f64>, iterations, stop| {
        let r = residuals(points, plane);
        let rms = (r.iter().map(|r| r * r).sum::<f64>() / n as f64).sqrt();
        let sigma = sigma.unwrap_or(rms).max(params.sigma_min_um);
        let outliers = r
            .iter()
            .filter(|r| r.abs() > params.outlier_sigmas * sigma)
            .count();
        PlaneFit {
            a: plane[0],
            b: plane[1],
            c: plane[2] + mean[2] - plane[0] * mean[0] - plane[1] * mean[1],
            iterations,
            outlier_fraction: outliers as f64 / n as f64,
            residual_um: weighted_mean_abs(&r, w),
            stop,
        }
    };
    let mut plane = weighted_plane(points, &unit)?;
    if !params.robust {
        return Some(finish(plane, &unit, None, 1, StopReason::LeastSquares));
    }
    // The weights (and σ) the current plane was fitted with, and the previous round's.
    let mut weights = unit;
    let mut sigma: Option<f64> = None;
    let mut previous: Option<Round> = None;
    let mut iterations = 1;
    let mut sigma_next = params.sigma_start_um.max(params.sigma_min_um);
    loop {
        let res = weighted_mean_abs(&residuals(points, plane), &weights);
        let at_floor = |s: Option<f64>| s.is_some_and(|s| s <= params.sigma_min_um);
        let diverged = previous
            .as_ref()
            .is_some_and(|p| res > params.divergence_factor * p.3 || !res.is_finite());
        let stalled = previous.as_ref().is_some_and(|p| {
            at_floor(sigma) && at_floor(p.2) && (res - p.3).abs() <= STALL_RATIO * p.3
        });
        let stop = if res < params.residual_tolerance_um {
            Some(StopReason::Converged)
        } else if diverged {
            Some(StopReason::Diverged)
        } else if stalled {
            Some(StopReason::Converged)
        } else if iterations >= params.max_iterations {
            Some(StopReason::MaxIterations)
        } else {
            None
        };
        if let Some(stop) = stop {
            // A diverged round keeps the previous plane with its weights and σ.
            return Some(match (&previous, diverged) {
                (Some((p_plane, p_weights, p_sigma, _)), true) => {
                    finish(*p_plane, p_weights, *p_sigma, iterations, stop)
                }
                _ => finish(plane, &weights, sigma, iterations, stop),
            });
        }
        let lorentz: Vec<f64> = residuals(points, plane)
            .iter()
            .map(|r| 1.0 / (1.0 + r * r / (2.0 * sigma_next * sigma_next)))
            .collect();
        let Some(next) = weighted_plane(points, &lorentz) else {
            return Some(finish(
                plane,
                &weights,
                sigma,
                iterations,
                StopReason::Diverged,
            ));
        };
        previous = Some((plane, std::mem::replace(&mut weights, lorentz), sigma, res));
        plane = next;
        iterations += 1;
        sigma = Some(sigma_next);
        sigma_next = (sigma_next * params.sigma_decay).max(params.sigma_min_um);
    }
}
