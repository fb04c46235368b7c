//! The workbench's actions on stages, presets, the scan's metadata, the clip and files: each
//! stage's status and rerun (with no scan open they say so and do nothing), save and load
//! presets, save `scan.toml`, reconstruct, play, export, dialogs, captures and video import.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use super::dialogs::DialogKind;
use super::export;
use super::files::{Confirm, PathPrompt};
use super::recon::{Clip, ReconRun};
use super::stages::STAGES;
use super::views::{StageStatus, View};
use super::workbench::{Workbench, repaint_fn};
use crate::engine::ReconstructOptions;
use crate::io::ScanMeta;
use crate::io::wav::WavBits;
use crate::pipeline::Stage;

impl Workbench {
    // ----- presets and metadata -----

    /// Loads a preset (an undoable change); on error the params stay as they are.
    ///
    /// # Errors
    /// The message shown.
    pub fn load_preset_from(&mut self, path: &Path) -> Result<(), String> {
        match super::tuning::load_preset(path) {
            Ok(p) => {
                if self.tuning.load_preset(path, p, Instant::now()) {
                    self.schedule();
                }
                self.info(format!("loaded preset {}", path.display()));
                Ok(())
            }
            Err(e) => {
                self.error(e.clone());
                Err(e)
            }
        }
    }

    /// Saves the params as a preset.
    ///
    /// # Errors
    /// The message shown (an existing file without `overwrite`, a failed write).
    pub fn save_preset_to(&mut self, path: &Path, overwrite: bool) -> Result<(), String> {
        let replaces = overwrite && path.exists();
        match super::tuning::save_preset(self.tuning.params(), path, overwrite) {
            Ok(()) => {
                self.tuning.saved_as(path);
                let done = if replaces { "replaced" } else { "saved" };
                self.info(format!("{done} preset {}", path.display()));
                Ok(())
            }
            Err(e) => {
                self.error(e.clone());
                Err(e)
            }
        }
    }

    /// Writes `meta` to the scan's `scan.toml` (atomically) and reruns the group with it.
    ///
    /// # Errors
    /// The message shown (invalid metadata, failed write).
    pub fn save_meta(&mut self, meta: ScanMeta) -> Result<(), String> {
        let Some(scan) = &mut self.nav.scan else {
            return Err("no scan open".into());
        };
        let path = scan.dir.join("scan.toml");
        let first_frame = scan.groups.first().and_then(|g| g.frame_path(0));
        let result = meta
            .validate()
            .and_then(|()| match first_frame {
                // What the scan folder holds must agree too (the next open checks it).
                Some(f) => crate::io::frames::frame_dimensions(&f)
                    .map_err(|e| e.to_string())
                    .and_then(|size| meta.check_against_scan(scan.groups.len(), size)),
                None => Ok(()),
            })
            .and_then(|()| meta.to_toml_string().map_err(|e| e.to_string()))
            .and_then(|text| {
                let _lock =
                    crate::io::lock::OutputLock::acquire(&path).map_err(|e| e.to_string())?;
                crate::io::write_atomic(&path, text.as_bytes(), true).map_err(|e| e.to_string())
            });
        match result {
            Ok(()) => {
                scan.meta = meta.clone();
                self.nav.meta = Some(Arc::new(meta));
                self.views.meta_form = None;
                self.info(format!("saved {}", path.display()));
                self.rerun(Stage::Derivatives);
                Ok(())
            }
            Err(e) => {
                let msg = format!("cannot save the metadata: {e}: {}", path.display());
                self.error(msg.clone());
                Err(msg)
            }
        }
    }

    // ----- the clip -----

    /// Reconstructs `groups` (None: all) in the background. When the clip on screen covers
    /// those groups of this scan and the params differ from its own only in `[dsp]`, its kept
    /// groups are finished again with them instead ([`ReconRun::refinish`]).
    pub fn reconstruct(&mut self, groups: Option<std::ops::Range<usize>>) {
        let Some(scan) = &self.nav.scan else {
            self.error("open a scan first");
            return;
        };
        let wanted = groups.clone().unwrap_or(0..scan.groups.len());
        if let Some(clip) =
            self.clip.clip.clone().filter(|c| {
                c.groups == wanted && c.refinishes_with(&scan.meta, self.tuning.params())
            })
        {
            match ReconRun::refinish(
                scan.clone(),
                &clip,
                self.tuning.params().clone(),
                self.tuning.state(),
                repaint_fn(&self.ctx),
            ) {
                Ok(Some(run)) => {
                    self.clip.run = Some(run);
                    self.clip.refresh_health();
                    return;
                }
                Ok(None) => {}
                Err(e) => {
                    self.error(format!("cannot start the reconstruction: {e}"));
                    return;
                }
            }
        }
        let opts = ReconstructOptions {
            params: self.tuning.params().clone(),
            groups,
            keep_going: true,
        };
        match ReconRun::start(
            scan.clone(),
            opts,
            self.tuning.state(),
            repaint_fn(&self.ctx),
        ) {
            Ok(run) => {
                self.clip.run = Some(run);
                self.clip.refresh_health();
            }
            Err(e) => self.error(format!("cannot start the reconstruction: {e}")),
        }
    }

    /// Stops the running reconstruction after its current group.
    pub fn cancel_reconstruction(&mut self) {
        self.clip.cancel();
    }

    /// Shows and loads a finished clip for playback; the clip before it stays beside it for
    /// A/B listening.
    pub fn set_clip(&mut self, clip: Clip) {
        self.info(format!(
            "clip ready: {:.1} ms from {} groups{}",
            clip.recon.audio.duration_secs() * 1000.0,
            clip.groups.len(),
            if clip.refinished {
                " (their sound finished again with the new filters: no group ran again)"
            } else {
                ""
            }
        ));
        self.clip.finish(clip);
        self.player.load(self.clip.play_buffers());
        self.views.wave.selection = None;
    }

    /// Applies a symptom preset on top of the knobs in force (one undoable step).
    pub fn apply_symptom(&mut self, preset: &super::symptoms::SymptomPreset) {
        match preset.apply(self.tuning.params()) {
            Ok(params) => {
                self.replace_params(params);
                self.info(format!(
                    "symptom preset \"{}\": {} (undo to go back)",
                    preset.name,
                    preset.settings().join(", ")
                ));
            }
            Err(e) => self.error(e),
        }
    }

    /// Plays the groups the running reconstruction has finished so far (they arrive after the
    /// group running now).
    pub fn play_so_far(&mut self) {
        if self.clip.is_running() {
            self.clip.request_partial();
        } else {
            self.error("no reconstruction is running");
        }
    }

    /// Reconstructs the groups within `radius` of the current one.
    pub fn reconstruct_around(&mut self, radius: usize) {
        let g = self.nav.group;
        let end = (g + radius + 1).min(self.nav.groups());
        self.reconstruct(Some(g.saturating_sub(radius)..end));
    }

    /// The health of every group of the open scan.
    #[must_use]
    pub fn health(&self) -> &super::health::ClipHealth {
        &self.clip.health
    }

    /// Exports the clip (or the selection) as WAV plus sidecar.
    ///
    /// # Errors
    /// The message shown (no clip, an existing file without `overwrite`, a failed write).
    pub fn export_wav_to(
        &mut self,
        path: &Path,
        bits: WavBits,
        selection: bool,
        overwrite: bool,
    ) -> Result<(), String> {
        let Some(clip) = self.clip.clip.clone() else {
            let msg = "nothing to export: reconstruct the clip first".to_string();
            self.error(msg.clone());
            return Err(msg);
        };
        let sel = if selection {
            self.views.wave.selection
        } else {
            None
        };
        let rate = self.views.wave.export_rate_hz;
        // Said plainly when a file is replaced, so no replacement passes unnoticed.
        let replaces = overwrite && export::would_overwrite(path);
        match export::export_wav(&clip, path, bits, rate, sel, overwrite) {
            Ok(()) => {
                let done = if replaces { "replaced" } else { "exported" };
                self.info(format!("{done} {}", path.display()));
                Ok(())
            }
            Err(e) => {
                self.error(e.clone());
                Err(e)
            }
        }
    }

    /// Exports to `path`, asking first when it would replace a file.
    pub fn request_export_wav(&mut self, path: PathBuf, selection: bool) {
        self.write_or_ask(Confirm::ExportWav { path, selection }, None);
    }

    /// Writes the file `c` stands for, or asks first (`c` becomes the open confirmation) when
    /// that would replace one: the WAV or its sidecar report, the preset, the PNG. Not asked
    /// again when `agreed` names the very file a native save dialog already asked about
    /// replacing. `c` that writes no file (switching scans) is always asked.
    pub(super) fn write_or_ask(&mut self, c: Confirm, agreed: Option<&Path>) {
        let (target, replaces) = match &c {
            Confirm::ExportWav { path, .. } | Confirm::ExportStill(path) => {
                (path.as_path(), export::would_overwrite(path))
            }
            Confirm::SavePreset(path) | Confirm::ExportPng(path, _) => {
                (path.as_path(), path.exists())
            }
            Confirm::SwitchScan(_) => {
                self.files.confirm = Some(c);
                return;
            }
        };
        if replaces && !(agreed == Some(target) && target.exists()) {
            self.files.confirm = Some(c);
        } else {
            self.write_confirmed(c, replaces);
        }
    }

    /// Selects `[a, b]` seconds of the clip.
    pub fn set_selection(&mut self, selection: Option<(f64, f64)>) {
        self.views.wave.selection = selection;
    }

    /// Sets the export encoding (at the clip's own rate).
    pub fn set_export_bits(&mut self, bits: WavBits) {
        self.views.wave.bits = bits;
        self.views.wave.export_rate_hz = None;
    }

    /// Sets the export format (encoding and rate).
    pub fn set_export_format(&mut self, format: &export::ExportFormat) {
        self.views.wave.bits = format.bits;
        self.views.wave.export_rate_hz = format.rate_hz;
    }

    // ----- files -----

    /// The name of the reconstruction path the scan is on with the params in force.
    fn path_name(&self) -> &'static str {
        let params = self.tuning.params();
        self.nav
            .meta
            .as_ref()
            .map_or("depth", |m| params.path_name(m))
    }

    /// Opens the dialog `kind`, starting in the scan's folder with a name made from the scan.
    pub fn show_dialog(&mut self, kind: DialogKind) {
        let (start, name) = self.dialog_start(&kind);
        let ctx = self.ctx.clone();
        if let Err(e) = self.files.dialogs.show(
            kind.clone(),
            start.clone(),
            name.clone(),
            Box::new(move || ctx.request_repaint()),
        ) {
            self.offer_path_field(kind, e);
        }
    }

    /// The folder a dialog for `kind` starts in and the file name it suggests: the still's
    /// folder for still dialogs (once a still is open), else the scan's.
    fn dialog_start(&self, kind: &DialogKind) -> (Option<PathBuf>, Option<String>) {
        match (kind, self.still_doc()) {
            (DialogKind::OpenStill, Some(doc)) => (doc.path.parent().map(Path::to_path_buf), None),
            (DialogKind::ExportStillWav, Some(doc)) => (
                doc.path.parent().map(Path::to_path_buf),
                super::files::still_export_name(doc),
            ),
            _ => {
                let start = self.nav.dir().map(Path::to_path_buf);
                let name = super::files::suggested_name(kind, start.as_deref(), self.path_name());
                (start, name)
            }
        }
    }

    /// Shows the in-app path field for `kind`, saying `reason` (no native dialog opened).
    pub(super) fn offer_path_field(&mut self, kind: DialogKind, reason: String) {
        let (start, name) = self.dialog_start(&kind);
        self.error(format!("{}: {reason}; type the path instead", kind.title()));
        self.files.prompt = Some(PathPrompt {
            text: super::files::suggested_path(start.as_deref(), name.as_deref()),
            kind,
            reason,
        });
    }

    /// Acts on a path chosen in a dialog. `asked` is true when a native save dialog chose it:
    /// such a dialog asks before it returns an existing file (rfd runs zenity with
    /// `--confirm-overwrite`; the desktop portals ask too), so replacing that very file is not
    /// asked about again. A file it did not name is still asked about: the report beside a WAV
    /// that is new, or a name that had its extension added. The in-app path field asks nothing
    /// itself, so its paths come with `asked` false and every replacement is asked about.
    pub fn use_dialog_path(&mut self, kind: DialogKind, path: PathBuf, asked: bool) {
        let agreed = asked.then_some(path.as_path());
        match kind {
            DialogKind::OpenScan => {
                let _ = self.open_scan(&path);
            }
            DialogKind::ExportWav(selection) => {
                let path = path.with_extension("wav");
                self.write_or_ask(Confirm::ExportWav { path, selection }, agreed);
            }
            DialogKind::LoadPreset => {
                let _ = self.load_preset_from(&path);
            }
            DialogKind::SavePreset => {
                self.write_or_ask(Confirm::SavePreset(path.with_extension("toml")), agreed);
            }
            DialogKind::OpenStill => self.open_still(&path),
            DialogKind::ExportStillWav => {
                self.write_or_ask(Confirm::ExportStill(path.with_extension("wav")), agreed);
            }
            DialogKind::ExportPng(view) => {
                self.write_or_ask(Confirm::ExportPng(path.with_extension("png"), view), agreed);
            }
            #[cfg(feature = "video")]
            DialogKind::VideoClip | DialogKind::VideoOut => {
                self.video_import.dialog_answer(&kind, path);
            }
        }
    }

    /// Answers the open confirmation (tests and keyboard-free use).
    pub fn answer_confirm(&mut self, yes: bool) {
        let Some(c) = self.files.confirm.take() else {
            return;
        };
        if !yes {
            self.info(match c {
                Confirm::SwitchScan(_) => "the scan stays open",
                _ => "not replaced",
            });
            return;
        }
        self.write_confirmed(c, true);
    }

    /// Does what `c` stands for; a file is replaced only with `overwrite` (else one that
    /// appeared meanwhile is refused).
    fn write_confirmed(&mut self, c: Confirm, overwrite: bool) {
        match c {
            Confirm::ExportWav { path, selection } => {
                let bits = self.views.wave.bits;
                let _ = self.export_wav_to(&path, bits, selection, overwrite);
            }
            Confirm::SavePreset(path) => {
                let _ = self.save_preset_to(&path, overwrite);
            }
            Confirm::ExportPng(path, view) => self.capture_view(path, view, overwrite),
            Confirm::ExportStill(path) => {
                let _ = self.export_still_to(&path, overwrite);
            }
            Confirm::SwitchScan(dir) => self.open_scan_anyway(&dir),
        }
    }

    /// Saves what `view` shows as PNG (a capture of its area on screen).
    pub fn capture_view(&mut self, path: PathBuf, view: View, overwrite: bool) {
        self.view = view;
        let tx = self.capture.channel.0.clone();
        let ctx = self.ctx.clone();
        self.capture.pending = Some(super::screenshot::PendingCapture { path, overwrite });
        self.ctx.request_screenshot(move |img| {
            let _ = tx.send(img);
            ctx.request_repaint();
        });
    }

    /// True once a requested screenshot was written.
    #[must_use]
    pub fn screenshot_done(&self) -> Option<Result<(), String>> {
        self.capture.plan.as_ref().and_then(|p| p.outcome())
    }

    /// Opens the "Import video" window.
    #[cfg(feature = "video")]
    pub fn open_import_video(&mut self) {
        self.video_import.open();
    }

    /// The open import form, for tests and scripting.
    #[cfg(feature = "video")]
    pub fn import_video_form_mut(&mut self) -> Option<&mut super::import_video::ImportForm> {
        self.video_import.form.as_mut()
    }

    /// Whether an import runs.
    #[cfg(feature = "video")]
    #[must_use]
    pub fn is_importing_video(&self) -> bool {
        self.video_import.run.is_some()
    }
}

impl Workbench {
    /// Status of `stage` for the current group ([`StageStatus::NoScan`] with no scan open).
    #[must_use]
    pub fn stage_status(&self, stage: Stage) -> StageStatus {
        if self.nav.scan.is_none() {
            return StageStatus::NoScan;
        }
        let params = self.tuning.params();
        self.stages.status(
            stage,
            self.nav.group,
            params,
            self.nav.uses_dual(params),
            self.jobs.running_stage(),
        )
    }

    /// Status of every stage.
    #[must_use]
    pub fn statuses(&self) -> [StageStatus; STAGES] {
        Stage::ALL.map(|s| self.stage_status(s))
    }

    /// Reruns `stage` and every later stage of the current group (frames that could not be
    /// read are read again by any stage's rerun); with no scan open there is nothing to run.
    pub fn rerun(&mut self, stage: Stage) {
        if self.nav.scan.is_none() {
            return;
        }
        self.stages.invalidate_from(stage);
        if stage == Stage::Derivatives || self.nav.load_error.is_some() {
            self.nav.forget_frames();
        }
        self.schedule();
    }
}
