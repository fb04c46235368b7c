//! The reconstruction pipeline: pure per-group stages (no I/O, no GUI) and the stage cache both front ends share.

// First, so that `knob!` (the knob docs) is in scope for the stages' params.
#[macro_use]
pub mod knobs;

pub mod audio_signal;
pub mod cache;
pub mod depth;
pub mod derivatives;
pub mod dsp;
pub mod edges;
pub mod eval;
pub mod finish;
pub mod fusion;
pub mod graph;
pub mod hough;
pub mod optical_flow;
pub mod orientation;
pub mod sampling;
pub mod simd;
pub mod slope_reference;
pub mod still;
#[cfg(test)]
pub(crate) mod test_support;
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
        Err(StageError::invalid(
            name,
            format!(
                "{} is not in [{}, {}]",
                compact(value),
                compact(lo),
                compact(hi)
            ),
        ))
    }
}

/// `v` as a message shows it: `{}` writes 1e-300 as 300 digits, so very large and very small
/// values are written as `1e-300` (scan.toml's messages use it too).
pub(crate) fn compact(v: f64) -> String {
    if v.abs() >= 1e9 || (v != 0.0 && v.abs() < 1e-4) {
        format!("{v:e}")
    } else {
        v.to_string()
    }
}

impl StageError {
    /// [`StageError::InvalidParam`] naming the parameter `name` (its TOML path).
    #[must_use]
    pub fn invalid(name: &str, problem: String) -> Self {
        Self::InvalidParam {
            name: name.to_string(),
            problem,
        }
    }
}

use serde::{Deserialize, Serialize};

use crate::meta::ScanMeta;
use audio_signal::SoundParams;
use depth::DepthParams;
use derivatives::DerivativeParams;
use dsp::DspParams;
use edges::EdgeParams;
use fusion::FusionParams;
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

/// Which decoder makes the sound.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// The wall tilt by optical flow (the path's stages, then the sound stage).
    Flow,
    /// The walls' sub-pixel borders ([`edges`]), differentiated.
    Edges,
    /// Both, combined per frequency band ([`fusion`]): the default, best or within 0.1 dB of
    /// the best in every measured case (docs/ACCURACY.md), where each single method fails in one.
    #[default]
    Fused,
}

impl Method {
    /// True when the method's sound reads the flow method's stages.
    #[must_use]
    pub fn reads_flow(self) -> bool {
        self != Method::Edges
    }

    /// True when the method's sound reads the edge stage.
    #[must_use]
    pub fn reads_edges(self) -> bool {
        self != Method::Flow
    }

    /// The name as in params.toml and `--method`.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Method::Flow => "flow",
            Method::Edges => "edges",
            Method::Fused => "fused",
        }
    }

    /// The method of a `--method` word.
    #[must_use]
    pub fn from_name(name: &str) -> Option<Self> {
        [Method::Flow, Method::Edges, Method::Fused]
            .into_iter()
            .find(|m| m.name() == name)
    }
}

/// Every knob of the pipeline, one table per stage (the `groovescope params` TOML).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields, default)]
pub struct PipelineParams {
    // The line names the `[dual_focus]` table of scan.toml, not an item.
    #[allow(rustdoc::broken_intra_doc_links)]
    #[doc = knob!("path")]
    pub path: PathChoice,
    #[doc = knob!("method")]
    pub method: Method,
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
    /// Edge stage (the `edges` and `fused` methods).
    pub edges: EdgeParams,
    /// Fused decoder (the `fused` method).
    pub fusion: FusionParams,
    /// The still-image decoder (`groovescope still`; scans do not read it).
    pub still: still::StillParams,
}

impl PipelineParams {
    /// True when `other` runs the same groups as these params: they differ at most in the
    /// `[dsp]` table, which only the finish reads.
    #[must_use]
    pub fn same_groups_as(&self, other: &Self) -> bool {
        *other
            == Self {
                dsp: other.dsp.clone(),
                ..self.clone()
            }
    }

    /// Parses params TOML (missing tables and keys take defaults).
    ///
    /// # Errors
    /// A message naming the bad key.
    pub fn from_toml_str(text: &str) -> Result<Self, String> {
        toml::from_str(text).map_err(|e| crate::toml_error::located(text, &e))
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

    /// The name of the path these params take on a scan of `meta`: "dual-focus" or "depth".
    #[must_use]
    pub fn path_name(&self, meta: &ScanMeta) -> &'static str {
        if self.uses_dual_focus(meta) {
            "dual-focus"
        } else {
            "depth"
        }
    }

    /// Checks every knob: each stage's table through its params' `validate` (the same checks
    /// the stages make). The clip-only checks are [`PipelineParams::validate_for_clip`]'s, so
    /// that a DSP setting never stops the per-group stages of the workbench.
    ///
    /// # Errors
    /// [`StageError::InvalidParam`] naming the first bad key.
    pub fn validate(&self) -> Result<(), StageError> {
        self.flow.validate()?;
        self.depth.validate()?;
        self.walls.validate()?;
        self.orientation.validate()?;
        self.sound.validate()?;
        self.dsp.validate()?;
        self.edges.validate()?;
        self.fusion.validate()?;
        self.hough.validate()?;
        self.still.validate()
    }

    /// [`PipelineParams::validate`], then what finishing a clip needs of the knobs together:
    /// the DSP corners below the output rate's Nyquist. Run before a clip's first group, so a
    /// filter the finishing would refuse is refused before hours of groups, not after them.
    ///
    /// # Errors
    /// [`StageError::InvalidParam`] naming the first bad key.
    pub fn validate_for_clip(&self) -> Result<(), StageError> {
        self.validate()?;
        dsp::check_chain(f64::from(self.sound.output_rate_hz), &self.dsp)
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

/// The mean of the finite entries of `values` within `half` of each index (NaN where there
/// are none), by prefix sums: a moving average that skips what was not measured. (NaN, not
/// `Option`: a side's edge decode takes these over 8 M samples.)
#[must_use]
pub(crate) fn finite_window_means(values: &[f64], half: usize) -> Vec<f64> {
    let n = values.len();
    let mut sum = vec![0.0_f64; n + 1];
    let mut count = vec![0usize; n + 1];
    for (i, &v) in values.iter().enumerate() {
        let known = v.is_finite();
        sum[i + 1] = sum[i] + if known { v } else { 0.0 };
        count[i + 1] = count[i] + usize::from(known);
    }
    (0..n)
        .map(|i| {
            let (lo, hi) = (i.saturating_sub(half), (i + half + 1).min(n));
            match count[hi] - count[lo] {
                0 => f64::NAN,
                k => (sum[hi] - sum[lo]) / k as f64,
            }
        })
        .collect()
}

/// Values a median is taken of: a total order (floats by `total_cmp`, so NaN sorts last).
pub(crate) trait TotalOrder: Copy {
    /// The order.
    fn total_order(&self, other: &Self) -> std::cmp::Ordering;
}

impl TotalOrder for f32 {
    fn total_order(&self, other: &Self) -> std::cmp::Ordering {
        self.total_cmp(other)
    }
}

impl TotalOrder for f64 {
    fn total_order(&self, other: &Self) -> std::cmp::Ordering {
        self.total_cmp(other)
    }
}

impl TotalOrder for usize {
    fn total_order(&self, other: &Self) -> std::cmp::Ordering {
        self.cmp(other)
    }
}

/// The median of `v` (the upper one of an even count), by selection, reordering `v`; None
/// when empty. The one median of the pipeline: every stage's medians call it.
pub(crate) fn median_in_place<T: TotalOrder>(v: &mut [T]) -> Option<T> {
    if v.is_empty() {
        return None;
    }
    let mid = v.len() / 2;
    let (_, &mut m, _) = v.select_nth_unstable_by(mid, T::total_order);
    Some(m)
}

/// [`median_in_place`] of a vector it takes.
pub(crate) fn median(mut v: Vec<f64>) -> Option<f64> {
    median_in_place(&mut v)
}

/// MAD to σ for normal noise.
const MAD_TO_SIGMA: f64 = 1.4826;

/// Robust σ of the finite values of `r` about zero (1.4826 × their median |r|), never under
/// `floor` (and `floor` when none is finite).
pub(crate) fn robust_sigma(r: &[f64], floor: f64) -> f64 {
    median(
        r.iter()
            .filter(|x| x.is_finite())
            .map(|x| x.abs())
            .collect(),
    )
    .map_or(floor, |m| (MAD_TO_SIGMA * m).max(floor))
}

/// Lagrange interpolation at `p` through the nodes `(x, y)` (distinct `x`): the one polynomial
/// interpolant of the pipeline (stitching, gap bridging, still resampling).
pub(crate) fn lagrange(nodes: &[(f64, f64)], p: f64) -> f64 {
    let mut sum = 0.0;
    for (i, &(xi, yi)) in nodes.iter().enumerate() {
        let mut basis = 1.0;
        for (j, &(xj, _)) in nodes.iter().enumerate() {
            if i != j {
                basis *= (p - xj) / (xi - xj);
            }
        }
        sum += basis * yi;
    }
    sum
}

/// `ranges` sorted by start, with overlapping or touching ones merged.
pub(crate) fn merge_ranges(mut ranges: Vec<std::ops::Range<usize>>) -> Vec<std::ops::Range<usize>> {
    ranges.sort_by_key(|r| r.start);
    let mut out: Vec<std::ops::Range<usize>> = Vec::new();
    for r in ranges {
        match out.last_mut() {
            Some(last) if r.start <= last.end => last.end = last.end.max(r.end),
            _ => out.push(r),
        }
    }
    out
}
