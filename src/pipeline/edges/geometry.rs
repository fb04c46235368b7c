//! Mapping between frame pixels and groove coordinates for a surface at a given distance: the
//! frame step, the perspective of the border's own height, and the cover glass.
//!
//! Conventions (docs/FORMAT.md, `synth`): principal point `cx = (W−1)/2`, `cy = (H−1)/2`; frame
//! `k` of group `g` looks from `cam_s = g·group_step + k·frame_step + cx·p`, and a surface at
//! distance `Z` from the optical centre is seen at column `x` where
//! `s = cam_s + (x − cx)·p·Z/WD` and at row `r` where `y = (r − cy)·p·Z/WD`. The land lies at
//! `Z = WD`; a groove bottom `D` deep at `WD + D`. Under a cover glass of thickness `d` and
//! index `n` a ray is displaced toward the axis as if the surface were `d·(1 − 1/n)` nearer
//! (paraxially), so rows on the glass side use that shorter distance.

use crate::meta::GlassSide;
use crate::meta::ScanMeta;

/// Pixel ↔ groove mapping of one group's frames.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameGeometry {
    /// Frame width (px).
    pub width: usize,
    /// Frame height (px).
    pub height: usize,
    /// Principal point column.
    pub cx: f64,
    /// Principal point row.
    pub cy: f64,
    /// Pixel size on the land (µm).
    pub pitch_um: f64,
    /// Optical centre to the land (µm).
    pub working_distance_um: f64,
    /// Record travel between frames (µm).
    pub frame_step_um: f64,
    /// Record travel between groups (µm).
    pub group_step_um: f64,
    /// Cover glass: rows on its side and its apparent shift of the surface toward the camera.
    pub glass: Option<Glass>,
}

/// The cover glass of a dual-focus scan, as the mapping needs it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Glass {
    /// Image row of the glass edge.
    pub edge_row: f64,
    /// True when rows above the edge (smaller rows) lie under the glass.
    pub on_top: bool,
    /// Apparent shift of a surface toward the camera under the glass, d·(1 − 1/n) (µm).
    pub shift_um: f64,
}

impl FrameGeometry {
    /// The mapping of `width`×`height` frames of a scan.
    #[must_use]
    pub fn new(meta: &ScanMeta, width: usize, height: usize) -> Self {
        let glass = meta.dual_focus.as_ref().map(|df| Glass {
            edge_row: df.glass_edge_row,
            on_top: df.glass_side == GlassSide::Top,
            shift_um: df.focus_shift_mm() * 1000.0,
        });
        Self {
            width,
            height,
            cx: 0.5 * (width as f64 - 1.0),
            cy: 0.5 * (height as f64 - 1.0),
            pitch_um: meta.camera.pixel_pitch_um,
            working_distance_um: meta.camera.working_distance_mm * 1000.0,
            frame_step_um: meta.motion.frame_step_um,
            group_step_um: meta.motion.group_step_um,
            glass,
        }
    }

    /// Groove position of the optical axis in frame `frame` of group `group` (µm).
    #[must_use]
    pub fn cam_s_um(&self, group: usize, frame: usize) -> f64 {
        group as f64 * self.group_step_um
            + frame as f64 * self.frame_step_um
            + self.cx * self.pitch_um
    }

    /// The distance a surface at `z_um` appears at when seen at `row` (the glass brings it nearer).
    #[must_use]
    pub fn apparent_z_um(&self, z_um: f64, row: f64) -> f64 {
        match self.glass {
            Some(g) if (row < g.edge_row) == g.on_top => z_um - g.shift_um,
            _ => z_um,
        }
    }

    /// Groove length per column for a surface at apparent distance `z_um` (µm/px).
    #[must_use]
    pub fn um_per_px(&self, z_um: f64) -> f64 {
        self.pitch_um * z_um / self.working_distance_um
    }

    /// Groove position `s` (µm) seen at column `x` from `cam_s_um` by a surface at apparent `z_um`.
    #[must_use]
    pub fn s_at(&self, cam_s_um: f64, x: f64, z_um: f64) -> f64 {
        cam_s_um + (x - self.cx) * self.um_per_px(z_um)
    }

    /// Column at which groove position `s_um` is seen (the inverse of [`Self::s_at`]).
    #[must_use]
    pub fn x_at(&self, cam_s_um: f64, s_um: f64, z_um: f64) -> f64 {
        self.cx + (s_um - cam_s_um) / self.um_per_px(z_um)
    }

    /// Record `y` (µm from the optical axis) seen at `row` by a surface at apparent `z_um`.
    #[must_use]
    pub fn y_at(&self, row: f64, z_um: f64) -> f64 {
        (row - self.cy) * self.um_per_px(z_um)
    }

    /// Row at which record `y_um` is seen (the inverse of [`Self::y_at`]).
    #[must_use]
    pub fn row_at(&self, y_um: f64, z_um: f64) -> f64 {
        self.cy + y_um / self.um_per_px(z_um)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;
    use crate::synth::test_support::narrow_dual_focus_groove;
    use crate::synth::{Groove, SynthConfig, scan_meta, tone};

    #[test]
    fn columns_and_rows_match_the_generator() {
        let cfg = SynthConfig::quick_test();
        let g = Groove::new(&tone(1000.0, 0.01, 48_000), &cfg).unwrap();
        let meta = scan_meta(&g).unwrap();
        let geo = FrameGeometry::new(&meta, g.cfg.width_px, g.cfg.height_px);
        // At the land, column x of frame k of group 1 sees the generator's land_s_um.
        let cam = geo.cam_s_um(1, 5);
        for x in [0.0, 17.5, 255.0] {
            let want = g.land_s_um(1, 5, x);
            assert!((geo.s_at(cam, x, geo.working_distance_um) - want).abs() < 1e-9);
            let back = geo.x_at(cam, want, geo.working_distance_um);
            assert!((back - x).abs() < 1e-9);
        }
        // Deeper surfaces spread less per pixel: 35 µm below a 4 mm land, 0.875% more µm/px.
        let z = geo.working_distance_um + 35.0;
        let ratio = geo.um_per_px(z) / geo.um_per_px(geo.working_distance_um);
        assert!((ratio - 1.008_75).abs() < 1e-12);
        let y = geo.y_at(200.0, z);
        assert!((geo.row_at(y, z) - 200.0).abs() < 1e-9);
        assert!(geo.glass.is_none());
        assert_eq!(geo.apparent_z_um(z, 3.0), z);
    }

    #[test]
    fn the_glass_brings_its_rows_nearer() {
        let g = narrow_dual_focus_groove();
        let meta = scan_meta(&g).unwrap();
        let geo = FrameGeometry::new(&meta, g.cfg.width_px, g.cfg.height_px);
        let glass = geo.glass.unwrap();
        assert!(glass.on_top);
        let shift = 110.0 * (1.0 - 1.0 / 1.515);
        assert!((glass.shift_um - shift).abs() < 1e-9);
        let z = 4000.0;
        assert!((geo.apparent_z_um(z, glass.edge_row - 1.0) - (z - shift)).abs() < 1e-9);
        assert_eq!(geo.apparent_z_um(z, glass.edge_row + 1.0), z);
    }
}
