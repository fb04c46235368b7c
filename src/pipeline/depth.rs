//! Depth from flow, Z = −f·U/u, refined over a group by the Barron–Ngai–Spies Kalman filter (horizontal-flow variant).
//!
//! # The filter
//! A point at depth Z seen at pixel (x, y) moves by u = −f·U/Z px per frame when the camera
//! translates by U along +X. For a locally planar surface the inverse depth is linear in the
//! image coordinates, 1/Z = α·(x − cx) + β·(y − cy) + γ, so the flow is linear in them too. Each
//! pixel carries the plane of its neighbourhood as a state µ = (α, β, ι), where ι = 1/Z at the
//! pixel itself (the plane's γ re-expressed about the pixel: ι = α·(x − cx) + β·(y − cy) + γ,
//! which keeps the 3×3 systems well conditioned); the state is stored dimensionless, scaled by
//! Z_ref = working distance (ι̃ = Z_ref/Z ≈ 1, α̃ = Z_ref·α per px, β̃ likewise).
//!
//! **Measurement.** Over the n×n neighbourhood N of pixel (x₀, y₀), each flow value with
//! confidence ≥ `min_confidence` gives m = u/u_land = ι̃ + α̃·dx + β̃·dy + noise, with
//! u_land = −f·U/Z_ref, dx = x − x₀, dy = y − y₀ and noise variance
//! `measurement_noise_px2`/(u_land²·w), w = confidence / mean confidence of the frame. The
//! weighted least-squares information J = Σ w·h·hᵀ/R, b = Σ w·m·h/R (h = (dx, dy, 1)) comes from
//! running box sums (no per-pixel window loops), and the update is the information-form Kalman
//! step Λ⁺ = P⁻¹ + J, µ⁺ = (Λ⁺)⁻¹·(P⁻¹·µ + b).
//!
//! **Prediction (state transform under a translation U along X).** The plane
//! 1/Z = α(x − cx) + β(y − cy) + γ is, in camera coordinates, f·α·X + f·β·Y + γ·Z = 1. After
//! the camera moves by U the same points have X′ = X − U, so f·α·X′ + f·β·Y′ + γ·Z′ = 1 − f·U·α:
//! every plane coefficient is scaled by s = 1/(1 − f·U·α). A tracked point keeps its Z (the
//! motion is along X), so ι is unchanged while it moves from pixel x to x − f·U/Z; hence the
//! state of pixel x′ in the new frame is the old state interpolated at x′ + f·U·ι, with
//! α′ = s·α, β′ = s·β, ι′ = ι. The covariance follows the Jacobian
//! F = [[s², 0, 0], [f·U·β·s², s, 0], [0, 0, 1]] and gains the process noise
//! Q = `process_noise`·diag(1/r², 1/r², 1) per frame (r = neighbourhood half-side: the same
//! relative change of inverse depth at the neighbourhood's edge as at its centre).
//!
//! After the last frame the inverse depth is median filtered (`median_px` × `median_px`,
//! paper: 5×5) and Z = 1/ι with Var Z = Var ι/ι⁴ (from the covariance) is output in the grid of
//! the last flow field. α and β are not part of the output, so only ι is median filtered.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::optical_flow::FlowField;
use super::{StageError, check_range};
use crate::image::Image;
use crate::io::Geometry;

/// Knobs of [`estimate_depth`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DepthParams {
    /// Run the Kalman filter; when false, average the per-frame depths.
    pub kalman: bool,
    /// Process noise of the planar-orientation state (per frame): variance added to the
    /// relative inverse depth Z_ref/Z (and that over r² to its per-pixel slopes).
    pub process_noise: f32,
    /// Measurement noise of one flow value (px²).
    pub measurement_noise_px2: f32,
    /// Side of the median filter on µ (paper: 5; odd, 1 = off).
    pub median_px: usize,
    /// Flow values with confidence below this are ignored.
    pub min_confidence: f32,
    /// Side of the square neighbourhood whose flows measure each pixel's plane (odd, px).
    pub neighbourhood_px: usize,
}

impl Default for DepthParams {
    fn default() -> Self {
        Self {
            kalman: true,
            process_noise: 1e-6,
            measurement_noise_px2: 1e-4,
            median_px: 5,
            min_confidence: 1e-3,
            neighbourhood_px: 5,
        }
    }
}

/// Depth below the optical centre (µm) with its variance, in the grid of frame `frame_index`.
#[derive(Clone, Debug, PartialEq)]
pub struct DepthMap {
    /// Z in µm (NaN where unknown).
    pub z_um: Image,
    /// Variance of Z in µm².
    pub variance: Image,
    /// Frame whose grid the map uses.
    pub frame_index: usize,
    /// Non-fatal problems (dropped frames, diverged pixels).
    pub warnings: Vec<String>,
}

/// Z = −f·U/u for one flow value (u in px/frame, U = frame step in µm); NaN when u is not negative.
#[must_use]
pub fn depth_from_flow_um(u_px: f32, geom: &Geometry) -> f32 {
    if u_px < 0.0 {
        (-(geom.focal_px * geom.frame_step_um) / f64::from(u_px)) as f32
    } else {
        f32::NAN
    }
}

/// Stage name used in errors.
const STAGE: &str = "depth";
/// Prior variance of the relative inverse depth ι̃ before any measurement (slopes: this / r²).
const INITIAL_VARIANCE: f64 = 1.0;
/// A pixel whose ι̃ variance stays above this share of the prior was never measured.
const UNMEASURED_SHARE: f64 = 0.5;
/// A prediction whose plane scale factor 1/s = 1 − f·U·α falls below this has diverged; the
/// pixel's state is reset to the prior.
const MIN_PLANE_SCALE: f64 = 0.5;
/// Largest accepted `median_px`.
const MAX_MEDIAN_PX: usize = 15;
/// Largest accepted `neighbourhood_px`.
const MAX_NEIGHBOURHOOD_PX: usize = 255;
/// Planes of the per-pixel state: α̃, β̃, ι̃, then the covariance P00 P01 P02 P11 P12 P22.
const PLANES: usize = 9;
/// Plane index of ι̃.
const IOTA: usize = 2;
/// Plane index of Var ι̃ (P22).
const VAR_IOTA: usize = 8;

/// Checks the params and the geometry the stage needs.
fn validate(p: &DepthParams, geom: &Geometry) -> Result<(), StageError> {
    check_range("depth.process_noise", f64::from(p.process_noise), 0.0, 1e12)?;
    check_range(
        "depth.measurement_noise_px2",
        f64::from(p.measurement_noise_px2),
        1e-30,
        1e12,
    )?;
    check_range(
        "depth.min_confidence",
        f64::from(p.min_confidence),
        0.0,
        1e12,
    )?;
    for (name, v, max) in [
        ("depth.median_px", p.median_px, MAX_MEDIAN_PX),
        (
            "depth.neighbourhood_px",
            p.neighbourhood_px,
            MAX_NEIGHBOURHOOD_PX,
        ),
    ] {
        if v % 2 == 0 || v > max {
            return Err(StageError::InvalidParam {
                name: name.into(),
                problem: format!("{v} is not an odd size in 1..={max}"),
            });
        }
    }
    check_range("geometry.focal_px", geom.focal_px, 1e-9, 1e12)?;
    check_range("geometry.frame_step_um", geom.frame_step_um, 1e-12, 1e12)?;
    check_range(
        "geometry.working_distance_um",
        geom.working_distance_um,
        1e-9,
        1e12,
    )?;
    Ok(())
}

/// Checks that the flow fields agree in size and run forward in time.
fn check_flows(flows: &[FlowField]) -> Result<(usize, usize), StageError> {
    let Some(first) = flows.first() else {
        return Err(StageError::BadInput {
            stage: STAGE,
            problem: "no flow fields".into(),
        });
    };
    let (w, h) = (first.u.width, first.u.height);
    if w == 0 || h == 0 {
        return Err(StageError::BadInput {
            stage: STAGE,
            problem: "empty flow field".into(),
        });
    }
    let mut prev: Option<usize> = None;
    for (k, fl) in flows.iter().enumerate() {
        for (name, im) in [("u", &fl.u), ("confidence", &fl.confidence)] {
            if im.width != w || im.height != h || im.data.len() != w * h {
                return Err(StageError::BadInput {
                    stage: STAGE,
                    problem: format!(
                        "flow {k} {name} is {}x{} ({} values), the first u is {w}x{h}",
                        im.width,
                        im.height,
                        im.data.len()
                    ),
                });
            }
        }
        if let Some(p) = prev
            && fl.frame_index <= p
        {
            return Err(StageError::BadInput {
                stage: STAGE,
                problem: format!(
                    "flow {k} is for frame {} after frame {p}; frames must increase",
                    fl.frame_index
                ),
            });
        }
        prev = Some(fl.frame_index);
    }
    Ok((w, h))
}

/// One frame's measurements: weight w and weight × normalised flow w·m per pixel.
struct Measurements {
    w: Vec<f32>,
    wm: Vec<f32>,
    /// Pixels with enough confidence.
    valid: usize,
    /// Confident pixels whose flow is not finite.
    bad_flow: usize,
}

/// Weights (confidence / mean confidence, 0 below `min_confidence`) and w·u/u_land.
fn measurements(flow: &FlowField, u_land: f64, min_confidence: f32) -> Measurements {
    let usable = |u: f32, c: f32| c.is_finite() && c >= min_confidence && u.is_finite();
    let (sum, valid, bad_flow) = flow
        .u
        .data
        .par_iter()
        .zip(&flow.confidence.data)
        .map(|(&u, &c)| {
            if usable(u, c) {
                (f64::from(c), 1_usize, 0_usize)
            } else if c.is_finite() && c >= min_confidence {
                (0.0, 0, 1)
            } else {
                (0.0, 0, 0)
            }
        })
        .reduce(|| (0.0, 0, 0), |a, b| (a.0 + b.0, a.1 + b.1, a.2 + b.2));
    // Weights are relative to the mean confidence; all-zero confidences weigh 1 each.
    let scale = if sum > 0.0 { valid as f64 / sum } else { 1.0 };
    let (w, wm): (Vec<f32>, Vec<f32>) = flow
        .u
        .data
        .par_iter()
        .zip(&flow.confidence.data)
        .map(|(&u, &c)| {
            if usable(u, c) {
                let w = if sum > 0.0 { f64::from(c) * scale } else { 1.0 };
                (w as f32, (w * f64::from(u) / u_land) as f32)
            } else {
                (0.0, 0.0)
            }
        })
        .unzip();
    Measurements {
        w,
        wm,
        valid,
        bad_flow,
    }
}

/// Inverse of a symmetric 3×3 matrix packed as [m00, m01, m02, m11, m12, m22]; None when it is
/// not positive definite enough to invert.
fn inv_sym3(m: [f64; 6]) -> Option<[f64; 6]> {
    let [a, b, c, d, e, f] = m;
    let c00 = d * f - e * e;
    let c01 = c * e - b * f;
    let c02 = b * e - c * d;
    let det = a * c00 + b * c01 + c * c02;
    if !(det > 0.0 && det.is_finite()) {
        return None;
    }
    let inv = 1.0 / det;
    Some([
        c00 * inv,
        c01 * inv,
        c02 * inv,
        (a * f - c * c) * inv,
        (b * c - a * e) * inv,
        (a * d - b * b) * inv,
    ])
}

/// Packed symmetric 3×3 times a vector.
fn mul_sym3(m: &[f64; 6], v: [f64; 3]) -> [f64; 3] {
    [
        m[0] * v[0] + m[1] * v[1] + m[2] * v[2],
        m[1] * v[0] + m[3] * v[1] + m[4] * v[2],
        m[2] * v[0] + m[4] * v[1] + m[5] * v[2],
    ]
}

/// Fixed quantities of one filter run.
struct Filter {
    width: usize,
    height: usize,
    /// Neighbourhood half-side.
    r: usize,
    /// |u_land| = f·U/Z_ref: the land flow in px/frame (positive).
    land_shift_px: f64,
    /// Measurement noise variance of m = u/u_land for weight 1.
    noise_var: f64,
    /// Process noise per frame: [α̃, β̃, ι̃] variances.
    q: [f64; 3],
    /// Prior covariance diagonal.
    p0: [f64; 3],
}

/// Per-thread buffers of one row update.
struct RowScratch {
    old: Vec<f32>,
    /// Vertical window sums per column: Σw, Σw·dy, Σw·dy², Σwm, Σwm·dy.
    col: Vec<[f64; 5]>,
}

/// What a row update counted.
#[derive(Clone, Copy, Default)]
struct RowStats {
    diverged: usize,
}

impl std::ops::Add for RowStats {
    type Output = Self;
    fn add(self, o: Self) -> Self {
        Self {
            diverged: self.diverged + o.diverged,
        }
    }
}

impl Filter {
    /// Writes the prior state into every pixel of a state row.
    fn reset_row(&self, row: &mut [f32]) {
        let w = self.width;
        let init = [
            0.0, 0.0, 1.0, self.p0[0], 0.0, 0.0, self.p0[1], 0.0, self.p0[2],
        ];
        for (plane, v) in row.chunks_exact_mut(w).zip(init) {
            plane.fill(v as f32);
        }
    }

    /// The prior state of one pixel.
    fn prior(&self) -> ([f64; 3], [f64; 6]) {
        (
            [0.0, 0.0, 1.0],
            [self.p0[0], 0.0, 0.0, self.p0[1], 0.0, self.p0[2]],
        )
    }

    /// Reads pixel x of a state row.
    fn read(&self, row: &[f32], x: usize) -> ([f64; 3], [f64; 6]) {
        let w = self.width;
        let at = |p: usize| f64::from(row.get(p * w + x).copied().unwrap_or(f32::NAN));
        (
            [at(0), at(1), at(2)],
            [at(3), at(4), at(5), at(6), at(7), at(8)],
        )
    }

    /// Writes pixel x of a state row.
    fn write(&self, row: &mut [f32], x: usize, mu: [f64; 3], p: [f64; 6]) {
        let w = self.width;
        for (k, v) in mu.into_iter().chain(p).enumerate() {
            if let Some(o) = row.get_mut(k * w + x) {
                *o = v as f32;
            }
        }
    }

    /// Prediction of one state row over `steps` frames: re-index by the known motion, apply the
    /// plane transform and add process noise. `old` holds the row before the step.
    fn predict_row(&self, row: &mut [f32], old: &[f32], steps: f64) -> RowStats {
        let mut stats = RowStats::default();
        let w = self.width;
        let k = self.land_shift_px * steps;
        let plane = |p: usize, i: usize| f64::from(old.get(p * w + i).copied().unwrap_or(f32::NAN));
        for x in 0..w {
            let iota = plane(IOTA, x);
            let xs = x as f64 + k * iota;
            let i0 = xs.floor();
            if !(i0 >= 0.0 && i0 + 1.0 < w as f64) {
                // New content entering the view (or a non-finite state): start from the prior.
                let (mu, p) = self.prior();
                self.write(row, x, mu, p);
                continue;
            }
            let t = xs - i0;
            let i = i0 as usize;
            let v: [f64; PLANES] =
                std::array::from_fn(|p| plane(p, i) * (1.0 - t) + plane(p, i + 1) * t);
            let [al, be, io, p00, p01, p02, p11, p12, p22] = v;
            let den = 1.0 - k * al;
            if den.is_nan() || den < MIN_PLANE_SCALE {
                stats.diverged += 1;
                let (mu, p) = self.prior();
                self.write(row, x, mu, p);
                continue;
            }
            let s = 1.0 / den;
            let s2 = s * s;
            let c = be * k * s2;
            let q = self.q;
            let p_new = [
                s2 * s2 * p00 + q[0] * steps,
                s2 * (c * p00 + s * p01),
                s2 * p02,
                c * c * p00 + 2.0 * c * s * p01 + s2 * p11 + q[1] * steps,
                c * p02 + s * p12,
                p22 + q[2] * steps,
            ];
            self.write(row, x, [s * al, s * be, io], p_new);
        }
        stats
    }

    /// Measurement update of state row `y` from one frame's weights.
    fn update_row(&self, y: usize, row: &mut [f32], meas: &Measurements, col: &mut [[f64; 5]]) {
        let (w, h, r) = (self.width, self.height, self.r);
        // Vertical sums over rows y − r ..= y + r (dy relative to y).
        col.fill([0.0; 5]);
        for yy in y.saturating_sub(r)..=(y + r).min(h - 1) {
            let dy = yy as f64 - y as f64;
            let (Some(wr), Some(mr)) = (
                meas.w.get(yy * w..(yy + 1) * w),
                meas.wm.get(yy * w..(yy + 1) * w),
            ) else {
                continue;
            };
            for ((c, &wv), &mv) in col.iter_mut().zip(wr).zip(mr) {
                if wv > 0.0 {
                    let (wv, mv) = (f64::from(wv), f64::from(mv));
                    c[0] += wv;
                    c[1] += wv * dy;
                    c[2] += wv * dy * dy;
                    c[3] += mv;
                    c[4] += mv * dy;
                }
            }
        }
        // Horizontal running sums over columns x − r ..= x + r of c·X^p (absolute column X),
        // moved to dx = X − x: Σc·dx = T1 − x·T0, Σc·dx² = T2 − 2x·T1 + x²·T0.
        // t = [Σc0, Σc0·X, Σc0·X², Σc1, Σc1·X, Σc2, Σc3, Σc3·X, Σc4].
        let mut t = [0.0_f64; 9];
        let add = |t: &mut [f64; 9], xc: usize, sign: f64| {
            let Some(c) = col.get(xc) else { return };
            let xf = xc as f64;
            let terms = [
                c[0],
                c[0] * xf,
                c[0] * xf * xf,
                c[1],
                c[1] * xf,
                c[2],
                c[3],
                c[3] * xf,
                c[4],
            ];
            for (acc, v) in t.iter_mut().zip(terms) {
                *acc += sign * v;
            }
        };
        for xc in 0..r.min(w) {
            add(&mut t, xc, 1.0);
        }
        let inv_r = 1.0 / self.noise_var;
        for x in 0..w {
            if x + r < w {
                add(&mut t, x + r, 1.0);
            }
            if x > r {
                add(&mut t, x - r - 1, -1.0);
            }
            let s0 = t[0];
            if s0.is_nan() || s0 <= 0.0 {
                continue;
            }
            let xf = x as f64;
            let sx = t[1] - xf * t[0];
            let sxx = t[2] - 2.0 * xf * t[1] + xf * xf * t[0];
            let sy = t[3];
            let sxy = t[4] - xf * t[3];
            let syy = t[5];
            let sm = t[6];
            let smx = t[7] - xf * t[6];
            let smy = t[8];
            let jm = [
                sxx * inv_r,
                sxy * inv_r,
                sx * inv_r,
                syy * inv_r,
                sy * inv_r,
                s0 * inv_r,
            ];
            let b = [smx * inv_r, smy * inv_r, sm * inv_r];
            let (mu, p) = self.read(row, x);
            let (lam, lmu) = match inv_sym3(p) {
                Some(l) if mu.iter().all(|v| v.is_finite()) => (l, mul_sym3(&l, mu)),
                // A broken prior carries no information.
                _ => ([0.0; 6], [0.0; 3]),
            };
            let post_info: [f64; 6] = std::array::from_fn(|k| lam[k] + jm[k]);
            let Some(p_post) = inv_sym3(post_info) else {
                continue;
            };
            let rhs = [lmu[0] + b[0], lmu[1] + b[1], lmu[2] + b[2]];
            self.write(row, x, mul_sym3(&p_post, rhs), p_post);
        }
    }
}

/// Median filter (side `m`, NaN-aware) of `v` → `out`; NaN where the window holds no finite
/// value. Near the borders the window shrinks symmetrically about the pixel, so a linear ramp
/// is left unbiased.
fn median_filter(v: &[f32], width: usize, height: usize, m: usize, out: &mut [f32]) {
    let r = m / 2;
    if r == 0 {
        out.copy_from_slice(v);
        return;
    }
    out.par_chunks_mut(width).enumerate().for_each_init(
        Vec::new,
        |buf: &mut Vec<f32>, (y, row)| {
            let ry = r.min(y).min(height - 1 - y);
            for (x, o) in row.iter_mut().enumerate() {
                let rx = r.min(x).min(width - 1 - x);
                buf.clear();
                for yy in y - ry..=y + ry {
                    let base = yy * width + x;
                    if let Some(s) = v.get(base - rx..=base + rx) {
                        buf.extend(s.iter().copied().filter(|e| e.is_finite()));
                    }
                }
                *o = if buf.is_empty() {
                    f32::NAN
                } else {
                    let mid = buf.len() / 2;
                    let (_, med, _) = buf.select_nth_unstable_by(mid, f32::total_cmp);
                    *med
                };
            }
        },
    );
}

/// Runs the Kalman filter over the flows; returns ι̃ (NaN where never measured) and Var ι̃.
fn kalman(
    flows: &[FlowField],
    filter: &Filter,
    min_confidence: f32,
    u_land: f64,
    warnings: &mut Vec<String>,
) -> (Vec<f32>, Vec<f32>) {
    let (w, h) = (filter.width, filter.height);
    let mut state = vec![0.0_f32; PLANES * w * h];
    state
        .par_chunks_mut(PLANES * w)
        .for_each(|row| filter.reset_row(row));
    let mut prev_index: Option<usize> = None;
    let mut diverged = 0;
    for (k, flow) in flows.iter().enumerate() {
        let meas = measurements(flow, u_land, min_confidence);
        note_frame(k, flow, &meas, prev_index, warnings);
        let steps = prev_index.map(|p| flow.frame_index.saturating_sub(p) as f64);
        prev_index = Some(flow.frame_index);
        let stats = state
            .par_chunks_mut(PLANES * w)
            .enumerate()
            .map_init(
                || RowScratch {
                    old: vec![0.0; PLANES * w],
                    col: vec![[0.0; 5]; w],
                },
                |sc, (y, row)| {
                    let mut st = RowStats::default();
                    if let Some(steps) = steps {
                        sc.old.copy_from_slice(row);
                        st = filter.predict_row(row, &sc.old, steps);
                    }
                    if meas.valid > 0 {
                        filter.update_row(y, row, &meas, &mut sc.col);
                    }
                    st
                },
            )
            .reduce(RowStats::default, |a, b| a + b);
        diverged += stats.diverged;
    }
    if diverged > 0 {
        warnings.push(format!(
            "{diverged} pixel predictions diverged (plane scale 1 − f·U·α < {MIN_PLANE_SCALE}) and restarted from the prior"
        ));
    }
    let limit = (UNMEASURED_SHARE * INITIAL_VARIANCE) as f32;
    let mut iota = vec![f32::NAN; w * h];
    let mut var = vec![f32::NAN; w * h];
    iota.par_chunks_mut(w)
        .zip(var.par_chunks_mut(w))
        .zip(state.par_chunks(PLANES * w))
        .for_each(|((io, va), st)| {
            let (Some(iv), Some(vv)) = (
                st.get(IOTA * w..(IOTA + 1) * w),
                st.get(VAR_IOTA * w..(VAR_IOTA + 1) * w),
            ) else {
                return;
            };
            for (((o, ov), &i), &v) in io.iter_mut().zip(va.iter_mut()).zip(iv).zip(vv) {
                if v.is_finite() && v < limit && i.is_finite() {
                    *o = i;
                    *ov = v;
                }
            }
        });
    (iota, var)
}

/// Adds the warnings about one flow field (dropped, non-finite flow, frame gap).
fn note_frame(
    k: usize,
    flow: &FlowField,
    meas: &Measurements,
    prev_index: Option<usize>,
    warnings: &mut Vec<String>,
) {
    if meas.valid == 0 {
        warnings.push(format!(
            "flow {k} (frame {}) dropped: no pixel with usable flow and enough confidence",
            flow.frame_index
        ));
    }
    if meas.bad_flow > 0 {
        warnings.push(format!(
            "flow {k} (frame {}): {} confident pixels have non-finite flow and were skipped",
            flow.frame_index, meas.bad_flow
        ));
    }
    if let Some(p) = prev_index
        && flow.frame_index > p + 1
    {
        warnings.push(format!(
            "flow {k}: frames {} to {} are missing",
            p + 1,
            flow.frame_index - 1
        ));
    }
}

/// Averages the per-frame depths Z = −f·U/u, each moved into the last frame's grid; returns
/// ι̃ = Z_ref/Z̄ and Var ι̃ of the mean.
fn average(
    flows: &[FlowField],
    width: usize,
    height: usize,
    geom: &Geometry,
    params: &DepthParams,
    warnings: &mut Vec<String>,
) -> (Vec<f32>, Vec<f32>) {
    let fu = geom.focal_px * geom.frame_step_um;
    let z_ref = geom.working_distance_um;
    let last = flows.last().map_or(0, |f| f.frame_index);
    let mut sum = vec![0.0_f64; width * height];
    let mut var_sum = vec![0.0_f64; width * height];
    let mut count = vec![0_u32; width * height];
    let noise = f64::from(params.measurement_noise_px2);
    let mut prev_index = None;
    for (k, flow) in flows.iter().enumerate() {
        let meas = measurements(flow, -fu / z_ref, params.min_confidence);
        note_frame(k, flow, &meas, prev_index, warnings);
        prev_index = Some(flow.frame_index);
        if meas.valid == 0 {
            continue;
        }
        let steps = last.saturating_sub(flow.frame_index) as f64;
        // Per-pixel depth and its variance in this frame's grid (NaN where unusable).
        let depth_at = |i: usize| -> Option<(f64, f64)> {
            let wv = f64::from(*meas.w.get(i)?);
            let u = f64::from(*flow.u.data.get(i)?);
            (wv > 0.0 && u < 0.0).then(|| {
                let z = -fu / u;
                (z, (z / u).powi(2) * noise / wv)
            })
        };
        sum.par_chunks_mut(width)
            .zip(var_sum.par_chunks_mut(width))
            .zip(count.par_chunks_mut(width))
            .enumerate()
            .for_each(|(y, ((s, vs), c))| {
                for x in 0..width {
                    let base = y * width;
                    let Some((z_here, _)) = depth_at(base + x) else {
                        continue;
                    };
                    let xs = x as f64 + steps * fu / z_here;
                    let i0 = xs.floor();
                    if !(i0 >= 0.0 && i0 < width as f64) {
                        continue;
                    }
                    let (i, t) = (i0 as usize, xs - i0);
                    let Some((za, va)) = depth_at(base + i) else {
                        continue;
                    };
                    let (z, v) = if t > 0.0 {
                        let Some((zb, vb)) = depth_at(base + i + 1).filter(|_| i + 1 < width)
                        else {
                            continue;
                        };
                        (za * (1.0 - t) + zb * t, va * (1.0 - t) + vb * t)
                    } else {
                        (za, va)
                    };
                    if let (Some(so), Some(vo), Some(co)) =
                        (s.get_mut(x), vs.get_mut(x), c.get_mut(x))
                    {
                        *so += z;
                        *vo += v;
                        *co += 1;
                    }
                }
            });
    }
    let mut iota = vec![f32::NAN; width * height];
    let mut var = vec![f32::NAN; width * height];
    for (((o, ov), (&s, &vs)), &c) in iota
        .iter_mut()
        .zip(var.iter_mut())
        .zip(sum.iter().zip(&var_sum))
        .zip(&count)
    {
        if c > 0 {
            let n = f64::from(c);
            let z = s / n;
            let io = z_ref / z;
            *o = io as f32;
            // Var ι̃ = Var Z · (Z_ref/Z²)².
            *ov = (vs / (n * n) * (io / z).powi(2)) as f32;
        }
    }
    (iota, var)
}

/// Estimates the depth map of a group from its flow fields.
///
/// With `params.kalman` the Barron–Ngai–Spies filter described in the module docs runs over the
/// flows in order (each field in its own frame's grid, `frame_index` increasing); otherwise the
/// per-frame depths −f·U/u are moved into the last frame's grid and averaged. Either way the
/// inverse depth is median filtered and the map is in the grid of the last flow's frame.
/// Dropped frames (no confident pixel), missing frame indices, non-finite flows, diverged and
/// unmeasured pixels are reported in `warnings`; unmeasured pixels are NaN.
///
/// # Errors
/// [`StageError`] when there are no flow fields, sizes differ, or params are invalid.
pub fn estimate_depth(
    flows: &[FlowField],
    geom: &Geometry,
    params: &DepthParams,
) -> Result<DepthMap, StageError> {
    validate(params, geom)?;
    let (width, height) = check_flows(flows)?;
    let z_ref = geom.working_distance_um;
    let land_shift_px = geom.focal_px * geom.frame_step_um / z_ref;
    let u_land = -land_shift_px;
    let mut warnings = Vec::new();
    let (iota, var) = if params.kalman {
        let r = params.neighbourhood_px / 2;
        let r2 = (r.max(1) * r.max(1)) as f64;
        let q = f64::from(params.process_noise);
        let filter = Filter {
            width,
            height,
            r,
            land_shift_px,
            noise_var: f64::from(params.measurement_noise_px2) / (u_land * u_land),
            q: [q / r2, q / r2, q],
            p0: [
                INITIAL_VARIANCE / r2,
                INITIAL_VARIANCE / r2,
                INITIAL_VARIANCE,
            ],
        };
        kalman(flows, &filter, params.min_confidence, u_land, &mut warnings)
    } else {
        average(flows, width, height, geom, params, &mut warnings)
    };
    let unmeasured = iota.iter().filter(|v| v.is_nan()).count();
    if unmeasured > 0 {
        warnings.push(format!(
            "{unmeasured} of {} pixels were never measured",
            width * height
        ));
    }
    let mut smooth = vec![f32::NAN; width * height];
    median_filter(&iota, width, height, params.median_px, &mut smooth);
    let mut nonpositive = 0;
    let mut z = vec![f32::NAN; width * height];
    let mut zvar = vec![f32::NAN; width * height];
    for (((zo, vo), &io), &vi) in z.iter_mut().zip(zvar.iter_mut()).zip(&smooth).zip(&var) {
        if io > 0.0 {
            let io = f64::from(io);
            *zo = (z_ref / io) as f32;
            // Z = Z_ref/ι̃ → Var Z = Var ι̃ · Z_ref²/ι̃⁴.
            *vo = (f64::from(vi) * (z_ref / (io * io)).powi(2)) as f32;
        } else if io.is_finite() {
            nonpositive += 1;
        }
    }
    if nonpositive > 0 {
        warnings.push(format!(
            "{nonpositive} pixels have a non-positive inverse depth (flow toward +x) and are NaN"
        ));
    }
    let frame_index = flows.last().map_or(0, |f| f.frame_index);
    let (Some(z_um), Some(variance)) = (
        Image::from_vec(width, height, z),
        Image::from_vec(width, height, zvar),
    ) else {
        return Err(StageError::BadInput {
            stage: STAGE,
            problem: "internal size mismatch".into(),
        });
    };
    Ok(DepthMap {
        z_um,
        variance,
        frame_index,
        warnings,
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // Tests fail loudly on purpose.
mod tests {
    use super::*;
    use crate::pipeline::walls::test_support::{Rng, paper_geometry};

    fn field(u: Image, frame_index: usize) -> FlowField {
        let (w, h) = (u.width, u.height);
        FlowField {
            u,
            v: Image::zeros(w, h),
            confidence: Image::filled(w, h, 1.0),
            iterations: 1,
            converged: true,
            frame_index,
        }
    }

    /// Z seen at pixel (x, y) of frame k on the plane Z = z0 + ax·X_world + ay·Y, where the
    /// camera sits at X = k·U: 1/Z is linear in the pixel coordinates.
    fn plane_z(x: usize, y: usize, k: usize, w: usize, h: usize, g: &Geometry, p: [f64; 3]) -> f64 {
        let [z0, ax, ay] = p;
        let (px, py) = (
            (x as f64 - (w as f64 - 1.0) / 2.0) / g.focal_px,
            (y as f64 - (h as f64 - 1.0) / 2.0) / g.focal_px,
        );
        (z0 + ax * k as f64 * g.frame_step_um) / (1.0 - ax * px - ay * py)
    }

    fn plane_flows(
        w: usize,
        h: usize,
        frames: usize,
        g: &Geometry,
        p: [f64; 3],
        noise_px: f64,
        seed: u64,
    ) -> Vec<FlowField> {
        let mut rng = Rng::new(seed);
        (0..frames)
            .map(|k| {
                let u = Image::from_fn(w, h, |x, y| {
                    let z = plane_z(x, y, k, w, h, g, p);
                    (-g.focal_px * g.frame_step_um / z + noise_px * rng.gauss()) as f32
                });
                field(u, k + 3)
            })
            .collect()
    }

    /// Least-squares slope of Z against Y = (y − cy)·Z/f over the map.
    fn tilt_dz_dy(map: &DepthMap, g: &Geometry) -> f64 {
        let (w, h) = (map.z_um.width, map.z_um.height);
        let (mut n, mut sy, mut sz, mut syy, mut syz) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for y in 0..h {
            for x in 0..w {
                let z = f64::from(map.z_um.get(x, y).unwrap());
                let yy = (y as f64 - (h as f64 - 1.0) / 2.0) * z / g.focal_px;
                n += 1.0;
                sy += yy;
                sz += z;
                syy += yy * yy;
                syz += yy * z;
            }
        }
        (syz - sy * sz / n) / (syy - sy * sy / n)
    }

    fn rel_err(map: &DepthMap, truth: impl Fn(usize, usize) -> f64) -> (f64, f64) {
        let (w, h) = (map.z_um.width, map.z_um.height);
        let (mut max, mut ss, mut n) = (0.0_f64, 0.0, 0.0);
        for y in 0..h {
            for x in 0..w {
                let t = truth(x, y);
                let e = (f64::from(map.z_um.get(x, y).unwrap()) - t) / t;
                max = max.max(e.abs());
                ss += e * e;
                n += 1.0;
            }
        }
        (max, (ss / n).sqrt())
    }

    #[test]
    fn exact_flows_of_a_plane_tilted_across_give_depth_and_tilt() {
        let g = paper_geometry();
        let (w, h) = (96, 64);
        let p = [4000.0, 0.0, 0.8];
        let flows = plane_flows(w, h, 6, &g, p, 0.0, 1);
        for kalman in [true, false] {
            let map = estimate_depth(
                &flows,
                &g,
                &DepthParams {
                    kalman,
                    ..DepthParams::default()
                },
            )
            .unwrap();
            assert_eq!(map.frame_index, 8);
            let (max, _) = rel_err(&map, |x, y| plane_z(x, y, 5, w, h, &g, p));
            assert!(max < 1e-3, "kalman {kalman}: max relative error {max}");
            let tilt = tilt_dz_dy(&map, &g);
            assert!((tilt - 0.8).abs() < 0.008, "kalman {kalman}: tilt {tilt}");
            assert!(
                map.variance.data.iter().all(|v| v.is_finite() && *v >= 0.0),
                "kalman {kalman}"
            );
        }
    }

    #[test]
    fn plane_tilted_along_the_motion_is_tracked_into_the_last_frame() {
        let g = paper_geometry();
        let (w, h) = (80, 40);
        // Z changes by 0.8·U = 0.62 µm per frame under each pixel: a wrong re-indexing or a
        // map left in an earlier frame's grid is off by ≥ 1.5e-4.
        let p = [4000.0, 0.8, 0.3];
        let flows = plane_flows(w, h, 6, &g, p, 0.0, 1);
        let map = estimate_depth(&flows, &g, &DepthParams::default()).unwrap();
        let (max, _) = rel_err(&map, |x, y| plane_z(x, y, 5, w, h, &g, p));
        assert!(max < 2e-5, "max relative error {max}");
        let (max_first, _) = rel_err(&map, |x, y| plane_z(x, y, 0, w, h, &g, p));
        assert!(max_first > 5e-4, "{max_first}");
    }

    #[test]
    fn kalman_over_six_noisy_frames_beats_one_frame() {
        let g = paper_geometry();
        let (w, h) = (120, 80);
        let p = [4000.0, 0.2, 0.8];
        let flows = plane_flows(w, h, 6, &g, p, 0.02, 9);
        // The filter's noise model matches the flows; the plane does not change.
        let params = DepthParams {
            measurement_noise_px2: 0.02 * 0.02,
            process_noise: 1e-9,
            ..DepthParams::default()
        };
        let truth = |x, y| plane_z(x, y, 5, w, h, &g, p);
        let (_, rms6) = rel_err(&estimate_depth(&flows, &g, &params).unwrap(), truth);
        let (_, rms1) = rel_err(&estimate_depth(&flows[5..], &g, &params).unwrap(), truth);
        let raw = DepthMap {
            z_um: Image::from_fn(w, h, |x, y| {
                depth_from_flow_um(flows[5].u.get(x, y).unwrap(), &g)
            }),
            variance: Image::zeros(w, h),
            frame_index: 8,
            warnings: Vec::new(),
        };
        let (_, rms_raw) = rel_err(&raw, truth);
        assert!(rms6 < 0.6 * rms1, "6 frames {rms6}, 1 frame {rms1}");
        assert!(rms1 < rms_raw, "1 frame {rms1}, raw {rms_raw}");
        let avg = DepthParams {
            kalman: false,
            ..params
        };
        let (_, rms_avg) = rel_err(&estimate_depth(&flows, &g, &avg).unwrap(), truth);
        assert!(rms_avg < rms_raw, "average {rms_avg}, raw {rms_raw}");
    }

    #[test]
    fn dropped_frames_and_unmeasured_pixels_are_warnings() {
        let g = paper_geometry();
        let (w, h) = (40, 30);
        let mut flows = plane_flows(w, h, 4, &g, [4000.0, 0.0, 0.0], 0.0, 1);
        flows[1].confidence = Image::zeros(w, h);
        flows[3].frame_index += 2;
        for f in &mut flows {
            for y in 0..h {
                for x in w - 10..w {
                    f.confidence.data[y * w + x] = 0.0;
                }
            }
        }
        flows[2].u.data[w * 15 + 20] = f32::NAN;
        let map = estimate_depth(&flows, &g, &DepthParams::default()).unwrap();
        let all = map.warnings.join("\n");
        assert!(all.contains("flow 1 (frame 4) dropped"), "{all}");
        assert!(all.contains("missing"), "{all}");
        assert!(all.contains("never measured"), "{all}");
        assert!(all.contains("non-finite flow"), "{all}");
        assert_eq!(map.frame_index, 8);
        // New content enters at the right, where nothing is ever confident.
        assert!(map.z_um.get(w - 3, 15).unwrap().is_nan());
        let z = map.z_um.get(10, 15).unwrap();
        assert!((z - 4000.0).abs() < 0.1, "{z}");
    }

    #[test]
    fn bad_input_and_params_are_errors() {
        let g = paper_geometry();
        let flows = plane_flows(20, 10, 3, &g, [4000.0, 0.0, 0.0], 0.0, 1);
        let p = DepthParams::default();
        assert!(matches!(
            estimate_depth(&[], &g, &p),
            Err(StageError::BadInput { .. })
        ));
        let mut rev = flows.clone();
        rev.swap(0, 2);
        assert!(matches!(
            estimate_depth(&rev, &g, &p),
            Err(StageError::BadInput { .. })
        ));
        let mut odd = flows.clone();
        odd[1].confidence = Image::zeros(21, 10);
        assert!(matches!(
            estimate_depth(&odd, &g, &p),
            Err(StageError::BadInput { .. })
        ));
        for bad in [
            DepthParams {
                median_px: 4,
                ..p.clone()
            },
            DepthParams {
                neighbourhood_px: 0,
                ..p.clone()
            },
            DepthParams {
                measurement_noise_px2: f32::NAN,
                ..p.clone()
            },
            DepthParams {
                process_noise: -1.0,
                ..p.clone()
            },
        ] {
            assert!(matches!(
                estimate_depth(&flows, &g, &bad),
                Err(StageError::InvalidParam { .. })
            ));
        }
        let no_step = Geometry {
            frame_step_um: 0.0,
            ..g
        };
        assert!(matches!(
            estimate_depth(&flows, &no_step, &p),
            Err(StageError::InvalidParam { .. })
        ));
    }

    #[test]
    fn depth_from_flow_matches_the_land() {
        let g = paper_geometry();
        let z = depth_from_flow_um(g.land_flow_px() as f32, &g);
        assert!((z - 4000.0).abs() < 1e-2, "{z}");
        assert!(depth_from_flow_um(0.5, &g).is_nan());
    }
}
