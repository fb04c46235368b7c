//! `pack`: a scan folder converted to a Zarr store, each chunk read back and checked, then renamed into place.

use std::path::{Path, PathBuf};

use rayon::prelude::*;

use super::{SampleType, ZarrGroup, ZarrWriter, load_group_raw};
use crate::io::atomic::dir_is_missing_or_empty;
use crate::io::frames::{RawFrame, load_frame_raw};
use crate::io::{LoadError, Scan};
use crate::job::Job;

/// What `pack` did.
#[derive(Clone, Debug)]
pub struct PackSummary {
    /// The store.
    pub out: PathBuf,
    /// Groups packed.
    pub groups: usize,
    /// Frames per group.
    pub frames_per_group: usize,
    /// How samples are stored.
    pub sample_type: SampleType,
    /// Bytes of the frame files read.
    pub folder_bytes: u64,
    /// Bytes of the store on disk (chunks and metadata).
    pub store_bytes: u64,
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

/// Converts the scan folder `scan` into a Zarr store at `out` (a new or empty folder): every
/// group becomes one zstd chunk (at `level`) which is read back and compared sample for sample
/// before the next; the store is written beside `out` and renamed into place, so a failed or
/// cancelled pack leaves nothing. `reference.wav` and `preset.toml` are copied in.
/// `job` is told each finished group; cancelling it stops before the next.
///
/// # Errors
/// [`LoadError`] naming the file: an unreadable frame, groups of different frame counts,
/// sizes or bit depths, an output folder that is not empty, a write or check that fails.
pub fn pack_scan(
    scan: &Scan,
    out: &Path,
    level: i32,
    job: Job<'_>,
) -> Result<PackSummary, LoadError> {
    if scan.is_store() {
        return Err(LoadError::Io {
            problem: "this scan is a Zarr store already".into(),
            path: scan.dir.clone(),
        });
    }
    // A place the numbering skips is refused before any group is packed.
    if let Some(missing) = scan.groups.iter().find_map(|g| g.missing_error()) {
        return Err(missing);
    }
    if !dir_is_missing_or_empty(out)? {
        return Err(LoadError::Io {
            problem: "the output folder must be new or empty".into(),
            path: out.to_path_buf(),
        });
    }
    let tmp = crate::io::atomic::beside(out, "scan.zarr", |name| {
        format!(".{name}.pack-{}.tmp", std::process::id())
    });
    let result = pack_into(scan, &tmp, level, job);
    let finished = result.and_then(|mut summary| {
        if out.exists() {
            std::fs::remove_dir(out).map_err(|e| LoadError::Io {
                problem: format!("cannot replace the empty output folder: {e}"),
                path: out.to_path_buf(),
            })?;
        }
        std::fs::rename(&tmp, out).map_err(|e| LoadError::Io {
            problem: format!("cannot move the store into place: {e}"),
            path: out.to_path_buf(),
        })?;
        summary.out = out.to_path_buf();
        Ok(summary)
    });
    if finished.is_err() {
        let _ = std::fs::remove_dir_all(&tmp);
    }
    finished
}

fn pack_into(scan: &Scan, tmp: &Path, level: i32, job: Job<'_>) -> Result<PackSummary, LoadError> {
    let _ = std::fs::remove_dir_all(tmp);
    let total = scan.groups.len();
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
    let (frames, width, height) = (first.len(), f0.width, f0.height);
    let sample_type = SampleType::of(&f0.samples);
    let mut writer = ZarrWriter::create(tmp, frames, width, height, sample_type, level)?;
    let mut folder_bytes = 0;
    let mut pending = Some(first);
    for (g, entry) in scan.groups.iter().enumerate() {
        if job.is_cancelled() {
            return Err(LoadError::Io {
                problem: "packing this scan was cancelled; the unfinished store is removed".into(),
                path: scan.dir.clone(),
            });
        }
        let raw = match pending.take() {
            Some(r) => r,
            None => raw_group(entry)?,
        };
        folder_bytes += entry
            .frames
            .iter()
            .map(|p| std::fs::metadata(p).map_or(0, |m| m.len()))
            .sum::<u64>();
        writer.write_group(&entry.name(), raw.clone(), &entry.dir)?;
        let stored = ZarrGroup {
            store: tmp.to_path_buf(),
            group: g,
            frames,
            width,
            height,
            sample_type,
        };
        if load_group_raw(&stored)? != raw {
            return Err(LoadError::Io {
                problem: "the chunk read back differs from the frames written".into(),
                path: stored.chunk_path(),
            });
        }
        job.report(g + 1, total);
    }
    for side_file in ["reference.wav", "preset.toml"] {
        let from = scan.dir.join(side_file);
        if from.is_file() {
            std::fs::copy(&from, tmp.join(side_file)).map_err(|e| LoadError::Io {
                problem: format!("cannot copy {side_file} into the store: {e}"),
                path: from.clone(),
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
        out: tmp.to_path_buf(),
        groups: total,
        frames_per_group: frames,
        sample_type,
        folder_bytes,
        store_bytes: dir_bytes(tmp),
    })
}
