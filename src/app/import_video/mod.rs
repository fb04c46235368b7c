//! "Import video…" (features `gui` + `video`): a form for the clip, its grouping and metadata, an
//! import on a named worker thread with progress and cancel, then the new scan opens.
//!
//! The scan is written as a folder of PNG frames or, for long clips, as a Zarr store (one zstd
//! chunk per group, as `import-video --zarr` writes it). A stopped store import keeps the groups
//! it wrote, and importing into the same store again goes on from there.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc::{self, Receiver};
use std::thread::JoinHandle;

use egui::{Color32, Grid, Ui};

use super::dialogs::DialogKind;
use super::views::meta_ui::number_row;
use crate::io::Cut;
use crate::io::video::{
    ClipMeta, GroupLayout, ImportSummary, VideoError, import_video, import_video_to_store,
};
use crate::io::zarr::{DEFAULT_ZSTD_LEVEL, PackOptions, kept_groups};
use crate::job::Job;

/// The form's draft: everything [`import_video`] needs.
#[derive(Clone, Debug, PartialEq)]
pub struct ImportForm {
    /// The clip.
    pub clip: Option<PathBuf>,
    /// The output scan folder (or store), as typed or picked.
    pub out: String,
    /// Write a Zarr store rather than a folder of PNG frames (also chosen by an output name
    /// ending in `.zarr`).
    pub store: bool,
    /// Into a store that an interrupted import left groups for: discard them and start over
    /// (otherwise the import goes on from them).
    pub start_over: bool,
    /// Frames per group.
    pub frames_per_group: usize,
    /// Frames between the first frames of consecutive groups.
    pub group_stride_frames: usize,
    /// Most groups written; 0 = all the clip holds.
    pub max_groups: usize,
    /// Metadata; `group_step_um` is used only when `own_group_step` is on.
    pub meta: ClipMeta,
    /// Whether the operator gives the group step rather than stride × frame step.
    pub own_group_step: bool,
    /// The group step when `own_group_step` is on.
    pub group_step_um: f64,
}

impl Default for ImportForm {
    fn default() -> Self {
        let layout = GroupLayout::default();
        let meta = ClipMeta::default();
        Self {
            clip: None,
            out: String::new(),
            store: false,
            start_over: false,
            frames_per_group: layout.frames_per_group,
            group_stride_frames: layout.stride(),
            max_groups: 0,
            group_step_um: layout.stride() as f64 * meta.frame_step_um,
            meta,
            own_group_step: false,
        }
    }
}

/// A validated request.
#[derive(Clone, Debug, PartialEq)]
pub struct ImportRequest {
    /// The clip.
    pub clip: PathBuf,
    /// The output folder or store.
    pub out: PathBuf,
    /// For a Zarr store, how it is written (resume or start over); None for a folder.
    pub store: Option<PackOptions>,
    /// Grouping.
    pub layout: GroupLayout,
    /// Metadata.
    pub meta: ClipMeta,
}

impl ImportForm {
    /// The request the form describes, or the first problem (checked as the import checks).
    ///
    /// # Errors
    /// A sentence for the form.
    pub fn request(&self) -> Result<ImportRequest, String> {
        let (clip, out) = self.check_files()?;
        self.request_for(clip, out)
    }

    /// The clip and the output, checked on disk: the clip is a file, the output's folder
    /// exists and the output is new or empty.
    ///
    /// # Errors
    /// A sentence for the form.
    fn check_files(&self) -> Result<(PathBuf, PathBuf), String> {
        let Some(clip) = self.clip.clone() else {
            return Err("choose a video clip".into());
        };
        if !clip.is_file() {
            return Err(format!("no such video file: {}", clip.display()));
        }
        if self.out.trim().is_empty() {
            return Err("choose an output folder".into());
        }
        let out = PathBuf::from(self.out.trim());
        // As the command line checks it: a mistyped parent is named, never created.
        if let Err(e) = crate::output_checks::check_parent_exists(&out) {
            return Err(e.to_string());
        }
        if out.exists() && std::fs::read_dir(&out).map_or(true, |mut d| d.next().is_some()) {
            return Err(format!(
                "the output folder must be new or empty: {}",
                out.display()
            ));
        }
        Ok((clip, out))
    }

    /// The request for checked files: the grouping and the metadata checked.
    fn request_for(&self, clip: PathBuf, out: PathBuf) -> Result<ImportRequest, String> {
        let layout = GroupLayout {
            frames_per_group: self.frames_per_group,
            group_stride_frames: Some(self.group_stride_frames),
            first_frame: 0,
            max_groups: (self.max_groups > 0).then_some(self.max_groups),
        };
        layout.validate()?;
        let meta = ClipMeta {
            group_step_um: self.own_group_step.then_some(self.group_step_um),
            ..self.meta.clone()
        };
        meta.scan_meta(&layout).map_err(|e| e.to_string())?;
        let store = self.writes_store().then_some(PackOptions {
            zstd_level: DEFAULT_ZSTD_LEVEL,
            resume: !self.start_over,
            force: self.start_over,
        });
        Ok(ImportRequest {
            clip,
            out,
            store,
            layout,
            meta,
        })
    }

    /// Whether the import writes a Zarr store: asked for, or named `….zarr`.
    #[must_use]
    pub fn writes_store(&self) -> bool {
        self.store
            || Path::new(self.out.trim())
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("zarr"))
    }

    /// Groups that an interrupted import into the chosen store kept (None: a folder, or
    /// nothing kept).
    #[must_use]
    pub fn kept_groups(&self) -> Option<usize> {
        let out = self.out.trim();
        (self.writes_store() && !out.is_empty())
            .then(|| kept_groups(Path::new(out)))
            .flatten()
    }

    /// Sets the output from a picked folder: itself when empty, else `<folder>/<clip
    /// stem>-scan` (`.zarr` added for a store).
    pub fn set_out_from_pick(&mut self, folder: &Path) {
        let empty = std::fs::read_dir(folder).is_ok_and(|mut d| d.next().is_none());
        let out = if empty {
            folder.to_path_buf()
        } else {
            let stem = self
                .clip
                .as_ref()
                .and_then(|c| c.file_stem())
                .map_or_else(|| "imported".into(), |s| s.to_string_lossy().into_owned());
            let ext = if self.store { ".zarr" } else { "" };
            folder.join(format!("{stem}-scan{ext}"))
        };
        self.out = out.display().to_string();
    }
}

/// An import running on the `groovescope-import` thread.
#[derive(Debug)]
pub struct ImportRun {
    cancel: Arc<AtomicBool>,
    done: Arc<AtomicUsize>,
    total: Arc<AtomicUsize>,
    rx: Receiver<Result<ImportSummary, String>>,
    thread: Option<JoinHandle<()>>,
}

impl ImportRun {
    /// Starts importing; `repaint` wakes the UI on progress and at the end.
    ///
    /// # Errors
    /// When the thread cannot be started.
    pub fn start(
        req: ImportRequest,
        repaint: Box<dyn Fn() + Send + Sync>,
    ) -> std::io::Result<Self> {
        let cancel = Arc::new(AtomicBool::new(false));
        let done = Arc::new(AtomicUsize::new(0));
        let total = Arc::new(AtomicUsize::new(0));
        let (tx, rx) = mpsc::channel();
        let (flag, d, t) = (cancel.clone(), done.clone(), total.clone());
        let thread = std::thread::Builder::new()
            .name("groovescope-import".into())
            .spawn(move || {
                let progress = |n: usize, of: usize| {
                    d.store(n, Ordering::Relaxed);
                    t.store(of, Ordering::Relaxed);
                    repaint();
                };
                // A store keeps what it checked before a crash (its record is on disk).
                let crashed = if req.store.is_some() {
                    format!(
                        "the import crashed (a bug); any groups it wrote and checked are kept{GO_ON}"
                    )
                } else {
                    "the import crashed (a bug); nothing was written".to_owned()
                };
                let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                    let job = Job::new(&progress, &flag);
                    match req.store {
                        Some(options) => import_video_to_store(
                            &req.clip,
                            &req.out,
                            &req.layout,
                            &req.meta,
                            options,
                            job,
                        ),
                        None => import_video(&req.clip, &req.out, &req.layout, &req.meta, job),
                    }
                }));
                let outcome = match result {
                    Ok(r) => r.map_err(|e| failure_line(&e)),
                    Err(_) => Err(crashed),
                };
                let _ = tx.send(outcome);
                repaint();
            })?;
        Ok(Self {
            cancel,
            done,
            total,
            rx,
            thread: Some(thread),
        })
    }

    /// Frames decoded and expected (0 = unknown).
    #[must_use]
    pub fn progress(&self) -> (usize, usize) {
        (
            self.done.load(Ordering::Relaxed),
            self.total.load(Ordering::Relaxed),
        )
    }

    /// Asks the thread to stop: a folder import removes what it wrote, a store import keeps
    /// the groups it wrote and checked for the next import into that store.
    pub fn cancel(&self) {
        self.cancel.store(true, Ordering::Relaxed);
    }

    /// The outcome once the thread finished.
    pub fn poll(&mut self) -> Option<Result<ImportSummary, String>> {
        let got = self.rx.try_recv().ok()?;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        Some(got)
    }
}

impl Drop for ImportRun {
    fn drop(&mut self) {
        self.cancel();
    }
}

/// What the window adds to a line saying that a store import stopped and kept groups.
const GO_ON: &str = ": Import into the same store goes on from there";

/// A failed import in one line for the window; a stopped store import says how to go on in
/// the workbench's terms.
fn failure_line(e: &VideoError) -> String {
    match e {
        VideoError::Kept { .. } => format!("{e}{GO_ON}"),
        e => e.to_string(),
    }
}

/// The window's state on the workbench.
#[derive(Debug, Default)]
pub struct VideoImport {
    /// The form, while the window is open.
    pub form: Option<ImportForm>,
    /// The running import.
    pub run: Option<ImportRun>,
    /// The last failure, shown in the window.
    pub problem: Option<String>,
    /// The form's files as last looked at on disk.
    on_disk: Option<OnDisk>,
}

/// What the form's files look like on disk: read when the clip, the output or the choice of a
/// store changes, or an import ends, not on every frame the window draws (a stalled network
/// folder would stall the window with it). Import checks them afresh.
#[derive(Debug)]
struct OnDisk {
    /// The clip, the output as typed, and whether it is a store.
    key: (Option<PathBuf>, String, bool),
    /// [`ImportForm::check_files`].
    files: Result<(PathBuf, PathBuf), String>,
    /// [`ImportForm::kept_groups`].
    kept: Option<usize>,
}

/// What the window asks for.
#[derive(Clone, Debug, PartialEq)]
pub enum ImportAction {
    /// Pick the clip.
    PickClip,
    /// Pick the output folder.
    PickOut,
    /// Start importing.
    Start(ImportRequest),
    /// Stop the running import.
    Cancel,
    /// Close the window.
    Close,
}

fn count(ui: &mut Ui, text: &str, value: &mut usize, min: usize) {
    let l = ui.label(text);
    ui.add(egui::DragValue::new(value).range(min..=100_000))
        .labelled_by(l.id);
    ui.end_row();
}

/// Draws the form (or the running import's progress) and returns what was asked for.
pub fn import_video_ui(ui: &mut Ui, state: &mut VideoImport) -> Option<ImportAction> {
    let mut action = None;
    if let Some(run) = &state.run {
        let (done, total) = run.progress();
        let frac = if total > 0 {
            done as f32 / total as f32
        } else {
            0.0
        };
        ui.add(egui::ProgressBar::new(frac).text(format!("decoded {done}/{total} frames")));
        if ui.button("Cancel import").clicked() {
            action = Some(ImportAction::Cancel);
        }
        return action;
    }
    let form = state.form.as_mut()?;
    ui.horizontal(|ui| {
        if ui.button("Choose clip…").clicked() {
            action = Some(ImportAction::PickClip);
        }
        match &form.clip {
            Some(c) => ui.label(c.display().to_string()),
            None => ui.weak("no clip chosen"),
        };
    });
    ui.horizontal(|ui| {
        if ui.button("Output folder…").clicked() {
            action = Some(ImportAction::PickOut);
        }
        ui.add(egui::TextEdit::singleline(&mut form.out).hint_text("new or empty folder"));
    });
    ui.horizontal(|ui| {
        let named = !form.store && form.writes_store();
        ui.add_enabled_ui(!named, |ui| {
            let mut store = form.writes_store();
            if ui
                .checkbox(&mut store, "Zarr store (one zstd chunk per group)")
                .on_hover_text(
                    "For long clips: one file per group instead of one per frame, and a stopped \
                     import keeps its groups and goes on from them",
                )
                .changed()
            {
                form.store = store;
            }
        });
        if named {
            ui.weak("(the name ends in .zarr)");
        }
    });
    let looked = state.on_disk.as_ref().is_some_and(|d| {
        d.key.0 == form.clip && d.key.1 == form.out.trim() && d.key.2 == form.writes_store()
    });
    if !looked {
        state.on_disk = Some(OnDisk {
            files: form.check_files(),
            kept: form.kept_groups(),
            key: (
                form.clip.clone(),
                form.out.trim().to_owned(),
                form.writes_store(),
            ),
        });
    }
    let files = state.on_disk.as_ref().map(|d| d.files.clone());
    if let Some(kept) = state.on_disk.as_ref().and_then(|d| d.kept) {
        ui.horizontal(|ui| {
            if form.start_over {
                ui.label(format!(
                    "an interrupted import into this store kept {kept} groups: they are discarded"
                ));
            } else {
                ui.label(format!(
                    "an interrupted import into this store kept {kept} groups: Import goes on \
                     from them"
                ));
            }
            ui.checkbox(&mut form.start_over, "start over");
        });
    }
    Grid::new("import_video_form")
        .num_columns(2)
        .show(ui, |ui| {
            count(ui, "frames per group", &mut form.frames_per_group, 7);
            count(
                ui,
                "group stride (frames)",
                &mut form.group_stride_frames,
                1,
            );
            count(ui, "max groups (0 = all)", &mut form.max_groups, 0);
            number_row(ui, "rpm", &mut form.meta.rpm, 0.1);
            number_row(ui, "radius (mm)", &mut form.meta.radius_mm, 0.1);
            let l = ui.label("cut");
            egui::ComboBox::from_id_salt("import_cut")
                .selected_text(format!("{:?}", form.meta.cut).to_lowercase())
                .show_ui(ui, |ui| {
                    for c in [Cut::Lateral, Cut::Stereo, Cut::Vertical] {
                        ui.selectable_value(&mut form.meta.cut, c, format!("{c:?}").to_lowercase());
                    }
                })
                .response
                .labelled_by(l.id);
            ui.end_row();
            number_row(ui, "pixel pitch (µm)", &mut form.meta.pixel_pitch_um, 0.01);
            number_row(
                ui,
                "working distance (mm)",
                &mut form.meta.working_distance_mm,
                0.01,
            );
            number_row(ui, "frame step (µm)", &mut form.meta.frame_step_um, 0.01);
            let own = ui.checkbox(&mut form.own_group_step, "group step (µm)");
            if form.own_group_step {
                ui.add(egui::DragValue::new(&mut form.group_step_um).speed(0.1))
                    .labelled_by(own.id);
            } else {
                ui.weak(format!(
                    "{:.4} (stride × frame step)",
                    form.group_stride_frames as f64 * form.meta.frame_step_um
                ));
            }
            ui.end_row();
        });
    let request = files
        .unwrap_or_else(|| form.check_files())
        .and_then(|(clip, out)| form.request_for(clip, out));
    if let Err(problem) = &request {
        ui.colored_label(Color32::from_rgb(235, 90, 80), problem);
    } else if let Some(p) = &state.problem {
        ui.colored_label(Color32::from_rgb(235, 90, 80), p);
    }
    ui.horizontal(|ui| {
        if ui
            .add_enabled(request.is_ok(), egui::Button::new("Import"))
            .clicked()
        {
            // Checked afresh: the disk may have changed since the files were looked at.
            match form.request() {
                Ok(req) => action = Some(ImportAction::Start(req)),
                Err(_) => state.on_disk = None,
            }
        }
        if ui.button("Close").clicked() {
            action = Some(ImportAction::Close);
        }
    });
    action
}

/// What the import window asks of the workbench.
#[derive(Clone, Debug, PartialEq)]
pub enum ImportEvent {
    /// A note for the status bar.
    Info(String),
    /// An error for the status bar.
    Error(String),
    /// Open the imported scan.
    Open(PathBuf),
    /// Show this file dialog.
    Dialog(DialogKind),
}

impl VideoImport {
    /// Opens the window.
    pub fn open(&mut self) {
        self.on_disk = None;
        if self.form.is_none() {
            self.form = Some(ImportForm::default());
        }
    }

    /// Takes a picked clip or output folder.
    pub fn dialog_answer(&mut self, kind: &DialogKind, path: PathBuf) {
        let Some(form) = self.form.as_mut() else {
            return;
        };
        match kind {
            DialogKind::VideoClip => form.clip = Some(path),
            DialogKind::VideoOut => form.set_out_from_pick(&path),
            _ => {}
        }
    }

    /// Draws the window and polls the running import; returns what the workbench must do.
    pub fn step(&mut self, ctx: &egui::Context) -> Vec<ImportEvent> {
        let mut events = Vec::new();
        if let Some(run) = self.run.as_mut()
            && let Some(outcome) = run.poll()
        {
            self.run = None;
            // The output, and what the store keeps, have changed.
            self.on_disk = None;
            match outcome {
                Ok(s) => {
                    let stale = match s.removed_stale.len() {
                        0 => String::new(),
                        n => format!(" (removed {n} unfinished import(s) left by killed runs)"),
                    };
                    let resumed = match s.resumed_groups {
                        0 => String::new(),
                        n => format!(" ({n} of them kept by an interrupted import)"),
                    };
                    events.push(ImportEvent::Info(format!(
                        "imported {} groups of {} frames into {}{resumed}{stale}",
                        s.groups,
                        s.frames_per_group,
                        s.out_dir.display()
                    )));
                    self.form = None;
                    self.problem = None;
                    events.push(ImportEvent::Open(s.out_dir));
                }
                Err(e) => {
                    events.push(ImportEvent::Error(format!("video import failed: {e}")));
                    self.problem = Some(e);
                }
            }
        }
        if self.form.is_none() && self.run.is_none() {
            return events;
        }
        let mut open = true;
        let mut action = None;
        egui::Window::new("Import video")
            .open(&mut open)
            .collapsible(false)
            .resizable(false)
            .show(ctx, |ui| action = import_video_ui(ui, self));
        if !open {
            action = Some(ImportAction::Close);
        }
        match action {
            Some(ImportAction::PickClip) => events.push(ImportEvent::Dialog(DialogKind::VideoClip)),
            Some(ImportAction::PickOut) => events.push(ImportEvent::Dialog(DialogKind::VideoOut)),
            Some(ImportAction::Start(req)) => {
                self.problem = None;
                let c = ctx.clone();
                match ImportRun::start(req, Box::new(move || c.request_repaint())) {
                    Ok(run) => self.run = Some(run),
                    Err(e) => {
                        events.push(ImportEvent::Error(format!("cannot start the import: {e}")))
                    }
                }
            }
            Some(ImportAction::Cancel) => {
                if let Some(run) = &self.run {
                    run.cancel();
                }
            }
            Some(ImportAction::Close) => {
                if let Some(run) = &self.run {
                    run.cancel();
                } else {
                    self.form = None;
                }
            }
            None => {}
        }
        if self.run.is_some() {
            ctx.request_repaint_after(std::time::Duration::from_millis(100));
        }
        events
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests;
