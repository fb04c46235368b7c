//! Robust wall orientation: Lorentzian M-estimator plane fits α̂·P = c about each wall line (paper §6–7).

use serde::{Deserialize, Serialize};

use super::StageError;
use super::depth::DepthMap;
use super::walls::{WallLine, WallSide};
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

/// Fits a plane to points `[X, Y, Z]` (µm), robustly when `params.robust`.
///
/// # Errors
/// [`StageError`] with fewer than 3 points, a degenerate set, or invalid params.
pub fn fit_plane(points: &[[f64; 3]], params: &OrientationParams) -> Result<PlaneFit, StageError> {
    todo!("orientation helper: {} {params:?}", points.len())
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
}

/// tan θ of a fitted wall plane: the wall's velocity along its normal over Vt, −a·sign(b)/√(1+b²).
#[must_use]
pub fn tan_theta(fit: &PlaneFit) -> f64 {
    -fit.a * fit.b.signum() / (1.0 + fit.b * fit.b).sqrt()
}

/// Orientation from a depth map: a plane per sample column through the depth values in the
/// neighbourhood about each wall line (depth path).
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
    todo!(
        "orientation helper: {} {} {} {geom:?} {params:?}",
        depth.frame_index,
        walls.len(),
        sample_columns.len()
    )
}

/// Orientation from iso-depth lines (dual-focus path): a plane per sample column through the
/// 3-D points of the lines of each wall within the neighbourhood.
///
/// # Errors
/// [`StageError`] when a wall has fewer than two lines at distinct depths, or params are invalid.
pub fn orient_from_lines(
    lines: &[WallLine],
    width: usize,
    height: usize,
    sample_columns: &[f32],
    geom: &Geometry,
    params: &OrientationParams,
) -> Result<Orientation, StageError> {
    todo!(
        "orientation helper: {} {width} {height} {} {geom:?} {params:?}",
        lines.len(),
        sample_columns.len()
    )
}
