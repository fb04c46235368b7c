//! The stage worker as the UI sees it: the newest job's number, the job waiting for the
//! worker's queue, and which stage of the running job is under way.

use super::worker::{Job, Worker, WorkerEvent};
use crate::pipeline::Stage;

/// The job the worker is on.
#[derive(Clone, Debug)]
struct Running {
    generation: u64,
    /// Stage running now (None while frames load).
    current: Option<Stage>,
}

/// Jobs sent to the stage worker.
#[derive(Debug)]
pub struct Jobs {
    worker: Worker,
    generation: u64,
    pending: Option<Box<Job>>,
    running: Option<Running>,
}

impl Jobs {
    /// Starts the worker thread; `repaint` wakes the UI after every event.
    ///
    /// # Errors
    /// When the thread cannot be started.
    pub fn start(repaint: Box<dyn Fn() + Send + Sync>) -> std::io::Result<Self> {
        Ok(Self {
            worker: Worker::spawn(repaint)?,
            generation: 0,
            pending: None,
            running: None,
        })
    }

    /// A number for a new job; every older job stops at its next stage.
    pub fn next_generation(&mut self) -> u64 {
        self.generation += 1;
        self.worker.supersede(self.generation);
        self.generation
    }

    /// The newest job's number.
    #[must_use]
    pub fn generation(&self) -> u64 {
        self.generation
    }

    /// Hands `job` (numbered by [`Jobs::next_generation`]) to the worker, replacing a job that
    /// still waits; `starts_at` is the stage it starts with (None while it loads frames).
    pub fn submit(&mut self, job: Job, starts_at: Option<Stage>) {
        self.running = Some(Running {
            generation: job.generation,
            current: starts_at,
        });
        self.pending = Some(Box::new(job));
        self.submit_pending();
    }

    /// Retries handing the waiting job to the worker (its queue holds one).
    pub fn submit_pending(&mut self) {
        if let Some(job) = self.pending.take()
            && let Err(job) = self.worker.try_submit(job)
        {
            self.pending = Some(job);
        }
    }

    /// Everything the worker reported since the last call.
    #[must_use]
    pub fn poll(&self) -> Vec<WorkerEvent> {
        self.worker.poll()
    }

    /// True when no job runs or waits.
    #[must_use]
    pub fn is_idle(&self) -> bool {
        self.running.is_none() && self.pending.is_none()
    }

    /// The stage the newest job is running.
    #[must_use]
    pub fn running_stage(&self) -> Option<Stage> {
        self.running.as_ref().and_then(|r| r.current)
    }

    /// The newest job moved on to `stage` (None: it is past the last one).
    pub fn advance(&mut self, generation: u64, stage: Option<Stage>) {
        if let Some(r) = &mut self.running
            && r.generation == generation
        {
            r.current = stage;
        }
    }

    /// Job `generation` ended; true when it was the newest one.
    pub fn finished(&mut self, generation: u64) -> bool {
        if self
            .running
            .as_ref()
            .is_some_and(|r| r.generation == generation)
        {
            self.running = None;
            true
        } else {
            false
        }
    }

    /// Forgets the running job (its result no longer matters).
    pub fn drop_running(&mut self) {
        self.running = None;
    }
}
