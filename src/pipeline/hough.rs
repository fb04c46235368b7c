//! Dual-focus stripes: in-focus map, Hough accumulator, three peaks with windows, segmentation and centroid lines (paper §9).

use serde::{Deserialize, Serialize};

use super::StageError;
use super::derivatives::Derivatives;
use super::optical_flow::FlowField;
use super::walls::WallLine;
use crate::image::Image;
use crate::io::scan::DualFocusMeta;

/// Knobs of [`segment_stripes`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HoughParams {
    /// In-focus pixels have gradient magnitude above this (grey levels per px).
    pub gradient_threshold: f32,
    /// θ range start (degrees).
    pub theta_min_deg: f32,
    /// θ range end (degrees).
    pub theta_max_deg: f32,
    /// θ bin width (degrees); a coarser value trades accuracy for speed.
    pub theta_step_deg: f32,
    /// ρ bin width (px); ρ runs from 0 to the image height.
    pub rho_step_px: f32,
    /// Peaks searched for (paper: 3).
    pub peak_count: usize,
    /// Half-width of a peak's window in θ (degrees).
    pub window_theta_deg: f32,
    /// Half-width of a peak's window in ρ (px).
    pub window_rho_px: f32,
    /// Smoothing of centroid lines along x (moving-average half-width, px).
    pub line_smoothing_px: usize,
}

impl Default for HoughParams {
    fn default() -> Self {
        Self {
            gradient_threshold: 0.02,
            theta_min_deg: -45.0,
            theta_max_deg: 45.0,
            theta_step_deg: 1.0,
            rho_step_px: 1.0,
            peak_count: 3,
            window_theta_deg: 4.0,
            window_rho_px: 15.0,
            line_smoothing_px: 3,
        }
    }
}

/// The Hough vote array: `votes[t * rho_bins + r]` for θ bin t and ρ bin r.
#[derive(Clone, Debug, PartialEq)]
pub struct Accumulator {
    /// θ of each bin (radians).
    pub thetas_rad: Vec<f32>,
    /// ρ of bin 0 (px).
    pub rho_min_px: f32,
    /// ρ bin width (px).
    pub rho_step_px: f32,
    /// Number of ρ bins.
    pub rho_bins: usize,
    /// Votes.
    pub votes: Vec<u32>,
}

/// One accumulator peak and its window, x·cos θ + y·sin θ = ρ.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Peak {
    /// Line angle (radians).
    pub theta_rad: f32,
    /// Line offset (px).
    pub rho_px: f32,
    /// Votes at the peak.
    pub votes: u32,
}

/// Region label of a pixel in [`Stripes::labels`].
pub mod label {
    /// Not in focus.
    pub const NONE: i8 = -1;
    /// In focus but in two or more windows (discarded as noise).
    pub const DISCARDED: i8 = -2;
    /// In focus but in no window.
    pub const UNASSIGNED: i8 = -3;
}

/// Everything the stripe stage found, for the sound path and for the GUI.
#[derive(Clone, Debug, PartialEq)]
pub struct Stripes {
    /// 1 where a pixel is in focus (carries flow), else 0.
    pub in_focus: Image,
    /// The vote array.
    pub accumulator: Accumulator,
    /// Peaks, sorted top to bottom (by row at the image centre).
    pub peaks: Vec<Peak>,
    /// Per pixel: index into `peaks`, or a [`label`] constant; row-major.
    pub labels: Vec<i8>,
    /// Index (into `peaks`) of the dropped top stripe.
    pub dropped: usize,
    /// The two kept centroid lines, each with its depth and filled voids marked.
    pub lines: Vec<WallLine>,
}

/// Runs the dual-focus stripe stages on one derivative set and its flow.
///
/// # Errors
/// [`StageError`] on invalid params, or when fewer than three stripes are found.
pub fn segment_stripes(
    derivs: &Derivatives,
    flow: &FlowField,
    dual: &DualFocusMeta,
    params: &HoughParams,
) -> Result<Stripes, StageError> {
    todo!(
        "hough helper: {} {} {dual:?} {params:?}",
        derivs.frame_index,
        flow.frame_index
    )
}
