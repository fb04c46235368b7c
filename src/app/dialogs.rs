//! Native file dialogs (rfd) on a named thread, so the UI keeps drawing while one is open, and
//! the check for whether one can open at all: rfd asks the XDG desktop portal and falls back to
//! `zenity`; with neither it returns nothing, which would read as a cancel. So before asking,
//! [`native_dialogs`] looks for `zenity` on `PATH` and for a D-Bus session bus (where a portal
//! may answer); when neither is there the dialog is answered at once with
//! [`DialogAnswer::Unavailable`], and the workbench offers its own path field instead.

use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{self, Receiver, Sender};

use super::views::View;

/// What a dialog is for.
#[derive(Clone, Debug, PartialEq)]
pub enum DialogKind {
    /// Pick a scan folder.
    OpenScan,
    /// Choose where to export the clip (selection only when true).
    ExportWav(bool),
    /// Pick a preset to load.
    LoadPreset,
    /// Choose where to save the preset.
    SavePreset,
    /// Choose where to save a view as PNG.
    ExportPng(View),
    /// Pick a still image to open in the still window.
    OpenStill,
    /// Choose where to export the still's decoded groove.
    ExportStillWav,
    /// Pick a video clip to import.
    #[cfg(feature = "video")]
    VideoClip,
    /// Pick the folder an imported scan goes to.
    #[cfg(feature = "video")]
    VideoOut,
}

impl DialogKind {
    /// The dialog's title.
    #[must_use]
    pub fn title(&self) -> &'static str {
        match self {
            DialogKind::OpenScan => "Open scan folder",
            DialogKind::ExportWav(false) => "Export WAV",
            DialogKind::ExportWav(true) => "Export the selection as WAV",
            DialogKind::LoadPreset => "Load preset",
            DialogKind::SavePreset => "Save preset",
            DialogKind::ExportPng(_) => "Export view as PNG",
            DialogKind::OpenStill => "Open still image",
            DialogKind::ExportStillWav => "Export the groove as WAV",
            #[cfg(feature = "video")]
            DialogKind::VideoClip => "Import video clip",
            #[cfg(feature = "video")]
            DialogKind::VideoOut => "Folder for the imported scan (new or empty)",
        }
    }

    /// The dialog named `name` (`open-scan`, `export-wav`, `load-preset`, `save-preset`,
    /// `export-png` of the view shown first), as `GROOVESCOPE_DIALOG` names it.
    #[must_use]
    pub fn from_name(name: &str, view: View) -> Option<DialogKind> {
        match name.trim() {
            "open-scan" => Some(DialogKind::OpenScan),
            "export-wav" => Some(DialogKind::ExportWav(false)),
            "load-preset" => Some(DialogKind::LoadPreset),
            "save-preset" => Some(DialogKind::SavePreset),
            "export-png" => Some(DialogKind::ExportPng(view)),
            "open-still" => Some(DialogKind::OpenStill),
            _ => None,
        }
    }

    /// True for dialogs that choose a new file (the rest pick an existing file or folder).
    #[must_use]
    pub fn saves(&self) -> bool {
        matches!(
            self,
            DialogKind::ExportWav(_)
                | DialogKind::SavePreset
                | DialogKind::ExportPng(_)
                | DialogKind::ExportStillWav
        )
    }

    /// True for dialogs that pick a folder.
    #[must_use]
    pub fn picks_folder(&self) -> bool {
        match self {
            DialogKind::OpenScan => true,
            #[cfg(feature = "video")]
            DialogKind::VideoOut => true,
            _ => false,
        }
    }
}

/// How a dialog ended.
#[derive(Clone, Debug, PartialEq)]
pub enum DialogAnswer {
    /// The operator chose this path.
    Picked(PathBuf),
    /// It closed without a path. `maybe_unshown` is true when no `zenity` is installed, so it
    /// may never have appeared (a session bus was there, but perhaps no portal on it).
    Closed {
        /// See above.
        maybe_unshown: bool,
    },
    /// No native dialog can open here: why.
    Unavailable(String),
}

/// Which native dialog rfd can show here.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum NativeDialogs {
    /// `zenity` is installed (rfd's fallback when no portal answers): a dialog always opens.
    Zenity,
    /// No `zenity`, but a session bus on which a desktop portal may answer.
    PortalOnly,
    /// Neither: no dialog can open (the message says so).
    None(String),
}

/// What a bare machine lacks for native dialogs, said once wherever it matters.
pub const NO_DIALOG_REASON: &str = "no file dialog can open here: there is no desktop portal \
     and no zenity (scripts/setup.sh installs zenity)";

/// Which native dialogs can open, given the `PATH` value (searched for `zenity`) and whether a
/// D-Bus session bus is known.
#[must_use]
pub fn native_dialogs(path_var: Option<&OsStr>, session_bus: bool) -> NativeDialogs {
    let zenity = path_var
        .is_some_and(|p| std::env::split_paths(p).any(|dir| is_executable(&dir.join("zenity"))));
    match (zenity, session_bus) {
        (true, _) => NativeDialogs::Zenity,
        (false, true) => NativeDialogs::PortalOnly,
        (false, false) => NativeDialogs::None(NO_DIALOG_REASON.into()),
    }
}

/// [`native_dialogs`] for this process: its `PATH`, and a session bus when
/// `DBUS_SESSION_BUS_ADDRESS` is set or `$XDG_RUNTIME_DIR/bus` exists.
#[must_use]
pub fn native_dialogs_here() -> NativeDialogs {
    let bus = std::env::var_os("DBUS_SESSION_BUS_ADDRESS").is_some_and(|a| !a.is_empty())
        || std::env::var_os("XDG_RUNTIME_DIR")
            .is_some_and(|d| !d.is_empty() && Path::new(&d).join("bus").exists());
    native_dialogs(std::env::var_os("PATH").as_deref(), bus)
}

fn is_executable(p: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        p.metadata()
            .is_ok_and(|m| m.is_file() && m.permissions().mode() & 0o111 != 0)
    }
    #[cfg(not(unix))]
    {
        p.is_file()
    }
}

/// Runs one dialog at a time and hands back its answer.
#[derive(Debug)]
pub struct Dialogs {
    tx: Sender<(DialogKind, DialogAnswer)>,
    rx: Receiver<(DialogKind, DialogAnswer)>,
    open: bool,
}

impl Default for Dialogs {
    fn default() -> Self {
        let (tx, rx) = mpsc::channel();
        Self {
            tx,
            rx,
            open: false,
        }
    }
}

impl Dialogs {
    /// True while a dialog is showing.
    #[must_use]
    pub fn is_open(&self) -> bool {
        self.open
    }

    /// Opens a dialog (ignored while another is open) in the folder `start`, suggesting
    /// `file_name` for new files. When no native dialog can open, it is answered at once with
    /// [`DialogAnswer::Unavailable`].
    ///
    /// # Errors
    /// When the dialog thread cannot be started.
    pub fn show(
        &mut self,
        kind: DialogKind,
        start: Option<PathBuf>,
        file_name: Option<String>,
        repaint: Box<dyn Fn() + Send>,
    ) -> Result<(), String> {
        if self.open {
            return Ok(());
        }
        let native = native_dialogs_here();
        if let NativeDialogs::None(why) = native {
            let _ = self.tx.send((kind, DialogAnswer::Unavailable(why)));
            self.open = true;
            return Ok(());
        }
        let tx = self.tx.clone();
        std::thread::Builder::new()
            .name("groovescope-dialog".into())
            .spawn(move || {
                let maybe_unshown = native == NativeDialogs::PortalOnly;
                let picked = run_native(&kind, start.filter(|s| s.is_dir()), file_name, &native);
                let answer = match picked {
                    Some(p) => DialogAnswer::Picked(p),
                    None => DialogAnswer::Closed { maybe_unshown },
                };
                let _ = tx.send((kind, answer));
                repaint();
            })
            .map_err(|e| format!("cannot open a file dialog: {e}"))?;
        self.open = true;
        Ok(())
    }

    /// The answer of the finished dialog, if any.
    pub fn poll(&mut self) -> Option<(DialogKind, DialogAnswer)> {
        let got = self.rx.try_recv().ok();
        if got.is_some() {
            self.open = false;
        }
        got
    }
}

/// Shows the dialog through rfd. zenity ignores the starting folder and starts where its
/// `--filename` points, so when zenity is what will answer, the suggested name carries the
/// folder (a folder alone ends in `/`); the portal takes the folder and a bare name.
fn run_native(
    kind: &DialogKind,
    start: Option<PathBuf>,
    file_name: Option<String>,
    native: &NativeDialogs,
) -> Option<PathBuf> {
    let mut d = rfd::FileDialog::new().set_title(kind.title());
    // zenity reads a relative --filename from its own idea of the folder (it opened on Recent
    // or the home folder for the demo's `assets/demo`): the folder goes absolute.
    let start = start.map(|dir| std::path::absolute(&dir).unwrap_or(dir));
    let zenity_name = match (&start, &file_name) {
        (Some(dir), Some(name)) => Some(dir.join(name).display().to_string()),
        (Some(dir), None) => Some(format!("{}/", dir.display())),
        (None, name) => name.clone(),
    };
    if let Some(s) = start {
        d = d.set_directory(s);
    }
    let name = if *native == NativeDialogs::Zenity {
        zenity_name
    } else {
        file_name
    };
    if let Some(n) = name {
        d = d.set_file_name(n);
    }
    match kind {
        DialogKind::OpenScan => d.pick_folder(),
        DialogKind::ExportWav(_) => d.add_filter("WAV", &["wav"]).save_file(),
        DialogKind::LoadPreset => d.add_filter("TOML preset", &["toml"]).pick_file(),
        DialogKind::SavePreset => d.add_filter("TOML preset", &["toml"]).save_file(),
        DialogKind::ExportPng(_) => d.add_filter("PNG", &["png"]).save_file(),
        DialogKind::OpenStill => d
            .add_filter("Still image", &["png", "tif", "tiff"])
            .pick_file(),
        DialogKind::ExportStillWav => d.add_filter("WAV", &["wav"]).save_file(),
        #[cfg(feature = "video")]
        DialogKind::VideoClip => d
            .add_filter("Video", &["avi", "mp4", "mkv", "mov", "m4v"])
            .pick_file(),
        #[cfg(feature = "video")]
        DialogKind::VideoOut => d.pick_folder(),
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;

    #[test]
    fn zenity_on_the_path_or_a_session_bus_means_a_dialog_can_open() {
        let dir = tempfile::tempdir().unwrap();
        let path = std::env::join_paths([dir.path()]).unwrap();
        assert!(matches!(
            native_dialogs(Some(&path), false),
            NativeDialogs::None(_)
        ));
        assert!(matches!(
            native_dialogs(None, false),
            NativeDialogs::None(_)
        ));
        assert_eq!(native_dialogs(Some(&path), true), NativeDialogs::PortalOnly);
        let zenity = dir.path().join("zenity");
        std::fs::write(&zenity, "#!/bin/sh\n").unwrap();
        // Not executable: not a zenity.
        assert!(matches!(
            native_dialogs(Some(&path), false),
            NativeDialogs::None(_)
        ));
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(&zenity, std::fs::Permissions::from_mode(0o755)).unwrap();
            assert_eq!(native_dialogs(Some(&path), false), NativeDialogs::Zenity);
        }
    }
}
