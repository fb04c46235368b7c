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
use super::files::{Confirm, Files, PathPrompt};
use super::jobs::Jobs;
use super::messages::{Message, Messages};
use super::nav::{Navigation, Opening};
use super::recent::RecentScans;
use super::recon::Clip;
use super::screenshot::Capture;
use super::stages::StageState;
use super::tuning::{ParamState, Tuning};
use super::views::View;
use super::views::states::ViewStates;
use super::worker::{Job, JobInput, Outcome, StageDone, WorkerEvent};
use crate::image::Image;
use crate::io::Scan;
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
    /// Open "Compare methods" and run it with these methods once the scan is open (scripts:
    /// see [`super::COMPARE_METHODS_ENV`]).
    pub compare_methods: Option<[crate::pipeline::Method; 2]>,
    /// Open this still image in the still window.
    pub still: Option<PathBuf>,
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
    /// The "Compare methods" window and its runs.
    pub(super) methods: super::compare::CompareState,
    /// A method comparison to run once the scan is open ([`WorkbenchOptions::compare_methods`]).
    pub(super) compare_on_open: Option<[crate::pipeline::Method; 2]>,
    /// The still window, its open still and its decode.
    pub(super) still: super::still::StillState,
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
            methods: super::compare::CompareState::default(),
            compare_on_open: opts.compare_methods,
            still: super::still::StillState::default(),
            #[cfg(feature = "video")]
            video_import: super::import_video::VideoImport::default(),
        };
        if let Some(dir) = opts.scan {
            let _ = wb.open_scan(&dir);
        }
        if let Some(still) = opts.still {
            wb.open_still(&still);
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

    /// True while the clip reconstructs, a method comparison runs or a still decodes.
    #[must_use]
    pub fn is_reconstructing(&self) -> bool {
        self.clip.is_running() || self.methods.run.is_some() || self.still.job.is_some()
    }

    /// Longest UI frame (time spent in `ui`) seen while the worker was busy.
    #[must_use]
    pub fn max_busy_frame(&self) -> Duration {
        self.max_busy_frame
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
    pub(super) fn open_scan_anyway(&mut self, dir: &Path) {
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
            match scan.reference.as_deref().map(std::path::Path::is_file) {
                Some(true) => ", with reference.wav",
                Some(false) => ", with a reference.wav that is no file",
                None => "",
            }
        ));
        let groups = scan.groups.len();
        let missing = scan.missing_note(0..groups);
        self.nav = Navigation::opened(scan, frames);
        self.stages = StageState::default();
        self.tuning = tuning;
        self.clip = ClipState::for_scan(groups);
        self.player.load(PlayBuffers::default());
        self.views = ViewStates::default();
        self.methods = super::compare::CompareState {
            open: self.methods.open,
            ..Default::default()
        };
        self.files.confirm = None;
        self.files.prompt = None;
        if let Err(e) = self.files.recent.push(&dir) {
            self.error(format!("cannot remember the scan: {e}"));
        }
        match note {
            Ok(m) => self.info(m),
            Err(e) => self.error(e),
        }
        if let Some(m) = missing {
            self.error(format!("{m}: each stays a gap of silence, in its place"));
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
        self.poll_comparison();
        self.poll_still();
        match self.clip.partial_arrived.take() {
            Some(Ok(p)) => {
                self.clip.comparison_heard = None;
                self.clip.still_heard = false;
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
                self.stages.frames_unreadable(&e);
                self.nav.load_error = Some(e);
                self.nav.frames = None;
            }
            Err(_) => {}
        }
    }
}
