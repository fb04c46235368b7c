//! Exports from the workbench: the clip (or a selection) as WAV with a JSON sidecar that records
//! the preset, presets as TOML, and views as PNG. Nothing is overwritten unless the caller says so.

use std::path::{Path, PathBuf};

use serde::Serialize;

use super::recon::Clip;
use crate::engine::GroupReport;
use crate::io::lock::OutputLock;
use crate::io::wav::{Audio, WavBits, write_wav};
use crate::io::write_atomic;
use crate::pipeline::PipelineParams;
use crate::pipeline::eval::Scores;

/// The sidecar report written beside an exported WAV (`NAME.wav` → `NAME.json`).
#[derive(Debug, Serialize)]
pub struct Sidecar {
    /// The program and version that wrote it.
    pub generator: String,
    /// The scan folder.
    pub scan: PathBuf,
    /// Groups reconstructed (start, end exclusive).
    pub groups: [usize; 2],
    /// Exported stretch (seconds from the clip start).
    pub selection_secs: [f64; 2],
    /// Sample rate (Hz).
    pub sample_rate_hz: u32,
    /// Sample encoding.
    pub bits: WavBits,
    /// Preset file the params came from, if one was loaded.
    pub preset_file: Option<PathBuf>,
    /// The full preset (`PipelineParams` TOML).
    pub preset: String,
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

/// Writes the clip (or the selection) as WAV plus its sidecar report.
///
/// # Errors
/// A message naming the file when it exists and `overwrite` is false, the selection is empty,
/// or a write fails.
pub fn export_wav(
    clip: &Clip,
    path: &Path,
    bits: WavBits,
    selection_secs: Option<(f64, f64)>,
    preset_file: Option<&Path>,
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
    let audio = Audio {
        sample_rate_hz: clip.rate_hz(),
        channels: clip
            .recon
            .audio
            .channels
            .iter()
            .map(|c| c[s..e].to_vec())
            .collect(),
    };
    let preset = clip.params.to_toml_string().map_err(|e| e.to_string())?;
    let rate = f64::from(clip.rate_hz());
    let sidecar = Sidecar {
        generator: format!("groovescope {} workbench", env!("CARGO_PKG_VERSION")),
        scan: clip.scan_dir.clone(),
        groups: [clip.groups.start, clip.groups.end],
        selection_secs: [s as f64 / rate, e as f64 / rate],
        sample_rate_hz: clip.rate_hz(),
        bits,
        preset_file: preset_file.map(Path::to_path_buf),
        preset,
        scores: clip.recon.scores,
        group_reports: clip.recon.groups.clone(),
        warnings: clip.recon.warnings.clone(),
    };
    let json = serde_json::to_string_pretty(&sidecar).map_err(|e| e.to_string())?;
    write_wav(path, &audio, bits, overwrite).map_err(|e| e.to_string())?;
    write_atomic(&sidecar_path(path), json.as_bytes(), overwrite).map_err(|e| e.to_string())
}

/// Saves `params` as a TOML preset.
///
/// # Errors
/// A message naming the file when it exists and `overwrite` is false, or the write fails.
pub fn save_preset(params: &PipelineParams, path: &Path, overwrite: bool) -> Result<(), String> {
    let text = params.to_toml_string().map_err(|e| e.to_string())?;
    let _lock = OutputLock::acquire(path).map_err(|e| e.to_string())?;
    write_atomic(path, text.as_bytes(), overwrite).map_err(|e| e.to_string())
}

/// Reads and validates a TOML preset.
///
/// # Errors
/// A message naming the file and the bad key or value.
pub fn load_preset(path: &Path) -> Result<PipelineParams, String> {
    let text = crate::io::limits::read_toml_text(path, "preset").map_err(|e| e.to_string())?;
    let params = PipelineParams::from_toml_str(&text)
        .map_err(|e| format!("invalid preset: {e}: {}", path.display()))?;
    params
        .validate()
        .map_err(|e| format!("invalid preset: {e}: {}", path.display()))?;
    Ok(params)
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

    #[test]
    fn preset_round_trips_and_bad_presets_name_the_key() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("disc.toml");
        let mut params = PipelineParams::default();
        params.flow.lambda = 0.25;
        params.hough.theta_min_deg = -30.0;
        save_preset(&params, &p, false).unwrap();
        assert!(
            save_preset(&params, &p, false).is_err(),
            "no silent overwrite"
        );
        assert_eq!(load_preset(&p).unwrap(), params);
        std::fs::write(&p, "[flow]\nlamda = 3\n").unwrap();
        let err = load_preset(&p).unwrap_err();
        assert!(err.contains("lamda") && err.contains("disc.toml"), "{err}");
        std::fs::write(&p, "[flow]\nlambda = -3.0\n").unwrap();
        let err = load_preset(&p).unwrap_err();
        assert!(err.contains("flow.lambda"), "{err}");
    }

    #[test]
    fn png_capture_is_written_once() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("v.png");
        let img = egui::ColorImage::filled([4, 3], egui::Color32::RED);
        save_color_image(&img, &p, false).unwrap();
        assert!(save_color_image(&img, &p, false).is_err());
        let back = image::open(&p).unwrap().to_rgba8();
        assert_eq!(back.dimensions(), (4, 3));
        assert_eq!(back.get_pixel(2, 1).0, [255, 0, 0, 255]);
    }
}
