//! Where the bundled demos (`assets/…`) are found: the working folder, beside the executable, then the source tree the binary was built from.

use std::path::{Path, PathBuf};

/// The places a bundled asset `rel` (such as `assets/demo`) may lie, in the order they are
/// tried: under the working folder, beside the executable (a copied release with its
/// `assets/`), then in the source tree the binary was built from.
#[must_use]
pub fn candidates(rel: &str) -> Vec<PathBuf> {
    let beside_exe = std::env::current_exe()
        .ok()
        .and_then(|exe| exe.parent().map(|dir| dir.join(rel)));
    std::iter::once(PathBuf::from(rel))
        .chain(beside_exe)
        .chain(std::iter::once(
            Path::new(env!("CARGO_MANIFEST_DIR")).join(rel),
        ))
        .collect()
}

/// The first of [`candidates`] that `holds_it` accepts.
#[must_use]
pub fn find(rel: &str, holds_it: impl Fn(&Path) -> bool) -> Option<PathBuf> {
    candidates(rel).into_iter().find(|p| holds_it(p))
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;

    #[test]
    fn the_working_folder_comes_first_then_the_executable_then_the_sources() {
        let c = candidates("assets/demo");
        assert_eq!(c.len(), 3);
        assert_eq!(c[0], Path::new("assets/demo"));
        let exe_dir = std::env::current_exe()
            .unwrap()
            .parent()
            .unwrap()
            .to_path_buf();
        assert_eq!(c[1], exe_dir.join("assets/demo"));
        assert_eq!(
            c[2],
            Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/demo")
        );
        // The test binary's folder holds no assets: the source tree's demo is found.
        let found = find("assets/demo", crate::io::Scan::is_scan_dir).unwrap();
        assert!(found.ends_with("assets/demo"), "{found:?}");
    }
}
