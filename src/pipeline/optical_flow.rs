//! Optical flow: Horn–Schunck with the groove-orientation constraint (paper eqs. 20–23), plain Horn–Schunck and Lucas–Kanade.

use serde::{Deserialize, Serialize};

use super::StageError;
use super::derivatives::Derivatives;
use crate::image::Image;

/// Which flow algorithm runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum FlowMethod {
    /// Horn–Schunck plus ∂u/∂y = −u/(c·f) on the walls.
    #[default]
    GrooveHornSchunck,
    /// Plain Horn–Schunck.
    HornSchunck,
    /// Lucas–Kanade with the smallest-eigenvalue confidence.
    LucasKanade,
}

/// Iteration scheme of the Horn–Schunck variants.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Solver {
    /// In-place Gauss–Seidel sweeps (red–black ordering may be used for parallelism).
    #[default]
    GaussSeidel,
    /// Jacobi iteration.
    Jacobi,
}

/// Knobs of [`compute_flow`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FlowParams {
    /// Algorithm.
    pub method: FlowMethod,
    /// Iteration scheme.
    pub solver: Solver,
    /// Smoothness weight λ (α in Horn–Schunck).
    pub lambda: f32,
    /// Iteration cap (paper: 100).
    pub max_iterations: u32,
    /// Convergence threshold τ: stop when the mean absolute update falls below it (px).
    pub tolerance_px: f32,
    /// Pixels whose gradient magnitude is below this carry no flow (confidence 0).
    pub gradient_threshold: f32,
    /// Lucas–Kanade window side, px (odd).
    pub lk_window_px: usize,
}

impl Default for FlowParams {
    fn default() -> Self {
        Self {
            method: FlowMethod::GrooveHornSchunck,
            solver: Solver::GaussSeidel,
            lambda: 0.05,
            max_iterations: 100,
            tolerance_px: 1e-5,
            gradient_threshold: 1e-3,
            lk_window_px: 7,
        }
    }
}

/// Per-pixel wall side c ∈ {−1, 0, +1} for the groove-orientation constraint (0: land or bottom).
#[derive(Clone, Debug, PartialEq)]
pub struct WallSideMap {
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Row-major signs.
    pub sign: Vec<i8>,
}

/// A dense flow field in pixels per frame, in the coordinates of frame `frame_index`.
#[derive(Clone, Debug, PartialEq)]
pub struct FlowField {
    /// Horizontal flow (base flow added back).
    pub u: Image,
    /// Vertical flow.
    pub v: Image,
    /// Per-pixel confidence (gradient magnitude, or the LK smallest eigenvalue); 0 = no flow.
    pub confidence: Image,
    /// Iterations run.
    pub iterations: u32,
    /// True when τ was reached before the cap.
    pub converged: bool,
    /// Frame whose grid the field uses.
    pub frame_index: usize,
}

/// Computes the flow of one derivative set.
///
/// `focal_px` is the focal length in pixels (the constraint's f); `walls` gives c per pixel
/// (when `None` the groove method estimates it itself).
///
/// # Errors
/// [`StageError`] on invalid params (NaN, λ ≤ 0, zero iterations) or mismatched sizes.
pub fn compute_flow(
    d: &Derivatives,
    focal_px: f64,
    walls: Option<&WallSideMap>,
    params: &FlowParams,
) -> Result<FlowField, StageError> {
    todo!(
        "flow helper: {} {focal_px} {} {params:?}",
        d.frame_index,
        walls.is_some()
    )
}
