//! Pure renderers from stage outputs to RGBA8 images, shared by the GUI (textures) and the CLI (PNG dumps).
//!
//! Nothing here knows about egui: every function takes stage outputs and returns an
//! [`Rgba8Image`]. Conventions:
//! - NaN (or otherwise non-finite) values are drawn as [`NAN_RGBA`]: grey with zero alpha, so
//!   they are transparent where alpha is honoured and grey elsewhere.
//! - Heat maps use a perceptual colour map ([`ColorMap`]): low = dark.
//! - Flow uses the Middlebury colour wheel (hue = direction, saturation = magnitude / max).

use std::path::Path;

use image::ImageEncoder;

use crate::image::Image;
use crate::io::LoadError;
use crate::io::atomic::write_atomic_with;
use crate::pipeline::edges::{BorderTrack, Edges};
use crate::pipeline::hough::{Accumulator, Peak, Stripes, label};
use crate::pipeline::optical_flow::FlowField;

/// Colour of a NaN pixel: grey, fully transparent.
pub const NAN_RGBA: [u8; 4] = [128, 128, 128, 0];
/// In-focus pixels in two or more windows.
pub const DISCARDED_RGBA: [u8; 4] = [255, 40, 40, 255];
/// In-focus pixels in no window.
pub const UNASSIGNED_RGBA: [u8; 4] = [170, 170, 170, 255];
/// Measured columns of a centroid line.
pub const LINE_RGBA: [u8; 4] = [255, 255, 255, 255];
/// Filled (void) columns of a centroid line.
pub const FILLED_RGBA: [u8; 4] = [255, 0, 255, 255];
/// Window box of a kept Hough peak.
pub const WINDOW_RGBA: [u8; 4] = [0, 255, 255, 255];
/// Window box of the dropped Hough peak.
pub const DROPPED_WINDOW_RGBA: [u8; 4] = [150, 150, 150, 255];
/// Peak centre marks in the Hough image.
pub const PEAK_RGBA: [u8; 4] = [0, 255, 0, 255];
/// One colour per stripe region (index into the peaks, repeating).
pub const REGION_RGBA: [[u8; 4]; 3] = [[0, 200, 80, 255], [60, 140, 255, 255], [255, 200, 0, 255]];
/// How bright the frame behind the segmentation overlay is (0–1).
const OVERLAY_BACKGROUND_GAIN: f32 = 0.6;
/// Half-length of the peak cross in the Hough image (bins).
const PEAK_MARK_ARM: isize = 2;

/// An 8-bit RGBA raster, row-major, 4 bytes per pixel (straight alpha).
#[derive(Clone, Debug, PartialEq, Eq, Default)]
pub struct Rgba8Image {
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// `width * height * 4` bytes: R, G, B, A per pixel.
    pub pixels: Vec<u8>,
}

impl Rgba8Image {
    /// An image with every pixel set to `rgba`.
    #[must_use]
    pub fn filled(width: usize, height: usize, rgba: [u8; 4]) -> Self {
        Self {
            width,
            height,
            pixels: rgba.repeat(width * height),
        }
    }

    /// The pixel at `(x, y)`, or `None` outside.
    #[must_use]
    pub fn get(&self, x: usize, y: usize) -> Option<[u8; 4]> {
        if x >= self.width || y >= self.height {
            return None;
        }
        let i = (y * self.width + x) * 4;
        let p = self.pixels.get(i..i + 4)?;
        Some([p[0], p[1], p[2], p[3]])
    }

    /// Sets the pixel at `(x, y)`; coordinates outside are ignored (drawing clips).
    pub fn set(&mut self, x: isize, y: isize, rgba: [u8; 4]) {
        if x < 0 || y < 0 || x as usize >= self.width || y as usize >= self.height {
            return;
        }
        let i = (y as usize * self.width + x as usize) * 4;
        if let Some(p) = self.pixels.get_mut(i..i + 4) {
            p.copy_from_slice(&rgba);
        }
    }

    /// Draws the outline of the rectangle with corners `(x0, y0)` and `(x1, y1)` (inclusive), clipped.
    pub fn draw_rect(&mut self, x0: isize, y0: isize, x1: isize, y1: isize, rgba: [u8; 4]) {
        let (xa, xb) = (x0.min(x1), x0.max(x1));
        let (ya, yb) = (y0.min(y1), y0.max(y1));
        let w = self.width as isize;
        let h = self.height as isize;
        for x in xa.max(-1)..=xb.min(w) {
            self.set(x, ya, rgba);
            self.set(x, yb, rgba);
        }
        for y in ya.max(-1)..=yb.min(h) {
            self.set(xa, y, rgba);
            self.set(xb, y, rgba);
        }
    }

    /// Draws a vertical run from row `y0` to `y1` (inclusive) in column `x`, clipped.
    pub fn draw_vspan(&mut self, x: isize, y0: isize, y1: isize, rgba: [u8; 4]) {
        let h = self.height as isize;
        for y in y0.min(y1).max(-1)..=y0.max(y1).min(h) {
            self.set(x, y, rgba);
        }
    }
}

/// A perceptual colour map.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum ColorMap {
    /// Dark blue -> green -> yellow.
    #[default]
    Viridis,
    /// Black -> purple -> orange -> pale yellow.
    Inferno,
}

/// Degree-6 polynomial fits of matplotlib's maps (Matt Zucker's CC0 fits), per channel, constant first.
const VIRIDIS_POLY: [[f32; 3]; 7] = [
    [0.277_727_33, 0.005_407_344_5, 0.334_099_8],
    [0.105_093_04, 1.404_613_5, 1.384_590_2],
    [-0.330_861_83, 0.214_847_56, 0.095_095_16],
    [-4.634_230_5, -5.799_101, -19.332_441],
    [6.228_27, 14.179_933, 56.690_55],
    [4.776_385, -13.745_145, -65.353_03],
    [-5.435_456, 4.645_852_6, 26.312_435],
];
const INFERNO_POLY: [[f32; 3]; 7] = [
    [0.000_218_940_37, 0.001_651_004_6, -0.019_480_898],
    [0.106_513_42, 0.563_956_4, 3.932_712_4],
    [11.602_493, -3.972_854, -15.942_394],
    [-41.703_996, 17.436_4, 44.354_145],
    [77.162_94, -33.402_36, -81.807_31],
    [-71.319_43, 32.626_064, 73.209_52],
    [25.131_126, -12.242_669, -23.070_325],
];

impl ColorMap {
    /// Colour of `t` in [0, 1] (clamped; NaN gives [`NAN_RGBA`]).
    #[must_use]
    pub fn rgba(self, t: f32) -> [u8; 4] {
        if !t.is_finite() {
            return NAN_RGBA;
        }
        let t = t.clamp(0.0, 1.0);
        let poly = match self {
            Self::Viridis => &VIRIDIS_POLY,
            Self::Inferno => &INFERNO_POLY,
        };
        let mut out = [0u8, 0, 0, 255];
        for (ch, o) in out.iter_mut().take(3).enumerate() {
            let v = poly.iter().rev().fold(0.0_f32, |acc, c| acc * t + c[ch]);
            *o = to_u8(v);
        }
        out
    }
}

fn to_u8(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// Maps `v` into [0, 1] over `(lo, hi)`; a flat range maps to 0.5.
fn normalise(v: f32, lo: f32, hi: f32) -> f32 {
    if hi > lo { (v - lo) / (hi - lo) } else { 0.5 }
}

/// A grey image with its finite range stretched to black..white; NaN as [`NAN_RGBA`].
#[must_use]
pub fn grey_image(img: &Image) -> Rgba8Image {
    let (lo, hi) = img.finite_range().unwrap_or((0.0, 1.0));
    let mut pixels = Vec::with_capacity(img.data.len() * 4);
    for &v in &img.data {
        if v.is_finite() {
            let g = to_u8(normalise(v, lo, hi));
            pixels.extend_from_slice(&[g, g, g, 255]);
        } else {
            pixels.extend_from_slice(&NAN_RGBA);
        }
    }
    Rgba8Image {
        width: img.width,
        height: img.height,
        pixels,
    }
}

/// A heat map over `range` (`None`: the image's finite range); NaN as [`NAN_RGBA`].
#[must_use]
pub fn heat_map(img: &Image, range: Option<(f32, f32)>, map: ColorMap) -> Rgba8Image {
    let (lo, hi) = range.or_else(|| img.finite_range()).unwrap_or((0.0, 1.0));
    let mut pixels = Vec::with_capacity(img.data.len() * 4);
    for &v in &img.data {
        let c = if v.is_finite() {
            map.rgba(normalise(v, lo, hi))
        } else {
            NAN_RGBA
        };
        pixels.extend_from_slice(&c);
    }
    Rgba8Image {
        width: img.width,
        height: img.height,
        pixels,
    }
}

/// Most values sampled by [`robust_range`].
const RANGE_SAMPLES: usize = 65_536;

/// Share of values left out at each end by [`robust_range`].
pub const ROBUST_TAIL: f64 = 0.01;

/// The range between the [`ROBUST_TAIL`] and 1 − [`ROBUST_TAIL`] quantiles of the finite values
/// (sampled), so a few outliers do not flatten a heat map.
#[must_use]
pub fn robust_range(values: &[f32]) -> Option<(f32, f32)> {
    crate::pipeline::sampled_quantiles(values, ROBUST_TAIL, 1.0 - ROBUST_TAIL, RANGE_SAMPLES)
}

/// The Middlebury colour wheel (55 hues: red, yellow, green, cyan, blue, magenta).
fn color_wheel() -> Vec<[f32; 3]> {
    const SEGMENTS: [usize; 6] = [15, 6, 4, 11, 13, 6];
    let mut wheel = Vec::with_capacity(SEGMENTS.iter().sum());
    for (seg, &n) in SEGMENTS.iter().enumerate() {
        for i in 0..n {
            let ramp = (255 * i / n) as f32;
            let c = match seg {
                0 => [255.0, ramp, 0.0],
                1 => [255.0 - ramp, 255.0, 0.0],
                2 => [0.0, 255.0, ramp],
                3 => [0.0, 255.0 - ramp, 255.0],
                4 => [ramp, 0.0, 255.0],
                _ => [255.0, 0.0, 255.0 - ramp],
            };
            wheel.push(c);
        }
    }
    wheel
}

/// Middlebury colour of a flow vector already divided by the maximum magnitude (|(u, v)| ≤ 1 for
/// full saturation; larger vectors are darkened). (0, 0) is white; +x is red; NaN gives [`NAN_RGBA`].
#[must_use]
pub fn flow_color(u: f32, v: f32) -> [u8; 4] {
    flow_color_with(&color_wheel(), u, v)
}

fn flow_color_with(wheel: &[[f32; 3]], u: f32, v: f32) -> [u8; 4] {
    if !(u.is_finite() && v.is_finite()) || wheel.is_empty() {
        return NAN_RGBA;
    }
    let n = wheel.len();
    let rad = u.hypot(v);
    let a = (-v).atan2(-u) / std::f32::consts::PI;
    let fk = (a + 1.0) * 0.5 * (n - 1) as f32;
    let k0 = (fk.floor() as usize).min(n - 1);
    let k1 = (k0 + 1) % n;
    let f = fk - k0 as f32;
    let mut out = [0u8, 0, 0, 255];
    for (ch, o) in out.iter_mut().take(3).enumerate() {
        let mut col = ((1.0 - f) * wheel[k0][ch] + f * wheel[k1][ch]) / 255.0;
        if rad <= 1.0 {
            col = 1.0 - rad * (1.0 - col);
        } else {
            col *= 0.75;
        }
        *o = to_u8(col);
    }
    out
}

/// The flow as a Middlebury colour image, after subtracting `subtract_u_px` from u (pass the land
/// flow to see the residual, or 0), scaled so the largest finite magnitude is fully saturated.
#[must_use]
pub fn flow_image(flow: &FlowField, subtract_u_px: f32) -> Rgba8Image {
    let (u, v) = (&flow.u, &flow.v);
    let max = u
        .data
        .iter()
        .zip(&v.data)
        .map(|(&a, &b)| (a - subtract_u_px).hypot(b))
        .filter(|m| m.is_finite())
        .fold(0.0_f32, f32::max);
    let scale = if max > 0.0 { 1.0 / max } else { 1.0 };
    let wheel = color_wheel();
    let mut pixels = Vec::with_capacity(u.data.len() * 4);
    for (&a, &b) in u.data.iter().zip(&v.data) {
        pixels.extend_from_slice(&flow_color_with(
            &wheel,
            (a - subtract_u_px) * scale,
            b * scale,
        ));
    }
    pixels.resize(u.width * u.height * 4, 0);
    Rgba8Image {
        width: u.width,
        height: u.height,
        pixels,
    }
}

/// The Hough accumulator as a log-scaled inferno heat map (x = θ bin, y = ρ bin, so ρ grows
/// downward like image rows), with each peak's window drawn as a box (the `dropped` one in grey)
/// and a cross on each peak.
#[must_use]
pub fn hough_image(acc: &Accumulator, peaks: &[Peak], dropped: Option<usize>) -> Rgba8Image {
    let (nt, nr) = (acc.theta_bins(), acc.rho_bins);
    let max = acc.votes.iter().copied().max().unwrap_or(0);
    let log_max = (1.0 + max as f32).ln();
    let mut img = Rgba8Image::filled(nt, nr, [0, 0, 0, 255]);
    for t in 0..nt {
        for r in 0..nr {
            let v = acc.get(t, r);
            let x = if log_max > 0.0 {
                (1.0 + v as f32).ln() / log_max
            } else {
                0.0
            };
            img.set(t as isize, r as isize, ColorMap::Inferno.rgba(x));
        }
    }
    let theta_step = match (acc.thetas_rad.first(), acc.thetas_rad.get(1)) {
        (Some(a), Some(b)) if b > a => b - a,
        _ => 1.0,
    };
    for (k, p) in peaks.iter().enumerate() {
        let tc = acc.theta_bin_f(p.theta_rad);
        let rc = acc.rho_bin_f(p.rho_px);
        let ht = p.window_theta_rad / theta_step;
        let hr = p.window_rho_px / acc.rho_step_px;
        let colour = if dropped == Some(k) {
            DROPPED_WINDOW_RGBA
        } else {
            WINDOW_RGBA
        };
        img.draw_rect(
            (tc - ht).round() as isize,
            (rc - hr).round() as isize,
            (tc + ht).round() as isize,
            (rc + hr).round() as isize,
            colour,
        );
        let (ti, ri) = (tc.round() as isize, rc.round() as isize);
        for d in -PEAK_MARK_ARM..=PEAK_MARK_ARM {
            img.set(ti + d, ri, PEAK_RGBA);
            img.set(ti, ri + d, PEAK_RGBA);
        }
    }
    img
}

/// The segmentation over the (dimmed, auto-ranged) frame: one colour per region
/// ([`REGION_RGBA`]), discarded pixels red, unassigned grey, then the centroid lines (measured
/// columns white, filled voids magenta). The output has the size of `stripes.in_focus`.
#[must_use]
pub fn stripes_overlay(frame: &Image, stripes: &Stripes) -> Rgba8Image {
    let (w, h) = (stripes.in_focus.width, stripes.in_focus.height);
    let (lo, hi) = frame.finite_range().unwrap_or((0.0, 1.0));
    let mut img = Rgba8Image::filled(w, h, [0, 0, 0, 255]);
    for y in 0..h {
        for x in 0..w {
            let l = stripes.label_at(x, y);
            let c = match l {
                label::DISCARDED => DISCARDED_RGBA,
                label::UNASSIGNED => UNASSIGNED_RGBA,
                k if k >= 0 => REGION_RGBA[k as usize % REGION_RGBA.len()],
                _ => match frame.get(x, y) {
                    Some(v) if v.is_finite() => {
                        let g = to_u8(normalise(v, lo, hi) * OVERLAY_BACKGROUND_GAIN);
                        [g, g, g, 255]
                    }
                    _ => NAN_RGBA,
                },
            };
            img.set(x as isize, y as isize, c);
        }
    }
    for line in &stripes.lines {
        let mut prev: Option<isize> = None;
        for (x, &row) in line.rows.iter().enumerate() {
            if !row.is_finite() {
                prev = None;
                continue;
            }
            let r = row.round() as isize;
            let colour = if line.filled.get(x).copied().unwrap_or(false) {
                FILLED_RGBA
            } else {
                LINE_RGBA
            };
            // Join to the previous column so steep lines stay connected.
            let from = prev.map_or(r, |p| {
                if p < r {
                    (p + 1).min(r)
                } else {
                    (p - 1).max(r)
                }
            });
            img.draw_vspan(x as isize, from, r, colour);
            prev = Some(r);
        }
    }
    img
}

/// The borders' colours, in [`crate::pipeline::edges::BorderId`] order: each land border warm,
/// each bottom border cool.
pub const BORDER_RGBA: [[u8; 4]; 4] = [
    [255, 170, 40, 255],
    [0, 200, 80, 255],
    [60, 140, 255, 255],
    [235, 90, 235, 255],
];

/// Where a border's fine fit lies on the reference frame, per sample: the column (the mean of
/// the sample's columns by their weights) and the row, pixel centres at `+ 0.5`; None where
/// the sample has no fit.
#[must_use]
pub fn border_fit_points(track: &BorderTrack) -> Vec<Option<[f64; 2]>> {
    track
        .fits
        .iter()
        .map(|f| {
            let f = f.as_ref()?;
            let (sum, weight) = f
                .column_weights
                .iter()
                .fold((0.0, 0.0), |(s, w), &(x, cw)| {
                    (s + x as f64 * f64::from(cw), w + f64::from(cw))
                });
            (weight > 0.0 && f.row_px.is_finite()).then(|| [sum / weight + 0.5, f.row_px + 0.5])
        })
        .collect()
}

/// The frame the borders were read on (auto-ranged grey) with a 3 × 3 dot at each sample's
/// fitted border, one colour a border ([`BORDER_RGBA`]).
#[must_use]
pub fn edges_overlay(frame: &Image, edges: &Edges) -> Rgba8Image {
    let mut img = grey_image(frame);
    for track in &edges.borders {
        let colour = BORDER_RGBA[track.id as usize % BORDER_RGBA.len()];
        for [x, y] in border_fit_points(track).into_iter().flatten() {
            let (cx, cy) = (x.floor() as isize, y.floor() as isize);
            for dy in -1..=1 {
                for dx in -1..=1 {
                    img.set(cx + dx, cy + dy, colour);
                }
            }
        }
    }
    img
}

/// Writes `img` as an 8-bit RGBA PNG, atomically.
///
/// # Errors
/// [`LoadError::Io`] naming the file when the buffer does not match the size, the file exists
/// (without `overwrite`) or the write fails.
pub fn save_png(img: &Rgba8Image, path: &Path, overwrite: bool) -> Result<(), LoadError> {
    let (Ok(w), Ok(h)) = (u32::try_from(img.width), u32::try_from(img.height)) else {
        return Err(LoadError::Io {
            problem: "image too large for PNG".into(),
            path: path.to_path_buf(),
        });
    };
    if img.pixels.len() != img.width * img.height * 4 || img.width == 0 || img.height == 0 {
        return Err(LoadError::Io {
            problem: format!(
                "RGBA buffer of {} bytes does not match {}×{}",
                img.pixels.len(),
                img.width,
                img.height
            ),
            path: path.to_path_buf(),
        });
    }
    write_atomic_with(path, overwrite, |wr| {
        image::codecs::png::PngEncoder::new(wr)
            .write_image(&img.pixels, w, h, image::ExtendedColorType::Rgba8)
            .map_err(std::io::Error::other)
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // Tests may panic on a broken expectation.
mod tests {
    use super::*;
    use crate::pipeline::walls::{WallLine, WallSide};

    fn close(a: [u8; 4], b: [u8; 4], tol: u8) -> bool {
        a.iter().zip(&b).all(|(x, y)| x.abs_diff(*y) <= tol)
    }

    #[test]
    fn robust_range_ignores_a_few_outliers() {
        let mut v: Vec<f32> = (0..1000).map(|i| 4000.0 + (i % 50) as f32).collect();
        v[3] = 1e6;
        v[9] = -1e6;
        v[11] = f32::NAN;
        let (lo, hi) = robust_range(&v).unwrap();
        assert!((4000.0..=4001.0).contains(&lo), "{lo}");
        assert!((4048.0..=4049.0).contains(&hi), "{hi}");
        assert!(robust_range(&[f32::NAN]).is_none());
    }

    #[test]
    fn colour_maps_hit_their_known_ends() {
        // matplotlib: viridis(0) = #440154, viridis(1) = #fde725, inferno(0) = #000004, inferno(1) = #fcffa4.
        assert!(close(ColorMap::Viridis.rgba(0.0), [68, 1, 84, 255], 4));
        assert!(close(ColorMap::Viridis.rgba(1.0), [253, 231, 37, 255], 4));
        assert!(close(ColorMap::Viridis.rgba(0.5), [33, 145, 140, 255], 4));
        assert!(close(ColorMap::Inferno.rgba(0.0), [0, 0, 4, 255], 4));
        assert!(close(ColorMap::Inferno.rgba(1.0), [252, 255, 164, 255], 6));
        assert_eq!(ColorMap::Viridis.rgba(f32::NAN), NAN_RGBA);
    }

    #[test]
    fn grey_and_heat_have_the_input_size_and_range() {
        let mut im = Image::from_fn(5, 3, |x, _| x as f32);
        im.data[7] = f32::NAN;
        let g = grey_image(&im);
        assert_eq!((g.width, g.height, g.pixels.len()), (5, 3, 60));
        assert_eq!(g.get(0, 0), Some([0, 0, 0, 255]));
        assert_eq!(g.get(4, 0), Some([255, 255, 255, 255]));
        assert_eq!(g.get(2, 1), Some(NAN_RGBA));
        let hm = heat_map(&im, None, ColorMap::Viridis);
        assert_eq!(hm.get(4, 2), Some(ColorMap::Viridis.rgba(1.0)));
        assert_eq!(hm.get(2, 1), Some(NAN_RGBA));
    }

    #[test]
    fn flow_wheel_colours() {
        assert_eq!(flow_color(0.0, 0.0), [255, 255, 255, 255]);
        // +x is red (the wheel wraps from magenta-red to red there), -x the cyan-blue opposite.
        assert_eq!(flow_color(1.0, 0.0), [255, 0, 0, 255]);
        assert!(close(flow_color(0.0, -1.0), [88, 0, 255, 255], 1));
        assert!(close(flow_color(0.0, 1.0), [255, 230, 0, 255], 1));
        // Longer than the scale: darkened to 3/4.
        assert_eq!(flow_color(2.0, 0.0), [191, 0, 0, 255]);
        assert!(close(flow_color(-1.0, 0.0), [0, 209, 255, 255], 1));
        assert_eq!(flow_color(f32::NAN, 0.0), NAN_RGBA);
        let z = Image::zeros(4, 2);
        let flow = FlowField {
            u: Image::from_fn(4, 2, |x, _| -2.0 + x as f32 * 0.1),
            v: z.clone(),
            confidence: z,
            iterations: 0,
            converged: true,
            frame_index: 0,
        };
        let img = flow_image(&flow, -2.0);
        assert_eq!((img.width, img.height, img.pixels.len()), (4, 2, 32));
        assert_eq!(img.get(0, 0), Some([255, 255, 255, 255]));
        assert_eq!(img.get(3, 1), Some([255, 0, 0, 255]));
    }

    fn tiny_stripes() -> Stripes {
        let acc = Accumulator {
            thetas_rad: (0..5).map(|t| (t as f32 - 2.0).to_radians()).collect(),
            rho_min_px: 0.0,
            rho_step_px: 1.0,
            rho_bins: 20,
            votes: (0..100)
                .map(|i| if i == 2 * 20 + 10 { 50 } else { 1 })
                .collect(),
            x_origin_px: 4.5,
            vote_stride: 1,
        };
        let peak = Peak {
            theta_rad: 0.0,
            rho_px: 10.0,
            votes: 50,
            x_origin_px: 4.5,
            window_theta_rad: 1f32.to_radians(),
            window_rho_px: 3.0,
        };
        let mut labels = vec![label::NONE; 10 * 20];
        labels[10 * 10 + 3] = 0;
        labels[10 * 10 + 4] = label::DISCARDED;
        labels[10 * 10 + 5] = label::UNASSIGNED;
        Stripes {
            in_focus: Image::zeros(10, 20),
            accumulator: acc,
            peaks: vec![peak],
            labels,
            dropped: 0,
            lines: vec![WallLine {
                side: WallSide::Right,
                rows: vec![5.0; 10],
                half_width_px: vec![1.0; 10],
                depth_um: None,
                projection_depth_um: None,
                filled: (0..10).map(|x| x >= 8).collect(),
            }],
            line_peaks: vec![0],
        }
    }

    #[test]
    fn hough_image_marks_peaks_and_windows() {
        let s = tiny_stripes();
        let img = hough_image(&s.accumulator, &s.peaks, None);
        assert_eq!((img.width, img.height), (5, 20));
        assert_eq!(img.get(2, 10), Some(PEAK_RGBA));
        // The window box spans θ bins 1..=3, ρ bins 7..=13.
        assert_eq!(img.get(1, 7), Some(WINDOW_RGBA));
        assert_eq!(img.get(3, 13), Some(WINDOW_RGBA));
        // Away from marks: the log heat map (1 vote of 50 max).
        let expect = ColorMap::Inferno.rgba(2f32.ln() / 51f32.ln());
        assert_eq!(img.get(0, 0), Some(expect));
        let dimmed = hough_image(&s.accumulator, &s.peaks, Some(0));
        assert_eq!(dimmed.get(1, 7), Some(DROPPED_WINDOW_RGBA));
    }

    #[test]
    fn overlay_colours_labels_and_lines() {
        let s = tiny_stripes();
        let frame = Image::from_fn(10, 20, |x, _| x as f32);
        let img = stripes_overlay(&frame, &s);
        assert_eq!((img.width, img.height), (10, 20));
        assert_eq!(img.get(3, 10), Some(REGION_RGBA[0]));
        assert_eq!(img.get(4, 10), Some(DISCARDED_RGBA));
        assert_eq!(img.get(5, 10), Some(UNASSIGNED_RGBA));
        assert_eq!(img.get(2, 5), Some(LINE_RGBA));
        assert_eq!(img.get(9, 5), Some(FILLED_RGBA));
        assert_eq!(img.get(9, 0), Some([153, 153, 153, 255]));
    }

    #[test]
    fn png_round_trips_and_respects_overwrite() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("v.png");
        let mut img = Rgba8Image::filled(3, 2, [10, 20, 30, 255]);
        img.set(2, 1, [1, 2, 3, 4]);
        save_png(&img, &p, false).unwrap();
        let back = image::open(&p).unwrap().to_rgba8();
        assert_eq!(back.dimensions(), (3, 2));
        assert_eq!(back.as_raw(), &img.pixels);
        assert!(save_png(&img, &p, false).is_err());
        save_png(&img, &p, true).unwrap();
        let broken = Rgba8Image {
            width: 3,
            height: 2,
            pixels: vec![0; 5],
        };
        assert!(save_png(&broken, &dir.path().join("b.png"), true).is_err());
    }
}
