//! `pack`: a scan folder converted to a Zarr store, each chunk read back and checked, written as a partial store that a stopped pack goes on with (`--resume`).

use std::path::{Path, PathBuf};

use rayon::prelude::*;

use super::SampleType;
use super::partial::{Kept, PackOptions, PartialStore};
use crate::io::fingerprint::scan_names_fingerprint;
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
#[error("{error}{}", kept.as_ref().map(ToString::to_string).unwrap_or_default())]
pub struct PackError {
    /// What went wrong, naming the file.
    pub error: LoadError,
    /// The groups kept in the partial store, if any.
    pub kept: Option<Kept>,
}

impl From<LoadError> for PackError {
    fn from(error: LoadError) -> Self {
        Self { error, kept: None }
    }
}

fn raw_group(scan_group: &crate::io::GroupEntry) -> Result<Vec<RawFrame>, LoadError> {
    if scan_group.frame_names.is_empty() {
        let none = LoadError::TooFewFrames {
            found: 0,
            needed: crate::io::scan::MIN_FRAMES_PER_GROUP,
            path: scan_group.dir.clone(),
        };
        return Err(crate::io::frames::missing_or(scan_group, none));
    }
    scan_group
        .frame_names
        .par_iter()
        .map(|name| load_frame_raw(&scan_group.dir.join(name)))
        .collect::<Result<_, _>>()
        .map_err(|e| crate::io::frames::missing_or(scan_group, e))
}

/// Converts the scan folder `scan` into a Zarr store at `out` (a new or empty folder): every
/// group becomes one zstd chunk which is read back and compared sample for sample before the
/// next, in a partial store beside `out` ([`super::partial`]) renamed into place at the end,
/// so `out` is complete or absent. `reference.wav` and `preset.toml` are copied in. `job` is
/// told each finished group; cancelling it stops before the next. With `resume` a pack goes
/// on after the groups an interrupted pack of this scan counted (its record must carry this
/// scan's metadata and group names, [`scan_names_fingerprint`], and the same zstd level).
///
/// # Errors
/// [`PackError`]: the [`LoadError`] naming the file (an unreadable frame, groups of different
/// frame counts, sizes or bit depths, an output folder that is not empty, an interrupted
/// pack's partial store without `resume` or `force`, or of another scan, a write or check
/// that fails), with what was kept to go on from.
pub fn pack_scan(
    scan: &Scan,
    out: &Path,
    options: PackOptions,
    job: Job<'_>,
) -> Result<PackSummary, PackError> {
    if scan.is_store() {
        return Err(LoadError::io("this scan is a Zarr store already", &scan.dir).into());
    }
    // A place the numbering skips is refused before any group is packed.
    if let Some(missing) = scan.groups.iter().find_map(|g| g.missing_error()) {
        return Err(missing.into());
    }
    if scan.groups.is_empty() {
        return Err(LoadError::NotAScan {
            problem: "the scan holds no groups".into(),
            path: scan.dir.clone(),
        }
        .into());
    }
    let start_over = format!(
        "pack {} again with --force to start over",
        scan.dir.display()
    );
    let names = |k: usize| scan.groups[..k].iter().map(|g| g.name()).collect();
    let mut store = PartialStore::open(
        out,
        scan_names_fingerprint(scan),
        options,
        &start_over,
        names,
    )?;
    let done = pack_into(scan, &mut store, job).and_then(|()| {
        let meta_toml = scan
            .meta
            .to_toml_string()
            .map_err(|e| LoadError::Metadata {
                problem: e.to_string(),
                path: scan.dir.join("scan.toml"),
            })?;
        store.finish(&meta_toml)
    });
    let done = match done {
        Ok(done) => done,
        Err(error) => {
            let kept = store.abandon(Some(scan.groups.len()));
            return Err(PackError { error, kept });
        }
    };
    Ok(PackSummary {
        out: done.out,
        groups: done.groups,
        resumed: done.resumed,
        frames_per_group: done.layout.frames,
        sample_type: done.layout.sample_type,
        folder_bytes: scan.groups.iter().map(frame_bytes).sum(),
        store_bytes: done.store_bytes,
    })
}

/// Bytes of a group's frame files.
fn frame_bytes(entry: &crate::io::GroupEntry) -> u64 {
    entry
        .frame_paths()
        .map(|p| std::fs::metadata(p).map_or(0, |m| m.len()))
        .sum()
}

/// Packs the groups of `scan` after the ones `store` holds, then copies the side files in.
fn pack_into(scan: &Scan, store: &mut PartialStore, job: Job<'_>) -> Result<(), LoadError> {
    let total = scan.groups.len();
    let from = store.groups();
    // The groups taken over are not read again, but each must still hold as many frames as
    // the store's chunks do (a group mended since would be packed as it was).
    if let Some(layout) = store.layout()
        && let Some(changed) = scan.groups[..from]
            .iter()
            .find(|g| g.frame_count() != layout.frames)
    {
        return Err(LoadError::io(
            format!(
                "this group now holds {} frames, but the interrupted pack stored it with {}; \
                 start over with --force",
                changed.frame_count(),
                layout.frames
            ),
            &changed.dir,
        ));
    }
    job.report(from, total);
    for (g, entry) in scan.groups.iter().enumerate().skip(from) {
        if job.is_cancelled() {
            return Err(LoadError::io(
                format!("packing this scan was stopped before group {g}"),
                &scan.dir,
            ));
        }
        let raw = raw_group(entry)?;
        store.add_group(&entry.name(), &raw, &entry.dir)?;
        job.report(g + 1, total);
    }
    for side_file in ["reference.wav", "preset.toml"] {
        let from = scan.dir.join(side_file);
        if from.is_file() {
            std::fs::copy(&from, store.folder().join(side_file)).map_err(|e| {
                LoadError::io(
                    format!("cannot copy {side_file} into the store: {e}"),
                    &from,
                )
            })?;
        }
    }
    Ok(())
}
