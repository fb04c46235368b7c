//! The workbench: its state, one part per concern (navigation, stage results and the jobs that
//! make them, the knobs, the clip, playback, files, messages, views), and the operator's actions
//! that span them: open a scan, navigate, tune with undo/redo, rerun stale stages on the worker,
//! reconstruct, play and export.
//!
//! Everything that belongs to one scan (place, results, knobs and their history, clip, view
//! read-outs) is rebuilt when another scan opens, so nothing of one disc carries into the next.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use super::clip_state::ClipState;
use super::dialogs::DialogKind;
use super::export;
use super::files::{Confirm, Files, PathPrompt};
use super::jobs::Jobs;
use super::messages::{Message, Messages};
use super::nav::{Navigation, Opening};
use super::recent::RecentScans;
use super::recon::{Clip, ReconRun};
use super::screenshot::Capture;
use super::stages::StageState;
use super::tuning::{ParamState, Tuning};
use super::views::states::ViewStates;
use super::views::{StageStatus, View};
use super::worker::{Job, JobInput, Outcome, StageDone, WorkerEvent};
use crate::engine::ReconstructOptions;
use crate::image::Image;
use crate::io::wav::WavBits;
use crate::io::{Scan, ScanMeta};
use crate::pipeline::{GroupInput, PipelineParams, Stage, StageCache};
use crate::playback::{DeviceChoice, PlayBuffers, Player};

pub use super::tuning::SCAN_PRESET_FILE;

/// How the workbench starts.
#[derive(Clone, Debug, Default)]
pub struct WorkbenchOptions {
    /// Scan to open first.
    pub scan: Option<PathBuf>,
    /// Folder of the recent-scans list (None: not remembered).
    pub config_dir: Option<PathBuf>,
    /// Audio output.
    pub audio: DeviceChoice,
    /// View shown first.
    pub view: Option<View>,
    /// Save a screenshot here once everything settled, then close.
    pub screenshot: Option<PathBuf>,
    /// Reconstruct the clip as soon as the scan is open.
    pub reconstruct_on_open: bool,
    /// Show a fixed "– ms" instead of each stage's measured time, so that nothing on screen
    /// depends on the machine or its load (snapshot tests).
    pub hide_timings: bool,
    /// Open this file dialog once the work settled (scripts: see [`super::DIALOG_ENV`]).
    pub open_dialog: Option<DialogKind>,
    /// Once the clip is made, apply this symptom preset and reconstruct again (scripts: see
    /// [`super::COMPARE_ENV`]).
    pub compare: Option<super::symptoms::SymptomPreset>,
}

/// Settings that hold for the whole session.
#[derive(Clone, Copy, Debug, Default)]
pub struct Settings {
    /// See [`WorkbenchOptions::reconstruct_on_open`].
    pub reconstruct_on_open: bool,
    /// See [`WorkbenchOptions::hide_timings`].
    pub hide_timings: bool,
}

/// The workbench.
pub struct Workbench {
    pub(super) ctx: egui::Context,
    pub(super) settings: Settings,
    /// The open scan and the place in it.
    pub(super) nav: Navigation,
    /// The current group's stage results.
    pub(super) stages: StageState,
    /// The stage worker's jobs.
    pub(super) jobs: Jobs,
    /// The knobs of the open scan.
    pub(super) tuning: Tuning,
    /// The open scan's clip.
    pub(super) clip: ClipState,
    /// Audio output.
    pub(super) player: Player,
    /// Dialogs, questions, recent scans.
    pub(super) files: Files,
    /// Status-bar messages.
    pub(super) messages: Messages,
    /// The view on screen.
    pub(super) view: View,
    /// Per-view state of the open scan.
    pub(super) views: ViewStates,
    /// View exports and the screenshot mode.
    pub(super) capture: Capture,
    /// Longest UI frame while the worker was busy.
    pub(super) max_busy_frame: Duration,
    /// A dialog to open once the work settled ([`WorkbenchOptions::open_dialog`]).
    pub(super) open_dialog: Option<DialogKind>,
    /// A second reconstruction to make for A/B ([`WorkbenchOptions::compare`]).
    pub(super) compare: Option<super::symptoms::SymptomPreset>,
    /// The "Import video" window and its running import.
    #[cfg(feature = "video")]
    pub(super) video_import: super::import_video::VideoImport,
}

impl std::fmt::Debug for Workbench {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Workbench")
            .field("scan", &self.nav.dir())
            .field("group", &self.nav.group)
            .field("generation", &self.jobs.generation())
            .finish_non_exhaustive()
    }
}

pub(super) fn repaint_fn(ctx: &egui::Context) -> Box<dyn Fn() + Send + Sync> {
    let ctx = ctx.clone();
    Box::new(move || ctx.request_repaint())
}

impl Workbench {
    /// Builds the workbench (starting its worker and audio) and starts opening `opts.scan`.
    ///
    /// # Errors
    /// When the worker thread cannot be started.
    pub fn new(ctx: &egui::Context, opts: WorkbenchOptions) -> std::io::Result<Self> {
        let jobs = Jobs::start(repaint_fn(ctx))?;
        let mut recent = RecentScans::load(opts.config_dir.as_deref());
        recent.prune();
        let mut wb = Self {
            ctx: ctx.clone(),
            settings: Settings {
                reconstruct_on_open: opts.reconstruct_on_open,
                hide_timings: opts.hide_timings,
            },
            nav: Navigation::default(),
            stages: StageState::default(),
            jobs,
            tuning: Tuning::default(),
            clip: ClipState::default(),
            player: Player::open(&opts.audio),
            files: Files {
                recent,
                ..Files::default()
            },
            messages: Messages::default(),
            view: opts.view.unwrap_or(View::Overview),
            views: ViewStates::default(),
            capture: Capture::new(opts.screenshot),
            max_busy_frame: Duration::ZERO,
            open_dialog: opts.open_dialog,
            compare: opts.compare,
            #[cfg(feature = "video")]
            video_import: super::import_video::VideoImport::default(),
        };
        if let Some(dir) = opts.scan {
            let _ = wb.open_scan(&dir);
        }
        Ok(wb)
    }

    // ----- read access (views and tests) -----

    /// The open scan.
    #[must_use]
    pub fn scan(&self) -> Option<&Scan> {
        self.nav.scan.as_ref()
    }

    /// Current group index.
    #[must_use]
    pub fn group(&self) -> usize {
        self.nav.group
    }

    /// Current frame index within the group.
    #[must_use]
    pub fn frame(&self) -> usize {
        self.nav.frame
    }

    /// The current group's frames, once loaded.
    #[must_use]
    pub fn frames(&self) -> Option<&Arc<Vec<Image>>> {
        self.nav.frames()
    }

    /// The params in force.
    #[must_use]
    pub fn params(&self) -> &PipelineParams {
        self.tuning.params()
    }

    /// Where the params in force came from (defaults or a preset) and whether they changed since.
    #[must_use]
    pub fn param_state(&self) -> ParamState {
        self.tuning.state()
    }

    /// The stage results on screen.
    #[must_use]
    pub fn cache(&self) -> &StageCache {
        &self.stages.cache
    }

    /// How often `stage` finished for the current scan (counts reruns).
    #[must_use]
    pub fn stage_runs(&self, stage: Stage) -> u64 {
        self.stages.runs(stage)
    }

    /// The finished clip.
    #[must_use]
    pub fn clip(&self) -> Option<&Clip> {
        self.clip.clip.as_deref()
    }

    /// The audio player.
    #[must_use]
    pub fn player(&self) -> &Player {
        &self.player
    }

    /// The view on screen.
    #[must_use]
    pub fn view(&self) -> View {
        self.view
    }

    /// Shows `view`.
    pub fn set_view(&mut self, view: View) {
        self.view = view;
    }

    /// Status-bar messages, oldest first.
    #[must_use]
    pub fn messages(&self) -> &[Message] {
        self.messages.all()
    }

    /// The question waiting for the operator.
    #[must_use]
    pub fn confirm(&self) -> Option<&Confirm> {
        self.files.confirm.as_ref()
    }

    /// The in-app path field, when shown (no native dialog could open).
    #[must_use]
    pub fn path_prompt(&self) -> Option<&PathPrompt> {
        self.files.prompt.as_ref()
    }

    /// Where the Hough view drew each peak's window last frame (screen points).
    #[must_use]
    pub fn hough_window_rects(&self) -> &[egui::Rect] {
        &self.views.hough.windows_on_screen
    }

    /// The recent scans.
    #[must_use]
    pub fn recent(&self) -> &[PathBuf] {
        &self.files.recent.scans
    }

    /// True when no stage work or scan opening is under way.
    #[must_use]
    pub fn is_idle(&self) -> bool {
        self.jobs.is_idle() && self.nav.opening.is_none()
    }

    /// True while the clip reconstructs.
    #[must_use]
    pub fn is_reconstructing(&self) -> bool {
        self.clip.is_running()
    }

    /// Longest UI frame (time spent in `ui`) seen while the worker was busy.
    #[must_use]
    pub fn max_busy_frame(&self) -> Duration {
        self.max_busy_frame
    }

    /// Status of `stage` for the current group.
    #[must_use]
    pub fn stage_status(&self, stage: Stage) -> StageStatus {
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
    pub fn statuses(&self) -> [StageStatus; super::stages::STAGES] {
        Stage::ALL.map(|s| self.stage_status(s))
    }

    pub(super) fn info(&mut self, text: impl Into<String>) {
        self.messages.info(text);
    }

    pub(super) fn error(&mut self, text: impl Into<String>) {
        self.messages.error(text);
    }

    // ----- scan -----

    /// Starts opening the scan in `dir`. It replaces the open scan once its first group has
    /// loaded, with that scan's `preset.toml` (or the defaults); if the folder is not a scan or
    /// a frame is broken, the open scan stays. When the knobs were changed since their preset
    /// (or the defaults), it asks first ([`Confirm::SwitchScan`]).
    ///
    /// # Errors
    /// The message shown when `dir` is not a scan.
    pub fn open_scan(&mut self, dir: &Path) -> Result<(), String> {
        let scan = self.read_scan(dir)?;
        if self.nav.scan.is_some() && self.tuning.is_modified() {
            self.files.confirm = Some(Confirm::SwitchScan(scan.dir));
            return Ok(());
        }
        self.start_opening(scan);
        Ok(())
    }

    /// Opens `dir` without asking about unsaved knobs (the answer to [`Confirm::SwitchScan`]).
    fn open_scan_anyway(&mut self, dir: &Path) {
        if let Ok(scan) = self.read_scan(dir) {
            self.start_opening(scan);
        }
    }

    fn read_scan(&mut self, dir: &Path) -> Result<Scan, String> {
        let scan = match Scan::open(dir) {
            Ok(s) => s,
            Err(e) => {
                let msg = format!("cannot open the scan: {e}");
                self.error(msg.clone());
                return Err(msg);
            }
        };
        if scan.groups.is_empty() {
            let msg = format!("the scan holds no groups: {}", dir.display());
            self.error(msg.clone());
            return Err(msg);
        }
        Ok(scan)
    }

    fn start_opening(&mut self, scan: Scan) {
        let Some(entry) = scan.groups.first().cloned() else {
            return;
        };
        let tuning = Tuning::for_scan(&scan.dir);
        let generation = self.jobs.next_generation();
        self.jobs.submit(
            Job {
                from: Stage::Derivatives,
                params: tuning.0.params().clone(),
                generation,
                input: JobInput::Load {
                    entry,
                    meta: Arc::new(scan.meta.clone()),
                },
                cache: StageCache::default(),
            },
            None,
        );
        self.nav.opening = Some(Opening {
            scan,
            tuning,
            generation,
        });
    }

    /// The opened scan's first group loaded: everything of the old scan gives way.
    fn install_scan(&mut self, opening: Opening, frames: Arc<Vec<Image>>) {
        let Opening {
            scan,
            tuning: (tuning, note),
            ..
        } = opening;
        let dir = scan.dir.clone();
        self.info(format!(
            "opened {} ({} groups{})",
            dir.display(),
            scan.groups.len(),
            if scan.reference.is_some() {
                ", with reference.wav"
            } else {
                ""
            }
        ));
        let groups = scan.groups.len();
        self.nav = Navigation::opened(scan, frames);
        self.stages = StageState::default();
        self.tuning = tuning;
        self.clip = ClipState::for_scan(groups);
        self.player.load(PlayBuffers::default());
        self.views = ViewStates::default();
        self.files.confirm = None;
        self.files.prompt = None;
        if let Err(e) = self.files.recent.push(&dir) {
            self.error(format!("cannot remember the scan: {e}"));
        }
        match note {
            Ok(m) => self.info(m),
            Err(e) => self.error(e),
        }
        if self.settings.reconstruct_on_open {
            self.reconstruct(None);
        }
    }

    /// Shows group `g` (clamped), loading it and rerunning its stages in the background.
    pub fn set_group(&mut self, g: usize) {
        if !self.nav.go_to_group(g) {
            return;
        }
        self.views.nav.jump = self.nav.group;
        self.views.clear_readouts();
        self.stages.clear_for_group();
        self.schedule();
    }

    /// Shows frame `f` of the current group (clamped).
    pub fn set_frame(&mut self, f: usize) {
        self.nav.set_frame(f);
    }

    // ----- params -----

    /// Applies `new` as one undoable change (edits in a burst to one stage merge) and reruns
    /// the stages it makes stale.
    pub fn set_params(&mut self, new: PipelineParams) {
        if self.tuning.set(new, Instant::now()) {
            self.schedule();
        }
    }

    /// Applies `new` as an undo step of its own (a TOML apply, a symptom preset).
    pub fn replace_params(&mut self, new: PipelineParams) {
        if self.tuning.replace(new, Instant::now()) {
            self.schedule();
        }
    }

    /// Undoes the last parameter change.
    pub fn undo(&mut self) {
        if self.tuning.undo() {
            self.schedule();
        }
    }

    /// Redoes the last undone change.
    pub fn redo(&mut self) {
        if self.tuning.redo() {
            self.schedule();
        }
    }

    /// True when there is something to undo / redo.
    #[must_use]
    pub fn can_undo_redo(&self) -> (bool, bool) {
        self.tuning.can_undo_redo()
    }

    /// Reruns `stage` and every later stage of the current group.
    pub fn rerun(&mut self, stage: Stage) {
        self.stages.invalidate_from(stage);
        if stage == Stage::Derivatives {
            self.nav.forget_frames();
        }
        self.schedule();
    }

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
        match super::tuning::save_preset(self.tuning.params(), path, overwrite) {
            Ok(()) => {
                self.tuning.saved_as(path);
                self.info(format!("saved preset {}", path.display()));
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
        let first_frame = scan.groups.first().and_then(|g| g.frames.first());
        let result = meta
            .validate()
            .and_then(|()| match first_frame {
                // What the scan folder holds must agree too (the next open checks it).
                Some(f) => crate::io::frames::frame_dimensions(f)
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

    // ----- the worker -----

    /// Sends the worker a job for whatever is stale (nothing when everything is fresh).
    pub(super) fn schedule(&mut self) {
        if self.nav.opening.is_some() {
            return;
        }
        let (Some(scan), Some(meta)) = (&self.nav.scan, &self.nav.meta) else {
            return;
        };
        let group = self.nav.group;
        let Some(entry) = scan.groups.get(group).cloned() else {
            return;
        };
        let meta = meta.clone();
        let loaded = self.nav.frames().cloned();
        let params = self.tuning.params();
        let from = if loaded.is_some() {
            self.stages.cache.first_stale(params)
        } else {
            Some(Stage::Derivatives)
        };
        let Some(from) = from else {
            return;
        };
        if loaded.is_none() && self.nav.load_error.is_some() {
            return; // the group's frames cannot be read: nothing to retry until a rerun
        }
        if self.stages.failed_with_these(from, group, params) {
            return; // it failed with these very inputs: wait for a change or a rerun
        }
        let params = params.clone();
        let generation = self.jobs.next_generation();
        self.stages.clear_errors_from(from);
        let input = match loaded {
            Some(frames) => JobInput::Ready(GroupInput {
                group,
                frames,
                first_frame: 0,
                meta,
            }),
            None => JobInput::Load { entry, meta },
        };
        let starts_at = matches!(input, JobInput::Ready(_)).then_some(from);
        self.jobs.submit(
            Job {
                from,
                params,
                generation,
                input,
                cache: self.stages.cache.clone(),
            },
            starts_at,
        );
    }

    fn on_stage_done(&mut self, done: StageDone) {
        let current = done.generation == self.jobs.generation();
        match done.result {
            Ok(res) => {
                let adopted = self.stages.adopt(
                    &self.ctx,
                    done.stage,
                    res,
                    done.elapsed,
                    self.nav.group,
                    self.tuning.params(),
                );
                if adopted && current {
                    let next = Stage::ALL.get(done.stage.index() + 1).copied();
                    self.jobs.advance(done.generation, next);
                }
            }
            Err(msg) if current => {
                let group = self.nav.group;
                self.error(format!("group {group}: {}: {msg}", done.stage.name()));
                self.stages
                    .fail(done.stage, msg, self.tuning.params(), group);
            }
            Err(_) => {}
        }
    }

    /// Handles everything the worker and the reconstruction reported.
    pub fn poll(&mut self) {
        self.jobs.submit_pending();
        for ev in self.jobs.poll() {
            match ev {
                WorkerEvent::Loaded {
                    generation,
                    group,
                    frames,
                    textures,
                } => self.on_loaded(generation, group, frames, textures),
                WorkerEvent::StageDone(d) => self.on_stage_done(*d),
                WorkerEvent::Finished {
                    generation,
                    outcome,
                } => {
                    if self.jobs.finished(generation)
                        && let Outcome::Failed(stage, _) = outcome
                    {
                        self.stages.fail_unexplained(stage);
                    }
                }
            }
        }
        match self.clip.poll() {
            Some(Ok(clip)) => self.set_clip(*clip),
            Some(Err(e)) => self.error(format!("reconstruction: {e}")),
            None => {}
        }
        match self.clip.partial_arrived.take() {
            Some(Ok(p)) => {
                self.player.load(PlayBuffers {
                    rate_hz: p.audio.sample_rate_hz,
                    sources: vec![p.audio.channels],
                });
                match self.player.play() {
                    Ok(()) => self.info(format!(
                        "playing the {} groups finished so far (the whole clip follows when \
                         the reconstruction ends)",
                        p.groups
                    )),
                    Err(e) => self.error(e),
                }
            }
            Some(Err(e)) => self.error(format!("cannot play the groups so far: {e}")),
            None => {}
        }
    }

    fn on_loaded(
        &mut self,
        generation: u64,
        group: usize,
        frames: Result<Arc<Vec<Image>>, String>,
        textures: Vec<Arc<egui::ColorImage>>,
    ) {
        if self
            .nav
            .opening
            .as_ref()
            .is_some_and(|p| p.generation == generation)
        {
            let Some(opening) = self.nav.opening.take() else {
                return;
            };
            match frames {
                Ok(frames) => {
                    self.install_scan(opening, frames.clone());
                    self.stages.textures.set_frames(group, &frames, textures);
                    self.jobs.advance(generation, Some(Stage::Derivatives));
                }
                Err(e) => {
                    self.jobs.drop_running();
                    let keep = self.nav.dir().map_or("no scan stays open".into(), |d| {
                        format!("{} stays open", d.display())
                    });
                    self.error(format!(
                        "cannot open {}: group 0: {e} ({keep})",
                        opening.scan.dir.display()
                    ));
                    self.schedule();
                }
            }
            return;
        }
        if group != self.nav.group {
            return;
        }
        let current = generation == self.jobs.generation();
        match frames {
            Ok(f) => {
                // Frames of the current group are good whichever job loaded them.
                if self.nav.frames_loaded(group, f.clone()) {
                    self.stages.textures.set_frames(group, &f, textures);
                }
                if current {
                    self.jobs.advance(generation, Some(Stage::Derivatives));
                }
            }
            Err(e) if current => {
                self.error(format!("group {group}: {e}"));
                self.nav.load_error = Some(e);
                self.nav.frames = None;
            }
            Err(_) => {}
        }
    }

    // ----- the clip -----

    /// Reconstructs `groups` (None: all) in the background.
    pub fn reconstruct(&mut self, groups: Option<std::ops::Range<usize>>) {
        let Some(scan) = &self.nav.scan else {
            self.error("open a scan first");
            return;
        };
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
            "clip ready: {:.1} ms from {} groups",
            clip.recon.audio.duration_secs() * 1000.0,
            clip.groups.len()
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
        match export::export_wav(&clip, path, bits, rate, sel, overwrite) {
            Ok(()) => {
                self.info(format!("exported {}", path.display()));
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
        if export::would_overwrite(&path) {
            self.files.confirm = Some(Confirm::ExportWav { path, selection });
        } else {
            let bits = self.views.wave.bits;
            let _ = self.export_wav_to(&path, bits, selection, false);
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
        if self.nav.uses_dual(self.tuning.params()) {
            "dual-focus"
        } else {
            "depth"
        }
    }

    /// Opens the dialog `kind`, starting in the scan's folder with a name made from the scan.
    pub fn show_dialog(&mut self, kind: DialogKind) {
        let start = self.nav.dir().map(Path::to_path_buf);
        let name = super::files::suggested_name(&kind, start.as_deref(), self.path_name());
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

    /// Shows the in-app path field for `kind`, saying `reason` (no native dialog opened).
    pub(super) fn offer_path_field(&mut self, kind: DialogKind, reason: String) {
        let start = self.nav.dir().map(Path::to_path_buf);
        let name = super::files::suggested_name(&kind, start.as_deref(), self.path_name());
        self.error(format!("{}: {reason}; type the path instead", kind.title()));
        self.files.prompt = Some(PathPrompt {
            text: super::files::suggested_path(start.as_deref(), name.as_deref()),
            kind,
            reason,
        });
    }

    /// Acts on a path chosen in a dialog (native or in-app).
    pub fn use_dialog_path(&mut self, kind: DialogKind, path: PathBuf) {
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
                    self.files.confirm = Some(Confirm::SavePreset(path));
                } else {
                    let _ = self.save_preset_to(&path, false);
                }
            }
            DialogKind::ExportPng(view) => {
                let path = path.with_extension("png");
                if path.exists() {
                    self.files.confirm = Some(Confirm::ExportPng(path, view));
                } else {
                    self.capture_view(path, view, false);
                }
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
        match c {
            Confirm::ExportWav { path, selection } => {
                let bits = self.views.wave.bits;
                let _ = self.export_wav_to(&path, bits, selection, true);
            }
            Confirm::SavePreset(path) => {
                let _ = self.save_preset_to(&path, true);
            }
            Confirm::ExportPng(path, view) => self.capture_view(path, view, true),
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
