//! Output locks: one writer at a time for an output file, across processes and workbench windows.
//!
//! A lock is an OS file lock (`flock`) on a hidden `.NAME.lock` file beside the output. It is
//! taken without waiting: a second `reconstruct` or workbench export to the same file is
//! refused at once with one line, instead of racing the first and mixing their files (a WAV of
//! one run beside the report of the other). The OS drops the lock when its holder exits, even
//! when it is killed, so a stale lock file never blocks anyone; the holder removes the file
//! when it is done.

use std::fs::{File, OpenOptions, TryLockError};
use std::path::{Path, PathBuf};

use super::LoadError;

/// Attempts to take a lock whose file a finishing holder removed at the same moment.
const LOCK_ATTEMPTS: usize = 8;

/// The lock file of `target`: `.NAME.lock` in the same folder.
#[must_use]
pub fn lock_path(target: &Path) -> PathBuf {
    super::atomic::beside(target, "out", |name| format!(".{name}.lock"))
}

/// An exclusive lock on one output file, held until dropped.
#[derive(Debug)]
pub struct OutputLock {
    /// The locked file (the lock lives as long as it is open).
    file: File,
    /// Its path, removed on drop.
    path: PathBuf,
}

impl OutputLock {
    /// Takes the lock on `target` (the output file, which need not exist yet).
    ///
    /// # Errors
    /// [`LoadError::Io`] naming `target` when another process or window holds the lock, or
    /// the lock file cannot be made (for example when the output folder does not exist).
    pub fn acquire(target: &Path) -> Result<Self, LoadError> {
        let path = lock_path(target);
        let io_err = |e: std::io::Error| LoadError::Io {
            problem: format!("cannot lock the output ({}): {e}", path.display()),
            path: target.to_path_buf(),
        };
        for _ in 0..LOCK_ATTEMPTS {
            let file = OpenOptions::new()
                .create(true)
                .truncate(false)
                .write(true)
                .open(&path)
                .map_err(io_err)?;
            match file.try_lock() {
                Ok(()) => {}
                Err(TryLockError::WouldBlock) => {
                    return Err(LoadError::Io {
                        problem: "another groovescope run or window is writing this output now; \
                                  wait for it to finish or choose another file"
                            .into(),
                        path: target.to_path_buf(),
                    });
                }
                Err(TryLockError::Error(e)) => return Err(io_err(e)),
            }
            // A holder that finished between our open and our lock removed the file we
            // locked; the lock only counts on the file the path still names.
            if same_file(&file, &path) {
                return Ok(Self { file, path });
            }
        }
        Err(LoadError::Io {
            problem: "cannot lock the output: its lock file keeps being replaced".into(),
            path: target.to_path_buf(),
        })
    }
}

impl Drop for OutputLock {
    fn drop(&mut self) {
        // Removed while still locked, so a waiting taker sees the change (see `acquire`).
        let _ = std::fs::remove_file(&self.path);
        let _ = self.file.unlock();
    }
}

#[cfg(unix)]
fn same_file(file: &File, path: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    match (file.metadata(), std::fs::metadata(path)) {
        (Ok(a), Ok(b)) => a.dev() == b.dev() && a.ino() == b.ino(),
        _ => false,
    }
}

#[cfg(not(unix))]
fn same_file(_file: &File, path: &Path) -> bool {
    path.exists()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::path_in_temp_dir;

    #[test]
    fn a_second_lock_on_the_same_output_is_refused_until_the_first_is_dropped() {
        let (dir, out) = path_in_temp_dir("clip.wav");
        let first = OutputLock::acquire(&out).unwrap();
        assert!(lock_path(&out).exists());
        let msg = OutputLock::acquire(&out).unwrap_err().to_string();
        assert!(msg.contains("clip.wav") && msg.contains("another"), "{msg}");
        // Another output in the same folder is not affected.
        let other = OutputLock::acquire(&dir.path().join("other.wav")).unwrap();
        drop(first);
        assert!(!lock_path(&out).exists(), "the lock file is removed");
        let again = OutputLock::acquire(&out).unwrap();
        drop((again, other));
        let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert!(names.is_empty(), "nothing left behind: {names:?}");
    }

    #[test]
    fn a_missing_output_folder_is_one_clear_error() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("gone").join("clip.wav");
        let msg = OutputLock::acquire(&out).unwrap_err().to_string();
        assert!(msg.contains("gone/clip.wav"), "{msg}");
    }
}
