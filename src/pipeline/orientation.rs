//! Robust wall orientation: Lorentzian M-estimator plane fits α̂·P = c about each wall line (paper §6–7).

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::depth::DepthMap;
use super::walls::{WallLine, WallSide};
use super::{StageError, check_range};
use crate::image::Image;
use crate::io::Geometry;

/// Knobs of the orientation stage.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OrientationParams {
    /// Use the Lorentzian M-estimator; when false, plain least squares.
    pub robust: bool,
    /// Side of the square neighbourhood about each sample on a wall line, px (paper: 100).
    pub neighbourhood_px: usize,
    /// Starting Lorentzian scale σ (µm of residual).
    pub sigma_start_um: f64,
    /// σ is multiplied by this each round (0 < f < 1).
    pub sigma_decay: f64,
    /// σ never falls below this (µm).
    pub sigma_min_um: f64,
    /// τ1: stop when the weighted mean residual (µm) falls below it.
    pub residual_tolerance_um: f64,
    /// τ2: stop (diverged) when the residual grows by more than this factor in a round.
    pub divergence_factor: f64,
    /// Iteration cap.
    pub max_iterations: u32,
    /// Residuals beyond this many σ count as outliers in the reported fraction.
    pub outlier_sigmas: f64,
    /// A fit whose cross-groove wall slope |b| differs from the median |b| of its wall in the
    /// group by more than this fraction is a failed fit and becomes a gap: a cut wall keeps its
    /// angle across the groove (modulation changes it by about 1 − cos θ, 2% at tan θ = 0.2),
    /// so a wall that seems to turn steeper or flatter is a fit locked onto damage. 0 = off.
    pub max_wall_slope_change: f64,
}

impl Default for OrientationParams {
    fn default() -> Self {
        Self {
            robust: true,
            neighbourhood_px: 100,
            sigma_start_um: 2.0,
            sigma_decay: 0.7,
            sigma_min_um: 0.05,
            residual_tolerance_um: 1e-3,
            divergence_factor: 2.0,
            max_iterations: 30,
            outlier_sigmas: 3.0,
            max_wall_slope_change: 0.25,
        }
    }
}

/// Why a robust fit stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StopReason {
    /// Residual below τ1.
    Converged,
    /// Residual grew past τ2; the previous estimate is kept.
    Diverged,
    /// Iteration cap reached.
    MaxIterations,
    /// Plain least squares (one round).
    LeastSquares,
}

/// A plane Z = a·X + b·Y + c fitted to 3-D points (µm).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlaneFit {
    /// ∂Z/∂X along the groove.
    pub a: f64,
    /// ∂Z/∂Y across the groove.
    pub b: f64,
    /// Offset.
    pub c: f64,
    /// Rounds run.
    pub iterations: u32,
    /// Share of points whose final residual exceeds `outlier_sigmas`·σ.
    pub outlier_fraction: f64,
    /// Final weighted mean absolute residual (µm).
    pub residual_um: f64,
    /// Why it stopped.
    pub stop: StopReason,
}

/// Stage name used in errors.
const STAGE: &str = "orientation";
/// Fewest points a sample's fit needs; fewer leave a gap.
const MIN_SAMPLE_POINTS: usize = 10;
/// The 2×2 reduced normal matrix counts as singular when its determinant falls below this
/// share of the product of its diagonal.
const SINGULAR_REL: f64 = 1e-12;
/// Once σ sits at its floor, the fit stops (converged) when the weighted mean residual changes
/// by less than this share between rounds: later rounds would repeat the same weights.
const STALL_RATIO: f64 = 1e-4;
/// Iso-depth lines whose depths differ by less than this (µm) count as one depth.
const DISTINCT_DEPTH_UM: f64 = 1e-6;
/// Independent partial sums per accumulator in the IRLS pass (lets the compiler vectorise).
const LANES: usize = 4;
/// Accumulators of one pass: Σw, Σwx, Σwy, Σwz, Σwx², Σwxy, Σwy², Σwxz, Σwyz, then the
/// residual of the current plane under the previous weights: Σw′|r|, Σw′.
const N_SUMS: usize = 11;

/// Checks the orientation params (same ranges as `PipelineParams::validate`).
/// Checks every orientation knob (shared by the stage and [`super::PipelineParams::validate`]).
///
/// # Errors
/// [`StageError::InvalidParam`] naming the first bad key.
pub fn validate(p: &OrientationParams) -> Result<(), StageError> {
    check_range("orientation.sigma_start_um", p.sigma_start_um, 1e-12, 1e9)?;
    check_range("orientation.sigma_decay", p.sigma_decay, 1e-6, 1.0)?;
    check_range("orientation.sigma_min_um", p.sigma_min_um, 1e-12, 1e9)?;
    check_range(
        "orientation.residual_tolerance_um",
        p.residual_tolerance_um,
        0.0,
        1e9,
    )?;
    check_range(
        "orientation.divergence_factor",
        p.divergence_factor,
        1.0,
        1e12,
    )?;
    check_range("orientation.outlier_sigmas", p.outlier_sigmas, 0.0, 1e6)?;
    check_range(
        "orientation.max_wall_slope_change",
        p.max_wall_slope_change,
        0.0,
        1e6,
    )?;
    if p.neighbourhood_px < 3 {
        return Err(StageError::InvalidParam {
            name: "orientation.neighbourhood_px".into(),
            problem: format!("{} is below the 3-pixel minimum", p.neighbourhood_px),
        });
    }
    if p.max_iterations == 0 {
        return Err(StageError::InvalidParam {
            name: "orientation.max_iterations".into(),
            problem: "must be at least 1".into(),
        });
    }
    Ok(())
}

/// Checks the camera geometry the back-projection needs.
fn check_geometry(geom: &Geometry) -> Result<(), StageError> {
    check_range("geometry.focal_px", geom.focal_px, 1e-9, 1e12)
}

/// 3-D points in structure-of-arrays form; [`PointSet::centre`] moves them to their mean.
#[derive(Default)]
struct PointSet {
    x: Vec<f64>,
    y: Vec<f64>,
    z: Vec<f64>,
    /// The mean subtracted by `centre`.
    mean: [f64; 3],
}

impl PointSet {
    fn clear(&mut self) {
        self.x.clear();
        self.y.clear();
        self.z.clear();
        self.mean = [0.0; 3];
    }

    fn push(&mut self, x: f64, y: f64, z: f64) {
        self.x.push(x);
        self.y.push(y);
        self.z.push(z);
    }

    fn len(&self) -> usize {
        self.x.len()
    }

    /// Subtracts the mean of each coordinate (keeps the normal equations well conditioned).
    fn centre(&mut self) {
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
struct FitScratch {
    w: [Vec<f64>; 3],
    /// Which buffer holds the weights of the returned fit.
    last: usize,
}

impl FitScratch {
    /// The weights the returned plane was fitted with.
    fn final_weights(&self) -> &[f64] {
        self.w.get(self.last).map_or(&[], Vec::as_slice)
    }
}

/// Splits the weight buffers into one to read (`r`) and another to write (`w`), `r ≠ w`.
fn read_write(bufs: &mut [Vec<f64>; 3], r: usize, w: usize) -> (&[f64], &mut [f64]) {
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
fn irls_pass(
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
fn irls_chunks(
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
fn point_terms([x, y, z, wo]: [f64; 4], r: f64, w: f64) -> [f64; N_SUMS] {
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
fn irls_chunks_avx2(
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
fn solve_plane(s: &[f64; N_SUMS]) -> Option<[f64; 3]> {
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
struct Outcome {
    plane: [f64; 3],
    weights: usize,
    sigma_um: Option<f64>,
    iterations: u32,
    stop: StopReason,
}

/// Turns an [`Outcome`] into a [`PlaneFit`]: residual under its weights, outlier share, offset
/// moved back from the centred coordinates.
fn finish(
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
fn fit_set(
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
/// The wall tilt at one sample column.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OrientationSample {
    /// Column of the sample centre.
    pub x_px: f32,
    /// tan θ of the wall normal against the zero-modulation normal along x (= wall velocity / Vt).
    pub tan_theta: f64,
    /// The fitted plane (None where no fit was possible: a gap).
    pub fit: Option<PlaneFit>,
}

/// Orientation samples of one wall.
#[derive(Clone, Debug, PartialEq)]
pub struct WallOrientation {
    /// Which wall.
    pub side: WallSide,
    /// One per sample column.
    pub samples: Vec<OrientationSample>,
}

/// Output of the orientation stage for one group.
#[derive(Clone, Debug, PartialEq)]
pub struct Orientation {
    /// One entry per measured wall.
    pub walls: Vec<WallOrientation>,
    /// Final robust weight per pixel used in any fit (NaN elsewhere), for the outlier view.
    pub weight_map: Image,
    /// Mean outlier fraction over all fits.
    pub outlier_fraction: f64,
    /// Fits turned into gaps for an implausible wall slope.
    pub rejected_fits: usize,
}

/// tan θ of a fitted wall plane: the wall's velocity along its normal over Vt, −a·sign(b)/√(1+b²).
#[must_use]
pub fn tan_theta(fit: &PlaneFit) -> f64 {
    -fit.a * fit.b.signum() / (1.0 + fit.b * fit.b).sqrt()
}

/// A sample with no fit (a gap).
fn gap(x_px: f32) -> OrientationSample {
    OrientationSample {
        x_px,
        tan_theta: f64::NAN,
        fit: None,
    }
}

/// Columns `x` with |x − x_s| ≤ n/2 inside `0..width` (empty for a non-finite centre).
fn window_columns(x_s: f32, n: usize, width: usize) -> std::ops::Range<usize> {
    let half = n as f64 / 2.0;
    let x_s = f64::from(x_s);
    if !x_s.is_finite() || width == 0 {
        return 0..0;
    }
    let lo = (x_s - half).ceil().max(0.0);
    let hi = (x_s + half).floor().min(width as f64 - 1.0);
    if hi < lo {
        return 0..0;
    }
    // Both bounds lie in [0, width − 1] here.
    lo as usize..hi as usize + 1
}

/// One fit's result with the pixels it used (row-major indices) and their final weights.
struct SampleResult {
    wall: usize,
    sample: OrientationSample,
    pixels: Vec<u32>,
    weights: Vec<f32>,
}

/// Per-thread buffers of the sample fits.
#[derive(Default)]
struct Workspace {
    set: PointSet,
    scratch: FitScratch,
    pixels: Vec<u32>,
}

impl Workspace {
    /// Fits the gathered points; a gap when there are too few or they are degenerate.
    fn fit_gathered(
        &mut self,
        wall: usize,
        x_px: f32,
        min_points: usize,
        params: &OrientationParams,
    ) -> SampleResult {
        let empty = |sample| SampleResult {
            wall,
            sample,
            pixels: Vec::new(),
            weights: Vec::new(),
        };
        if self.set.len() < min_points {
            return empty(gap(x_px));
        }
        self.set.centre();
        let Ok(fit) = fit_set(&self.set, params, &mut self.scratch) else {
            return empty(gap(x_px));
        };
        SampleResult {
            wall,
            sample: OrientationSample {
                x_px,
                tan_theta: tan_theta(&fit),
                fit: Some(fit),
            },
            pixels: self.pixels.clone(),
            weights: self
                .scratch
                .final_weights()
                .iter()
                .map(|&w| w as f32)
                .collect(),
        }
    }
}

/// Median |b| (cross-groove wall slope) of the fits in `samples`; None with fewer than 3 fits.
#[must_use]
pub fn median_wall_slope(samples: &[OrientationSample]) -> Option<f64> {
    let slopes: Vec<f64> = samples
        .iter()
        .filter_map(|s| s.fit.as_ref().map(|f| f.b.abs()))
        .filter(|b| b.is_finite())
        .collect();
    if slopes.len() < 3 {
        return None;
    }
    super::median(slopes)
}

/// Turns the fits of `samples` whose |b| strays from `reference` by more than
/// `max_change`·reference into gaps; returns how many it rejected. The stage uses the group's
/// own median as the reference; the engine also applies the median of the groups before, which
/// catches a group whose fits are mostly wrong (a long flaked chunk).
pub fn reject_slopes_against(
    samples: &mut [OrientationSample],
    reference: f64,
    max_change: f64,
) -> usize {
    if max_change <= 0.0 || !(reference.is_finite() && reference > 0.0) {
        return 0;
    }
    let mut rejected = 0;
    for s in samples.iter_mut() {
        let Some(b) = s.fit.as_ref().map(|f| f.b.abs()) else {
            continue;
        };
        if !b.is_finite() || (b - reference).abs() > max_change * reference {
            *s = gap(s.x_px);
            rejected += 1;
        }
    }
    rejected
}

/// [`reject_slopes_against`] the median of `samples` themselves.
fn reject_implausible_slopes(samples: &mut [OrientationSample], max_change: f64) -> usize {
    median_wall_slope(samples).map_or(0, |m| reject_slopes_against(samples, m, max_change))
}

/// A converged fit with slopes `a`, `b` (tests of the slope checks here and in the engine).
#[cfg(test)]
pub(crate) fn test_fit(a: f64, b: f64) -> PlaneFit {
    PlaneFit {
        a,
        b,
        c: 0.0,
        iterations: 1,
        outlier_fraction: 0.0,
        residual_um: 0.0,
        stop: StopReason::Converged,
    }
}

/// Assembles the per-wall sample lists, the weight map and the mean outlier share; rejects
/// fits with implausible wall slopes ([`OrientationParams::max_wall_slope_change`]).
fn assemble(
    sides: &[WallSide],
    n_samples: usize,
    results: Vec<SampleResult>,
    width: usize,
    height: usize,
    params: &OrientationParams,
) -> Orientation {
    let mut weight_map = Image::filled(width, height, f32::NAN);
    let mut walls: Vec<WallOrientation> = sides
        .iter()
        .map(|&side| WallOrientation {
            side,
            samples: Vec::with_capacity(n_samples),
        })
        .collect();
    let (mut outlier_sum, mut fits) = (0.0, 0_usize);
    for r in results {
        for (&p, &w) in r.pixels.iter().zip(&r.weights) {
            if let Some(m) = weight_map.data.get_mut(p as usize) {
                *m = if m.is_nan() { w } else { m.max(w) };
            }
        }
        if let Some(fit) = r.sample.fit {
            outlier_sum += fit.outlier_fraction;
            fits += 1;
        }
        if let Some(w) = walls.get_mut(r.wall) {
            w.samples.push(r.sample);
        }
    }
    let rejected_fits = walls
        .iter_mut()
        .map(|w| reject_implausible_slopes(&mut w.samples, params.max_wall_slope_change))
        .sum();
    Orientation {
        rejected_fits,
        walls,
        weight_map,
        outlier_fraction: if fits > 0 {
            outlier_sum / fits as f64
        } else {
            f64::NAN
        },
    }
}

/// Orientation from a depth map: a plane per sample column through the depth values in the
/// neighbourhood about each wall line (depth path).
///
/// For sample column x_s and each wall line, the pixels with |x − x_s| ≤ n/2 and
/// |y − row(x)| ≤ half_width(x) and a finite depth Z become points X = (x − cx)·Z/f,
/// Y = (y − cy)·Z/f, Z (µm) and are fitted by [`fit_plane`]'s method. Samples with fewer than
/// `MIN_SAMPLE_POINTS` points or a degenerate set are gaps (`fit: None`, tan θ NaN). One
/// [`WallOrientation`] per wall line, in the order of `walls`.
///
/// # Errors
/// [`StageError`] on invalid params or mismatched sizes.
pub fn orient_from_depth(
    depth: &DepthMap,
    walls: &[WallLine],
    sample_columns: &[f32],
    geom: &Geometry,
    params: &OrientationParams,
) -> Result<Orientation, StageError> {
    validate(params)?;
    check_geometry(geom)?;
    let z = &depth.z_um;
    let (width, height) = (z.width, z.height);
    if z.data.len() != width * height || u32::try_from(z.data.len()).is_err() {
        return Err(StageError::BadInput {
            stage: STAGE,
            problem: format!(
                "depth map of {width}x{height} holds {} values",
                z.data.len()
            ),
        });
    }
    check_lines(walls, width)?;
    let f = geom.focal_px;
    let cx = (width as f64 - 1.0) / 2.0;
    let cy = (height as f64 - 1.0) / 2.0;
    let jobs: Vec<(usize, usize)> = (0..walls.len())
        .flat_map(|w| (0..sample_columns.len()).map(move |s| (w, s)))
        .collect();
    let results: Vec<SampleResult> = jobs
        .par_iter()
        .map_init(Workspace::default, |ws, &(wi, si)| {
            let x_s = sample_columns.get(si).copied().unwrap_or(f32::NAN);
            let Some(line) = walls.get(wi) else {
                return ws.fit_gathered(wi, x_s, usize::MAX, params);
            };
            ws.set.clear();
            ws.pixels.clear();
            for x in window_columns(x_s, params.neighbourhood_px, width) {
                let (Some(&row), Some(&hw)) = (line.rows.get(x), line.half_width_px.get(x)) else {
                    continue;
                };
                if !(row.is_finite() && hw >= 0.0) {
                    continue;
                }
                let y_lo = f64::from(row - hw).ceil().max(0.0);
                let y_hi = f64::from(row + hw).floor().min(height as f64 - 1.0);
                if y_hi < y_lo {
                    continue;
                }
                let px = (x as f64 - cx) / f;
                for y in y_lo as usize..=y_hi as usize {
                    let idx = y * width + x;
                    let Some(&zv) = z.data.get(idx) else { continue };
                    if zv.is_finite() && zv > 0.0 {
                        let zv = f64::from(zv);
                        ws.set.push(px * zv, (y as f64 - cy) / f * zv, zv);
                        // Fits in u32: checked against the map size above.
                        ws.pixels.push(idx as u32);
                    }
                }
            }
            ws.fit_gathered(wi, x_s, MIN_SAMPLE_POINTS, params)
        })
        .collect();
    let sides: Vec<WallSide> = walls.iter().map(|l| l.side).collect();
    Ok(assemble(
        &sides,
        sample_columns.len(),
        results,
        width,
        height,
        params,
    ))
}

/// Checks that every line has one row and one half-width per column.
fn check_lines(lines: &[WallLine], width: usize) -> Result<(), StageError> {
    for (i, line) in lines.iter().enumerate() {
        if line.rows.len() != width || line.half_width_px.len() != width {
            return Err(StageError::BadInput {
                stage: STAGE,
                problem: format!(
                    "wall line {i} has {} rows and {} half-widths for {width} columns",
                    line.rows.len(),
                    line.half_width_px.len()
                ),
            });
        }
    }
    Ok(())
}

/// Number of distinct values among `depths` (µm).
fn distinct_depths(mut depths: Vec<f64>) -> usize {
    depths.sort_by(f64::total_cmp);
    depths.dedup_by(|a, b| (*a - *b).abs() < DISTINCT_DEPTH_UM);
    depths.len()
}

/// Orientation from iso-depth lines (dual-focus path): a plane per sample column through the
/// 3-D points of the lines of each wall within the neighbourhood.
///
/// Each line point (x, row(x)) with |x − x_s| ≤ n/2 becomes X = (x − cx)·d/f,
/// Y = (row − cy)·d/f, Z = `depth_um`, where d is `projection_depth_um` (else `depth_um`).
/// Lines without a finite `depth_um` are ignored. A wall side present in `lines` gets one
/// [`WallOrientation`] (Left first); its samples are gaps where fewer than two distinct depths
/// or fewer than `MIN_SAMPLE_POINTS` points fall in the window. `width` × `height` sizes the
/// weight map (pixels at the rounded line rows).
///
/// # Errors
/// [`StageError`] when no wall has two lines at distinct depths, or params are invalid.
pub fn orient_from_lines(
    lines: &[WallLine],
    width: usize,
    height: usize,
    sample_columns: &[f32],
    geom: &Geometry,
    params: &OrientationParams,
) -> Result<Orientation, StageError> {
    validate(params)?;
    check_geometry(geom)?;
    if lines.iter().any(|l| l.rows.len() != width) {
        return Err(StageError::BadInput {
            stage: STAGE,
            problem: format!("a line does not have one row per column ({width})"),
        });
    }
    if u32::try_from(width * height).is_err() {
        return Err(StageError::BadInput {
            stage: STAGE,
            problem: format!("{width}x{height} is too large"),
        });
    }
    let f = geom.focal_px;
    let cx = (width as f64 - 1.0) / 2.0;
    let cy = (height as f64 - 1.0) / 2.0;
    let depth_of = |l: &WallLine| l.depth_um.filter(|d| d.is_finite() && *d > 0.0);
    let mut sides = Vec::new();
    let mut members: Vec<Vec<&WallLine>> = Vec::new();
    let mut usable = Vec::new();
    for side in [WallSide::Left, WallSide::Right] {
        if !lines.iter().any(|l| l.side == side) {
            continue;
        }
        let group: Vec<&WallLine> = lines
            .iter()
            .filter(|l| l.side == side && depth_of(l).is_some())
            .collect();
        usable.push(distinct_depths(group.iter().filter_map(|l| depth_of(l)).collect()) >= 2);
        sides.push(side);
        members.push(group);
    }
    if !usable.iter().any(|&u| u) {
        return Err(StageError::NotFound {
            stage: STAGE,
            problem: "no wall has two iso-depth lines at distinct depths".into(),
        });
    }
    let jobs: Vec<(usize, usize)> = (0..sides.len())
        .flat_map(|w| (0..sample_columns.len()).map(move |s| (w, s)))
        .collect();
    let results: Vec<SampleResult> = jobs
        .par_iter()
        .map_init(Workspace::default, |ws, &(wi, si)| {
            let x_s = sample_columns.get(si).copied().unwrap_or(f32::NAN);
            let (Some(group), Some(true)) = (members.get(wi), usable.get(wi).copied()) else {
                return ws.fit_gathered(wi, x_s, usize::MAX, params);
            };
            ws.set.clear();
            ws.pixels.clear();
            let mut depths = Vec::new();
            for line in group {
                let Some(z) = depth_of(line) else { continue };
                let d = line
                    .projection_depth_um
                    .filter(|d| d.is_finite() && *d > 0.0)
                    .unwrap_or(z);
                let before = ws.set.len();
                for x in window_columns(x_s, params.neighbourhood_px, width) {
                    let Some(&row) = line.rows.get(x) else {
                        continue;
                    };
                    if !row.is_finite() {
                        continue;
                    }
                    let row = f64::from(row);
                    ws.set.push((x as f64 - cx) * d / f, (row - cy) * d / f, z);
                    let ry = row.round();
                    if ry >= 0.0 && ry < height as f64 {
                        // Fits in u32: checked above.
                        ws.pixels.push((ry as usize * width + x) as u32);
                    } else {
                        ws.pixels.push(u32::MAX);
                    }
                }
                if ws.set.len() > before {
                    depths.push(z);
                }
            }
            let min_points = if distinct_depths(depths) >= 2 {
                MIN_SAMPLE_POINTS
            } else {
                usize::MAX
            };
            ws.fit_gathered(wi, x_s, min_points, params)
        })
        .collect();
    Ok(assemble(
        &sides,
        sample_columns.len(),
        results,
        width,
        height,
        params,
    ))
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // Tests fail loudly on purpose.
mod tests {
    use super::*;

    #[test]
    fn fits_with_a_wall_slope_far_from_the_median_become_gaps() {
        let sample = |x: f32, a: f64, b: f64| OrientationSample {
            x_px: x,
            tan_theta: tan_theta(&test_fit(a, b)),
            fit: Some(test_fit(a, b)),
        };
        // Modulation moves b by a few per cent; a fit locked onto damage turns the wall steep.
        let mut s = vec![
            sample(0.0, 0.01, -0.38),
            sample(3.0, 0.05, -0.39),
            sample(6.0, 0.8, -1.2),
            sample(9.0, -0.04, -0.37),
            sample(12.0, 0.0, -0.38),
            gap(15.0),
        ];
        assert_eq!(reject_implausible_slopes(&mut s, 0.25), 1);
        assert!(s[2].fit.is_none() && s[2].tan_theta.is_nan());
        assert_eq!(s[2].x_px, 6.0);
        assert!(s.iter().filter(|x| x.fit.is_some()).count() == 4);
        // 0 turns the check off.
        let mut t = vec![
            sample(0.0, 0.0, -0.38),
            sample(1.0, 0.0, -0.38),
            sample(2.0, 0.8, -1.2),
        ];
        assert_eq!(reject_implausible_slopes(&mut t, 0.0), 0);
        assert!(t[2].fit.is_some());
    }
    use crate::pipeline::walls::test_support::{Groove, Rng, paper_geometry};

    fn params() -> OrientationParams {
        OrientationParams::default()
    }

    #[test]
    fn irls_pass_gives_the_same_bits_on_avx2() {
        let mut set = PointSet::default();
        let mut seed = 7_u64;
        let mut next = || {
            seed = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        // 4·m + 3 points, so the tail after the whole chunks is used too.
        for _ in 0..103 {
            let (x, y) = (next() * 40.0, next() * 40.0);
            set.x.push(x);
            set.y.push(y);
            set.z
                .push(0.3 * x - 0.2 * y + next() * if next() > 0.3 { 5.0 } else { 0.1 });
        }
        let w_old: Vec<f64> = (0..103).map(|_| next() + 0.5).collect();
        let (mut a, mut b) = (vec![0.0; 103], vec![0.0; 103]);
        let plane = [0.25, -0.15, 0.05];
        let sa = irls_pass(&set, plane, 0.7, &w_old, &mut a, false);
        let sb = irls_pass(&set, plane, 0.7, &w_old, &mut b, true);
        assert_eq!(sa.map(f64::to_bits), sb.map(f64::to_bits));
        assert_eq!(
            a.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            b.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
        );
        assert!(sa[0] > 0.0 && sa[0] < 103.0);
    }

    #[test]
    fn exact_plane_is_recovered_by_both_modes() {
        let mut pts = Vec::new();
        for i in 0..20 {
            for j in 0..15 {
                let (x, y) = (f64::from(i) * 1.3 - 7.0, f64::from(j) * 0.9 + 100.0);
                pts.push([x, y, 4000.0 + 0.02 * x - 0.7 * y]);
            }
        }
        for robust in [false, true] {
            let fit = fit_plane(&pts, &OrientationParams { robust, ..params() }).unwrap();
            assert!((fit.a - 0.02).abs() < 1e-9, "{fit:?}");
            assert!((fit.b + 0.7).abs() < 1e-9, "{fit:?}");
            assert!((fit.c - 4000.0).abs() < 1e-6, "{fit:?}");
            assert_eq!(fit.outlier_fraction, 0.0);
            let want = if robust {
                StopReason::Converged
            } else {
                StopReason::LeastSquares
            };
            assert_eq!(fit.stop, want);
        }
    }

    #[test]
    fn robust_fit_rejects_thirty_percent_gross_outliers() {
        let mut rng = Rng::new(7);
        let (a, b, c) = (0.03, 0.9, 4040.0);
        let mut pts = Vec::new();
        let mut outliers = 0;
        for i in 0..80 {
            for j in 0..60 {
                let (x, y) = (f64::from(i) * 0.5 - 20.0, f64::from(j) * 0.5 - 15.0);
                let z = if rng.uniform() < 0.3 {
                    outliers += 1;
                    c + 100.0 * (rng.uniform() - 0.5)
                } else {
                    a * x + b * y + c + 0.01 * rng.gauss()
                };
                pts.push([x, y, z]);
            }
        }
        let robust = fit_plane(&pts, &params()).unwrap();
        let plain = fit_plane(
            &pts,
            &OrientationParams {
                robust: false,
                ..params()
            },
        )
        .unwrap();
        let err_r = (robust.a - a).abs().max((robust.b - b).abs());
        let err_p = (plain.a - a).abs().max((plain.b - b).abs());
        assert!(err_r < 1e-3, "robust {robust:?}");
        assert!(
            err_p > 10.0 * 1e-3 && err_p > 10.0 * err_r,
            "plain {plain:?}"
        );
        let share = f64::from(outliers) / pts.len() as f64;
        assert!(
            (robust.outlier_fraction - share).abs() < 0.03,
            "{robust:?} vs {share}"
        );
        assert!(robust.iterations > 1);
    }

    #[test]
    fn fit_plane_rejects_bad_input() {
        let p = params();
        assert!(fit_plane(&[[0.0, 0.0, 1.0], [1.0, 0.0, 1.0]], &p).is_err());
        let line: Vec<[f64; 3]> = (0..10)
            .map(|i| [f64::from(i), 2.0 * f64::from(i), 1.0])
            .collect();
        assert!(fit_plane(&line, &p).is_err());
        let ok = [[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]];
        assert!(fit_plane(&ok, &p).is_ok());
        assert!(
            fit_plane(
                &[[f64::NAN, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]],
                &p
            )
            .is_err()
        );
        let bad = OrientationParams {
            sigma_decay: f64::NAN,
            ..params()
        };
        assert!(matches!(
            fit_plane(&ok, &bad),
            Err(StageError::InvalidParam { .. })
        ));
        let bad = OrientationParams {
            max_iterations: 0,
            ..params()
        };
        assert!(matches!(
            fit_plane(&ok, &bad),
            Err(StageError::InvalidParam { .. })
        ));
    }

    /// Lateral displacement d(X) = s·X of the whole groove: the left wall is
    /// Z = K + (Y − d(X)) (a = −s, b = +1), the right wall Z = K′ − (Y − d(X)) (a = +s, b = −1),
    /// so tan θ = −a·sign(b)/√(1 + b²) = s/√2 on both walls.
    #[test]
    fn tan_theta_sign_of_a_lateral_displacement() {
        let s = 0.05;
        let want = s / 2f64.sqrt();
        let mut left = Vec::new();
        let mut right = Vec::new();
        for i in 0..30 {
            for j in 0..30 {
                let (x, y) = (f64::from(i) - 15.0, f64::from(j) - 15.0);
                left.push([x, y, 4040.0 + (y - s * x)]);
                right.push([x, y, 4040.0 - (y - s * x)]);
            }
        }
        let fl = fit_plane(&left, &params()).unwrap();
        let fr = fit_plane(&right, &params()).unwrap();
        assert!(fl.b > 0.0 && fr.b < 0.0);
        assert!((tan_theta(&fl) - want).abs() < 1e-9, "{}", tan_theta(&fl));
        assert!((tan_theta(&fr) - want).abs() < 1e-9, "{}", tan_theta(&fr));
        // A displacement the other way flips the sign.
        let neg: Vec<[f64; 3]> = left
            .iter()
            .map(|p| [p[0], p[1], 4040.0 + (p[1] + s * p[0])])
            .collect();
        assert!((tan_theta(&fit_plane(&neg, &params()).unwrap()) + want).abs() < 1e-9);
    }

    fn hand_lines(g: &Groove, width: usize, height: usize, margin_px: f32) -> Vec<WallLine> {
        [WallSide::Left, WallSide::Right]
            .into_iter()
            .map(|side| {
                let (rows, hws): (Vec<f32>, Vec<f32>) = (0..width)
                    .map(|x| {
                        let (row, hw) = g.wall_band_px(side, x, width, height);
                        (row as f32, hw as f32 - margin_px)
                    })
                    .unzip();
                WallLine {
                    side,
                    rows,
                    half_width_px: hws,
                    depth_um: None,
                    projection_depth_um: None,
                    filled: vec![false; width],
                }
            })
            .collect()
    }

    #[test]
    fn depth_path_recovers_a_constant_wall_slope_on_both_walls() {
        let geom = paper_geometry();
        let s = 0.05;
        let g = Groove::new(geom, move |x_um| s * x_um);
        let (w, h) = (360, 640);
        let depth = g.depth_map(w, h);
        let walls = hand_lines(&g, w, h, 4.0);
        let columns = [60.0_f32, 180.0, 300.0];
        let out = orient_from_depth(&depth, &walls, &columns, &geom, &params()).unwrap();
        assert_eq!(out.walls.len(), 2);
        let want = s / 2f64.sqrt();
        for wall in &out.walls {
            assert_eq!(wall.samples.len(), 3);
            for smp in &wall.samples {
                let fit = smp.fit.unwrap();
                assert!(
                    (smp.tan_theta - want).abs() < 2e-4,
                    "{:?} {smp:?}",
                    wall.side
                );
                assert_eq!(fit.b > 0.0, wall.side == WallSide::Left);
            }
        }
        let used = out.weight_map.data.iter().filter(|v| v.is_finite()).count();
        assert!(used > 3 * 2 * 100 * 50, "{used}");
        assert!(out.outlier_fraction < 0.01);
        // Opposite displacement, opposite sign.
        let g2 = Groove::new(geom, move |x_um| -s * x_um);
        let out2 = orient_from_depth(
            &g2.depth_map(w, h),
            &hand_lines(&g2, w, h, 4.0),
            &columns,
            &geom,
            &params(),
        )
        .unwrap();
        for wall in &out2.walls {
            for smp in &wall.samples {
                assert!((smp.tan_theta + want).abs() < 2e-4, "{smp:?}");
            }
        }
    }

    #[test]
    fn depth_path_leaves_gaps_and_checks_sizes() {
        let geom = paper_geometry();
        let g = Groove::new(geom, |_| 0.0);
        let (w, h) = (200, 640);
        let depth = g.depth_map(w, h);
        let mut walls = hand_lines(&g, w, h, 4.0);
        for r in &mut walls[0].rows[..120] {
            *r = f32::NAN;
        }
        let out =
            orient_from_depth(&depth, &walls, &[40.0, 150.0, f32::NAN], &geom, &params()).unwrap();
        let left = &out.walls[0].samples;
        assert!(left[0].fit.is_none() && left[0].tan_theta.is_nan());
        assert!(left[1].fit.is_some() && left[1].tan_theta.abs() < 1e-4);
        assert!(left[2].fit.is_none());
        walls[1].rows.pop();
        assert!(matches!(
            orient_from_depth(&depth, &walls, &[40.0], &geom, &params()),
            Err(StageError::BadInput { .. })
        ));
    }

    /// An iso-depth line at depth z on a wall Z = K ± (Y − s·X): Y = ±(z − K) + s·X, so
    /// row(x) = cy + f·Y/z with X = (x − cx)·z/f.
    fn iso_line(
        side: WallSide,
        z: f64,
        k: f64,
        s: f64,
        width: usize,
        height: usize,
        f: f64,
    ) -> WallLine {
        let (cx, cy) = ((width as f64 - 1.0) / 2.0, (height as f64 - 1.0) / 2.0);
        let sign = if side == WallSide::Left { 1.0 } else { -1.0 };
        let rows = (0..width)
            .map(|x| {
                let big_x = (x as f64 - cx) * z / f;
                let big_y = sign * (z - k) + s * big_x;
                (cy + f * big_y / z) as f32
            })
            .collect();
        WallLine {
            side,
            rows,
            half_width_px: vec![0.0; width],
            depth_um: Some(z),
            projection_depth_um: Some(z),
            filled: vec![false; width],
        }
    }

    #[test]
    fn line_path_recovers_the_slope_from_two_iso_depth_lines() {
        let geom = paper_geometry();
        let f = geom.focal_px;
        let (w, h) = (400, 600);
        let s = 0.04;
        let want = s / 2f64.sqrt();
        let lines = vec![
            iso_line(WallSide::Left, 4030.0, 4050.0, s, w, h, f),
            iso_line(WallSide::Left, 4060.0, 4050.0, s, w, h, f),
            iso_line(WallSide::Right, 4030.0, 4050.0, s, w, h, f),
            iso_line(WallSide::Right, 4060.0, 4050.0, s, w, h, f),
        ];
        let out = orient_from_lines(&lines, w, h, &[100.0, 250.0], &geom, &params()).unwrap();
        assert_eq!(out.walls.len(), 2);
        for wall in &out.walls {
            for smp in &wall.samples {
                // Rows are stored as f32 (≈ 3e-5 px), a tiny error on a 30 µm lever.
                assert!(
                    (smp.tan_theta - want).abs() < 1e-4,
                    "{:?} {smp:?}",
                    wall.side
                );
            }
        }
        assert!(out.weight_map.data.iter().any(|v| v.is_finite()));
        // One line on the right: that wall is a gap, the left still works.
        let partial = vec![lines[0].clone(), lines[1].clone(), lines[2].clone()];
        let out = orient_from_lines(&partial, w, h, &[100.0], &geom, &params()).unwrap();
        assert!(out.walls[1].samples[0].fit.is_none());
        assert!(out.walls[0].samples[0].fit.is_some());
        // Two lines at the same depth on each wall: no wall is usable.
        let same = vec![lines[0].clone(), lines[0].clone(), lines[2].clone()];
        assert!(matches!(
            orient_from_lines(&same, w, h, &[100.0], &geom, &params()),
            Err(StageError::NotFound { .. })
        ));
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // Tests fail loudly on purpose.
mod end_to_end {
    use super::*;
    use crate::pipeline::depth::{DepthParams, estimate_depth};
    use crate::pipeline::optical_flow::FlowField;
    use crate::pipeline::walls::test_support::{Groove, Rng, paper_geometry};
    use crate::pipeline::walls::{WallParams, find_walls};

    /// Flows of a laterally sliding groove (with flow noise) → Kalman depth → walls → fits.
    fn run(noise_px: f64, seed: u64) -> Vec<(WallSide, f64)> {
        let geom = paper_geometry();
        let s = 0.05;
        let g = Groove::new(geom, move |x_um| s * x_um);
        let (w, h) = (300, 560);
        let mut rng = Rng::new(seed);
        let fu = geom.focal_px * geom.frame_step_um;
        let flows: Vec<FlowField> = (0..6)
            .map(|k| {
                let cam = f64::from(k) * geom.frame_step_um;
                let u = Image::from_fn(w, h, |x, y| {
                    let z = g.z_px_from(x as f64, y as f64, w, h, cam);
                    (-fu / z + noise_px * rng.gauss()) as f32
                });
                FlowField {
                    u,
                    v: Image::zeros(w, h),
                    confidence: Image::filled(w, h, 1.0),
                    iterations: 1,
                    converged: true,
                    frame_index: k as usize,
                }
            })
            .collect();
        let depth = estimate_depth(&flows, &geom, &DepthParams::default()).unwrap();
        let walls = find_walls(&depth, &geom, &WallParams::default()).unwrap();
        let out = orient_from_depth(
            &depth,
            &walls,
            &[75.0, 150.0, 225.0],
            &geom,
            &OrientationParams::default(),
        )
        .unwrap();
        out.walls
            .iter()
            .flat_map(|wo| wo.samples.iter().map(move |smp| (wo.side, smp.tan_theta)))
            .collect()
    }

    #[test]
    fn sliding_groove_gives_its_slope_from_flow_to_tan_theta() {
        let want = 0.05 / 2f64.sqrt();
        for (noise, tol) in [(0.0, 1e-5), (0.002, 5e-3)] {
            let got = run(noise, 5);
            eprintln!("noise {noise}: {got:?} want {want}");
            assert_eq!(got.len(), 6);
            for (side, t) in got {
                assert!(
                    (t - want).abs() < tol,
                    "noise {noise} {side:?}: {t} vs {want}"
                );
            }
        }
    }
}
