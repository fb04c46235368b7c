//! Files the operator picks and writes: the native dialogs, the in-app path field offered when
//! no dialog can open (or one closed without a file and may never have shown), the question
//! before a file is replaced or unsaved knobs are left behind, the recent scans, and the names
//! suggested for new files (from the scan: `<scan>-<path>.wav`).

use std::path::{Path, PathBuf};

use super::dialogs::{DialogKind, Dialogs};
use super::recent::RecentScans;
use super::views::View;

/// A question waiting for the operator.
#[derive(Clone, Debug, PartialEq)]
pub enum Confirm {
    /// Replace an existing WAV (and sidecar).
    ExportWav {
        /// Target.
        path: PathBuf,
        /// Selection only.
        selection: bool,
    },
    /// Replace an existing preset file.
    SavePreset(PathBuf),
    /// Replace an existing PNG.
    ExportPng(PathBuf, View),
    /// Open another scan although the knobs were changed since the preset (or defaults).
    SwitchScan(PathBuf),
    /// Replace an existing WAV (and report) with the still's decoded groove.
    ExportStill(PathBuf),
}

/// The in-app path field: what it is for, why it is shown, and the path typed so far.
#[derive(Clone, Debug, PartialEq)]
pub struct PathPrompt {
    /// The dialog it stands in for.
    pub kind: DialogKind,
    /// Why no native dialog is used.
    pub reason: String,
    /// The path being typed (starts as the suggestion).
    pub text: String,
}

/// Dialogs, questions and the recent-scans list.
#[derive(Debug, Default)]
pub struct Files {
    /// Native dialogs.
    pub dialogs: Dialogs,
    /// The question waiting for an answer.
    pub confirm: Option<Confirm>,
    /// The in-app path field, when shown.
    pub prompt: Option<PathPrompt>,
    /// Recently opened scans.
    pub recent: RecentScans,
}

/// The stem new files are named after: the scan folder's name (`scan` when it has none).
#[must_use]
pub fn scan_stem(scan_dir: Option<&Path>) -> String {
    scan_dir
        .and_then(Path::file_name)
        .map_or_else(|| "scan".into(), |n| n.to_string_lossy().into_owned())
}

/// The file name suggested for `kind` for a scan in `scan_dir` reconstructed on `path_name`
/// (`depth` or `dual-focus`): `<scan>-<path>.wav` (`-selection` for a selection), the scan's own
/// `preset.toml`, `<scan>-<view>.png`; None for dialogs that pick what exists.
#[must_use]
pub fn suggested_name(
    kind: &DialogKind,
    scan_dir: Option<&Path>,
    path_name: &str,
) -> Option<String> {
    let stem = scan_stem(scan_dir);
    match kind {
        DialogKind::ExportWav(false) => Some(format!("{stem}-{path_name}.wav")),
        DialogKind::ExportWav(true) => Some(format!("{stem}-{path_name}-selection.wav")),
        DialogKind::SavePreset => Some(super::tuning::SCAN_PRESET_FILE.into()),
        DialogKind::ExportPng(v) => Some(format!("{stem}-{}.png", v.name())),
        _ => None,
    }
}

/// The file name offered for the still's decoded groove: `IMAGE-grooveN.wav`.
#[must_use]
pub fn still_export_name(doc: &super::still::StillDoc) -> Option<String> {
    let stem = doc.path.file_stem()?.to_string_lossy().into_owned();
    let run = doc.run.as_ref()?;
    let n = run
        .analysis
        .grooves
        .grooves
        .get(run.analysis.chosen)?
        .number;
    Some(format!("{stem}-groove{n}.wav"))
}

/// The path the in-app field starts with: the suggested file in the scan folder, or the folder.
#[must_use]
pub fn suggested_path(start: Option<&Path>, name: Option<&str>) -> String {
    match (start, name) {
        (Some(dir), Some(n)) => dir.join(n).display().to_string(),
        (Some(dir), None) => dir.display().to_string(),
        (None, Some(n)) => n.to_string(),
        (None, None) => String::new(),
    }
}

/// The typed path: trimmed, `~/` expanded to the home folder.
#[must_use]
pub fn typed_path(text: &str) -> Option<PathBuf> {
    let t = text.trim();
    if t.is_empty() {
        return None;
    }
    if let Some(rest) = t.strip_prefix("~/")
        && let Some(home) = std::env::var_os("HOME")
    {
        return Some(PathBuf::from(home).join(rest));
    }
    Some(PathBuf::from(t))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn new_files_are_named_after_the_scan() {
        let dir = Path::new("/discs/caruso-1907");
        assert_eq!(
            suggested_name(&DialogKind::ExportWav(false), Some(dir), "dual-focus").as_deref(),
            Some("caruso-1907-dual-focus.wav")
        );
        assert_eq!(
            suggested_name(&DialogKind::ExportPng(View::Flow), Some(dir), "depth").as_deref(),
            Some("caruso-1907-flow.png")
        );
        assert_eq!(
            suggested_name(&DialogKind::SavePreset, Some(dir), "depth").as_deref(),
            Some("preset.toml")
        );
        assert!(suggested_name(&DialogKind::OpenScan, Some(dir), "depth").is_none());
        assert_eq!(
            suggested_path(Some(dir), Some("preset.toml")),
            "/discs/caruso-1907/preset.toml"
        );
        assert_eq!(typed_path("  /a/b.wav "), Some(PathBuf::from("/a/b.wav")));
        assert_eq!(typed_path("   "), None);
    }
}
