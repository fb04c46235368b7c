//! The workbench's state and the operator's actions: open a scan, navigate, tune params with
//! undo/redo, rerun stale stages on the worker, reconstruct, play and export.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::mpsc::{Receiver, Sender};
use std::time::{Duration, Instant};

use super::dialogs::Dialogs;
use super::export;
use super::history::History;
use super::recent::RecentScans;
use super::recon::{Clip, ReconRun};
use super::textures::Textures;
use super::views::StageStatus;
use super::views::View;
use super::views::depth_ui::DepthViewState;
use super::views::flow_ui::FlowViewState;
use super::views::frame_ui::FrameViewState;
use super::views::hough_ui::HoughViewState;
use super::views::meta_ui::MetaForm;
use super::views::nav_ui::NavState;
use super::views::orientation_ui::OrientationViewState;
use super::views::stripes_ui::StripesViewState;
use super::views::waveform_ui::WaveViewState;
use super::worker::{Job, JobInput, Outcome, StageDone, Worker, WorkerEvent};
use crate::engine::ReconstructOptions;
use crate::image::Image;
use crate::io::wav::WavBits;
use crate::io::{Scan, ScanMeta};
use crate::pipeline::{GroupInput, PipelineParams, Stage, StageCache};
use crate::playback::{DeviceChoice, PlayBuffers, Player};

/// Name of the per-disc preset loaded automatically from a scan folder.
pub const SCAN_PRESET_FILE: &str = "preset.toml";

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
}

/// A question waiting for the operator.
#[derive(Clone, Debug, PartialEq)]
pub enum Confirm {
    /// Replace an existing WAV (and sidecar).
    ExportWav {
        /// Target.
        path: PathBuf,
        /// Selection only.
        selection: bool,
    },
    /// Replace an existing preset file.
    SavePreset(PathBuf),
    /// Replace an existing PNG.
    ExportPng(PathBuf, View),
}

/// One line in the status bar.
#[derive(Clone, Debug, PartialEq)]
pub struct Message {
    /// The text.
    pub text: String,
    /// True for errors.
    pub error: bool,
}

/// The job the worker is on.
#[derive(Clone, Debug)]
pub(super) struct Running {
    pub generation: u64,
    /// Stage running now (None while frames load).
    pub current: Option<Stage>,
}

/// A scan waiting for its first group to load before it replaces the open one.
#[derive(Debug)]
pub(super) struct PendingOpen {
    pub scan: Scan,
    pub generation: u64,
}

/// Per-view UI state.
#[derive(Debug, Default)]
pub(super) struct ViewStates {
    pub frame: FrameViewState,
    pub flow: FlowViewState,
    pub hough: HoughViewState,
    pub stripes: StripesViewState,
    pub depth: DepthViewState,
    pub orientation: OrientationViewState,
    pub wave: WaveViewState,
    pub nav: NavState,
    pub toml: super::views::params_ui::TomlEditor,
}

/// The workbench.
pub struct Workbench {
    pub(super) ctx: egui::Context,
    pub(super) scan: Option<Scan>,
    pub(super) meta: Option<Arc<ScanMeta>>,
    pub(super) pending_open: Option<PendingOpen>,
    pub(super) group: usize,
    pub(super) frame: usize,
    pub(super) frames: Option<(usize, Arc<Vec<Image>>)>,
    pub(super) load_error: Option<String>,
    pub(super) params: PipelineParams,
    pub(super) history: History,
    pub(super) preset_file: Option<PathBuf>,
    pub(super) cache: StageCache,
    pub(super) stage_errors: [Option<String>; crate::pipeline::Stage::COUNT],
    /// Params and group each failed stage failed with (not retried until one of them changes).
    pub(super) failed_with: [Option<(PipelineParams, usize)>; crate::pipeline::Stage::COUNT],
    pub(super) stage_times: [Option<Duration>; crate::pipeline::Stage::COUNT],
    pub(super) stage_runs: [u64; crate::pipeline::Stage::COUNT],
    pub(super) textures: Textures,
    pub(super) worker: Worker,
    pub(super) generation: u64,
    pub(super) pending_job: Option<Box<Job>>,
    pub(super) running: Option<Running>,
    pub(super) recon: Option<ReconRun>,
    pub(super) clip: Option<Arc<Clip>>,
    pub(super) player: Player,
    pub(super) view: View,
    pub(super) views: ViewStates,
    pub(super) meta_form: Option<MetaForm>,
    pub(super) messages: Vec<Message>,
    pub(super) confirm: Option<Confirm>,
    pub(super) dialogs: Dialogs,
    pub(super) recent: RecentScans,
    pub(super) screenshot: Option<super::shell::ScreenshotPlan>,
    pub(super) capture: (
        Sender<Arc<egui::ColorImage>>,
        Receiver<Arc<egui::ColorImage>>,
    ),
    pub(super) pending_capture: Option<(PathBuf, egui::Rect, bool)>,
    pub(super) view_rect: egui::Rect,
    pub(super) reconstruct_on_open: bool,
    /// See [`WorkbenchOptions::hide_timings`].
    pub(super) hide_timings: bool,
    pub(super) max_busy_frame: Duration,
    /// The "Import video" window and its running import.
    #[cfg(feature = "video")]
    pub(super) video_import: super::import_video::VideoImport,
}

impl std::fmt::Debug for Workbench {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Workbench")
            .field("scan", &self.scan.as_ref().map(|s| &s.dir))
            .field("group", &self.group)
            .field("generation", &self.generation)
            .finish_non_exhaustive()
    }
}

fn repaint_fn(ctx: &egui::Context) -> Box<dyn Fn() + Send + Sync> {
    let ctx = ctx.clone();
    Box::new(move || ctx.request_repaint())
}

impl Workbench {
    /// Builds the workbench (starting its worker and audio) and starts opening `opts.scan`.
    ///
    /// # Errors
    /// When the worker thread cannot be started.
    pub fn new(ctx: &egui::Context, opts: WorkbenchOptions) -> std::io::Result<Self> {
        let worker = Worker::spawn(repaint_fn(ctx))?;
        let mut recent = RecentScans::load(opts.config_dir.as_deref());
        recent.prune();
        let mut wb = Self {
            ctx: ctx.clone(),
            scan: None,
            meta: None,
            pending_open: None,
            group: 0,
            frame: 0,
            frames: None,
            load_error: None,
            params: PipelineParams::default(),
            history: History::default(),
            preset_file: None,
            cache: StageCache::default(),
            stage_errors: Default::default(),
            failed_with: Default::default(),
            stage_times: [None; crate::pipeline::Stage::COUNT],
            stage_runs: [0; crate::pipeline::Stage::COUNT],
            textures: Textures::default(),
            worker,
            generation: 0,
            pending_job: None,
            running: None,
            recon: None,
            clip: None,
            player: Player::open(&opts.audio),
            view: opts.view.unwrap_or(View::Overview),
            views: ViewStates::default(),
            meta_form: None,
            messages: Vec::new(),
            confirm: None,
            dialogs: Dialogs::default(),
            recent,
            screenshot: opts.screenshot.map(super::shell::ScreenshotPlan::new),
            capture: std::sync::mpsc::channel(),
            pending_capture: None,
            view_rect: egui::Rect::NOTHING,
            reconstruct_on_open: opts.reconstruct_on_open,
            hide_timings: opts.hide_timings,
            max_busy_frame: Duration::ZERO,
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
        self.scan.as_ref()
    }

    /// Current group index.
    #[must_use]
    pub fn group(&self) -> usize {
        self.group
    }

    /// Current frame index within the group.
    #[must_use]
    pub fn frame(&self) -> usize {
        self.frame
    }

    /// The params in force.
    #[must_use]
    pub fn params(&self) -> &PipelineParams {
        &self.params
    }

    /// The stage results on screen.
    #[must_use]
    pub fn cache(&self) -> &StageCache {
        &self.cache
    }

    /// How often `stage` finished for the current scan (counts reruns).
    #[must_use]
    pub fn stage_runs(&self, stage: Stage) -> u64 {
        self.stage_runs[stage.index()]
    }

    /// The finished clip.
    #[must_use]
    pub fn clip(&self) -> Option<&Clip> {
        self.clip.as_deref()
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
        &self.messages
    }

    /// The question waiting for the operator.
    #[must_use]
    pub fn confirm(&self) -> Option<&Confirm> {
        self.confirm.as_ref()
    }

    /// The recent scans.
    #[must_use]
    pub fn recent(&self) -> &[PathBuf] {
        &self.recent.scans
    }

    /// True when no stage work or scan opening is under way.
    #[must_use]
    pub fn is_idle(&self) -> bool {
        self.running.is_none() && self.pending_job.is_none() && self.pending_open.is_none()
    }

    /// True while the clip reconstructs.
    #[must_use]
    pub fn is_reconstructing(&self) -> bool {
        self.recon.is_some()
    }

    /// Longest UI frame (time spent in `ui`) seen while the worker was busy.
    #[must_use]
    pub fn max_busy_frame(&self) -> Duration {
        self.max_busy_frame
    }

    fn uses_dual(&self) -> bool {
        self.meta
            .as_ref()
            .is_some_and(|m| self.params.uses_dual_focus(m))
    }

    /// Status of `stage` for the current group.
    #[must_use]
    pub fn stage_status(&self, stage: Stage) -> StageStatus {
        let i = stage.index();
        if let Some(e) = &self.stage_errors[i] {
            return StageStatus::Failed(e.clone());
        }
        if self
            .running
            .as_ref()
            .is_some_and(|r| r.current == Some(stage))
        {
            return StageStatus::Running;
        }
        if self.cache.group() == Some(self.group) && self.cache.is_fresh(stage, &self.params) {
            let unused = if self.uses_dual() {
                stage == Stage::Depth
            } else {
                stage == Stage::Stripes
            };
            return if unused {
                StageStatus::Unused
            } else {
                StageStatus::Fresh
            };
        }
        StageStatus::Stale
    }

    /// Status of every stage.
    #[must_use]
    pub fn statuses(&self) -> [StageStatus; crate::pipeline::Stage::COUNT] {
        Stage::ALL.map(|s| self.stage_status(s))
    }

    // ----- messages -----

    pub(super) fn info(&mut self, text: impl Into<String>) {
        self.messages.push(Message {
            text: text.into(),
            error: false,
        });
    }

    pub(super) fn error(&mut self, text: impl Into<String>) {
        let text = text.into();
        eprintln!("groovescope: {text}");
        self.messages.push(Message { text, error: true });
    }

    // ----- scan -----

    /// Starts opening the scan in `dir`. It replaces the open scan once its first group has
    /// loaded; if the folder is not a scan or a frame is broken, the open scan stays.
    ///
    /// # Errors
    /// The message shown when `dir` is not a scan.
    pub fn open_scan(&mut self, dir: &Path) -> Result<(), String> {
        let scan = match Scan::open(dir) {
            Ok(s) => s,
            Err(e) => {
                let msg = format!("cannot open the scan: {e}");
                self.error(msg.clone());
                return Err(msg);
            }
        };
        let Some(entry) = scan.groups.first().cloned() else {
            let msg = format!("the scan holds no groups: {}", dir.display());
            self.error(msg.clone());
            return Err(msg);
        };
        self.generation += 1;
        self.worker.supersede(self.generation);
        let job = Job {
            from: Stage::Derivatives,
            params: self.params.clone(),
            generation: self.generation,
            input: JobInput::Load {
                entry,
                meta: Arc::new(scan.meta.clone()),
            },
            cache: StageCache::default(),
        };
        self.pending_job = Some(Box::new(job));
        self.running = Some(Running {
            generation: self.generation,
            current: None,
        });
        self.pending_open = Some(PendingOpen {
            scan,
            generation: self.generation,
        });
        self.submit_pending();
        Ok(())
    }

    fn install_scan(&mut self, scan: Scan, frames: Arc<Vec<Image>>) {
        let dir = scan.dir.clone();
        self.meta = Some(Arc::new(scan.meta.clone()));
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
        self.scan = Some(scan);
        self.group = 0;
        self.frame = frames.len() / 2;
        self.frames = Some((0, frames));
        self.load_error = None;
        self.cache = StageCache::default();
        self.stage_errors = Default::default();
        self.failed_with = Default::default();
        self.stage_times = [None; crate::pipeline::Stage::COUNT];
        self.stage_runs = [0; crate::pipeline::Stage::COUNT];
        self.textures.clear();
        self.recon = None;
        self.clip = None;
        self.player.load(PlayBuffers::default());
        self.views.wave.selection = None;
        self.meta_form = None;
        if let Err(e) = self.recent.push(&dir) {
            self.error(format!("cannot remember the scan: {e}"));
        }
        let preset = dir.join(SCAN_PRESET_FILE);
        if preset.is_file() {
            match export::load_preset(&preset) {
                Ok(p) => {
                    self.info(format!("loaded the scan's preset {}", preset.display()));
                    self.preset_file = Some(preset);
                    self.replace_params(p);
                }
                Err(e) => self.error(e),
            }
        }
        if self.reconstruct_on_open {
            self.reconstruct(None);
        }
    }

    /// Shows group `g` (clamped), loading it and rerunning its stages in the background.
    pub fn set_group(&mut self, g: usize) {
        let Some(scan) = &self.scan else { return };
        let g = g.min(scan.groups.len().saturating_sub(1));
        if g == self.group && self.frames.as_ref().is_some_and(|(fg, _)| *fg == g) {
            return;
        }
        self.group = g;
        self.views.nav.jump = g;
        self.cache.clear();
        self.stage_errors = Default::default();
        self.failed_with = Default::default();
        self.load_error = None;
        self.schedule();
    }

    /// Shows frame `f` of the current group (clamped).
    pub fn set_frame(&mut self, f: usize) {
        let n = self.frames.as_ref().map_or(1, |(_, fr)| fr.len());
        self.frame = f.min(n.saturating_sub(1));
    }

    /// The current group's frames, once loaded.
    #[must_use]
    pub fn frames(&self) -> Option<&Arc<Vec<Image>>> {
        self.frames
            .as_ref()
            .filter(|(g, _)| *g == self.group)
            .map(|(_, f)| f)
    }

    // ----- params -----

    /// Applies `new` as one undoable change (edits in a burst to one stage merge) and reruns
    /// the stages it makes stale.
    pub fn set_params(&mut self, new: PipelineParams) {
        if new == self.params {
            return;
        }
        let stage = self.params.first_changed_stage(&new);
        self.history.record(&self.params, stage, Instant::now());
        self.params = new;
        self.schedule();
    }

    /// Replaces the params as a separate undo step (preset load).
    fn replace_params(&mut self, new: PipelineParams) {
        self.history.seal();
        self.set_params(new);
        self.history.seal();
    }

    /// Undoes the last parameter change.
    pub fn undo(&mut self) {
        if let Some(p) = self.history.undo(&self.params) {
            self.params = p;
            self.schedule();
        }
    }

    /// Redoes the last undone change.
    pub fn redo(&mut self) {
        if let Some(p) = self.history.redo(&self.params) {
            self.params = p;
            self.schedule();
        }
    }

    /// True when there is something to undo / redo.
    #[must_use]
    pub fn can_undo_redo(&self) -> (bool, bool) {
        (self.history.can_undo(), self.history.can_redo())
    }

    /// Reruns `stage` and every later stage of the current group.
    pub fn rerun(&mut self, stage: Stage) {
        self.cache.invalidate(stage);
        for f in &mut self.failed_with[stage.index()..] {
            *f = None;
        }
        if stage == Stage::Derivatives {
            self.frames = None;
            self.load_error = None;
        }
        self.schedule();
    }

    /// Loads a preset (an undoable change); on error the params stay as they are.
    ///
    /// # Errors
    /// The message shown.
    pub fn load_preset_from(&mut self, path: &Path) -> Result<(), String> {
        match export::load_preset(path) {
            Ok(p) => {
                self.preset_file = Some(path.to_path_buf());
                self.replace_params(p);
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
        match export::save_preset(&self.params, path, overwrite) {
            Ok(()) => {
                self.preset_file = Some(path.to_path_buf());
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
        let Some(scan) = &mut self.scan else {
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
                self.meta = Some(Arc::new(meta));
                self.meta_form = None;
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
        if self.pending_open.is_some() {
            return;
        }
        let (Some(scan), Some(meta)) = (&self.scan, &self.meta) else {
            return;
        };
        let Some(entry) = scan.groups.get(self.group).cloned() else {
            return;
        };
        let loaded = self.frames().cloned();
        let from = if loaded.is_some() {
            self.cache.first_stale(&self.params)
        } else {
            Some(Stage::Derivatives)
        };
        let Some(from) = from else {
            return;
        };
        if loaded.is_none() && self.load_error.is_some() {
            return; // the group's frames cannot be read: nothing to retry until a rerun
        }
        if let Some((p, g)) = &self.failed_with[from.index()]
            && *g == self.group
            && p.first_changed_stage(&self.params).is_none_or(|s| s > from)
        {
            return; // it failed with these very inputs: wait for a change or a rerun
        }
        self.generation += 1;
        self.worker.supersede(self.generation);
        for e in &mut self.stage_errors[from.index()..] {
            *e = None;
        }
        let input = match loaded {
            Some(frames) => JobInput::Ready(GroupInput {
                group: self.group,
                frames,
                first_frame: 0,
                meta: meta.clone(),
            }),
            None => JobInput::Load {
                entry,
                meta: meta.clone(),
            },
        };
        let current = matches!(input, JobInput::Ready(_)).then_some(from);
        self.pending_job = Some(Box::new(Job {
            from,
            params: self.params.clone(),
            generation: self.generation,
            input,
            cache: self.cache.clone(),
        }));
        self.running = Some(Running {
            generation: self.generation,
            current,
        });
        self.submit_pending();
    }

    fn submit_pending(&mut self) {
        if let Some(job) = self.pending_job.take()
            && let Err(job) = self.worker.try_submit(job)
        {
            self.pending_job = Some(job);
        }
    }

    fn on_stage_done(&mut self, done: StageDone) {
        let current = done.generation == self.generation;
        match done.result {
            Ok(res) => {
                let usable = res.cache.group() == Some(self.group)
                    && res.cache.is_fresh(done.stage, &self.params);
                if !usable {
                    return;
                }
                self.cache.adopt(done.stage, &res.cache);
                let i = done.stage.index();
                self.stage_errors[i] = None;
                self.stage_times[i] = Some(done.elapsed);
                self.stage_runs[i] += 1;
                let source = self.cache.output_id(done.stage);
                for (key, r) in res.renders {
                    self.textures.set(&self.ctx, key, r, source);
                }
                if current && let Some(r) = &mut self.running {
                    r.current = Stage::ALL.get(i + 1).copied();
                }
            }
            Err(msg) if current => {
                self.error(format!(
                    "group {}: {}: {msg}",
                    self.group,
                    done.stage.name()
                ));
                self.stage_errors[done.stage.index()] = Some(msg);
                self.failed_with[done.stage.index()] = Some((self.params.clone(), self.group));
            }
            Err(_) => {}
        }
    }

    /// Handles everything the worker, the reconstruction, dialogs and captures reported.
    pub fn poll(&mut self) {
        self.submit_pending();
        for ev in self.worker.poll() {
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
                    if self
                        .running
                        .as_ref()
                        .is_some_and(|r| r.generation == generation)
                    {
                        self.running = None;
                        if let Outcome::Failed(stage, _) = outcome
                            && let Some(r) = self.stage_errors.get_mut(stage.index())
                            && r.is_none()
                        {
                            *r = Some("failed".into());
                        }
                    }
                }
            }
        }
        if let Some(run) = &mut self.recon
            && let Some(outcome) = run.poll()
        {
            self.recon = None;
            match outcome {
                Ok(clip) => self.set_clip(*clip),
                Err(e) => self.error(format!("reconstruction: {e}")),
            }
        }
    }

    fn on_loaded(
        &mut self,
        generation: u64,
        group: usize,
        frames: Result<Arc<Vec<Image>>, String>,
        textures: Vec<Arc<egui::ColorImage>>,
    ) {
        let upload = |wb: &mut Self, f: &Arc<Vec<Image>>| {
            wb.textures.set_frames(group, f, textures.clone());
        };
        if self
            .pending_open
            .as_ref()
            .is_some_and(|p| p.generation == generation)
        {
            let Some(pending) = self.pending_open.take() else {
                return;
            };
            match frames {
                Ok(frames) => {
                    let job_params = self.params.clone();
                    self.install_scan(pending.scan, frames.clone());
                    upload(self, &frames);
                    if self.params != job_params {
                        self.schedule();
                    }
                }
                Err(e) => {
                    self.running = None;
                    let keep = self.scan.as_ref().map_or("no scan stays open".into(), |s| {
                        format!("{} stays open", s.dir.display())
                    });
                    self.error(format!(
                        "cannot open {}: group 0: {e} ({keep})",
                        pending.scan.dir.display()
                    ));
                    self.schedule();
                }
            }
            return;
        }
        if group != self.group {
            return;
        }
        let current = generation == self.generation;
        match frames {
            Ok(f) => {
                // Frames of the current group are good whichever job loaded them.
                if self.frames().is_none() {
                    self.frame = self.frame.min(f.len().saturating_sub(1));
                    upload(self, &f);
                    self.frames = Some((group, f));
                    self.load_error = None;
                }
                if let (true, Some(r)) = (current, &mut self.running) {
                    r.current = Some(Stage::Derivatives);
                }
            }
            Err(e) if current => {
                self.error(format!("group {group}: {e}"));
                self.load_error = Some(e);
                self.frames = None;
            }
            Err(_) => {}
        }
    }

    // ----- the clip -----

    /// Reconstructs `groups` (None: all) in the background.
    pub fn reconstruct(&mut self, groups: Option<std::ops::Range<usize>>) {
        let Some(scan) = &self.scan else {
            self.error("open a scan first");
            return;
        };
        let opts = ReconstructOptions {
            params: self.params.clone(),
            groups,
            keep_going: true,
        };
        match ReconRun::start(scan.clone(), opts, repaint_fn(&self.ctx)) {
            Ok(run) => self.recon = Some(run),
            Err(e) => self.error(format!("cannot start the reconstruction: {e}")),
        }
    }

    /// Stops the running reconstruction after its current group.
    pub fn cancel_reconstruction(&mut self) {
        if let Some(r) = &self.recon {
            r.cancel();
        }
    }

    /// Shows and loads a finished clip for playback.
    pub fn set_clip(&mut self, clip: Clip) {
        let reference = clip.reference.as_ref().map(|r| vec![r.to_vec()]);
        self.player.load(PlayBuffers {
            rate_hz: clip.rate_hz(),
            a: clip.recon.audio.channels.clone(),
            b: reference,
        });
        self.info(format!(
            "clip ready: {:.1} ms from {} groups",
            clip.recon.audio.duration_secs() * 1000.0,
            clip.groups.len()
        ));
        self.views.wave.selection = None;
        self.clip = Some(Arc::new(clip));
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
        let Some(clip) = self.clip.clone() else {
            let msg = "nothing to export: reconstruct the clip first".to_string();
            self.error(msg.clone());
            return Err(msg);
        };
        let sel = if selection {
            self.views.wave.selection
        } else {
            None
        };
        match export::export_wav(
            &clip,
            path,
            bits,
            sel,
            self.preset_file.as_deref(),
            overwrite,
        ) {
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
            self.confirm = Some(Confirm::ExportWav { path, selection });
        } else {
            let bits = self.views.wave.bits;
            let _ = self.export_wav_to(&path, bits, selection, false);
        }
    }

    /// Selects `[a, b]` seconds of the clip.
    pub fn set_selection(&mut self, selection: Option<(f64, f64)>) {
        self.views.wave.selection = selection;
    }

    /// Sets the export encoding.
    pub fn set_export_bits(&mut self, bits: WavBits) {
        self.views.wave.bits = bits;
    }
}
