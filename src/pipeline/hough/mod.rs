//! Dual-focus stripes: in-focus map, Hough accumulator, three peaks with windows, segmentation and centroid lines (paper §9).
//!
//! # Geometry
//! A cover glass (thickness d, index n) over part of the view moves the focal plane δv = d·(1 − 1/n)
//! deeper there. With a depth of field of about 1 µm only thin stripes of the 45° walls are sharp:
//! the iso-depth contours at the plain focal distance Z₀ (no glass) and at Z₀ + δv (under the glass).
//! The left wall is at the top of the image (depth grows with y), the right wall at the bottom.
//! A deeper contour lies closer to the groove centre on both walls, so, top to bottom, the four
//! candidate contours are left@Z₀, left@Z₀+δv, right@Z₀+δv, right@Z₀. The glass edge decides which
//! three are visible:
//!
//! - [`GlassSide::Top`] (glass over rows above the edge, edge on the right wall): left@Z₀+δv,
//!   right@Z₀+δv (under the glass), right@Z₀. The **top** stripe is dropped (it is the opposite-wall
//!   twin of the middle one); the kept two lie on the **right** wall; the upper kept line is the
//!   one under the glass.
//! - [`GlassSide::Bottom`] (glass over rows below the edge, edge on the left wall), the mirror
//!   image: left@Z₀, left@Z₀+δv (under the glass), right@Z₀+δv. The **bottom** stripe is dropped;
//!   the kept two lie on the **left** wall; the lower kept line is the one under the glass.
//!
//! In both cases the stripe dropped is the outermost one on the glass side and the kept stripe next
//! to it is under the glass. The assignment uses this order only; `glass_edge_row` is not needed.
//!
//! # Hough convention
//! The stripes run along x, so the line angle θ is measured from the x axis (θ = 0 is a horizontal
//! line, positive θ slopes toward +y as x grows) and ρ is the signed distance along the line's
//! normal, measured from the point (x₀, 0) with x₀ = (width − 1)/2, the centre column:
//!
//! ρ = −(x − x₀)·sin θ + y·cos θ,   i.e. the line is y = (ρ + (x − x₀)·sin θ) / cos θ.
//!
//! ρ is therefore (about) the row where the line crosses the centre column. Taking the origin at
//! the centre column rather than at x = 0 halves how far a pixel's (θ, ρ) curve sweeps across a
//! peak's θ window, so neighbouring stripes' windows overlap only for much closer stripes.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::derivatives::Derivatives;
use super::optical_flow::FlowField;
use super::walls::{WallLine, WallSide};
use super::{StageError, check_range, median_in_place};
use crate::image::Image;
use crate::meta::{DualFocusMeta, GlassSide};

mod lines;
mod peaks;
#[cfg(test)]
#[allow(clippy::unwrap_used)] // Tests may panic on a broken expectation.
mod tests;
mod votes;

use lines::*;
pub use peaks::find_peaks;
use votes::*;
pub use votes::{Accumulator, Peak};

/// Stage name used in errors.
const STAGE: &str = "stripes";
/// The dual-focus geometry shows exactly this many stripes.
pub const STRIPE_COUNT: usize = 3;
/// Largest accepted `window_theta_deg`: below 90° so that a window's θ interval is shorter
/// than π (see `WindowTest::rho_range`).
pub const MAX_WINDOW_THETA_DEG: f32 = 89.0;
/// Largest accumulator the stage agrees to allocate (cells).
pub const MAX_ACCUMULATOR_CELLS: usize = 64 << 20;
/// Fraction of the peak's votes a ρ bin needs to count in the peak's sub-bin centroid.
const RHO_REFINE_FRACTION: f32 = 0.5;
/// Rows beyond half the stripe thickness that still count in a column's centroid (px).
const CENTROID_GATE_MARGIN_PX: f32 = 1.0;
/// Smallest half-width of the running median that rejects outlier columns (px).
const MIN_MEDIAN_HALF_PX: usize = 3;
/// Points whose ρ bins are computed together before their votes are cast (lets the bin
/// arithmetic vectorise).
const VOTE_BATCH: usize = 8;
/// Micrometres per millimetre.
const UM_PER_MM: f64 = 1000.0;
/// Largest accepted `window_rho_px` and `peak_rho_band_px`: ρ runs over the image height, so
/// any window past a sensor's size suppresses (or sums) the whole ρ range already.
const MAX_RHO_WINDOW_PX: f64 = 1e5;
/// Largest accepted `line_smoothing_px` (a half-window along the image width).
const MAX_LINE_SMOOTHING_PX: usize = 100_000;

/// Knobs of [`segment_stripes`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HoughParams {
    #[doc = knob!("hough.gradient_threshold")]
    pub gradient_threshold: f32,
    #[doc = knob!("hough.theta_min_deg")]
    pub theta_min_deg: f32,
    #[doc = knob!("hough.theta_max_deg")]
    pub theta_max_deg: f32,
    #[doc = knob!("hough.theta_step_deg")]
    pub theta_step_deg: f32,
    #[doc = knob!("hough.rho_step_px")]
    pub rho_step_px: f32,
    #[doc = knob!("hough.peak_count")]
    ///
    /// The dual-focus geometry needs exactly 3.
    pub peak_count: usize,
    #[doc = knob!("hough.window_theta_deg")]
    pub window_theta_deg: f32,
    #[doc = knob!("hough.window_rho_px")]
    pub window_rho_px: f32,
    #[doc = knob!("hough.line_smoothing_px")]
    pub line_smoothing_px: usize,
    #[doc = knob!("hough.min_votes_per_column")]
    ///
    /// A one-pixel-thick line across the whole width gives 1; weaker maxima are not stripes.
    pub min_votes_per_column: f32,
    #[doc = knob!("hough.min_peak_ratio")]
    ///
    /// Keeps the "butterfly" flanks of a strong stripe and noise from passing for a missing stripe.
    pub min_peak_ratio: f32,
    #[doc = knob!("hough.peak_rho_band_px")]
    ///
    /// A stripe that wiggles by ±A px with the sound spreads its votes over about 2A px of ρ;
    /// summing over a band of about ±A makes its mean line win over chance tangents. The sums also
    /// collect more noise: raise `min_votes_per_column` with it. Peak votes and the thresholds then
    /// refer to the band sums.
    pub peak_rho_band_px: f32,
    #[doc = knob!("hough.max_vote_points")]
    ///
    /// The vote threshold is scaled by 1/k; segmentation always uses every pixel.
    pub max_vote_points: usize,
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
            min_votes_per_column: 0.1,
            min_peak_ratio: 0.25,
            peak_rho_band_px: 0.0,
            max_vote_points: 100_000,
        }
    }
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
    /// Index (into `peaks`) of the dropped stripe: 0 (top) for [`GlassSide::Top`], the last
    /// (bottom) for [`GlassSide::Bottom`].
    pub dropped: usize,
    /// The two kept centroid lines, top to bottom, each with its depth and filled voids marked.
    pub lines: Vec<WallLine>,
    /// Index (into `peaks`) of each line in `lines`.
    pub line_peaks: Vec<usize>,
}

impl Stripes {
    /// The label of pixel (`x`, `y`) of the in-focus map: an index into `peaks` or a [`label`]
    /// constant ([`label::NONE`] outside the map).
    #[must_use]
    pub fn label_at(&self, x: usize, y: usize) -> i8 {
        let w = self.in_focus.width;
        if x >= w {
            return label::NONE;
        }
        self.labels.get(y * w + x).copied().unwrap_or(label::NONE)
    }
}

/// The in-focus map, Hough accumulator and peaks alone, for showing why segmentation failed
/// (`inspect` writes them when [`segment_stripes`] returns an error).
///
/// # Errors
/// As [`segment_stripes`] for invalid params or mismatched images.
pub fn hough_diagnostics(
    derivs: &Derivatives,
    flow: &FlowField,
    params: &HoughParams,
) -> Result<(Image, Accumulator, Vec<Peak>), StageError> {
    let v = votes_and_peaks(derivs, flow, params)?;
    Ok((v.in_focus, v.accumulator, v.peaks))
}

/// Runs the dual-focus stripe stages on one derivative set and its flow.
///
/// In-focus map -> Hough votes -> three peaks with non-maximum suppression -> segmentation by
/// windows -> the two kept centroid lines (see the module docs for the geometry and conventions).
///
/// # Errors
/// [`StageError::InvalidParam`] on invalid params or dual-focus metadata, [`StageError::BadInput`]
/// when the images differ in size or are empty, [`StageError::NotFound`] when fewer than three
/// stripes are found or a kept stripe has no pixels of its own.
pub fn segment_stripes(
    derivs: &Derivatives,
    flow: &FlowField,
    dual: &DualFocusMeta,
    params: &HoughParams,
) -> Result<Stripes, StageError> {
    validate_dual(dual)?;
    let Votes {
        in_focus,
        points,
        accumulator,
        min_votes,
        peaks,
    } = votes_and_peaks(derivs, flow, params)?;
    let (w, h) = (derivs.ix.width, derivs.ix.height);
    if peaks.len() < STRIPE_COUNT {
        return Err(StageError::NotFound {
            stage: STAGE,
            problem: format!(
                "found {} stripes, need {STRIPE_COUNT} (peaks need {min_votes} votes)",
                peaks.len()
            ),
        });
    }

    let point_labels = label_points(&points, &peaks);
    let mut labels = vec![label::NONE; w * h];
    for (p, &l) in points.iter().zip(&point_labels) {
        if let Some(slot) = labels.get_mut(p.index as usize) {
            *slot = l;
        }
    }

    let (focus_plain_mm, focus_glass_mm) = dual.focal_distances_mm();
    // (dropped, [(kept peak, under glass)], wall) per the module docs.
    let (dropped, kept, side) = match dual.glass_side {
        GlassSide::Top => (0, [(1, true), (2, false)], WallSide::Right),
        GlassSide::Bottom => (2, [(0, false), (1, true)], WallSide::Left),
    };
    let mut lines = Vec::with_capacity(kept.len());
    let mut line_peaks = Vec::with_capacity(kept.len());
    for (k, under_glass) in kept {
        let Some(peak) = peaks.get(k) else {
            return Err(not_found(format!("stripe {k} missing")));
        };
        let line = centroid_line(&points, &point_labels, k, w, peak, params);
        if line.filled.iter().all(|&f| f) {
            return Err(not_found(format!(
                "stripe {k} has no pixels of its own (all lie in overlapping windows)"
            )));
        }
        let depth_mm = if under_glass {
            focus_glass_mm
        } else {
            focus_plain_mm
        };
        lines.push(WallLine {
            side,
            depth_um: Some(depth_mm * UM_PER_MM),
            // Under the glass a point at true distance Z appears at Z − δv = Z₀: both lines
            // back-project with the plain focal distance.
            projection_depth_um: Some(focus_plain_mm * UM_PER_MM),
            ..line
        });
        line_peaks.push(k);
    }

    Ok(Stripes {
        in_focus,
        accumulator,
        peaks,
        labels,
        dropped,
        lines,
        line_peaks,
    })
}

fn bad_input(problem: String) -> StageError {
    StageError::BadInput {
        stage: STAGE,
        problem,
    }
}

fn not_found(problem: String) -> StageError {
    StageError::NotFound {
        stage: STAGE,
        problem,
    }
}

impl HoughParams {
    /// Checks every Hough knob.
    ///
    /// # Errors
    /// [`StageError::InvalidParam`] naming the first bad key.
    pub fn validate(&self) -> Result<(), StageError> {
        let p = self;
        check_range(
            "hough.gradient_threshold",
            f64::from(p.gradient_threshold),
            0.0,
            f64::MAX,
        )?;
        check_range(
            "hough.theta_min_deg",
            f64::from(p.theta_min_deg),
            -90.0,
            90.0,
        )?;
        check_range(
            "hough.theta_max_deg",
            f64::from(p.theta_max_deg),
            -90.0,
            90.0,
        )?;
        if p.theta_max_deg < p.theta_min_deg {
            return Err(StageError::invalid(
                "hough.theta_max_deg",
                format!(
                    "θ range is reversed ({} > {})",
                    p.theta_min_deg, p.theta_max_deg
                ),
            ));
        }
        check_range(
            "hough.theta_step_deg",
            f64::from(p.theta_step_deg),
            1e-3,
            90.0,
        )?;
        if p.theta_step_deg <= 0.0 {
            return Err(StageError::invalid(
                "hough.theta_step_deg",
                "must be positive".into(),
            ));
        }
        check_range("hough.rho_step_px", f64::from(p.rho_step_px), 1e-2, 1e6)?;
        if p.peak_count != STRIPE_COUNT {
            return Err(StageError::invalid(
                "hough.peak_count",
                format!(
                    "the dual-focus geometry shows exactly {STRIPE_COUNT} stripes, got {}",
                    p.peak_count
                ),
            ));
        }
        check_range(
            "hough.window_theta_deg",
            f64::from(p.window_theta_deg),
            0.0,
            f64::from(MAX_WINDOW_THETA_DEG),
        )?;
        check_range(
            "hough.window_rho_px",
            f64::from(p.window_rho_px),
            0.0,
            MAX_RHO_WINDOW_PX,
        )?;
        check_range(
            "hough.peak_rho_band_px",
            f64::from(p.peak_rho_band_px),
            0.0,
            MAX_RHO_WINDOW_PX,
        )?;
        if p.line_smoothing_px > MAX_LINE_SMOOTHING_PX {
            return Err(StageError::invalid(
                "hough.line_smoothing_px",
                format!(
                    "{} is not in [0, {MAX_LINE_SMOOTHING_PX}]",
                    p.line_smoothing_px
                ),
            ));
        }
        check_range(
            "hough.min_peak_ratio",
            f64::from(p.min_peak_ratio),
            0.0,
            1.0,
        )?;
        check_range(
            "hough.min_votes_per_column",
            f64::from(p.min_votes_per_column),
            0.0,
            f64::MAX,
        )?;
        Ok(())
    }
}

/// [`HoughParams::validate`] (the path other code used).
///
/// # Errors
/// As that.
pub fn validate_params(p: &HoughParams) -> Result<(), StageError> {
    p.validate()
}

fn validate_dual(d: &DualFocusMeta) -> Result<(), StageError> {
    check_range(
        "dual_focus.focus_distance_mm",
        d.focus_distance_mm,
        f64::MIN_POSITIVE,
        f64::MAX,
    )?;
    check_range(
        "dual_focus.glass_thickness_mm",
        d.glass_thickness_mm,
        0.0,
        f64::MAX,
    )?;
    check_range("dual_focus.glass_index", d.glass_index, 1.0, f64::MAX)
}

/// Cells of the accumulator `params` make for frames of `height_px` rows (θ bins × ρ bins);
/// the stage refuses more than [`MAX_ACCUMULATOR_CELLS`].
#[must_use]
pub fn accumulator_cells(params: &HoughParams, height_px: usize) -> usize {
    theta_count(params).saturating_mul(rho_count(height_px, params))
}

fn theta_count(p: &HoughParams) -> usize {
    // A little slack so that e.g. −45..45 by 1 gives 91 bins despite rounding.
    ((p.theta_max_deg - p.theta_min_deg) / p.theta_step_deg + 1e-4).floor() as usize + 1
}

fn rho_count(height: usize, p: &HoughParams) -> usize {
    ((height as f32 / p.rho_step_px).ceil() as usize).max(1)
}

/// A synthetic input for [`segment_stripes`] (its tests and benchmark): ∂I/∂y is `gradient` at
/// the pixels where `in_focus(x, y)` holds and 0 elsewhere, with exact zero flow (full
/// confidence) on frame 3. `in_focus` is called once a pixel, row by row.
#[doc(hidden)]
#[must_use]
pub fn synthetic_input(
    width: usize,
    height: usize,
    gradient: f32,
    mut in_focus: impl FnMut(usize, usize) -> bool,
) -> (Derivatives, FlowField) {
    let value = |on: bool| if on { gradient } else { 0.0 };
    let iy = Image::from_fn(width, height, |x, y| value(in_focus(x, y)));
    let flow = FlowField::exact(Image::zeros(width, height), 3);
    (Derivatives::from_iy(iy, 3, -2.0), flow)
}
