//! Sound from wall tilt: V = Vt·tan θ per wall, channels by cut, stitching of overlapping groups and resampling.

use serde::{Deserialize, Serialize};

use super::StageError;
use super::orientation::Orientation;
use crate::io::Cut;

/// Knobs of the sound stage.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SoundParams {
    /// Output sample rate (44 100 or 48 000 Hz).
    pub output_rate_hz: u32,
    /// Spacing of the native (pre-resampling) samples along the groove; 0 = one output sample.
    pub native_spacing_um: f64,
    /// Peak level after normalisation (0 < p ≤ 1); 0 keeps velocity scaled by `full_scale_mm_s`.
    pub normalize_peak: f32,
    /// Velocity mapped to full scale when not normalising (mm/s).
    pub full_scale_mm_s: f64,
}

impl Default for SoundParams {
    fn default() -> Self {
        Self {
            output_rate_hz: 44_100,
            native_spacing_um: 0.0,
            normalize_peak: 0.89,
            full_scale_mm_s: 100.0,
        }
    }
}

/// The sound of one group: wall velocity (mm/s) at positions along the groove.
#[derive(Clone, Debug, PartialEq)]
pub struct GroupSignal {
    /// Group index.
    pub group: usize,
    /// Groove position of each sample (µm from the scan start), increasing.
    pub positions_um: Vec<f64>,
    /// One buffer per output channel (1 mono, 2 stereo), velocity in mm/s; NaN = gap.
    pub channels: Vec<Vec<f32>>,
    /// Groove speed Vt at this group (mm/s).
    pub groove_speed_mm_s: f64,
}

/// Turns a group's wall orientation into velocity samples.
///
/// Stereo: left wall → channel 0, right wall → channel 1. Lateral: (tanθ_L + tanθ_R)/√2 over the
/// walls measured. Vertical: (tanθ_R − tanθ_L)/√2. Column x maps to `column0_um + x·um_per_px`.
///
/// # Errors
/// [`StageError`] when the orientation has no wall the cut needs.
pub fn group_signal(
    group: usize,
    orientation: &Orientation,
    cut: Cut,
    column0_um: f64,
    um_per_px: f64,
    groove_speed_mm_s: f64,
) -> Result<GroupSignal, StageError> {
    todo!(
        "sound helper: {group} {} {cut:?} {column0_um} {um_per_px} {groove_speed_mm_s}",
        orientation.walls.len()
    )
}

/// A continuous signal on a uniform grid of groove positions.
#[derive(Clone, Debug, PartialEq)]
pub struct StitchedSignal {
    /// Position of sample 0 (µm).
    pub start_um: f64,
    /// Sample spacing (µm).
    pub spacing_um: f64,
    /// Native sample rate = Vt / spacing (Hz).
    pub native_rate_hz: f64,
    /// Channels, velocity mm/s (gaps filled with 0 and listed in `gaps`).
    pub channels: Vec<Vec<f32>>,
    /// Sample ranges that had no data (filled with silence).
    pub gaps: Vec<std::ops::Range<usize>>,
}

/// Stitches group signals onto one uniform grid, cross-fading where groups overlap so seams do not click.
///
/// # Errors
/// [`StageError`] when there are no groups or channel counts differ.
pub fn stitch(groups: &[GroupSignal], spacing_um: f64) -> Result<StitchedSignal, StageError> {
    todo!("sound helper: {} {spacing_um}", groups.len())
}

/// Band-limited resampling of one channel from `from_hz` to `to_hz` (rubato sinc).
///
/// # Errors
/// [`StageError`] on non-positive rates.
pub fn resample(samples: &[f32], from_hz: f64, to_hz: u32) -> Result<Vec<f32>, StageError> {
    todo!("sound helper: {} {from_hz} {to_hz}", samples.len())
}
