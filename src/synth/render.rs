//! The microscope camera: per-pixel rays (through the cover glass where there is one) intersected
//! exactly with the groove height field, shaded, defocus-blurred, noised and quantised.

use rayon::prelude::*;

use super::blur::{BLUR_LEVELS_PX, BlurStack};
use super::groove::{Groove, RAY_MAX_ITERATIONS, RAY_TOLERANCE_UM};
use super::noise::{Rng, hash_seq};
use crate::image::Image;

/// Gaussian σ of the defocus blur per unit of geometric blur radius NA·|ΔZ| (a disc of radius R
/// is close to a Gaussian of σ = R/2).
pub const DOF_SIGMA_PER_BLUR_RADIUS: f64 = 0.5;
/// Salt separating the sensor-noise streams from other seeded streams.
const NOISE_SALT: u64 = 0x4E01_5E00;

/// A rendered frame with its truth.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderedFrame {
    /// Grey values in `[0, 1]`, quantised exactly as the PNG stores them.
    pub image: Image,
    /// Distance Z (µm from the optical centre) of the surface each pixel sees (mean of its rays).
    pub z_um: Image,
    /// Gaussian defocus σ per pixel (px); all zeros without depth of field.
    pub blur_sigma_px: Image,
}

/// Per-ray constants of one pixel ray.
#[derive(Clone, Copy)]
struct Ray {
    cam_s: f64,
    dx: f64,
    dy: f64,
    off_s: f64,
    off_y: f64,
}

impl Groove {
    /// Lateral offset coefficient of a ray of slopes (dx, dy) through the cover glass: the ray
    /// is displaced by −d·(tan θ − tan θ_r) toward the axis, i.e. by `k·(dx, dy)`.
    fn glass_shift(&self, dx: f64, dy: f64) -> f64 {
        let tan_i = (dx * dx + dy * dy).sqrt();
        if tan_i <= 0.0 {
            return 0.0;
        }
        let sin_i = tan_i / (1.0 + tan_i * tan_i).sqrt();
        let sin_r = sin_i / self.optics.glass_index;
        let tan_r = sin_r / (1.0 - sin_r * sin_r).max(1e-12).sqrt();
        -self.optics.glass_thickness_um * (tan_i - tan_r) / tan_i
    }

    /// Intersects a ray with the height field by the fixed-point iteration
    /// t ← WD + depth(point(t)); returns Z and the hit point (s, y).
    #[inline]
    fn trace(&self, ray: &Ray, wd_um: f64, t_guess: f64) -> (f64, f64, f64) {
        let mut t = t_guess;
        for _ in 0..RAY_MAX_ITERATIONS {
            let s = ray.cam_s + t * ray.dx + ray.off_s;
            let y = t * ray.dy + ray.off_y;
            let next = wd_um + self.depth_um(s, y);
            let done = (next - t).abs() < RAY_TOLERANCE_UM;
            t = next;
            if done {
                break;
            }
        }
        (
            t,
            ray.cam_s + t * ray.dx + ray.off_s,
            t * ray.dy + ray.off_y,
        )
    }

    /// Renders frame `frame` of group `group` in memory, exactly as [`super::render_scan`] saves it.
    #[must_use]
    pub fn render_frame(&self, group: usize, frame: usize) -> Image {
        self.render_frame_detail(group, frame).image
    }

    /// Renders every frame of group `group` (frames in parallel).
    #[must_use]
    pub fn render_group(&self, group: usize) -> Vec<Image> {
        (0..self.cfg.frames_per_group)
            .into_par_iter()
            .map(|k| self.render_frame(group, k))
            .collect()
    }

    /// Renders one frame and returns it with the per-pixel Z and defocus σ.
    #[must_use]
    pub fn render_frame_detail(&self, group: usize, frame: usize) -> RenderedFrame {
        let c = &self.cfg;
        let (w, h) = (c.width_px, c.height_px);
        let p = c.pixel_pitch_um;
        let wd = c.working_distance_mm * 1000.0;
        let cx = 0.5 * (w as f64 - 1.0);
        let cy = 0.5 * (h as f64 - 1.0);
        let cam_s = self.land_s_um(group, frame, cx);
        let ss = c.supersample;
        let inv_ss = 1.0 / ss as f64;
        let mut sharp = Image::zeros(w, h);
        let mut z_map = Image::zeros(w, h);
        sharp
            .data
            .par_chunks_mut(w)
            .zip(z_map.data.par_chunks_mut(w))
            .enumerate()
            .for_each(|(row, (out, zout))| {
                let glass = self.optics.sees_glass(row);
                let mut guesses = [wd; 16];
                for (x, (o, zo)) in out.iter_mut().zip(zout.iter_mut()).enumerate() {
                    let mut acc = 0.0f32;
                    let mut zacc = 0.0;
                    for sy in 0..ss {
                        let py = row as f64 + (sy as f64 + 0.5) * inv_ss - 0.5;
                        let dy = (py - cy) * p / wd;
                        for sx in 0..ss {
                            let px = x as f64 + (sx as f64 + 0.5) * inv_ss - 0.5;
                            let dx = (px - cx) * p / wd;
                            let k = if glass { self.glass_shift(dx, dy) } else { 0.0 };
                            let ray = Ray {
                                cam_s,
                                dx,
                                dy,
                                off_s: k * dx,
                                off_y: k * dy,
                            };
                            let slot = (sy * ss + sx).min(15);
                            let (t, s, y) = self.trace(&ray, wd, guesses[slot]);
                            guesses[slot] = t;
                            let (v, _) = self.radiance(s, y);
                            acc += v;
                            zacc += t;
                        }
                    }
                    let n = (ss * ss) as f64;
                    *o = acc / n as f32;
                    *zo = (zacc / n) as f32;
                }
            });
        let mut sigma = Image::zeros(w, h);
        let blurred = if c.numerical_aperture > 0.0 {
            let k = DOF_SIGMA_PER_BLUR_RADIUS * c.numerical_aperture / p;
            let max_sigma = BLUR_LEVELS_PX.last().copied().unwrap_or(0.0);
            sigma
                .data
                .par_chunks_mut(w)
                .zip(z_map.data.par_chunks(w))
                .enumerate()
                .for_each(|(row, (srow, zrow))| {
                    let glass = self.optics.sees_glass(row);
                    let focus = if glass {
                        self.optics.focus_glass_um
                    } else {
                        self.optics.focus_um
                    };
                    for (sv, &z) in srow.iter_mut().zip(zrow) {
                        *sv = (k * (f64::from(z) - focus).abs()).min(max_sigma) as f32;
                    }
                });
            BlurStack::apply(&sharp, &sigma)
        } else {
            sharp
        };
        let image = self.finish(blurred, group, frame);
        RenderedFrame {
            image,
            z_um: z_map,
            blur_sigma_px: sigma,
        }
    }

    /// Adds seeded Gaussian sensor noise and quantises to the bit depth.
    fn finish(&self, mut img: Image, group: usize, frame: usize) -> Image {
        let c = &self.cfg;
        let w = img.width;
        let levels = if c.bit_depth == 16 { 65_535.0 } else { 255.0 };
        let sigma = (c.noise_sigma_8bit / 255.0) as f32;
        let seed = u64::from(c.seed) ^ NOISE_SALT;
        img.data
            .par_chunks_mut(w.max(1))
            .enumerate()
            .for_each(|(row, data)| {
                let mut rng = Rng::new(hash_seq(seed, &[group as u64, frame as u64, row as u64]));
                for v in data.iter_mut() {
                    let noisy = if sigma > 0.0 {
                        *v + sigma * rng.gaussian() as f32
                    } else {
                        *v
                    };
                    *v = (noisy.clamp(0.0, 1.0) * levels).round() / levels;
                }
            });
        img
    }
}

/// Renders frame `frame` of group `group` of `groove` in memory (see [`Groove::render_frame`]).
#[must_use]
pub fn render_frame(groove: &Groove, group: usize, frame: usize) -> Image {
    groove.render_frame(group, frame)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;
    use crate::synth::config::SynthConfig;
    use crate::synth::sounds::tone;
    use crate::synth::test_support::narrow_dual_focus_groove;

    #[test]
    fn glass_shift_matches_snell_for_a_known_angle() {
        let g = narrow_dual_focus_groove();
        // 30° incidence through 110 µm of n = 1.515 glass.
        let tan_i = 30f64.to_radians().tan();
        let k = g.glass_shift(tan_i, 0.0);
        let r = (30f64.to_radians().sin() / 1.515).asin();
        let want = -110.0 * (tan_i - r.tan());
        assert!((k * tan_i - want).abs() < 1e-9, "{} {want}", k * tan_i);
        // Paraxially the shift is −d(1 − 1/n)·tan θ: the 37 µm focus shift.
        let k0 = g.glass_shift(1e-4, 0.0);
        assert!((k0 + 110.0 * (1.0 - 1.0 / 1.515)).abs() < 1e-3, "{k0}");
    }

    #[test]
    fn rays_converge_onto_the_surface() {
        let cfg = SynthConfig::quick_test();
        let g = Groove::new(&tone(1000.0, 0.01, 48_000), &cfg).unwrap();
        let wd = 4000.0;
        for (x, y) in [(0.0, 0.0), (100.0, 160.0), (255.0, 319.0), (30.0, 200.0)] {
            let ray = Ray {
                cam_s: 50.0,
                dx: (x - 127.5) * 0.39 / wd,
                dy: (y - 159.5) * 0.39 / wd,
                off_s: 0.0,
                off_y: 0.0,
            };
            let (t, s, yy) = g.trace(&ray, wd, wd);
            assert!((t - wd - g.depth_um(s, yy)).abs() < 1e-5, "{x},{y}");
        }
    }
}
