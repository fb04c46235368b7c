//! Stage results turned into textures (`egui::ColorImage`): grey frames, heat maps, flow colours, labels.
//!
//! These run on the worker thread right after a stage finishes (and on the UI thread only for a
//! single frame when the operator scrubs), so the UI thread never converts whole stages.

use std::sync::Arc;

use egui::{Color32, ColorImage};

use crate::image::Image;
use crate::pipeline::hough::{Accumulator, Stripes, label};
use crate::pipeline::optical_flow::FlowField;

/// Stops of the heat colour map (dark blue, cyan, yellow, red), evenly spaced over `[0, 1]`.
const HEAT_STOPS: [[u8; 3]; 6] = [
    [10, 10, 40],
    [30, 60, 170],
    [20, 170, 200],
    [120, 220, 90],
    [250, 210, 40],
    [210, 40, 30],
];

/// Colour of NaN (unknown) pixels in heat maps.
pub const UNKNOWN_COLOUR: Color32 = Color32::from_rgb(60, 60, 60);

/// Distinct colours for stripe labels (index = peak).
pub const LABEL_COLOURS: [Color32; 6] = [
    Color32::from_rgb(230, 80, 80),
    Color32::from_rgb(80, 200, 90),
    Color32::from_rgb(80, 140, 240),
    Color32::from_rgb(230, 190, 60),
    Color32::from_rgb(190, 90, 220),
    Color32::from_rgb(60, 210, 210),
];

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

/// The heat colour of `t` in `[0, 1]` (clamped).
#[must_use]
pub fn heat_colour(t: f32) -> Color32 {
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let pos = t * (HEAT_STOPS.len() - 1) as f32;
    let i = (pos.floor() as usize).min(HEAT_STOPS.len() - 2);
    let f = pos - i as f32;
    let (a, b) = (HEAT_STOPS[i], HEAT_STOPS[i + 1]);
    let mix = |k: usize| (f32::from(a[k]) + (f32::from(b[k]) - f32::from(a[k])) * f).round() as u8;
    Color32::from_rgb(mix(0), mix(1), mix(2))
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

/// A grey frame with values in `[0, 1]` as an opaque texture.
#[must_use]
pub fn grey(img: &Image) -> ColorImage {
    let pixels = img
        .data
        .iter()
        .map(|&v| {
            let g = if v.is_finite() {
                (v.clamp(0.0, 1.0) * 255.0).round() as u8
            } else {
                0
            };
            Color32::from_gray(g)
        })
        .collect();
    ColorImage::new([img.width, img.height], pixels)
}

/// A heat map of `img` over its finite range (or `range` when given); NaN pixels are grey.
#[must_use]
pub fn heat(img: &Image, range: Option<(f32, f32)>) -> Rendered {
    let (lo, hi) = range
        .or_else(|| finite_range(&img.data))
        .unwrap_or((0.0, 1.0));
    let span = if hi > lo { hi - lo } else { 1.0 };
    let pixels = img
        .data
        .iter()
        .map(|&v| {
            if v.is_finite() {
                heat_colour((v - lo) / span)
            } else {
                UNKNOWN_COLOUR
            }
        })
        .collect();
    Rendered {
        image: Arc::new(ColorImage::new([img.width, img.height], pixels)),
        lo,
        hi,
    }
}

/// Flow as colour: hue from direction, saturation from magnitude over `max_px` (None: the field's
/// largest magnitude); pixels without confidence are black.
#[must_use]
pub fn flow_colour(flow: &FlowField, max_px: Option<f32>) -> Rendered {
    let mags: Vec<f32> = flow
        .u
        .data
        .iter()
        .zip(&flow.v.data)
        .map(|(u, v)| u.hypot(*v))
        .collect();
    let max = max_px
        .filter(|m| *m > 0.0)
        .or_else(|| finite_range(&mags).map(|(_, hi)| hi))
        .filter(|m| *m > 0.0)
        .unwrap_or(1.0);
    let pixels = flow
        .u
        .data
        .iter()
        .zip(&flow.v.data)
        .zip(mags.iter().zip(&flow.confidence.data))
        .map(|((&u, &v), (&m, &c))| {
            if !(u.is_finite() && v.is_finite()) || c <= 0.0 {
                return Color32::BLACK;
            }
            let hue = (v.atan2(u) / std::f32::consts::TAU).rem_euclid(1.0);
            let sat = (m / max).clamp(0.0, 1.0);
            egui::ecolor::Hsva::new(hue, sat, 1.0, 1.0).into()
        })
        .collect();
    Rendered {
        image: Arc::new(ColorImage::new([flow.u.width, flow.u.height], pixels)),
        lo: 0.0,
        hi: max,
    }
}

/// The Hough accumulator as a heat map on a log scale: width = θ bins, height = ρ bins.
#[must_use]
pub fn accumulator(acc: &Accumulator) -> Rendered {
    let tb = acc.thetas_rad.len();
    let rb = acc.rho_bins;
    let max = acc.votes.iter().copied().max().unwrap_or(0);
    let norm = (f64::from(max) + 1.0).ln().max(f64::MIN_POSITIVE);
    let mut pixels = vec![UNKNOWN_COLOUR; tb * rb];
    for t in 0..tb {
        for r in 0..rb {
            let votes = acc.votes.get(t * rb + r).copied().unwrap_or(0);
            let v = ((f64::from(votes) + 1.0).ln() / norm) as f32;
            pixels[r * tb + t] = heat_colour(v);
        }
    }
    Rendered {
        image: Arc::new(ColorImage::new([tb, rb], pixels)),
        lo: 0.0,
        hi: max as f32,
    }
}

/// Stripe labels as a translucent overlay: peak colours, discarded pixels white, others clear.
#[must_use]
pub fn labels(stripes: &Stripes) -> ColorImage {
    let (w, h) = (stripes.in_focus.width, stripes.in_focus.height);
    let pixels = (0..w * h)
        .map(
            |i| match stripes.labels.get(i).copied().unwrap_or(label::NONE) {
                l if l >= 0 => {
                    let c = LABEL_COLOURS[l as usize % LABEL_COLOURS.len()];
                    if l as usize == stripes.dropped {
                        Color32::from_rgba_unmultiplied(c.r(), c.g(), c.b(), 70)
                    } else {
                        Color32::from_rgba_unmultiplied(c.r(), c.g(), c.b(), 160)
                    }
                }
                label::DISCARDED => Color32::from_rgba_unmultiplied(255, 255, 255, 140),
                label::UNASSIGNED => Color32::from_rgba_unmultiplied(120, 120, 120, 90),
                _ => Color32::TRANSPARENT,
            },
        )
        .collect();
    ColorImage::new([w, h], pixels)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;

    #[test]
    fn heat_runs_from_dark_to_red_and_marks_nan() {
        assert_eq!(heat_colour(0.0), Color32::from_rgb(10, 10, 40));
        assert_eq!(heat_colour(1.0), Color32::from_rgb(210, 40, 30));
        assert_eq!(heat_colour(f32::NAN), heat_colour(0.0));
        let img = Image::from_vec(3, 1, vec![1.0, f32::NAN, 3.0]).unwrap();
        let r = heat(&img, None);
        assert_eq!((r.lo, r.hi), (1.0, 3.0));
        assert_eq!(r.image.pixels[1], UNKNOWN_COLOUR);
        assert_eq!(r.image.pixels[2], heat_colour(1.0));
    }

    #[test]
    fn flow_colour_hue_follows_direction() {
        let u = Image::from_vec(2, 1, vec![1.0, -1.0]).unwrap();
        let v = Image::zeros(2, 1);
        let flow = FlowField {
            u,
            v,
            confidence: Image::filled(2, 1, 1.0),
            iterations: 1,
            converged: true,
            frame_index: 0,
        };
        let r = flow_colour(&flow, None);
        let right = r.image.pixels[0];
        let left = r.image.pixels[1];
        assert!(right.r() > right.b(), "+x is red: {right:?}");
        assert!(
            left.r() < left.b() || left.g() > left.r(),
            "-x is cyan: {left:?}"
        );
        assert!((r.hi - 1.0).abs() < 1e-6);
    }

    #[test]
    fn accumulator_is_theta_by_rho() {
        let acc = Accumulator {
            thetas_rad: vec![0.0, 0.1, 0.2],
            rho_min_px: 0.0,
            rho_step_px: 1.0,
            rho_bins: 2,
            votes: vec![0, 0, 0, 9, 0, 0],
        };
        let r = accumulator(&acc);
        assert_eq!(r.image.size, [3, 2]);
        // θ bin 1, ρ bin 1 holds the maximum: pixel (x=1, y=1).
        assert_eq!(r.image.pixels[3 + 1], heat_colour(1.0));
        assert_eq!(r.hi, 9.0);
    }
}
