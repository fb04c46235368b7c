//! Settings of the top-view still generator ([`StillConfig`]), its presets and their validation.

use serde::{Deserialize, Serialize};

use crate::io::Cut;
use crate::pipeline::still::Axis;
use crate::synth::SynthError;
use crate::synth::config::Table;

/// Largest still the generator renders (pixels); it holds the image as `f32` while rendering.
pub const MAX_STILL_RENDER_PIXELS: usize = 64 * 1024 * 1024;
/// Narrowest land left between neighbouring grooves anywhere in the still (µm): closer grooves
/// would cut into each other, which a cutting lathe never does.
pub const MIN_LAND_UM: f64 = 2.0;

/// Everything the still generator needs besides the sound (written to the sidecar as `[still]`).
///
/// Grooves are neighbouring turns of one spiral seen from above, side by side across the image;
/// time runs down the image (vertical axis) or rightward (horizontal axis). Each wall is a
/// plane at `wall_angle_deg` from the record plane whose border with the land moves with the
/// sound; the groove has a flat bottom of `bottom_width_um`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StillConfig {
    /// Image side along the grooves (rows for a vertical still, columns for a horizontal one).
    pub length_px: usize,
    /// Image side across the grooves.
    pub across_px: usize,
    /// Which way the grooves run: `vertical` (time down the image) or `horizontal` (rightward).
    pub axis: Axis,
    /// Pixel size on the record.
    pub um_per_px: f64,
    /// Turntable speed the sound is cut at.
    pub rpm: f64,
    /// Radius of the middle groove (grooves further in have smaller radii, by `pitch_um` each).
    pub radius_mm: f64,
    /// `lateral` (mono: both walls move together) or `stereo` (45/45: one channel per wall).
    pub cut: Cut,
    /// Grooves in the image.
    pub grooves: usize,
    /// Distance between neighbouring turns' centre lines.
    pub pitch_um: f64,
    /// Groove width at the land, at rest.
    pub top_width_um: f64,
    /// Width of the flat bottom (the cutter's truncated tip).
    pub bottom_width_um: f64,
    /// Wall angle from the record plane (45° for standard grooves): a wall moving by `a` along
    /// its normal moves its land border by `a / sin` of this angle.
    pub wall_angle_deg: f64,
    /// Built-in tones (Hz) when no sound is given: one per groove for a lateral cut, two per
    /// groove (left wall, right wall) for stereo, in groove order from the image's left (top).
    /// Empty: [`default_tones_hz`].
    pub tones_hz: Vec<f64>,
    /// Largest cutter velocity of every wall (per channel for stereo).
    pub peak_velocity_mm_s: f64,
    /// Time of the middle groove's first line in a given sound (s); each turn further in starts
    /// one revolution later.
    pub start_secs: f64,
    /// Slow drift of every groove across the image from the first line to the last (µm, a skew).
    pub drift_um: f64,
    /// Amplitude of a slow wander of every groove across the image (µm).
    pub wander_um: f64,
    /// Period of that wander along the groove (µm).
    pub wander_period_um: f64,
    /// Bend the grooves on their true arc of radius `radius_mm` (the ends curve toward the centre).
    pub curved: bool,
    /// Grey level of the land (before illumination).
    pub land_level: f64,
    /// Grey level of the walls (each wall varies by ±`wall_level_spread`).
    pub wall_level: f64,
    /// Relative spread of the wall levels between walls (seeded).
    pub wall_level_spread: f64,
    /// Grey level of the flat bottom.
    pub bottom_level: f64,
    /// Share of walls with a bright rim at their land border (seeded per wall; 0–1).
    pub rim_fraction: f64,
    /// Grey level of a rim.
    pub rim_level: f64,
    /// Width of a rim on the land side of the border.
    pub rim_width_um: f64,
    /// Contrast of the surface texture (relative, multiplicative).
    pub texture: f64,
    /// Feature size of the surface texture.
    pub texture_scale_um: f64,
    /// Uneven illumination: the light varies by about ±this share over the image (0–0.9).
    pub illumination_unevenness: f64,
    /// Bright dust specks per megapixel.
    pub dust_per_mpx: f64,
    /// Largest dust speck radius.
    pub dust_max_radius_px: f64,
    /// Text burnt into the image (with a scale bar); empty for none.
    pub text: String,
    /// Height of the burnt-in text.
    pub text_height_px: usize,
    /// Gaussian blur of the optics (σ).
    pub blur_sigma_px: f64,
    /// Sensor noise (σ, share of full scale).
    pub noise_sigma: f64,
    /// 8 or 16 bits per pixel.
    pub bit_depth: u8,
    /// `png` or `tiff`.
    pub format: String,
    /// Seed of texture, levels, rims, dust and noise.
    pub seed: u32,
}

impl Default for StillConfig {
    /// The test still: 1000 × 4000 px at 1 µm/px of an LP (33⅓ rpm, R = 100 mm), seven
    /// 56 µm wide grooves 100 µm apart, drifting 90 µm across the image, with dust, text, rims
    /// on about half the walls, uneven light, blur σ = 1 px and 1 % noise, 8-bit PNG.
    fn default() -> Self {
        Self {
            length_px: 4000,
            across_px: 1000,
            axis: Axis::Vertical,
            um_per_px: 1.0,
            rpm: 100.0 / 3.0,
            radius_mm: 100.0,
            cut: Cut::Lateral,
            grooves: 7,
            pitch_um: 100.0,
            top_width_um: 56.0,
            bottom_width_um: 6.0,
            wall_angle_deg: 45.0,
            tones_hz: Vec::new(),
            peak_velocity_mm_s: 30.0,
            start_secs: 0.0,
            drift_um: 90.0,
            wander_um: 12.0,
            wander_period_um: 9000.0,
            curved: true,
            land_level: 0.62,
            wall_level: 0.2,
            wall_level_spread: 0.2,
            bottom_level: 0.5,
            rim_fraction: 0.5,
            rim_level: 0.95,
            rim_width_um: 2.0,
            texture: 0.08,
            texture_scale_um: 6.0,
            illumination_unevenness: 0.35,
            dust_per_mpx: 100.0,
            dust_max_radius_px: 5.0,
            text: "GROOVESCOPE TEST STILL 1.0 UM/PX".into(),
            text_height_px: 28,
            blur_sigma_px: 1.0,
            noise_sigma: 0.01,
            bit_depth: 8,
            format: "png".into(),
            seed: 7,
        }
    }
}

/// The built-in tones for `grooves` grooves, in groove order: lateral one per groove
/// (600 Hz × 1.25ᵏ: 600, 750, 938 … Hz), stereo two per groove (left wall 500 Hz × 1.15ᵏ, right
/// wall 1300 Hz × 1.15ᵏ: every left tone lies below every right one for up to 7 grooves).
#[must_use]
pub fn default_tones_hz(grooves: usize, cut: Cut) -> Vec<f64> {
    match cut {
        Cut::Stereo => (0..grooves)
            .flat_map(|k| {
                let g = 1.15_f64.powf(k as f64);
                [500.0 * g, 1300.0 * g]
            })
            .collect(),
        _ => (0..grooves)
            .map(|k| 600.0 * 1.25_f64.powf(k as f64))
            .collect(),
    }
}

/// The `[still]` table's checks.
const STILL: Table = Table("still");

impl StillConfig {
    /// The bundled demo strip: one long horizontal strip of a 16⅔ rpm speech disc (R = 75 mm)
    /// at 6 µm/px, three turns, 8-bit PNG; the middle groove carries the given sound.
    #[must_use]
    pub fn demo() -> Self {
        Self {
            length_px: 80_000,
            across_px: 64,
            axis: Axis::Horizontal,
            um_per_px: 6.0,
            rpm: 50.0 / 3.0,
            radius_mm: 75.0,
            grooves: 3,
            pitch_um: 110.0,
            top_width_um: 62.0,
            bottom_width_um: 8.0,
            peak_velocity_mm_s: 14.0,
            drift_um: 70.0,
            wander_um: 20.0,
            wander_period_um: 90_000.0,
            curved: false,
            dust_per_mpx: 120.0,
            dust_max_radius_px: 2.5,
            text: "GROOVESCOPE DEMO 6 UM/PX".into(),
            text_height_px: 14,
            blur_sigma_px: 0.7,
            noise_sigma: 0.012,
            texture_scale_um: 12.0,
            rim_width_um: 4.0,
            ..Self::default()
        }
    }

    /// Groove speed Vt = 2π·rpm/60·R of a groove at `radius_mm`, µm/s.
    #[must_use]
    pub fn groove_speed_um_s(&self, radius_mm: f64) -> f64 {
        std::f64::consts::TAU * self.rpm / 60.0 * radius_mm * 1000.0
    }

    /// Seconds per revolution.
    #[must_use]
    pub fn revolution_secs(&self) -> f64 {
        60.0 / self.rpm
    }

    /// Checks every setting (geometry that cannot be cut or seen is refused).
    ///
    /// # Errors
    /// [`SynthError::Config`] naming the first bad key.
    pub fn validate(&self) -> Result<(), SynthError> {
        if self.length_px < 16 || self.across_px < 8 {
            return Err(STILL.bad(
                "length_px",
                format!(
                    "the still must be at least 16 px long and 8 px across, got {} × {}",
                    self.length_px, self.across_px
                ),
            ));
        }
        if self.length_px.saturating_mul(self.across_px) > MAX_STILL_RENDER_PIXELS {
            return Err(STILL.bad(
                "length_px",
                format!(
                    "{} × {} px is larger than the generator's limit of {MAX_STILL_RENDER_PIXELS} pixels",
                    self.length_px, self.across_px
                ),
            ));
        }
        STILL.positive("um_per_px", self.um_per_px)?;
        STILL.positive("rpm", self.rpm)?;
        STILL.positive("radius_mm", self.radius_mm)?;
        if self.cut == Cut::Vertical {
            return Err(STILL.bad(
                "cut",
                "a vertical (hill-and-dale) cut does not move the borders seen from above; use lateral or stereo",
            ));
        }
        if !(1..=64).contains(&self.grooves) {
            return Err(STILL.bad("grooves", format!("must be 1–64, got {}", self.grooves)));
        }
        STILL.positive("pitch_um", self.pitch_um)?;
        STILL.positive("top_width_um", self.top_width_um)?;
        STILL.within(
            "bottom_width_um",
            self.bottom_width_um,
            0.0,
            self.top_width_um,
        )?;
        if self.top_width_um >= self.pitch_um {
            return Err(STILL.bad(
                "top_width_um",
                format!(
                    "{} µm wide grooves do not fit {} µm apart",
                    self.top_width_um, self.pitch_um
                ),
            ));
        }
        STILL.within("wall_angle_deg", self.wall_angle_deg, 10.0, 80.0)?;
        let walls = if self.cut == Cut::Stereo { 2 } else { 1 };
        if !self.tones_hz.is_empty() && self.tones_hz.len() != walls * self.grooves {
            return Err(STILL.bad(
                "tones_hz",
                format!(
                    "needs {} tones ({} per groove for a {:?} cut), got {}",
                    walls * self.grooves,
                    walls,
                    self.cut,
                    self.tones_hz.len()
                ),
            ));
        }
        for &f in &self.tones_hz {
            STILL.positive("tones_hz", f)?;
        }
        STILL.within("peak_velocity_mm_s", self.peak_velocity_mm_s, 0.0, 1e4)?;
        STILL.within("start_secs", self.start_secs, -1e6, 1e6)?;
        STILL.within("drift_um", self.drift_um, -1e7, 1e7)?;
        STILL.within("wander_um", self.wander_um, 0.0, 1e7)?;
        STILL.positive("wander_period_um", self.wander_period_um)?;
        for (key, v) in [
            ("land_level", self.land_level),
            ("wall_level", self.wall_level),
            ("bottom_level", self.bottom_level),
            ("rim_level", self.rim_level),
            ("rim_fraction", self.rim_fraction),
        ] {
            STILL.within(key, v, 0.0, 1.0)?;
        }
        STILL.within("wall_level_spread", self.wall_level_spread, 0.0, 0.9)?;
        STILL.within("rim_width_um", self.rim_width_um, 0.0, 1e4)?;
        STILL.within("texture", self.texture, 0.0, 1.0)?;
        STILL.positive("texture_scale_um", self.texture_scale_um)?;
        STILL.within(
            "illumination_unevenness",
            self.illumination_unevenness,
            0.0,
            0.9,
        )?;
        STILL.within("dust_per_mpx", self.dust_per_mpx, 0.0, 1e5)?;
        STILL.within("dust_max_radius_px", self.dust_max_radius_px, 0.5, 1e3)?;
        if self.text_height_px > 0 && self.text_height_px < 7 {
            return Err(STILL.bad(
                "text_height_px",
                format!(
                    "must be 0 (no text) or at least 7, got {}",
                    self.text_height_px
                ),
            ));
        }
        STILL.within("blur_sigma_px", self.blur_sigma_px, 0.0, 32.0)?;
        STILL.within("noise_sigma", self.noise_sigma, 0.0, 0.5)?;
        if self.bit_depth != 8 && self.bit_depth != 16 {
            return Err(STILL.bad(
                "bit_depth",
                format!("must be 8 or 16, got {}", self.bit_depth),
            ));
        }
        if !matches!(self.format.as_str(), "png" | "tiff") {
            return Err(STILL.bad(
                "format",
                format!("must be png or tiff, got {:?}", self.format),
            ));
        }
        let inner_mm = self.radius_mm - self.pitch_um / 1000.0 * self.grooves as f64;
        if inner_mm <= 0.0 {
            return Err(STILL.bad(
                "radius_mm",
                format!(
                    "{} grooves {} µm apart do not fit inside a radius of {} mm",
                    self.grooves, self.pitch_um, self.radius_mm
                ),
            ));
        }
        Ok(())
    }
}
