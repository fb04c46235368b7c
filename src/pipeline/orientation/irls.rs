//! The robust plane fit: iteratively reweighted least squares with the Lorentzian weight and an annealed σ, its pass over the points on 4 lanes (portable or AVX2).

use super::*;

/// The 2×2 reduced normal matrix counts as singular when its determinant falls below this
/// share of the product of its diagonal.
pub(super) const SINGULAR_REL: f64 = 1e-12;
/// Once σ sits at its floor, the fit stops (converged) when the weighted mean residual changes
/// by less than this share between rounds: later rounds would repeat the same weights.
pub(super) const STALL_RATIO: f64 = 1e-4;
pub(super) use crate::pipeline::simd::irls::{
    IRLS_LANES as LANES, IRLS_SUMS as N_SUMS, PassInputs, accumulate_chunks, point_terms,
};
/// 3-D points in structure-of-arrays form; [`PointSet::centre`] moves them to their mean.
#[derive(Default)]
pub(super) struct PointSet {
    pub(super) x: Vec<f64>,
    pub(super) y: Vec<f64>,
    pub(super) z: Vec<f64>,
    /// The mean subtracted by `centre`.
    pub(super) mean: [f64; 3],
}

impl PointSet {
    pub(super) fn clear(&mut self) {
        self.x.clear();
        self.y.clear();
        self.z.clear();
        self.mean = [0.0; 3];
    }

    pub(super) fn push(&mut self, x: f64, y: f64, z: f64) {
        self.x.push(x);
        self.y.push(y);
        self.z.push(z);
    }

    pub(super) fn len(&self) -> usize {
        self.x.len()
    }

    /// Subtracts the mean of each coordinate (keeps the normal equations well conditioned).
    pub(super) fn centre(&mut self) {
        let n = self.len() as f64;
        if n == 0.0 {
            return;
        }
        let mean = [
            self.x.iter().sum::<f64>() / n,
            self.y.iter().sum::<f64>() / n,
            self.z.iter().sum::<f64>() / n,
        ];
        for (v, m) in [&mut self.x, &mut self.y, &mut self.z]
            .into_iter()
            .zip(mean)
        {
            for e in v.iter_mut() {
                *e -= m;
            }
        }
        self.mean = mean;
    }
}

/// Weight buffers of the IRLS rounds (previous, current, next rotate through them).
#[derive(Default)]
pub(super) struct FitScratch {
    pub(super) w: [Vec<f64>; 3],
    /// Which buffer holds the weights of the returned fit.
    pub(super) last: usize,
}

impl FitScratch {
    /// The weights the returned plane was fitted with.
    pub(super) fn final_weights(&self) -> &[f64] {
        self.w.get(self.last).map_or(&[], Vec::as_slice)
    }
}

/// Splits the weight buffers into one to read (`r`) and another to write (`w`), `r ≠ w`.
pub(super) fn read_write(bufs: &mut [Vec<f64>; 3], r: usize, w: usize) -> (&[f64], &mut [f64]) {
    let [b0, b1, b2] = bufs;
    match (r, w) {
        (0, 1) => (b0, b1),
        (0, _) => (b0, b2),
        (1, 0) => (b1, b0),
        (1, _) => (b1, b2),
        (_, 0) => (b2, b0),
        _ => (b2, b1),
    }
}

/// One IRLS pass over centred points: residuals of `plane` = (a, b, c), new Lorentzian weights
/// w = 1/(1 + r²·k) (k = 1/(2σ²); k = 0 gives unit weights) into `w_new`, and the sums for the
/// next weighted fit plus the weighted residual of `plane` under `w_old`. The whole chunks of
/// [`LANES`] points run on `isa` (the same bits on every instruction set).
pub(super) fn irls_pass(
    set: &PointSet,
    plane: [f64; 3],
    k: f64,
    w_old: &[f64],
    w_new: &mut [f64],
    isa: Isa,
) -> [f64; N_SUMS] {
    let [a, b, c] = plane;
    let mut acc = [[0.0_f64; LANES]; N_SUMS];
    let n = set.len().min(w_old.len()).min(w_new.len());
    let full = n - n % LANES;
    let (chunk_old, chunk_new) = (&w_old[..full], &mut w_new[..full]);
    let pass = PassInputs {
        x: &set.x,
        y: &set.y,
        z: &set.z,
        plane,
        k,
        w_old: chunk_old,
    };
    accumulate_chunks(isa, pass, chunk_new, &mut acc);
    // The points after the whole chunks, into lane 0.
    for i in full..n {
        if let (Some(&x), Some(&y), Some(&z), Some(&wo)) =
            (set.x.get(i), set.y.get(i), set.z.get(i), w_old.get(i))
        {
            let r = z - a * x - b * y - c;
            let w = 1.0 / (1.0 + r * r * k);
            for (s, t) in acc.iter_mut().zip(point_terms([x, y, z, wo], r, w)) {
                s[0] += t;
            }
            if let Some(wn) = w_new.get_mut(i) {
                *wn = w;
            }
        }
    }
    acc.map(|lanes| lanes.iter().sum())
}

/// Solves the weighted normal equations of Z = aX + bY + c from the sums of [`irls_pass`].
///
/// The 3×3 system is reduced exactly by eliminating c (Schur complement about the weighted
/// mean), leaving a 2×2 system in (a, b); None when it is singular.
pub(super) fn solve_plane(s: &[f64; N_SUMS]) -> Option<[f64; 3]> {
    let [sw, sx, sy, sz, sxx, sxy, syy, sxz, syz, ..] = *s;
    if sw.is_nan() || sw <= 0.0 {
        return None;
    }
    let (mx, my, mz) = (sx / sw, sy / sw, sz / sw);
    let cxx = sxx - sx * mx;
    let cxy = sxy - sx * my;
    let cyy = syy - sy * my;
    let cxz = sxz - sx * mz;
    let cyz = syz - sy * mz;
    let det = cxx * cyy - cxy * cxy;
    if !(cxx > 0.0 && cyy > 0.0 && det > SINGULAR_REL * cxx * cyy) {
        return None;
    }
    let a = (cxz * cyy - cyz * cxy) / det;
    let b = (cyz * cxx - cxz * cxy) / det;
    let c = mz - a * mx - b * my;
    (a.is_finite() && b.is_finite() && c.is_finite()).then_some([a, b, c])
}

/// A finished fit: the plane (centred coordinates), the buffer with its weights, the σ that made
/// those weights (None: unit weights), rounds and stop reason.
pub(super) struct Outcome {
    pub(super) plane: [f64; 3],
    pub(super) weights: usize,
    pub(super) sigma_um: Option<f64>,
    pub(super) iterations: u32,
    pub(super) stop: StopReason,
}

/// Turns an [`Outcome`] into a [`PlaneFit`]: residual under its weights, outlier share, offset
/// moved back from the centred coordinates.
pub(super) fn finish(
    set: &PointSet,
    sc: &mut FitScratch,
    out: &Outcome,
    params: &OrientationParams,
) -> PlaneFit {
    sc.last = out.weights;
    let w = sc.final_weights();
    let [a, b, c] = out.plane;
    let resid = |i: usize| -> Option<f64> {
        Some(set.z.get(i)? - a * set.x.get(i)? - b * set.y.get(i)? - c)
    };
    let (mut swr, mut sw, mut sr2) = (0.0, 0.0, 0.0);
    for i in 0..set.len() {
        if let (Some(r), Some(&wi)) = (resid(i), w.get(i)) {
            swr += wi * r.abs();
            sw += wi;
            sr2 += r * r;
        }
    }
    let n = set.len() as f64;
    let sigma = out
        .sigma_um
        .unwrap_or_else(|| (sr2 / n).sqrt())
        .max(params.sigma_min_um);
    let limit = params.outlier_sigmas * sigma;
    let outliers = (0..set.len())
        .filter(|&i| resid(i).is_some_and(|r| r.abs() > limit))
        .count();
    let [mx, my, mz] = set.mean;
    PlaneFit {
        a,
        b,
        c: c + mz - a * mx - b * my,
        iterations: out.iterations,
        outlier_fraction: outliers as f64 / n,
        residual_um: if sw > 0.0 { swr / sw } else { f64::NAN },
        stop: out.stop,
    }
}

/// Fits a plane to a centred point set: least squares, then (robust mode) IRLS rounds with the
/// Lorentzian weight ψ(r)/r = 1/(1 + r²/(2σ²)) and a shrinking σ.
pub(super) fn fit_set(
    set: &PointSet,
    params: &OrientationParams,
    sc: &mut FitScratch,
) -> Result<PlaneFit, StageError> {
    let n = set.len();
    if n < 3 {
        return Err(StageError::BadInput {
            stage: STAGE,
            problem: format!("{n} points; a plane needs at least 3"),
        });
    }
    for buf in &mut sc.w {
        buf.clear();
        buf.resize(n, 1.0);
    }
    let (mut ip, mut ic, mut inx) = (0_usize, 1_usize, 2_usize);
    // Round 1: plain least squares (k = 0 writes unit weights into buffer `ic`).
    let sums = {
        let (wo, wn) = read_write(&mut sc.w, ip, ic);
        irls_pass(set, [0.0; 3], 0.0, wo, wn, params.isa)
    };
    let Some(mut plane) = solve_plane(&sums) else {
        return Err(StageError::BadInput {
            stage: STAGE,
            problem: format!("the {n} points are degenerate (collinear or coincident)"),
        });
    };
    let mut iterations = 1_u32;
    if !params.robust {
        let out = Outcome {
            plane,
            weights: ic,
            sigma_um: None,
            iterations,
            stop: StopReason::LeastSquares,
        };
        return Ok(finish(set, sc, &out, params));
    }
    let mut sigma_cur: Option<f64> = None;
    let mut sigma_next = params.sigma_start_um.max(params.sigma_min_um);
    // The previous round's plane, residual and σ.
    let mut prev: Option<([f64; 3], f64, Option<f64>)> = None;
    loop {
        let k = 0.5 / (sigma_next * sigma_next);
        let sums = {
            let (wo, wn) = read_write(&mut sc.w, ic, inx);
            irls_pass(set, plane, k, wo, wn, params.isa)
        };
        let res = sums[9] / sums[10];
        let at_floor = |s: Option<f64>| s.is_some_and(|s| s <= params.sigma_min_um);
        let current = |stop| Outcome {
            plane,
            weights: ic,
            sigma_um: sigma_cur,
            iterations,
            stop,
        };
        if res < params.residual_tolerance_um {
            return Ok(finish(set, sc, &current(StopReason::Converged), params));
        }
        if let Some((p_plane, p_res, p_sigma)) = prev {
            if res > params.divergence_factor * p_res || !res.is_finite() {
                let out = Outcome {
                    plane: p_plane,
                    weights: ip,
                    sigma_um: p_sigma,
                    iterations,
                    stop: StopReason::Diverged,
                };
                return Ok(finish(set, sc, &out, params));
            }
            if at_floor(sigma_cur)
                && at_floor(p_sigma)
                && (res - p_res).abs() <= STALL_RATIO * p_res
            {
                return Ok(finish(set, sc, &current(StopReason::Converged), params));
            }
        }
        if iterations >= params.max_iterations {
            return Ok(finish(set, sc, &current(StopReason::MaxIterations), params));
        }
        let Some(next) = solve_plane(&sums) else {
            // The weights left too few effective points: keep the last good plane.
            return Ok(finish(set, sc, &current(StopReason::Diverged), params));
        };
        prev = Some((plane, res, sigma_cur));
        plane = next;
        iterations += 1;
        (ip, ic, inx) = (ic, inx, ip);
        sigma_cur = Some(sigma_next);
        sigma_next = (sigma_next * params.sigma_decay).max(params.sigma_min_um);
    }
}

/// Fits a plane to points `[X, Y, Z]` (µm), robustly when `params.robust`.
///
/// Least squares solves the weighted normal equations in f64 about the points' mean. The robust
/// mode is the Lorentzian M-estimator ρ(r) = log(1 + r²/(2σ²)) by iteratively reweighted least
/// squares with weights ψ(r)/r = 1/(1 + r²/(2σ²)) (Black & Anandan, as in the paper §6–7): σ
/// starts at `sigma_start_um` and shrinks by `sigma_decay` per round down to `sigma_min_um`.
/// It stops when the weighted mean |residual| falls below `residual_tolerance_um` or stalls
/// with σ at its floor (Converged), grows by more than `divergence_factor` (Diverged: the
/// previous plane is kept) or after `max_iterations` rounds.
///
/// # Errors
/// [`StageError`] with fewer than 3 points, a degenerate set, or invalid params.
pub fn fit_plane(points: &[[f64; 3]], params: &OrientationParams) -> Result<PlaneFit, StageError> {
    params.validate()?;
    let mut set = PointSet::default();
    for &[x, y, z] in points {
        if !(x.is_finite() && y.is_finite() && z.is_finite()) {
            return Err(StageError::BadInput {
                stage: STAGE,
                problem: "a point is not finite".into(),
            });
        }
        set.push(x, y, z);
    }
    set.centre();
    fit_set(&set, params, &mut FitScratch::default())
}
