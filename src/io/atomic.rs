//! Atomic file output: write a temporary file beside the target, sync it, then rename it into place.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use super::LoadError;

/// A file beside `target`, named by `name_of` from `target`'s file name (`fallback` when it
/// has none).
#[must_use]
pub fn beside(target: &Path, fallback: &str, name_of: impl FnOnce(&str) -> String) -> PathBuf {
    let name = target
        .file_name()
        .map_or_else(|| fallback.to_owned(), |n| n.to_string_lossy().into_owned());
    target.with_file_name(name_of(&name))
}

/// A temporary name beside `target`, unique to this process and this write (two threads, or
/// two windows, writing the same target never share one).
fn temp_path(target: &Path) -> PathBuf {
    static NEXT: AtomicU64 = AtomicU64::new(0);
    let n = NEXT.fetch_add(1, Ordering::Relaxed);
    beside(target, "out", |name| {
        format!(".{name}.{}.{n}.tmp", std::process::id())
    })
}

/// Removes the temporary files that writes of `target` killed part way left beside it
/// (the names `write_atomic_with` gives them: `.NAME.PID.N.tmp`), whichever process made them.
pub fn remove_stale_temps(target: &Path) {
    let (Some(dir), Some(name)) = (target.parent(), target.file_name()) else {
        return;
    };
    let prefix = format!(".{}.", name.to_string_lossy());
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let entry = e.file_name().to_string_lossy().into_owned();
        if entry.starts_with(&prefix) && entry.ends_with(".tmp") {
            let _ = std::fs::remove_file(e.path());
        }
    }
}

/// Moves the finished temporary file to `target`. Without `overwrite` this never replaces a
/// file that appeared meanwhile (another run writing the same output): the file is linked
/// in under the new name, which fails when the name exists, and the temporary name removed.
/// File systems without hard links fall back to a rename after a fresh check.
fn publish(tmp: &Path, target: &Path, overwrite: bool) -> std::io::Result<()> {
    if overwrite {
        return std::fs::rename(tmp, target);
    }
    match std::fs::hard_link(tmp, target) {
        Ok(()) => std::fs::remove_file(tmp),
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => Err(std::io::Error::new(
            e.kind(),
            "another writer created the file meanwhile; it was left as it is (use --force to replace it)",
        )),
        Err(_) if !target.exists() => std::fs::rename(tmp, target),
        Err(e) => Err(e),
    }
}

/// Writes a file atomically through `fill`, which receives a buffered writer.
///
/// The target appears complete or not at all. Unless `overwrite` is true an existing
/// target is an error and is left untouched.
///
/// # Errors
/// [`LoadError::Io`] naming the target when it exists (and `overwrite` is false), or when
/// any write fails (a full disk, for example); the temporary file is removed.
pub fn write_atomic_with(
    target: &Path,
    overwrite: bool,
    fill: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
) -> Result<(), LoadError> {
    if !overwrite && target.exists() {
        return Err(LoadError::Io {
            problem: "refusing to overwrite an existing file (use --force)".into(),
            path: target.to_path_buf(),
        });
    }
    let tmp = temp_path(target);
    let result = (|| -> std::io::Result<()> {
        let file = File::create(&tmp)?;
        let mut w = BufWriter::new(file);
        fill(&mut w)?;
        w.flush()?;
        let file = w
            .into_inner()
            .map_err(std::io::IntoInnerError::into_error)?;
        file.sync_all()?;
        drop(file);
        publish(&tmp, target, overwrite)
    })();
    result.map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        LoadError::Io {
            problem: format!("cannot write file: {e}"),
            path: target.to_path_buf(),
        }
    })
}

/// Writes `bytes` to `target` atomically (see [`write_atomic_with`]).
///
/// # Errors
/// As [`write_atomic_with`].
pub fn write_atomic(target: &Path, bytes: &[u8], overwrite: bool) -> Result<(), LoadError> {
    write_atomic_with(target, overwrite, |w| w.write_all(bytes))
}

/// Writes `value` as pretty JSON to `target` atomically, streamed through the file's buffer
/// (a whole side's report is never held as one string).
///
/// # Errors
/// As [`write_atomic_with`].
pub fn write_json_atomic(
    target: &Path,
    value: &impl serde::Serialize,
    overwrite: bool,
) -> Result<(), LoadError> {
    write_atomic_with(target, overwrite, |w| {
        serde_json::to_writer_pretty(w, value).map_err(std::io::Error::from)
    })
}

/// Whether `dir` may receive a new scan: it does not exist, or it is an empty folder.
/// Shared by the generator and the video import, which never write into a non-empty folder.
///
/// # Errors
/// [`LoadError::Io`] naming the folder when it cannot be listed.
pub(crate) fn dir_is_missing_or_empty(dir: &Path) -> Result<bool, LoadError> {
    if !dir.exists() {
        return Ok(true);
    }
    if !dir.is_dir() {
        return Ok(false);
    }
    let mut entries = std::fs::read_dir(dir).map_err(|e| LoadError::Io {
        problem: format!("cannot list output folder: {e}"),
        path: dir.to_path_buf(),
    })?;
    Ok(entries.next().is_none())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::path_in_temp_dir;

    #[test]
    fn refuses_to_overwrite_and_leaves_no_temp_file() {
        let (dir, p) = path_in_temp_dir("a.txt");
        write_atomic(&p, b"one", false).unwrap();
        let err = write_atomic(&p, b"two", false).unwrap_err();
        assert!(err.to_string().contains("a.txt"));
        assert_eq!(std::fs::read(&p).unwrap(), b"one");
        write_atomic(&p, b"two", true).unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"two");
        let failed = write_atomic_with(&dir.path().join("b.txt"), false, |_| {
            Err(std::io::Error::other("disk full"))
        });
        assert!(failed.unwrap_err().to_string().contains("disk full"));
        let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(names.len(), 1, "only a.txt remains");
    }
}
