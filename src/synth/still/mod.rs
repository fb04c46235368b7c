//! Top-view stills for the still decoder: neighbouring turns of a spiral groove seen from above,
//! each wall cut with a known sound, rendered with real micrographs' troubles (dust, burnt-in
//! text, uneven light, rims on some walls, drift, close neighbours, blur, noise).
//!
//! [`write_still`] writes a folder:
//! - `still.png` or `still.tif` (8 or 16 bit grey),
//! - `groove1.wav`, `groove2.wav`, …: each groove's sound from the image's first line to its
//!   last (32-bit float, cutter velocity / `peak_velocity_mm_s`; mono for lateral, left and
//!   right wall for stereo),
//! - `truth.toml` (written last): `[truth]` ([`StillTruth`]: what to pass to `groovescope still`,
//!   each groove's radius, speed, tones, position and rims) and `[still]` (the [`StillConfig`]).
//!
//! Grooves are numbered from 1 from the image's left (vertical) or top (horizontal), as
//! `groovescope still --groove N` counts them. Same config, sound and seed give the same bytes.

pub mod config;
pub mod font;
pub mod raster;
pub mod scene;

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests;

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

pub use config::{StillConfig, default_tones_hz};
pub use raster::{StillImage, render_still};
pub use scene::{Borders, Motion, StillGroove, StillScene};

use crate::io::Cut;
use crate::io::still::save_grey_image;
use crate::io::wav::{Audio, WavBits, write_wav};
use crate::pipeline::still::Axis;
use crate::synth::{BUILTIN_RATE_HZ, SynthError, fill_out_dir};

/// One groove's ground truth in the sidecar.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StillGrooveTruth {
    /// `--groove` number (from 1, from the image's left or top).
    pub number: usize,
    /// Radius (pass as `--radius-mm`).
    pub radius_mm: f64,
    /// Groove speed Vt.
    pub groove_speed_mm_s: f64,
    /// Samples per second along the groove: Vt / pixel size.
    pub line_rate_hz: f64,
    /// Time of the first line in the groove's sound.
    pub start_secs: f64,
    /// Its sound file in the folder.
    pub reference: String,
    /// The tones cut: one (lateral) or left and right wall (stereo); empty for a given sound.
    pub tones_hz: Vec<f64>,
    /// Centre line across the image at the first and the last line (pixel-centre coordinates).
    pub centre_px: [f64; 2],
    /// Outermost borders over the whole image, across (pixel-centre coordinates).
    pub extent_px: [f64; 2],
    /// Bright rim on the left and on the right wall.
    pub rims: [bool; 2],
}

/// What a still holds (the sidecar's `[truth]` table).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StillTruth {
    /// The image file in the folder.
    pub image: String,
    /// Image width.
    pub width_px: usize,
    /// Image height.
    pub height_px: usize,
    /// Pass as `--axis`.
    pub axis: Axis,
    /// The cut.
    pub cut: Cut,
    /// Pass as `--um-per-px`.
    pub um_per_px: f64,
    /// Pass as `--rpm`.
    pub rpm: f64,
    /// Where the left wall is: the wall on the left hand when facing the way time runs.
    pub left_wall: String,
    /// Dust particles laid.
    pub dust_particles: usize,
    /// Box of the burnt-in text and scale bar `[x0, y0, x1, y1]`.
    pub text_box: Option<[usize; 4]>,
    /// Every groove, in `--groove` order.
    pub grooves: Vec<StillGrooveTruth>,
}

/// The sidecar file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StillSidecar {
    /// What the still holds.
    pub truth: StillTruth,
    /// The settings it was made with.
    pub still: StillConfig,
}

/// Groove `k`'s sound over the image (velocity / peak, mono or left+right) at `rate_hz`.
#[must_use]
pub fn groove_reference(scene: &StillScene, k: usize, rate_hz: u32) -> Audio {
    let c = &scene.cfg;
    let p = c.um_per_px;
    let (Some(g), true) = (scene.grooves.get(k), rate_hz > 0) else {
        return Audio {
            sample_rate_hz: rate_hz,
            channels: Vec::new(),
        };
    };
    let t0 = scene.time_secs(k, 0.5 * p);
    let t1 = scene.time_secs(k, (c.length_px as f64 - 0.5) * p);
    let rate = f64::from(rate_hz);
    let n = ((t1 - t0) * rate).floor().max(0.0) as usize + 1;
    let peak = c.peak_velocity_mm_s * 1000.0;
    let norm = if peak > 0.0 { 1.0 / peak } else { 0.0 };
    let chan = |m: &Motion| -> Vec<f32> {
        (0..n)
            .map(|i| (m.at(t0 + i as f64 / rate).1 * norm) as f32)
            .collect()
    };
    let channels = if c.cut == Cut::Stereo {
        vec![chan(&g.left), chan(&g.right)]
    } else {
        vec![chan(&g.left)]
    };
    Audio {
        sample_rate_hz: rate_hz,
        channels,
    }
}

/// The sidecar's `[truth]` of a rendered scene.
#[must_use]
pub fn still_truth(scene: &StillScene, rendered: &StillImage, image_name: &str) -> StillTruth {
    let c = &scene.cfg;
    let left = scene.left_wall_index();
    let grooves = scene
        .grooves
        .iter()
        .enumerate()
        .map(|(k, g)| {
            let first = scene.borders_px(k, 0);
            let last = scene.borders_px(k, c.length_px - 1);
            let (lo, hi) = (0..c.length_px).fold((f64::MAX, f64::MIN), |(lo, hi), n| {
                let b = scene.borders_px(k, n);
                (lo.min(b[0]), hi.max(b[3]))
            });
            StillGrooveTruth {
                number: k + 1,
                radius_mm: g.radius_mm,
                groove_speed_mm_s: g.vt_um_s / 1000.0,
                line_rate_hz: g.vt_um_s / c.um_per_px,
                start_secs: scene.time_secs(k, 0.5 * c.um_per_px),
                reference: format!("groove{}.wav", k + 1),
                tones_hz: match (g.tones_hz, c.cut) {
                    (Some((l, r)), Cut::Stereo) => vec![l, r],
                    (Some((l, _)), _) => vec![l],
                    (None, _) => Vec::new(),
                },
                centre_px: [0.5 * (first[0] + first[3]), 0.5 * (last[0] + last[3])],
                extent_px: [lo, hi],
                rims: [g.rims[left], g.rims[1 - left]],
            }
        })
        .collect();
    StillTruth {
        image: image_name.to_string(),
        width_px: rendered.image.width,
        height_px: rendered.image.height,
        axis: c.axis,
        cut: c.cut,
        um_per_px: c.um_per_px,
        rpm: c.rpm,
        left_wall: match c.axis {
            Axis::Vertical => "the right-hand wall of each groove (time runs down)".into(),
            Axis::Horizontal => "the upper wall of each groove (time runs rightward)".into(),
        },
        dust_particles: rendered.dust_particles,
        text_box: rendered.text_box,
        grooves,
    }
}

/// What [`write_still`] wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct StillSummary {
    /// The image file.
    pub image: PathBuf,
    /// The sidecar.
    pub truth: StillTruth,
}

/// Renders `scene` and writes the folder `out_dir` (created, or empty): the image, one WAV per
/// groove and `truth.toml` last, in a hidden folder renamed into place when done (a failed or
/// killed run leaves no half folder).
///
/// # Errors
/// [`SynthError::OutputExists`] for a folder that is not empty, [`SynthError::Load`] for a
/// failed write (naming the file), [`SynthError::Config`] when the sidecar cannot be written.
pub fn write_still(scene: &StillScene, out_dir: &Path) -> Result<StillSummary, SynthError> {
    let c = &scene.cfg;
    fill_out_dir(out_dir, |dir| {
        let rendered = render_still(scene);
        let ext = if c.format == "tiff" { "tif" } else { "png" };
        let name = format!("still.{ext}");
        let image_path = dir.join(&name);
        save_grey_image(&rendered.image, &image_path, c.bit_depth == 16, false)?;
        let truth = still_truth(scene, &rendered, &name);
        for (k, g) in scene.grooves.iter().enumerate() {
            let rate = match &g.left {
                Motion::Sound { rate_hz, .. } => *rate_hz as u32,
                Motion::Tone { .. } => BUILTIN_RATE_HZ,
            };
            let audio = groove_reference(scene, k, rate);
            write_wav(
                &dir.join(format!("groove{}.wav", k + 1)),
                &audio,
                WavBits::Float32,
                false,
            )?;
        }
        let sidecar = StillSidecar {
            truth: truth.clone(),
            still: c.clone(),
        };
        let text = toml::to_string_pretty(&sidecar).map_err(|e| SynthError::Config {
            key: "still".into(),
            problem: format!("cannot be written as TOML: {e}"),
        })?;
        let header = "# A generated still (groovescope synth-still) and its ground truth.\n";
        crate::io::write_atomic(
            &dir.join("truth.toml"),
            format!("{header}{text}").as_bytes(),
            false,
        )?;
        Ok(StillSummary {
            image: out_dir.join(&name),
            truth,
        })
    })
}
