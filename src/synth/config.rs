//! Settings of the ground-truth generator ([`SynthConfig`]), presets and their validation.

use serde::{Deserialize, Serialize};

use super::SynthError;
use crate::io::Cut;
use crate::io::scan::MIN_FRAMES_PER_GROUP;

/// The cover glass of a dual-focus scan (paper §9): it covers the image rows above the glass edge.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DualFocusConfig {
    /// Optical centre to the focal plane without glass (the glass moves it deeper by d·(1 − 1/n)).
    pub focus_distance_mm: f64,
    /// Glass thickness d.
    pub glass_thickness_mm: f64,
    /// Glass refractive index n.
    pub glass_index: f64,
}

impl Default for DualFocusConfig {
    fn default() -> Self {
        Self {
            focus_distance_mm: 4.0,
            glass_thickness_mm: 0.11,
            glass_index: 1.515,
        }
    }
}

impl DualFocusConfig {
    /// Focus shift of the glass d·(1 − 1/n), in µm.
    #[must_use]
    pub fn focus_shift_um(&self) -> f64 {
        self.glass_thickness_mm * 1000.0 * (1.0 - 1.0 / self.glass_index)
    }
}

/// One missing wall chunk placed by hand (in addition to the random ones).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WallChunk {
    /// Groove position where the chunk starts (µm from the scan start).
    pub start_um: f64,
    /// Length along the groove.
    pub length_um: f64,
    /// True for the right wall (larger y), false for the left wall.
    pub right_wall: bool,
    /// Share of the wall height missing, measured down from the land (0–1].
    pub wall_fraction: f64,
    /// How much deeper than the wall the flaked surface lies, at most.
    pub depth_um: f64,
}

/// Record damage. Every feature is fixed to the material (it moves with the record) and seeded.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DamageConfig {
    /// Mean number of scratches across the groove per mm of groove (thin bright or dark lines).
    pub scratches_per_mm: f64,
    /// Mean number of dust particles per mm² of the imaged strip (bright or dark blobs on top).
    pub dust_per_mm2: f64,
    /// Mean number of missing wall chunks per mm of groove.
    pub missing_wall_chunks_per_mm: f64,
    /// Mean length of a random chunk along the groove.
    pub chunk_length_um: f64,
    /// Mean share of the wall height a random chunk removes, from the land down (0–1].
    pub chunk_wall_fraction: f64,
    /// Mean extra depth of a chunk's flaked surface below the wall.
    pub chunk_depth_um: f64,
    /// Chunks placed by hand.
    pub chunks: Vec<WallChunk>,
    /// Seed of the damage layout.
    pub seed: u32,
}

impl Default for DamageConfig {
    fn default() -> Self {
        Self {
            scratches_per_mm: 0.0,
            dust_per_mm2: 0.0,
            missing_wall_chunks_per_mm: 0.0,
            chunk_length_um: 150.0,
            chunk_wall_fraction: 0.45,
            chunk_depth_um: 6.0,
            chunks: Vec::new(),
            seed: 1,
        }
    }
}

/// Everything the generator needs besides the sound. Written to `scan.toml` as `[synth]`.
///
/// Record coordinates: `s` along the groove (µm from the scan start), `y` across it (µm, 0 on the
/// optical axis), `Z` the distance from the optical centre (the land lies at the working distance).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SynthConfig {
    /// Frame width (columns, along the groove).
    pub width_px: usize,
    /// Frame height (rows, across the groove).
    pub height_px: usize,
    /// Pixel size on the land plane.
    pub pixel_pitch_um: f64,
    /// Optical centre to the land plane.
    pub working_distance_mm: f64,
    /// Turntable speed the sound is cut at.
    pub rpm: f64,
    /// Groove radius.
    pub radius_mm: f64,
    /// Lateral (mono), 45/45 stereo or vertical cut.
    pub cut: Cut,
    /// Frames in each group.
    pub frames_per_group: usize,
    /// Record travel between frames of a group.
    pub frame_step_um: f64,
    /// Columns shared by consecutive groups; group step = (width − overlap)·pitch.
    pub group_overlap_px: usize,
    /// Groove width at the land (at zero vertical offset).
    pub groove_top_width_um: f64,
    /// Groove depth below the land (at zero vertical offset).
    pub groove_depth_um: f64,
    /// Wall angle from the record plane (45° for standard grooves).
    pub wall_angle_deg: f64,
    /// Radius of the arcs joining the walls to the bottom: 0 gives a flat bottom with sharp
    /// corners; the largest radius that fits gives a fully rounded bottom.
    pub bottom_radius_um: f64,
    /// Groove centre line across the frame at zero displacement (+ toward larger rows).
    pub groove_offset_um: f64,
    /// Largest cutter velocity (lateral for `lateral`, vertical for `vertical`, per wall for
    /// `stereo`); the sound is scaled to reach it.
    pub peak_velocity_mm_s: f64,
    /// Size of the marble texture features.
    pub texture_scale_um: f64,
    /// Texture modulation depth, 0 (flat shading) to 1.
    pub texture_contrast: f64,
    /// Grey level of the land (0–1).
    pub land_brightness: f64,
    /// Grey level of the walls (0–1).
    pub wall_brightness: f64,
    /// Grey level of the groove bottom (0–1).
    pub bottom_brightness: f64,
    /// Grey level of flaked (missing-chunk) surfaces (0–1).
    pub flake_brightness: f64,
    /// Gaussian sensor noise σ in 8-bit grey levels (1/255 of full scale), whatever the bit depth.
    pub noise_sigma_8bit: f64,
    /// PNG bit depth, 8 or 16.
    pub bit_depth: u8,
    /// Sub-rays per pixel along each axis (1 = one ray through the pixel centre).
    pub supersample: usize,
    /// Numerical aperture for depth-of-field blur; 0 renders everything sharp.
    pub numerical_aperture: f64,
    /// Focal plane distance when not dual focus; `None` focuses on the land.
    pub focus_distance_mm: Option<f64>,
    /// Cover glass over the top rows, giving a second focal plane.
    pub dual_focus: Option<DualFocusConfig>,
    /// Scratches, dust and missing wall chunks.
    pub damage: DamageConfig,
    /// Seed of the texture and the sensor noise.
    pub seed: u32,
    /// Where in the sound the scan starts (snapped to a sample).
    pub start_secs: f64,
    /// Render at most this many groups; `None` renders as many as the sound covers.
    pub max_groups: Option<usize>,
}

impl Default for SynthConfig {
    fn default() -> Self {
        Self {
            width_px: 1280,
            height_px: 1024,
            pixel_pitch_um: 0.39,
            working_distance_mm: 4.0,
            rpm: 78.0,
            radius_mm: 115.0,
            cut: Cut::Lateral,
            frames_per_group: 12,
            frame_step_um: 0.78,
            group_overlap_px: 100,
            groove_top_width_um: 180.0,
            groove_depth_um: 70.0,
            wall_angle_deg: 45.0,
            bottom_radius_um: 0.0,
            groove_offset_um: 0.0,
            peak_velocity_mm_s: 50.0,
            texture_scale_um: 3.0,
            texture_contrast: 0.5,
            land_brightness: 0.15,
            wall_brightness: 0.75,
            bottom_brightness: 0.10,
            flake_brightness: 0.05,
            noise_sigma_8bit: 1.0,
            bit_depth: 8,
            supersample: 1,
            numerical_aperture: 0.0,
            focus_distance_mm: None,
            dual_focus: None,
            damage: DamageConfig::default(),
            seed: 1,
            start_secs: 0.0,
            max_groups: None,
        }
    }
}

/// The checks of one config table's values; an error names the key as `table.key`.
#[derive(Clone, Copy)]
pub(crate) struct Table(pub(crate) &'static str);

impl Table {
    pub(crate) fn bad(self, key: &str, problem: impl Into<String>) -> SynthError {
        SynthError::Config {
            key: format!("{}.{key}", self.0),
            problem: problem.into(),
        }
    }

    pub(crate) fn positive(self, key: &str, v: f64) -> Result<(), SynthError> {
        if v.is_finite() && v > 0.0 {
            Ok(())
        } else {
            Err(self.bad(key, format!("must be a positive number, got {v}")))
        }
    }

    pub(crate) fn within(self, key: &str, v: f64, lo: f64, hi: f64) -> Result<(), SynthError> {
        if v.is_finite() && v >= lo && v <= hi {
            Ok(())
        } else {
            Err(self.bad(key, format!("must lie in [{lo}, {hi}], got {v}")))
        }
    }
}

/// The `[synth]` table's checks.
const SYNTH: Table = Table("synth");

/// Largest frame side accepted.
const MAX_SIDE_PX: usize = 16_384;

impl SynthConfig {
    /// A tiny lateral scan for unit tests: 256×320 px frames, a 90 µm wide, 35 µm deep groove,
    /// 8-bit, no noise blur or damage. Renders a group in well under a second.
    #[must_use]
    pub fn quick_test() -> Self {
        Self {
            width_px: 256,
            height_px: 320,
            group_overlap_px: 40,
            groove_top_width_um: 90.0,
            groove_depth_um: 35.0,
            peak_velocity_mm_s: 20.0,
            max_groups: Some(2),
            ..Self::default()
        }
    }

    /// A few-MB demo scan: the paper's optics (0.39 µm/px, 4 mm, 12 frames of 0.78 µm) on
    /// 640×512 px 8-bit frames, a 140 µm wide, 55 µm deep groove with rounded corners, 30 mm/s
    /// peak, light damage, 2 groups (≈ 0.3 MB per frame).
    #[must_use]
    pub fn demo() -> Self {
        Self {
            width_px: 640,
            height_px: 512,
            group_overlap_px: 60,
            groove_top_width_um: 140.0,
            groove_depth_um: 55.0,
            bottom_radius_um: 8.0,
            peak_velocity_mm_s: 30.0,
            damage: DamageConfig {
                scratches_per_mm: 2.0,
                dust_per_mm2: 20.0,
                missing_wall_chunks_per_mm: 0.3,
                ..DamageConfig::default()
            },
            max_groups: Some(2),
            ..Self::default()
        }
    }

    /// The dual-focus set-up of paper §9: land at 3.97 mm, focus at 4.0 mm (4.037 mm under
    /// 0.11 mm of n = 1.515 glass), a 100 µm deep groove, NA 0.45 depth of field (in-focus stripes ≈ 15 px wide).
    #[must_use]
    pub fn dual_focus_demo() -> Self {
        Self {
            working_distance_mm: 3.97,
            groove_top_width_um: 240.0,
            groove_depth_um: 100.0,
            numerical_aperture: 0.45,
            dual_focus: Some(DualFocusConfig::default()),
            peak_velocity_mm_s: 20.0,
            bit_depth: 16,
            noise_sigma_8bit: 0.5,
            max_groups: Some(10),
            ..Self::default()
        }
    }

    /// Paper Fig. 20's case on the dual-focus set-up: the upper 45% of the right wall (where
    /// the no-glass focus stripe lies) is missing from 300 µm to 1300 µm of the scan (frames of
    /// groups 1–2 at the default frame size).
    #[must_use]
    pub fn dual_focus_fig20() -> Self {
        let mut cfg = Self::dual_focus_demo();
        cfg.damage.chunks.push(WallChunk {
            start_um: 300.0,
            length_um: 1000.0,
            right_wall: true,
            wall_fraction: 0.45,
            depth_um: 8.0,
        });
        cfg
    }

    /// Group step along the groove, (width − overlap)·pitch, in µm.
    #[must_use]
    pub fn group_step_um(&self) -> f64 {
        self.width_px.saturating_sub(self.group_overlap_px) as f64 * self.pixel_pitch_um
    }

    /// Groove speed Vt = 2π·rpm/60·R, in µm/s.
    #[must_use]
    pub fn groove_speed_um_s(&self) -> f64 {
        std::f64::consts::TAU * self.rpm / 60.0 * self.radius_mm * 1000.0
    }

    /// Groove length one group's frames cover at the land, in µm.
    #[must_use]
    pub fn group_span_um(&self) -> f64 {
        self.frames_per_group.saturating_sub(1) as f64 * self.frame_step_um
            + self.width_px as f64 * self.pixel_pitch_um
    }

    /// Distance of the focal plane without glass, µm (the land when nothing is set).
    #[must_use]
    pub fn focus_distance_um(&self) -> f64 {
        match (&self.dual_focus, self.focus_distance_mm) {
            (Some(df), _) => df.focus_distance_mm * 1000.0,
            (None, Some(f)) => f * 1000.0,
            (None, None) => self.working_distance_mm * 1000.0,
        }
    }

    /// Checks every value on its own and against the others (the sound is checked later).
    ///
    /// # Errors
    /// [`SynthError::Config`] naming the first bad key (`synth.<key>`) and the problem.
    pub fn validate(&self) -> Result<(), SynthError> {
        for (key, v) in [("width_px", self.width_px), ("height_px", self.height_px)] {
            if !(16..=MAX_SIDE_PX).contains(&v) {
                return Err(SYNTH.bad(key, format!("must lie in [16, {MAX_SIDE_PX}], got {v}")));
            }
        }
        SYNTH.positive("pixel_pitch_um", self.pixel_pitch_um)?;
        SYNTH.positive("working_distance_mm", self.working_distance_mm)?;
        SYNTH.positive("rpm", self.rpm)?;
        SYNTH.positive("radius_mm", self.radius_mm)?;
        if !(MIN_FRAMES_PER_GROUP..=999).contains(&self.frames_per_group) {
            return Err(SYNTH.bad(
                "frames_per_group",
                format!(
                    "must lie in [{MIN_FRAMES_PER_GROUP}, 999], got {}",
                    self.frames_per_group
                ),
            ));
        }
        SYNTH.positive("frame_step_um", self.frame_step_um)?;
        if self.group_overlap_px >= self.width_px {
            return Err(SYNTH.bad(
                "group_overlap_px",
                format!(
                    "{} must be smaller than width_px = {}",
                    self.group_overlap_px, self.width_px
                ),
            ));
        }
        SYNTH.positive("groove_top_width_um", self.groove_top_width_um)?;
        SYNTH.positive("groove_depth_um", self.groove_depth_um)?;
        SYNTH.within("wall_angle_deg", self.wall_angle_deg, 1.0, 89.0)?;
        SYNTH.within("bottom_radius_um", self.bottom_radius_um, 0.0, 1e6)?;
        let frame_um = self.height_px as f64 * self.pixel_pitch_um;
        if self.groove_top_width_um >= frame_um {
            return Err(SYNTH.bad(
                "groove_top_width_um",
                format!(
                    "the groove ({} µm) is wider than the frame ({frame_um:.1} µm = height_px × pixel_pitch_um)",
                    self.groove_top_width_um
                ),
            ));
        }
        let tan_wall = self.wall_angle_deg.to_radians().tan();
        let half_top = 0.5 * self.groove_top_width_um;
        if self.groove_depth_um / tan_wall > half_top {
            return Err(SYNTH.bad(
                "groove_depth_um",
                format!(
                    "{} µm walls at {}° do not fit in a {} µm wide groove (they would cross above the bottom)",
                    self.groove_depth_um, self.wall_angle_deg, self.groove_top_width_um
                ),
            ));
        }
        let r = self.bottom_radius_um;
        let wall_angle = self.wall_angle_deg.to_radians();
        let uc0 = half_top - (self.groove_depth_um - r + r / wall_angle.cos()) / tan_wall;
        if uc0 < 0.0 || r > self.groove_depth_um {
            return Err(SYNTH.bad(
                "bottom_radius_um",
                format!(
                    "{r} µm is too large for a {} µm deep, {} µm wide groove",
                    self.groove_depth_um, self.groove_top_width_um
                ),
            ));
        }
        SYNTH.within(
            "groove_offset_um",
            self.groove_offset_um,
            -frame_um,
            frame_um,
        )?;
        SYNTH.within("peak_velocity_mm_s", self.peak_velocity_mm_s, 0.0, 1e4)?;
        SYNTH.positive("texture_scale_um", self.texture_scale_um)?;
        SYNTH.within("texture_contrast", self.texture_contrast, 0.0, 1.0)?;
        for (key, v) in [
            ("land_brightness", self.land_brightness),
            ("wall_brightness", self.wall_brightness),
            ("bottom_brightness", self.bottom_brightness),
            ("flake_brightness", self.flake_brightness),
        ] {
            SYNTH.within(key, v, 0.0, 1.0)?;
        }
        SYNTH.within("noise_sigma_8bit", self.noise_sigma_8bit, 0.0, 255.0)?;
        if !matches!(self.bit_depth, 8 | 16) {
            return Err(SYNTH.bad(
                "bit_depth",
                format!("must be 8 or 16, got {}", self.bit_depth),
            ));
        }
        if !(1..=4).contains(&self.supersample) {
            return Err(SYNTH.bad(
                "supersample",
                format!("must lie in [1, 4], got {}", self.supersample),
            ));
        }
        SYNTH.within("numerical_aperture", self.numerical_aperture, 0.0, 0.95)?;
        if let Some(f) = self.focus_distance_mm {
            SYNTH.positive("focus_distance_mm", f)?;
        }
        if let Some(df) = &self.dual_focus {
            self.validate_dual_focus(df)?;
        }
        self.validate_damage()?;
        SYNTH.within("start_secs", self.start_secs, 0.0, 1e6)?;
        match self.max_groups {
            Some(0) => return Err(SYNTH.bad("max_groups", "must be at least 1 when given")),
            // The scan's own scan.toml records it, and TOML integers are 64-bit signed.
            Some(n) if i64::try_from(n).is_err() => {
                return Err(SYNTH.bad(
                    "max_groups",
                    format!("{n} is more than a scan.toml can record ({})", i64::MAX),
                ));
            }
            _ => {}
        }
        Ok(())
    }

    fn validate_dual_focus(&self, df: &DualFocusConfig) -> Result<(), SynthError> {
        SYNTH.positive("dual_focus.focus_distance_mm", df.focus_distance_mm)?;
        SYNTH.positive("dual_focus.glass_thickness_mm", df.glass_thickness_mm)?;
        SYNTH.within("dual_focus.glass_index", df.glass_index, 1.0, 4.0)?;
        if self.numerical_aperture <= 0.0 {
            return Err(SYNTH.bad(
                "numerical_aperture",
                "dual focus needs depth of field: set a numerical aperture above 0 (e.g. 0.3)",
            ));
        }
        if self.focus_distance_mm.is_some() {
            return Err(SYNTH.bad(
                "focus_distance_mm",
                "give the focus in dual_focus.focus_distance_mm only",
            ));
        }
        let land_um = self.working_distance_mm * 1000.0;
        let z_plain = df.focus_distance_mm * 1000.0 - land_um;
        let z_glass = z_plain + df.focus_shift_um();
        let depth = self.groove_depth_um;
        if !(z_plain > 0.05 * depth && z_glass < 0.95 * depth) {
            return Err(SYNTH.bad(
                "dual_focus.focus_distance_mm",
                format!(
                    "the focal planes lie {z_plain:.1} µm and {z_glass:.1} µm below the land; both must \
                     fall on the {depth} µm deep walls (move working_distance_mm or the focus)"
                ),
            ));
        }
        Ok(())
    }

    fn validate_damage(&self) -> Result<(), SynthError> {
        let d = &self.damage;
        SYNTH.within("damage.scratches_per_mm", d.scratches_per_mm, 0.0, 1000.0)?;
        SYNTH.within("damage.dust_per_mm2", d.dust_per_mm2, 0.0, 1e5)?;
        SYNTH.within(
            "damage.missing_wall_chunks_per_mm",
            d.missing_wall_chunks_per_mm,
            0.0,
            100.0,
        )?;
        SYNTH.positive("damage.chunk_length_um", d.chunk_length_um)?;
        SYNTH.within(
            "damage.chunk_wall_fraction",
            d.chunk_wall_fraction,
            0.01,
            1.0,
        )?;
        SYNTH.within("damage.chunk_depth_um", d.chunk_depth_um, 0.0, 50.0)?;
        for (i, c) in d.chunks.iter().enumerate() {
            SYNTH.within(
                &format!("damage.chunks[{i}].start_um"),
                c.start_um,
                -1e12,
                1e12,
            )?;
            SYNTH.positive(&format!("damage.chunks[{i}].length_um"), c.length_um)?;
            SYNTH.within(
                &format!("damage.chunks[{i}].wall_fraction"),
                c.wall_fraction,
                0.01,
                1.0,
            )?;
            SYNTH.within(
                &format!("damage.chunks[{i}].depth_um"),
                c.depth_um,
                0.0,
                50.0,
            )?;
        }
        Ok(())
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;

    fn key_of(err: SynthError) -> String {
        match err {
            SynthError::Config { key, .. } => key,
            other => panic!("expected a config error, got {other}"),
        }
    }

    #[test]
    fn defaults_and_presets_are_valid() {
        SynthConfig::default().validate().unwrap();
        SynthConfig::quick_test().validate().unwrap();
        SynthConfig::demo().validate().unwrap();
        SynthConfig::dual_focus_demo().validate().unwrap();
        SynthConfig::dual_focus_fig20().validate().unwrap();
        let c = SynthConfig::default();
        assert!((c.group_step_um() - 1180.0 * 0.39).abs() < 1e-9);
        assert!(
            (c.groove_speed_um_s() - 939_336.2).abs() < 0.1,
            "{}",
            c.groove_speed_um_s()
        );
    }

    #[test]
    fn absurd_geometry_names_the_key() {
        /// One bad value set on the defaults.
        type Edit = fn(&mut SynthConfig);
        // (the edit, the key its error names)
        let cases: [(Edit, &str); 7] = [
            (|c| c.max_groups = Some(0), "synth.max_groups"),
            // More than its scan.toml could record.
            (|c| c.max_groups = Some(usize::MAX), "synth.max_groups"),
            (|c| c.groove_depth_um = -3.0, "synth.groove_depth_um"),
            (|c| c.wall_angle_deg = 90.0, "synth.wall_angle_deg"),
            (|c| c.bit_depth = 12, "synth.bit_depth"),
            (|c| c.pixel_pitch_um = f64::NAN, "synth.pixel_pitch_um"),
            (|c| c.bottom_radius_um = 60.0, "synth.bottom_radius_um"),
        ];
        for (edit, key) in cases {
            let mut c = SynthConfig::default();
            edit(&mut c);
            assert_eq!(key_of(c.validate().unwrap_err()), key);
        }
        let c = SynthConfig {
            groove_top_width_um: 500.0,
            ..SynthConfig::default()
        };
        let e = c.validate().unwrap_err();
        assert!(e.to_string().contains("wider than the frame"), "{e}");
        let mut c = SynthConfig::dual_focus_demo();
        c.working_distance_mm = 4.0;
        assert_eq!(
            key_of(c.validate().unwrap_err()),
            "synth.dual_focus.focus_distance_mm"
        );
    }

    #[test]
    fn toml_round_trip_and_unknown_keys_rejected() {
        let c = SynthConfig::dual_focus_demo();
        let text = toml::to_string(&c).unwrap();
        let back: SynthConfig = toml::from_str(&text).unwrap();
        assert_eq!(c, back);
        let partial: SynthConfig = toml::from_str("height_px = 400\n").unwrap();
        assert_eq!(partial.height_px, 400);
        assert_eq!(partial.width_px, 1280);
        assert!(toml::from_str::<SynthConfig>("hieght_px = 400\n").is_err());
    }
}
