//! Exports from the workbench: the clip (or a selection) as WAV with a JSON sidecar that records
//! the params it was made with, and views as PNG. Nothing is overwritten unless the caller says
//! so. (Presets are saved and loaded by [`super::tuning`].)

use std::path::{Path, PathBuf};

use serde::Serialize;

use super::recon::Clip;
use super::tuning::ParamState;
use crate::engine::GroupReport;
use crate::io::lock::OutputLock;
use crate::io::wav::{Audio, WavBits, write_transfer_wav};
use crate::io::write_atomic;
use crate::pipeline::audio_signal::resample;
use crate::pipeline::eval::Scores;

/// A way to write the clip, as the export menu offers it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ExportFormat {
    /// Name in the menu.
    pub name: &'static str,
    /// Sample encoding.
    pub bits: WavBits,
    /// Sample rate written (None: the clip's own).
    pub rate_hz: Option<u32>,
    /// What it is for, in one line.
    pub reason: &'static str,
}

/// The export formats offered, the first the default.
pub const EXPORT_FORMATS: [ExportFormat; 3] = [
    ExportFormat {
        name: "archive (24-bit)",
        bits: WavBits::Int24,
        rate_hz: None,
        reason: "24-bit at the reconstruction's rate: keeps all the detail the clip holds",
    },
    ExportFormat {
        name: "plain 16-bit 44.1 kHz",
        bits: WavBits::Int16,
        rate_hz: Some(44_100),
        reason: "16-bit at 44.1 kHz, as on a CD: plays in any software or player (resampled \
                 when the clip has another rate)",
    },
    ExportFormat {
        name: "32-bit float",
        bits: WavBits::Float32,
        rate_hz: None,
        reason: "32-bit float at the reconstruction's rate: for further processing, no rounding",
    },
];

/// The sidecar report written beside an exported WAV (`NAME.wav` → `NAME.json`).
#[derive(Debug, Serialize)]
pub struct Sidecar {
    /// The program and version that wrote it.
    pub generator: String,
    /// The scan folder.
    pub scan: PathBuf,
    /// Groups the exported stretch covers (start, end exclusive): those whose sound overlaps
    /// it.
    pub groups: [usize; 2],
    /// Groups the clip was reconstructed from (start, end exclusive).
    pub clip_groups: [usize; 2],
    /// Exported stretch (seconds from the clip start).
    pub selection_secs: [f64; 2],
    /// Sample rate written (Hz).
    pub sample_rate_hz: u32,
    /// The clip's own rate when the export was resampled to another (Hz).
    pub resampled_from_hz: Option<u32>,
    /// Sample encoding.
    pub bits: WavBits,
    /// Where the params came from when the clip was reconstructed: `defaults` or a preset file,
    /// and whether they had been changed since (then `preset` below, not the file, is what ran).
    pub params_state: ParamState,
    /// Preset file the params came from, if any.
    pub preset_file: Option<PathBuf>,
    /// The params the clip was made with, in full (`PipelineParams` TOML).
    pub preset: String,
    /// The filters the sound went through, in order and in words (phase included).
    pub filters: String,
    /// Scores against the reference, if any.
    pub scores: Option<Scores>,
    /// Per-group report.
    pub group_reports: Vec<GroupReport>,
    /// Warnings of the reconstruction.
    pub warnings: Vec<String>,
}

/// The sidecar path of a WAV path.
#[must_use]
pub fn sidecar_path(wav: &Path) -> PathBuf {
    wav.with_extension("json")
}

/// True when writing `wav` would replace a file (the WAV or its sidecar).
#[must_use]
pub fn would_overwrite(wav: &Path) -> bool {
    wav.exists() || sidecar_path(wav).exists()
}

/// Samples `[start, end)` of the clip for a selection in seconds (the whole clip when None).
#[must_use]
pub fn selection_samples(clip: &Clip, selection_secs: Option<(f64, f64)>) -> (usize, usize) {
    let n = clip.recon.audio.len();
    let rate = f64::from(clip.rate_hz());
    match selection_secs {
        Some((a, b)) if b > a => {
            let s = ((a.max(0.0) * rate).floor() as usize).min(n);
            let e = ((b * rate).ceil() as usize).clamp(s, n);
            (s, e)
        }
        _ => (0, n),
    }
}

/// The groups (start, end exclusive) whose sound overlaps `[a, b]` seconds of the clip; the
/// clip's groups when none does (a selection over gaps only).
fn groups_covering(clip: &Clip, a: f64, b: f64) -> [usize; 2] {
    let (lo, hi) = clip
        .tracks
        .iter()
        .filter(|t| clip.secs_at_um(t.span_um.0) < b && clip.secs_at_um(t.span_um.1) > a)
        .fold((usize::MAX, 0), |(lo, hi), t| {
            (lo.min(t.group), hi.max(t.group + 1))
        });
    if lo < hi {
        [lo, hi]
    } else {
        [clip.groups.start, clip.groups.end]
    }
}

/// Writes the clip (or the selection) as a Broadcast WAV, at `rate_hz` when given
/// (resampled), plus its sidecar report, which records the params the clip was made with and
/// where they came from; the WAV's `bext` chunk names the clip's scan and params.
///
/// # Errors
/// A message naming the file when it exists and `overwrite` is false, the selection is empty,
/// or a write fails.
pub fn export_wav(
    clip: &Clip,
    path: &Path,
    bits: WavBits,
    rate_hz: Option<u32>,
    selection_secs: Option<(f64, f64)>,
    overwrite: bool,
) -> Result<(), String> {
    // Another window exporting to the same file is refused, so a WAV and its sidecar always
    // come from one export.
    let _lock = OutputLock::acquire(path).map_err(|e| e.to_string())?;
    if !overwrite && would_overwrite(path) {
        return Err(format!(
            "refusing to overwrite an existing file: {}",
            path.display()
        ));
    }
    let (s, e) = selection_samples(clip, selection_secs);
    if e <= s {
        return Err(format!("the selection is empty: {}", path.display()));
    }
    let rate_out = rate_hz.unwrap_or(clip.rate_hz());
    let channels = clip
        .recon
        .audio
        .channels
        .iter()
        .map(|c| {
            let part = c.get(s..e).unwrap_or(&[]);
            if rate_out == clip.rate_hz() {
                Ok(part.to_vec())
            } else {
                resample(part, f64::from(clip.rate_hz()), rate_out).map_err(|err| {
                    format!(
                        "cannot resample to {rate_out} Hz: {err}: {}",
                        path.display()
                    )
                })
            }
        })
        .collect::<Result<Vec<_>, String>>()?;
    let audio = Audio {
        sample_rate_hz: rate_out,
        channels,
    };
    let preset = clip.params.to_toml_string().map_err(|e| e.to_string())?;
    let rate = f64::from(clip.rate_hz());
    let sidecar = Sidecar {
        generator: format!("groovescope {} workbench", env!("CARGO_PKG_VERSION")),
        scan: clip.scan_dir.clone(),
        groups: groups_covering(clip, s as f64 / rate, e as f64 / rate),
        clip_groups: [clip.groups.start, clip.groups.end],
        selection_secs: [s as f64 / rate, e as f64 / rate],
        sample_rate_hz: rate_out,
        resampled_from_hz: (rate_out != clip.rate_hz()).then_some(clip.rate_hz()),
        bits,
        params_state: clip.param_state.clone(),
        preset_file: clip.param_state.preset_file().map(Path::to_path_buf),
        preset,
        filters: crate::pipeline::finish::describe_filters(&clip.params.dsp, clip.recon.method),
        scores: clip.recon.scores,
        group_reports: clip.recon.groups.clone(),
        warnings: clip.recon.warnings.clone(),
    };
    let json = serde_json::to_string_pretty(&sidecar).map_err(|e| e.to_string())?;
    let params_fingerprint = crate::side::params_fingerprint(&clip.params);
    let info = crate::side::cli::transfer_info(
        &clip.scan_meta,
        &clip.params,
        &clip.recon,
        (&clip.scan_fingerprint, &params_fingerprint),
        (&audio, bits),
    );
    write_transfer_wav(path, &audio, bits, overwrite, &info).map_err(|e| e.to_string())?;
    write_atomic(&sidecar_path(path), json.as_bytes(), overwrite).map_err(|e| e.to_string())
}

/// Saves a screen capture as PNG.
///
/// # Errors
/// A message naming the file when it exists and `overwrite` is false, or the write fails.
pub fn save_color_image(
    img: &egui::ColorImage,
    path: &Path,
    overwrite: bool,
) -> Result<(), String> {
    let [w, h] = img.size;
    let Some(buf) = image::RgbaImage::from_raw(w as u32, h as u32, img.as_raw().to_vec()) else {
        return Err(format!(
            "image size does not match its data: {}",
            path.display()
        ));
    };
    crate::io::write_atomic_with(path, overwrite, |wr| {
        image::DynamicImage::ImageRgba8(buf)
            .write_to(wr, image::ImageFormat::Png)
            .map_err(std::io::Error::other)
    })
    .map_err(|e| e.to_string())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;
    use crate::test_support::path_in_temp_dir;

    #[test]
    fn png_capture_is_written_once() {
        let (_dir, p) = path_in_temp_dir("v.png");
        let img = egui::ColorImage::filled([4, 3], egui::Color32::RED);
        save_color_image(&img, &p, false).unwrap();
        assert!(save_color_image(&img, &p, false).is_err());
        let back = image::open(&p).unwrap().to_rgba8();
        assert_eq!(back.dimensions(), (4, 3));
        assert_eq!(back.get_pixel(2, 1).0, [255, 0, 0, 255]);
    }
}
