//! The workbench's still-mode actions: open a still image, find its grooves and decode one in
//! the background, pick another groove, listen, export the groove's sound, and draw the still
//! window each frame.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use super::background::take_ended;
use super::still::{SetupSource, StillDoc, StillTask, setup_for, start_still};
use super::views::still_ui::{StillAction, still_window};
use super::workbench::{Workbench, repaint_fn};
use crate::io::lock::OutputLock;
use crate::io::wav::{WavBits, write_transfer_wav};
use crate::pipeline::still::StillSetup;

/// Why another still cannot start while one decodes.
const STILL_BUSY: &str = "a still is being decoded: cancel it first";

impl Workbench {
    /// Opens the still at `path`: reads it whole, finds its grooves and decodes one (the groove
    /// its `truth.toml` names, else the decoder's pick), all in the background.
    pub fn open_still(&mut self, path: &Path) {
        if self
            .messages
            .refuse_if(self.is_decoding_still(), STILL_BUSY)
        {
            return;
        }
        let (width, height) = match crate::io::still::StillReader::open(path) {
            Ok(r) => (r.width(), r.height()),
            Err(e) => {
                self.error(e.to_string());
                return;
            }
        };
        let (setup, groove, source) = setup_for(path, width, height);
        self.still.open = true;
        self.still.first_line = 0.0;
        self.still.lines_shown = 0.0;
        self.still.doc = None;
        if self.clip.still_heard {
            // The player gives the old still's sound back for the clip's.
            self.clip.still_heard = false;
            self.player.stop();
            self.player.load(self.clip.play_buffers());
        }
        self.start_still_task(
            StillTask {
                path: path.to_path_buf(),
                image: None,
                found: None,
                setup: setup.clone(),
                groove,
                params: self.tuning.params().clone(),
            },
            Some((setup, source)),
        );
    }

    fn start_still_task(&mut self, task: StillTask, fresh: Option<(StillSetup, SetupSource)>) {
        let what = match task.groove {
            Some(n) => format!("groove {n}"),
            None => "the most complete groove near the centre".into(),
        };
        let name = task.path.display().to_string();
        let (path, setup) = (task.path.clone(), task.setup.clone());
        match start_still(task, repaint_fn(&self.ctx)) {
            Ok(job) => {
                self.still.job = Some(job);
                if let Some((setup, source)) = fresh {
                    self.still.pending = Some((path, setup, source));
                } else if let Some(doc) = &mut self.still.doc {
                    doc.setup = setup;
                }
                self.info(format!("decoding {what} of {name}"));
            }
            Err(e) => self.error(format!("cannot start decoding the still: {e}")),
        }
    }

    /// Decodes groove `number` (from 1; None: the decoder's pick) of the open still with the
    /// settings shown; the grooves are found again only when the settings changed.
    pub fn decode_still_groove(&mut self, number: Option<usize>) {
        if self.still.doc.is_none() {
            self.error("open a still image first");
            return;
        }
        if self
            .messages
            .refuse_if(self.is_decoding_still(), STILL_BUSY)
        {
            return;
        }
        let Some(doc) = self.still.doc.as_mut() else {
            return;
        };
        let changed = doc.found_with.as_ref() != Some(&doc.setup);
        // Guessed settings changed in the window before a find are the operator's own.
        if changed && doc.found_with.is_some() && doc.source == SetupSource::Guessed {
            doc.source = SetupSource::Entered;
        }
        let found = doc.found.clone().filter(|_| !changed);
        let task = StillTask {
            path: doc.path.clone(),
            image: Some(doc.image.clone()),
            found,
            setup: doc.setup.clone(),
            groove: number,
            params: self.tuning.params().clone(),
        };
        self.start_still_task(task, None);
    }

    /// Stops the still decode at its next band of rows.
    pub fn cancel_still(&mut self) {
        if let Some(j) = &self.still.job {
            j.cancel();
        }
    }

    /// True while a still decodes.
    #[must_use]
    pub fn is_decoding_still(&self) -> bool {
        self.still.job.is_some()
    }

    /// The open still.
    #[must_use]
    pub fn still_doc(&self) -> Option<&StillDoc> {
        self.still.doc.as_ref()
    }

    /// The open still's settings, to edit (they apply with the next decode).
    pub fn still_setup_mut(&mut self) -> Option<&mut StillSetup> {
        self.still.doc.as_mut().map(|d| &mut d.setup)
    }

    /// True when the still window is shown.
    #[must_use]
    pub fn still_open(&self) -> bool {
        self.still.open
    }

    /// Takes the still decode's progress and outcome.
    pub(super) fn poll_still(&mut self) {
        let Some((outcome, cancelled)) = take_ended(&mut self.still.job) else {
            return;
        };
        let outcome = match outcome {
            Ok(o) => o,
            Err(e) => {
                self.error(format!("still: {e}"));
                return;
            }
        };
        if let Some((path, setup, source)) = self.still.pending.take() {
            let Some(image) = outcome.image.clone() else {
                self.error(
                    outcome
                        .error
                        .unwrap_or_else(|| "the still did not open".into()),
                );
                return;
            };
            self.still.doc = Some(StillDoc {
                path,
                image,
                setup,
                source,
                found: None,
                found_with: None,
                run: None,
                problem: None,
            });
        }
        let Some(doc) = self.still.doc.as_mut() else {
            return;
        };
        if let Some(found) = outcome.found {
            if !doc.found.as_ref().is_some_and(|f| Arc::ptr_eq(f, &found)) {
                doc.found_with = Some(doc.setup.clone());
            }
            doc.found = Some(found);
        }
        match (outcome.run, outcome.error) {
            (Some(run), _) => {
                let g = &run.analysis.grooves.grooves[run.analysis.chosen];
                let msg = format!(
                    "still: groove {} of {} decoded: {:.2} s at {} Hz in {:.1} s",
                    g.number,
                    run.analysis.grooves.grooves.len(),
                    run.audio.duration_secs(),
                    run.audio.sample_rate_hz,
                    run.timings.total_secs
                );
                let warnings = run.warnings.clone();
                doc.run = Some(run);
                doc.problem = None;
                if self.clip.still_heard
                    && let Some(buffers) = doc.play_buffers()
                {
                    // The player holds the still: it takes the new groove's sound.
                    self.player.stop();
                    self.player.load(buffers);
                }
                self.info(msg);
                for w in warnings {
                    self.error(format!("still: {w}"));
                }
            }
            (None, _) if cancelled => self.info("still decode cancelled"),
            (None, Some(e)) => {
                doc.problem = Some(e.clone());
                self.error(e);
            }
            (None, None) => {}
        }
    }

    /// Plays the decoded groove (the player holds it until the next clip or groove).
    pub fn listen_still(&mut self) {
        let Some(buffers) = self.still.doc.as_ref().and_then(StillDoc::play_buffers) else {
            self.error("nothing to listen to: decode a groove first");
            return;
        };
        if !self.clip.still_heard {
            self.player.load(buffers);
            self.player.set_source(0);
            self.clip.comparison_heard = None;
            self.clip.still_heard = true;
        }
        if !self.player.is_playing()
            && let Err(e) = self.player.play()
        {
            self.error(e);
        }
    }

    /// Writes the decoded groove's sound to `path` (24-bit) with its JSON report beside it
    /// (`NAME.json`); an existing file is replaced only when `overwrite`.
    ///
    /// # Errors
    /// A message naming the file (also shown in the message area).
    pub fn export_still_to(&mut self, path: &Path, overwrite: bool) -> Result<(), String> {
        let replaces = overwrite && super::export::would_overwrite(path);
        let result = self.export_still_inner(path, overwrite);
        let done = if replaces { "replaced" } else { "exported" };
        match &result {
            Ok(()) => self.info(format!("{done} {}", path.display())),
            Err(e) => self.error(e.clone()),
        }
        result
    }

    fn export_still_inner(&self, path: &Path, overwrite: bool) -> Result<(), String> {
        let Some(doc) = &self.still.doc else {
            return Err("open a still image first".into());
        };
        let Some(run) = &doc.run else {
            return Err("nothing to export: decode a groove first".into());
        };
        let _lock = OutputLock::acquire(path).map_err(|e| e.to_string())?;
        let report = super::export::sidecar_path(path);
        if !overwrite && super::export::would_overwrite(path) {
            return Err(format!(
                "refusing to overwrite an existing file: {}",
                path.display()
            ));
        }
        let what = crate::still::cli::ReportInputs {
            image: &doc.path,
            out: path,
            params_file: None,
            reference: None,
            scores: None,
            chosen_automatically: false,
        };
        let params = self.tuning.params();
        let info = crate::still::cli::still_transfer_info(
            &doc.path,
            run,
            &doc.setup,
            params,
            WavBits::Int24,
        );
        write_transfer_wav(path, &run.audio, WavBits::Int24, overwrite, &info)
            .map_err(|e| e.to_string())?;
        crate::still::cli::write_still_report(&report, run, &doc.setup, params, &what, overwrite)
            .map_err(|e| e.to_string())
    }

    /// Exports to `path`, asking first when it would replace a file.
    pub fn request_export_still(&mut self, path: PathBuf) {
        self.write_or_ask(super::files::Confirm::ExportStill(path), None);
    }

    /// Draws the still window (when open) and does what was asked in it.
    pub(super) fn still_step(&mut self, ctx: &egui::Context) {
        if !self.still.open {
            return;
        }
        let position = self.clip.still_heard.then(|| self.player.position_secs());
        let playing = self.clip.still_heard && self.player.is_playing();
        let place = self.views.tool_place;
        let actions = still_window(ctx, place, &mut self.still, position, playing);
        for a in actions {
            match a {
                StillAction::Open => self.show_dialog(super::dialogs::DialogKind::OpenStill),
                StillAction::Decode(n) => self.decode_still_groove(n),
                StillAction::Cancel => self.cancel_still(),
                StillAction::Listen => self.listen_still(),
                StillAction::Stop => self.player.stop(),
                StillAction::Export => {
                    self.show_dialog(super::dialogs::DialogKind::ExportStillWav);
                }
            }
        }
        if self.still.job.is_some() {
            ctx.request_repaint_after(std::time::Duration::from_millis(100));
        }
        if playing {
            ctx.request_repaint_after(std::time::Duration::from_millis(50));
        }
    }
}
