//! Fixtures shared by the unit tests of several modules of the crate.

use std::path::PathBuf;

/// A path named `name` in a fresh temporary folder, which lives as long as the returned guard.
#[allow(clippy::unwrap_used)] // test support: a temporary folder can be made
pub(crate) fn path_in_temp_dir(name: &str) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(name);
    (dir, path)
}
