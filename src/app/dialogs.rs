//! Native file dialogs (rfd) run on a named thread so the UI keeps drawing while one is open.

use std::path::PathBuf;
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
    /// Pick a video clip to import.
    #[cfg(feature = "video")]
    VideoClip,
    /// Pick the folder an imported scan goes to.
    #[cfg(feature = "video")]
    VideoOut,
}

/// Runs one dialog at a time and hands back its answer.
#[derive(Debug)]
pub struct Dialogs {
    tx: Sender<(DialogKind, Option<PathBuf>)>,
    rx: Receiver<(DialogKind, Option<PathBuf>)>,
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

    /// Opens a dialog (ignored while another is open); `start` is the folder it starts in.
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
        let tx = self.tx.clone();
        std::thread::Builder::new()
            .name("groovescope-dialog".into())
            .spawn(move || {
                let mut d = rfd::FileDialog::new();
                if let Some(s) = start.filter(|s| s.is_dir()) {
                    d = d.set_directory(s);
                }
                if let Some(n) = file_name {
                    d = d.set_file_name(n);
                }
                let picked = match &kind {
                    DialogKind::OpenScan => d.set_title("Open scan folder").pick_folder(),
                    DialogKind::ExportWav(_) => d
                        .set_title("Export WAV")
                        .add_filter("WAV", &["wav"])
                        .save_file(),
                    DialogKind::LoadPreset => d
                        .set_title("Load preset")
                        .add_filter("TOML preset", &["toml"])
                        .pick_file(),
                    DialogKind::SavePreset => d
                        .set_title("Save preset")
                        .add_filter("TOML preset", &["toml"])
                        .save_file(),
                    DialogKind::ExportPng(_) => d
                        .set_title("Export view as PNG")
                        .add_filter("PNG", &["png"])
                        .save_file(),
                    #[cfg(feature = "video")]
                    DialogKind::VideoClip => d
                        .set_title("Import video clip")
                        .add_filter("Video", &["avi", "mp4", "mkv", "mov", "m4v"])
                        .pick_file(),
                    #[cfg(feature = "video")]
                    DialogKind::VideoOut => d
                        .set_title("Folder for the imported scan (new or empty)")
                        .pick_folder(),
                };
                let _ = tx.send((kind, picked));
                repaint();
            })
            .map_err(|e| format!("cannot open a file dialog: {e}"))?;
        self.open = true;
        Ok(())
    }

    /// The answer of the finished dialog, if any (None inside: cancelled).
    pub fn poll(&mut self) -> Option<(DialogKind, Option<PathBuf>)> {
        let got = self.rx.try_recv().ok();
        if got.is_some() {
            self.open = false;
        }
        got
    }
}
