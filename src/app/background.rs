//! One piece of heavy work on a named thread of its own: it reports progress, can be cancelled,
//! never blocks the UI (dropping the handle only asks it to stop), and a panic in it comes back
//! as an error message instead of taking the workbench down.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, Sender};
use std::thread::JoinHandle;
use std::time::Instant;

/// Messages from the thread.
#[derive(Debug)]
enum Event<P, T> {
    Progress(P),
    Finished(Result<T, String>),
}

/// What the work sees of its handle: where to report progress and whether to stop.
pub struct Reporter<P, T> {
    tx: Sender<Event<P, T>>,
    cancel: Arc<AtomicBool>,
    repaint: Box<dyn Fn() + Send + Sync>,
}

impl<P, T> Reporter<P, T> {
    /// Reports progress (and wakes the UI); returns false once cancel was asked for.
    pub fn report(&self, progress: P) -> bool {
        let _ = self.tx.send(Event::Progress(progress));
        (self.repaint)();
        !self.cancelled()
    }

    /// True once cancel was asked for.
    #[must_use]
    pub fn cancelled(&self) -> bool {
        self.cancel.load(Ordering::Relaxed)
    }

    /// The cancel flag itself (for work that takes one).
    #[must_use]
    pub fn flag(&self) -> &AtomicBool {
        &self.cancel
    }
}

/// Heavy work running in the background.
#[derive(Debug)]
pub struct Background<P, T> {
    cancel: Arc<AtomicBool>,
    rx: Receiver<Event<P, T>>,
    thread: Option<JoinHandle<()>>,
    /// When it started.
    pub started: Instant,
    /// The last progress reported.
    pub progress: P,
}

impl<P: Send + 'static, T: Send + 'static> Background<P, T> {
    /// Runs `work` on a thread named `name`, with `progress` as the progress until the first
    /// report; `repaint` wakes the UI after every report and at the end.
    ///
    /// # Errors
    /// When the thread cannot be started.
    pub fn start(
        name: &str,
        progress: P,
        repaint: Box<dyn Fn() + Send + Sync>,
        work: impl FnOnce(&Reporter<P, T>) -> Result<T, String> + Send + 'static,
    ) -> std::io::Result<Self> {
        let cancel = Arc::new(AtomicBool::new(false));
        let (tx, rx) = mpsc::channel();
        let reporter = Reporter {
            tx,
            cancel: cancel.clone(),
            repaint,
        };
        let what = name.to_string();
        let thread = std::thread::Builder::new()
            .name(name.into())
            .spawn(move || {
                let outcome =
                    std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| work(&reporter)))
                        .unwrap_or_else(|_| Err(format!("{what} panicked (see the log)")));
                let _ = reporter.tx.send(Event::Finished(outcome));
                (reporter.repaint)();
            })?;
        Ok(Self {
            cancel,
            rx,
            thread: Some(thread),
            started: Instant::now(),
            progress,
        })
    }
}

impl<P, T> Background<P, T> {
    /// Asks the work to stop at its next check.
    pub fn cancel(&self) {
        self.cancel.store(true, Ordering::Relaxed);
    }
}

/// Work the UI polls once a frame: it takes the progress reports, then the outcome once the
/// work ended.
pub trait Polled {
    /// What the work ends with.
    type Outcome;
    /// Takes the waiting progress reports; returns the outcome once the work ended.
    fn poll(&mut self) -> Option<Self::Outcome>;
    /// True once cancel was asked for.
    #[must_use]
    fn cancelling(&self) -> bool;
}

impl<P, T> Polled for Background<P, T> {
    type Outcome = Result<T, String>;

    fn poll(&mut self) -> Option<Self::Outcome> {
        while let Ok(ev) = self.rx.try_recv() {
            match ev {
                Event::Progress(p) => self.progress = p,
                Event::Finished(outcome) => {
                    if let Some(t) = self.thread.take() {
                        let _ = t.join();
                    }
                    return Some(outcome);
                }
            }
        }
        None
    }

    fn cancelling(&self) -> bool {
        self.cancel.load(Ordering::Relaxed)
    }
}

/// The outcome of the work in `slot` once it ended, and whether cancel had been asked for;
/// the slot is emptied then. None while it runs or when there is none.
pub fn take_ended<W: Polled>(slot: &mut Option<W>) -> Option<(W::Outcome, bool)> {
    let work = slot.as_mut()?;
    let outcome = work.poll()?;
    let cancelled = work.cancelling();
    *slot = None;
    Some((outcome, cancelled))
}

impl<P, T> Drop for Background<P, T> {
    /// Asks the work to stop and lets the thread finish on its own (never blocks the UI).
    fn drop(&mut self) {
        self.cancel();
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;
    use std::time::Duration;

    fn wait<P, T>(b: &mut Background<P, T>) -> Result<T, String> {
        let t = Instant::now();
        loop {
            if let Some(r) = b.poll() {
                return r;
            }
            assert!(
                t.elapsed() < Duration::from_secs(30),
                "the work never ended"
            );
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    #[test]
    fn progress_arrives_and_the_outcome_follows() {
        let mut b = Background::start("t-progress", 0usize, Box::new(|| {}), |r| {
            for i in 1..=3 {
                r.report(i);
            }
            Ok("done")
        })
        .unwrap();
        assert_eq!(wait(&mut b), Ok("done"));
        assert_eq!(b.progress, 3);
    }

    #[test]
    fn cancel_reaches_the_work_and_a_panic_becomes_an_error() {
        let (go_tx, go_rx) = mpsc::channel::<()>();
        let mut b = Background::start("t-cancel", (), Box::new(|| {}), move |r| {
            go_rx.recv().unwrap();
            if r.report(()) {
                Ok(1)
            } else {
                Err("cancelled".to_string())
            }
        })
        .unwrap();
        b.cancel();
        assert!(b.cancelling());
        go_tx.send(()).unwrap();
        assert_eq!(wait(&mut b), Err("cancelled".to_string()));
        let mut p = Background::<(), ()>::start("t-panic", (), Box::new(|| {}), |_| panic!("boom"))
            .unwrap();
        assert!(wait(&mut p).unwrap_err().contains("t-panic panicked"));
    }
}
