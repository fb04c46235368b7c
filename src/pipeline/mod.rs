//! The reconstruction pipeline: pure per-group stages (no I/O, no GUI) and the stage cache both front ends share.

pub mod audio_signal;
pub mod cache;
pub mod depth;
pub mod derivatives;
pub mod dsp;
pub mod eval;
pub mod finish;
pub mod graph;
pub mod hough;
pub mod knobs;
pub mod optical_flow;
pub mod orientation;
pub mod sampling;
pub mod slope_reference;
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

    /// The earliest stage (in [`Stage::ALL`] order) that reads a knob that differs between
    /// `self` and `other` (None when none does).
    #[must_use]
    pub fn first_changed_stage(&self, other: &Self) -> Option<Stage> {
        graph::GRAPH
            .iter()
            .find(|spec| (spec.knobs_changed)(self, other))
            .map(|spec| spec.stage)
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
        let max_iterations = optical_flow::MAX_FLOW_ITERATIONS;
        if self.flow.max_iterations == 0 || self.flow.max_iterations > max_iterations {
            return Err(StageError::InvalidParam {
                name: "flow.max_iterations".into(),
                problem: format!(
                    "{} is not in [1, {max_iterations}]",
                    self.flow.max_iterations
                ),
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
        Ok(())
    }
}

pub use cache::{GroupInput, StageCache};
pub use graph::{DepthOutput, FlowDetail, OrientationOutput, Stage, frames_read};

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
