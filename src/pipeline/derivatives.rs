//! Spatio-temporal derivatives: [1/4,1/2,1/4] temporal pre-blur and Simoncelli's matched p5/d5 filters (paper §3).

use serde::{Deserialize, Serialize};

use super::StageError;
use crate::image::Image;

/// How derivatives are taken.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum DerivativeMode {
    /// 7 frames -> pre-blur -> 5 frames -> p5/d5: one derivative set per 7-frame window.
    #[default]
    Simoncelli,
    /// Simple differences between two consecutive frames: one set per frame pair.
    TwoFrame,
}

/// Knobs of [`compute_derivatives`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DerivativeParams {
    /// Filter family.
    pub mode: DerivativeMode,
    /// Shift every frame back by the known land motion before filtering, so the flow stage
    /// only measures the small residual (keeps the linearisation valid for steps > 1 px).
    pub prewarp: bool,
}

impl Default for DerivativeParams {
    fn default() -> Self {
        Self {
            mode: DerivativeMode::Simoncelli,
            prewarp: true,
        }
    }
}

/// Ix, Iy, It of one temporal window, in the coordinates of frame `frame_index`.
#[derive(Clone, Debug, PartialEq)]
pub struct Derivatives {
    /// ∂I/∂x.
    pub ix: Image,
    /// ∂I/∂y.
    pub iy: Image,
    /// ∂I/∂t (per frame).
    pub it: Image,
    /// The pre-filtered grey image the derivatives belong to (for display and in-focus maps).
    pub image: Image,
    /// Frame of the group whose pixel grid these derivatives use (window centre).
    pub frame_index: usize,
    /// Flow (px/frame along x) removed by pre-warping; the flow stage adds it back.
    pub base_flow_px: f32,
}

/// Computes derivative sets over a group of frames.
///
/// `land_flow_px` is the known image motion of the land plane per frame (negative: content
/// moves toward -x); used only when `params.prewarp` is set.
///
/// # Errors
/// [`StageError`] when there are too few frames for the mode, sizes differ, or a value is not finite.
pub fn compute_derivatives(
    frames: &[Image],
    land_flow_px: f64,
    params: &DerivativeParams,
) -> Result<Vec<Derivatives>, StageError> {
    todo!(
        "derivatives helper: {} {land_flow_px} {params:?}",
        frames.len()
    )
}
