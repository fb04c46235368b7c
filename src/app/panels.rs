//! The window's panels: the menu bar, the side panel (navigation, stages, parameters), the
//! status bar, the central view and the modal questions (replace a file, leave unsaved knobs,
//! the in-app path field).

use egui::{Color32, Ui};

use super::dialogs::DialogKind;
use super::files::{Confirm, typed_path};
use super::stages::STAGES;
use super::symptoms::symptom_presets;
use super::views::frame_ui::StageData;
use super::views::guidance::guidance_ui;
use super::views::health_ui::health_strip_ui;
use super::views::meta_ui::{MetaAction, MetaForm, meta_ui};
use super::views::nav_ui::{NavAction, nav_ui, stages_ui};
use super::views::overview_ui::overview_ui;
use super::views::params_ui::{params_ui, toml_ui};
use super::views::transport_ui::WaveAction;
use super::views::waveform_ui::waveform_ui;
use super::views::{StageStatus, View, empty_note};
use super::workbench::Workbench;

/// Colour of error lines.
/// Colour of error text (the status bar, the still window).
pub(super) const ERROR_COLOUR: Color32 = Color32::from_rgb(235, 90, 80);
/// Colour of warnings.
const WARN_COLOUR: Color32 = Color32::from_rgb(220, 170, 60);
/// What the health strip's colours mean.
const HEALTH_KEY: &str = "One cell per group. Green: sound. Amber to red: part of the group is \
     missing (gaps, a failed group), wall fits were rejected, or its fits hold far more outliers \
     than the clip's other groups. Grey: not reconstructed yet. The white outline is the group \
     shown.";

impl Workbench {
    pub(super) fn menu_bar(&mut self, ui: &mut Ui) {
        egui::MenuBar::new().ui(ui, |ui| {
            ui.menu_button("File", |ui| {
                if ui.button("Open scan…").clicked() {
                    self.show_dialog(DialogKind::OpenScan);
                }
                #[cfg(feature = "video")]
                if ui.button("Import video…").clicked() {
                    self.open_import_video();
                }
                ui.menu_button("Recent scans", |ui| {
                    let recent = self.files.recent.scans.clone();
                    if recent.is_empty() {
                        ui.weak("none yet");
                    }
                    for p in recent {
                        if ui.button(p.display().to_string()).clicked() {
                            let _ = self.open_scan(&p);
                        }
                    }
                });
                if ui
                    .button("Open still image…")
                    .on_hover_text("a PNG or TIFF of grooves seen from above: find them, pick one, listen")
                    .clicked()
                {
                    self.show_dialog(DialogKind::OpenStill);
                }
                ui.separator();
                if ui.button("Load preset…").clicked() {
                    self.show_dialog(DialogKind::LoadPreset);
                }
                if ui.button("Save preset…").clicked() {
                    self.show_dialog(DialogKind::SavePreset);
                }
                ui.separator();
                let ready = self.clip.clip.is_some();
                if ui
                    .add_enabled(ready, egui::Button::new("Export WAV…"))
                    .clicked()
                {
                    self.show_dialog(DialogKind::ExportWav(false));
                }
                if ui
                    .add_enabled(self.nav.scan.is_some(), egui::Button::new("Compare methods…"))
                    .on_hover_text("the clip with two methods: both waveforms, their difference, the agreement per group, listen to either")
                    .on_disabled_hover_text(super::views::transport_ui::NO_SCAN_TO_RECONSTRUCT)
                    .clicked()
                {
                    self.open_compare();
                }
                if ui.button("Export view as PNG…").clicked() {
                    self.show_dialog(DialogKind::ExportPng(self.view));
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
            let title = match (self.nav.dir(), &self.nav.opening) {
                (_, Some(p)) => format!("opening {} …", p.scan.dir.display()),
                (Some(d), None) => d.display().to_string(),
                (None, None) => "no scan: File > Open scan…, or drop a folder here".into(),
            };
            ui.weak(title);
        });
    }

    pub(super) fn side_panel(&mut self, ui: &mut Ui, statuses: &[StageStatus; STAGES]) {
        // On a small window the panel is narrower than its knobs: it scrolls sideways too, with
        // its scroll bars shown (a wide one keeps the panel as wide as its content).
        let compact = self.views.compact;
        if compact {
            ui.spacing_mut().scroll = egui::style::ScrollStyle::thin();
        }
        egui::ScrollArea::new([compact, true]).show(ui, |ui| {
            ui.heading("navigate");
            let mut actions = nav_ui(
                ui,
                self.nav.groups(),
                self.nav.group,
                self.nav.frame_count(),
                self.nav.frame,
                &mut self.views.nav,
            );
            if !self.clip.health.is_empty() {
                ui.horizontal(|ui| {
                    ui.label("clip health");
                    ui.weak("(per group; hover, click to go)")
                        .on_hover_text(HEALTH_KEY);
                });
                if let Some(g) = health_strip_ui(ui, &self.clip.health, self.nav.group) {
                    actions.push(NavAction::Group(g));
                }
            }
            ui.separator();
            ui.heading("stages");
            actions.extend(stages_ui(
                ui,
                statuses,
                self.stages.times(),
                self.settings.hide_timings,
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
            // One line each, always there, so nothing below moves when they change.
            let state = self.tuning.state();
            let text = egui::RichText::new(state.line());
            let text = if state.modified {
                text.color(WARN_COLOUR)
            } else {
                text.weak()
            };
            ui.add(egui::Label::new(text).truncate())
                .on_hover_text(state.line());
            let note = match self.clip.clip.as_ref() {
                Some(c) if c.params != *self.tuning.params() => {
                    let text = if self
                        .nav
                        .scan
                        .as_ref()
                        .is_some_and(|s| c.refinishes_with(&s.meta, self.tuning.params()))
                    {
                        "the clip was made with other filters: reconstruct to hear them (its \
                         groups are kept: only the finish runs again)"
                    } else {
                        "the clip was made with other params: reconstruct to hear them"
                    };
                    egui::RichText::new(text).color(WARN_COLOUR)
                }
                _ => egui::RichText::new(" "),
            };
            ui.add(egui::Label::new(note).truncate());
            self.symptom_buttons(ui);
            let mut draft = self.tuning.params().clone();
            params_ui(ui, &mut draft, statuses);
            if let Some(p) = toml_ui(ui, self.tuning.params(), &mut self.views.toml) {
                self.replace_params(p);
            } else {
                self.set_params(draft);
            }
        });
    }

    /// One button per symptom preset ("flaked wall", "dusty", "noisy"), its reason on hover.
    fn symptom_buttons(&mut self, ui: &mut Ui) {
        let presets = match symptom_presets() {
            Ok(p) => p,
            Err(e) => {
                ui.colored_label(ERROR_COLOUR, e);
                return;
            }
        };
        let mut chosen = None;
        ui.horizontal_wrapped(|ui| {
            ui.label("symptom:");
            for p in &presets {
                let hover = format!("{}\n\nsets {}", p.reason, p.settings().join(", "));
                if ui.small_button(&p.name).on_hover_text(hover).clicked() {
                    chosen = Some(p.clone());
                }
            }
        });
        if let Some(p) = chosen {
            self.apply_symptom(&p);
        }
    }

    pub(super) fn status_bar(&mut self, ui: &mut Ui) {
        ui.horizontal(|ui| {
            // The right-hand part first; the last message takes the room left, cut short with
            // the whole line on hover (drawn first, a long one ran under the audio status).
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
                if let Some(r) = &self.clip.run {
                    ui.add(
                        egui::ProgressBar::new(r.fraction())
                            .desired_width(160.0)
                            .text(if r.refinishing {
                                "refinishing the clip".to_string()
                            } else {
                                format!("reconstructing {}/{}", r.done, r.total)
                            }),
                    );
                }
                if !self.is_idle() {
                    ui.spinner();
                }
                if let Some(m) = self.messages.last() {
                    let c = if m.error {
                        ERROR_COLOUR
                    } else {
                        ui.visuals().text_color()
                    };
                    ui.with_layout(egui::Layout::left_to_right(egui::Align::Center), |ui| {
                        ui.add(egui::Label::new(egui::RichText::new(&m.text).color(c)).truncate());
                    });
                }
            });
        });
    }

    pub(super) fn central(&mut self, ui: &mut Ui, statuses: &[StageStatus; STAGES]) {
        ui.horizontal_wrapped(|ui| {
            for v in View::ALL {
                ui.selectable_value(&mut self.view, v, v.name());
            }
            ui.separator();
            if ui.button("export PNG…").clicked() {
                self.show_dialog(DialogKind::ExportPng(self.view));
            }
        });
        ui.separator();
        // Below the tabs the view scrolls (each view its own offset), so a small window loses
        // none of it.
        let viewport_top = ui.cursor().top();
        let left = ui.max_rect().left();
        if self.views.compact {
            // Scroll bars shown: on a small window much of a view lies out of sight.
            ui.spacing_mut().scroll = egui::style::ScrollStyle::thin();
        }
        egui::ScrollArea::both()
            .id_salt(("central", self.view.name()))
            .auto_shrink(false)
            .show(ui, |ui| self.central_view(ui, statuses));
        // Tool windows open below the tabs, and in the waveform view below its toolbar.
        let top = match self.view {
            View::Waveform => self.views.wave.toolbar_bottom.max(viewport_top),
            _ => viewport_top,
        };
        self.views.tool_place.corner = egui::pos2(left, top);
    }

    /// The central view below its tabs: the guidance line and the view itself.
    fn central_view(&mut self, ui: &mut Ui, statuses: &[StageStatus; STAGES]) {
        let frames = self.nav.frames().cloned();
        let params = self.tuning.params().clone();
        guidance_ui(ui, self.view, self.nav.uses_dual(&params));
        let data = StageData {
            cache: &self.stages.cache,
            frames: frames.as_ref(),
            load_error: self.nav.load_error.as_deref(),
            group: self.nav.group,
            frame: self.nav.frame,
            status: statuses,
            params: &params,
            meta: self.nav.meta.as_deref(),
            height: (ui.available_height() - 60.0).max(200.0),
        };
        let top = ui.cursor().min;
        let textures = &mut self.stages.textures;
        let v = &mut self.views;
        let mut new_hough = None;
        let mut wave_actions = Vec::new();
        let mut open_view = None;
        let mut meta_action = None;
        if self.nav.scan.is_none() && !matches!(self.view, View::Waveform) {
            empty_note(
                ui,
                "no scan open: File > Open scan…, a recent scan, or drop a scan folder here",
            );
        } else {
            match self.view {
                View::Overview => {
                    open_view = overview_ui(ui, &data, textures, self.clip.clip.as_deref());
                }
                View::Frame => v.frame.ui(ui, &data, textures),
                View::Flow => v.flow.ui(ui, &data, textures),
                View::Hough => {
                    let mut draft = params.hough.clone();
                    v.hough.ui(ui, &data, textures, &mut draft);
                    if draft != params.hough {
                        new_hough = Some(draft);
                    }
                }
                View::Stripes => v.stripes.ui(ui, &data, textures),
                View::Depth => v.depth.ui(ui, &data, textures),
                View::Orientation => v.orientation.ui(ui, &data, textures),
                View::Edges => v.edges.ui(ui, &data, textures),
                View::Waveform => {
                    wave_actions = waveform_ui(
                        ui,
                        &self.clip,
                        self.nav.groups(),
                        self.nav.group,
                        &mut self.player,
                        &mut v.wave,
                        data.height,
                    );
                }
                View::Metadata => {
                    if let Some(scan) = &self.nav.scan {
                        let original = scan.meta.clone();
                        let form = v.meta_form.get_or_insert_with(|| MetaForm::new(&original));
                        meta_action = meta_ui(ui, form, &original);
                    }
                }
            }
        }
        // A view export keeps what is on screen of the view.
        self.capture.view_rect =
            egui::Rect::from_min_max(top, ui.min_rect().max).intersect(ui.clip_rect());
        if let Some(view) = open_view {
            self.view = view;
        }
        if let Some(h) = new_hough {
            let mut p = params;
            p.hough = h;
            self.set_params(p);
        }
        for a in wave_actions {
            match a {
                WaveAction::Reconstruct(r) => self.reconstruct(r),
                WaveAction::ReconstructAround(n) => self.reconstruct_around(n),
                WaveAction::PlaySoFar => self.play_so_far(),
                WaveAction::Group(g) => self.set_group(g),
                WaveAction::Cancel => self.cancel_reconstruction(),
                WaveAction::ExportWav(sel) => self.show_dialog(DialogKind::ExportWav(sel)),
                WaveAction::Message(m) => self.error(m),
            }
        }
        match meta_action {
            Some(MetaAction::Save(m)) => {
                let _ = self.save_meta(m);
            }
            Some(MetaAction::Revert) => self.views.meta_form = None,
            None => {}
        }
    }

    pub(super) fn confirm_modal(&mut self, ctx: &egui::Context) {
        let Some(c) = self.files.confirm.clone() else {
            return;
        };
        let (heading, text, path, yes) = match &c {
            Confirm::ExportWav { path, .. } => (
                "File exists",
                "Replace the existing WAV (and its .json report)?",
                path,
                "Replace",
            ),
            Confirm::SavePreset(path) => (
                "File exists",
                "Replace the existing preset?",
                path,
                "Replace",
            ),
            Confirm::ExportPng(path, _) => {
                ("File exists", "Replace the existing PNG?", path, "Replace")
            }
            Confirm::ExportStill(path) => (
                "File exists",
                "Replace the existing WAV (and its .json report) with this groove?",
                path,
                "Replace",
            ),
            Confirm::SwitchScan(path) => (
                "Unsaved parameters",
                "The parameters were changed since their preset (or the defaults) and are not \
                 saved. Open the other scan and leave them behind?",
                path,
                "Open anyway",
            ),
        };
        let mut answer = None;
        egui::Modal::new(egui::Id::unique("confirm_modal")).show(ctx, |ui| {
            ui.heading(heading);
            ui.label(text);
            ui.monospace(path.display().to_string());
            ui.horizontal(|ui| {
                if ui.button(yes).clicked() {
                    answer = Some(true);
                }
                if ui.button("Cancel").clicked() {
                    answer = Some(false);
                }
            });
        });
        if let Some(a) = answer {
            self.answer_confirm(a);
        }
    }

    /// The in-app path field, shown where no native dialog could open.
    pub(super) fn prompt_modal(&mut self, ctx: &egui::Context) {
        let Some(prompt) = self.files.prompt.as_mut() else {
            return;
        };
        let mut answer: Option<bool> = None;
        egui::Modal::new(egui::Id::unique("path_prompt")).show(ctx, |ui| {
            ui.heading(prompt.kind.title());
            ui.colored_label(WARN_COLOUR, &prompt.reason);
            let what = if prompt.kind.picks_folder() {
                "folder"
            } else {
                "file"
            };
            let l = ui.label(format!("type the {what}'s path:"));
            let edit = ui.add(
                egui::TextEdit::singleline(&mut prompt.text)
                    .desired_width(560.0)
                    .code_editor(),
            );
            let edit = edit.labelled_by(l.id);
            if edit.lost_focus() && ui.input(|i| i.key_pressed(egui::Key::Enter)) {
                answer = Some(true);
            }
            ui.horizontal(|ui| {
                if ui.button("OK").clicked() {
                    answer = Some(true);
                }
                if ui.button("Cancel").clicked() {
                    answer = Some(false);
                }
            });
        });
        match answer {
            Some(true) => {
                let Some(p) = self.files.prompt.take() else {
                    return;
                };
                match typed_path(&p.text) {
                    // Nothing asked about replacing it yet: the app asks.
                    Some(path) => self.use_dialog_path(p.kind, path, false),
                    None => {
                        self.error("no path typed");
                        self.files.prompt = Some(p);
                    }
                }
            }
            Some(false) => self.files.prompt = None,
            None => {}
        }
    }
}
