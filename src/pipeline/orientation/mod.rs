//! Robust wall orientation: Lorentzian M-estimator plane fits α̂·P = c about each wall line (paper §6–7).

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::depth::DepthMap;
use super::walls::{WallLine, WallSide};
use super::{StageError, check_range};
use crate::image::Image;
use crate::meta::Geometry;
use crate::pipeline::simd::Isa;

mod irls;
#[cfg(test)]
mod reference;
mod samples;
#[cfg(test)]
#[allow(clippy::unwrap_used)] // Tests fail loudly on purpose.
mod tests;

pub use irls::fit_plane;
use irls::*;
#[cfg(test)]
pub(crate) use samples::test_fit;
use samples::*;
pub use samples::{median_wall_slope, reject_slopes_against};

/// Knobs of the orientation stage.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OrientationParams {
    #[doc = knob!("orientation.robust")]
    pub robust: bool,
    #[doc = knob!("orientation.neighbourhood_px")]
    pub neighbourhood_px: usize,
    #[doc = knob!("orientation.sigma_start_um")]
    pub sigma_start_um: f64,
    #[doc = knob!("orientation.sigma_decay")]
    pub sigma_decay: f64,
    #[doc = knob!("orientation.sigma_min_um")]
    pub sigma_min_um: f64,
    #[doc = knob!("orientation.residual_tolerance_um")]
    pub residual_tolerance_um: f64,
    #[doc = knob!("orientation.divergence_factor")]
    pub divergence_factor: f64,
    #[doc = knob!("orientation.max_iterations")]
    pub max_iterations: u32,
    #[doc = knob!("orientation.outlier_sigmas")]
    pub outlier_sigmas: f64,
    #[doc = knob!("orientation.max_wall_slope_change")]
    ///
    /// Such a fit becomes a gap: a cut wall keeps its angle across the groove (modulation changes
    /// it by about 1 − cos θ, 2% at tan θ = 0.2), so a wall that seems to turn steeper or flatter
    /// is a fit locked onto damage. 0 = off.
    pub max_wall_slope_change: f64,
    /// Instruction set of the IRLS pass (not a knob: never in the TOML; by default the CPU's
    /// best, detected once).
    #[serde(skip)]
    pub isa: Isa,
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
            isa: Isa::detect(),
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
/// Iso-depth lines whose depths differ by less than this (µm) count as one depth.
const DISTINCT_DEPTH_UM: f64 = 1e-6;

impl OrientationParams {
    /// Checks every orientation knob.
    ///
    /// # Errors
    /// [`StageError::InvalidParam`] naming the first bad key.
    pub fn validate(&self) -> Result<(), StageError> {
        let p = self;
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
}

/// [`OrientationParams::validate`] (the path other code used).
///
/// # Errors
/// As that.
pub fn validate(p: &OrientationParams) -> Result<(), StageError> {
    p.validate()
}

/// Checks the knobs and the camera geometry the back-projection needs.
fn check_setup(params: &OrientationParams, geom: &Geometry) -> Result<(), StageError> {
    params.validate()?;
    check_range("geometry.focal_px", geom.focal_px, 1e-9, 1e12)
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
    check_setup(params, geom)?;
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
    let sides: Vec<WallSide> = walls.iter().map(|l| l.side).collect();
    // The points and weight-map pixels of one sample's fit.
    let gather = |ws: &mut Workspace, wi: usize, x_s: f32| {
        let Some(line) = walls.get(wi) else {
            return usize::MAX;
        };
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
        MIN_SAMPLE_POINTS
    };
    Ok(fit_walls(
        &sides,
        sample_columns,
        width,
        height,
        params,
        gather,
    ))
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
    check_setup(params, geom)?;
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
    // The points and weight-map pixels of one sample's fit.
    let gather = |ws: &mut Workspace, wi: usize, x_s: f32| {
        let (Some(group), Some(true)) = (members.get(wi), usable.get(wi).copied()) else {
            return usize::MAX;
        };
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
        if distinct_depths(depths) >= 2 {
            MIN_SAMPLE_POINTS
        } else {
            usize::MAX
        }
    };
    Ok(fit_walls(
        &sides,
        sample_columns,
        width,
        height,
        params,
        gather,
    ))
}
