//! The fine fit of one border of one output sample over all frames of a group: straightened,
//! sub-pixel binned profiles, the border model on their sum, dust columns rejected, and each
//! frame's own position.
//!
//! Every frame sees the sample's stretch of groove `[s − Δ/2, s + Δ/2)` at its own columns
//! (the frame step and the border's distance place them). In each column the rows within
//! `band_half_height_px` of the predicted border row `b̂(x)` are read, and each pixel goes to the
//! bin of its offset `u = r − b̂(x)` (`bin_px` wide): a border that moves across the columns
//! then samples the edge at many sub-pixel offsets (the slanted-edge method), and the end
//! columns count by the share of them inside the stretch, so consecutive samples tile the
//! groove exactly. The border model fitted to the sum of all frames' bins gives the offset μ;
//! the border row of the sample is the mean `b̂` over its columns plus μ (the border averaged
//! over the stretch).
//!
//! Dust and scratches are fixed to the record, so they are the same in every frame and only
//! the columns they cover can be told apart: on the reference frame each column's own offset is
//! one Gauss–Newton step on the fitted model, Lorentzian weights `1/(1 + δ²/(2σ²))` down-weight
//! columns that stray (`column_sigma_px`), and while a column not yet left out weighs less
//! than [`OUTLIER_WEIGHT`] the bins are summed again with those weights (outliers left out;
//! applied in every frame to the columns that see the same groove position) and refitted, up
//! to `column_rounds` times. Columns already left out stray from the refit too, by design, so
//! they do not ask for another round: once no new column strays the fit has settled.
//! Each frame's own position is then one linear least-squares step (levels and position) from
//! the joint fit on that frame's bins.
//!
//! Each frame's band is read from the frame once (a `BandView`: every column's pixels with
//! their bins and offsets) and every robust round re-weights those; `reference.rs` holds the
//! plain version that reads the frame pixel by pixel in every round, and the two give the same
//! bits (the same sums in the same order).

use super::EdgeParams;
use super::border::{Border, BorderSeed, ProfilePoint, fit_border, normal_cdf, normal_pdf};
use super::geometry::FrameGeometry;
use crate::image::Image;

/// A column weighing less than this after the robust check counts as an outlier (its weight
/// is then applied and the profile refitted).
pub const OUTLIER_WEIGHT: f64 = 0.5;

/// What the fine fit needs to know about one border of one sample.
pub struct SampleTask<'a> {
    /// Groove positions of the stretch, `[s_lo, s_hi)` (µm).
    pub s_lo_um: f64,
    /// End of the stretch (µm).
    pub s_hi_um: f64,
    /// Apparent distance of the border's surface (µm; the glass already applied).
    pub z_um: f64,
    /// Predicted record `y` of the border at groove position `s` (µm).
    pub predict_y: &'a dyn Fn(f64) -> f64,
}

/// One frame's view of one border of one sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameBorder {
    /// Index of the frame in the group.
    pub frame_index: usize,
    /// Column at the middle of the sample's stretch in this frame.
    pub column_px: f64,
    /// Border row averaged over the stretch.
    pub row_px: f64,
    /// Standard error of the row (px).
    pub std_error_px: f64,
}

/// The fine fit of one border of one sample.
#[derive(Clone, Debug, PartialEq)]
pub struct SampleBorder {
    /// Border row averaged over the stretch and over the frames that see it (px).
    pub row_px: f64,
    /// Standard error of that row (px), from the joint fit.
    pub std_error_px: f64,
    /// The joint fit (positions relative to the predicted row).
    pub fit: Border,
    /// Each frame's own row.
    pub frames: Vec<FrameBorder>,
    /// Columns of the reference frame read, with their robust weights (1 = kept).
    pub column_weights: Vec<(usize, f32)>,
    /// Robust rounds run.
    pub rounds: u32,
}

/// One column of one frame inside the stretch.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Column {
    /// Column index.
    pub x: usize,
    /// Share of the column inside the stretch (0, 1].
    pub share: f64,
    /// Predicted border row.
    pub row: f64,
    /// Groove position of the column centre (µm).
    pub s_um: f64,
}

/// The columns of frame `cam_s_um` covering the task's stretch; None when it leaves the frame.
#[cfg(test)]
pub(crate) fn columns(
    geo: &FrameGeometry,
    cam_s_um: f64,
    task: &SampleTask,
) -> Option<Vec<Column>> {
    let mut cols = Vec::new();
    columns_into(geo, cam_s_um, task, &mut cols).then_some(cols)
}

/// [`columns`] into `cols` (emptied first, its buffer kept); false when the stretch leaves the
/// frame.
fn columns_into(
    geo: &FrameGeometry,
    cam_s_um: f64,
    task: &SampleTask,
    cols: &mut Vec<Column>,
) -> bool {
    cols.clear();
    let x_lo = geo.x_at(cam_s_um, task.s_lo_um, task.z_um);
    let x_hi = geo.x_at(cam_s_um, task.s_hi_um, task.z_um);
    if !(x_lo >= -0.5 && x_hi <= geo.width as f64 - 0.5 && x_hi > x_lo) {
        return false;
    }
    let first = (x_lo + 0.5).floor().max(0.0) as usize;
    let last = ((x_hi + 0.5).ceil() as usize).min(geo.width);
    cols.extend((first..last).filter_map(|x| {
        let xf = x as f64;
        let share = (xf + 0.5).min(x_hi) - (xf - 0.5).max(x_lo);
        (share > 0.0).then(|| {
            let s_um = geo.s_at(cam_s_um, xf, task.z_um);
            Column {
                x,
                share,
                row: geo.row_at((task.predict_y)(s_um), task.z_um),
                s_um,
            }
        })
    }));
    true
}

/// Sub-pixel bins of one frame's straightened profile: Σw, Σw·u, Σw·v per bin.
#[derive(Clone, Debug)]
pub(super) struct Bins {
    pub(super) sums: Vec<[f64; 3]>,
    /// Σ share·weight·row over the columns, and Σ share·weight.
    pub(super) row_sum: f64,
    pub(super) weight_sum: f64,
}

impl Bins {
    pub(super) fn new(n: usize) -> Self {
        Self {
            sums: vec![[0.0; 3]; n],
            row_sum: 0.0,
            weight_sum: 0.0,
        }
    }

    fn add(&mut self, other: &Bins) {
        for (a, b) in self.sums.iter_mut().zip(&other.sums) {
            for (x, y) in a.iter_mut().zip(b) {
                *x += y;
            }
        }
        self.row_sum += other.row_sum;
        self.weight_sum += other.weight_sum;
    }

    fn points(&self) -> Vec<ProfilePoint> {
        self.sums
            .iter()
            .filter(|s| s[0] > 0.0)
            .map(|s| ProfilePoint {
                x_px: s[1] / s[0],
                value: s[2] / s[0],
                weight: s[0],
            })
            .collect()
    }

    /// Back to empty, keeping its buffer.
    fn clear(&mut self) {
        self.sums.fill([0.0; 3]);
        self.row_sum = 0.0;
        self.weight_sum = 0.0;
    }

    fn mean_row(&self) -> Option<f64> {
        (self.weight_sum > 0.0).then(|| self.row_sum / self.weight_sum)
    }
}

/// Band geometry shared by the passes.
#[derive(Clone, Copy)]
pub(super) struct Band {
    pub(super) half_px: f64,
    pub(super) bin_px: f64,
    pub(super) bins: usize,
}

impl Band {
    pub(super) fn new(params: &EdgeParams) -> Self {
        let half_px = params.band_half_height_px;
        let bin_px = params.bin_px;
        Self {
            half_px,
            bin_px,
            bins: (2.0 * half_px / bin_px).ceil() as usize,
        }
    }

    /// Rows of a column whose offset lies in the band, with their offsets.
    pub(super) fn rows(&self, predicted: f64, height: usize) -> impl Iterator<Item = (usize, f64)> {
        let lo = (predicted - self.half_px).ceil().max(0.0) as usize;
        let hi = ((predicted + self.half_px).floor().max(-1.0) + 1.0) as usize;
        (lo..hi.min(height)).map(move |r| (r, r as f64 - predicted))
    }

    /// The bin of offset `u`: `⌊(u + half)/bin⌋` when inside the band. For a non-negative
    /// quotient truncation is the floor (and saturates as the floor's cast does), and NaN or a
    /// negative quotient is outside, so no floor call is needed per pixel.
    fn bin(&self, u: f64) -> Option<usize> {
        let t = (u + self.half_px) / self.bin_px;
        if t >= 0.0 {
            let b = t as usize;
            (b < self.bins).then_some(b)
        } else {
            None
        }
    }
}

/// One pixel of a column inside the band: its row (its offset from the predicted row is
/// `row − column.row`, recomputed exactly as `Band::rows` gives it), its bin and its grey level.
/// Twelve bytes, so a fit's bands stay in the cache between its robust rounds.
#[derive(Clone, Copy, Debug)]
struct BandPixel {
    row: u32,
    bin: u32,
    v: f32,
}

/// One frame's band, read from the frame once: each column's pixels inside the band, in row
/// order (`ends[k]` closes column `k`'s run of `pixels`, `start` opens the first). The views of
/// one fit share one pixel buffer.
struct BandView<'c, 'p> {
    cols: &'c [Column],
    start: usize,
    ends: &'p [usize],
    pixels: &'p [BandPixel],
}

/// Reads the band of `cols` from `frame`, appending the pixels to `pixels` and each column's
/// end to `ends`.
fn gather(
    frame: &Image,
    cols: &[Column],
    band: Band,
    pixels: &mut Vec<BandPixel>,
    ends: &mut Vec<usize>,
) {
    for c in cols {
        for (r, u) in band.rows(c.row, frame.height) {
            if let (Some(bin), Some(v)) = (band.bin(u), frame.get(c.x, r))
                && let (Ok(row), Ok(bin)) = (u32::try_from(r), u32::try_from(bin))
            {
                pixels.push(BandPixel { row, bin, v });
            }
        }
        ends.push(pixels.len());
    }
}

impl BandView<'_, '_> {
    /// Each column with its pixels.
    fn columns(&self) -> impl Iterator<Item = (&Column, &[BandPixel])> {
        let starts = std::iter::once(self.start).chain(self.ends.iter().copied());
        self.cols
            .iter()
            .zip(starts.zip(self.ends))
            .map(|(c, (a, &b))| (c, self.pixels.get(a..b).unwrap_or(&[])))
    }

    /// The columns accumulated into the empty `bins`, each weighted by `weight(s)`.
    fn accumulate(&self, bins: &mut Bins, weight: &dyn Fn(f64) -> f64) {
        for (c, pixels) in self.columns() {
            let w = c.share * weight(c.s_um);
            if w <= 0.0 {
                continue;
            }
            for p in pixels {
                if let Some(s) = bins.sums.get_mut(p.bin as usize) {
                    s[0] += w;
                    s[1] += w * (f64::from(p.row) - c.row);
                    s[2] += w * f64::from(p.v);
                }
            }
            bins.row_sum += w * c.row;
            bins.weight_sum += w;
        }
    }

    /// Per-column offsets against the fitted model and their Lorentzian weights (see
    /// [`column_table`]).
    fn column_weights(&self, table: &[(f64, f64)], sigma_px: f64) -> ColumnWeights {
        self.columns()
            .map(|(c, pixels)| {
                let (mut num, mut den) = (0.0, 0.0);
                for p in pixels {
                    let Some(&(m, slope)) = table.get(p.bin as usize) else {
                        continue;
                    };
                    // model(u − δ) ≈ m − slope·δ  ⇒  δ = −Σ(v − m)·slope / Σ slope².
                    num -= (f64::from(p.v) - m) * slope;
                    den += slope * slope;
                }
                let delta = if den > 0.0 { num / den } else { 0.0 };
                (c.x, c.s_um, lorentzian_weight(delta, sigma_px))
            })
            .collect()
    }
}

/// Per column of a view: (column, groove position in µm, Lorentzian weight).
pub(super) type ColumnWeights = Vec<(usize, f64, f64)>;

/// How a fit reads its frames' bands: view `k` is the `k`-th frame that sees the stretch.
pub(super) trait BandReader {
    /// View `k`'s columns accumulated into bins, each weighted by `weight(s)`.
    fn bins(&self, k: usize, weight: &dyn Fn(f64) -> f64) -> Option<Bins>;
    /// [`bins`](Self::bins) into `out` (which may hold an earlier view's sums); false when
    /// there is no view `k`.
    fn bins_into(&self, k: usize, weight: &dyn Fn(f64) -> f64, out: &mut Bins) -> bool {
        match self.bins(k, weight) {
            Some(b) => {
                *out = b;
                true
            }
            None => false,
        }
    }
    /// View `k`'s per-column (column, groove position, Lorentzian weight at scale `sigma`,
    /// px) against the model `table` (see [`column_table`]).
    fn column_weights(&self, k: usize, table: &[(f64, f64)], sigma: f64) -> Option<ColumnWeights>;
}

/// Every view's band gathered once.
struct Gathered<'c, 'p> {
    band: Band,
    views: Vec<BandView<'c, 'p>>,
}

impl BandReader for Gathered<'_, '_> {
    fn bins(&self, k: usize, weight: &dyn Fn(f64) -> f64) -> Option<Bins> {
        let mut out = Bins::new(self.band.bins);
        self.bins_into(k, weight, &mut out).then_some(out)
    }

    fn bins_into(&self, k: usize, weight: &dyn Fn(f64) -> f64, out: &mut Bins) -> bool {
        let Some(view) = self.views.get(k) else {
            return false;
        };
        if out.sums.len() == self.band.bins {
            out.clear();
        } else {
            *out = Bins::new(self.band.bins);
        }
        view.accumulate(out, weight);
        true
    }

    fn column_weights(&self, k: usize, table: &[(f64, f64)], sigma: f64) -> Option<ColumnWeights> {
        let view = self.views.get(k)?;
        Some(view.column_weights(table, sigma))
    }
}

/// Lorentzian weight of a residual `r` at scale `sigma`: ψ(r)/r = 1/(1 + r²/(2σ²)).
#[must_use]
pub fn lorentzian_weight(r: f64, sigma: f64) -> f64 {
    1.0 / (1.0 + r * r / (2.0 * sigma * sigma))
}

/// The fitted model and its slope at each bin centre, looked up per pixel by the column check:
/// each column's offset is one Gauss–Newton step on the position, and its Lorentzian weight
/// follows.
pub(super) fn column_table(band: Band, fit: &Border) -> Vec<(f64, f64)> {
    (0..band.bins)
        .map(|b| {
            let u = -band.half_px + (b as f64 + 0.5) * band.bin_px;
            (fit.model_at(u), fit.slope_at(u))
        })
        .collect()
}

/// One linear least-squares step (Δlow, Δhigh, Δposition) from the joint fit on one frame's
/// bins: the frame's position and its standard error.
fn frame_step(bins: &Bins, fit: &Border) -> Option<(f64, f64)> {
    let pts = bins.points();
    if pts.len() < 4 {
        return None;
    }
    let c = fit.contrast();
    let mut a = [[0.0f64; 3]; 3];
    let mut g = [0.0f64; 3];
    let mut terms = Vec::with_capacity(pts.len());
    for p in &pts {
        let z = (p.x_px - fit.position_px) / fit.width_px;
        let cdf = normal_cdf(z);
        let j = [1.0 - cdf, cdf, -c * normal_pdf(z) / fit.width_px];
        let r = p.value - (fit.low + c * cdf);
        for i in 0..3 {
            g[i] += p.weight * j[i] * r;
            for k in 0..3 {
                a[i][k] += p.weight * j[i] * j[k];
            }
        }
        terms.push((j, r, p.weight));
    }
    let inv = invert3(&a)?;
    let step: [f64; 3] = std::array::from_fn(|i| (0..3).map(|k| inv[i][k] * g[k]).sum());
    let sse: f64 = terms
        .iter()
        .map(|(j, r, w)| {
            let e = r - (0..3).map(|i| j[i] * step[i]).sum::<f64>();
            w * e * e
        })
        .sum();
    let dof = (pts.len() - 3) as f64;
    let se = (sse / dof * inv[2][2].max(0.0)).sqrt();
    (step[2].is_finite() && se.is_finite()).then_some((fit.position_px + step[2], se))
}

/// Inverse of a 3×3 matrix (None when singular).
fn invert3(m: &[[f64; 3]; 3]) -> Option<[[f64; 3]; 3]> {
    let c = |i: usize, j: usize| {
        let (i1, i2) = ((i + 1) % 3, (i + 2) % 3);
        let (j1, j2) = ((j + 1) % 3, (j + 2) % 3);
        m[i1][j1] * m[i2][j2] - m[i1][j2] * m[i2][j1]
    };
    let det = m[0][0] * c(0, 0) + m[0][1] * c(0, 1) + m[0][2] * c(0, 2);
    if det.abs().partial_cmp(&1e-300) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    Some(std::array::from_fn(|i| {
        std::array::from_fn(|j| c(j, i) / det)
    }))
}

/// The frames that see the whole stretch (index in `frames`, their columns), as the plain
/// reference reads them.
#[cfg(test)]
pub(super) fn frame_views(
    frames: &[(&Image, f64, usize)],
    geo: &FrameGeometry,
    task: &SampleTask,
) -> Vec<(usize, Vec<Column>)> {
    frames
        .iter()
        .enumerate()
        .filter_map(|(i, (_, cam, _))| columns(geo, *cam, task).map(|c| (i, c)))
        .collect()
}

/// The buffers of one thread's fine fits, reused from fit to fit: a fit would otherwise make
/// some forty allocations of a few kB (every frame's columns and band), and with the
/// allocator's single arena (`crate::alloc`) the fits running on every core queued on its lock
/// (a dual-focus group's edge stage took as long on two cores as on one).
#[derive(Default)]
struct FitBuffers {
    /// Frame views: `views[..used]` are this fit's, the rest keep their buffers.
    views: Vec<(usize, Vec<Column>)>,
    pixels: Vec<BandPixel>,
    ends: Vec<usize>,
}

thread_local! {
    static FIT_BUFFERS: std::cell::RefCell<FitBuffers> = std::cell::RefCell::default();
}

/// Fits one border of one sample over `frames` (each with its `cam_s_um` and index in the
/// group); `reference` is the position in `frames` of the frame the robust column check reads.
/// None when no frame sees the whole stretch or the fit finds no border. Each frame's own row
/// is left out (`frames` empty); `fit_gathered` adds them for the tests.
#[must_use]
pub fn fit_sample(
    frames: &[(&Image, f64, usize)],
    reference: usize,
    geo: &FrameGeometry,
    task: &SampleTask,
    params: &EdgeParams,
) -> Option<SampleBorder> {
    fit_gathered(frames, reference, geo, task, params, false)
}

/// [`fit_sample`], with each frame's own row too (one least-squares step per frame) when
/// `want_frames`.
pub(super) fn fit_gathered(
    frames: &[(&Image, f64, usize)],
    reference: usize,
    geo: &FrameGeometry,
    task: &SampleTask,
    params: &EdgeParams,
    want_frames: bool,
) -> Option<SampleBorder> {
    // Taken out for the fit and put back after, so the thread's buffers are never borrowed
    // across the fit.
    let mut buf = FIT_BUFFERS.with(|b| std::mem::take(&mut *b.borrow_mut()));
    let band = Band::new(params);
    buf.pixels.clear();
    buf.ends.clear();
    // The frames that see the stretch, each with its columns and band.
    let mut used = 0;
    for (i, (img, cam, _)) in frames.iter().enumerate() {
        if used == buf.views.len() {
            buf.views.push((i, Vec::new()));
        }
        let view = &mut buf.views[used];
        if columns_into(geo, *cam, task, &mut view.1) {
            view.0 = i;
            gather(img, &view.1, band, &mut buf.pixels, &mut buf.ends);
            used += 1;
        }
    }
    let views = &buf.views[..used];
    // The views' column ends follow one another in `ends` (one per column), and each view's
    // pixels start where the previous view's last column ended.
    let mut first_end = 0usize;
    let reader = Gathered {
        band,
        views: views
            .iter()
            .map(|(_, cols)| {
                let start = first_end
                    .checked_sub(1)
                    .and_then(|e| buf.ends.get(e))
                    .copied()
                    .unwrap_or(0);
                let ends = &buf.ends[first_end..first_end + cols.len()];
                first_end += cols.len();
                BandView {
                    cols,
                    start,
                    ends,
                    pixels: &buf.pixels,
                }
            })
            .collect(),
    };
    let fit = fit_views(
        frames,
        views,
        reference,
        geo,
        task,
        params,
        &reader,
        want_frames,
    );
    drop(reader);
    FIT_BUFFERS.with(|b| *b.borrow_mut() = buf);
    fit
}

/// The fit of [`fit_sample`] on the frames' `views`, their bands read through `reader`; with
/// `want_frames` each frame's own row too.
#[allow(clippy::too_many_arguments)] // the fit's inputs, each its own kind
pub(super) fn fit_views(
    frames: &[(&Image, f64, usize)],
    views: &[(usize, Vec<Column>)],
    reference: usize,
    geo: &FrameGeometry,
    task: &SampleTask,
    params: &EdgeParams,
    reader: &dyn BandReader,
    want_frames: bool,
) -> Option<SampleBorder> {
    let band = Band::new(params);
    if views.is_empty() {
        return None;
    }
    // The reference frame for the column check: the asked one when it sees the stretch, else
    // the nearest that does.
    let ref_view = views
        .iter()
        .enumerate()
        .min_by_key(|(_, (i, _))| i.abs_diff(reference))
        .map(|(k, _)| k)?;
    let seed = BorderSeed {
        position_px: 0.0,
        width_px: 1.0,
    };
    // Robust column weights by groove position (ref-frame columns: start s, weight).
    let mut weights: Vec<(f64, f64)> = Vec::new();
    let weight_at = |w: &[(f64, f64)], s: f64| -> f64 {
        if w.is_empty() {
            return 1.0;
        }
        let i = w.partition_point(|e| e.0 <= s);
        i.checked_sub(1).and_then(|k| w.get(k)).map_or(1.0, |e| e.1)
    };
    let mut rounds = 0;
    // One frame's bins, reused; the joint bins sum them frame by frame.
    let mut scratch = Bins::new(band.bins);
    let mut per_frame: Vec<(usize, Bins)> = Vec::new();
    loop {
        rounds += 1;
        per_frame.clear();
        let mut joint = Bins::new(band.bins);
        for (k, (i, _)) in views.iter().enumerate() {
            if reader.bins_into(k, &|s| weight_at(&weights, s), &mut scratch) {
                joint.add(&scratch);
                if want_frames {
                    per_frame.push((*i, scratch.clone()));
                }
            }
        }
        let fit = fit_border(&joint.points(), seed, &params.border)?;
        let table = column_table(band, &fit);
        let checked = reader.column_weights(ref_view, &table, params.column_sigma_px)?;
        // A new outlier: one the last round kept (the columns are the reference view's, in the
        // same order every round).
        let outliers = checked
            .iter()
            .enumerate()
            .any(|(k, c)| c.2 < OUTLIER_WEIGHT && weights.get(k).is_none_or(|w| w.1 > 0.0));
        #[allow(clippy::cast_possible_truncation)] // weights in [0, 1]
        let column_report: Vec<(usize, f32)> = checked.iter().map(|c| (c.0, c.2 as f32)).collect();
        if outliers && rounds < params.column_rounds {
            // Column k covers the groove from halfway to its left neighbour. Outliers are left
            // out altogether; the others keep their Lorentzian weight.
            let half = 0.5 * geo.um_per_px(task.z_um);
            weights = checked
                .iter()
                .map(|c| (c.1 - half, if c.2 < OUTLIER_WEIGHT { 0.0 } else { c.2 }))
                .collect();
            continue;
        }
        let mean_row = joint.mean_row()?;
        let frames_out = per_frame
            .iter()
            .filter_map(|(i, bins)| {
                let (_, cam, index) = frames.get(*i)?;
                let (mu, se) = frame_step(bins, &fit)?;
                let row = bins.mean_row()? + mu;
                let s_mid = 0.5 * (task.s_lo_um + task.s_hi_um);
                Some(FrameBorder {
                    frame_index: *index,
                    column_px: geo.x_at(*cam, s_mid, task.z_um),
                    row_px: row,
                    std_error_px: se,
                })
            })
            .collect();
        return Some(SampleBorder {
            row_px: mean_row + fit.position_px,
            std_error_px: fit.std_error_px,
            fit,
            frames: frames_out,
            column_weights: column_report,
            rounds,
        });
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
pub(super) mod tests;
