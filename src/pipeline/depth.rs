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
//! weighted least-squares information J = Σ w·h·hᵀ/R, b = Σ w·m·h/R (h = (dx, dy, 1)) is summed
//! separably (vertical moments per column, then along the row): directly in f32 for windows up
//! to 9×9, by running and prefix sums in f64 for wider ones. The update is the information-form
//! Kalman step Λ⁺ = P⁻¹ + J, µ⁺ = (Λ⁺)⁻¹·(P⁻¹·µ + b).
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
use crate::image::{Image, zeros_par};
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
/// Values of the per-pixel state: α̃, β̃, ι̃, then the covariance P00 P01 P02 P11 P12 P22.
const PLANES: usize = 9;
/// Index of ι̃ in the state.
const IOTA: usize = 2;
/// Index of Var ι̃ (P22) in the state.
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
#[derive(Default)]
struct Measurements {
    w: Vec<f32>,
    wm: Vec<f32>,
    /// Pixels with enough confidence.
    valid: usize,
    /// Confident pixels whose flow is not finite.
    bad_flow: usize,
}

/// Pixels per parallel work item of the per-pixel passes.
const CHUNK_PX: usize = 1 << 14;

impl Measurements {
    /// Fills the weights (confidence / mean confidence, 0 below `min_confidence`) and
    /// w·u/u_land of one flow field, reusing the buffers.
    fn fill(&mut self, flow: &FlowField, u_land: f64, min_confidence: f32) {
        let usable = |u: f32, c: f32| c.is_finite() && c >= min_confidence && u.is_finite();
        let (sum, valid, bad_flow) = flow
            .u
            .data
            .par_chunks(CHUNK_PX)
            .zip(flow.confidence.data.par_chunks(CHUNK_PX))
            .map(|(us, cs)| {
                let (mut sum, mut valid, mut bad) = (0.0_f64, 0_usize, 0_usize);
                for (&u, &c) in us.iter().zip(cs) {
                    if usable(u, c) {
                        sum += f64::from(c);
                        valid += 1;
                    } else if c.is_finite() && c >= min_confidence {
                        bad += 1;
                    }
                }
                (sum, valid, bad)
            })
            // Summed in chunk order: a parallel reduce adds in whatever order the threads
            // split the work, and the last bits of the sum would vary from run to run.
            .collect::<Vec<_>>()
            .into_iter()
            .fold((0.0, 0, 0), |a, b| (a.0 + b.0, a.1 + b.1, a.2 + b.2));
        // Weights are relative to the mean confidence; all-zero confidences weigh 1 each.
        let scale = if sum > 0.0 {
            (valid as f64 / sum) as f32
        } else {
            0.0
        };
        let inv_u_land = (1.0 / u_land) as f32;
        let n = flow.u.data.len();
        self.w.resize(n, 0.0);
        self.wm.resize(n, 0.0);
        self.w
            .par_chunks_mut(CHUNK_PX)
            .zip(self.wm.par_chunks_mut(CHUNK_PX))
            .zip(flow.u.data.par_chunks(CHUNK_PX))
            .zip(flow.confidence.data.par_chunks(CHUNK_PX))
            .for_each(|(((ws, wms), us), cs)| {
                for (((w, wm), &u), &c) in ws.iter_mut().zip(wms.iter_mut()).zip(us).zip(cs) {
                    (*w, *wm) = if usable(u, c) {
                        let wv = if scale > 0.0 { c * scale } else { 1.0 };
                        (wv, wv * u * inv_u_land)
                    } else {
                        (0.0, 0.0)
                    };
                }
            });
        self.valid = valid;
        self.bad_flow = bad_flow;
    }
}

/// One pixel's state: α̃, β̃, ι̃, then the covariance P00 P01 P02 P11 P12 P22.
type Cell = [f32; PLANES];

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

/// Rows per parallel work item of the filter (the vertical window sums slide down a band).
const BAND_ROWS: usize = 32;

/// Vertical window sums of one column over absolute rows Y: Σw, Σw·Y, Σw·Y², Σwm, Σwm·Y.
type ColumnSums = [f64; 5];

impl Filter {
    /// The prior state of one pixel.
    fn prior(&self) -> Cell {
        let p0 = self.p0.map(|v| v as f32);
        [0.0, 0.0, 1.0, p0[0], 0.0, 0.0, p0[1], 0.0, p0[2]]
    }

    /// Adds (`sign` = 1) or removes (−1) row `yy` of the weights to the column sums.
    #[inline(always)]
    fn slide(&self, vs: &mut [ColumnSums], meas: &Measurements, yy: usize, sign: f64) {
        let w = self.width;
        let (Some(wr), Some(mr)) = (
            meas.w.get(yy * w..(yy + 1) * w),
            meas.wm.get(yy * w..(yy + 1) * w),
        ) else {
            return;
        };
        let yf = yy as f64;
        for ((c, &wv), &mv) in vs.iter_mut().zip(wr).zip(mr) {
            let (wv, mv) = (sign * f64::from(wv), sign * f64::from(mv));
            c[0] += wv;
            c[1] += wv * yf;
            c[2] += wv * yf * yf;
            c[3] += mv;
            c[4] += mv * yf;
        }
    }

    /// Whether the window is narrow enough (r ≤ [`DIRECT_WINDOW_MAX_R`]) to be summed directly
    /// ([`Filter::direct_info`]) rather than by running sums ([`Filter::prefix_info`]).
    fn sums_directly(&self) -> bool {
        self.r <= DIRECT_WINDOW_MAX_R
    }

    /// The measurement information of row `y` summed directly over the (2r+1)² window in f32
    /// (r ≤ [`DIRECT_WINDOW_MAX_R`]): the vertical moments of each column relative to row y,
    /// then the horizontal sums of those relative to each pixel. Pixels outside the image
    /// weigh 0. Fills `sc.info` (zeroed by the caller).
    #[inline(always)]
    fn direct_info(&self, y: usize, meas: &Measurements, sc: &mut SweepScratch) {
        let (w, h, r) = (self.width, self.height, self.r);
        let inv_r = (1.0 / self.noise_var) as f32;
        let padded = w + 2 * r;
        sc.moments.clear();
        sc.moments.resize(5 * padded, 0.0);
        let [m0, m1, m2, m3, m4] = split5(&mut sc.moments, padded);
        for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
            let (Some(wr), Some(mr)) = (
                meas.w.get(yy * w..(yy + 1) * w),
                meas.wm.get(yy * w..(yy + 1) * w),
            ) else {
                continue;
            };
            let dy = yy as f32 - y as f32;
            let cols = m0[r..r + w]
                .iter_mut()
                .zip(&mut m1[r..r + w])
                .zip(&mut m2[r..r + w])
                .zip(&mut m3[r..r + w])
                .zip(&mut m4[r..r + w]);
            for (((((c0, c1), c2), c3), c4), (&wv, &mv)) in cols.zip(wr.iter().zip(mr)) {
                *c0 += wv;
                *c1 += dy * wv;
                *c2 += dy * dy * wv;
                *c3 += mv;
                *c4 += dy * mv;
            }
        }
        // info block p accumulates Σ_dx weight(dx)·moment[x + dx] for its moment and dx power:
        // (αα: dx², Σw), (αβ: dx, Σw·dy), (αι: dx, Σw), (ββ: 1, Σw·dy²), (βι: 1, Σw·dy),
        // (ιι: 1, Σw), (α: dx, Σwm), (β: 1, Σwm·dy), (ι: 1, Σwm).
        let terms: [(u32, &[f32]); 9] = [
            (2, m0),
            (1, m1),
            (1, m0),
            (0, m2),
            (0, m1),
            (0, m0),
            (1, m3),
            (0, m4),
            (0, m3),
        ];
        for (out, (power, moment)) in sc.info.chunks_exact_mut(w).zip(terms) {
            for dx in 0..=2 * r {
                let d = dx as f32 - r as f32;
                let f = d.powi(power as i32);
                if let Some(src) = moment.get(dx..dx + w) {
                    for (o, &m) in out.iter_mut().zip(src) {
                        *o += f * m;
                    }
                }
            }
            for o in out.iter_mut() {
                *o *= inv_r;
            }
        }
    }

    /// The measurement information of row `y` from the column sums `vs` slid down the band
    /// (absolute rows), by prefix sums along the row in f64: for any window size. Fills
    /// `sc.info` (zeroed by the caller) where the window holds weight.
    fn prefix_info(&self, y: usize, vs: &[ColumnSums], sc: &mut SweepScratch) {
        let (w, r) = (self.width, self.r);
        let yf = y as f64;
        let inv_r = 1.0 / self.noise_var;
        // Prefix sums along the row of the column sums taken relative to row y
        // (Σw, Σw·dy, Σw·dy², Σwm, Σwm·dy), weighted by the absolute column X and X²:
        // pre[X] = Σ_{X′<X} [c0, c0·X′, c0·X′², c1, c1·X′, c2, c3, c3·X′, c4].
        sc.prefix.clear();
        sc.prefix.reserve(w + 1);
        let mut acc = [0.0_f64; 9];
        sc.prefix.push(acc);
        for (xc, c) in vs.iter().enumerate() {
            let xf = xc as f64;
            let c1 = c[1] - yf * c[0];
            let c2 = c[2] - 2.0 * yf * c[1] + yf * yf * c[0];
            let c4 = c[4] - yf * c[3];
            let terms = [
                c[0],
                c[0] * xf,
                c[0] * xf * xf,
                c1,
                c1 * xf,
                c2,
                c[3],
                c[3] * xf,
                c4,
            ];
            for (a, v) in acc.iter_mut().zip(terms) {
                *a += v;
            }
            sc.prefix.push(acc);
        }
        // Window sums over x − r ..= x + r, moved to dx = X − x:
        // Σc·dx = T1 − x·T0, Σc·dx² = T2 − 2x·T1 + x²·T0. Then
        // J = Σ w·h·hᵀ/R packed (αα, αβ, αι, ββ, βι, ιι) and b = Σ w·m·h/R.
        for x in 0..w {
            let (Some(hi), Some(lo)) = (
                sc.prefix.get((x + r + 1).min(w)),
                sc.prefix.get(x.saturating_sub(r)),
            ) else {
                continue;
            };
            let t: [f64; 9] = std::array::from_fn(|i| hi[i] - lo[i]);
            if t[0] > 0.0 {
                let xf = x as f64;
                let v = [
                    t[2] - 2.0 * xf * t[1] + xf * xf * t[0],
                    t[4] - xf * t[3],
                    t[1] - xf * t[0],
                    t[5],
                    t[3],
                    t[0],
                    t[7] - xf * t[6],
                    t[8],
                    t[6],
                ];
                for (p, e) in v.into_iter().enumerate() {
                    if let Some(d) = sc.info.get_mut(p * w + x) {
                        *d = (e * inv_r) as f32;
                    }
                }
            }
        }
    }

    /// One row of frame `f`: prediction from the previous frame (when `f.steps` is Some) fused
    /// with the measurement update from the window about row `y` (`vs`: that frame's column
    /// sums, read only for windows too wide to sum directly). Returns the number of diverged
    /// predictions.
    ///
    /// `row` holds the row's state planar: one block of w values per state term.
    ///
    /// Phase A: each pixel's information J and b ([`Filter::direct_info`] or
    /// [`Filter::prefix_info`]), and from the old state its source position
    /// x + f·U·ι·steps. Phase B then predicts and updates [`LANES`] pixels at a time in f32
    /// lanes; it overwrites the state in place, which is safe because content moves toward −x:
    /// a pixel's sources lie at or right of it and are read before its block is written.
    #[inline(always)]
    fn sweep_row(
        &self,
        y: usize,
        row: &mut [f32],
        f: &FrameInput,
        vs: &[ColumnSums],
        sc: &mut SweepScratch,
    ) -> usize {
        let w = self.width;
        let (steps, measured) = (f.steps, f.measured());
        let k = self.land_shift_px * steps.unwrap_or(0.0);
        // Phase A.
        sc.info.clear();
        sc.info.resize(9 * w, 0.0);
        if measured && self.sums_directly() {
            self.direct_info(y, &f.meas, sc);
        } else if measured {
            self.prefix_info(y, vs, sc);
        }
        sc.src.clear();
        if steps.is_some() {
            let iotas = row.get(IOTA * w..(IOTA + 1) * w).unwrap_or_default();
            for x in 0..w {
                let iota = iotas.get(x).map_or(f64::NAN, |&v| f64::from(v));
                let xs = x as f64 + k * iota;
                let i0 = xs.floor();
                // The source lies at or right of x; anything else (new content entering at the
                // right edge, a broken state) restarts from the prior.
                let ok = i0 >= x as f64 && i0 + 1.0 < w as f64;
                sc.src.push(if ok {
                    (i0 as u32, (xs - i0) as f32)
                } else {
                    (u32::MAX, 0.0)
                });
            }
        }
        // Phase B.
        let prior = self.prior();
        let mut diverged = 0;
        let mut x0 = 0;
        while x0 < w {
            let n = LANES.min(w - x0);
            let mut st: [Lane; PLANES] = std::array::from_fn(|p| [prior[p]; LANES]);
            let mut info = [[0.0_f32; LANES]; 9];
            let mut fresh = [true; LANES];
            if steps.is_some() {
                let srcs = sc.src.get(x0..x0 + n).unwrap_or_default();
                // Usually every lane reads the same offset d: cells x0 + d + l and the next.
                let d = srcs
                    .first()
                    .map_or(w, |&(i, _)| (i as usize).saturating_sub(x0));
                let uniform = n == LANES
                    && x0.saturating_add(d).saturating_add(LANES) < w
                    && srcs
                        .iter()
                        .enumerate()
                        .all(|(l, &(i, _))| i as usize == x0 + d + l);
                if uniform {
                    let t: Lane = std::array::from_fn(|l| srcs.get(l).map_or(0.0, |s| s.1));
                    for (p, s) in st.iter_mut().enumerate() {
                        let at = p * w + x0 + d;
                        if let (Some(a), Some(b)) =
                            (row.get(at..at + LANES), row.get(at + 1..at + 1 + LANES))
                        {
                            *s = lanes(|l| a[l] + (b[l] - a[l]) * t[l]);
                        }
                    }
                    fresh = [false; LANES];
                } else {
                    for (l, &(i, tt)) in srcs.iter().enumerate() {
                        let i = i as usize;
                        if i == u32::MAX as usize || i + 1 >= w {
                            continue;
                        }
                        for (p, s) in st.iter_mut().enumerate() {
                            if let (Some(&a), Some(&b)) =
                                (row.get(p * w + i), row.get(p * w + i + 1))
                            {
                                s[l] = a + (b - a) * tt;
                            }
                        }
                        fresh[l] = false;
                    }
                }
            } else {
                for (p, s) in st.iter_mut().enumerate() {
                    if let Some(src) = row.get(p * w + x0..p * w + x0 + n) {
                        s[..n].copy_from_slice(src);
                    }
                }
                fresh[..n].fill(false);
            }
            for (p, d) in info.iter_mut().enumerate() {
                if let Some(src) = sc.info.get(p * w + x0..p * w + x0 + n) {
                    d[..n].copy_from_slice(src);
                }
            }
            if let Some(steps) = steps {
                diverged += predict_lanes(
                    &mut st,
                    &fresh,
                    k as f32,
                    self.q.map(|q| (q * steps) as f32),
                    &prior,
                );
            }
            if measured {
                update_lanes(&mut st, &info);
            }
            for (p, s) in st.iter().enumerate() {
                if let Some(dst) = row.get_mut(p * w + x0..p * w + x0 + n) {
                    dst.copy_from_slice(&s[..n]);
                }
            }
            x0 += LANES;
        }
        diverged
    }

    /// A band of rows starting at `y0` through every frame: row by row, the row's state runs
    /// through the frames in order (for wide windows, each frame's column sums slide down the
    /// band with it), so only one row of state is kept and it stays in cache. Rows never
    /// exchange state (content moves along x only), so this is the same arithmetic, in the same
    /// order per row and frame, as sweeping the whole image one frame at a time. Writes ι̃ and
    /// Var ι̃ of the band (NaN where never measured) and returns the number of diverged
    /// predictions. Runs the AVX2 build of the same code where the CPU has it (no FMA, so the
    /// results are identical).
    fn band(
        &self,
        y0: usize,
        frames: &[FrameInput],
        out: (&mut [f32], &mut [f32]),
        sc: &mut SweepScratch,
    ) -> usize {
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU reported AVX2, all that `band_avx2` requires.
                return unsafe { self.band_avx2(y0, frames, out, sc) };
            }
        }
        self.band_impl(y0, frames, out, sc)
    }

    /// [`Filter::band_impl`] compiled for AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn band_avx2(
        &self,
        y0: usize,
        frames: &[FrameInput],
        out: (&mut [f32], &mut [f32]),
        sc: &mut SweepScratch,
    ) -> usize {
        self.band_impl(y0, frames, out, sc)
    }

    /// See [`Filter::band`].
    #[inline(always)]
    fn band_impl(
        &self,
        y0: usize,
        frames: &[FrameInput],
        (iota, var): (&mut [f32], &mut [f32]),
        sc: &mut SweepScratch,
    ) -> usize {
        let (w, h, r) = (self.width, self.height, self.r);
        // Column sums slid down the band: only for windows too wide to sum directly.
        let slid = |f: &FrameInput| f.measured() && !self.sums_directly();
        let mut vs = std::mem::take(&mut sc.vs);
        vs.resize_with(frames.len(), Vec::new);
        for (sums, f) in vs.iter_mut().zip(frames) {
            sums.clear();
            if slid(f) {
                sums.resize(w, [0.0; 5]);
                for yy in y0.saturating_sub(r)..(y0 + r).min(h) {
                    self.slide(sums, &f.meas, yy, 1.0);
                }
            }
        }
        let prior = self.prior();
        let mut row = std::mem::take(&mut sc.row);
        let limit = (UNMEASURED_SHARE * INITIAL_VARIANCE) as f32;
        let mut diverged = 0;
        for (i, (io_row, var_row)) in iota.chunks_mut(w).zip(var.chunks_mut(w)).enumerate() {
            let y = y0 + i;
            row.clear();
            for &p in &prior {
                row.resize(row.len() + w, p);
            }
            for (sums, f) in vs.iter_mut().zip(frames) {
                if slid(f) {
                    if y + r < h {
                        self.slide(sums, &f.meas, y + r, 1.0);
                    }
                    if i > 0 && y > r {
                        self.slide(sums, &f.meas, y - r - 1, -1.0);
                    }
                }
                diverged += self.sweep_row(y, &mut row, f, sums, sc);
            }
            let (Some(is), Some(vs)) = (
                row.get(IOTA * w..(IOTA + 1) * w),
                row.get(VAR_IOTA * w..(VAR_IOTA + 1) * w),
            ) else {
                continue;
            };
            for (((o, ov), &i), &v) in io_row.iter_mut().zip(var_row.iter_mut()).zip(is).zip(vs) {
                (*o, *ov) = if v.is_finite() && v < limit && i.is_finite() {
                    (i, v)
                } else {
                    (f32::NAN, f32::NAN)
                };
            }
        }
        sc.vs = vs;
        sc.row = row;
        diverged
    }
}

/// One flow field as the filter reads it: its measurements and the frame steps since the
/// previous field (None for the first).
struct FrameInput {
    meas: Measurements,
    steps: Option<f64>,
}

impl FrameInput {
    fn measured(&self) -> bool {
        self.meas.valid > 0
    }
}

/// Largest neighbourhood half-side whose window sums are taken directly in f32 (O(r) work per
/// pixel); larger windows use running sums in f64.
const DIRECT_WINDOW_MAX_R: usize = 4;

/// The five consecutive blocks of length `n` at the start of `v`.
fn split5(v: &mut [f32], n: usize) -> [&mut [f32]; 5] {
    let (a, rest) = v.split_at_mut(n);
    let (b, rest) = rest.split_at_mut(n);
    let (c, rest) = rest.split_at_mut(n);
    let (d, rest) = rest.split_at_mut(n);
    let (e, _) = rest.split_at_mut(n);
    [a, b, c, d, e]
}

/// Pixels predicted and updated together (f32 lanes the compiler maps onto SIMD registers).
const LANES: usize = 8;
/// One value for each pixel of a block.
type Lane = [f32; LANES];

/// Per-thread buffers of the row sweeps.
#[derive(Default)]
struct SweepScratch {
    /// Per frame: vertical window sums per column (wide windows only).
    vs: Vec<Vec<ColumnSums>>,
    /// The state of the row being filtered, planar.
    row: Vec<f32>,
    /// J (αα, αβ, αι, ββ, βι, ιι) and b (α, β, ι) of this frame, one block of the row's
    /// pixels each.
    info: Vec<f32>,
    /// Per column (padded by r zero columns each side): the window's vertical moments
    /// Σw, Σw·dy, Σw·dy², Σwm, Σwm·dy, one block each (direct window sums).
    moments: Vec<f32>,
    /// Per pixel: source cell and interpolation weight of the prediction (u32::MAX: prior).
    src: Vec<(u32, f32)>,
    /// Prefix sums along the row of the window moments.
    prefix: Vec<[f64; 9]>,
}

/// A lane-wise map: `f` applied to every lane index (written so the compiler emits SIMD).
#[inline(always)]
fn lanes(f: impl Fn(usize) -> f32) -> Lane {
    std::array::from_fn(f)
}

/// The plane transform and process noise on a block of interpolated states (module docs):
/// α′ = s·α, β′ = s·β, ι′ = ι with s = 1/(1 − k·α), P′ = F·P·Fᵀ + Q. Lanes marked `fresh` hold
/// the prior and are left alone; diverged lanes (1 − k·α < `MIN_PLANE_SCALE`) are reset to the
/// prior. Returns the number of diverged lanes.
#[inline(always)]
fn predict_lanes(
    st: &mut [Lane; PLANES],
    fresh: &[bool; LANES],
    k: f32,
    q: [f32; 3],
    prior: &Cell,
) -> usize {
    let [al, be, io, p00, p01, p02, p11, p12, p22] = *st;
    let den = lanes(|l| 1.0 - k * al[l]);
    let s = lanes(|l| 1.0 / den[l]);
    let s2 = lanes(|l| s[l] * s[l]);
    let c = lanes(|l| be[l] * k * s2[l]);
    let new: [Lane; PLANES] = [
        lanes(|l| s[l] * al[l]),
        lanes(|l| s[l] * be[l]),
        io,
        lanes(|l| s2[l] * s2[l] * p00[l] + q[0]),
        lanes(|l| s2[l] * (c[l] * p00[l] + s[l] * p01[l])),
        lanes(|l| s2[l] * p02[l]),
        lanes(|l| c[l] * c[l] * p00[l] + 2.0 * c[l] * s[l] * p01[l] + s2[l] * p11[l] + q[1]),
        lanes(|l| c[l] * p02[l] + s[l] * p12[l]),
        lanes(|l| p22[l] + q[2]),
    ];
    let ok: [bool; LANES] = std::array::from_fn(|l| den[l] >= MIN_PLANE_SCALE as f32);
    for ((dst, nw), &pr) in st.iter_mut().zip(&new).zip(prior) {
        *dst = lanes(|l| {
            if fresh[l] {
                dst[l]
            } else if ok[l] {
                nw[l]
            } else {
                pr
            }
        });
    }
    (0..LANES).filter(|&l| !ok[l] && !fresh[l]).count()
}

/// Inverse of packed symmetric 3×3 matrices, lane-wise, scaled by the trace so that f32 copes
/// with any magnitude; zero (and a false flag) where the matrix is not invertible.
#[inline(always)]
fn inv_sym3_lanes(m: &[Lane; 6]) -> ([Lane; 6], [bool; LANES]) {
    let sc = lanes(|l| 1.0 / (m[0][l] + m[3][l] + m[5][l]));
    let a = lanes(|l| m[0][l] * sc[l]);
    let b = lanes(|l| m[1][l] * sc[l]);
    let c = lanes(|l| m[2][l] * sc[l]);
    let d = lanes(|l| m[3][l] * sc[l]);
    let e = lanes(|l| m[4][l] * sc[l]);
    let f = lanes(|l| m[5][l] * sc[l]);
    let c00 = lanes(|l| d[l] * f[l] - e[l] * e[l]);
    let c01 = lanes(|l| c[l] * e[l] - b[l] * f[l]);
    let c02 = lanes(|l| b[l] * e[l] - c[l] * d[l]);
    let det = lanes(|l| a[l] * c00[l] + b[l] * c01[l] + c[l] * c02[l]);
    let ok: [bool; LANES] = std::array::from_fn(|l| det[l] > 0.0 && det[l] < f32::INFINITY);
    let g = lanes(|l| if ok[l] { sc[l] / det[l] } else { 0.0 });
    let inv = [
        lanes(|l| c00[l] * g[l]),
        lanes(|l| c01[l] * g[l]),
        lanes(|l| c02[l] * g[l]),
        lanes(|l| (a[l] * f[l] - c[l] * c[l]) * g[l]),
        lanes(|l| (b[l] * c[l] - a[l] * e[l]) * g[l]),
        lanes(|l| (a[l] * d[l] - b[l] * b[l]) * g[l]),
    ];
    (inv, ok)
}

/// Packed symmetric 3×3 times a vector, lane-wise.
#[inline(always)]
fn mul_sym3_lanes(m: &[Lane; 6], v: &[Lane; 3]) -> [Lane; 3] {
    let [x, y, z] = v;
    [
        lanes(|l| m[0][l] * x[l] + m[1][l] * y[l] + m[2][l] * z[l]),
        lanes(|l| m[1][l] * x[l] + m[3][l] * y[l] + m[4][l] * z[l]),
        lanes(|l| m[2][l] * x[l] + m[4][l] * y[l] + m[5][l] * z[l]),
    ]
}

/// The information-form measurement update on a block: Λ⁺ = P⁻¹ + J,
/// µ⁺ = (Λ⁺)⁻¹·(P⁻¹·µ + b). Lanes without a measurement (J_ιι = 0) or with a singular
/// posterior keep their prior; a non-finite prior carries no information.
#[inline(always)]
fn update_lanes(st: &mut [Lane; PLANES], info: &[Lane; 9]) {
    let [a0, a1, a2, p0, p1, p2, p3, p4, p5] = *st;
    let fin = lanes(|l| {
        if a0[l].is_finite() && a1[l].is_finite() && a2[l].is_finite() {
            1.0
        } else {
            0.0
        }
    });
    let mu = [
        lanes(|l| if fin[l] > 0.0 { a0[l] } else { 0.0 }),
        lanes(|l| if fin[l] > 0.0 { a1[l] } else { 0.0 }),
        lanes(|l| if fin[l] > 0.0 { a2[l] } else { 0.0 }),
    ];
    // A non-finite prior carries no information (its Λ is zeroed).
    let (lam, _) = inv_sym3_lanes(&[p0, p1, p2, p3, p4, p5]);
    let mut post = lam;
    for (pr, jr) in post.iter_mut().zip(info) {
        *pr = lanes(|l| pr[l] * fin[l] + jr[l]);
    }
    let mut lmu = mul_sym3_lanes(&lam, &mu);
    for (lr, br) in lmu.iter_mut().zip(&info[6..]) {
        *lr = lanes(|l| lr[l] * fin[l] + br[l]);
    }
    let (p_post, ok) = inv_sym3_lanes(&post);
    let mu_post = mul_sym3_lanes(&p_post, &lmu);
    let take: [bool; LANES] = std::array::from_fn(|l| ok[l] && info[5][l] > 0.0);
    for (dst, nw) in st.iter_mut().zip(mu_post.iter().chain(&p_post)) {
        *dst = lanes(|l| if take[l] { nw[l] } else { dst[l] });
    }
}

/// Pixels filtered together by the median network (one SIMD-friendly block).
const MEDIAN_LANES: usize = 8;
/// Largest window (m²) handled by the network; larger ones use selection per pixel.
const MAX_NETWORK_INPUTS: usize = 49;

/// A selection network that leaves the median of `n` inputs at `target`: Batcher's odd–even
/// merge sort on `n` inputs padded to a power of two with −∞ (the first slots) and +∞, with
/// the comparators that touch a pad resolved while it is built (they are no-ops or relabel
/// the slots), then pruned to the comparators the median depends on. It works on the `n`
/// inputs alone (5×5: 114 comparators instead of the 191 of the padded sort).
struct MedianNetwork {
    n: usize,
    target: usize,
    /// (low, high): the smaller value goes to `low`, the larger to `high`; both < `n`.
    pairs: Vec<(usize, usize)>,
}

impl MedianNetwork {
    fn new(n: usize) -> Self {
        #[derive(Clone, Copy, PartialEq)]
        enum Slot {
            Low,
            Input(usize),
            High,
        }
        let size = n.next_power_of_two();
        let lo_pad = (size - n) / 2;
        let mut slots: Vec<Slot> = (0..size)
            .map(|s| match s.checked_sub(lo_pad) {
                None => Slot::Low,
                Some(i) if i < n => Slot::Input(i),
                Some(_) => Slot::High,
            })
            .collect();
        let mut pairs = Vec::new();
        let mut p = 1;
        while p < size {
            let mut k = p;
            while k >= 1 {
                let mut j = k % p;
                while j + k < size {
                    for i in 0..k.min(size - j - k) {
                        let (a, b) = (i + j, i + j + k);
                        if a / (2 * p) != b / (2 * p) {
                            continue;
                        }
                        let (Some(&sa), Some(&sb)) = (slots.get(a), slots.get(b)) else {
                            continue;
                        };
                        match (sa, sb) {
                            (Slot::Input(x), Slot::Input(y)) => pairs.push((x, y)),
                            // Already in order: nothing moves.
                            (Slot::Low, _) | (_, Slot::High) => {}
                            // Out of order: the values swap slots.
                            _ => slots.swap(a, b),
                        }
                    }
                    j += 2 * k;
                }
                k /= 2;
            }
            p *= 2;
        }
        let target = match slots.get(lo_pad + n / 2) {
            Some(&Slot::Input(t)) => t,
            _ => 0,
        };
        let mut needed = vec![false; n];
        if let Some(t) = needed.get_mut(target) {
            *t = true;
        }
        let mut kept: Vec<(usize, usize)> = Vec::new();
        for &(a, b) in pairs.iter().rev() {
            let hit =
                needed.get(a).copied().unwrap_or(false) || needed.get(b).copied().unwrap_or(false);
            if hit {
                for i in [a, b] {
                    if let Some(nd) = needed.get_mut(i) {
                        *nd = true;
                    }
                }
                kept.push((a, b));
            }
        }
        kept.reverse();
        Self {
            n,
            target,
            pairs: kept,
        }
    }

    /// Medians of `MEDIAN_LANES` pixels whose windows were loaded into `v[..n]` (finite values
    /// only); None when `v` is shorter. Runs on AVX2 where the CPU has it (same results).
    fn run(&self, v: &mut [[f32; MEDIAN_LANES]]) -> Option<[f32; MEDIAN_LANES]> {
        let v = v.get_mut(..self.n)?;
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU reported AVX2, all that `run_avx2` requires.
                unsafe { self.run_avx2(v) };
                return v.get(self.target).copied();
            }
        }
        self.run_portable(v)
    }

    /// The comparators in plain code (the compiler vectorises the lanes).
    fn run_portable(&self, v: &mut [[f32; MEDIAN_LANES]]) -> Option<[f32; MEDIAN_LANES]> {
        for &(a, b) in &self.pairs {
            let (Some(&va), Some(&vb)) = (v.get(a), v.get(b)) else {
                return None;
            };
            // Finite inputs only, so the plain comparisons are exact min/max.
            let lo: [f32; MEDIAN_LANES] =
                std::array::from_fn(|l| if va[l] < vb[l] { va[l] } else { vb[l] });
            let hi: [f32; MEDIAN_LANES] =
                std::array::from_fn(|l| if va[l] < vb[l] { vb[l] } else { va[l] });
            if let Some(s) = v.get_mut(a) {
                *s = lo;
            }
            if let Some(s) = v.get_mut(b) {
                *s = hi;
            }
        }
        v.get(self.target).copied()
    }

    /// The comparators on AVX2 registers, the same choices as
    /// [`MedianNetwork::run_portable`] (min keeps the second value on a tie, max the first).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn run_avx2(&self, v: &mut [[f32; MEDIAN_LANES]]) {
        use std::arch::x86_64::{_mm256_loadu_ps, _mm256_max_ps, _mm256_min_ps, _mm256_storeu_ps};
        const { assert!(MEDIAN_LANES == 8) };

        for &(a, b) in &self.pairs {
            let (Some(va), Some(vb)) = (v.get(a), v.get(b)) else {
                return;
            };
            // SAFETY: `va` and `vb` are 8 f32 each, as the unaligned loads read.
            let (x, y) = unsafe { (_mm256_loadu_ps(va.as_ptr()), _mm256_loadu_ps(vb.as_ptr())) };
            if let Some(d) = v.get_mut(a) {
                // SAFETY: 8 f32, as the unaligned store writes.
                unsafe { _mm256_storeu_ps(d.as_mut_ptr(), _mm256_min_ps(x, y)) };
            }
            if let Some(d) = v.get_mut(b) {
                // SAFETY: as above.
                unsafe { _mm256_storeu_ps(d.as_mut_ptr(), _mm256_max_ps(y, x)) };
            }
        }
    }
}

/// Median of the finite values in the window of half-sides (rx, ry) about (x, y), by selection.
fn median_select(
    v: &[f32],
    width: usize,
    x: usize,
    y: usize,
    rx: usize,
    ry: usize,
    buf: &mut Vec<f32>,
) -> f32 {
    buf.clear();
    for yy in y - ry..=y + ry {
        let base = yy * width + x;
        if let Some(s) = v.get(base - rx..=base + rx) {
            buf.extend(s.iter().copied().filter(|e| e.is_finite()));
        }
    }
    if buf.is_empty() {
        return f32::NAN;
    }
    let mid = buf.len() / 2;
    let (_, med, _) = buf.select_nth_unstable_by(mid, f32::total_cmp);
    *med
}

/// Median filter (side `m`, NaN-aware) of `v` → `out`; NaN where the window holds no finite
/// value. Near the borders the window shrinks symmetrically about the pixel, so a linear ramp
/// is left unbiased. Interior blocks of finite values go through a sorting network, eight
/// pixels at a time; the rest use selection.
fn median_filter(v: &[f32], width: usize, height: usize, m: usize, out: &mut [f32]) {
    let r = m / 2;
    if r == 0 {
        out.copy_from_slice(v);
        return;
    }
    let n = m * m;
    let net = (n <= MAX_NETWORK_INPUTS).then(|| MedianNetwork::new(n));
    // Per row, the count of non-finite values left of each column (w + 1 entries), so that a
    // block's window is checked with two lookups per row.
    let stride = width + 1;
    let mut bad = vec![0_u32; stride * height];
    bad.par_chunks_mut(stride)
        .zip(v.par_chunks(width))
        .for_each(|(counts, row)| {
            let mut c = 0;
            for (k, &e) in counts.iter_mut().skip(1).zip(row) {
                c += u32::from(!e.is_finite());
                *k = c;
            }
        });
    let clean = |y0: usize, y1: usize, x0: usize, x1: usize| {
        (y0..y1).all(|yy| bad.get(yy * stride + x1) == bad.get(yy * stride + x0))
    };
    out.par_chunks_mut(width).enumerate().for_each_init(
        || (Vec::new(), Vec::new()),
        |(buf, lanes): &mut (Vec<f32>, Vec<[f32; MEDIAN_LANES]>), (y, row)| {
            let ry = r.min(y).min(height - 1 - y);
            let mut x = 0;
            while x < width {
                let block_ok = ry == r
                    && x >= r
                    && x + MEDIAN_LANES + r <= width
                    && clean(y - r, y + r + 1, x - r, x + MEDIAN_LANES + r);
                if let (true, Some(net)) = (block_ok, net.as_ref()) {
                    lanes.clear();
                    for yy in y - r..=y + r {
                        let row0 = yy * width + x - r;
                        for base in row0..row0 + m {
                            if let Some(src) = v.get(base..base + MEDIAN_LANES) {
                                let mut lane = [0.0; MEDIAN_LANES];
                                lane.copy_from_slice(src);
                                lanes.push(lane);
                            }
                        }
                    }
                    if let Some(med) = net.run(lanes) {
                        if let Some(o) = row.get_mut(x..x + MEDIAN_LANES) {
                            o.copy_from_slice(&med);
                        }
                        x += MEDIAN_LANES;
                        continue;
                    }
                }
                let rx = r.min(x).min(width - 1 - x);
                if let Some(o) = row.get_mut(x) {
                    *o = median_select(v, width, x, y, rx, ry, buf);
                }
                x += 1;
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
    let mut prev_index: Option<usize> = None;
    let frames: Vec<FrameInput> = flows
        .iter()
        .enumerate()
        .map(|(k, flow)| {
            let mut meas = Measurements::default();
            meas.fill(flow, u_land, min_confidence);
            note_frame(k, flow, &meas, prev_index, warnings);
            let steps = prev_index.map(|p| flow.frame_index.saturating_sub(p) as f64);
            prev_index = Some(flow.frame_index);
            FrameInput { meas, steps }
        })
        .collect();
    let mut iota = zeros_par(w * h);
    let mut var = zeros_par(w * h);
    let diverged = iota
        .par_chunks_mut(BAND_ROWS * w)
        .zip(var.par_chunks_mut(BAND_ROWS * w))
        .enumerate()
        .map_init(SweepScratch::default, |sc, (band, out)| {
            filter.band(band * BAND_ROWS, &frames, out, sc)
        })
        .sum::<usize>();
    if diverged > 0 {
        warnings.push(format!(
            "{diverged} pixel predictions diverged (plane scale 1 − f·U·α < {MIN_PLANE_SCALE}) and restarted from the prior"
        ));
    }
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
        let mut meas = Measurements::default();
        meas.fill(flow, -fu / z_ref, params.min_confidence);
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
    let unmeasured = iota.par_iter().filter(|v| v.is_nan()).count();
    if unmeasured > 0 {
        warnings.push(format!(
            "{unmeasured} of {} pixels were never measured",
            width * height
        ));
    }
    let mut smooth = zeros_par(width * height);
    median_filter(&iota, width, height, params.median_px, &mut smooth);
    let mut z = zeros_par(width * height);
    let mut zvar = zeros_par(width * height);
    let nonpositive: usize = z
        .par_chunks_mut(CHUNK_PX)
        .zip(zvar.par_chunks_mut(CHUNK_PX))
        .zip(smooth.par_chunks(CHUNK_PX).zip(var.par_chunks(CHUNK_PX)))
        .map(|((zs, vs), (ios, vis))| {
            let mut nonpositive = 0;
            for (((zo, vo), &io), &vi) in zs.iter_mut().zip(vs.iter_mut()).zip(ios).zip(vis) {
                (*zo, *vo) = if io > 0.0 {
                    let io = f64::from(io);
                    // Z = Z_ref/ι̃ → Var Z = Var ι̃ · Z_ref²/ι̃⁴.
                    (
                        (z_ref / io) as f32,
                        (f64::from(vi) * (z_ref / (io * io)).powi(2)) as f32,
                    )
                } else {
                    nonpositive += usize::from(io.is_finite());
                    (f32::NAN, f32::NAN)
                };
            }
            nonpositive
        })
        .sum();
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
        // 11 px: wider than the direct window sums, so the f64 running sums are used.
        for (kalman, neighbourhood_px) in [(true, 5), (true, 11), (false, 5)] {
            let map = estimate_depth(
                &flows,
                &g,
                &DepthParams {
                    kalman,
                    neighbourhood_px,
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

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn avx2_bands_give_the_same_bits() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            return;
        }
        let g = paper_geometry();
        let (w, h) = (53, 40);
        let flows = plane_flows(w, h, 3, &g, [4000.0, 0.3, -0.5], 0.05, 4);
        let land = g.focal_px * g.frame_step_um / g.working_distance_um;
        let filter = Filter {
            width: w,
            height: h,
            r: 2,
            land_shift_px: land,
            noise_var: 1e-4 / (land * land),
            q: [1e-6 / 4.0, 1e-6 / 4.0, 1e-6],
            p0: [
                INITIAL_VARIANCE / 4.0,
                INITIAL_VARIANCE / 4.0,
                INITIAL_VARIANCE,
            ],
        };
        let frames: Vec<FrameInput> = flows
            .iter()
            .enumerate()
            .map(|(k, flow)| {
                let mut meas = Measurements::default();
                meas.fill(flow, -land, 1e-3);
                FrameInput {
                    meas,
                    steps: (k > 0).then_some(1.0),
                }
            })
            .collect();
        let (mut plain, mut plain_var) = (vec![0.0; w * h], vec![0.0; w * h]);
        let (mut simd, mut simd_var) = (plain.clone(), plain_var.clone());
        let mut sc = SweepScratch::default();
        let a = filter.band_impl(0, &frames, (&mut plain, &mut plain_var), &mut sc);
        // SAFETY: AVX2 was detected above.
        let b = unsafe { filter.band_avx2(0, &frames, (&mut simd, &mut simd_var), &mut sc) };
        assert_eq!(a, b);
        let bits = |s: &[f32]| -> Vec<u32> { s.iter().map(|v| v.to_bits()).collect() };
        assert!(plain.iter().any(|&v| v != 1.0 && v.is_finite()));
        assert_eq!(bits(&plain), bits(&simd));
        assert_eq!(bits(&plain_var), bits(&simd_var));
    }

    #[test]
    fn direct_and_prefix_window_sums_agree() {
        let g = paper_geometry();
        let (w, h) = (41, 23);
        let flows = plane_flows(w, h, 1, &g, [4000.0, 0.3, -0.5], 0.05, 7);
        let land = g.focal_px * g.frame_step_um / g.working_distance_um;
        let mut meas = Measurements::default();
        meas.fill(&flows[0], -land, 1e-3);
        // Some pixels without weight, so windows are partly empty.
        for i in (0..w * h).step_by(5) {
            meas.w[i] = 0.0;
            meas.wm[i] = 0.0;
        }
        for r in 1..=DIRECT_WINDOW_MAX_R {
            let filter = Filter {
                width: w,
                height: h,
                r,
                land_shift_px: land,
                noise_var: 1e-4 / (land * land),
                q: [0.0; 3],
                p0: [1.0; 3],
            };
            for y in [0, r, h / 2, h - 1] {
                let mut vs = vec![[0.0; 5]; w];
                for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
                    filter.slide(&mut vs, &meas, yy, 1.0);
                }
                let mut sc = SweepScratch {
                    info: vec![0.0; 9 * w],
                    ..SweepScratch::default()
                };
                filter.prefix_info(y, &vs, &mut sc);
                let want = std::mem::take(&mut sc.info);
                sc.info = vec![0.0; 9 * w];
                filter.direct_info(y, &meas, &mut sc);
                let scale = want.iter().fold(0.0_f32, |m, v| m.max(v.abs()));
                assert!(scale > 0.0);
                for (i, (a, b)) in sc.info.iter().zip(&want).enumerate() {
                    assert!(
                        (a - b).abs() <= 1e-5 * scale,
                        "r {r} y {y} [{i}]: {a} vs {b}"
                    );
                }
            }
        }
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
    fn median_network_matches_selection() {
        let mut rng = Rng::new(4);
        let (w, h) = (45, 23);
        let mut v: Vec<f32> = (0..w * h).map(|_| rng.gauss() as f32).collect();
        for i in (0..w * h).step_by(97) {
            v[i] = f32::NAN;
        }
        let mut buf = Vec::new();
        for m in [3, 5, 7] {
            let r = m / 2;
            let mut out = vec![0.0; w * h];
            median_filter(&v, w, h, m, &mut out);
            for y in 0..h {
                for x in 0..w {
                    let (rx, ry) = (r.min(x).min(w - 1 - x), r.min(y).min(h - 1 - y));
                    let want = median_select(&v, w, x, y, rx, ry, &mut buf);
                    assert_eq!(
                        out[y * w + x].to_bits(),
                        want.to_bits(),
                        "m {m} at ({x}, {y})"
                    );
                }
            }
        }
    }

    #[test]
    fn median_network_paths_agree_with_sorting_including_ties() {
        assert_eq!(MedianNetwork::new(25).pairs.len(), 114);
        let mut rng = Rng::new(9);
        for n in [1, 9, 25, 49] {
            let net = MedianNetwork::new(n);
            for _ in 0..200 {
                // Few distinct values, so ties are common.
                let input: Vec<[f32; MEDIAN_LANES]> = (0..n)
                    .map(|_| std::array::from_fn(|_| (rng.gauss() * 3.0).round() as f32))
                    .collect();
                let want: [f32; MEDIAN_LANES] = std::array::from_fn(|l| {
                    let mut col: Vec<f32> = input.iter().map(|v| v[l]).collect();
                    col.sort_by(f32::total_cmp);
                    col[n / 2]
                });
                let mut a = input.clone();
                assert_eq!(net.run_portable(&mut a), Some(want), "n {n}");
                let mut b = input.clone();
                assert_eq!(net.run(&mut b), Some(want), "n {n}");
            }
            assert_eq!(net.run(&mut vec![[0.0; MEDIAN_LANES]; n - 1]), None);
        }
    }

    #[test]
    fn depth_from_flow_matches_the_land() {
        let g = paper_geometry();
        let z = depth_from_flow_um(g.land_flow_px() as f32, &g);
        assert!((z - 4000.0).abs() < 1e-2, "{z}");
        assert!(depth_from_flow_um(0.5, &g).is_nan());
    }
}
