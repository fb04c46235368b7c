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
use super::{StageError, check_range};
use crate::image::Image;
use crate::io::scan::{DualFocusMeta, GlassSide};

/// Stage name used in errors.
const STAGE: &str = "stripes";
/// The dual-focus geometry shows exactly this many stripes.
const STRIPE_COUNT: usize = 3;
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
    /// Peaks searched for (paper: 3). The dual-focus geometry needs exactly 3.
    pub peak_count: usize,
    /// Half-width of a peak's window in θ (degrees).
    pub window_theta_deg: f32,
    /// Half-width of a peak's window in ρ (px).
    pub window_rho_px: f32,
    /// Smoothing of centroid lines along x (moving-average half-width, px).
    pub line_smoothing_px: usize,
    /// A peak needs at least this many votes per image column (a one-pixel-thick line across the
    /// whole width gives 1); weaker maxima are not stripes.
    pub min_votes_per_column: f32,
    /// A peak also needs at least this fraction of the strongest peak's votes (keeps the
    /// "butterfly" flanks of a strong stripe and noise from passing for a missing stripe).
    pub min_peak_ratio: f32,
    /// Peaks are searched on the votes summed over ±this many px of ρ (0: single bins, the
    /// paper's plain Hough). A stripe that wiggles by ±A px with the sound spreads its votes over
    /// about 2A px of ρ; summing over a band of about ±A makes its mean line win over chance
    /// tangents. The sums also collect more noise: raise `min_votes_per_column` with it.
    /// Peak votes and the thresholds then refer to the band sums.
    pub peak_rho_band_px: f32,
    /// At most this many in-focus pixels vote (0 = all); above it every k-th pixel (row-major)
    /// votes, and the vote threshold is scaled by 1/k. Segmentation always uses every pixel.
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

/// The Hough vote array: `votes[t * rho_bins + r]` for θ bin t and ρ bin r.
///
/// θ bin t is centred on `thetas_rad[t]`; ρ bin r is centred on `rho_min_px + r·rho_step_px` and
/// covers half a step either side. A pixel (x, y) votes in θ bin t for the ρ bin holding
/// ρ = −(x − x_origin_px)·sin θ + y·cos θ (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct Accumulator {
    /// θ of each bin (radians): the line angle from the x axis.
    pub thetas_rad: Vec<f32>,
    /// ρ of bin 0 (px).
    pub rho_min_px: f32,
    /// ρ bin width (px).
    pub rho_step_px: f32,
    /// Number of ρ bins.
    pub rho_bins: usize,
    /// Votes.
    pub votes: Vec<u32>,
    /// Column the ρ origin sits on, (width − 1)/2 (px).
    pub x_origin_px: f32,
    /// Every `vote_stride`-th in-focus pixel voted (1 = all).
    pub vote_stride: usize,
}

impl Accumulator {
    /// Number of θ bins.
    #[must_use]
    pub fn theta_bins(&self) -> usize {
        self.thetas_rad.len()
    }

    /// Votes at θ bin `t`, ρ bin `r` (0 outside).
    #[must_use]
    pub fn get(&self, t: usize, r: usize) -> u32 {
        if r >= self.rho_bins {
            return 0;
        }
        self.votes.get(t * self.rho_bins + r).copied().unwrap_or(0)
    }

    /// Centre of ρ bin `r` (px).
    #[must_use]
    pub fn rho_of_bin(&self, r: usize) -> f32 {
        self.rho_min_px + r as f32 * self.rho_step_px
    }

    /// Fractional θ bin of an angle (bin centres are integers).
    #[must_use]
    pub fn theta_bin_f(&self, theta_rad: f32) -> f32 {
        let (Some(first), Some(second)) = (self.thetas_rad.first(), self.thetas_rad.get(1)) else {
            return 0.0;
        };
        (theta_rad - first) / (second - first)
    }

    /// Fractional ρ bin of an offset (bin centres are integers).
    #[must_use]
    pub fn rho_bin_f(&self, rho_px: f32) -> f32 {
        (rho_px - self.rho_min_px) / self.rho_step_px
    }
}

/// One accumulator peak and its window: the line −(x − x₀)·sin θ + y·cos θ = ρ with x₀ = `x_origin_px`.
///
/// The window is θ ∈ [θ − window_theta_rad, θ + window_theta_rad] × ρ ∈ [ρ − window_rho_px, ρ + window_rho_px].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Peak {
    /// Line angle from the x axis (radians); the centre of the winning θ bin.
    pub theta_rad: f32,
    /// Line offset (px): about the row at the centre column. Refined below the bin width by the
    /// vote-weighted centroid of the bins at the peak's θ holding at least half its votes.
    pub rho_px: f32,
    /// Votes at the peak.
    pub votes: u32,
    /// Column of the ρ origin (px).
    pub x_origin_px: f32,
    /// Half-width of the window in θ (radians).
    pub window_theta_rad: f32,
    /// Half-width of the window in ρ (px).
    pub window_rho_px: f32,
}

impl Peak {
    /// Row of the peak line at column `x` (px).
    #[must_use]
    pub fn row_at_px(&self, x: f32) -> f32 {
        let (s, c) = self.theta_rad.sin_cos();
        (self.rho_px + (x - self.x_origin_px) * s) / c
    }

    /// True when the (θ, ρ) curve of pixel (x, y) passes through this peak's window, i.e. some θ
    /// in the window gives a ρ in the window.
    #[must_use]
    pub fn window_contains_curve_of(&self, x: f32, y: f32) -> bool {
        WindowTest::new(self).contains(f64::from(x - self.x_origin_px), f64::from(y))
    }
}

/// A peak's window with its θ ends' sines and cosines precomputed, for the per-pixel test.
#[derive(Clone, Copy, Debug)]
struct WindowTest {
    /// sin, cos of θ − wθ.
    sa: f64,
    ca: f64,
    /// sin, cos of θ + wθ.
    sb: f64,
    cb: f64,
    rho_lo: f64,
    rho_hi: f64,
}

impl WindowTest {
    fn new(p: &Peak) -> Self {
        let (sa, ca) = f64::from(p.theta_rad - p.window_theta_rad).sin_cos();
        let (sb, cb) = f64::from(p.theta_rad + p.window_theta_rad).sin_cos();
        let rho = f64::from(p.rho_px);
        let w = f64::from(p.window_rho_px);
        Self {
            sa,
            ca,
            sb,
            cb,
            rho_lo: rho - w,
            rho_hi: rho + w,
        }
    }

    /// Range of ρ(θ) = −xc·sin θ + y·cos θ over the window's θ interval (shorter than π).
    ///
    /// ρ(θ) = r·cos(θ − θ*) has its maximum r where dρ/dθ = −xc·cos θ − y·sin θ turns from
    /// positive to negative and its minimum −r where it turns the other way; an interval shorter
    /// than π holds at most one of them, found from the derivative's signs at the two ends.
    fn rho_range(&self, xc: f64, y: f64) -> (f64, f64) {
        let ra = -xc * self.sa + y * self.ca;
        let rb = -xc * self.sb + y * self.cb;
        let da = -xc * self.ca - y * self.sa;
        let db = -xc * self.cb - y * self.sb;
        let mut lo = ra.min(rb);
        let mut hi = ra.max(rb);
        if da > 0.0 && db < 0.0 {
            hi = xc.hypot(y);
        } else if da < 0.0 && db > 0.0 {
            lo = -xc.hypot(y);
        }
        (lo, hi)
    }

    /// True when the curve of the pixel at centred column `xc`, row `y` meets the window.
    fn contains(&self, xc: f64, y: f64) -> bool {
        let (lo, hi) = self.rho_range(xc, y);
        hi >= self.rho_lo && lo <= self.rho_hi
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

/// An in-focus pixel: centred column x − x₀, row y, and its row-major index.
#[derive(Clone, Copy, Debug)]
struct FocusPoint {
    xc: f32,
    y: f32,
    index: u32,
}

/// The in-focus map, its points, the Hough accumulator and its peaks of one derivative set.
struct Votes {
    in_focus: Image,
    points: Vec<FocusPoint>,
    accumulator: Accumulator,
    min_votes: u32,
    peaks: Vec<Peak>,
}

/// Checks the inputs, finds the in-focus pixels, votes and finds the peaks (the first half of
/// [`segment_stripes`]).
fn votes_and_peaks(
    derivs: &Derivatives,
    flow: &FlowField,
    params: &HoughParams,
) -> Result<Votes, StageError> {
    validate_params(params)?;
    let (w, h) = (derivs.ix.width, derivs.ix.height);
    if w == 0 || h == 0 {
        return Err(bad_input("empty image".into()));
    }
    if !derivs.ix.same_size(&derivs.iy) || !derivs.ix.same_size(&flow.confidence) {
        return Err(bad_input(format!(
            "sizes differ: Ix {}×{}, Iy {}×{}, flow confidence {}×{}",
            w, h, derivs.iy.width, derivs.iy.height, flow.confidence.width, flow.confidence.height
        )));
    }
    if w > usize::from(u16::MAX) || h > usize::from(u16::MAX) {
        return Err(bad_input(format!("image {w}×{h} is too large")));
    }
    let cells = accumulator_cells(params, h);
    if cells > MAX_ACCUMULATOR_CELLS {
        return Err(invalid(
            "hough.theta_step_deg",
            format!(
                "the accumulator would have {cells} cells (at most {MAX_ACCUMULATOR_CELLS}); use coarser θ or ρ steps"
            ),
        ));
    }
    let (in_focus, points) = in_focus_points(&derivs.ix, &derivs.iy, &flow.confidence, params);
    let stride = vote_stride(points.len(), params.max_vote_points);
    let accumulator = vote(&points, stride, w, h, params);
    let min_votes = min_peak_votes(w, stride, params);
    let peaks = find_peaks(&accumulator, params, min_votes);
    Ok(Votes {
        in_focus,
        points,
        accumulator,
        min_votes,
        peaks,
    })
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

fn invalid(name: &str, problem: String) -> StageError {
    StageError::InvalidParam {
        name: name.to_string(),
        problem,
    }
}

/// Checks every knob of [`HoughParams`].
///
/// # Errors
/// [`StageError::InvalidParam`] naming the first bad knob.
pub fn validate_params(p: &HoughParams) -> Result<(), StageError> {
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
        return Err(invalid(
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
        return Err(invalid("hough.theta_step_deg", "must be positive".into()));
    }
    check_range("hough.rho_step_px", f64::from(p.rho_step_px), 1e-2, 1e6)?;
    if p.peak_count != STRIPE_COUNT {
        return Err(invalid(
            "hough.peak_count",
            format!(
                "the dual-focus geometry shows exactly {STRIPE_COUNT} stripes, got {}",
                p.peak_count
            ),
        ));
    }
    // Below 90° so a window's θ interval is shorter than π (see `WindowTest::rho_range`).
    check_range(
        "hough.window_theta_deg",
        f64::from(p.window_theta_deg),
        0.0,
        89.0,
    )?;
    check_range(
        "hough.window_rho_px",
        f64::from(p.window_rho_px),
        0.0,
        f64::MAX,
    )?;
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

/// Builds the in-focus map and the list of in-focus pixels (row-major order).
fn in_focus_points(
    ix: &Image,
    iy: &Image,
    confidence: &Image,
    params: &HoughParams,
) -> (Image, Vec<FocusPoint>) {
    let (w, h) = (ix.width, ix.height);
    let x0 = (w as f32 - 1.0) * 0.5;
    let thr2 = params.gradient_threshold * params.gradient_threshold;
    let mut map = Image::zeros(w, h);
    let rows: Vec<Vec<FocusPoint>> = map
        .data
        .par_chunks_mut(w)
        .enumerate()
        .map(|(y, out)| {
            let mut pts = Vec::new();
            let gx = ix.row(y);
            let gy = iy.row(y);
            let cf = confidence.row(y);
            for (x, (((o, &a), &b), &c)) in out.iter_mut().zip(gx).zip(gy).zip(cf).enumerate() {
                if a * a + b * b > thr2 && c > 0.0 {
                    *o = 1.0;
                    pts.push(FocusPoint {
                        xc: x as f32 - x0,
                        y: y as f32,
                        index: (y * w + x) as u32,
                    });
                }
            }
            pts
        })
        .collect();
    let points = rows.into_iter().flatten().collect();
    (map, points)
}

fn vote_stride(n_points: usize, max_points: usize) -> usize {
    if max_points == 0 || n_points <= max_points {
        1
    } else {
        n_points.div_ceil(max_points)
    }
}

fn min_peak_votes(width: usize, stride: usize, p: &HoughParams) -> u32 {
    let v = (p.min_votes_per_column * width as f32 / stride as f32).ceil();
    (v as u32).max(1)
}

/// Votes the points (every `stride`-th) into a fresh accumulator, one θ row per rayon task.
fn vote(
    points: &[FocusPoint],
    stride: usize,
    width: usize,
    height: usize,
    p: &HoughParams,
) -> Accumulator {
    let nt = theta_count(p);
    let nr = rho_count(height, p);
    let thetas_rad: Vec<f32> = (0..nt)
        .map(|t| (p.theta_min_deg + t as f32 * p.theta_step_deg).to_radians())
        .collect();
    let rho_min_px = 0.0_f32;
    let inv_step = 1.0 / p.rho_step_px;
    let mut votes = vec![0u32; nt * nr];
    let positions: Vec<[f32; 2]> = points
        .iter()
        .step_by(stride)
        .map(|pt| [pt.xc, pt.y])
        .collect();
    votes
        .par_chunks_mut(nr)
        .zip(thetas_rad.par_iter())
        .for_each(|(row, &theta)| {
            let (s, c) = theta.sin_cos();
            // ρ bin = round((ρ − ρ_min)/step) = floor(a·xc + b·y + off), with the rounding 0.5
            // and a further +1 folded into `off` so that truncation toward zero acts as floor for
            // every bin ≥ −1; the 1 is taken off after the cast and negative bins wrap to huge
            // u32 values that fall outside the row.
            let a = -s * inv_step;
            let b = c * inv_step;
            let off = -rho_min_px * inv_step + 0.5 + 1.0;
            let bin = |p: &[f32; 2]| ((p[0] * a + p[1] * b + off) as i32).wrapping_sub(1) as u32;
            let mut chunks = positions.chunks_exact(VOTE_BATCH);
            for batch in &mut chunks {
                // Bins first (vectorises), then the scattered increments.
                let mut ks = [0u32; VOTE_BATCH];
                for (k, p) in ks.iter_mut().zip(batch) {
                    *k = bin(p);
                }
                for &k in &ks {
                    if let Some(v) = row.get_mut(k as usize) {
                        *v += 1;
                    }
                }
            }
            for p in chunks.remainder() {
                if let Some(v) = row.get_mut(bin(p) as usize) {
                    *v += 1;
                }
            }
        });
    Accumulator {
        thetas_rad,
        rho_min_px,
        rho_step_px: p.rho_step_px,
        rho_bins: nr,
        votes,
        x_origin_px: (width as f32 - 1.0) * 0.5,
        vote_stride: stride,
    }
}

/// Finds up to `params.peak_count` global maxima with at least `min_votes` votes (and at least
/// `params.min_peak_ratio` of the first peak's votes), suppressing
/// each peak's window (±window_theta_deg, ±window_rho_px) before looking for the next, and
/// returns them sorted top to bottom (by row at the centre column). A maximum whose line crosses
/// a chosen peak's line inside the frame, or comes within a window half-width of it, is another
/// tangent of the same (curved) stripe and is skipped.
#[must_use]
pub fn find_peaks(acc: &Accumulator, params: &HoughParams, min_votes: u32) -> Vec<Peak> {
    let nr = acc.rho_bins;
    let nt = acc.theta_bins();
    if nr == 0 || nt == 0 {
        return Vec::new();
    }
    let wt = (params.window_theta_deg / params.theta_step_deg).round() as usize;
    let wr = (params.window_rho_px / acc.rho_step_px).round() as usize;
    let band = (params.peak_rho_band_px / acc.rho_step_px).round() as usize;
    let mut work = if band == 0 {
        acc.votes.clone()
    } else {
        band_sums(acc, band)
    };
    let mut peaks: Vec<Peak> = Vec::with_capacity(params.peak_count);
    'next_peak: while peaks.len() < params.peak_count {
        let Some((best, &votes)) = work
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(&a.0)))
        else {
            break;
        };
        let ratio_floor = peaks
            .first()
            .map_or(0.0, |p: &Peak| p.votes as f32 * params.min_peak_ratio);
        if votes < min_votes || votes == 0 || (votes as f32) < ratio_floor {
            break;
        }
        let (t, r) = (best / nr, best % nr);
        for tt in t.saturating_sub(wt)..=(t + wt).min(nt - 1) {
            let row = tt * nr;
            for rr in r.saturating_sub(wr)..=(r + wr).min(nr - 1) {
                if let Some(v) = work.get_mut(row + rr) {
                    *v = 0;
                }
            }
        }
        let theta_rad = acc.thetas_rad.get(t).copied().unwrap_or(0.0);
        let peak = Peak {
            theta_rad,
            rho_px: if band == 0 {
                refine_rho(acc, t, r, wr)
            } else {
                band_centroid(acc, t, r, band)
            },
            votes,
            x_origin_px: acc.x_origin_px,
            window_theta_rad: params.window_theta_deg.to_radians(),
            window_rho_px: params.window_rho_px,
        };
        // Distinct stripes never cross: a maximum whose line crosses, or comes within a window
        // half-width of, a chosen line inside the frame is another part of that stripe (a curved
        // stripe votes for several tangents), not a new one.
        if peaks.iter().any(|p| same_stripe(p, &peak)) {
            continue 'next_peak;
        }
        peaks.push(peak);
    }
    let x0 = acc.x_origin_px;
    peaks.sort_by(|a, b| a.row_at_px(x0).total_cmp(&b.row_at_px(x0)));
    peaks
}

/// True when the lines of `a` and `b` cross inside the frame (columns 0..=2·x₀) or come closer
/// than `a`'s window half-width in ρ there.
fn same_stripe(a: &Peak, b: &Peak) -> bool {
    let right = 2.0 * a.x_origin_px;
    let d0 = a.row_at_px(0.0) - b.row_at_px(0.0);
    let d1 = a.row_at_px(right) - b.row_at_px(right);
    !(d0.is_finite() && d1.is_finite())
        || d0.signum() != d1.signum()
        || d0.abs().min(d1.abs()) < a.window_rho_px
}

/// Each θ row's votes summed over ±`band` ρ bins (clipped at the ends).
fn band_sums(acc: &Accumulator, band: usize) -> Vec<u32> {
    let nr = acc.rho_bins;
    let mut out = vec![0u32; acc.votes.len()];
    out.par_chunks_mut(nr)
        .zip(acc.votes.par_chunks(nr))
        .for_each(|(o, row)| {
            let mut prefix = Vec::with_capacity(nr + 1);
            prefix.push(0u64);
            let mut total = 0u64;
            for &v in row {
                total += u64::from(v);
                prefix.push(total);
            }
            for (r, slot) in o.iter_mut().enumerate() {
                let lo = r.saturating_sub(band);
                let hi = (r + band + 1).min(nr);
                let sum =
                    prefix.get(hi).copied().unwrap_or(0) - prefix.get(lo).copied().unwrap_or(0);
                *slot = u32::try_from(sum).unwrap_or(u32::MAX);
            }
        });
    out
}

/// Vote-weighted mean ρ of the bins within ±`band` of bin `r` at θ bin `t` (the centre of a
/// wiggling stripe's votes).
fn band_centroid(acc: &Accumulator, t: usize, r: usize, band: usize) -> f32 {
    let mut sum = 0.0_f64;
    let mut weight = 0.0_f64;
    for rr in r.saturating_sub(band)..=(r + band).min(acc.rho_bins.saturating_sub(1)) {
        let v = f64::from(acc.get(t, rr));
        sum += v * rr as f64;
        weight += v;
    }
    let bin = if weight > 0.0 { sum / weight } else { r as f64 };
    acc.rho_min_px + bin as f32 * acc.rho_step_px
}

/// Vote-weighted centroid of the contiguous ρ bins (within ±`wr`) around peak bin `r` at θ bin `t`
/// that hold at least [`RHO_REFINE_FRACTION`] of its votes: the centre of a thick stripe.
fn refine_rho(acc: &Accumulator, t: usize, r: usize, wr: usize) -> f32 {
    let peak = acc.get(t, r) as f32;
    let floor = peak * RHO_REFINE_FRACTION;
    let mut sum = 0.0_f64;
    let mut weight = 0.0_f64;
    let mut add = |rr: usize| {
        let v = acc.get(t, rr) as f32;
        if v >= floor && v > 0.0 {
            sum += f64::from(v) * rr as f64;
            weight += f64::from(v);
            true
        } else {
            false
        }
    };
    add(r);
    for rr in (r + 1)..=(r + wr).min(acc.rho_bins.saturating_sub(1)) {
        if !add(rr) {
            break;
        }
    }
    for rr in (r.saturating_sub(wr)..r).rev() {
        if !add(rr) {
            break;
        }
    }
    let bin = if weight > 0.0 {
        (sum / weight) as f32
    } else {
        r as f32
    };
    acc.rho_min_px + bin * acc.rho_step_px
}

/// Labels every point: the index of the single window its curve passes through, else
/// [`label::DISCARDED`] (two or more) or [`label::UNASSIGNED`] (none).
fn label_points(points: &[FocusPoint], peaks: &[Peak]) -> Vec<i8> {
    let windows: Vec<WindowTest> = peaks.iter().map(WindowTest::new).collect();
    points
        .par_iter()
        .map(|pt| {
            let (xc, y) = (f64::from(pt.xc), f64::from(pt.y));
            let mut found = label::UNASSIGNED;
            for (k, window) in windows.iter().enumerate() {
                if window.contains(xc, y) {
                    if found != label::UNASSIGNED {
                        return label::DISCARDED;
                    }
                    found = i8::try_from(k).unwrap_or(label::DISCARDED);
                }
            }
            found
        })
        .collect()
}

/// The centroid line of region `k`.
///
/// Per column, the region's rows are gathered (sorted, as the points are row-major). Pass 1 takes
/// the mean of the span of 2·gate rows holding the most of them ([`densest_run`]), with
/// gate = ½·T + [`CENTROID_GATE_MARGIN_PX`] and T the median pixel count per measured column (the
/// stripe thickness); a running median of these along x (±max(`line_smoothing_px`,
/// [`MIN_MEDIAN_HALF_PX`])) gives a reference row per column. The centroid is the mean of the
/// column's rows within ±gate of that reference (none: a void). On a clean stripe this is the plain
/// mean; stray in-focus pixels that fall in the window (which, in image space, widens toward the
/// image sides) no longer pull it. The
/// centroids are smoothed over the measured columns within ±`line_smoothing_px`; voids are taken
/// from the peak line and marked. The half-width is half the gated pixel count per column (smoothed
/// alike; voids get the mean). Depths are left unset.
fn centroid_line(
    points: &[FocusPoint],
    labels: &[i8],
    k: usize,
    width: usize,
    peak: &Peak,
    params: &HoughParams,
) -> WallLine {
    let want = i8::try_from(k).unwrap_or(label::NONE);
    let x0 = peak.x_origin_px;
    let column_of = |pt: &FocusPoint| {
        let x = (pt.xc + x0).round();
        (x >= 0.0 && (x as usize) < width).then_some(x as usize)
    };
    // Bucket the region's rows by column (CSR layout: offsets, then rows).
    let mut offsets = vec![0usize; width + 1];
    for (pt, &l) in points.iter().zip(labels) {
        if l == want
            && let Some(x) = column_of(pt)
        {
            offsets[x + 1] += 1;
        }
    }
    for x in 0..width {
        offsets[x + 1] += offsets[x];
    }
    let mut fill = offsets.clone();
    let mut col_rows = vec![0.0_f32; offsets[width]];
    for (pt, &l) in points.iter().zip(labels) {
        if l == want
            && let Some(x) = column_of(pt)
            && let Some(slot) = col_rows.get_mut(fill[x])
        {
            *slot = pt.y;
            fill[x] += 1;
        }
    }
    let column = |x: usize| col_rows.get(offsets[x]..offsets[x + 1]).unwrap_or(&[]);

    let mut counts: Vec<usize> = (0..width)
        .map(|x| column(x).len())
        .filter(|&c| c > 0)
        .collect();
    let thickness = if counts.is_empty() {
        0.0
    } else {
        let mid = counts.len() / 2;
        *counts.select_nth_unstable(mid).1 as f32
    };
    let gate = 0.5 * thickness + CENTROID_GATE_MARGIN_PX;

    // Pass 1: the densest span per column; a running median along x then removes columns where a
    // chance cluster of stray pixels outnumbered a thin stripe.
    let first: Vec<f64> = (0..width)
        .map(|x| {
            densest_run(column(x), 2.0 * gate, peak.row_at_px(x as f32)).map_or(f64::NAN, |r| r.0)
        })
        .collect();
    let reference = running_median(&first, params.line_smoothing_px.max(MIN_MEDIAN_HALF_PX));
    // Pass 2: the mean of the rows within ±gate of the reference.
    let mut raw_rows = vec![f64::NAN; width];
    let mut raw_half = vec![f64::NAN; width];
    for x in 0..width {
        let Some(&r) = reference.get(x) else {
            continue;
        };
        if !r.is_finite() {
            continue;
        }
        let (mut sum, mut n) = (0.0_f64, 0usize);
        for &y in column(x) {
            if (f64::from(y) - r).abs() <= f64::from(gate) {
                sum += f64::from(y);
                n += 1;
            }
        }
        if n > 0 {
            raw_rows[x] = sum / n as f64;
            raw_half[x] = 0.5 * n as f64;
        }
    }
    let rows_s = smooth_measured(&raw_rows, params.line_smoothing_px);
    let half_s = smooth_measured(&raw_half, params.line_smoothing_px);
    let measured: Vec<f64> = raw_half.iter().copied().filter(|v| v.is_finite()).collect();
    let mean_half = if measured.is_empty() {
        0.0
    } else {
        measured.iter().sum::<f64>() / measured.len() as f64
    };

    let mut rows = Vec::with_capacity(width);
    let mut half_width_px = Vec::with_capacity(width);
    let mut filled = Vec::with_capacity(width);
    for x in 0..width {
        let r = rows_s.get(x).copied().unwrap_or(f64::NAN);
        if r.is_finite() {
            rows.push(r as f32);
            half_width_px.push(half_s.get(x).copied().unwrap_or(mean_half) as f32);
            filled.push(false);
        } else {
            rows.push(peak.row_at_px(x as f32));
            half_width_px.push(mean_half as f32);
            filled.push(true);
        }
    }
    WallLine {
        side: WallSide::Right,
        rows,
        half_width_px,
        depth_um: None,
        projection_depth_um: None,
        filled,
    }
}

/// The span of at most `span` rows holding the most of the sorted `rows` (ties: the one whose
/// mean is closest to `prior`): returns its mean row and its pixel count; `None` when empty.
fn densest_run(rows: &[f32], span: f32, prior: f32) -> Option<(f64, usize)> {
    let mut best: Option<(usize, f64, f64)> = None; // (count, mean, distance to prior)
    let mut j = 0;
    let mut sum = 0.0_f64;
    for (i, &start) in rows.iter().enumerate() {
        if j < i {
            j = i;
            sum = 0.0;
        }
        while let Some(&y) = rows.get(j) {
            if y - start > span {
                break;
            }
            sum += f64::from(y);
            j += 1;
        }
        let n = j - i;
        let mean = sum / n as f64;
        let dist = (mean - f64::from(prior)).abs();
        let better = match best {
            None => true,
            Some((bn, _, bd)) => n > bn || (n == bn && dist < bd),
        };
        if better {
            best = Some((n, mean, dist));
        }
        sum -= f64::from(start);
    }
    best.map(|(n, mean, _)| (mean, n))
}

/// Running median over ±`half` of the finite entries (NaN where none).
fn running_median(values: &[f64], half: usize) -> Vec<f64> {
    let n = values.len();
    let mut window = Vec::with_capacity(2 * half + 1);
    (0..n)
        .map(|i| {
            window.clear();
            let lo = i.saturating_sub(half);
            let hi = (i + half + 1).min(n);
            window.extend(values[lo..hi].iter().copied().filter(|v| v.is_finite()));
            if window.is_empty() {
                return f64::NAN;
            }
            let mid = window.len() / 2;
            *window.select_nth_unstable_by(mid, f64::total_cmp).1
        })
        .collect()
}

/// Moving average over ±`half` of the finite entries; NaN stays NaN.
fn smooth_measured(values: &[f64], half: usize) -> Vec<f64> {
    let n = values.len();
    let mut sum = vec![0.0_f64; n + 1];
    let mut cnt = vec![0u32; n + 1];
    for (i, &v) in values.iter().enumerate() {
        let ok = v.is_finite();
        sum[i + 1] = sum[i] + if ok { v } else { 0.0 };
        cnt[i + 1] = cnt[i] + u32::from(ok);
    }
    values
        .iter()
        .enumerate()
        .map(|(i, &v)| {
            if !v.is_finite() {
                return f64::NAN;
            }
            let lo = i.saturating_sub(half);
            let hi = (i + half + 1).min(n);
            let c = cnt[hi] - cnt[lo];
            (sum[hi] - sum[lo]) / f64::from(c.max(1))
        })
        .collect()
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // Tests may panic on a broken expectation.
mod tests {
    use super::*;

    /// A tiny deterministic generator (tests only).
    struct Lcg(u64);
    impl Lcg {
        fn next_f32(&mut self) -> f32 {
            self.0 = self
                .0
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            ((self.0 >> 40) as f32) / (1u64 << 24) as f32
        }
    }

    /// One stripe: rows centred on `row_at(x)` ± `half` px.
    struct Line {
        theta_deg: f32,
        rho_px: f32,
    }

    impl Line {
        fn row_at(&self, x: usize, width: usize) -> f32 {
            let x0 = (width as f32 - 1.0) * 0.5;
            let (s, c) = self.theta_deg.to_radians().sin_cos();
            (self.rho_px + (x as f32 - x0) * s) / c
        }
    }

    /// Derivatives whose gradient is 1 on the stripes (and at noise pixels), 0 elsewhere;
    /// flow confidence 1 everywhere. `void` columns are left out of every stripe except the first.
    fn scene(
        width: usize,
        height: usize,
        lines: &[Line],
        half: f32,
        noise: f32,
        void: std::ops::Range<usize>,
    ) -> (Derivatives, FlowField) {
        let mut rng = Lcg(7);
        let iy = Image::from_fn(width, height, |x, y| {
            let on_line = lines.iter().enumerate().any(|(i, l)| {
                (i == 0 || !void.contains(&x)) && (y as f32 - l.row_at(x, width)).abs() <= half
            });
            if on_line || rng.next_f32() < noise {
                1.0
            } else {
                0.0
            }
        });
        let zeros = Image::zeros(width, height);
        let d = Derivatives {
            ix: zeros.clone(),
            iy,
            it: zeros.clone(),
            image: zeros.clone(),
            frame_index: 3,
            base_flow_px: -2.0,
        };
        let f = FlowField {
            u: zeros.clone(),
            v: zeros,
            confidence: Image::filled(width, height, 1.0),
            iterations: 1,
            converged: true,
            frame_index: 3,
        };
        (d, f)
    }

    fn dual(side: GlassSide) -> DualFocusMeta {
        DualFocusMeta {
            focus_distance_mm: 4.05,
            glass_thickness_mm: 0.11,
            glass_index: 1.515,
            glass_side: side,
            glass_edge_row: 100.0,
        }
    }

    fn three_lines() -> Vec<Line> {
        vec![
            Line {
                theta_deg: 2.0,
                rho_px: 40.0,
            },
            Line {
                theta_deg: -3.0,
                rho_px: 95.0,
            },
            Line {
                theta_deg: 1.0,
                rho_px: 150.0,
            },
        ]
    }

    #[test]
    fn focus_shift_of_the_paper_glass() {
        let d = dual(GlassSide::Top);
        assert!(
            (d.focus_shift_mm() - 0.0374).abs() < 5e-5,
            "{}",
            d.focus_shift_mm()
        );
        let (plain, glass) = d.focal_distances_mm();
        assert_eq!(plain, 4.05);
        assert!((glass - plain - 0.0374).abs() < 5e-5);
    }

    #[test]
    fn hough_finds_three_known_lines_in_noise() {
        let lines = three_lines();
        let (d, f) = scene(400, 200, &lines, 1.0, 0.03, 0..0);
        let params = HoughParams::default();
        let s = segment_stripes(&d, &f, &dual(GlassSide::Top), &params).unwrap();
        assert_eq!(s.peaks.len(), 3);
        for (p, l) in s.peaks.iter().zip(&lines) {
            let dt = (p.theta_rad.to_degrees() - l.theta_deg).abs();
            assert!(dt <= params.theta_step_deg, "θ {p:?} vs {}", l.theta_deg);
            assert!(
                (p.rho_px - l.rho_px).abs() <= params.rho_step_px,
                "ρ {p:?} vs {}",
                l.rho_px
            );
        }
        // The lines follow the stripes: the gated centroid ignores the noise in the windows.
        for (line, &k) in s.lines.iter().zip(&s.line_peaks) {
            let truth = &lines[k];
            let mut worst = 0.0_f32;
            let mut total = 0.0_f32;
            for x in 0..400 {
                let e = (line.rows[x] - truth.row_at(x, 400)).abs();
                worst = worst.max(e);
                total += e;
                assert!(!line.filled[x]);
            }
            // Pixel quantisation of a 3-px stripe alone gives up to ±0.5 px.
            assert!(worst < 1.0, "line {k} off by {worst} px");
            assert!(
                total / 400.0 < 0.3,
                "line {k} mean error {} px",
                total / 400.0
            );
        }
        // Sub-bin: the stripe rows on a pure θ bin give ρ within a fraction of a bin.
        assert!((s.peaks[2].rho_px - 150.0).abs() < 0.5);
    }

    #[test]
    fn a_bent_stripe_gives_one_peak_not_two() {
        // A stripe bent at the centre column (±8°, as a strongly modulated groove curves within
        // a frame) votes for two tangents, both stronger than the short straight stripes below
        // it; the tangents cross inside the frame, so only one may become a
        // peak.
        let (w, h) = (400, 200);
        let x0 = (w as f32 - 1.0) * 0.5;
        let bent = |x: usize| 40.0 + (x as f32 - x0).abs() * 8f32.to_radians().tan();
        let (mut d, f) = scene(w, h, &[], 1.0, 0.0, 0..0);
        d.iy = Image::from_fn(w, h, |x, y| {
            let y = y as f32;
            let short = (150..250).contains(&x);
            let on = (y - bent(x)).abs() <= 1.0 || (short && (y == 110.0 || y == 160.0));
            if on { 1.0 } else { 0.0 }
        });
        let s = segment_stripes(&d, &f, &dual(GlassSide::Top), &HoughParams::default()).unwrap();
        let rows: Vec<f32> = s.peaks.iter().map(|p| p.row_at_px(x0)).collect();
        assert_eq!(rows.len(), 3, "{rows:?}");
        assert!((rows[0] - 40.0).abs() < 3.0, "{rows:?}");
        assert!((rows[1] - 110.0).abs() < 1.0, "{rows:?}");
        assert!((rows[2] - 160.0).abs() < 1.0, "{rows:?}");
    }

    #[test]
    fn pure_hough_votes_land_in_the_right_bin() {
        let params = HoughParams::default();
        let width = 101;
        let pts: Vec<FocusPoint> = (0..width)
            .map(|x| FocusPoint {
                xc: x as f32 - 50.0,
                y: 30.0 + (x as f32 - 50.0) * 10f32.to_radians().tan(),
                index: 0,
            })
            .collect();
        let acc = vote(&pts, 1, width, 80, &params);
        assert_eq!(acc.theta_bins(), 91);
        assert_eq!(acc.rho_bins, 80);
        // θ = 10° is bin 55; ρ = 30·cos10° = 29.54 -> bin 30.
        assert_eq!(acc.get(55, 30), width as u32);
        // Away from the true line its butterfly gives other local maxima of about 101·step/sin Δθ.
        let peaks = find_peaks(&acc, &params, 60);
        assert_eq!(peaks.len(), 1);
        assert!((peaks[0].theta_rad.to_degrees() - 10.0).abs() < 1e-4);
        assert!((peaks[0].row_at_px(50.0) - 30.0).abs() < 0.6);
    }

    #[test]
    fn points_in_overlapping_windows_are_discarded() {
        // Two stripes 20 px apart with ±15 px windows: their windows overlap between them.
        let lines = vec![
            Line {
                theta_deg: 0.0,
                rho_px: 30.0,
            },
            Line {
                theta_deg: 0.0,
                rho_px: 90.0,
            },
            Line {
                theta_deg: 0.0,
                rho_px: 110.0,
            },
        ];
        let (mut d, f) = scene(120, 160, &lines, 1.0, 0.0, 0..0);
        // A lone in-focus pixel halfway between the two close stripes, and one far away.
        d.iy.data[100 * 120 + 60] = 1.0;
        d.iy.data[60 * 120 + 60] = 1.0;
        let s = segment_stripes(&d, &f, &dual(GlassSide::Top), &HoughParams::default()).unwrap();
        assert_eq!(s.labels[100 * 120 + 60], label::DISCARDED);
        assert_eq!(s.labels[60 * 120 + 60], label::UNASSIGNED);
        assert_eq!(s.labels[30 * 120 + 5], 0);
        assert_eq!(s.labels[90 * 120 + 60], 1);
        assert_eq!(s.labels[110 * 120 + 60], 2);
        assert_eq!(s.labels[5 * 120 + 5], label::NONE);
        // At the far columns a stripe pixel's curve sweeps ±59·sin 4° ≈ ±4 px: still only its window.
        assert_eq!(s.labels[110 * 120 + 119], 2);
        // A pixel 6 px below the middle stripe lies 14 px from the bottom one: in both windows.
        d.iy.data[96 * 120 + 60] = 1.0;
        let s = segment_stripes(&d, &f, &dual(GlassSide::Top), &HoughParams::default()).unwrap();
        assert_eq!(s.labels[96 * 120 + 60], label::DISCARDED);
        assert_eq!(s.in_focus.data[96 * 120 + 60], 1.0);
    }

    #[test]
    fn curve_range_matches_brute_force() {
        for &(xc, y, a, b) in &[
            (100.0, 50.0, -0.2, 0.1),
            (-300.0, 10.0, -0.5, 0.5),
            (0.0, 80.0, -0.1, 0.1),
            (500.0, 1.0, -1.5, -1.4),
            (500.0, 1.0, -1.5, 1.4),
            (-20.0, -600.0, -1.0, 1.0),
            (3.0, 0.0, 1.0, 2.0),
        ] {
            let half = (b - a) / 2.0;
            let peak = Peak {
                theta_rad: (a + half) as f32,
                rho_px: 0.0,
                votes: 1,
                x_origin_px: 0.0,
                window_theta_rad: half as f32,
                window_rho_px: 1.0,
            };
            let (lo, hi) = WindowTest::new(&peak).rho_range(xc, y);
            let mut blo = f64::MAX;
            let mut bhi = f64::MIN;
            for i in 0..=10_000 {
                let t = a + (b - a) * f64::from(i) / 10_000.0;
                let r = -xc * t.sin() + y * t.cos();
                blo = blo.min(r);
                bhi = bhi.max(r);
            }
            assert!(
                (lo - blo).abs() < 1e-3 && (hi - bhi).abs() < 1e-3,
                "{xc} {y}"
            );
        }
    }

    #[test]
    fn a_rho_band_finds_the_mean_line_of_wiggling_stripes() {
        // Three 3-px stripes that wiggle ±6 px (two periods across 1280 px), in 4% noise.
        let (w, h) = (1280, 800);
        let rows = [200.0_f32, 420.0, 540.0];
        let mut rng = Lcg(11);
        let iy = Image::from_fn(w, h, |x, y| {
            let wave = 6.0 * (x as f32 * 0.01).sin();
            let on = rows.iter().any(|&r| (y as f32 - r - wave).abs() <= 1.0);
            if on || rng.next_f32() < 0.04 {
                1.0
            } else {
                0.0
            }
        });
        let (mut d, f) = scene(w, h, &[], 1.0, 0.0, 0..0);
        d.iy = iy;
        let params = HoughParams {
            peak_rho_band_px: 8.0,
            min_votes_per_column: 1.0,
            ..HoughParams::default()
        };
        let s = segment_stripes(&d, &f, &dual(GlassSide::Top), &params).unwrap();
        // The mean of 6·sin(0.01·x) over the frame is about 0.3 px.
        for (p, &r) in s.peaks.iter().zip(&rows) {
            assert!(p.theta_rad.abs() <= 1f32.to_radians() + 1e-6, "{p:?}");
            assert!((p.row_at_px(639.5) - r).abs() < 2.0, "{p:?} vs {r}");
        }
        // The centroid lines follow the wiggle itself.
        for (line, &k) in s.lines.iter().zip(&s.line_peaks) {
            for x in (0..w).step_by(50) {
                let truth = rows[k] + 6.0 * (x as f32 * 0.01).sin();
                assert!(
                    (line.rows[x] - truth).abs() < 1.0,
                    "x {x}: {} vs {truth}",
                    line.rows[x]
                );
            }
        }
    }

    #[test]
    fn densest_run_skips_stray_rows() {
        let rows = [3.0, 40.0, 41.0, 42.0, 50.0, 51.0, 58.0, 59.0];
        assert_eq!(densest_run(&rows, 3.0, 0.0), Some((41.0, 3)));
        // A tie goes to the run nearer the prior.
        assert_eq!(
            densest_run(&[10.0, 11.0, 30.0, 31.0], 2.0, 29.0),
            Some((30.5, 2))
        );
        assert_eq!(densest_run(&[], 2.0, 0.0), None);
    }

    #[test]
    fn void_is_filled_on_the_peak_line() {
        let lines = three_lines();
        let (d, f) = scene(400, 200, &lines, 1.0, 0.0, 150..190);
        let s = segment_stripes(&d, &f, &dual(GlassSide::Top), &HoughParams::default()).unwrap();
        assert_eq!(s.line_peaks, vec![1, 2]);
        for (line, &k) in s.lines.iter().zip(&s.line_peaks) {
            let peak = &s.peaks[k];
            for x in 0..400 {
                assert_eq!(line.filled[x], (150..190).contains(&x), "x {x}");
                let truth = lines[k].row_at(x, 400);
                if line.filled[x] {
                    assert_eq!(line.rows[x], peak.row_at_px(x as f32));
                    assert!((line.rows[x] - truth).abs() < 1.0);
                } else {
                    // Without noise the centroid sits on the stripe (pixel rounding only).
                    assert!((line.rows[x] - truth).abs() < 0.6, "x {x}");
                    assert!((line.half_width_px[x] - 1.5).abs() < 0.6);
                }
                assert!(line.rows[x].is_finite());
            }
        }
    }

    #[test]
    fn kept_lines_get_the_right_depths_for_glass_on_top() {
        let (d, f) = scene(400, 200, &three_lines(), 1.0, 0.01, 0..0);
        let meta = dual(GlassSide::Top);
        let s = segment_stripes(&d, &f, &meta, &HoughParams::default()).unwrap();
        assert_eq!(s.dropped, 0);
        assert_eq!(s.line_peaks, vec![1, 2]);
        let shift_um = meta.focus_shift_mm() * 1000.0;
        let (a, b) = (&s.lines[0], &s.lines[1]);
        assert!((a.depth_um.unwrap() - (4050.0 + shift_um)).abs() < 1e-6);
        assert!((b.depth_um.unwrap() - 4050.0).abs() < 1e-6);
        assert_eq!(a.projection_depth_um, Some(4050.0));
        assert_eq!(b.projection_depth_um, Some(4050.0));
        assert_eq!(a.side, WallSide::Right);
        assert_eq!(b.side, WallSide::Right);
        // The upper kept line is the one under the glass.
        assert!(a.rows[200] < b.rows[200]);
    }

    #[test]
    fn glass_at_the_bottom_mirrors_the_choice() {
        let (d, f) = scene(400, 200, &three_lines(), 1.0, 0.01, 0..0);
        let meta = dual(GlassSide::Bottom);
        let s = segment_stripes(&d, &f, &meta, &HoughParams::default()).unwrap();
        assert_eq!(s.dropped, 2);
        assert_eq!(s.line_peaks, vec![0, 1]);
        assert!((s.lines[0].depth_um.unwrap() - 4050.0).abs() < 1e-6);
        assert!(s.lines[1].depth_um.unwrap() > 4087.0);
        assert!(s.lines.iter().all(|l| l.side == WallSide::Left));
    }

    #[test]
    fn two_stripes_are_not_enough() {
        let lines = three_lines();
        let (d, f) = scene(400, 200, &lines[..2], 1.0, 0.03, 0..0);
        let err =
            segment_stripes(&d, &f, &dual(GlassSide::Top), &HoughParams::default()).unwrap_err();
        match err {
            StageError::NotFound { problem, .. } => {
                assert!(problem.starts_with("found 2 stripes, need 3"), "{problem}");
            }
            other => panic!("{other:?}"),
        }
        // Blurred everywhere (no gradient): nothing found.
        let (mut d, f) = scene(64, 64, &lines[..1], 1.0, 0.0, 0..0);
        d.iy = Image::zeros(64, 64);
        let err =
            segment_stripes(&d, &f, &dual(GlassSide::Top), &HoughParams::default()).unwrap_err();
        assert!(err.to_string().contains("found 0 stripes"), "{err}");
    }

    #[test]
    fn pixels_without_flow_are_not_in_focus() {
        let (d, mut f) = scene(400, 200, &three_lines(), 1.0, 0.0, 0..0);
        f.confidence = Image::zeros(400, 200);
        assert!(matches!(
            segment_stripes(&d, &f, &dual(GlassSide::Top), &HoughParams::default()),
            Err(StageError::NotFound { .. })
        ));
    }

    #[test]
    fn subsampled_votes_find_the_same_peaks() {
        let lines = three_lines();
        let (d, f) = scene(400, 200, &lines, 1.0, 0.03, 0..0);
        let full = segment_stripes(&d, &f, &dual(GlassSide::Top), &HoughParams::default()).unwrap();
        let params = HoughParams {
            max_vote_points: 1000,
            ..HoughParams::default()
        };
        let sub = segment_stripes(&d, &f, &dual(GlassSide::Top), &params).unwrap();
        assert!(sub.accumulator.vote_stride > 1);
        for (a, b) in full.peaks.iter().zip(&sub.peaks) {
            assert_eq!(a.theta_rad, b.theta_rad);
            assert!((a.rho_px - b.rho_px).abs() <= 1.0);
        }
    }

    #[test]
    fn invalid_params_and_inputs_are_rejected() {
        let (d, f) = scene(40, 30, &three_lines(), 1.0, 0.0, 0..0);
        let meta = dual(GlassSide::Top);
        let bad = [
            HoughParams {
                gradient_threshold: f32::NAN,
                ..HoughParams::default()
            },
            HoughParams {
                theta_min_deg: 10.0,
                theta_max_deg: -10.0,
                ..HoughParams::default()
            },
            HoughParams {
                theta_step_deg: 0.0,
                ..HoughParams::default()
            },
            HoughParams {
                rho_step_px: 0.0,
                ..HoughParams::default()
            },
            HoughParams {
                window_rho_px: -1.0,
                ..HoughParams::default()
            },
            HoughParams {
                peak_count: 2,
                ..HoughParams::default()
            },
        ];
        for p in &bad {
            assert!(
                matches!(
                    segment_stripes(&d, &f, &meta, p),
                    Err(StageError::InvalidParam { .. })
                ),
                "{p:?}"
            );
        }
        let mut bad_meta = meta.clone();
        bad_meta.glass_index = 0.5;
        assert!(matches!(
            segment_stripes(&d, &f, &bad_meta, &HoughParams::default()),
            Err(StageError::InvalidParam { .. })
        ));
        let mut f2 = f.clone();
        f2.confidence = Image::zeros(10, 10);
        assert!(matches!(
            segment_stripes(&d, &f2, &meta, &HoughParams::default()),
            Err(StageError::BadInput { .. })
        ));
    }
}
