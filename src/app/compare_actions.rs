//! The workbench's "Compare methods" actions: open the window, run and cancel a comparison,
//! take its outcome, listen to A or B, and draw the window each frame.

use std::sync::Arc;

use super::background::take_ended;
use super::compare::{CompareRun, MethodComparison};
use super::views::compare_ui::{CompareAction, compare_window};
use super::workbench::{Workbench, repaint_fn};
use crate::pipeline::Method;

impl Workbench {
    /// Shows the "Compare methods" window.
    pub fn open_compare(&mut self) {
        self.methods.open = true;
    }

    /// True when the "Compare methods" window is shown.
    #[must_use]
    pub fn compare_open(&self) -> bool {
        self.methods.open
    }

    /// The last finished method comparison.
    #[must_use]
    pub fn comparison(&self) -> Option<&MethodComparison> {
        self.methods.result.as_deref()
    }

    /// True while a method comparison runs.
    #[must_use]
    pub fn is_comparing(&self) -> bool {
        self.methods.run.is_some()
    }

    /// Reconstructs the clip with method A, then B, in the background (the other knobs as in
    /// force; the groups of the last clip when there is one, else all).
    pub fn compare_methods(&mut self, methods: [Method; 2]) {
        let Some(scan) = &self.nav.scan else {
            self.error("open a scan first");
            return;
        };
        if self.messages.refuse_if(
            self.is_comparing(),
            "a method comparison is already running",
        ) {
            return;
        }
        let groups = self.clip.clip.as_ref().map(|c| c.groups.clone());
        self.methods.open = true;
        self.methods.methods = Some(methods);
        match CompareRun::start(
            scan.clone(),
            self.tuning.params(),
            methods,
            groups,
            self.tuning.state(),
            repaint_fn(&self.ctx),
        ) {
            Ok(run) => {
                self.methods.run = Some(run);
                self.info(format!(
                    "comparing methods: A {} against B {}",
                    methods[0].name(),
                    methods[1].name()
                ));
            }
            Err(e) => self.error(format!("cannot start the method comparison: {e}")),
        }
    }

    /// Stops the running comparison after its current group.
    pub fn cancel_comparison(&mut self) {
        if let Some(r) = &self.methods.run {
            r.cancel();
        }
    }

    /// Takes the running comparison's reports and its outcome.
    pub(super) fn poll_comparison(&mut self) {
        let Some((outcome, cancelled)) = take_ended(&mut self.methods.run) else {
            return;
        };
        match outcome {
            Ok(cmp) => {
                let [a, b] = cmp.methods.map(Method::name);
                self.info(format!(
                    "methods compared: B {b} against A {a}: r {:.3}, {:.1} dB over {} groups",
                    cmp.overall.r,
                    cmp.overall.snr_db,
                    cmp.groups.len()
                ));
                if self.clip.comparison_heard.is_some() {
                    self.clip.comparison_heard = None;
                    self.player.load(self.clip.play_buffers());
                }
                self.methods.result = Some(Arc::new(*cmp));
            }
            Err(_) if cancelled => self.info("method comparison cancelled"),
            Err(e) => self.error(format!("method comparison: {e}")),
        }
    }

    /// Plays A (`which` 0) or B (1) of the comparison from where the player stands; the
    /// player holds the comparison's sound until the next clip. Without a sound device it
    /// says so in the message area.
    pub fn listen_comparison(&mut self, which: usize) {
        let Some(cmp) = self.methods.result.clone() else {
            self.error("nothing to listen to: run the comparison first");
            return;
        };
        if self.clip.comparison_heard != Some(cmp.methods) {
            self.player.load(cmp.play_buffers());
            self.clip.comparison_heard = Some(cmp.methods);
            self.clip.still_heard = false;
        }
        self.player.set_source(which.min(1));
        if !self.player.is_playing()
            && let Err(e) = self.player.play()
        {
            self.error(e);
        }
    }

    /// Draws the window (when open) and does what was asked in it.
    pub(super) fn compare_step(&mut self, ctx: &egui::Context) {
        if let Some(pair) = self.compare_on_open
            && self.nav.scan.is_some()
            && self.nav.opening.is_none()
        {
            self.compare_on_open = None;
            self.compare_methods(pair);
        }
        let actions = compare_window(
            ctx,
            self.views.tool_place,
            &mut self.methods,
            self.tuning.params().method,
            &self.player,
            self.clip.comparison_heard.is_some(),
        );
        for a in actions {
            match a {
                CompareAction::Run(pair) => self.compare_methods(pair),
                CompareAction::Cancel => self.cancel_comparison(),
                CompareAction::Listen(i) => self.listen_comparison(i),
                CompareAction::Stop => self.player.stop(),
            }
        }
        if self.methods.run.is_some() {
            ctx.request_repaint_after(std::time::Duration::from_millis(100));
        }
    }
}
