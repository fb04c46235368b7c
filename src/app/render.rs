//! Stage results turned into textures: `crate::viz` renderings wrapped as `egui::ColorImage`s,
//! with the value range each colour map spans (for colour bars and legends).
//!
//! These run on the worker thread right after a stage finishes (and on the UI thread only for a
//! single frame or flow window the operator picks), so the UI thread never converts whole stages.

use std::sync::Arc;

use egui::{Color32, ColorImage};

use crate::image::Image;
use crate::pipeline::hough::{Accumulator, Stripes};
use crate::pipeline::optical_flow::FlowField;
use crate::viz::{self, ColorMap, Rgba8Image};

/// Colour map of heat maps (depth, weights, accumulator).
pub const HEAT_MAP: ColorMap = ColorMap::Inferno;

/// Colour of stripe region `k` (the same colours as `viz::stripes_overlay`).
#[must_use]
pub fn region_colour(k: usize) -> Color32 {
    let [r, g, b, _] = viz::REGION_RGBA[k % viz::REGION_RGBA.len()];
    Color32::from_rgb(r, g, b)
}

/// A texture with the value range its colours span (for colour bars).
#[derive(Clone, Debug)]
pub struct Rendered {
    /// The pixels (shared: handed to the GPU without a copy).
    pub image: Arc<ColorImage>,
    /// Value at colour 0.
    pub lo: f32,
    /// Value at colour 1.
    pub hi: f32,
}

/// A `viz` raster as an egui image.
#[must_use]
pub fn color_image(img: &Rgba8Image) -> ColorImage {
    if img.pixels.len() == img.width * img.height * 4 {
        ColorImage::from_rgba_unmultiplied([img.width, img.height], &img.pixels)
    } else {
        ColorImage::filled([img.width, img.height], Color32::TRANSPARENT)
    }
}

fn rendered(img: &Rgba8Image, lo: f32, hi: f32) -> Rendered {
    Rendered {
        image: Arc::new(color_image(img)),
        lo,
        hi,
    }
}

/// The heat colour of `t` in `[0, 1]` (clamped; NaN gives the map's NaN colour).
#[must_use]
pub fn heat_colour(t: f32) -> Color32 {
    let [r, g, b, a] = HEAT_MAP.rgba(t);
    Color32::from_rgba_unmultiplied(r, g, b, a)
}

/// Finite minimum and maximum of `values` (None when none is finite).
#[must_use]
pub fn finite_range(values: &[f32]) -> Option<(f32, f32)> {
    let mut lo = f32::INFINITY;
    let mut hi = f32::NEG_INFINITY;
    for &v in values {
        if v.is_finite() {
            lo = lo.min(v);
            hi = hi.max(v);
        }
    }
    (lo <= hi).then_some((lo, hi))
}

/// A grey frame (contrast stretched to its range) as a texture.
#[must_use]
pub fn grey(img: &Image) -> ColorImage {
    color_image(&viz::grey_image(img))
}

/// A heat map of `img` over its finite range (or `range` when given); NaN pixels are clear.
#[must_use]
pub fn heat(img: &Image, range: Option<(f32, f32)>) -> Rendered {
    let (lo, hi) = range
        .or_else(|| finite_range(&img.data))
        .unwrap_or((0.0, 1.0));
    rendered(&viz::heat_map(img, Some((lo, hi)), HEAT_MAP), lo, hi)
}

/// Colour of pixels in no robust fit in the weight map (outliers, weight 0, are the heat map's
/// black; trusted pixels are bright).
pub const NO_FIT_COLOUR: Color32 = Color32::from_rgb(70, 95, 125);

/// The robust fits' weight map: weights 0–1 as a heat map, pixels in no fit (NaN) in
/// [`NO_FIT_COLOUR`], so they do not read as outliers.
#[must_use]
pub fn weights(map: &Image) -> Rendered {
    let mut r = heat(map, Some((0.0, 1.0)));
    let img = Arc::make_mut(&mut r.image);
    for (p, v) in img.pixels.iter_mut().zip(&map.data) {
        if !v.is_finite() {
            *p = NO_FIT_COLOUR;
        }
    }
    r
}

/// Residual magnitudes above this quantile saturate the flow colours (a few wild pixels would
/// otherwise wash the rest out).
pub const FLOW_SATURATION_QUANTILE: f64 = 0.98;
/// Most magnitudes sampled to find that quantile.
const FLOW_QUANTILE_SAMPLES: usize = 65_536;

/// Flow as colour (Middlebury wheel) after subtracting `subtract_u_px` from u, so the residual
/// that depth causes shows. Residuals longer than the [`FLOW_SATURATION_QUANTILE`] of all are
/// shortened to it first; `hi` is that length (full saturation).
#[must_use]
pub fn flow_colour(flow: &FlowField, subtract_u_px: f32) -> Rendered {
    let n = flow.u.data.len().min(flow.v.data.len());
    let stride = n.div_ceil(FLOW_QUANTILE_SAMPLES).max(1);
    let mut mags: Vec<f32> = (0..n)
        .step_by(stride)
        .map(|i| (flow.u.data[i] - subtract_u_px).hypot(flow.v.data[i]))
        .filter(|m| m.is_finite())
        .collect();
    if mags.is_empty() {
        return rendered(&viz::flow_image(flow, subtract_u_px), 0.0, 0.0);
    }
    let k = ((mags.len() - 1) as f64 * FLOW_SATURATION_QUANTILE).round() as usize;
    let (_, &mut hi, _) = mags.select_nth_unstable_by(k, f32::total_cmp);
    if hi <= 0.0 {
        return rendered(&viz::flow_image(flow, subtract_u_px), 0.0, hi);
    }
    let mut limited = flow.clone();
    for (u, v) in limited.u.data.iter_mut().zip(limited.v.data.iter_mut()) {
        let du = *u - subtract_u_px;
        let m = du.hypot(*v);
        if m > hi {
            let s = hi / m;
            *u = subtract_u_px + du * s;
            *v *= s;
        }
    }
    rendered(&viz::flow_image(&limited, subtract_u_px), 0.0, hi)
}

/// The Hough accumulator as a log-scaled heat map: width = θ bins, height = ρ bins (the
/// windows are drawn by the view, so they follow edits).
#[must_use]
pub fn accumulator(acc: &Accumulator) -> Rendered {
    let max = acc.votes.iter().copied().max().unwrap_or(0);
    rendered(&viz::hough_image(acc, &[], None), 0.0, max as f32)
}

/// The segmentation over the frame with the centroid lines (`viz::stripes_overlay`).
#[must_use]
pub fn stripes(frame: &Image, stripes: &Stripes) -> Rendered {
    rendered(&viz::stripes_overlay(frame, stripes), 0.0, 1.0)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;

    #[test]
    fn heat_spans_the_range_and_clears_nan() {
        let img = Image::from_vec(3, 1, vec![1.0, f32::NAN, 3.0]).unwrap();
        let r = heat(&img, None);
        assert_eq!((r.lo, r.hi), (1.0, 3.0));
        assert_eq!(r.image.pixels[1].a(), 0, "NaN is transparent");
        assert_eq!(r.image.pixels[2], heat_colour(1.0));
        assert_ne!(r.image.pixels[0], r.image.pixels[2]);
    }

    #[test]
    fn weights_keep_no_fit_apart_from_outliers() {
        let map = Image::from_vec(3, 1, vec![0.0, f32::NAN, 1.0]).unwrap();
        let r = weights(&map);
        assert_eq!(r.image.pixels[1], NO_FIT_COLOUR);
        assert_eq!(r.image.pixels[0], heat_colour(0.0));
        assert_ne!(r.image.pixels[0], r.image.pixels[1]);
        assert_eq!(r.image.pixels[2], heat_colour(1.0));
    }

    #[test]
    fn flow_colour_reports_the_residual_magnitude() {
        let flow = FlowField::exact(Image::from_vec(2, 1, vec![-2.0, -1.5]).unwrap(), 0);
        let r = flow_colour(&flow, -2.0);
        assert!((r.hi - 0.5).abs() < 1e-6);
        assert_eq!(r.image.size, [2, 1]);
        assert_ne!(r.image.pixels[0], r.image.pixels[1]);
        // One wild pixel among 99 small ones does not set the scale.
        let mut u = vec![0.1_f32; 100];
        u[7] = 50.0;
        let wild = FlowField::exact(Image::from_vec(100, 1, u).unwrap(), 0);
        let r = flow_colour(&wild, 0.0);
        assert!((r.hi - 0.1).abs() < 1e-6, "{}", r.hi);
        assert_eq!(
            r.image.pixels[7], r.image.pixels[0],
            "the wild pixel saturates"
        );
    }

    #[test]
    fn accumulator_is_theta_by_rho() {
        let acc = Accumulator {
            thetas_rad: vec![0.0, 0.1, 0.2],
            rho_min_px: 0.0,
            rho_step_px: 1.0,
            rho_bins: 2,
            votes: vec![0, 0, 0, 9, 0, 0],
            x_origin_px: 0.0,
            vote_stride: 1,
        };
        let r = accumulator(&acc);
        assert_eq!(r.image.size, [3, 2]);
        assert_eq!(r.hi, 9.0);
        // θ bin 1, ρ bin 1 holds the maximum: pixel (x = 1, y = 1) is the brightest.
        let bright = r.image.pixels[3 + 1];
        assert!(r.image.pixels.iter().all(|p| p.r() <= bright.r()));
    }
}
