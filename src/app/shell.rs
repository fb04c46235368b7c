//! The workbench window: menus, side panel (navigation, stages, parameters), view tabs, status
//! bar, confirmations, drag-and-drop, keyboard shortcuts, PNG capture and the screenshot mode.

use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use egui::{Color32, Key, KeyboardShortcut, Modifiers, Ui};

use super::dialogs::DialogKind;
use super::export;
use super::views::depth_ui::depth_ui;
use super::views::flow_ui::flow_ui;
use super::views::frame_ui::{StageData, frame_ui};
use super::views::hough_ui::hough_ui;
use super::views::meta_ui::{MetaAction, MetaForm, meta_ui};
use super::views::nav_ui::{NavAction, nav_ui, stages_ui};
use super::views::orientation_ui::orientation_ui;
use super::views::overview_ui::overview_ui;
use super::views::params_ui::{params_ui, toml_ui};
use super::views::stripes_ui::stripes_ui;
use super::views::waveform_ui::{WaveAction, waveform_ui};
use super::views::{View, empty_note};
use super::workbench::{Confirm, Workbench};

/// Frames to wait after everything settled before a screenshot (textures and layout settle).
const SCREENSHOT_SETTLE_FRAMES: u32 = 6;
/// Longest wait for the app to settle before the screenshot is taken anyway.
const SCREENSHOT_TIMEOUT: Duration = Duration::from_secs(600);

/// Screenshot mode: wait until the work is done, capture the window, save it, close.
#[derive(Debug)]
pub struct ScreenshotPlan {
    path: PathBuf,
    started: Instant,
    settled: u32,
    requested: bool,
    result: Arc<Mutex<Option<Result<(), String>>>>,
}

impl ScreenshotPlan {
    /// A plan to save the window to `path`.
    #[must_use]
    pub fn new(path: PathBuf) -> Self {
        Self {
            path,
            started: Instant::now(),
            settled: 0,
            requested: false,
            result: Arc::new(Mutex::new(None)),
        }
    }
}

impl Workbench {
    fn start_dir(&self) -> Option<PathBuf> {
        self.scan.as_ref().map(|s| s.dir.clone())
    }

    pub(super) fn show_dialog(&mut self, kind: DialogKind, file_name: Option<String>) {
        let ctx = self.ctx.clone();
        let start = self.start_dir();
        if let Err(e) = self.dialogs.show(
            kind,
            start,
            file_name,
            Box::new(move || ctx.request_repaint()),
        ) {
            self.error(e);
        }
    }

    fn handle_dialog(&mut self, kind: DialogKind, path: PathBuf) {
        match kind {
            DialogKind::OpenScan => {
                let _ = self.open_scan(&path);
            }
            DialogKind::ExportWav(sel) => {
                self.request_export_wav(path.with_extension("wav"), sel);
            }
            DialogKind::LoadPreset => {
                let _ = self.load_preset_from(&path);
            }
            DialogKind::SavePreset => {
                let path = path.with_extension("toml");
                if path.exists() {
                    self.confirm = Some(Confirm::SavePreset(path));
                } else {
                    let _ = self.save_preset_to(&path, false);
                }
            }
            DialogKind::ExportPng(view) => {
                let path = path.with_extension("png");
                if path.exists() {
                    self.confirm = Some(Confirm::ExportPng(path, view));
                } else {
                    self.capture_view(path, view, false);
                }
            }
            #[cfg(feature = "video")]
            DialogKind::VideoClip | DialogKind::VideoOut => self.video_dialog_answer(&kind, path),
        }
    }

    /// Saves what `view` shows as PNG (a capture of its area on screen).
    pub fn capture_view(&mut self, path: PathBuf, view: View, overwrite: bool) {
        self.view = view;
        let tx = self.capture.0.clone();
        let ctx = self.ctx.clone();
        self.pending_capture = Some((path, egui::Rect::NOTHING, overwrite));
        self.ctx.request_screenshot(move |img| {
            let _ = tx.send(img);
            ctx.request_repaint();
        });
    }

    fn poll_capture(&mut self, ctx: &egui::Context) {
        let Ok(img) = self.capture.1.try_recv() else {
            return;
        };
        let Some((path, _, overwrite)) = self.pending_capture.take() else {
            return;
        };
        let rect = self.view_rect;
        let region = if rect.is_positive() {
            img.region(&rect, Some(ctx.pixels_per_point()))
        } else {
            (*img).clone()
        };
        match export::save_color_image(&region, &path, overwrite) {
            Ok(()) => self.info(format!("saved {}", path.display())),
            Err(e) => self.error(e),
        }
    }

    fn shortcuts(&mut self, ctx: &egui::Context) {
        let undo = KeyboardShortcut::new(Modifiers::COMMAND, Key::Z);
        let redo = KeyboardShortcut::new(Modifiers::COMMAND | Modifiers::SHIFT, Key::Z);
        let redo_y = KeyboardShortcut::new(Modifiers::COMMAND, Key::Y);
        let open = KeyboardShortcut::new(Modifiers::COMMAND, Key::O);
        let (r, r2, u, o) = ctx.input_mut(|i| {
            (
                i.consume_shortcut(&redo),
                i.consume_shortcut(&redo_y),
                i.consume_shortcut(&undo),
                i.consume_shortcut(&open),
            )
        });
        if r || r2 {
            self.redo();
        } else if u {
            self.undo();
        }
        if o {
            self.show_dialog(DialogKind::OpenScan, None);
        }
        if !ctx.egui_wants_keyboard_input() {
            let (space, left, right) = ctx.input(|i| {
                (
                    i.key_pressed(Key::Space),
                    i.key_pressed(Key::PageUp),
                    i.key_pressed(Key::PageDown),
                )
            });
            if space && self.clip.is_some() {
                if self.player.is_playing() {
                    self.player.pause();
                } else if let Err(e) = self.player.play() {
                    self.error(e);
                }
            }
            if left && self.group > 0 {
                self.set_group(self.group - 1);
            }
            if right {
                self.set_group(self.group + 1);
            }
        }
    }

    fn dropped(&mut self, ctx: &egui::Context) {
        let files = ctx.input(|i| i.raw.dropped_files.clone());
        for f in files {
            let p = f.path().to_path_buf();
            if p.is_dir() {
                let _ = self.open_scan(&p);
            } else if p.file_name().is_some_and(|n| n == "scan.toml") {
                if let Some(dir) = p.parent() {
                    let _ = self.open_scan(dir);
                }
            } else if p.extension().is_some_and(|e| e == "toml") {
                let _ = self.load_preset_from(&p);
            } else {
                self.error(format!(
                    "drop a scan folder or a preset .toml, not {}",
                    p.display()
                ));
            }
        }
    }

    fn menu_bar(&mut self, ui: &mut Ui) {
        egui::MenuBar::new().ui(ui, |ui| {
            ui.menu_button("File", |ui| {
                if ui.button("Open scan…").clicked() {
                    self.show_dialog(DialogKind::OpenScan, None);
                }
                #[cfg(feature = "video")]
                if ui.button("Import video…").clicked() {
                    self.open_import_video();
                }
                ui.menu_button("Recent scans", |ui| {
                    let recent = self.recent.scans.clone();
                    if recent.is_empty() {
                        ui.weak("none yet");
                    }
                    for p in recent {
                        if ui.button(p.display().to_string()).clicked() {
                            let _ = self.open_scan(&p);
                        }
                    }
                });
                ui.separator();
                if ui.button("Load preset…").clicked() {
                    self.show_dialog(DialogKind::LoadPreset, None);
                }
                if ui.button("Save preset…").clicked() {
                    self.show_dialog(DialogKind::SavePreset, Some("preset.toml".into()));
                }
                ui.separator();
                let ready = self.clip.is_some();
                if ui
                    .add_enabled(ready, egui::Button::new("Export WAV…"))
                    .clicked()
                {
                    self.show_dialog(DialogKind::ExportWav(false), Some("recovered.wav".into()));
                }
                if ui.button("Export view as PNG…").clicked() {
                    let v = self.view;
                    self.show_dialog(DialogKind::ExportPng(v), Some(format!("{}.png", v.name())));
                }
                ui.separator();
                if ui.button("Quit").clicked() {
                    ui.ctx().send_viewport_cmd(egui::ViewportCommand::Close);
                }
            });
            ui.menu_button("Edit", |ui| {
                let (u, r) = self.can_undo_redo();
                if ui
                    .add_enabled(u, egui::Button::new("Undo  (Ctrl+Z)"))
                    .clicked()
                {
                    self.undo();
                }
                if ui
                    .add_enabled(r, egui::Button::new("Redo  (Ctrl+Shift+Z)"))
                    .clicked()
                {
                    self.redo();
                }
            });
            ui.separator();
            let title = match (&self.scan, &self.pending_open) {
                (_, Some(p)) => format!("opening {} …", p.scan.dir.display()),
                (Some(s), None) => s.dir.display().to_string(),
                (None, None) => "no scan: File > Open scan…, or drop a folder here".into(),
            };
            ui.weak(title);
        });
    }

    fn side_panel(&mut self, ui: &mut Ui, statuses: &[super::views::StageStatus; crate::pipeline::Stage::COUNT]) {
        egui::ScrollArea::vertical().show(ui, |ui| {
            ui.heading("navigate");
            let groups = self.scan.as_ref().map_or(0, |s| s.groups.len());
            let frames = self.frames().map_or(0, |f| f.len());
            let mut actions = nav_ui(
                ui,
                groups,
                self.group,
                frames,
                self.frame,
                &mut self.views.nav,
            );
            ui.separator();
            ui.heading("stages");
            actions.extend(stages_ui(
                ui,
                statuses,
                &self.stage_times,
                self.hide_timings,
            ));
            for a in actions {
                match a {
                    NavAction::Group(g) => self.set_group(g),
                    NavAction::Frame(f) => self.set_frame(f),
                    NavAction::Rerun(s) => self.rerun(s),
                }
            }
            ui.separator();
            ui.horizontal(|ui| {
                ui.heading("parameters");
                let (u, r) = self.can_undo_redo();
                if ui.add_enabled(u, egui::Button::new("undo")).clicked() {
                    self.undo();
                }
                if ui.add_enabled(r, egui::Button::new("redo")).clicked() {
                    self.redo();
                }
            });
            if let Some(p) = &self.preset_file {
                ui.weak(format!("preset: {}", p.display()));
            }
            if self.clip.as_ref().is_some_and(|c| c.params != self.params) {
                ui.colored_label(
                    Color32::from_rgb(220, 170, 60),
                    "the clip was made with other params: reconstruct to hear them",
                );
            }
            let mut draft = self.params.clone();
            params_ui(ui, &mut draft, statuses);
            if let Some(p) = toml_ui(ui, &self.params, &mut self.views.toml) {
                draft = p;
                self.history.seal();
            }
            self.set_params(draft);
        });
    }

    fn status_bar(&mut self, ui: &mut Ui) {
        ui.horizontal(|ui| {
            if let Some(m) = self.messages.last() {
                let c = if m.error {
                    Color32::from_rgb(235, 90, 80)
                } else {
                    ui.visuals().text_color()
                };
                ui.colored_label(c, &m.text);
            }
            ui.with_layout(egui::Layout::right_to_left(egui::Align::Center), |ui| {
                match self.player.status() {
                    crate::playback::AudioStatus::Ready {
                        device, rate_hz, ..
                    } => {
                        ui.weak(format!("audio: {device} @ {rate_hz} Hz"));
                    }
                    crate::playback::AudioStatus::Unavailable(why) => {
                        ui.colored_label(
                            Color32::from_rgb(235, 150, 60),
                            format!("audio unavailable: {why}"),
                        );
                    }
                }
                if let Some(r) = &self.recon {
                    ui.add(
                        egui::ProgressBar::new(r.fraction())
                            .desired_width(160.0)
                            .text(format!("reconstructing {}/{}", r.done, r.total)),
                    );
                }
                if !self.is_idle() {
                    ui.spinner();
                }
            });
        });
    }

    fn central(&mut self, ui: &mut Ui, statuses: &[super::views::StageStatus; crate::pipeline::Stage::COUNT]) {
        ui.horizontal_wrapped(|ui| {
            for v in View::ALL {
                ui.selectable_value(&mut self.view, v, v.name());
            }
            ui.separator();
            if ui.button("export PNG…").clicked() {
                let v = self.view;
                self.show_dialog(DialogKind::ExportPng(v), Some(format!("{}.png", v.name())));
            }
        });
        ui.separator();
        let frames = self.frames().cloned();
        let data = StageData {
            cache: &self.cache,
            frames: frames.as_ref(),
            load_error: self.load_error.as_deref(),
            group: self.group,
            frame: self.frame,
            status: statuses,
            params: &self.params,
            meta: self.meta.as_deref(),
        };
        let height = (ui.available_height() - 60.0).max(200.0);
        let top = ui.cursor().min;
        let no_scan = self.scan.is_none();
        if no_scan && !matches!(self.view, View::Waveform) {
            empty_note(
                ui,
                "no scan open: File > Open scan…, a recent scan, or drop a scan folder here",
            );
        } else {
            let v = &mut self.views;
            match self.view {
                View::Overview => {
                    if let Some(open) =
                        overview_ui(ui, &data, &mut self.textures, self.clip.as_deref(), height)
                    {
                        self.view = open;
                    }
                }
                View::Frame => frame_ui(ui, &data, &mut self.textures, &mut v.frame, height),
                View::Flow => flow_ui(ui, &data, &mut self.textures, &mut v.flow, height),
                View::Hough => {
                    let mut draft = self.params.hough.clone();
                    hough_ui(
                        ui,
                        &data,
                        &self.textures,
                        &mut v.hough,
                        &mut draft,
                        height - 130.0,
                    );
                    if draft != self.params.hough {
                        let mut p = self.params.clone();
                        p.hough = draft;
                        self.set_params(p);
                    }
                }
                View::Stripes => stripes_ui(ui, &data, &mut self.textures, &mut v.stripes, height),
                View::Depth => depth_ui(ui, &data, &self.textures, &mut v.depth, height),
                View::Orientation => {
                    orientation_ui(ui, &data, &self.textures, &mut v.orientation, height)
                }
                View::Waveform => {
                    let groups = self.scan.as_ref().map_or(0, |s| s.groups.len());
                    let actions = waveform_ui(
                        ui,
                        self.clip.as_deref(),
                        self.recon.as_ref(),
                        groups,
                        &mut self.player,
                        &mut v.wave,
                        height,
                    );
                    for a in actions {
                        match a {
                            WaveAction::Reconstruct(r) => self.reconstruct(r),
                            WaveAction::Cancel => self.cancel_reconstruction(),
                            WaveAction::ExportWav(sel) => {
                                self.show_dialog(
                                    DialogKind::ExportWav(sel),
                                    Some("recovered.wav".into()),
                                );
                            }
                            WaveAction::Message(m) => self.error(m),
                        }
                    }
                }
                View::Metadata => {
                    if let Some(scan) = &self.scan {
                        let original = scan.meta.clone();
                        let form = self
                            .meta_form
                            .get_or_insert_with(|| MetaForm::new(&original));
                        match meta_ui(ui, form, &original) {
                            Some(MetaAction::Save(m)) => {
                                let _ = self.save_meta(m);
                            }
                            Some(MetaAction::Revert) => self.meta_form = None,
                            None => {}
                        }
                    }
                }
            }
        }
        self.view_rect = egui::Rect::from_min_max(top, ui.min_rect().max);
    }

    fn confirm_modal(&mut self, ctx: &egui::Context) {
        let Some(c) = self.confirm.clone() else {
            return;
        };
        let (text, path) = match &c {
            Confirm::ExportWav { path, .. } => {
                ("Replace the existing WAV (and its .json report)?", path)
            }
            Confirm::SavePreset(path) => ("Replace the existing preset?", path),
            Confirm::ExportPng(path, _) => ("Replace the existing PNG?", path),
        };
        let mut answer = None;
        egui::Modal::new(egui::Id::unique("confirm_overwrite")).show(ctx, |ui| {
            ui.heading("File exists");
            ui.label(text);
            ui.monospace(path.display().to_string());
            ui.horizontal(|ui| {
                if ui.button("Replace").clicked() {
                    answer = Some(true);
                }
                if ui.button("Cancel").clicked() {
                    answer = Some(false);
                }
            });
        });
        match answer {
            Some(true) => {
                self.confirm = None;
                match c {
                    Confirm::ExportWav { path, selection } => {
                        let bits = self.views.wave.bits;
                        let _ = self.export_wav_to(&path, bits, selection, true);
                    }
                    Confirm::SavePreset(path) => {
                        let _ = self.save_preset_to(&path, true);
                    }
                    Confirm::ExportPng(path, view) => self.capture_view(path, view, true),
                }
            }
            Some(false) => {
                self.confirm = None;
                self.info("not replaced");
            }
            None => {}
        }
    }

    /// Answers the open confirmation (tests and keyboard-free use).
    pub fn answer_confirm(&mut self, replace: bool) {
        let Some(c) = self.confirm.take() else { return };
        if !replace {
            self.info("not replaced");
            return;
        }
        match c {
            Confirm::ExportWav { path, selection } => {
                let bits = self.views.wave.bits;
                let _ = self.export_wav_to(&path, bits, selection, true);
            }
            Confirm::SavePreset(path) => {
                let _ = self.save_preset_to(&path, true);
            }
            Confirm::ExportPng(path, view) => self.capture_view(path, view, true),
        }
    }

    fn screenshot_step(&mut self, ctx: &egui::Context) {
        let ready = self.is_idle() && !self.is_reconstructing() && self.scan.is_some();
        let Some(plan) = &mut self.screenshot else {
            return;
        };
        if let Some(result) = plan.result.lock().ok().and_then(|r| r.clone()) {
            if let Err(e) = result {
                eprintln!("groovescope: screenshot failed: {e}");
            }
            ctx.send_viewport_cmd(egui::ViewportCommand::Close);
            return;
        }
        if plan.requested {
            ctx.request_repaint_after(Duration::from_millis(50));
            return;
        }
        let timed_out = plan.started.elapsed() > SCREENSHOT_TIMEOUT;
        plan.settled = if ready { plan.settled + 1 } else { 0 };
        if plan.settled >= SCREENSHOT_SETTLE_FRAMES || timed_out {
            if timed_out {
                eprintln!("groovescope: the app did not settle; taking the screenshot anyway");
            }
            plan.requested = true;
            let path = plan.path.clone();
            let slot = plan.result.clone();
            let c2 = ctx.clone();
            ctx.request_screenshot(move |img| {
                let r = export::save_color_image(&img, &path, true);
                if let Ok(mut s) = slot.lock() {
                    *s = Some(r);
                }
                c2.request_repaint();
            });
        }
        ctx.request_repaint_after(Duration::from_millis(50));
    }

    /// True once a requested screenshot was written.
    #[must_use]
    pub fn screenshot_done(&self) -> Option<Result<(), String>> {
        self.screenshot
            .as_ref()
            .and_then(|p| p.result.lock().ok().and_then(|r| r.clone()))
    }
}

impl eframe::App for Workbench {
    fn ui(&mut self, ui: &mut Ui, _frame: &mut eframe::Frame) {
        let started = Instant::now();
        let busy = !self.is_idle();
        let ctx = ui.ctx().clone();
        self.poll();
        if let Some(msg) = self.player.poll_device() {
            self.error(msg);
        }
        if let Some((kind, path)) = self.dialogs.poll()
            && let Some(p) = path
        {
            self.handle_dialog(kind, p);
        }
        self.poll_capture(&ctx);
        self.dropped(&ctx);
        self.shortcuts(&ctx);
        let statuses = self.statuses();
        egui::Panel::top("menu").show(ui, |ui| self.menu_bar(ui));
        egui::Panel::bottom("status").show(ui, |ui| self.status_bar(ui));
        egui::Panel::left("side")
            .resizable(true)
            .default_size(330.0)
            .show(ui, |ui| self.side_panel(ui, &statuses));
        egui::CentralPanel::default().show(ui, |ui| self.central(ui, &statuses));
        self.confirm_modal(&ctx);
        #[cfg(feature = "video")]
        self.import_video_step(&ctx);
        if ctx.input(|i| !i.raw.hovered_files.is_empty()) {
            egui::Area::new(egui::Id::unique("drop_hint"))
                .fixed_pos(egui::pos2(40.0, 40.0))
                .show(&ctx, |ui| {
                    ui.heading("drop a scan folder (or a preset .toml) to open it")
                });
        }
        if !self.is_idle() || self.is_reconstructing() {
            ctx.request_repaint_after(Duration::from_millis(100));
        }
        self.screenshot_step(&ctx);
        if busy {
            self.max_busy_frame = self.max_busy_frame.max(started.elapsed());
        }
    }

    /// In screenshot mode the pointer is hidden from the app (no hover crosshair in pictures).
    fn raw_input_hook(&mut self, _ctx: &egui::Context, raw_input: &mut egui::RawInput) {
        if self.screenshot.is_some() {
            raw_input.events.retain(|e| {
                !matches!(
                    e,
                    egui::Event::PointerMoved(_) | egui::Event::PointerButton { .. }
                )
            });
            raw_input.events.push(egui::Event::PointerGone);
        }
    }

    fn on_exit(&mut self) {
        self.player.pause();
        self.cancel_reconstruction();
    }
}
