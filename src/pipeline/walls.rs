//! Wall lines: where each groove wall lies in every column, found from the depth map (depth path) or stripes (dual focus).

use serde::{Deserialize, Serialize};

use super::StageError;
use super::depth::DepthMap;
use crate::io::Geometry;

/// Which wall of the groove.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum WallSide {
    /// The wall at smaller y (top of the image): depth grows with y.
    Left,
    /// The wall at larger y (bottom of the image): depth shrinks with y.
    Right,
}

/// A line along one wall: a row per column (NaN = void), at a known depth when it is an iso-depth stripe.
#[derive(Clone, Debug, PartialEq)]
pub struct WallLine {
    /// The wall it lies on.
    pub side: WallSide,
    /// Row (y) per column; NaN where unknown.
    pub rows: Vec<f32>,
    /// Half-height of the wall band about the line, per column (px); used for neighbourhoods.
    pub half_width_px: Vec<f32>,
    /// True depth from the optical centre (µm) when the line is an iso-depth contour (dual focus).
    pub depth_um: Option<f64>,
    /// Distance used to back-project its pixels, X = x·d/f (µm). Under a cover glass this is
    /// the true depth minus the glass's focus shift; elsewhere it equals the depth.
    pub projection_depth_um: Option<f64>,
    /// Columns whose row was filled from a fitted line (voids).
    pub filled: Vec<bool>,
}

/// Knobs of [`find_walls`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WallParams {
    /// |∂Z/∂Y| above this marks a wall pixel (45° walls give 1).
    pub min_slope: f32,
    /// Rows trimmed from each end of a wall band, px (keeps edge pixels out of fits).
    pub trim_px: usize,
}

impl Default for WallParams {
    fn default() -> Self {
        Self {
            min_slope: 0.4,
            trim_px: 6,
        }
    }
}

/// Finds the left and right walls in a depth map: one [`WallLine`] per wall (centre of the band).
///
/// # Errors
/// [`StageError`] when no wall can be found.
pub fn find_walls(
    depth: &DepthMap,
    geom: &Geometry,
    params: &WallParams,
) -> Result<Vec<WallLine>, StageError> {
    todo!("walls helper: {} {geom:?} {params:?}", depth.frame_index)
}
