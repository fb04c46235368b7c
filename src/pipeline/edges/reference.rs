//! A plain reference of the fine fit's band reads: every robust round reads each column's band
//! from the frame pixel by pixel (`⌊(u + half)/bin⌋` by a floor call); the fast fit, which reads
//! each band once and re-weights it, is tested against it bit for bit.

use super::EdgeParams;
use super::geometry::FrameGeometry;
use super::profile::{
    Band, BandReader, Bins, Column, ColumnWeights, SampleBorder, SampleTask, fit_views,
    frame_views, lorentzian_weight,
};
use crate::image::Image;

/// The bin of offset `u`, by the floor.
fn plain_bin(band: Band, u: f64) -> Option<usize> {
    let b = ((u + band.half_px) / band.bin_px).floor();
    (b >= 0.0 && (b as usize) < band.bins).then_some(b as usize)
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
            let (Some(b), Some(v)) = (plain_bin(band, u), frame.get(c.x, r)) else {
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

/// Per-column offsets against the fitted model's `table` (one Gauss–Newton step on the
/// position per column) and their Lorentzian weights.
fn column_weights(
    frame: &Image,
    cols: &[Column],
    band: Band,
    table: &[(f64, f64)],
    sigma_px: f64,
) -> ColumnWeights {
    cols.iter()
        .map(|c| {
            let (mut num, mut den) = (0.0, 0.0);
            for (r, u) in band.rows(c.row, frame.height) {
                let (Some(b), Some(v)) = (plain_bin(band, u), frame.get(c.x, r)) else {
                    continue;
                };
                let Some(&(m, slope)) = table.get(b) else {
                    continue;
                };
                num -= (f64::from(v) - m) * slope;
                den += slope * slope;
            }
            let delta = if den > 0.0 { num / den } else { 0.0 };
            (c.x, c.s_um, lorentzian_weight(delta, sigma_px))
        })
        .collect()
}

/// Reads every view's band from its frame, every time.
struct PlainReader<'a> {
    frames: &'a [(&'a Image, f64, usize)],
    views: &'a [(usize, Vec<Column>)],
    band: Band,
}

impl BandReader for PlainReader<'_> {
    fn bins(&self, k: usize, weight: &dyn Fn(f64) -> f64) -> Option<Bins> {
        let (i, cols) = self.views.get(k)?;
        let (img, _, _) = self.frames.get(*i)?;
        Some(accumulate(img, cols, self.band, weight))
    }

    fn column_weights(&self, k: usize, table: &[(f64, f64)], sigma: f64) -> Option<ColumnWeights> {
        let (i, cols) = self.views.get(k)?;
        let (img, _, _) = self.frames.get(*i)?;
        Some(column_weights(img, cols, self.band, table, sigma))
    }
}

/// [`super::profile::fit_sample`] with the plain band reads.
fn fit_sample(
    frames: &[(&Image, f64, usize)],
    reference: usize,
    geo: &FrameGeometry,
    task: &SampleTask,
    params: &EdgeParams,
) -> Option<SampleBorder> {
    let views = frame_views(frames, geo, task);
    let reader = PlainReader {
        frames,
        views: &views,
        band: Band::new(params),
    };
    fit_views(frames, &views, reference, geo, task, params, &reader, true)
}

#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::super::profile::tests::{frames, meta};
    use super::*;

    /// A multiplicative texture fixed to the record (a hash of the pixel's record cell), so
    /// the profile sums carry every rounding a real scan does.
    fn textured(geo: &FrameGeometry, imgs: &[Image]) -> Vec<Image> {
        imgs.iter()
            .enumerate()
            .map(|(k, img)| {
                let cam = geo.cam_s_um(0, k);
                Image::from_fn(img.width, img.height, |x, r| {
                    let s = geo.s_at(cam, x as f64, geo.working_distance_um);
                    let cell = (s / 0.39).round() as i64 * 7919 + r as i64 * 104_729;
                    let h = (cell.wrapping_mul(0x9E37_79B9) >> 7) & 1023;
                    img.get(x, r).unwrap() * (0.9 + 0.2 * h as f32 / 1023.0)
                })
            })
            .collect()
    }

    #[test]
    fn the_gathered_band_fit_matches_the_plain_reads_bit_for_bit() {
        let geo = FrameGeometry::new(&meta(), 120, 60);
        let mut compared = 0;
        let mut robust = 0;
        for (speck, slope) in [(0, 0.03), (6, 0.03), (3, -0.05), (9, 0.1)] {
            let imgs = textured(&geo, &frames(&geo, 0.7, slope, speck));
            let list: Vec<(&Image, f64, usize)> = imgs
                .iter()
                .enumerate()
                .map(|(k, f)| (f, geo.cam_s_um(0, k), k))
                .collect();
            for (lo, off, rounds) in [
                (10.0, 0.3, 3),
                (4.0, -0.6, 3),
                (14.5, 1.1, 1),
                (-3.0, 0.0, 3),
            ] {
                let predict = move |s: f64| 0.7 + slope * s + off;
                let task = SampleTask {
                    s_lo_um: lo,
                    s_hi_um: lo + 21.3,
                    z_um: geo.working_distance_um,
                    predict_y: &predict,
                };
                let params = EdgeParams {
                    column_rounds: rounds,
                    ..EdgeParams::default()
                };
                for reference in [0, 3, 5] {
                    let fast = super::super::profile::fit_gathered(
                        &list, reference, &geo, &task, &params, true,
                    );
                    let plain = fit_sample(&list, reference, &geo, &task, &params);
                    assert_eq!(
                        fast, plain,
                        "speck {speck}, stretch from {lo}, ref {reference}"
                    );
                    if let Some(f) = fast {
                        compared += 1;
                        robust += usize::from(f.rounds > 1);
                    }
                }
            }
        }
        assert!(compared >= 30, "{compared} fits compared");
        assert!(robust >= 3, "{robust} fits ran the robust rounds");
    }
}
