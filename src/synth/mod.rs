//! Ground-truth generator: ray-traces a sound's groove under a perspective microscope camera and
//! writes a scan folder (`scan.toml`, `gNNNNN/fNNN.png`, `reference.wav`), plus depth test scenes.
//!
//! # Conventions (identical to the engine's)
//! Pixel centres; principal point `cx = (W−1)/2`, `cy = (H−1)/2`. Record coordinates: `s` along
//! the groove (µm from the scan start, = X), `y` across (µm, 0 on the optical axis), `Z` the
//! distance from the optical centre (the land lies at the working distance `WD`). The camera of
//! frame `k` of group `g` sits above `cam_s = g·group_step + k·frame_step + cx·pitch`; pixel
//! `(x, y)` casts the ray `(s, y, Z) = (cam_s, 0, 0) + t·((x−cx)·p/WD, (y−cy)·p/WD, 1)`, so at the
//! land column `x` sees `s = g·group_step + k·frame_step + x·p` and content moves toward −x as
//! `k` grows. The ray meets the height field `Z = WD + depth(s, y)` exactly (fixed-point
//! iteration to 1e-6 µm), so deeper points move less between frames (parallax).
//!
//! The groove: cutter velocity ∝ sound (DC removed, scaled so max |V| = `peak_velocity_mm_s`),
//! time `t = start + s/Vt` with `Vt = 2π·rpm/60·R`; lateral displacement `d(s) = ∫ V dt`
//! (velocity linear between samples, integrated exactly; centred over the scan). The left wall
//! lies at smaller y (depth grows with y). Each wall's plane `Z = a·X + b·Y + c` has
//! `tan θ = −a·sign(b)/√(1+b²)` = that wall's velocity / Vt (derivation in [`groove`]).
//!
//! # Files written by [`render_scan`]
//! - `scan.toml`: [`crate::io::ScanMeta`] plus `[synth]` (the [`SynthConfig`]) and `[synth_info]`
//!   ([`SynthInfo`]: groups, scanned length, groove speed, reference scale, glass edge row).
//! - `g00000/f000.png …`: 8- or 16-bit grey frames (more digits when needed so names sort).
//! - `reference.wav`: 32-bit float, the sound's rate, the stretch from s = 0 to the scan's end,
//!   as cutter velocity / `peak_velocity_mm_s` (mono for lateral/vertical; left, right wall
//!   channels for stereo). Sample `i` is the velocity at `s = i·Vt/rate`.
//!
//! `scan.toml` is written last, so a cancelled or failed run never leaves a loadable scan.

pub mod blur;
pub mod config;
pub mod damage;
pub mod groove;
pub mod noise;
pub mod render;
pub mod scene;
pub mod sounds;
pub mod still;
#[cfg(test)]
pub(crate) mod test_support;
pub mod track;

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests;

use std::path::{Path, PathBuf};

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

pub use config::{DamageConfig, DualFocusConfig, SynthConfig, WallChunk};
pub use groove::{Groove, GrooveTruth, Optics, groove_truth};
pub use render::{RenderedFrame, render_frame};
pub use scene::{SceneConfig, SceneKind, SceneMeta, load_true_depth, render_scene};
pub use sounds::{BUILTIN_RATE_HZ, arpeggio, chord, melody, stereo, sweep, tone};

use crate::io::LoadError;
use crate::io::frames::save_grey_png;
use crate::io::scan::{
    CameraMeta, DualFocusMeta, FORMAT_VERSION, GlassSide, MotionMeta, NumberedNames, RecordMeta,
    ScanMeta,
};
use crate::io::wav::{Audio, WavBits, write_wav};
use crate::job::Job;

/// Why a scan or scene could not be generated.
#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    /// A setting is invalid or the geometry is absurd.
    #[error("invalid synth setting {key}: {problem}")]
    Config {
        /// The TOML key, such as `synth.groove_depth_um`.
        key: String,
        /// What is wrong.
        problem: String,
    },
    /// The sound cannot be cut (empty, zero rate, non-finite, too short).
    #[error("unusable sound: {problem}")]
    Sound {
        /// What is wrong.
        problem: String,
    },
    /// A file could not be read or written (the message names it).
    #[error(transparent)]
    Load(#[from] LoadError),
    /// The output folder exists and is not empty; nothing was written.
    #[error("refusing to write into a folder that is not empty: {}", path.display())]
    OutputExists {
        /// The folder.
        path: PathBuf,
    },
    /// The cancel flag was raised (the unfinished scan is removed).
    #[error("cancelled: the unfinished scan was removed")]
    Cancelled,
}

/// Derived facts written to `scan.toml` as `[synth_info]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SynthInfo {
    /// Groups written.
    pub groups: usize,
    /// Groove length covered at the land, µm.
    pub scan_length_um: f64,
    /// Groove speed Vt, mm/s.
    pub groove_speed_mm_s: f64,
    /// Sample rate of the sound and of `reference.wav`.
    pub sample_rate_hz: u32,
    /// Sound sample at s = 0.
    pub start_sample: i64,
    /// Samples in `reference.wav`.
    pub reference_samples: usize,
    /// Cutter velocity (mm/s) of a `reference.wav` sample of 1.0.
    pub reference_unit_mm_s: f64,
    /// Damage features laid out.
    pub damage_features: usize,
}

/// What [`render_scan`] wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct SynthSummary {
    /// The scan folder.
    pub out_dir: PathBuf,
    /// Groups written.
    pub groups: usize,
    /// Frames in each group.
    pub frames_per_group: usize,
    /// Groove length covered at the land, µm.
    pub scan_length_um: f64,
    /// Duration of `reference.wav`, s.
    pub reference_secs: f64,
    /// Groove speed Vt, mm/s.
    pub groove_speed_mm_s: f64,
    /// Image row of the cover-glass edge (dual focus only).
    pub glass_edge_row: Option<f64>,
    /// Damage features laid out.
    pub damage_features: usize,
    /// Non-fatal problems (for example focus stripes crossing the glass edge at loud passages).
    pub warnings: Vec<String>,
}

fn io_err(problem: String, path: &Path) -> SynthError {
    SynthError::Load(LoadError::Io {
        problem,
        path: path.to_path_buf(),
    })
}

/// Writes a new output folder through `fill`, which writes into the folder it is given: a
/// hidden temporary one beside `dir` ([`crate::io::staged`]), renamed to `dir` once `fill`
/// succeeds. `dir` must be missing or an empty folder (anything else is an error and nothing
/// is touched). When `fill` fails (a cancel, a full disk) the temporary folder is removed, and
/// one a killed run left is removed by the next run: `dir` never holds a half-written scan.
pub(crate) fn fill_out_dir<T>(
    dir: &Path,
    fill: impl FnOnce(&Path) -> Result<T, SynthError>,
) -> Result<T, SynthError> {
    if dir.exists() && !dir.is_dir() {
        return Err(io_err(
            "the output is a file; give a folder that is new or empty".into(),
            dir,
        ));
    }
    if !crate::io::atomic::dir_is_missing_or_empty(dir)? {
        return Err(SynthError::OutputExists {
            path: dir.to_path_buf(),
        });
    }
    let _ = crate::io::staged::remove_stale(dir, SYNTH_KIND);
    let staged = crate::io::staged::StagedDir::create(dir, SYNTH_KIND)?;
    let filled = fill(staged.path())?;
    staged.finish(dir)?;
    Ok(filled)
}

/// The kind in the names of the generators' temporary folders (`.NAME.synth-PID.tmp`).
const SYNTH_KIND: &str = "synth";

/// What the earlier generator runs into `dir` that never finished (killed outright, so they
/// could not clean up) left beside it: a line for each hidden `.NAME.synth-PID.tmp` folder.
/// Those whose process is gone and that nothing touched for an hour are removed
/// ([`crate::io::staged::remove_stale`], as `fill_out_dir` and the video import do); the others
/// are kept, since the process id may be another machine's run writing the same shared
/// folder, and named with why, so that a rerun is never confused by them in silence. A
/// command calls this before its run; the lines go to standard error.
#[must_use]
pub fn earlier_unfinished_runs(dir: &Path) -> Vec<String> {
    let removed = crate::io::staged::remove_stale(dir, SYNTH_KIND);
    let mut lines: Vec<String> = removed
        .iter()
        .map(|p| {
            format!(
                "removed an unfinished folder left by an earlier, killed generator run: {}",
                p.display()
            )
        })
        .collect();
    let kept = crate::io::staged::unfinished(dir, SYNTH_KIND)
        .into_iter()
        .filter(|&(_, pid)| pid != std::process::id());
    // Without /proc (not Linux) whether a process runs is not known, and nothing was removed.
    let proc_fs = Path::new("/proc/self").exists();
    for (path, pid) in kept {
        let path = path.display();
        lines.push(if !proc_fs {
            format!(
                "warning: an unfinished folder of another generator run (process {pid}: killed, or \
                 still writing) lies beside the output; remove it once no run writes it: {path}"
            )
        } else if Path::new("/proc").join(pid.to_string()).exists() {
            format!(
                "warning: process {pid} may be writing this output now (its unfinished folder \
                 lies beside it): {path}"
            )
        } else {
            format!(
                "warning: kept the unfinished folder of an earlier generator run (process {pid}, \
                 not running here: killed, or another machine's run still writing it); a later \
                 run removes it once nothing has written to it for an hour, or remove it \
                 yourself: {path}"
            )
        });
    }
    lines
}

/// The folder name of group `g` in a scan whose group numbers are padded to `digits`
/// (`g00012`): the generator, the video import's folders and its stores name groups alike.
#[must_use]
pub(crate) fn group_name(g: usize, digits: usize) -> String {
    format!("g{g:0digits$}")
}

/// Zero-padded width for `count` indices (at least `min` digits).
pub(crate) fn digits(count: usize, min: usize) -> usize {
    count.saturating_sub(1).max(1).to_string().len().max(min)
}

/// Renders `sound` as a scan into `out_dir` (created, or empty) and returns what was written.
///
/// `job` is told 0 first and then each finished group; cancelling it stops before the next
/// frame with [`SynthError::Cancelled`]. The scan is written in a hidden folder beside `out_dir`
/// and renamed into place when done (`fill_out_dir`), so a run that fails, is cancelled or is
/// killed leaves no half scan there. Frames of a group
/// render in parallel, rows in parallel within a frame. A WAV file's sound renders with
/// [`Groove::from_wav`] and [`write_scan`].
///
/// # Errors
/// [`SynthError::Config`] / [`SynthError::Sound`] from [`Groove::new`], [`SynthError::OutputExists`]
/// for a non-empty folder, [`SynthError::Load`] for write failures (naming the file),
/// [`SynthError::Cancelled`].
pub fn render_scan(
    sound: &Audio,
    cfg: &SynthConfig,
    out_dir: &Path,
    job: Job<'_>,
) -> Result<SynthSummary, SynthError> {
    let groove = Groove::new(sound, cfg)?;
    write_scan(&groove, out_dir, job)
}

/// The `scan.toml` metadata of a groove's scan.
///
/// # Errors
/// [`SynthError::Config`] if the settings cannot be written as TOML.
pub fn scan_meta(groove: &Groove) -> Result<ScanMeta, SynthError> {
    let cfg = groove.config();
    let optics = groove.optics();
    let dual_focus = match (&cfg.dual_focus, optics.glass_edge_row) {
        (Some(df), Some(row)) => Some(DualFocusMeta {
            focus_distance_mm: df.focus_distance_mm,
            glass_thickness_mm: df.glass_thickness_mm,
            glass_index: df.glass_index,
            glass_side: GlassSide::Top,
            glass_edge_row: row,
        }),
        _ => None,
    };
    let reference = groove.reference();
    let info = SynthInfo {
        groups: groove.groups(),
        scan_length_um: groove.scan_length_um(),
        groove_speed_mm_s: groove.groove_speed_mm_s(),
        sample_rate_hz: reference.sample_rate_hz,
        start_sample: groove.start_sample(),
        reference_samples: reference.len(),
        reference_unit_mm_s: cfg.peak_velocity_mm_s,
        damage_features: groove.damage_features(),
    };
    let to_table = |what: &str, v: Result<toml::Table, toml::ser::Error>| {
        v.map_err(|e| SynthError::Config {
            key: what.into(),
            problem: format!("cannot be written as TOML: {e}"),
        })
    };
    let mut extra = toml::Table::new();
    extra.insert(
        "synth".into(),
        toml::Value::Table(to_table("synth", toml::Table::try_from(cfg))?),
    );
    extra.insert(
        "synth_info".into(),
        toml::Value::Table(to_table("synth_info", toml::Table::try_from(&info))?),
    );
    Ok(ScanMeta {
        format: FORMAT_VERSION,
        record: RecordMeta {
            rpm: cfg.rpm,
            radius_mm: cfg.radius_mm,
            cut: cfg.cut,
            group_radius_mm: None,
        },
        camera: CameraMeta {
            pixel_pitch_um: cfg.pixel_pitch_um,
            working_distance_mm: cfg.working_distance_mm,
        },
        motion: MotionMeta {
            frame_step_um: cfg.frame_step_um,
            group_step_um: cfg.group_step_um(),
            numbered_names: NumberedNames::Positions,
        },
        dual_focus,
        extra,
    })
}

/// Writes the reference, every group's frames and, last, `scan.toml` into `out_dir`; returns
/// the group count.
fn write_scan_files(
    groove: &Groove,
    out_dir: &Path,
    meta_text: &str,
    job: Job<'_>,
) -> Result<usize, SynthError> {
    let cfg = groove.config();
    write_wav(
        &out_dir.join("reference.wav"),
        groove.reference(),
        WavBits::Float32,
        false,
    )?;
    let groups = groove.groups();
    let gw = digits(groups, 5);
    let fw = digits(cfg.frames_per_group, 3);
    job.report(0, groups);
    for g in 0..groups {
        if job.is_cancelled() {
            return Err(SynthError::Cancelled);
        }
        let gdir = out_dir.join(group_name(g, gw));
        std::fs::create_dir(&gdir)
            .map_err(|e| io_err(format!("cannot create group folder: {e}"), &gdir))?;
        (0..cfg.frames_per_group)
            .into_par_iter()
            .try_for_each(|k| -> Result<(), SynthError> {
                if job.is_cancelled() {
                    return Err(SynthError::Cancelled);
                }
                let img = groove.render_frame(g, k);
                save_grey_png(
                    &img,
                    &gdir.join(format!("f{k:0fw$}.png")),
                    cfg.bit_depth == 16,
                    false,
                )?;
                Ok(())
            })?;
        job.report(g + 1, groups);
    }
    crate::io::write_atomic(&out_dir.join("scan.toml"), meta_text.as_bytes(), false)?;
    Ok(groups)
}

/// Writes a prepared groove's scan (see [`render_scan`]).
///
/// # Errors
/// As [`render_scan`].
pub fn write_scan(
    groove: &Groove,
    out_dir: &Path,
    job: Job<'_>,
) -> Result<SynthSummary, SynthError> {
    let cfg = groove.config();
    let meta = scan_meta(groove)?;
    let meta_text = meta.to_toml_string().map_err(|e| SynthError::Config {
        key: "synth".into(),
        problem: format!("cannot be written as TOML: {e}"),
    })?;
    let groups = fill_out_dir(out_dir, |dir| {
        write_scan_files(groove, dir, &meta_text, job)
    })?;
    let reference = groove.reference();
    Ok(SynthSummary {
        out_dir: out_dir.to_path_buf(),
        groups,
        frames_per_group: cfg.frames_per_group,
        scan_length_um: groove.scan_length_um(),
        reference_secs: reference.duration_secs(),
        groove_speed_mm_s: groove.groove_speed_mm_s(),
        glass_edge_row: groove.optics().glass_edge_row,
        damage_features: groove.damage_features(),
        warnings: groove.warnings().to_vec(),
    })
}
