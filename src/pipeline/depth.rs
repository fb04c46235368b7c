//! Depth from flow, Z = −f·U/u, refined over a group by the Barron–Ngai–Spies Kalman filter (horizontal-flow variant).

use serde::{Deserialize, Serialize};

use super::StageError;
use super::optical_flow::FlowField;
use crate::image::Image;
use crate::io::Geometry;

/// Knobs of [`estimate_depth`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DepthParams {
    /// Run the Kalman filter; when false, average the per-frame depths.
    pub kalman: bool,
    /// Process noise of the planar-orientation state (per frame).
    pub process_noise: f32,
    /// Measurement noise of one flow value (px²).
    pub measurement_noise_px2: f32,
    /// Side of the median filter on µ (paper: 5).
    pub median_px: usize,
    /// Flow values with confidence below this are ignored.
    pub min_confidence: f32,
}

impl Default for DepthParams {
    fn default() -> Self {
        Self {
            kalman: true,
            process_noise: 1e-6,
            measurement_noise_px2: 1e-4,
            median_px: 5,
            min_confidence: 1e-3,
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

/// Estimates the depth map of a group from its flow fields.
///
/// # Errors
/// [`StageError`] when there are no flow fields, sizes differ, or params are invalid.
pub fn estimate_depth(
    flows: &[FlowField],
    geom: &Geometry,
    params: &DepthParams,
) -> Result<DepthMap, StageError> {
    todo!("depth helper: {} {geom:?} {params:?}", flows.len())
}
