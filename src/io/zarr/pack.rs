//! `pack`: a scan folder converted to a Zarr store, each chunk read back and checked, then renamed into place; an interrupted pack goes on with `--resume`.
//!
//! The store is written as a *partial* store beside the output (`.NAME.pack-partial`). After
//! each group's chunk is read back, checked and synced, a progress record in the partial store
//! (`pack-progress.json`, written atomically) counts it, with the scan's fingerprint and the
//! store's layout. A pack that stops (Ctrl-C, a bad frame, a kill) after one or more groups
//! keeps the partial store; `--resume` checks the record against the scan and the options and
//! goes on after the last counted group, `--force` starts over. The finished store loses the
//! record and is renamed into place, so the output is complete or absent.

use std::path::{Path, PathBuf};

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::{ChunkLayout, SampleType, ZarrGroup, ZarrWriter, load_group_raw};
use crate::io::atomic::{beside, dir_is_missing_or_empty, write_json_atomic};
use crate::io::fingerprint::scan_names_fingerprint;
use crate::io::frames::{RawFrame, load_frame_raw};
use crate::io::lock::OutputLock;
use crate::io::{LoadError, Scan};
use crate::job::Job;

/// The progress record's file inside a partial store.
pub const PROGRESS_FILE: &str = "pack-progress.json";
/// Layout version of the progress record this build reads and writes.
const PROGRESS_FORMAT: u32 = 1;

/// How `pack` runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PackOptions {
    /// zstd level of the chunks (1 fastest … 22 smallest).
    pub zstd_level: i32,
    /// Go on from an interrupted pack's partial store when there is one.
    pub resume: bool,
    /// Remove an interrupted pack's partial store and start over.
    pub force: bool,
    /// Keep the partial store of a pack that stops after packing a group (false where its
    /// source goes away with the failure, as in the video import).
    pub keep_partial: bool,
}

impl PackOptions {
    /// A pack at `zstd_level` that keeps nothing when it stops.
    #[must_use]
    pub fn once(zstd_level: i32) -> Self {
        Self {
            zstd_level,
            resume: false,
            force: false,
            keep_partial: false,
        }
    }
}

/// What `pack` did.
#[derive(Clone, Debug)]
pub struct PackSummary {
    /// The store.
    pub out: PathBuf,
    /// Groups packed.
    pub groups: usize,
    /// Groups taken over from an interrupted pack (`--resume`) rather than packed by this run.
    pub resumed: usize,
    /// Frames per group.
    pub frames_per_group: usize,
    /// How samples are stored.
    pub sample_type: SampleType,
    /// Bytes of the frame files read.
    pub folder_bytes: u64,
    /// Bytes of the store on disk (chunks and metadata).
    pub store_bytes: u64,
}

/// Why `pack` stopped, and what it kept to go on from.
#[derive(Debug, thiserror::Error)]
#[error("{error}{}", kept_note(*.kept, .partial.as_deref(), *.total))]
pub struct PackError {
    /// What went wrong, naming the file.
    pub error: LoadError,
    /// Groups packed, checked and kept in the partial store (0: nothing kept).
    pub kept: usize,
    /// The scan's groups.
    pub total: usize,
    /// The partial store, when it was kept.
    pub partial: Option<PathBuf>,
}

fn kept_note(kept: usize, partial: Option<&Path>, total: usize) -> String {
    partial.map_or_else(String::new, |p| {
        format!(
            "; the {kept} of {total} groups packed and checked so far are kept in {}: run the \
             same command with --resume to go on",
            p.display()
        )
    })
}

impl From<LoadError> for PackError {
    fn from(error: LoadError) -> Self {
        Self {
            error,
            kept: 0,
            total: 0,
            partial: None,
        }
    }
}

/// The record of a partial store: whose groups it holds, how, and how many are checked.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Progress {
    /// [`PROGRESS_FORMAT`].
    progress_format: u32,
    /// [`scan_names_fingerprint`] of the scan being packed.
    scan_names_fingerprint: String,
    /// The chunks' zstd level.
    zstd_level: i32,
    /// The groups' frames.
    #[serde(flatten)]
    layout: ChunkLayout,
    /// Groups whose chunks are written, read back, checked and synced, from the first.
    groups_checked: usize,
    /// Bytes of those groups' frame files.
    folder_bytes: u64,
}

/// The partial store of a pack to `out`: `.NAME.pack-partial` beside it.
#[must_use]
pub fn partial_path(out: &Path) -> PathBuf {
    beside(out, "scan.zarr", |name| format!(".{name}.pack-partial"))
}

fn raw_group(scan_group: &crate::io::GroupEntry) -> Result<Vec<RawFrame>, LoadError> {
    if scan_group.frames.is_empty() {
        let none = LoadError::TooFewFrames {
            found: 0,
            needed: crate::io::scan::MIN_FRAMES_PER_GROUP,
            path: scan_group.dir.clone(),
        };
        return Err(crate::io::frames::missing_or(scan_group, none));
    }
    scan_group
        .frames
        .par_iter()
        .map(|p| load_frame_raw(p))
        .collect::<Result<_, _>>()
        .map_err(|e| crate::io::frames::missing_or(scan_group, e))
}

/// Bytes of the files under `dir`.
fn dir_bytes(dir: &Path) -> u64 {
    let Ok(rd) = std::fs::read_dir(dir) else {
        return 0;
    };
    rd.flatten()
        .map(|e| match e.file_type() {
            Ok(t) if t.is_dir() => dir_bytes(&e.path()),
            Ok(_) => e.metadata().map_or(0, |m| m.len()),
            Err(_) => 0,
        })
        .sum()
}

fn io_err(problem: impl Into<String>, path: &Path) -> LoadError {
    LoadError::Io {
        problem: problem.into(),
        path: path.to_path_buf(),
    }
}

/// Reads the progress record of the partial store `partial`.
fn read_progress(partial: &Path) -> Result<Progress, LoadError> {
    let file = partial.join(PROGRESS_FILE);
    let damaged = |why: String| {
        io_err(
            format!(
                "the interrupted pack's progress record cannot be read ({why}); start over with \
                 --force"
            ),
            &file,
        )
    };
    let bytes = std::fs::read(&file).map_err(|e| damaged(e.to_string()))?;
    let progress: Progress = serde_json::from_slice(&bytes).map_err(|e| damaged(e.to_string()))?;
    if progress.progress_format != PROGRESS_FORMAT {
        return Err(damaged(format!(
            "record format {}, this build reads {PROGRESS_FORMAT}",
            progress.progress_format
        )));
    }
    Ok(progress)
}

/// The groups the partial store `partial` holds for `scan` packed at `level`, once its record
/// says it belongs to them.
fn resumable(partial: &Path, scan: &Scan, level: i32) -> Result<Progress, LoadError> {
    let progress = read_progress(partial)?;
    let refuse = |why: String| io_err(format!("cannot resume this pack: {why}"), partial);
    if progress.scan_names_fingerprint != scan_names_fingerprint(scan) {
        return Err(refuse(format!(
            "it was packing another scan (or this one's metadata or group names have changed \
             since); pack {} again with --force to start over",
            scan.dir.display()
        )));
    }
    if progress.zstd_level != level {
        return Err(refuse(format!(
            "it was packing at --zstd-level {}, not {level}; resume with that level, or start \
             over with --force",
            progress.zstd_level
        )));
    }
    if progress.groups_checked > scan.groups.len() {
        return Err(refuse(format!(
            "its record counts {} groups, the scan has {}; start over with --force",
            progress.groups_checked,
            scan.groups.len()
        )));
    }
    Ok(progress)
}

/// Converts the scan folder `scan` into a Zarr store at `out` (a new or empty folder): every
/// group becomes one zstd chunk which is read back and compared sample for sample before the
/// next; the store is written as a partial store beside `out` ([`partial_path`]) and renamed
/// into place, so `out` is complete or absent. `reference.wav` and `preset.toml` are copied
/// in. `job` is told each finished group; cancelling it stops before the next. With
/// `keep_partial`, a pack that stops after packing a group keeps its partial store for
/// `resume` (see the module docs); otherwise it removes it.
///
/// # Errors
/// [`PackError`]: the [`LoadError`] naming the file (an unreadable frame, groups of different
/// frame counts, sizes or bit depths, an output folder that is not empty, an interrupted
/// pack's partial store without `resume` or `force`, one that belongs to another scan, a
/// write or check that fails), with what was kept to go on from.
pub fn pack_scan(
    scan: &Scan,
    out: &Path,
    options: PackOptions,
    job: Job<'_>,
) -> Result<PackSummary, PackError> {
    if scan.is_store() {
        return Err(io_err("this scan is a Zarr store already", &scan.dir).into());
    }
    // A place the numbering skips is refused before any group is packed.
    if let Some(missing) = scan.groups.iter().find_map(|g| g.missing_error()) {
        return Err(missing.into());
    }
    if !dir_is_missing_or_empty(out)? {
        return Err(io_err("the output folder must be new or empty", out).into());
    }
    if let Some(parent) = out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent)
            .map_err(|e| io_err(format!("cannot create the output's folder: {e}"), parent))?;
    }
    // One pack at a time writes the partial store of `out`.
    let _lock = OutputLock::acquire(out)?;
    let partial = partial_path(out);
    // A partial store without a record holds no checked group: it is started again.
    let progress = if partial.join(PROGRESS_FILE).exists() {
        if options.resume {
            Some(resumable(&partial, scan, options.zstd_level)?)
        } else if options.force {
            std::fs::remove_dir_all(&partial).map_err(|e| {
                io_err(format!("cannot remove the interrupted pack: {e}"), &partial)
            })?;
            None
        } else {
            let counted = read_progress(&partial).map_or_else(
                |_| String::new(),
                |p| {
                    format!(
                        " ({} of {} groups packed)",
                        p.groups_checked,
                        scan.groups.len()
                    )
                },
            );
            return Err(io_err(
                format!(
                    "an interrupted pack of this output is kept here{counted}: continue it with \
                     --resume, or start over with --force"
                ),
                &partial,
            )
            .into());
        }
    } else {
        None
    };
    let mut checked = progress.as_ref().map_or(0, |p| p.groups_checked);
    let result = pack_into(
        scan,
        &partial,
        options.zstd_level,
        progress,
        &mut checked,
        job,
    );
    let finished = result.and_then(|mut summary| {
        std::fs::remove_file(partial.join(PROGRESS_FILE))
            .map_err(|e| io_err(format!("cannot remove the progress record: {e}"), &partial))?;
        summary.store_bytes = dir_bytes(&partial);
        if out.exists() {
            std::fs::remove_dir(out)
                .map_err(|e| io_err(format!("cannot replace the empty output folder: {e}"), out))?;
        }
        std::fs::rename(&partial, out)
            .map_err(|e| io_err(format!("cannot move the store into place: {e}"), out))?;
        summary.out = out.to_path_buf();
        Ok(summary)
    });
    finished.map_err(|error| {
        let keep = options.keep_partial && checked > 0 && partial.join(PROGRESS_FILE).is_file();
        if !keep {
            let _ = std::fs::remove_dir_all(&partial);
        }
        PackError {
            error,
            kept: if keep { checked } else { 0 },
            total: scan.groups.len(),
            partial: keep.then_some(partial),
        }
    })
}

/// Packs the groups of `scan` after the ones `progress` counts into the partial store
/// `partial`, keeping `checked` (and the record) up to date after each.
fn pack_into(
    scan: &Scan,
    partial: &Path,
    level: i32,
    progress: Option<Progress>,
    checked: &mut usize,
    job: Job<'_>,
) -> Result<PackSummary, LoadError> {
    let total = scan.groups.len();
    let mut pending = None;
    let mut progress = if let Some(p) = progress {
        p
    } else {
        let _ = std::fs::remove_dir_all(partial);
        let Some(first_group) = scan.groups.first() else {
            return Err(LoadError::NotAScan {
                problem: "the scan holds no groups".into(),
                path: scan.dir.clone(),
            });
        };
        let first = raw_group(first_group)?;
        let Some(f0) = first.first() else {
            return Err(LoadError::TooFewFrames {
                found: 0,
                needed: crate::io::scan::MIN_FRAMES_PER_GROUP,
                path: first_group.dir.clone(),
            });
        };
        let p = Progress {
            progress_format: PROGRESS_FORMAT,
            scan_names_fingerprint: scan_names_fingerprint(scan),
            zstd_level: level,
            layout: ChunkLayout {
                frames: first.len(),
                width: f0.width,
                height: f0.height,
                sample_type: SampleType::of(&f0.samples),
            },
            groups_checked: 0,
            folder_bytes: 0,
        };
        pending = Some(first);
        p
    };
    let resumed = progress.groups_checked;
    let names = scan.groups[..resumed].iter().map(|g| g.name()).collect();
    let layout = progress.layout;
    let mut writer = ZarrWriter::reopen(partial, layout, level, names)?;
    job.report(resumed, total);
    for (g, entry) in scan.groups.iter().enumerate().skip(resumed) {
        if job.is_cancelled() {
            return Err(io_err(
                format!("packing this scan was stopped before group {g}"),
                &scan.dir,
            ));
        }
        let raw = match pending.take() {
            Some(r) => r,
            None => raw_group(entry)?,
        };
        let group_bytes = entry
            .frames
            .iter()
            .map(|p| std::fs::metadata(p).map_or(0, |m| m.len()))
            .sum::<u64>();
        writer.write_group(&entry.name(), raw.clone(), &entry.dir)?;
        let stored = ZarrGroup {
            store: partial.to_path_buf(),
            group: g,
            layout,
        };
        if load_group_raw(&stored)? != raw {
            return Err(io_err(
                "the chunk read back differs from the frames written",
                &stored.chunk_path(),
            ));
        }
        // On disk before the record counts it, so a counted chunk survives a crash.
        std::fs::File::open(stored.chunk_path())
            .and_then(|f| f.sync_all())
            .map_err(|e| io_err(format!("cannot sync the chunk: {e}"), &stored.chunk_path()))?;
        progress.groups_checked = g + 1;
        progress.folder_bytes += group_bytes;
        write_json_atomic(&partial.join(PROGRESS_FILE), &progress, true)?;
        *checked = g + 1;
        job.report(g + 1, total);
    }
    for side_file in ["reference.wav", "preset.toml"] {
        let from = scan.dir.join(side_file);
        if from.is_file() {
            std::fs::copy(&from, partial.join(side_file)).map_err(|e| {
                io_err(
                    format!("cannot copy {side_file} into the store: {e}"),
                    &from,
                )
            })?;
        }
    }
    let meta_toml = scan
        .meta
        .to_toml_string()
        .map_err(|e| LoadError::Metadata {
            problem: e.to_string(),
            path: scan.dir.join("scan.toml"),
        })?;
    writer.finish(&meta_toml)?;
    Ok(PackSummary {
        out: partial.to_path_buf(),
        groups: total,
        resumed,
        frames_per_group: layout.frames,
        sample_type: layout.sample_type,
        folder_bytes: progress.folder_bytes,
        store_bytes: 0,
    })
}
