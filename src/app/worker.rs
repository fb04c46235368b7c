//! The stage worker: a named thread that loads the current group and reruns its stale stages,
//! reporting after every stage and stopping early when a newer job supersedes the running one.

use std::panic::AssertUnwindSafe;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, SyncSender, TrySendError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use rayon::prelude::*;

use super::render::{self, Rendered};

use crate::image::Image;
use crate::io::{GroupEntry, ScanMeta, load_group};
use crate::pipeline::{GroupInput, PipelineParams, Stage, StageCache, StageError};

/// Jobs waiting for the worker; a newer job replaces a waiting one on the UI side.
const JOB_QUEUE: usize = 1;

/// Where a job's frames come from.
#[derive(Clone, Debug)]
pub enum JobInput {
    /// The frames are loaded already.
    Ready(GroupInput),
    /// Load the group's frames first (reported with [`WorkerEvent::Loaded`]).
    Load {
        /// The group to load.
        entry: GroupEntry,
        /// The scan's metadata.
        meta: Arc<ScanMeta>,
    },
}

impl JobInput {
    /// The group index the job works on.
    #[must_use]
    pub fn group(&self) -> usize {
        match self {
            JobInput::Ready(input) => input.group,
            JobInput::Load { entry, .. } => entry.index,
        }
    }
}

/// One request to the worker: run `from` and every later stage with `params`.
#[derive(Clone, Debug)]
pub struct Job {
    /// First stage to run.
    pub from: Stage,
    /// The knobs to run with.
    pub params: PipelineParams,
    /// Number of this request; the worker drops it once a newer one exists.
    pub generation: u64,
    /// The frames (or where to load them).
    pub input: JobInput,
    /// The UI's cache (cheap `Arc` clones); earlier stages are taken from it.
    pub cache: StageCache,
}

/// Which texture a rendering belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ViewImage {
    /// Flow colour of the flow field with this index.
    FlowColour(usize),
    /// Depth heat map.
    Depth,
    /// Hough accumulator.
    Accumulator,
    /// Segmentation and centroid lines over the frame.
    Segmentation,
    /// In-focus map.
    InFocus,
    /// Robust-fit weights (outlier map).
    Weights,
}

/// What one finished stage left behind.
#[derive(Clone, Debug)]
pub struct StageResult {
    /// The whole cache after the stage (the UI swaps it in).
    pub cache: StageCache,
    /// Textures of the stage's views, rendered off the UI thread.
    pub renders: Vec<(ViewImage, Arc<Rendered>)>,
}

/// Report after one stage.
#[derive(Clone, Debug)]
pub struct StageDone {
    /// The stage.
    pub stage: Stage,
    /// The job it belongs to.
    pub generation: u64,
    /// Its outputs, or the error text.
    pub result: Result<StageResult, String>,
    /// Time the stage took.
    pub elapsed: Duration,
}

/// How a job ended.
#[derive(Clone, Debug, PartialEq)]
pub enum Outcome {
    /// Every stage ran.
    Done,
    /// A newer job superseded it.
    Cancelled,
    /// Loading failed.
    LoadFailed(String),
    /// This stage failed with this message.
    Failed(Stage, String),
}

/// Messages from the worker to the UI.
#[derive(Clone, Debug)]
pub enum WorkerEvent {
    /// A group's frames were loaded (or could not be).
    Loaded {
        /// The job.
        generation: u64,
        /// The group.
        group: usize,
        /// The frames or the error text.
        frames: Result<Arc<Vec<Image>>, String>,
        /// Textures of every frame, rendered off the UI thread (scrubbing and the movie only
        /// upload them).
        textures: Vec<Arc<egui::ColorImage>>,
    },
    /// A stage finished.
    StageDone(Box<StageDone>),
    /// The job ended.
    Finished {
        /// The job.
        generation: u64,
        /// How.
        outcome: Outcome,
    },
}

/// Handle to the worker thread.
pub struct Worker {
    jobs: Option<SyncSender<Box<Job>>>,
    events: Receiver<WorkerEvent>,
    latest: Arc<AtomicU64>,
    thread: Option<JoinHandle<()>>,
}

impl std::fmt::Debug for Worker {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Worker")
            .field("latest", &self.latest.load(Ordering::Relaxed))
            .finish_non_exhaustive()
    }
}

/// Renders the views of `stage` from `cache` (empty for stages without textures); flow colours
/// show the residual after subtracting the land flow `land_px` (px/frame).
#[must_use]
pub fn render_stage(
    stage: Stage,
    cache: &StageCache,
    land_px: f32,
) -> Vec<(ViewImage, Arc<Rendered>)> {
    let mut out = Vec::new();
    match stage {
        Stage::Flow => {
            if let Some(flows) = cache.flows() {
                let mid = flows.len() / 2;
                if let Some(f) = flows.get(mid) {
                    out.push((
                        ViewImage::FlowColour(mid),
                        Arc::new(render::flow_colour(f, land_px)),
                    ));
                }
            }
        }
        Stage::Depth => {
            if let Some(d) = cache.depth() {
                let range = crate::viz::robust_range(&d.map.z_um.data);
                out.push((ViewImage::Depth, Arc::new(render::heat(&d.map.z_um, range))));
            }
        }
        Stage::Stripes => {
            if let Some(s) = cache.stripes() {
                out.push((
                    ViewImage::Accumulator,
                    Arc::new(render::accumulator(&s.accumulator)),
                ));
                let frame = cache
                    .derivatives()
                    .as_ref()
                    .and_then(|d| d.get(d.len() / 2))
                    .map(|d| &d.image);
                if let Some(f) = frame {
                    out.push((ViewImage::Segmentation, Arc::new(render::stripes(f, s))));
                }
                out.push((
                    ViewImage::InFocus,
                    Arc::new(render::heat(&s.in_focus, Some((0.0, 1.0)))),
                ));
            }
        }
        Stage::Orientation => {
            if let Some(o) = cache.orientation() {
                out.push((
                    ViewImage::Weights,
                    Arc::new(render::weights(&o.orientation.weight_map)),
                ));
            }
        }
        Stage::Derivatives | Stage::Sound | Stage::Edges => {}
    }
    out
}

fn panic_text(payload: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = payload.downcast_ref::<&str>() {
        (*s).to_string()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "unknown panic".into()
    }
}

/// Runs one job on the calling thread, sending events to `tx` (the worker loop's body).
pub fn run_job(
    job: Job,
    latest: &AtomicU64,
    tx: &mpsc::Sender<WorkerEvent>,
    repaint: &(dyn Fn() + Send + Sync),
) {
    let generation = job.generation;
    let current = || latest.load(Ordering::Acquire) == generation;
    let finish = |outcome: Outcome| {
        let _ = tx.send(WorkerEvent::Finished {
            generation,
            outcome,
        });
        repaint();
    };
    if !current() {
        return;
    }
    let input = match job.input {
        JobInput::Ready(input) => input,
        JobInput::Load { entry, meta } => {
            let loaded = load_group(&entry).map(Arc::new).map_err(|e| e.to_string());
            let textures = loaded.as_ref().map_or_else(
                |_| Vec::new(),
                |f| {
                    f.par_iter()
                        .map(|img| Arc::new(render::grey(img)))
                        .collect()
                },
            );
            let _ = tx.send(WorkerEvent::Loaded {
                generation,
                group: entry.index,
                frames: loaded.clone(),
                textures,
            });
            repaint();
            match loaded {
                Ok(frames) => GroupInput {
                    group: entry.index,
                    frames,
                    first_frame: 0,
                    meta,
                },
                Err(e) => return finish(Outcome::LoadFailed(e)),
            }
        }
    };
    if !current() {
        return finish(Outcome::Cancelled);
    }
    let land_px = input.meta.geometry().land_flow_px() as f32;
    let mut cache = job.cache;
    let mut next = Some(job.from);
    let mut started = Instant::now();
    let run = std::panic::catch_unwind(AssertUnwindSafe(|| {
        cache.run_from(job.from, &input, &job.params, &mut |stage, c| {
            let elapsed = started.elapsed();
            let result = StageResult {
                cache: c.clone(),
                renders: render_stage(stage, c, land_px),
            };
            let _ = tx.send(WorkerEvent::StageDone(Box::new(StageDone {
                stage,
                generation,
                result: Ok(result),
                elapsed,
            })));
            repaint();
            next = Stage::ALL.get(stage.index() + 1).copied();
            started = Instant::now();
            current()
        })
    }));
    let failed_stage = next.unwrap_or(Stage::Sound);
    let outcome = match run {
        Ok(Ok(())) => Outcome::Done,
        Ok(Err(StageError::Cancelled)) => Outcome::Cancelled,
        Ok(Err(e)) => Outcome::Failed(failed_stage, e.to_string()),
        Err(payload) => Outcome::Failed(
            failed_stage,
            format!("the stage panicked: {}", panic_text(payload.as_ref())),
        ),
    };
    if let Outcome::Failed(stage, msg) = &outcome {
        let _ = tx.send(WorkerEvent::StageDone(Box::new(StageDone {
            stage: *stage,
            generation,
            result: Err(msg.clone()),
            elapsed: started.elapsed(),
        })));
    }
    finish(outcome);
}

impl Worker {
    /// Starts the worker thread; `repaint` is called after every event (wakes the UI).
    ///
    /// # Errors
    /// When the thread cannot be started.
    pub fn spawn(repaint: Box<dyn Fn() + Send + Sync>) -> std::io::Result<Self> {
        let (job_tx, job_rx) = mpsc::sync_channel::<Box<Job>>(JOB_QUEUE);
        let (ev_tx, ev_rx) = mpsc::channel();
        let latest = Arc::new(AtomicU64::new(0));
        let thread_latest = latest.clone();
        let thread = std::thread::Builder::new()
            .name("groovescope-stages".into())
            .spawn(move || {
                for job in job_rx {
                    run_job(*job, &thread_latest, &ev_tx, repaint.as_ref());
                }
            })?;
        Ok(Self {
            jobs: Some(job_tx),
            events: ev_rx,
            latest,
            thread: Some(thread),
        })
    }

    /// Marks `generation` as the newest request; running older work stops at the next stage.
    pub fn supersede(&self, generation: u64) {
        self.latest.store(generation, Ordering::Release);
    }

    /// The newest generation.
    #[must_use]
    pub fn latest(&self) -> u64 {
        self.latest.load(Ordering::Acquire)
    }

    /// Hands `job` to the worker without blocking; gives it back when the queue is full.
    ///
    /// # Errors
    /// The job itself when the queue is full or the worker has stopped.
    pub fn try_submit(&self, job: Box<Job>) -> Result<(), Box<Job>> {
        let Some(tx) = &self.jobs else {
            return Err(job);
        };
        match tx.try_send(job) {
            Ok(()) => Ok(()),
            Err(TrySendError::Full(job) | TrySendError::Disconnected(job)) => Err(job),
        }
    }

    /// Every event waiting, oldest first (never blocks).
    #[must_use]
    pub fn poll(&self) -> Vec<WorkerEvent> {
        self.events.try_iter().collect()
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        self.latest.store(u64::MAX, Ordering::Release);
        self.jobs = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;
    use crate::io::Scan;

    fn wait_finished(w: &Worker, generation: u64) -> Vec<WorkerEvent> {
        let mut all = Vec::new();
        let t0 = Instant::now();
        while t0.elapsed() < Duration::from_secs(20) {
            let evs = w.poll();
            let done = evs.iter().any(
                |e| matches!(e, WorkerEvent::Finished { generation: g, .. } if *g == generation),
            );
            all.extend(evs);
            if done {
                return all;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        panic!("worker did not finish generation {generation}");
    }

    fn tiny_scan(dir: &std::path::Path, broken: bool) -> Scan {
        std::fs::write(
            dir.join("scan.toml"),
            "format = 1\n[record]\nrpm = 78.0\nradius_mm = 115.0\n[camera]\npixel_pitch_um = 0.39\nworking_distance_mm = 4.0\n[motion]\nframe_step_um = 0.78\ngroup_step_um = 20.0\n",
        )
        .unwrap();
        let g = dir.join("g000");
        std::fs::create_dir_all(&g).unwrap();
        for i in 0..7 {
            let img = Image::from_fn(16, 8, |x, y| ((x + y + i) % 5) as f32 / 5.0);
            crate::io::save_grey_png(&img, &g.join(format!("{i:03}.png")), false, true).unwrap();
        }
        if broken {
            std::fs::write(g.join("003.png"), b"garbage").unwrap();
        }
        Scan::open(dir).unwrap()
    }

    /// A worker that has been told generation `generation` is the current one.
    fn worker_at(generation: u64) -> Worker {
        let w = Worker::spawn(Box::new(|| {})).unwrap();
        w.supersede(generation);
        w
    }

    /// A job that loads the first group of `scan` and runs from `from` with `params`.
    fn load_job(scan: &Scan, from: Stage, params: PipelineParams, generation: u64) -> Box<Job> {
        Box::new(Job {
            from,
            params,
            generation,
            input: JobInput::Load {
                entry: scan.groups[0].clone(),
                meta: Arc::new(scan.meta.clone()),
            },
            cache: StageCache::default(),
        })
    }

    #[test]
    fn broken_frame_is_reported_with_its_file() {
        let dir = tempfile::tempdir().unwrap();
        let scan = tiny_scan(dir.path(), true);
        let w = worker_at(1);
        w.try_submit(load_job(
            &scan,
            Stage::Derivatives,
            PipelineParams::default(),
            1,
        ))
        .unwrap();
        let evs = wait_finished(&w, 1);
        let loaded = evs.iter().find_map(|e| match e {
            WorkerEvent::Loaded { frames, .. } => Some(frames.clone()),
            _ => None,
        });
        let err = loaded.unwrap().unwrap_err();
        assert!(err.contains("003.png"), "{err}");
        assert!(matches!(
            evs.last(),
            Some(WorkerEvent::Finished {
                outcome: Outcome::LoadFailed(_),
                ..
            })
        ));
    }

    #[test]
    fn superseded_job_is_skipped_and_invalid_params_fail_at_the_first_stage() {
        let dir = tempfile::tempdir().unwrap();
        let scan = tiny_scan(dir.path(), false);
        let w = worker_at(2);
        let mut bad = PipelineParams::default();
        bad.flow.lambda = f32::NAN;
        let job = |generation| load_job(&scan, Stage::Flow, bad.clone(), generation);
        w.try_submit(job(1)).unwrap();
        let mut second = job(2);
        // The queue holds one job; wait until the worker took the first.
        loop {
            match w.try_submit(second) {
                Ok(()) => break,
                Err(j) => {
                    second = j;
                    std::thread::sleep(Duration::from_millis(2));
                }
            }
        }
        let evs = wait_finished(&w, 2);
        assert!(
            evs.iter().all(|e| match e {
                WorkerEvent::Loaded { generation, .. } => *generation == 2,
                WorkerEvent::StageDone(d) => d.generation == 2,
                WorkerEvent::Finished { generation, .. } => *generation == 2,
            }),
            "generation 1 was superseded before it started: {evs:?}"
        );
        match evs.last() {
            Some(WorkerEvent::Finished {
                outcome: Outcome::Failed(stage, msg),
                ..
            }) => {
                assert_eq!(*stage, Stage::Flow);
                assert!(msg.contains("flow.lambda"), "{msg}");
            }
            other => panic!("expected a failure, got {other:?}"),
        }
    }
}
