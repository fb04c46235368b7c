//! A new output folder written under a hidden temporary name beside it and renamed into place
//! whole, so that a failed, cancelled or killed writer never leaves a half-written folder
//! where the finished one goes.
//!
//! A writer killed outright (power cut, `kill -9`) cannot clean up: the next writer of the same
//! output removes such a folder once the process that made it is gone (where the OS lets us see
//! that, i.e. Linux's `/proc`) and nothing has written to it for an hour.

use std::path::{Path, PathBuf};

use super::LoadError;

/// Suffix of the temporary folders' names: `.NAME.KIND-PID.tmp` beside the output `NAME`.
const TEMP_SUFFIX: &str = ".tmp";

/// A temporary folder touched this recently is kept even when its process id is not running
/// here: it may belong to a writer on another machine writing to the same shared folder.
const STALE_AFTER: std::time::Duration = std::time::Duration::from_secs(3600);

/// The hidden folder an output folder is written into; removed on drop unless it was moved
/// into place ([`StagedDir::finish`]).
#[derive(Debug)]
pub struct StagedDir {
    path: PathBuf,
    keep: bool,
}

impl Drop for StagedDir {
    fn drop(&mut self) {
        if !self.keep {
            let _ = std::fs::remove_dir_all(&self.path);
        }
    }
}

fn io_err(problem: String, path: &Path) -> LoadError {
    LoadError::Io {
        problem,
        path: path.to_path_buf(),
    }
}

/// The folder holding `out_dir` and the start of its temporary folders' names: a writer of
/// `kind` run by process PID writes into `{prefix}{PID}{TEMP_SUFFIX}` there.
fn parent_and_prefix(out_dir: &Path, kind: &str) -> (PathBuf, String) {
    let name = out_dir
        .file_name()
        .map_or_else(|| "scan".into(), |n| n.to_string_lossy().into_owned());
    let parent = match out_dir.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    (parent, format!(".{name}.{kind}-"))
}

impl StagedDir {
    /// Creates the hidden folder beside `out_dir` that a writer of `kind` (`import`,
    /// `synth`) fills (the folder holding `out_dir` is created when missing).
    ///
    /// # Errors
    /// [`LoadError::Io`] when a folder cannot be created.
    pub fn create(out_dir: &Path, kind: &str) -> Result<Self, LoadError> {
        let (parent, prefix) = parent_and_prefix(out_dir, kind);
        std::fs::create_dir_all(&parent)
            .map_err(|e| io_err(format!("cannot create output folder: {e}"), &parent))?;
        let path = parent.join(format!("{prefix}{}{TEMP_SUFFIX}", std::process::id()));
        std::fs::create_dir(&path)
            .map_err(|e| io_err(format!("cannot create temporary folder: {e}"), &path))?;
        Ok(Self { path, keep: false })
    }

    /// Where the output is written until it is finished.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Renames the finished folder to `out_dir`, replacing it only when it is an empty folder
    /// (`remove_dir` refuses anything else, so nothing can be lost).
    ///
    /// # Errors
    /// [`LoadError::Io`] naming `out_dir` when it cannot be replaced or the rename fails (the
    /// temporary folder is then removed).
    pub fn finish(mut self, out_dir: &Path) -> Result<(), LoadError> {
        if out_dir.exists() {
            std::fs::remove_dir(out_dir).map_err(|e| {
                io_err(
                    format!("cannot replace the empty output folder: {e}"),
                    out_dir,
                )
            })?;
        }
        std::fs::rename(&self.path, out_dir).map_err(|e| {
            io_err(
                format!("cannot move the finished folder into place: {e}"),
                out_dir,
            )
        })?;
        self.keep = true;
        Ok(())
    }
}

/// Whether `dir` or any entry directly in it was modified within [`STALE_AFTER`] (or its
/// times cannot be read).
fn recently_touched(dir: &Path) -> bool {
    let recent = |m: std::io::Result<std::fs::Metadata>| {
        m.and_then(|m| m.modified())
            .ok()
            .and_then(|t| t.elapsed().ok())
            .is_none_or(|age| age < STALE_AFTER)
    };
    recent(std::fs::metadata(dir))
        || std::fs::read_dir(dir).map_or(true, |entries| {
            entries.flatten().any(|e| recent(e.metadata()))
        })
}

/// Removes the temporary folders of earlier writers of `kind` to `out_dir` whose process no
/// longer runs (`.NAME.KIND-PID.tmp` beside it, PID not in `/proc`) and that nothing has
/// touched for an hour (`STALE_AFTER`); returns them. Without `/proc` nothing is removed: a live
/// writer's folder must never go.
#[must_use]
pub fn remove_stale(out_dir: &Path, kind: &str) -> Vec<PathBuf> {
    if !Path::new("/proc/self").exists() {
        return Vec::new();
    }
    let mut removed = Vec::new();
    for (path, pid) in unfinished(out_dir, kind) {
        let alive = pid == std::process::id() || Path::new("/proc").join(pid.to_string()).exists();
        if !alive && !recently_touched(&path) && std::fs::remove_dir_all(&path).is_ok() {
            removed.push(path);
        }
    }
    removed
}

/// The temporary folders beside `out_dir` of writers of `kind`, each with the id of the
/// process that made it, sorted by path.
#[must_use]
pub fn unfinished(out_dir: &Path, kind: &str) -> Vec<(PathBuf, u32)> {
    let (parent, prefix) = parent_and_prefix(out_dir, kind);
    let Ok(entries) = std::fs::read_dir(&parent) else {
        return Vec::new();
    };
    let mut found: Vec<(PathBuf, u32)> = entries
        .flatten()
        .filter_map(|entry| {
            let pid = entry
                .file_name()
                .to_str()?
                .strip_prefix(&prefix)?
                .strip_suffix(TEMP_SUFFIX)?
                .parse::<u32>()
                .ok()?;
            let path = entry.path();
            path.is_dir().then_some((path, pid))
        })
        .collect();
    found.sort();
    found
}
