//! Synthetic grooves, the paper's optics and a seeded noise source for the depth, wall and orientation tests.

use super::{DepthMap, WallSide};
use crate::image::Image;
use crate::meta::Geometry;

/// The paper's optics: 0.39 µm/px, 4 mm working distance, 0.78 µm frame step.
pub(crate) fn paper_geometry() -> Geometry {
    Geometry {
        focal_px: 4000.0 / 0.39,
        pixel_pitch_um: 0.39,
        working_distance_um: 4000.0,
        frame_step_um: 0.78,
    }
}

/// A small deterministic generator (xorshift64*) with uniform and Gaussian draws.
pub(crate) struct Rng(u64);

impl Rng {
    pub(crate) fn new(seed: u64) -> Self {
        Self(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }

    /// Uniform in [0, 1).
    pub(crate) fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Standard normal (Box–Muller).
    pub(crate) fn gauss(&mut self) -> f64 {
        let u1 = self.uniform().max(1e-300);
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

/// A V-groove with a flat bottom in a flat land, displaced laterally by d(X):
/// Z = land + clamp(depth + bottom_half − |Y − d(X)|, 0, depth) (45° walls).
pub(crate) struct Groove {
    pub(crate) geom: Geometry,
    pub(crate) land_um: f64,
    pub(crate) depth_um: f64,
    pub(crate) bottom_half_um: f64,
    pub(crate) d: Box<dyn Fn(f64) -> f64>,
}

impl Groove {
    /// A 60 µm deep groove with a 10 µm bottom at the working distance.
    pub(crate) fn new(geom: Geometry, d: impl Fn(f64) -> f64 + 'static) -> Self {
        Self {
            geom,
            land_um: geom.working_distance_um,
            depth_um: 60.0,
            bottom_half_um: 5.0,
            d: Box::new(d),
        }
    }

    /// [`Groove::new`] displaced by a sine of `amplitude_um` and `wavelength_um` along the
    /// groove.
    pub(crate) fn sine(geom: Geometry, amplitude_um: f64, wavelength_um: f64) -> Self {
        Self::new(geom, move |x_um| {
            amplitude_um * (std::f64::consts::TAU * x_um / wavelength_um).sin()
        })
    }

    /// Z (µm) at the physical point (X, Y).
    pub(crate) fn z_at(&self, x_um: f64, y_um: f64) -> f64 {
        let inner = self.depth_um + self.bottom_half_um - (y_um - (self.d)(x_um)).abs();
        self.land_um + inner.clamp(0.0, self.depth_um)
    }

    /// Z seen at pixel (x, y): the fixed point of Z = z_at((x − cx)·Z/f, (y − cy)·Z/f).
    pub(crate) fn z_px(&self, x: f64, y: f64, width: usize, height: usize) -> f64 {
        self.z_px_from(x, y, width, height, 0.0)
    }

    /// Z seen at pixel (x, y) with the camera moved to X = `cam_um`.
    pub(crate) fn z_px_from(
        &self,
        x: f64,
        y: f64,
        width: usize,
        height: usize,
        cam_um: f64,
    ) -> f64 {
        let f = self.geom.focal_px;
        let (px, py) = (
            (x - (width as f64 - 1.0) / 2.0) / f,
            (y - (height as f64 - 1.0) / 2.0) / f,
        );
        let mut z = self.land_um;
        for _ in 0..40 {
            z = self.z_at(px * z + cam_um, py * z);
        }
        z
    }

    /// The rendered depth map.
    pub(crate) fn depth_map(&self, width: usize, height: usize) -> DepthMap {
        DepthMap {
            z_um: Image::from_fn(width, height, |x, y| {
                self.z_px(x as f64, y as f64, width, height) as f32
            }),
            variance: Image::zeros(width, height),
            frame_index: 0,
            warnings: Vec::new(),
        }
    }

    /// The wall band in column x: (centre row, half height) in px, from the rows where the
    /// wall meets the land and the bottom.
    pub(crate) fn wall_band_px(
        &self,
        side: WallSide,
        x: usize,
        width: usize,
        height: usize,
    ) -> (f64, f64) {
        let f = self.geom.focal_px;
        let (cx, cy) = ((width as f64 - 1.0) / 2.0, (height as f64 - 1.0) / 2.0);
        let row_at = |z: f64, off: f64| {
            let big_x = (x as f64 - cx) * z / f;
            cy + f * ((self.d)(big_x) + off) / z
        };
        let (outer, inner) = (self.depth_um + self.bottom_half_um, self.bottom_half_um);
        let (a, b) = match side {
            WallSide::Left => (
                row_at(self.land_um, -outer),
                row_at(self.land_um + self.depth_um, -inner),
            ),
            WallSide::Right => (
                row_at(self.land_um + self.depth_um, inner),
                row_at(self.land_um, outer),
            ),
        };
        ((a + b) / 2.0, (b - a).abs() / 2.0)
    }
}
