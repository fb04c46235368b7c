//! A store written beside its output with a progress record, so a writer that stops goes on where it stopped (`pack --resume`, `import-video --resume`).
//!
//! The store is written as a *partial* store beside the output (`.NAME.partial`). After each
//! group's chunk is read back, compared and synced, a progress record in it (`progress.json`,
//! written atomically) counts the group, with a fingerprint of what is being written (the scan
//! or the clip and its settings) and the store's layout, so every counted group is whole. A
//! writer that stops (Ctrl-C, bad input, a kill) after one or more groups keeps the partial
//! store; `resume` checks the record against the fingerprint and the zstd level and goes on
//! after the last counted group, `force` starts over, and without either the output is
//! refused. A partial store without a record holds no counted group and is started again. The
//! finished store loses the record and is renamed into place, so the output is complete or
//! absent; a lock beside the output keeps a second writer out meanwhile.

use std::fmt;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::{ChunkLayout, ZarrGroup, ZarrWriter, load_group_raw};
use crate::io::LoadError;
use crate::io::atomic::{beside, dir_is_missing_or_empty, write_json_atomic};
use crate::io::frames::RawFrame;
use crate::io::lock::OutputLock;

/// The progress record's file inside a partial store.
pub const PROGRESS_FILE: &str = "progress.json";
/// Layout version of the progress record this build reads and writes.
const PROGRESS_FORMAT: u32 = 1;

/// How a store is written when an interrupted writer of the same output left one behind.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PackOptions {
    /// zstd level of the chunks (1 fastest … 22 smallest).
    pub zstd_level: i32,
    /// Go on from an interrupted writer's partial store when there is one.
    pub resume: bool,
    /// Remove an interrupted writer's partial store and start over.
    pub force: bool,
    /// Keep the partial store of a writer that stops after writing a group (false where its
    /// source goes away with the failure).
    pub keep_partial: bool,
}

impl PackOptions {
    /// A store at `zstd_level` that keeps nothing when its writer stops.
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

/// What a stopped writer kept to go on from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Kept {
    /// Groups written, checked and kept.
    pub groups: usize,
    /// Groups the whole store would hold, where known.
    pub total: Option<usize>,
    /// The partial store.
    pub partial: PathBuf,
}

impl fmt::Display for Kept {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let of = self.total.map_or_else(String::new, |t| format!(" of {t}"));
        write!(
            f,
            "; the {}{of} groups written and checked so far are kept in {}: run the same \
             command with --resume to go on",
            self.groups,
            self.partial.display()
        )
    }
}

/// The record of a partial store: whose groups it holds, how, and how many are checked.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Progress {
    /// [`PROGRESS_FORMAT`].
    progress_format: u32,
    /// Fingerprint of what is being written (see [`PartialStore::open`]).
    source_fingerprint: String,
    /// The chunks' zstd level.
    zstd_level: i32,
    /// The groups' frames.
    #[serde(flatten)]
    layout: ChunkLayout,
    /// Groups whose chunks are written, read back, checked and synced, from the first.
    groups_checked: usize,
    /// Bytes read from the source for those groups.
    source_bytes: u64,
}

/// The partial store of a store written to `out`: `.NAME.partial` beside it.
#[must_use]
pub fn partial_path(out: &Path) -> PathBuf {
    beside(out, "scan.zarr", |name| format!(".{name}.partial"))
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
                "the interrupted writer's progress record cannot be read ({why}); start over \
                 with --force"
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

/// What a finished store holds.
#[derive(Clone, Debug, PartialEq)]
pub struct FinishedStore {
    /// The store, in place.
    pub out: PathBuf,
    /// Groups it holds.
    pub groups: usize,
    /// Of those, the groups an interrupted writer had written (taken over by `resume`).
    pub resumed: usize,
    /// Its layout.
    pub layout: ChunkLayout,
    /// Bytes read from the source, over every group.
    pub source_bytes: u64,
    /// Bytes of the store on disk.
    pub store_bytes: u64,
}

/// A store being written group by group into its partial store (see the module docs).
#[derive(Debug)]
pub struct PartialStore {
    out: PathBuf,
    path: PathBuf,
    options: PackOptions,
    fingerprint: String,
    /// The record, once the first group's layout (or the resumed record) is known.
    progress: Option<Progress>,
    writer: Option<ZarrWriter>,
    resumed: usize,
    /// Held until the store is finished or abandoned.
    _lock: OutputLock,
}

impl PartialStore {
    /// Starts writing a store to `out` (a new or empty folder) of what `fingerprint` stands
    /// for, or, with `options.resume` and an interrupted writer's partial store of `out`
    /// whose record carries the same fingerprint and zstd level, goes on with it.
    /// `start_over` says in errors how to make a fingerprint that differs start over.
    ///
    /// # Errors
    /// [`LoadError::Io`]: `out` is not new or empty, another writer holds it, a partial store
    /// is there without `resume` or `force`, its record is damaged or belongs to another
    /// source or level.
    pub fn open(
        out: &Path,
        fingerprint: String,
        options: PackOptions,
        start_over: &str,
    ) -> Result<Self, LoadError> {
        if !dir_is_missing_or_empty(out)? {
            return Err(io_err("the output folder must be new or empty", out));
        }
        if let Some(parent) = out.parent().filter(|p| !p.as_os_str().is_empty()) {
            std::fs::create_dir_all(parent)
                .map_err(|e| io_err(format!("cannot create the output's folder: {e}"), parent))?;
        }
        let lock = OutputLock::acquire(out)?;
        let path = partial_path(out);
        // A partial store without a record holds no checked group: it is started again.
        let progress = if path.join(PROGRESS_FILE).exists() {
            let progress = read_progress(&path)?;
            if options.resume {
                let refuse = |why: String| io_err(format!("cannot resume: {why}"), &path);
                if progress.source_fingerprint != fingerprint {
                    return Err(refuse(format!(
                        "the interrupted writer was writing something else (or what it wrote \
                         has changed since); {start_over}"
                    )));
                }
                if progress.zstd_level != options.zstd_level {
                    return Err(refuse(format!(
                        "the interrupted writer used --zstd-level {}, not {}; resume with that \
                         level, or start over with --force",
                        progress.zstd_level, options.zstd_level
                    )));
                }
                Some(progress)
            } else if options.force {
                None
            } else {
                return Err(io_err(
                    format!(
                        "an interrupted run's partial store of this output is kept here ({} \
                         groups written): continue it with --resume, or start over with --force",
                        progress.groups_checked
                    ),
                    &path,
                ));
            }
        } else {
            None
        };
        if progress.is_none() && path.exists() {
            std::fs::remove_dir_all(&path).map_err(|e| {
                io_err(
                    format!("cannot remove the interrupted run's store: {e}"),
                    &path,
                )
            })?;
        }
        let resumed = progress.as_ref().map_or(0, |p| p.groups_checked);
        Ok(Self {
            out: out.to_path_buf(),
            path,
            options,
            fingerprint,
            progress,
            writer: None,
            resumed,
            _lock: lock,
        })
    }

    /// Groups the interrupted writer had written and checked (0 when starting).
    #[must_use]
    pub fn resumed(&self) -> usize {
        self.resumed
    }

    /// Groups written and checked so far, the resumed ones included.
    #[must_use]
    pub fn groups(&self) -> usize {
        self.progress.as_ref().map_or(0, |p| p.groups_checked)
    }

    /// The layout of the groups, once known (from the resumed record or the first group).
    #[must_use]
    pub fn layout(&self) -> Option<ChunkLayout> {
        self.progress.as_ref().map(|p| p.layout)
    }

    /// Writes the next group (`frames`, named `name`; `source` names it in errors,
    /// `source_bytes` is what was read for it), reads its chunk back and compares it, syncs
    /// it, and counts it in the record. The first group sets the layout; `names` of the
    /// resumed groups are asked for once, when the store is reopened.
    ///
    /// # Errors
    /// [`LoadError`] naming the group when its frames do not fit the store, a write fails, or
    /// the chunk reads back different.
    pub fn add_group(
        &mut self,
        name: &str,
        frames: Vec<RawFrame>,
        source: &Path,
        source_bytes: u64,
        resumed_names: impl FnOnce(usize) -> Vec<String>,
    ) -> Result<(), LoadError> {
        if self.writer.is_none() {
            let progress = match self.progress.take() {
                Some(p) => p,
                None => {
                    let Some(f0) = frames.first() else {
                        return Err(io_err("a group of no frames", source));
                    };
                    Progress {
                        progress_format: PROGRESS_FORMAT,
                        source_fingerprint: self.fingerprint.clone(),
                        zstd_level: self.options.zstd_level,
                        layout: ChunkLayout {
                            frames: frames.len(),
                            width: f0.width,
                            height: f0.height,
                            sample_type: super::SampleType::of(&f0.samples),
                        },
                        groups_checked: 0,
                        source_bytes: 0,
                    }
                }
            };
            let names = resumed_names(progress.groups_checked);
            self.writer = Some(ZarrWriter::reopen(
                &self.path,
                progress.layout,
                self.options.zstd_level,
                names,
            )?);
            self.progress = Some(progress);
        }
        let (Some(writer), Some(progress)) = (self.writer.as_mut(), self.progress.as_mut()) else {
            return Err(io_err("the store was not started", &self.path));
        };
        let g = progress.groups_checked;
        writer.write_group(name, frames.clone(), source)?;
        let stored = ZarrGroup {
            store: self.path.clone(),
            group: g,
            layout: progress.layout,
        };
        let chunk = stored.chunk_path();
        if load_group_raw(&stored)? != frames {
            return Err(io_err(
                "the chunk read back differs from the frames written",
                &chunk,
            ));
        }
        // On disk before the record counts it, so a counted chunk survives a crash.
        std::fs::File::open(&chunk)
            .and_then(|f| f.sync_all())
            .map_err(|e| io_err(format!("cannot sync the chunk: {e}"), &chunk))?;
        progress.groups_checked = g + 1;
        progress.source_bytes += source_bytes;
        write_json_atomic(&self.path.join(PROGRESS_FILE), &*progress, true)
    }

    /// The partial store's folder (side files such as `reference.wav` are copied into it
    /// before [`Self::finish`]).
    #[must_use]
    pub fn folder(&self) -> &Path {
        &self.path
    }

    /// Ends the store: its metadata with `scan_toml`, the record removed, renamed into place.
    ///
    /// # Errors
    /// [`LoadError::Io`] naming the store when no group was written or a write or the rename
    /// fails.
    pub fn finish(mut self, scan_toml: &str) -> Result<FinishedStore, LoadError> {
        let (Some(writer), Some(progress)) = (self.writer.take(), self.progress.take()) else {
            return Err(io_err("no group was written", &self.path));
        };
        writer.finish(scan_toml)?;
        std::fs::remove_file(self.path.join(PROGRESS_FILE)).map_err(|e| {
            io_err(
                format!("cannot remove the progress record: {e}"),
                &self.path,
            )
        })?;
        let store_bytes = dir_bytes(&self.path);
        if self.out.exists() {
            std::fs::remove_dir(&self.out).map_err(|e| {
                io_err(
                    format!("cannot replace the empty output folder: {e}"),
                    &self.out,
                )
            })?;
        }
        std::fs::rename(&self.path, &self.out)
            .map_err(|e| io_err(format!("cannot move the store into place: {e}"), &self.out))?;
        Ok(FinishedStore {
            out: self.out.clone(),
            groups: progress.groups_checked,
            resumed: self.resumed,
            layout: progress.layout,
            source_bytes: progress.source_bytes,
            store_bytes,
        })
    }

    /// Ends a writer that failed: keeps the partial store when the options say so and it
    /// counts a group (what was kept, for the error line), else removes it.
    #[must_use]
    pub fn abandon(self, total: Option<usize>) -> Option<Kept> {
        let groups = self.groups();
        let counted = self.path.join(PROGRESS_FILE).is_file();
        if self.options.keep_partial && groups > 0 && counted {
            return Some(Kept {
                groups,
                total,
                partial: self.path.clone(),
            });
        }
        let _ = std::fs::remove_dir_all(&self.path);
        None
    }
}
