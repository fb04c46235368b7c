//! The workbench window's frame loop (`eframe::App`): poll the worker, the reconstruction,
//! dialogs and captures, take keyboard shortcuts and dropped files, step the frame movie, then
//! draw the panels; plus the screenshot mode.

use std::time::{Duration, Instant};

use egui::{Key, KeyboardShortcut, Modifiers, Ui};

use super::dialogs::{DialogAnswer, DialogKind};
use super::export;
use super::screenshot::{SCREENSHOT_SETTLE_FRAMES, SCREENSHOT_TIMEOUT};
use super::workbench::Workbench;

/// Seconds per frame when playing a group as a movie.
pub const MOVIE_FRAME_SECS: f64 = 0.12;
/// The side panel's width on a wide window (points).
pub const SIDE_PANEL_DEFAULT: f32 = 330.0;
/// The narrowest the side panel gets (points).
pub const SIDE_PANEL_MIN: f32 = 200.0;
/// The largest share of the window's width the side panel takes (above its narrowest).
pub const SIDE_PANEL_SHARE: f32 = 0.4;

impl Workbench {
    fn poll_dialog(&mut self) {
        if let Some((kind, answer)) = self.files.dialogs.poll() {
            self.answer_dialog(kind, answer);
        }
    }

    /// Acts on how a native dialog ended (what the dialog thread sends back). A save dialog
    /// asked before returning an existing file, so that file is replaced without a second
    /// question ([`Workbench::use_dialog_path`]).
    pub fn answer_dialog(&mut self, kind: DialogKind, answer: DialogAnswer) {
        match answer {
            DialogAnswer::Picked(p) => {
                let asked = kind.saves();
                self.use_dialog_path(kind, p, asked);
            }
            DialogAnswer::Unavailable(why) => self.offer_path_field(kind, why),
            DialogAnswer::Closed {
                maybe_unshown: true,
            } => self.offer_path_field(
                kind,
                "the file dialog closed without a file; if none appeared, no desktop portal \
                 answered and zenity is not installed (scripts/setup.sh installs it)"
                    .into(),
            ),
            DialogAnswer::Closed {
                maybe_unshown: false,
            } => self.info(format!("{}: cancelled", kind.title())),
        }
    }

    fn poll_capture(&mut self, ctx: &egui::Context) {
        let Ok(img) = self.capture.channel.1.try_recv() else {
            return;
        };
        let Some(pending) = self.capture.pending.take() else {
            return;
        };
        let rect = self.capture.view_rect;
        let region = if rect.is_positive() {
            img.region(&rect, Some(ctx.pixels_per_point()))
        } else {
            (*img).clone()
        };
        match export::save_color_image(&region, &pending.path, pending.overwrite) {
            Ok(()) => self.info(format!("saved {}", pending.path.display())),
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
            self.show_dialog(DialogKind::OpenScan);
        }
        if ctx.egui_wants_keyboard_input() {
            return;
        }
        let (space, up, down, left, right) = ctx.input(|i| {
            (
                i.key_pressed(Key::Space),
                i.key_pressed(Key::PageUp),
                i.key_pressed(Key::PageDown),
                i.key_pressed(Key::ArrowLeft),
                i.key_pressed(Key::ArrowRight),
            )
        });
        if space && self.player.buffers().is_some_and(|b| !b.is_empty()) {
            if self.player.is_playing() {
                self.player.pause();
            } else if let Err(e) = self.player.play() {
                self.error(e);
            }
        }
        if up && self.nav.group > 0 {
            self.set_group(self.nav.group - 1);
        }
        if down {
            self.set_group(self.nav.group + 1);
        }
        if left {
            self.set_frame(self.nav.frame.saturating_sub(1));
        }
        if right {
            self.set_frame(self.nav.frame + 1);
        }
    }

    /// Steps the frame movie before anything is drawn, so every panel shows the same frame.
    fn step_movie(&mut self, ctx: &egui::Context) {
        let n = self.nav.frame_count();
        let state = &mut self.views.nav;
        if !state.movie || n == 0 {
            return;
        }
        let now = ctx.input(|i| i.time);
        if now - state.last_step >= MOVIE_FRAME_SECS {
            state.last_step = now;
            self.nav.set_frame((self.nav.frame + 1) % n);
        }
        ctx.request_repaint_after(Duration::from_secs_f64(MOVIE_FRAME_SECS));
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
            } else if super::still::is_still_image(&p) {
                self.open_still(&p);
            } else {
                self.error(format!(
                    "drop a scan folder, a preset .toml or a still image (PNG, TIFF), not {}",
                    p.display()
                ));
            }
        }
    }

    #[cfg(feature = "video")]
    fn import_video_step(&mut self, ctx: &egui::Context) {
        use super::import_video::ImportEvent;
        for ev in self.video_import.step(ctx) {
            match ev {
                ImportEvent::Info(m) => self.info(m),
                ImportEvent::Error(m) => self.error(m),
                ImportEvent::Open(dir) => {
                    let _ = self.open_scan(&dir);
                }
                ImportEvent::Dialog(kind) => self.show_dialog(kind),
            }
        }
    }

    fn screenshot_step(&mut self, ctx: &egui::Context) {
        let ready = self.is_idle()
            && !self.is_reconstructing()
            && self.compare_on_open.is_none()
            && self.nav.scan.is_some();
        if ready
            && self.clip.clip.is_some()
            && let Some(preset) = self.compare.take()
        {
            self.apply_symptom(&preset);
            self.reconstruct(None);
            ctx.request_repaint();
            return;
        }
        if ready && let Some(kind) = self.open_dialog.take() {
            self.show_dialog(kind);
            if let Some(plan) = &mut self.capture.plan {
                plan.settled = 0;
            }
            ctx.request_repaint();
            return;
        }
        let Some(plan) = &mut self.capture.plan else {
            return;
        };
        if let Some(result) = plan.outcome() {
            if let Err(e) = result {
                crate::tell!("groovescope: screenshot failed: {e}");
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
                crate::tell!("groovescope: the app did not settle; taking the screenshot anyway");
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
}

impl eframe::App for Workbench {
    fn ui(&mut self, ui: &mut Ui, _frame: &mut eframe::Frame) {
        let started = Instant::now();
        let busy = !self.is_idle();
        let ctx = ui.ctx().clone();
        self.poll();
        self.poll_dialog();
        if let Some(msg) = self.player.poll_device() {
            self.error(msg);
        }
        self.poll_capture(&ctx);
        self.dropped(&ctx);
        self.shortcuts(&ctx);
        self.step_movie(&ctx);
        let statuses = self.statuses();
        let width = ui.available_width();
        let small = super::views::states::COMPACT_BELOW;
        self.views.compact = width < small.x || ui.available_height() < small.y;
        let menu = egui::Panel::top("menu").show(ui, |ui| self.menu_bar(ui));
        let status = egui::Panel::bottom("status").show(ui, |ui| self.status_bar(ui));
        // Tool windows stay between the menu bar and the status bar.
        let (menu, status) = (menu.response.rect, status.response.rect);
        self.views.tool_place.area = egui::Rect::from_x_y_ranges(
            menu.x_range(),
            menu.bottom()..=status.top().max(menu.bottom()),
        );
        // On a narrow window the side panel is narrower, so the central view keeps room.
        egui::Panel::left("side")
            .resizable(true)
            .default_size(SIDE_PANEL_DEFAULT)
            .size_range(SIDE_PANEL_MIN..=(width * SIDE_PANEL_SHARE).max(SIDE_PANEL_MIN))
            .show(ui, |ui| self.side_panel(ui, &statuses));
        egui::CentralPanel::default().show(ui, |ui| self.central(ui, &statuses));
        self.compare_step(&ctx);
        self.still_step(&ctx);
        self.confirm_modal(&ctx);
        self.prompt_modal(&ctx);
        #[cfg(feature = "video")]
        self.import_video_step(&ctx);
        if ctx.input(|i| !i.raw.hovered_files.is_empty()) {
            egui::Area::new(egui::Id::unique("drop_hint"))
                .fixed_pos(egui::pos2(40.0, 40.0))
                .show(&ctx, |ui| {
                    ui.heading("drop a scan folder, a preset .toml or a still image to open it")
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
        if self.capture.plan.is_some() {
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
        self.cancel_comparison();
        self.cancel_still();
    }
}
