//! Renders a [`StillScene`] as a grey image: exact area coverage of land, rims, walls and
//! bottoms, surface texture, dust, uneven light, blur, sensor noise, burnt-in text, quantisation.
//!
//! Rendering runs line by line along the grooves (in parallel; every random value comes from a
//! hash of the seed and its position, so the image does not depend on the threads). Each line is
//! averaged over `SUB_LINES` sub-lines; within a sub-line every material's share of a pixel is
//! its exact overlap with the pixel.

use rayon::prelude::*;

use crate::image::Image;
use crate::pipeline::still::Axis;
use crate::synth::blur::gaussian_blur;
use crate::synth::noise::{Rng, fbm3, hash_seq};

use super::font::text_mask;
use super::scene::StillScene;

/// Sub-lines averaged per image line.
const SUB_LINES: usize = 4;
/// Salts of the random streams.
const TEXTURE_SALT: u64 = 0x5711_0101;
/// See [`TEXTURE_SALT`].
const DUST_SALT: u64 = 0x5711_0102;
/// See [`TEXTURE_SALT`].
const LIGHT_SALT: u64 = 0x5711_0103;
/// See [`TEXTURE_SALT`].
const NOISE_SALT: u64 = 0x5711_0104;
/// Share of dust particles that are fibres rather than specks.
const FIBRE_SHARE: f64 = 0.1;
/// Longest fibre, px.
const FIBRE_MAX_LEN_PX: f64 = 60.0;
/// Darkest and brightest dust level.
const DUST_LEVELS: (f64, f64) = (0.85, 1.0);
/// Grey level of burnt-in text and its scale bar, and of their drop shadow.
const TEXT_LEVELS: (f32, f32) = (1.0, 0.0);
/// Length of the burnt-in scale bar, µm.
const SCALE_BAR_UM: f64 = 100.0;
/// Texture octaves.
const TEXTURE_OCTAVES: u32 = 2;

/// A rendered still and what was put into it.
#[derive(Clone, Debug)]
pub struct StillImage {
    /// The image (rows × columns as the file has them), quantised to its bit depth, in [0, 1].
    pub image: Image,
    /// Dust particles laid.
    pub dust_particles: usize,
    /// Box of the burnt-in text and scale bar `[x0, y0, x1, y1]` (image pixels, exclusive end).
    pub text_box: Option<[usize; 4]>,
}

/// One dust particle: a disc, or a fibre (a thin segment), in (line, cross) pixel coordinates.
struct Dust {
    line: f64,
    cross: f64,
    radius_px: f64,
    /// Fibre direction and length (0 for a speck).
    dir: (f64, f64),
    len_px: f64,
    level: f64,
}

impl Dust {
    /// Distance of a pixel centre from the particle's core (its centre or its segment).
    fn distance(&self, line: f64, cross: f64) -> f64 {
        let (dl, dc) = (line - self.line, cross - self.cross);
        if self.len_px <= 0.0 {
            return dl.hypot(dc);
        }
        let t = (dl * self.dir.0 + dc * self.dir.1).clamp(0.0, self.len_px);
        (dl - t * self.dir.0).hypot(dc - t * self.dir.1)
    }
}

/// Adds `level` over `[a, b)` (pixel-edge coordinates) to the pixels of `acc` it covers.
fn add_segment(acc: &mut [f64], a: f64, b: f64, level: f64) {
    let n = acc.len() as f64;
    let (a, b) = (a.max(0.0), b.min(n));
    if b <= a {
        return;
    }
    let first = a.floor() as usize;
    let last = (b.ceil() as usize).min(acc.len());
    for (m, v) in acc.iter_mut().enumerate().take(last).skip(first) {
        let lo = a.max(m as f64);
        let hi = b.min(m as f64 + 1.0);
        if hi > lo {
            *v += level * (hi - lo);
        }
    }
}

/// The surface of one line (land, rims, walls, bottoms; no texture yet), one value per cross pixel.
fn surface_line(scene: &StillScene, line: usize, out: &mut [f64]) {
    let c = &scene.cfg;
    let p = c.um_per_px;
    let rim_w = c.rim_width_um / p;
    let n = out.len() as f64;
    out.fill(0.0);
    let weight = 1.0 / SUB_LINES as f64;
    for j in 0..SUB_LINES {
        let y = (line as f64 + (j as f64 + 0.5) / SUB_LINES as f64) * p;
        let mut land_from = f64::NEG_INFINITY;
        for (k, g) in scene.grooves.iter().enumerate() {
            let b = scene.borders_um(k, y).map(|x| x / p);
            let rim_lo = if g.rims[0] {
                (b[0] - rim_w).max(land_from)
            } else {
                b[0]
            };
            add_segment(out, land_from.max(-1.0), rim_lo, c.land_level * weight);
            add_segment(out, rim_lo, b[0], c.rim_level * weight);
            add_segment(out, b[0], b[1], g.wall_levels[0] * weight);
            add_segment(out, b[1], b[2], c.bottom_level * weight);
            add_segment(out, b[2], b[3], g.wall_levels[1] * weight);
            land_from = b[3];
            if g.rims[1] {
                let next = scene.borders_um(k + 1, y)[0] / p;
                let end = if next.is_finite() {
                    (b[3] + rim_w).min(next)
                } else {
                    b[3] + rim_w
                };
                add_segment(out, b[3], end, c.rim_level * weight);
                land_from = end;
            }
        }
        add_segment(out, land_from.max(-1.0), n + 1.0, c.land_level * weight);
    }
}

/// Lays the dust particles (seeded), in (line, cross) pixel coordinates.
fn lay_dust(scene: &StillScene) -> Vec<Dust> {
    let c = &scene.cfg;
    let mut rng = Rng::new(hash_seq(u64::from(c.seed), &[DUST_SALT]));
    let mpx = (c.length_px * c.across_px) as f64 / 1e6;
    let count = rng.poisson(c.dust_per_mpx * mpx);
    (0..count)
        .map(|_| {
            let line = rng.range(0.0, c.length_px as f64);
            let cross = rng.range(0.0, c.across_px as f64);
            let fibre = rng.uniform() < FIBRE_SHARE;
            let u = rng.uniform();
            let radius_px = if fibre {
                0.6
            } else {
                0.6 + (c.dust_max_radius_px - 0.6).max(0.0) * u * u
            };
            let ang = rng.range(0.0, std::f64::consts::TAU);
            let len_px = if fibre {
                rng.range(10.0, FIBRE_MAX_LEN_PX)
            } else {
                0.0
            };
            Dust {
                line,
                cross,
                radius_px,
                dir: (ang.cos(), ang.sin()),
                len_px,
                level: rng.range(DUST_LEVELS.0, DUST_LEVELS.1),
            }
        })
        .collect()
}

/// Covers the line-major buffer (`across` values per line) with the dust.
fn draw_dust(buf: &mut [f64], across: usize, dust: &[Dust]) {
    let lines = buf.len() / across.max(1);
    for d in dust {
        let reach = d.radius_px + d.len_px + 1.5;
        let l0 = (d.line - reach).floor().max(0.0) as usize;
        let l1 = ((d.line + reach).ceil().max(0.0) as usize).min(lines);
        let c0 = (d.cross - reach).floor().max(0.0) as usize;
        let c1 = ((d.cross + reach).ceil().max(0.0) as usize).min(across);
        for l in l0..l1 {
            for m in c0..c1 {
                let dist = d.distance(l as f64 + 0.5, m as f64 + 0.5);
                let a = (d.radius_px + 0.5 - dist).clamp(0.0, 1.0);
                if a > 0.0 {
                    let v = &mut buf[l * across + m];
                    *v = *v * (1.0 - a) + d.level * a;
                }
            }
        }
    }
}

/// The uneven light at a pixel: about 1 ± `unevenness` (a cross gradient and a slow fBm field).
fn light(scene: &StillScene, gradient: f64, line: usize, m: usize) -> f64 {
    let c = &scene.cfg;
    let u = c.illumination_unevenness;
    if u <= 0.0 {
        return 1.0;
    }
    let scale = c.across_px as f64;
    let xn = 2.0 * (m as f64 + 0.5) / c.across_px as f64 - 1.0;
    let f = fbm3(
        [m as f64 / scale, line as f64 / scale, 0.5],
        3,
        hash_seq(u64::from(c.seed), &[LIGHT_SALT]),
    );
    1.0 + u * (1.4 * f + 0.5 * gradient * xn).clamp(-1.0, 1.0)
}

/// Renders the still. Deterministic: same scene, same pixels.
#[must_use]
pub fn render_still(scene: &StillScene) -> StillImage {
    let c = &scene.cfg;
    let (lines, across) = (c.length_px, c.across_px);
    let p = c.um_per_px;
    let tex_seed = hash_seq(u64::from(c.seed), &[TEXTURE_SALT]);
    let gradient = 2.0 * Rng::new(hash_seq(u64::from(c.seed), &[LIGHT_SALT])).uniform() - 1.0;
    let mut buf = vec![0.0f64; lines * across];
    buf.par_chunks_mut(across).enumerate().for_each_init(
        || vec![0.0f64; across],
        |surf, (line, row)| {
            surface_line(scene, line, surf);
            for (m, (v, s)) in row.iter_mut().zip(surf.iter()).enumerate() {
                let t = if c.texture > 0.0 {
                    let q = [
                        (m as f64 + 0.5) * p / c.texture_scale_um,
                        (line as f64 + 0.5) * p / c.texture_scale_um,
                        0.0,
                    ];
                    1.0 + c.texture * fbm3(q, TEXTURE_OCTAVES, tex_seed)
                } else {
                    1.0
                };
                *v = s * t;
            }
        },
    );
    let dust = lay_dust(scene);
    draw_dust(&mut buf, across, &dust);
    buf.par_chunks_mut(across)
        .enumerate()
        .for_each(|(line, row)| {
            for (m, v) in row.iter_mut().enumerate() {
                *v *= light(scene, gradient, line, m);
            }
        });
    let mut img = Image {
        width: across,
        height: lines,
        data: buf.iter().map(|&v| v as f32).collect(),
    };
    drop(buf);
    if c.blur_sigma_px > 0.0 {
        img = gaussian_blur(&img, c.blur_sigma_px);
    }
    if c.noise_sigma > 0.0 {
        img.data
            .par_chunks_mut(across)
            .enumerate()
            .for_each(|(line, row)| {
                let mut rng = Rng::new(hash_seq(u64::from(c.seed), &[NOISE_SALT, line as u64]));
                for v in row.iter_mut() {
                    *v += (c.noise_sigma * rng.gaussian()) as f32;
                }
            });
    }
    if c.axis == Axis::Horizontal {
        img = transpose(&img);
    }
    let text_box = burn_text(scene, &mut img);
    let levels = if c.bit_depth == 16 { 65535.0 } else { 255.0 };
    for v in &mut img.data {
        *v = (v.clamp(0.0, 1.0) * levels).round() / levels;
    }
    StillImage {
        image: img,
        dust_particles: dust.len(),
        text_box,
    }
}

fn transpose(img: &Image) -> Image {
    let (w, h) = (img.width, img.height);
    let mut out = vec![0.0f32; w * h];
    out.par_chunks_mut(h).enumerate().for_each(|(x, row)| {
        for (y, v) in row.iter_mut().enumerate() {
            *v = img.data[y * w + x];
        }
    });
    Image {
        width: h,
        height: w,
        data: out,
    }
}

/// Burns the text and a scale bar into the lower left corner (with a one-pixel drop shadow)
/// and returns their box.
fn burn_text(scene: &StillScene, img: &mut Image) -> Option<[usize; 4]> {
    let c = &scene.cfg;
    if c.text.is_empty() || c.text_height_px == 0 {
        return None;
    }
    let scale = (c.text_height_px / 7).max(1);
    let (tw, th, mask) = text_mask(&c.text, scale);
    let bar_w = (SCALE_BAR_UM / c.um_per_px).round() as usize;
    let bar_h = (th / 3).max(1);
    let gap = 3 * scale;
    let margin_x = img.width / 50 + 2;
    let margin_y = img.height / 50 + 2;
    let x0 = margin_x;
    let y0 = img.height.checked_sub(margin_y + th)?;
    let w = tw + gap + bar_w;
    let mut pixels = Vec::new();
    for ty in 0..th {
        for tx in 0..tw {
            if mask[ty * tw + tx] {
                pixels.push((x0 + tx, y0 + ty));
            }
        }
    }
    for by in 0..bar_h {
        for bx in 0..bar_w {
            pixels.push((x0 + tw + gap + bx, y0 + th - bar_h + by));
        }
    }
    // The shadow first, so it never covers the ink.
    for (d, level) in [(1, TEXT_LEVELS.1), (0, TEXT_LEVELS.0)] {
        for &(x, y) in &pixels {
            let (px, py) = (x + d, y + d);
            if px < img.width && py < img.height {
                img.data[py * img.width + px] = level;
            }
        }
    }
    Some([
        x0,
        y0,
        (x0 + w + 1).min(img.width),
        (y0 + th + 1).min(img.height),
    ])
}
