//! A store written beside its output with a progress record, so a writer that stops goes on where it stopped (`pack --resume`, `import-video --resume`).
//!
//! The store is written as a *partial* store beside the output (`.NAME.partial`). After each
//! group's chunk is read back, compared and synced, a progress record in it (`progress.json`,
//! written atomically) counts the group, with a fingerprint of what is being written (the scan
//! or the clip and its settings) and the store's layout. A writer that stops (Ctrl-C, bad
//! input, a kill) after one or more groups keeps the partial store; `resume` checks the record
//! against the fingerprint and the zstd level and goes on after the last counted group whose
//! chunk is still there, `force` starts over, and without either the output is refused. A
//! partial store without a record holds no counted group and is started again. The finished
//! store is renamed into place before it loses the record, so the output is complete or absent
//! and a failure on the way never costs a counted group; a lock beside the output keeps a
//! second writer out meanwhile.

use std::fmt;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::{ChunkLayout, ZarrWriter, chunk_file};
use crate::io::LoadError;
use crate::io::atomic::{beside, dir_is_missing_or_empty, remove_stale_temps, write_json_atomic};
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
}

/// What a stopped writer kept to go on from. Its line states the facts; each front end adds
/// how to go on in its own terms (the command line's `--resume`, the workbench's Import).
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
            "; the {}{of} groups written and checked so far are kept in {}",
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
}

/// The partial store of a store written to `out`: `.NAME.partial` beside it.
#[must_use]
pub fn partial_path(out: &Path) -> PathBuf {
    beside(out, "scan.zarr", |name| format!(".{name}.partial"))
}

/// Groups an interrupted writer of `out` wrote and checked, kept in its partial store for a
/// resume (None: no partial store with a readable record).
#[must_use]
pub fn kept_groups(out: &Path) -> Option<usize> {
    let path = partial_path(out);
    if !path.join(PROGRESS_FILE).is_file() {
        return None;
    }
    read_progress(&path).ok().map(|p| p.groups_checked)
}

/// Reads the progress record of the partial store `partial`.
fn read_progress(partial: &Path) -> Result<Progress, LoadError> {
    let file = partial.join(PROGRESS_FILE);
    let damaged = |why: String| {
        LoadError::io(
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

/// The layout of a new store whose first group is `frames` (`source` names it in errors).
fn first_layout(frames: &[RawFrame], source: &Path) -> Result<ChunkLayout, LoadError> {
    let Some(f0) = frames.first() else {
        return Err(LoadError::io("a group of no frames", source));
    };
    Ok(ChunkLayout {
        frames: frames.len(),
        width: f0.width,
        height: f0.height,
        sample_type: super::SampleType::of(&f0.samples),
    })
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
    /// Bytes of the store on disk.
    pub store_bytes: u64,
}

/// A partial store's writer and the record of what it holds, together from the first group
/// (or the resumed record) on.
#[derive(Debug)]
struct Started {
    writer: ZarrWriter,
    progress: Progress,
}

/// A store being written group by group into its partial store (see the module docs).
#[derive(Debug)]
pub struct PartialStore {
    out: PathBuf,
    path: PathBuf,
    options: PackOptions,
    fingerprint: String,
    /// None until the first group's layout (or the resumed record) is known.
    started: Option<Started>,
    resumed: usize,
    /// Held until the store is dropped.
    _lock: OutputLock,
}

impl PartialStore {
    /// Starts writing a store to `out` (a new or empty folder) of what `fingerprint` stands
    /// for, or, with `options.resume` and an interrupted writer's partial store of `out`
    /// whose record carries the same fingerprint and zstd level, goes on with it after the
    /// last counted group whose chunk is still on disk: the store is reopened at once, its
    /// first groups named by `resumed_names(groups it holds)`. `start_over` says in errors
    /// how to make a fingerprint that differs start over.
    ///
    /// # Errors
    /// [`LoadError::Io`]: `out` is not new or empty, another writer holds it, a partial store
    /// is there without `resume` or `force`, its record is damaged or belongs to another
    /// source or level, or the store cannot be reopened.
    pub fn open(
        out: &Path,
        fingerprint: String,
        options: PackOptions,
        start_over: &str,
        resumed_names: impl FnOnce(usize) -> Vec<String>,
    ) -> Result<Self, LoadError> {
        if let Some(parent) = out.parent().filter(|p| !p.as_os_str().is_empty()) {
            std::fs::create_dir_all(parent).map_err(|e| {
                LoadError::io(format!("cannot create the output's folder: {e}"), parent)
            })?;
        }
        let lock = OutputLock::acquire(out)?;
        // Checked under the lock: a writer that finished meanwhile filled it.
        if !dir_is_missing_or_empty(out)? {
            return Err(LoadError::io("the output folder must be new or empty", out));
        }
        let path = partial_path(out);
        // A partial store without a record holds no checked group: it is started again.
        let recorded = path.join(PROGRESS_FILE).exists();
        let mut progress = None;
        if recorded && options.resume {
            let p = read_progress(&path)?;
            let refuse = |why: String| LoadError::io(format!("cannot resume: {why}"), &path);
            if p.source_fingerprint != fingerprint {
                return Err(refuse(format!(
                    "the interrupted writer was writing something else (or what it wrote has \
                     changed since); {start_over}"
                )));
            }
            if p.zstd_level != options.zstd_level {
                return Err(refuse(format!(
                    "the interrupted writer used --zstd-level {}, not {}; resume with that \
                     level, or start over with --force",
                    p.zstd_level, options.zstd_level
                )));
            }
            progress = Some(p);
        } else if recorded && !options.force {
            let counted = read_progress(&path)?.groups_checked;
            return Err(LoadError::io(
                format!(
                    "an interrupted run's partial store of this output is kept here ({counted} \
                     groups written): continue it with --resume, or start over with --force"
                ),
                &path,
            ));
        }
        if progress.is_none() && path.exists() {
            std::fs::remove_dir_all(&path).map_err(|e| {
                LoadError::io(
                    format!("cannot remove the interrupted run's store: {e}"),
                    &path,
                )
            })?;
        }
        // A counted chunk that a power cut took from the file system is written again.
        if let Some(p) = progress.as_mut()
            && let Some(lost) = (0..p.groups_checked).find(|&g| !chunk_file(&path, g).is_file())
        {
            p.groups_checked = lost;
        }
        let resumed = progress.as_ref().map_or(0, |p| p.groups_checked);
        let started = match progress {
            Some(progress) => Some(Started {
                writer: ZarrWriter::reopen(
                    &path,
                    progress.layout,
                    options.zstd_level,
                    resumed_names(resumed),
                )?,
                progress,
            }),
            None => None,
        };
        Ok(Self {
            out: out.to_path_buf(),
            path,
            options,
            fingerprint,
            started,
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
        self.started
            .as_ref()
            .map_or(0, |s| s.progress.groups_checked)
    }

    /// The layout of the groups, once known (from the resumed record or the first group).
    #[must_use]
    pub fn layout(&self) -> Option<ChunkLayout> {
        self.started.as_ref().map(|s| s.progress.layout)
    }

    /// Writes the next group (`frames`, named `name`; `source` names it in errors), reads its
    /// chunk back and compares it, syncs it, and counts it in the record. The first group of
    /// a new store sets its layout.
    ///
    /// # Errors
    /// [`LoadError`] naming the group when its frames do not fit the store, a write fails, or
    /// the chunk reads back different.
    pub fn add_group(
        &mut self,
        name: &str,
        frames: &[RawFrame],
        source: &Path,
    ) -> Result<(), LoadError> {
        let started = match &mut self.started {
            Some(started) => started,
            None => {
                let layout = first_layout(frames, source)?;
                let writer = ZarrWriter::create(&self.path, layout, self.options.zstd_level)?;
                let progress = Progress {
                    progress_format: PROGRESS_FORMAT,
                    source_fingerprint: self.fingerprint.clone(),
                    zstd_level: self.options.zstd_level,
                    layout,
                    groups_checked: 0,
                };
                self.started.insert(Started { writer, progress })
            }
        };
        let g = started.progress.groups_checked;
        started.writer.write_group(name, frames, source)?;
        if started.writer.read_back(g)? != frames {
            let chunk = chunk_file(&self.path, g);
            return Err(LoadError::io(
                "the chunk read back differs from the frames written",
                &chunk,
            ));
        }
        // On disk before the record counts it, so a counted chunk survives a crash.
        let chunk = chunk_file(&self.path, g);
        std::fs::File::open(&chunk)
            .and_then(|f| f.sync_all())
            .map_err(|e| LoadError::io(format!("cannot sync the chunk: {e}"), &chunk))?;
        let mut next = started.progress.clone();
        next.groups_checked = g + 1;
        write_json_atomic(&self.path.join(PROGRESS_FILE), &next, true)?;
        started.progress = next;
        Ok(())
    }

    /// The partial store's folder (side files such as `reference.wav` are copied into it
    /// before [`Self::finish`]).
    #[must_use]
    pub fn folder(&self) -> &Path {
        &self.path
    }

    /// Ends the store: its metadata with `scan_toml`, renamed into place, then the record
    /// (and any temporary file a killed record write left) removed. Until the rename the
    /// partial store keeps its record, so a failure here keeps every counted group.
    ///
    /// # Errors
    /// [`LoadError::Io`] naming the store when no group was written or a write or the rename
    /// fails.
    pub fn finish(&mut self, scan_toml: &str) -> Result<FinishedStore, LoadError> {
        let Some(Started { writer, progress }) = &self.started else {
            return Err(LoadError::io("no group was written", &self.path));
        };
        writer.store_metadata(scan_toml)?;
        if self.out.exists() {
            std::fs::remove_dir(&self.out).map_err(|e| {
                LoadError::io(
                    format!("cannot replace the empty output folder: {e}"),
                    &self.out,
                )
            })?;
        }
        std::fs::rename(&self.path, &self.out).map_err(|e| {
            LoadError::io(format!("cannot move the store into place: {e}"), &self.out)
        })?;
        let record = self.out.join(PROGRESS_FILE);
        let _ = std::fs::remove_file(&record);
        remove_stale_temps(&record);
        let done = FinishedStore {
            out: self.out.clone(),
            groups: progress.groups_checked,
            resumed: self.resumed,
            layout: progress.layout,
            store_bytes: dir_bytes(&self.out),
        };
        self.started = None;
        Ok(done)
    }

    /// Ends a writer that failed: keeps the partial store when its record counts a group
    /// (what was kept goes into the error line), else removes it.
    #[must_use]
    pub fn abandon(self, total: Option<usize>) -> Option<Kept> {
        let counted = self.groups();
        if counted > 0 {
            return Some(Kept {
                groups: counted,
                total,
                partial: self.path.clone(),
            });
        }
        let _ = std::fs::remove_dir_all(&self.path);
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::frames::RawSamples;
    use crate::io::zarr::load_group_raw;
    use crate::test_support::path_in_temp_dir;

    /// Group `g`: seven 40 × 2 frames of 8-bit samples of its own.
    fn group(g: u8) -> Vec<RawFrame> {
        (0..7)
            .map(|k| RawFrame {
                width: 40,
                height: 2,
                samples: RawSamples::U8((0..80).map(|i| g ^ k ^ i).collect()),
            })
            .collect()
    }

    fn names(n: usize) -> Vec<String> {
        (0..n).map(|g| format!("g{g}")).collect()
    }

    const TOML: &str = "format = 1\n[record]\nrpm = 78.0\nradius_mm = 115.0\n[camera]\n\
        pixel_pitch_um = 0.39\nworking_distance_mm = 4.0\n[motion]\nframe_step_um = 0.78\n\
        group_step_um = 1.0\n";

    fn resume() -> PackOptions {
        PackOptions {
            zstd_level: 3,
            resume: true,
            force: false,
        }
    }

    /// A partial store of `n` counted groups at `out`, left as a kill leaves it.
    fn killed_after(out: &Path, n: u8) {
        let mut store = PartialStore::open(out, "f".into(), resume(), "", names).unwrap();
        for g in 0..n {
            store.add_group(&format!("g{g}"), &group(g), out).unwrap();
        }
        // No finish, no abandon: the lock goes with the process.
        drop(store);
        assert!(partial_path(out).join(PROGRESS_FILE).is_file());
    }

    /// `out` is a finished store of groups 0..n.
    fn assert_finished(out: &Path, n: usize) {
        let scan = crate::io::Scan::open(out).unwrap();
        assert_eq!(scan.groups.len(), n);
        for (g, entry) in scan.groups.iter().enumerate() {
            let z = entry.zarr.as_ref().unwrap();
            assert_eq!(load_group_raw(z).unwrap(), group(g as u8));
        }
        assert!(!partial_path(out).exists() && !out.join(PROGRESS_FILE).exists());
    }

    #[test]
    fn a_store_killed_after_its_last_group_was_counted_finishes_on_resume() {
        let (_dir, out) = path_in_temp_dir("s.zarr");
        killed_after(&out, 3);
        let other = PartialStore::open(&out, "g".into(), resume(), "start over", names);
        assert!(other.unwrap_err().to_string().contains("something else"));
        let mut store = PartialStore::open(&out, "f".into(), resume(), "", names).unwrap();
        assert_eq!((store.resumed(), store.groups()), (3, 3));
        let done = store.finish(TOML).unwrap();
        assert_eq!((done.groups, done.resumed), (3, 3));
        assert_finished(&out, 3);
    }

    #[test]
    fn a_counted_chunk_the_disk_lost_is_written_again() {
        let (_dir, out) = path_in_temp_dir("s.zarr");
        killed_after(&out, 3);
        std::fs::remove_file(chunk_file(&partial_path(&out), 1)).unwrap();
        let mut store = PartialStore::open(&out, "f".into(), resume(), "", names).unwrap();
        assert_eq!(store.groups(), 1);
        for g in 1..3 {
            store.add_group(&format!("g{g}"), &group(g), &out).unwrap();
        }
        store.finish(TOML).unwrap();
        assert_finished(&out, 3);
    }

    #[test]
    fn a_finish_that_fails_keeps_every_group_and_force_clears_a_damaged_record() {
        let (_dir, out) = path_in_temp_dir("s.zarr");
        killed_after(&out, 2);
        let mut store = PartialStore::open(&out, "f".into(), resume(), "", names).unwrap();
        // Something put into the output meanwhile: the rename must not replace it.
        std::fs::create_dir(&out).unwrap();
        std::fs::write(out.join("notes.txt"), "mine").unwrap();
        assert!(store.finish(TOML).is_err());
        let kept = store.abandon(Some(2)).unwrap();
        assert_eq!(kept.groups, 2);
        assert_eq!(
            std::fs::read_to_string(out.join("notes.txt")).unwrap(),
            "mine"
        );
        std::fs::remove_dir_all(&out).unwrap();

        std::fs::write(partial_path(&out).join(PROGRESS_FILE), b"{ torn").unwrap();
        let msg = PartialStore::open(&out, "f".into(), resume(), "", names)
            .unwrap_err()
            .to_string();
        assert!(
            msg.contains("cannot be read") && msg.contains("--force"),
            "{msg}"
        );
        let force = PackOptions {
            zstd_level: 3,
            resume: false,
            force: true,
        };
        let mut store = PartialStore::open(&out, "f".into(), force, "", names).unwrap();
        assert_eq!(store.groups(), 0);
        for g in 0..2 {
            store.add_group(&format!("g{g}"), &group(g), &out).unwrap();
        }
        store.finish(TOML).unwrap();
        assert_finished(&out, 2);
    }
}
