//! The recent-scans list, kept as a small TOML file under the user's config folder.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

/// Env var that overrides the config folder (tests point it at a temporary folder).
pub const CONFIG_DIR_ENV: &str = "GROOVESCOPE_CONFIG_DIR";

/// Most scans remembered.
pub const MAX_RECENT: usize = 10;

/// File name of the list inside the config folder.
const RECENT_FILE: &str = "recent.toml";

/// The config folder: `$GROOVESCOPE_CONFIG_DIR`, else `$XDG_CONFIG_HOME/groovescope`, else
/// `~/.config/groovescope` (None when none of them is known).
#[must_use]
pub fn config_dir() -> Option<PathBuf> {
    if let Some(d) = std::env::var_os(CONFIG_DIR_ENV) {
        return Some(PathBuf::from(d));
    }
    if let Some(d) = std::env::var_os("XDG_CONFIG_HOME").filter(|d| !d.is_empty()) {
        return Some(PathBuf::from(d).join("groovescope"));
    }
    std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".config").join("groovescope"))
}

#[derive(Serialize, Deserialize, Default)]
struct RecentFile {
    scans: Vec<PathBuf>,
}

/// Recently opened scan folders, newest first.
#[derive(Clone, Debug, Default)]
pub struct RecentScans {
    /// The folders, newest first.
    pub scans: Vec<PathBuf>,
    file: Option<PathBuf>,
}

impl RecentScans {
    /// Reads the list from `dir` (an empty list when the file is missing or unreadable).
    #[must_use]
    pub fn load(dir: Option<&Path>) -> Self {
        let file = dir.map(|d| d.join(RECENT_FILE));
        let scans = file
            .as_ref()
            .and_then(|f| std::fs::read_to_string(f).ok())
            .and_then(|t| toml::from_str::<RecentFile>(&t).ok())
            .map(|r| r.scans)
            .unwrap_or_default();
        Self { scans, file }
    }

    /// Puts `scan` first (removing an older entry) and saves the list.
    ///
    /// # Errors
    /// A message when the list cannot be written (the list in memory is updated anyway).
    pub fn push(&mut self, scan: &Path) -> Result<(), String> {
        let scan = scan.canonicalize().unwrap_or_else(|_| scan.to_path_buf());
        self.scans.retain(|p| p != &scan);
        self.scans.insert(0, scan);
        self.scans.truncate(MAX_RECENT);
        self.save()
    }

    /// Drops folders that no longer exist.
    pub fn prune(&mut self) {
        self.scans.retain(|p| p.is_dir());
    }

    fn save(&self) -> Result<(), String> {
        let Some(file) = &self.file else {
            return Ok(());
        };
        if let Some(parent) = file.parent() {
            std::fs::create_dir_all(parent)
                .map_err(|e| format!("cannot create {}: {e}", parent.display()))?;
        }
        let text = toml::to_string_pretty(&RecentFile {
            scans: self.scans.clone(),
        })
        .map_err(|e| e.to_string())?;
        crate::io::write_atomic(file, text.as_bytes(), true).map_err(|e| e.to_string())
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;

    #[test]
    fn newest_first_without_duplicates_and_survives_reload() {
        let cfg = tempfile::tempdir().unwrap();
        let a = tempfile::tempdir().unwrap();
        let b = tempfile::tempdir().unwrap();
        let mut r = RecentScans::load(Some(cfg.path()));
        assert!(r.scans.is_empty());
        r.push(a.path()).unwrap();
        r.push(b.path()).unwrap();
        r.push(a.path()).unwrap();
        let back = RecentScans::load(Some(cfg.path()));
        assert_eq!(back.scans.len(), 2);
        assert_eq!(back.scans[0], a.path().canonicalize().unwrap());
        std::fs::write(cfg.path().join(RECENT_FILE), "not = [toml").unwrap();
        assert!(RecentScans::load(Some(cfg.path())).scans.is_empty());
    }
}
