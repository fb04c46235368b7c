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
use super::{StageError, check_range, median_in_place};
use crate::image::{Image, zeros_par};
use crate::meta::Geometry;
use crate::pipeline::simd::{Compiled, Isa};

mod average;
mod kalman;
mod measure;
mod median;
#[cfg(test)]
mod reference;
#[cfg(test)]
#[allow(clippy::unwrap_used)] // Tests fail loudly on purpose.
mod tests;
mod window_sums;

use average::*;
use kalman::*;
use measure::*;
use median::*;
use window_sums::*;

/// Knobs of [`estimate_depth`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DepthParams {
    #[doc = knob!("depth.kalman")]
    pub kalman: bool,
    #[doc = knob!("depth.process_noise")]
    ///
    /// The variance added per frame to the relative inverse depth Z_ref/Z, and that over r² to its
    /// per-pixel slopes.
    pub process_noise: f32,
    #[doc = knob!("depth.measurement_noise_px2")]
    pub measurement_noise_px2: f32,
    #[doc = knob!("depth.median_px")]
    ///
    /// Odd; 1 = off.
    pub median_px: usize,
    #[doc = knob!("depth.min_confidence")]
    pub min_confidence: f32,
    #[doc = knob!("depth.neighbourhood_px")]
    pub neighbourhood_px: usize,
    /// Instruction set of the filter's row bands and the median network (not a knob: never in
    /// the TOML; by default the CPU's best, detected once).
    #[serde(skip)]
    pub isa: Isa,
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
            isa: Isa::detect(),
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
pub const MAX_MEDIAN_PX: usize = 15;
/// Largest accepted `neighbourhood_px`.
const MAX_NEIGHBOURHOOD_PX: usize = 255;
/// Values of the per-pixel state: α̃, β̃, ι̃, then the covariance P00 P01 P02 P11 P12 P22.
const PLANES: usize = 9;
/// Index of ι̃ in the state.
const IOTA: usize = 2;
/// Index of Var ι̃ (P22) in the state.
const VAR_IOTA: usize = 8;

impl DepthParams {
    /// Checks every depth knob.
    ///
    /// # Errors
    /// [`StageError::InvalidParam`] naming the first bad key.
    pub fn validate(&self) -> Result<(), StageError> {
        let p = self;
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
        Ok(())
    }
}

/// Checks the geometry the stage needs.
fn check_geometry(geom: &Geometry) -> Result<(), StageError> {
    check_range("geometry.focal_px", geom.focal_px, 1e-9, 1e12)?;
    check_range("geometry.frame_step_um", geom.frame_step_um, 1e-12, 1e12)?;
    check_range(
        "geometry.working_distance_um",
        geom.working_distance_um,
        1e-9,
        1e12,
    )
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
    params.validate()?;
    check_geometry(geom)?;
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
            isa: params.isa,
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
    median_filter(
        &iota,
        width,
        height,
        params.median_px,
        &mut smooth,
        params.isa,
    );
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
