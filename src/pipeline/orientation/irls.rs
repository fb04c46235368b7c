//! The robust plane fit: iteratively reweighted least squares with the Lorentzian weight and an annealed σ, its pass over the points on 4 lanes (portable or AVX2).

use super::*;

/// The 2×2 reduced normal matrix counts as singular when its determinant falls below this
/// share of the product of its diagonal.
pub(super) const SINGULAR_REL: f64 = 1e-12;
/// Once σ sits at its floor, the fit stops (converged) when the weighted mean residual changes
/// by less than this share between rounds: later rounds would repeat the same weights.
pub(super) const STALL_RATIO: f64 = 1e-4;
/// Independent partial sums per accumulator in the IRLS pass (lets the compiler vectorise).
pub(super) const LANES: usize = 4;
/// Accumulators of one pass: Σw, Σwx, Σwy, Σwz, Σwx², Σwxy, Σwy², Σwxz, Σwyz, then the
/// residual of the current plane under the previous weights: Σw′|r|, Σw′.
pub(super) const N_SUMS: usize = 11;
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
/// [`LANES`] points run on AVX2 when `allow_avx2` and the CPU has it (the same bits either way).
pub(super) fn irls_pass(
    set: &PointSet,
    plane: [f64; 3],
    k: f64,
    w_old: &[f64],
    w_new: &mut [f64],
    allow_avx2: bool,
) -> [f64; N_SUMS] {
    let [a, b, c] = plane;
    let mut acc = [[0.0_f64; LANES]; N_SUMS];
    let n = set.len().min(w_old.len()).min(w_new.len());
    let full = n - n % LANES;
    let (chunk_old, chunk_new) = (&w_old[..full], &mut w_new[..full]);
    #[cfg(target_arch = "x86_64")]
    if allow_avx2 && std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU reported AVX2, all that `irls_chunks_avx2` requires.
        unsafe { irls_chunks_avx2(set, plane, k, chunk_old, chunk_new, &mut acc) };
    } else {
        irls_chunks(set, plane, k, chunk_old, chunk_new, &mut acc);
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let _ = allow_avx2;
        irls_chunks(set, plane, k, chunk_old, chunk_new, &mut acc);
    }
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

/// The whole-chunk part of [`irls_pass`]: the first `w_old.len()` points (a multiple of
/// [`LANES`]), point l of each chunk into lane l of `acc`.
pub(super) fn irls_chunks(
    set: &PointSet,
    [a, b, c]: [f64; 3],
    k: f64,
    w_old: &[f64],
    w_new: &mut [f64],
    acc: &mut [[f64; LANES]; N_SUMS],
) {
    let chunks = set
        .x
        .chunks_exact(LANES)
        .zip(set.y.chunks_exact(LANES))
        .zip(set.z.chunks_exact(LANES))
        .zip(w_old.chunks_exact(LANES))
        .zip(w_new.chunks_exact_mut(LANES));
    for ((((xc, yc), zc), woc), wnc) in chunks {
        let (Ok(xc), Ok(yc), Ok(zc), Ok(woc), Ok(wnc)) = (
            <&[f64; LANES]>::try_from(xc),
            <&[f64; LANES]>::try_from(yc),
            <&[f64; LANES]>::try_from(zc),
            <&[f64; LANES]>::try_from(woc),
            <&mut [f64; LANES]>::try_from(wnc),
        ) else {
            continue;
        };
        // Lane-wise arithmetic on fixed-size arrays (the compiler maps it onto SIMD registers).
        let r: [f64; LANES] = std::array::from_fn(|l| zc[l] - a * xc[l] - b * yc[l] - c);
        let w: [f64; LANES] = std::array::from_fn(|l| 1.0 / (1.0 + r[l] * r[l] * k));
        *wnc = w;
        for l in 0..LANES {
            let terms = point_terms([xc[l], yc[l], zc[l], woc[l]], r[l], w[l]);
            for (s, t) in acc.iter_mut().zip(terms) {
                s[l] += t;
            }
        }
    }
}

/// The sums one point adds for the next weighted fit: `w, w·x, w·y, w·z, w·x·x, w·x·y,
/// w·y·y, w·x·z, w·y·z` under its new weight `w`, then `wo·|r|, wo` under its old one (point
/// `[x, y, z, wo]`, residual `r`). [`irls_chunks_avx2`] computes the same products in the same
/// order.
#[inline(always)]
pub(super) fn point_terms([x, y, z, wo]: [f64; 4], r: f64, w: f64) -> [f64; N_SUMS] {
    let (wx, wy) = (w * x, w * y);
    [
        w,
        wx,
        wy,
        w * z,
        wx * x,
        wx * y,
        wy * y,
        wx * z,
        wy * z,
        wo * r.abs(),
        wo,
    ]
}

/// [`irls_chunks`] on AVX2 registers: lane l of each 4-wide vector is lane l of its
/// accumulators, with the same operations in the same order (no FMA), so the sums are bit for
/// bit the same.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
pub(super) fn irls_chunks_avx2(
    set: &PointSet,
    [a, b, c]: [f64; 3],
    k: f64,
    w_old: &[f64],
    w_new: &mut [f64],
    acc: &mut [[f64; LANES]; N_SUMS],
) {
    use std::arch::x86_64::{
        __m256d, _mm256_add_pd, _mm256_andnot_pd, _mm256_div_pd, _mm256_loadu_pd, _mm256_mul_pd,
        _mm256_set1_pd, _mm256_setzero_pd, _mm256_storeu_pd, _mm256_sub_pd,
    };
    const { assert!(LANES == 4) };
    let full = w_old.len().min(w_new.len()) / LANES * LANES;
    let (Some(xs), Some(ys), Some(zs)) = (set.x.get(..full), set.y.get(..full), set.z.get(..full))
    else {
        return;
    };
    let (va, vb, vc, vk) = (
        _mm256_set1_pd(a),
        _mm256_set1_pd(b),
        _mm256_set1_pd(c),
        _mm256_set1_pd(k),
    );
    let (one, sign) = (_mm256_set1_pd(1.0), _mm256_set1_pd(-0.0));
    let mut s: [__m256d; N_SUMS] = [_mm256_setzero_pd(); N_SUMS];
    let chunks = xs
        .chunks_exact(LANES)
        .zip(ys.chunks_exact(LANES))
        .zip(zs.chunks_exact(LANES))
        .zip(w_old.chunks_exact(LANES))
        .zip(w_new.chunks_exact_mut(LANES));
    for ((((xc, yc), zc), woc), wnc) in chunks {
        // SAFETY: every chunk holds 4 f64, as the unaligned loads and the store access.
        let (x, y, z, wo) = unsafe {
            (
                _mm256_loadu_pd(xc.as_ptr()),
                _mm256_loadu_pd(yc.as_ptr()),
                _mm256_loadu_pd(zc.as_ptr()),
                _mm256_loadu_pd(woc.as_ptr()),
            )
        };
        // r = ((z − a·x) − b·y) − c; w = 1/(1 + (r·r)·k), as in the portable lanes.
        let r = _mm256_sub_pd(
            _mm256_sub_pd(_mm256_sub_pd(z, _mm256_mul_pd(va, x)), _mm256_mul_pd(vb, y)),
            vc,
        );
        let w = _mm256_div_pd(
            one,
            _mm256_add_pd(one, _mm256_mul_pd(_mm256_mul_pd(r, r), vk)),
        );
        // SAFETY: as above.
        unsafe { _mm256_storeu_pd(wnc.as_mut_ptr(), w) };
        let (wx, wy) = (_mm256_mul_pd(w, x), _mm256_mul_pd(w, y));
        let terms = [
            w,
            wx,
            wy,
            _mm256_mul_pd(w, z),
            _mm256_mul_pd(wx, x),
            _mm256_mul_pd(wx, y),
            _mm256_mul_pd(wy, y),
            _mm256_mul_pd(wx, z),
            _mm256_mul_pd(wy, z),
            _mm256_mul_pd(wo, _mm256_andnot_pd(sign, r)),
            wo,
        ];
        for (sum, t) in s.iter_mut().zip(terms) {
            *sum = _mm256_add_pd(*sum, t);
        }
    }
    for (lanes, sum) in acc.iter_mut().zip(s) {
        let mut v = [0.0_f64; LANES];
        // SAFETY: `v` holds 4 f64.
        unsafe { _mm256_storeu_pd(v.as_mut_ptr(), sum) };
        for (l, x) in lanes.iter_mut().zip(v) {
            *l += x;
        }
    }
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
        irls_pass(set, [0.0; 3], 0.0, wo, wn, true)
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
            irls_pass(set, plane, k, wo, wn, true)
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
    validate(params)?;
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
