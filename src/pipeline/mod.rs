//! The reconstruction pipeline: pure per-group stages (no I/O, no GUI) and the stage cache both front ends share.

pub mod audio_signal;
pub mod cache;
pub mod depth;
pub mod derivatives;
pub mod dsp;
pub mod edges;
pub mod eval;
pub mod hough;
pub mod knobs;
pub mod optical_flow;
pub mod orientation;
pub mod still;
pub mod walls;

/// Why a stage could not produce its output.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StageError {
    /// A parameter is NaN, out of range or inconsistent.
    #[error("invalid parameter {name}: {problem}")]
    InvalidParam {
        /// The parameter (TOML path such as `flow.lambda`).
        name: String,
        /// What is wrong with it.
        problem: String,
    },
    /// The input does not suit the stage (too few frames, mismatched sizes, ...).
    #[error("{stage}: {problem}")]
    BadInput {
        /// The stage.
        stage: &'static str,
        /// What is wrong.
        problem: String,
    },
    /// The stage ran but found nothing usable (no walls, fewer than three stripes, ...).
    #[error("{stage}: {problem}")]
    NotFound {
        /// The stage.
        stage: &'static str,
        /// What was not found.
        problem: String,
    },
    /// A newer job superseded this one.
    #[error("cancelled")]
    Cancelled,
}

/// Checks that a float parameter is finite and inside `[lo, hi]`.
///
/// # Errors
/// [`StageError::InvalidParam`] naming `name`.
pub fn check_range(name: &str, value: f64, lo: f64, hi: f64) -> Result<(), StageError> {
    if value.is_finite() && value >= lo && value <= hi {
        Ok(())
    } else {
        Err(StageError::InvalidParam {
            name: name.to_string(),
            problem: format!("{value} is not in [{lo}, {hi}]"),
        })
    }
}

use serde::{Deserialize, Serialize};

use crate::io::ScanMeta;
use audio_signal::SoundParams;
use depth::DepthParams;
use derivatives::DerivativeParams;
use dsp::DspParams;
use hough::HoughParams;
use optical_flow::FlowParams;
use orientation::OrientationParams;
use walls::WallParams;

/// The per-group stages, in the order they run. A change to one makes it and every later stage stale.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Stage {
    /// Ix, Iy, It of every 7-frame window (dual-focus path: the middle window only, the one
    /// its stripes are read from).
    Derivatives,
    /// Optical flow of every derivative set.
    Flow,
    /// Kalman depth map and wall lines (depth path).
    Depth,
    /// In-focus map, Hough accumulator, stripes and centroid lines (dual-focus path).
    Stripes,
    /// Robust wall orientation per sample column.
    Orientation,
    /// Velocity samples of the group.
    Sound,
}

impl Stage {
    /// Every stage in run order.
    pub const ALL: [Stage; 6] = [
        Stage::Derivatives,
        Stage::Flow,
        Stage::Depth,
        Stage::Stripes,
        Stage::Orientation,
        Stage::Sound,
    ];

    /// Position in [`Stage::ALL`].
    #[must_use]
    pub fn index(self) -> usize {
        self as usize
    }

    /// Human-readable name.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Stage::Derivatives => "derivatives",
            Stage::Flow => "flow",
            Stage::Depth => "depth",
            Stage::Stripes => "stripes",
            Stage::Orientation => "orientation",
            Stage::Sound => "sound",
        }
    }
}

/// Which reconstruction path runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum PathChoice {
    /// Dual focus when `scan.toml` has a `[dual_focus]` table, else depth.
    #[default]
    Auto,
    /// Flow → Kalman depth → orientation.
    Depth,
    /// Flow → in-focus stripes → Hough → centroid lines → orientation.
    DualFocus,
}

/// Every knob of the pipeline, one table per stage (the `groovescope params` TOML).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields, default)]
pub struct PipelineParams {
    /// Reconstruction path.
    pub path: PathChoice,
    /// Derivative stage.
    pub derivatives: DerivativeParams,
    /// Flow stage.
    pub flow: FlowParams,
    /// Kalman depth stage.
    pub depth: DepthParams,
    /// Wall finding on the depth map.
    pub walls: WallParams,
    /// Dual-focus stripe stage.
    pub hough: HoughParams,
    /// Robust orientation stage.
    pub orientation: OrientationParams,
    /// Sound stage (sampling, stitching, output rate, level).
    pub sound: SoundParams,
    /// Post-processing of the whole clip.
    pub dsp: DspParams,
    /// The still-image decoder (`groovescope still`; scans do not read it).
    pub still: still::StillParams,
}

impl PipelineParams {
    /// Parses params TOML (missing tables and keys take defaults).
    ///
    /// # Errors
    /// A message naming the bad key.
    pub fn from_toml_str(text: &str) -> Result<Self, String> {
        toml::from_str(text).map_err(|e| e.message().to_string())
    }

    /// TOML text of these params.
    ///
    /// # Errors
    /// When serialisation fails.
    pub fn to_toml_string(&self) -> Result<String, toml::ser::Error> {
        toml::to_string_pretty(self)
    }

    /// The earliest stage whose params differ between `self` and `other` (None when equal).
    #[must_use]
    pub fn first_changed_stage(&self, other: &Self) -> Option<Stage> {
        if self.path != other.path || self.derivatives != other.derivatives {
            Some(Stage::Derivatives)
        } else if self.flow != other.flow {
            Some(Stage::Flow)
        } else if self.depth != other.depth || self.walls != other.walls {
            Some(Stage::Depth)
        } else if self.hough != other.hough {
            Some(Stage::Stripes)
        } else if self.orientation != other.orientation {
            Some(Stage::Orientation)
        } else if self.sound != other.sound {
            Some(Stage::Sound)
        } else {
            None
        }
    }

    /// True when the dual-focus path runs for a scan with this metadata.
    #[must_use]
    pub fn uses_dual_focus(&self, meta: &ScanMeta) -> bool {
        match self.path {
            PathChoice::Auto => meta.dual_focus.is_some(),
            PathChoice::Depth => false,
            PathChoice::DualFocus => true,
        }
    }

    /// Checks every number for NaN and sign (the stages check their own ranges too).
    ///
    /// # Errors
    /// [`StageError::InvalidParam`] naming the first bad key.
    pub fn validate(&self) -> Result<(), StageError> {
        check_range("flow.lambda", f64::from(self.flow.lambda), 1e-12, 1e12)?;
        check_range(
            "flow.tolerance_px",
            f64::from(self.flow.tolerance_px),
            0.0,
            1e3,
        )?;
        check_range(
            "flow.gradient_threshold",
            f64::from(self.flow.gradient_threshold),
            0.0,
            1e6,
        )?;
        if self.flow.max_iterations == 0 {
            return Err(StageError::InvalidParam {
                name: "flow.max_iterations".into(),
                problem: "must be at least 1".into(),
            });
        }
        check_range(
            "depth.process_noise",
            f64::from(self.depth.process_noise),
            0.0,
            1e12,
        )?;
        check_range(
            "depth.measurement_noise_px2",
            f64::from(self.depth.measurement_noise_px2),
            1e-30,
            1e12,
        )?;
        check_range(
            "depth.min_confidence",
            f64::from(self.depth.min_confidence),
            0.0,
            1e12,
        )?;
        check_range("walls.min_slope", f64::from(self.walls.min_slope), 0.0, 1e6)?;
        orientation::validate(&self.orientation)?;
        let s = &self.sound;
        if !matches!(s.output_rate_hz, 8_000..=192_000) {
            return Err(StageError::InvalidParam {
                name: "sound.output_rate_hz".into(),
                problem: format!(
                    "{} Hz is not a usable rate (8000..192000)",
                    s.output_rate_hz
                ),
            });
        }
        check_range("sound.native_spacing_um", s.native_spacing_um, 0.0, 1e6)?;
        check_range(
            "sound.normalize_peak",
            f64::from(s.normalize_peak),
            0.0,
            1.0,
        )?;
        check_range("sound.full_scale_mm_s", s.full_scale_mm_s, 1e-9, 1e9)?;
        check_range("dsp.lowpass_hz", self.dsp.lowpass_hz, 1.0, 1e6)?;
        hough::validate_params(&self.hough)?;
        self.still.validate()?;
        Ok(())
    }
}

pub use cache::{FlowDetail, GroupInput, StageCache};

/// The `lo` and `hi` quantiles (0–1) of the finite values, from at most about `samples` of them
/// taken at an even stride; None when none is finite.
#[must_use]
pub fn sampled_quantiles(values: &[f32], lo: f64, hi: f64, samples: usize) -> Option<(f32, f32)> {
    let stride = values.len().div_ceil(samples.max(1)).max(1);
    let mut v: Vec<f32> = values
        .iter()
        .step_by(stride)
        .copied()
        .filter(|x| x.is_finite())
        .collect();
    let last = v.len().checked_sub(1)?;
    let k = |q: f64| ((last as f64 * q.clamp(0.0, 1.0)).round() as usize).min(last);
    let (_, &mut a, _) = v.select_nth_unstable_by(k(lo), f32::total_cmp);
    let (_, &mut b, _) = v.select_nth_unstable_by(k(hi), f32::total_cmp);
    Some((a, b))
}

/// The median of `v` (the upper one of an even count); None when empty. NaN sorts last.
pub(crate) fn median(mut v: Vec<f64>) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    let mid = v.len() / 2;
    let (_, &mut m, _) = v.select_nth_unstable_by(mid, f64::total_cmp);
    Some(m)
}
