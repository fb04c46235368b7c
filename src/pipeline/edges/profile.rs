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
//! columns that stray (`column_sigma_px`), and while any column weighs less than
//! [`OUTLIER_WEIGHT`] the bins are summed again with those weights (outliers left out; applied
//! in every frame to the columns that see the same groove position) and refitted, up to
//! `column_rounds` times.
//! Each frame's own position is then one linear least-squares step (levels and position) from
//! the joint fit on that frame's bins.

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
pub(crate) fn columns(
    geo: &FrameGeometry,
    cam_s_um: f64,
    task: &SampleTask,
) -> Option<Vec<Column>> {
    let x_lo = geo.x_at(cam_s_um, task.s_lo_um, task.z_um);
    let x_hi = geo.x_at(cam_s_um, task.s_hi_um, task.z_um);
    if !(x_lo >= -0.5 && x_hi <= geo.width as f64 - 0.5 && x_hi > x_lo) {
        return None;
    }
    let first = (x_lo + 0.5).floor().max(0.0) as usize;
    let last = ((x_hi + 0.5).ceil() as usize).min(geo.width);
    let cols = (first..last)
        .filter_map(|x| {
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
        })
        .collect();
    Some(cols)
}

/// Sub-pixel bins of one frame's straightened profile: Σw, Σw·u, Σw·v per bin.
#[derive(Clone, Debug)]
struct Bins {
    sums: Vec<[f64; 3]>,
    /// Σ share·weight·row over the columns, and Σ share·weight.
    row_sum: f64,
    weight_sum: f64,
}

impl Bins {
    fn new(n: usize) -> Self {
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

    fn mean_row(&self) -> Option<f64> {
        (self.weight_sum > 0.0).then(|| self.row_sum / self.weight_sum)
    }
}

/// Band geometry shared by the passes.
#[derive(Clone, Copy)]
struct Band {
    half_px: f64,
    bin_px: f64,
    bins: usize,
}

impl Band {
    fn new(params: &EdgeParams) -> Self {
        let half_px = params.band_half_height_px;
        let bin_px = params.bin_px;
        Self {
            half_px,
            bin_px,
            bins: (2.0 * half_px / bin_px).ceil() as usize,
        }
    }

    /// Rows of a column whose offset lies in the band, with their offsets.
    fn rows(&self, predicted: f64, height: usize) -> impl Iterator<Item = (usize, f64)> {
        let lo = (predicted - self.half_px).ceil().max(0.0) as usize;
        let hi = ((predicted + self.half_px).floor().max(-1.0) + 1.0) as usize;
        (lo..hi.min(height)).map(move |r| (r, r as f64 - predicted))
    }

    fn bin(&self, u: f64) -> Option<usize> {
        let b = ((u + self.half_px) / self.bin_px).floor();
        (b >= 0.0 && (b as usize) < self.bins).then_some(b as usize)
    }
}

/// Accumulates one frame's columns into bins, each column weighted by `weight(s)`.
fn accumulate(frame: &Image, cols: &[Column], band: Band, weight: &dyn Fn(f64) -> f64) -> Bins {
    let mut bins = Bins::new(band.bins);
    for c in cols {
        let w = c.share * weight(c.s_um);
        if w <= 0.0 {
            continue;
        }
        for (r, u) in band.rows(c.row, frame.height) {
            let (Some(b), Some(v)) = (band.bin(u), frame.get(c.x, r)) else {
                continue;
            };
            if let Some(s) = bins.sums.get_mut(b) {
                s[0] += w;
                s[1] += w * u;
                s[2] += w * f64::from(v);
            }
        }
        bins.row_sum += w * c.row;
        bins.weight_sum += w;
    }
    bins
}

/// Lorentzian weight of a residual `r` at scale `sigma`: ψ(r)/r = 1/(1 + r²/(2σ²)).
#[must_use]
pub fn lorentzian_weight(r: f64, sigma: f64) -> f64 {
    1.0 / (1.0 + r * r / (2.0 * sigma * sigma))
}

/// Per-column offsets on the reference frame against the fitted model (one Gauss–Newton step
/// on the position per column) and their Lorentzian weights.
fn column_weights(
    frame: &Image,
    cols: &[Column],
    band: Band,
    fit: &Border,
    sigma_px: f64,
) -> Vec<(usize, f64, f64)> {
    // The model and its slope at each bin centre, looked up per pixel.
    let table: Vec<(f64, f64)> = (0..band.bins)
        .map(|b| {
            let u = -band.half_px + (b as f64 + 0.5) * band.bin_px;
            (fit.model_at(u), fit.slope_at(u))
        })
        .collect();
    cols.iter()
        .map(|c| {
            let (mut num, mut den) = (0.0, 0.0);
            for (r, u) in band.rows(c.row, frame.height) {
                let (Some(b), Some(v)) = (band.bin(u), frame.get(c.x, r)) else {
                    continue;
                };
                let Some(&(m, slope)) = table.get(b) else {
                    continue;
                };
                // model(u − δ) ≈ m − slope·δ  ⇒  δ = −Σ(v − m)·slope / Σ slope².
                num -= (f64::from(v) - m) * slope;
                den += slope * slope;
            }
            let delta = if den > 0.0 { num / den } else { 0.0 };
            (c.x, c.s_um, lorentzian_weight(delta, sigma_px))
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

/// Fits one border of one sample over `frames` (each with its `cam_s_um` and index in the
/// group); `reference` is the position in `frames` of the frame the robust column check reads.
/// None when no frame sees the whole stretch or the fit finds no border.
#[must_use]
pub fn fit_sample(
    frames: &[(&Image, f64, usize)],
    reference: usize,
    geo: &FrameGeometry,
    task: &SampleTask,
    params: &EdgeParams,
) -> Option<SampleBorder> {
    let band = Band::new(params);
    let views: Vec<(usize, Vec<Column>)> = frames
        .iter()
        .enumerate()
        .filter_map(|(i, (_, cam, _))| columns(geo, *cam, task).map(|c| (i, c)))
        .collect();
    if views.is_empty() {
        return None;
    }
    // The reference frame for the column check: the asked one when it sees the stretch, else
    // the nearest that does.
    let ref_view = views
        .iter()
        .min_by_key(|(i, _)| i.abs_diff(reference))
        .map(|(i, _)| *i)?;
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
    loop {
        rounds += 1;
        let per_frame: Vec<(usize, Bins)> = views
            .iter()
            .filter_map(|(i, cols)| {
                let (img, _, _) = frames.get(*i)?;
                Some((*i, accumulate(img, cols, band, &|s| weight_at(&weights, s))))
            })
            .collect();
        let mut joint = Bins::new(band.bins);
        for (_, b) in &per_frame {
            joint.add(b);
        }
        let fit = fit_border(&joint.points(), seed, &params.border)?;
        let (ref_img, _, _) = frames.get(ref_view)?;
        let ref_cols = &views.iter().find(|(i, _)| *i == ref_view)?.1;
        let checked = column_weights(ref_img, ref_cols, band, &fit, params.column_sigma_px);
        let outliers = checked.iter().any(|c| c.2 < OUTLIER_WEIGHT);
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
mod tests {
    use super::*;
    use crate::io::scan::test_support::scan_meta;
    use crate::meta::ScanMeta;

    fn meta() -> ScanMeta {
        scan_meta(40.0)
    }

    /// Frames of a land/wall border at record y(s) = `y0 + slope·s` (µm), blurred by 0.7 px,
    /// with a bright speck `speck` columns wide across it at groove position 20 µm.
    fn frames(geo: &FrameGeometry, y0: f64, slope: f64, speck: usize) -> Vec<Image> {
        (0..6)
            .map(|k| {
                let cam = geo.cam_s_um(0, k);
                Image::from_fn(geo.width, geo.height, |x, r| {
                    let s = geo.s_at(cam, x as f64, geo.working_distance_um);
                    let y = geo.y_at(r as f64, geo.working_distance_um);
                    let edge = y0 + slope * s;
                    let mut v = 0.15 + 0.6 * normal_cdf((y - edge) / (0.7 * 0.39));
                    // The speck is fixed to the record: the same groove position in every frame.
                    if speck > 0
                        && (s - 20.0).abs() < 0.5 * speck as f64 * 0.39
                        && (y - edge).abs() < 2.0
                    {
                        v = 1.0;
                    }
                    v as f32
                })
            })
            .collect()
    }

    fn run(speck: usize, rounds: u32) -> (f64, SampleBorder, FrameGeometry) {
        let geo = FrameGeometry::new(&meta(), 120, 60);
        let (y0, slope) = (0.7, 0.03);
        let imgs = frames(&geo, y0, slope, speck);
        let list: Vec<(&Image, f64, usize)> = imgs
            .iter()
            .enumerate()
            .map(|(k, f)| (f, geo.cam_s_um(0, k), k))
            .collect();
        let predict = |s: f64| y0 + slope * s + 0.3; // a prediction 0.3 µm off
        let task = SampleTask {
            s_lo_um: 10.0,
            s_hi_um: 31.3,
            z_um: geo.working_distance_um,
            predict_y: &predict,
        };
        let params = EdgeParams {
            column_rounds: rounds,
            ..EdgeParams::default()
        };
        let got = fit_sample(&list, 3, &geo, &task, &params).unwrap();
        // The truth: the border averaged over the stretch, in rows.
        let y_mean = y0 + slope * 20.65;
        (geo.row_at(y_mean, geo.working_distance_um), got, geo)
    }

    #[test]
    fn a_sloped_border_is_found_in_every_frame() {
        let (want, got, _) = run(0, 3);
        assert!((got.row_px - want).abs() < 0.01, "{} vs {want}", got.row_px);
        assert_eq!(got.frames.len(), 6);
        for f in &got.frames {
            assert!((f.row_px - want).abs() < 0.02, "{f:?} vs {want}");
        }
        assert_eq!(got.rounds, 1);
    }

    #[test]
    fn a_dust_speck_across_the_border_is_rejected() {
        // Without the robust rounds the speck pulls the border; with them it is weighted out.
        let (want, plain, _) = run(6, 1);
        let (_, robust, _) = run(6, 3);
        let plain_err = (plain.row_px - want).abs();
        let robust_err = (robust.row_px - want).abs();
        assert!(plain_err > 0.05, "the speck should matter: {plain_err}");
        assert!(
            robust_err < 0.02,
            "robust error {robust_err} (plain {plain_err})"
        );
        assert!(robust.rounds > 1);
        let rejected = robust.column_weights.iter().filter(|c| c.1 < 0.5).count();
        assert!((4..=10).contains(&rejected), "{rejected} columns rejected");
    }

    #[test]
    fn a_stretch_outside_every_frame_is_none() {
        let geo = FrameGeometry::new(&meta(), 120, 60);
        let imgs = frames(&geo, 0.7, 0.0, 0);
        let list: Vec<(&Image, f64, usize)> = vec![(&imgs[0], geo.cam_s_um(0, 0), 0)];
        let predict = |_: f64| 0.7;
        let task = SampleTask {
            s_lo_um: 500.0,
            s_hi_um: 521.3,
            z_um: geo.working_distance_um,
            predict_y: &predict,
        };
        assert!(fit_sample(&list, 0, &geo, &task, &EdgeParams::default()).is_none());
    }
}
