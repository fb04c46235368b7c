//! The accuracy suite: renders ground-truth scans and depth scenes, reconstructs them with the engine and reports the scores as markdown.
//!
//! Every figure in the report is measured here against what the generator knows: the
//! reference sound of a scan (r, envelope r, SNR from [`crate::pipeline::eval`]) or the true
//! depth map of a scene (the paper's Table 2 error bands). Nothing is typed in by hand.

mod kept;
pub mod methods;
mod scenes;
mod suite;

pub use kept::{KEPT_BEGIN, KEPT_END, kept_blocks, with_kept};
pub use scenes::{DepthErrors, SceneDepthRow, depth_errors, scene_depth_table};
pub use suite::run_suite;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use crate::engine::{ReconstructOptions, reconstruct};
use crate::io::wav::Audio;
use crate::io::{Scan, write_atomic};
use crate::job::Job;
use crate::pipeline::PipelineParams;
use crate::pipeline::audio_signal::SoundParams;
use crate::pipeline::eval::Scores;
use crate::synth::{BUILTIN_RATE_HZ, DamageConfig, SynthConfig, render_scan, tone};

/// Sound rendered beyond the last group's span (s): the generator never runs short.
const SOUND_MARGIN_SECS: f64 = 0.01;

/// Output rate the report's sound cases are scored at (the engine's default), Hz.
fn output_rate_hz() -> f64 {
    f64::from(SoundParams::default().output_rate_hz)
}
/// The paper's Table 2 frames (1-based there; here the frame index from 0 of a 40-frame scene).
pub const TABLE2_FRAMES: [usize; 4] = [7, 19, 27, 36];
/// The phrase spoken by `espeak-ng` for the speech cases.
pub const PHRASE: &str = "groove scope";

/// Why the suite could not run.
#[derive(Debug, thiserror::Error)]
pub enum AccuracyError {
    /// The report file exists and overwriting was not asked for.
    #[error("the report already exists (use --force to replace it): {}", .0.display())]
    ReportExists(PathBuf),
    /// The folder the report is to go in does not exist.
    #[error("the report's folder does not exist: {}", .0.display())]
    NoReportFolder(PathBuf),
    /// A case failed; the message names the case.
    #[error("{case}: {problem}")]
    Case {
        /// Which case.
        case: String,
        /// What went wrong.
        problem: String,
    },
    /// Writing the report or a work folder failed.
    #[error(transparent)]
    Io(#[from] crate::io::LoadError),
}

fn case_err(case: &str, e: impl std::fmt::Display) -> AccuracyError {
    AccuracyError::Case {
        case: case.to_string(),
        problem: e.to_string(),
    }
}

/// The "small camera" of the sound cases: 0.78 µm pixels (about 200×), 320×384 px frames, 7
/// frames a group, a 16⅔ rpm transcription disc at 60 mm (Vt ≈ 105 mm/s, so one group spans
/// about 2.2 ms of sound), with the dual-focus cover glass of paper §9.
#[must_use]
pub fn small_dual_focus(groups: usize) -> SynthConfig {
    SynthConfig {
        width_px: 320,
        height_px: 384,
        pixel_pitch_um: 0.78,
        frame_step_um: 1.56,
        frames_per_group: 7,
        group_overlap_px: 24,
        rpm: 16.667,
        radius_mm: 60.0,
        bit_depth: 8,
        noise_sigma_8bit: 0.5,
        max_groups: Some(groups),
        ..SynthConfig::dual_focus_demo()
    }
}

/// The same camera and disc without the cover glass and depth-of-field blur, with 12 frames a
/// group: the depth path's case (flow → Kalman depth → orientation).
#[must_use]
pub fn small_lateral(groups: usize) -> SynthConfig {
    SynthConfig {
        working_distance_mm: 4.0,
        numerical_aperture: 0.0,
        dual_focus: None,
        frames_per_group: 12,
        groove_top_width_um: 180.0,
        groove_depth_um: 70.0,
        ..small_dual_focus(groups)
    }
}

/// Scratches, dust and missing wall chunks for the damaged-groove cases.
#[must_use]
pub fn heavy_damage() -> DamageConfig {
    DamageConfig {
        scratches_per_mm: 6.0,
        dust_per_mm2: 60.0,
        missing_wall_chunks_per_mm: 2.0,
        chunk_length_um: 150.0,
        chunk_wall_fraction: 0.45,
        ..DamageConfig::default()
    }
}

/// The orientation neighbourhood that spans about two output samples along the groove
/// (odd, at least 5 px): the smallest window that does not low-pass the sound below Nyquist.
#[must_use]
pub fn two_sample_window_px(cfg: &SynthConfig) -> usize {
    let spacing_px = cfg.groove_speed_um_s() / output_rate_hz() / cfg.pixel_pitch_um;
    let n = (2.0 * spacing_px).round().max(5.0) as usize;
    n | 1
}

/// Params of the sound cases: the defaults with the low-pass off (so tones above 3 kHz are
/// measured, not filtered away), the given orientation window and robust switch, and the flow
/// method (the suite's cases measure it; [`methods`] scores the decoders side by side).
#[must_use]
pub fn sound_params(window_px: usize, robust: bool) -> PipelineParams {
    let mut p = PipelineParams {
        method: crate::pipeline::Method::Flow,
        ..PipelineParams::default()
    };
    p.dsp.lowpass = false;
    p.orientation.neighbourhood_px = window_px;
    p.orientation.robust = robust;
    p
}

/// SNR (dB) that a signal with correlation `r` to its reference would have if the difference
/// were independent noise: 10·log10(r² / (1 − r²)).
#[must_use]
pub fn snr_from_r_db(r: f64) -> f64 {
    let r2 = (r * r).min(1.0 - 1e-12);
    10.0 * (r2 / (1.0 - r2)).log10()
}

/// Renders a scan of `sound` with `cfg` into `dir` (which must not exist or be empty).
///
/// # Errors
/// The generator's error, named by `case`.
pub fn render(
    case: &str,
    sound: &Audio,
    cfg: &SynthConfig,
    dir: &Path,
) -> Result<(), AccuracyError> {
    render_scan(sound, cfg, dir, Job::reporting(&|_, _| {}))
        .map(|_| ())
        .map_err(|e| case_err(case, e))
}

/// Seconds of sound that `cfg.max_groups` groups cover (with a margin).
#[must_use]
pub fn scan_secs(cfg: &SynthConfig) -> f64 {
    let groups = cfg.max_groups.unwrap_or(1) as f64;
    groups * cfg.group_span_um() / cfg.groove_speed_um_s() + SOUND_MARGIN_SECS
}

/// Renders a scan of a `freq_hz` tone long enough for `cfg.max_groups` groups into `dir`.
///
/// # Errors
/// As [`render`].
pub fn render_tone(
    case: &str,
    freq_hz: f64,
    cfg: &SynthConfig,
    dir: &Path,
) -> Result<(), AccuracyError> {
    render(
        case,
        &tone(freq_hz, scan_secs(cfg), BUILTIN_RATE_HZ),
        cfg,
        dir,
    )
}

/// Reconstructs the scan in `dir` with `params` and scores it against its `reference.wav`;
/// also returns the wall-clock seconds.
///
/// # Errors
/// The engine's error, named by `case`; a scan without a reference is an error.
pub fn score_scan(
    case: &str,
    dir: &Path,
    params: &PipelineParams,
) -> Result<(Scores, f64), AccuracyError> {
    let scan = Scan::open(dir).map_err(|e| case_err(case, e))?;
    let opts = ReconstructOptions {
        params: params.clone(),
        groups: None,
        keep_going: true,
    };
    let t = Instant::now();
    let rec = reconstruct(&scan, &opts, &mut |_| {}, crate::job::interrupted())
        .map_err(|e| case_err(case, e))?;
    let secs = t.elapsed().as_secs_f64();
    let scores = rec
        .scores
        .ok_or_else(|| case_err(case, "the scan has no reference.wav to score against"))?;
    Ok((scores, secs))
}

/// Speaks `phrase` with `espeak-ng` into a WAV file in `dir`; `None` when espeak-ng is missing
/// or fails (the report then says the speech cases were skipped).
#[must_use]
pub fn speak(phrase: &str, dir: &Path) -> Option<PathBuf> {
    let path = dir.join("speech.wav");
    let ok = Command::new("espeak-ng")
        .args(["-s", "160", "-w"])
        .arg(&path)
        .arg(phrase)
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    (ok && path.is_file()).then_some(path)
}

/// First time (s) the sound rises above 2% of its peak (skips leading silence).
#[must_use]
pub fn onset_secs(audio: &Audio) -> f64 {
    let Some(ch) = audio.channels.first() else {
        return 0.0;
    };
    let peak = ch.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    let first = ch.iter().position(|v| v.abs() > 0.02 * peak).unwrap_or(0);
    first as f64 / f64::from(audio.sample_rate_hz)
}

/// Settings of a suite run.
#[derive(Clone, Debug, Default)]
pub struct AccuracyOptions {
    /// Fewer, shorter cases (about a minute): tones 500 Hz–5 kHz, 0.1 s of speech, no melody.
    pub quick: bool,
    /// Keep the rendered scans in this folder (must not exist or be empty) instead of a
    /// temporary one.
    pub keep: Option<PathBuf>,
}

/// Runs the suite and writes the report to `out` atomically; refuses an existing file unless
/// `force`, and a folder that does not exist. The checks come first, so nothing runs for a
/// refused report. A replaced report's hand-run sections (between [`KEPT_BEGIN`] and
/// [`KEPT_END`]) are kept verbatim ([`with_kept`]).
///
/// # Errors
/// [`AccuracyError::ReportExists`], [`AccuracyError::NoReportFolder`], or the suite's or the
/// write's error.
pub fn write_report(
    out: &Path,
    force: bool,
    opts: &AccuracyOptions,
    log: &mut dyn FnMut(&str),
) -> Result<(), AccuracyError> {
    if out.exists() && !force {
        return Err(AccuracyError::ReportExists(out.to_path_buf()));
    }
    if let Some(folder) = out.parent().filter(|f| !f.as_os_str().is_empty())
        && !folder.is_dir()
    {
        return Err(AccuracyError::NoReportFolder(folder.to_path_buf()));
    }
    let md = run_suite(opts, log)?;
    let md = match std::fs::read_to_string(out) {
        Ok(old) => with_kept(&md, &old),
        Err(e) => {
            if out.exists() {
                log(&format!(
                    "kept no section of {} (unreadable: {e})",
                    out.display()
                ));
            }
            md
        }
    };
    write_atomic(out, md.as_bytes(), force)?;
    Ok(())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;

    #[test]
    fn a_report_in_a_missing_folder_is_refused_before_the_suite_runs() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("missing").join("report.md");
        let mut logged = Vec::new();
        let e = write_report(&out, false, &AccuracyOptions::default(), &mut |l| {
            logged.push(l.to_string());
        })
        .unwrap_err();
        assert!(matches!(e, AccuracyError::NoReportFolder(_)), "{e}");
        assert!(e.to_string().ends_with("missing"), "{e}");
        assert!(logged.is_empty(), "the suite ran: {logged:?}");
    }

    #[test]
    fn snr_from_r_and_window() {
        assert!(snr_from_r_db(0.0) < -100.0);
        assert!((snr_from_r_db((0.5f64).sqrt())).abs() < 1e-9);
        assert!((snr_from_r_db(0.995) - 19.98).abs() < 0.05);
        let w = two_sample_window_px(&small_dual_focus(1));
        assert_eq!(w % 2, 1);
        assert!((5..=9).contains(&w), "{w}");
        // The paper's optics: ≈ 21 µm per output sample at 0.39 µm/px → ≈ 109 px.
        let paper = two_sample_window_px(&SynthConfig::default());
        assert!((101..=121).contains(&paper), "{paper}");
    }
}
