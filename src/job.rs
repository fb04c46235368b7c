//! The handle a long piece of work (rendering, importing or packing a scan) reports its progress
//! to and is cancelled through, and the command line's Ctrl-C that cancels it.

use std::fmt;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};

/// The flag of [`Job::unwatched`]: never raised.
static NEVER: AtomicBool = AtomicBool::new(false);

/// The flag the first Ctrl-C (SIGINT) or SIGTERM raises once [`catch_interrupts`] has run.
fn interrupt_flag() -> &'static Arc<AtomicBool> {
    static FLAG: OnceLock<Arc<AtomicBool>> = OnceLock::new();
    FLAG.get_or_init(|| Arc::new(AtomicBool::new(false)))
}

/// A second interrupt this soon after the first is the same one delivered twice: `timeout -s
/// INT` signals the command and then its process group, which holds the command too.
const SAME_INTERRUPT: std::time::Duration = std::time::Duration::from_millis(200);

/// Makes Ctrl-C and SIGTERM cancel the command line's jobs instead of killing the process:
/// the first raises [`interrupted`], so a job stops at its next unit of work, removes what it
/// had not finished (or keeps its journal) and says so; a second one (200 ms or more
/// after it: sooner, it is the same one delivered twice) says so and exits at once (status 130).
///
/// # Errors
/// When the handlers cannot be installed.
pub fn catch_interrupts() -> std::io::Result<()> {
    use signal_hook::consts::{SIGINT, SIGTERM};
    let mut signals = signal_hook::iterator::Signals::new([SIGINT, SIGTERM])?;
    let flag = Arc::clone(interrupt_flag());
    std::thread::Builder::new()
        .name("interrupts".into())
        .spawn(move || {
            let mut first: Option<std::time::Instant> = None;
            for _ in signals.forever() {
                match first {
                    None => {
                        flag.store(true, Ordering::SeqCst);
                        first = Some(std::time::Instant::now());
                    }
                    Some(t) if t.elapsed() >= SAME_INTERRUPT => {
                        crate::tell!(
                            "interrupted again: stopped at once, without removing what was \
                             unfinished (a journal or partial store keeps what it holds)"
                        );
                        std::process::exit(130);
                    }
                    Some(_) => {}
                }
            }
        })?;
    Ok(())
}

/// Raised once the operator pressed Ctrl-C (see [`catch_interrupts`]).
#[must_use]
pub fn interrupted() -> &'static AtomicBool {
    interrupt_flag()
}

/// Ignores a progress report.
fn ignore(_done: usize, _total: usize) {}

/// Where a long job reports `progress(done, total)` and the flag that cancels it.
///
/// It is `Copy` and `Sync`, so parallel workers can each hold one.
#[derive(Clone, Copy)]
pub struct Job<'a> {
    progress: &'a (dyn Fn(usize, usize) + Sync),
    cancel: &'a AtomicBool,
}

impl<'a> Job<'a> {
    /// A job that reports to `progress` and stops once `cancel` is raised.
    #[must_use]
    pub fn new(progress: &'a (dyn Fn(usize, usize) + Sync), cancel: &'a AtomicBool) -> Self {
        Self { progress, cancel }
    }

    /// A job that reports to `progress` (a command line's progress bar) and is cancelled by
    /// Ctrl-C once [`catch_interrupts`] has run.
    #[must_use]
    pub fn reporting(progress: &'a (dyn Fn(usize, usize) + Sync)) -> Self {
        Self::new(progress, interrupted())
    }

    /// A job nobody watches: its reports go nowhere and it is never cancelled.
    #[must_use]
    pub fn unwatched() -> Job<'static> {
        Job {
            progress: &ignore,
            cancel: &NEVER,
        }
    }

    /// Reports that `done` of `total` units are finished.
    pub fn report(&self, done: usize, total: usize) {
        (self.progress)(done, total);
    }

    /// True once the job has been asked to stop.
    #[must_use]
    pub fn is_cancelled(&self) -> bool {
        self.cancel.load(Ordering::Relaxed)
    }
}

impl fmt::Debug for Job<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Job")
            .field("cancelled", &self.is_cancelled())
            .finish_non_exhaustive()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;

    #[test]
    fn reports_reach_the_callback_and_the_flag_cancels() {
        let seen = Mutex::new(Vec::new());
        let record = |done, total| seen.lock().unwrap().push((done, total));
        let cancel = AtomicBool::new(false);
        let job = Job::new(&record, &cancel);
        job.report(0, 3);
        job.report(3, 3);
        assert!(!job.is_cancelled());
        cancel.store(true, Ordering::Relaxed);
        assert!(job.is_cancelled());
        assert_eq!(*seen.lock().unwrap(), [(0, 3), (3, 3)]);
    }

    #[test]
    fn an_unwatched_job_is_never_cancelled() {
        let job = Job::unwatched();
        job.report(1, 2);
        assert!(!job.is_cancelled());
    }

    #[test]
    fn a_reporting_job_reports_and_is_not_cancelled_without_an_interrupt() {
        let seen = Mutex::new(Vec::new());
        let record = |done, total| seen.lock().unwrap().push((done, total));
        let job = Job::reporting(&record);
        job.report(2, 5);
        assert!(!job.is_cancelled());
        assert_eq!(*seen.lock().unwrap(), [(2, 5)]);
    }
}
