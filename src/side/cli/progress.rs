//! Terminal progress of a journaled run: the bar or JSON lines, the groups before a shard apart from its own, and what a run stopped before its first group was doing.

use std::ops::Range;
use std::time::Instant;

use indicatif::ProgressBar;

use super::{RunProgress, json_line};
use crate::cli::{ReconstructArgs, progress_bar};
use crate::side::run::RunEvent;

/// Terminal progress: an indicatif bar (groups/s, ETA), or with `--progress-json` one JSON
/// line per event on stdout. The groups before a shard (run for its slope history) have the
/// bar to themselves while they run; the range's rate and ETA count from when its own groups
/// start, so the time before them does not pass for theirs.
pub(super) struct ProgressOut {
    /// The bar (hidden with --quiet or --progress-json).
    pub(super) bar: ProgressBar,
    json: bool,
    quiet: bool,
    started: Instant,
    /// When the range's own groups started (None while the groups before it run).
    groups_started: Option<Instant>,
    total: usize,
    resumed: usize,
    /// Groups of the range finished, those read back included.
    done: usize,
    /// Groups before the range asked for, and run, for the slope history; the span they cover.
    context: usize,
    context_done: usize,
    context_span: Option<Range<usize>>,
}

impl ProgressOut {
    pub(super) fn new(total: usize, args: &ReconstructArgs) -> Self {
        let json = args.side.progress_json;
        Self {
            bar: progress_bar(total, args.quiet || json),
            json,
            quiet: args.quiet,
            started: Instant::now(),
            groups_started: None,
            total,
            resumed: 0,
            done: 0,
            context: 0,
            context_done: 0,
            context_span: None,
        }
    }

    /// What a run that Ctrl-C stopped before any group of its range finished was doing, and
    /// how to go on, after `e` (the engine's "cancelled"): None when groups finished (the
    /// failure's line says where they are kept).
    pub(super) fn cancelled_early(&self, e: &crate::side::SideError) -> Option<String> {
        use crate::engine::EngineError;
        use crate::side::SideError;
        if !matches!(e, SideError::Engine(EngineError::Cancelled)) || self.done + self.resumed > 0 {
            return None;
        }
        let secs = self.started.elapsed().as_secs_f64();
        Some(match (&self.context_span, self.groups_started) {
            (Some(span), None) => format!(
                "{e} while running groups {}..{} before the shard, which only rebuild the slope \
                 history its first group is checked against ({} of {} run in {secs:.1} s; none \
                 of the shard's own groups had begun, so there is nothing to keep): the same \
                 command starts the shard again, those groups first",
                span.start, span.end, self.context_done, self.context
            ),
            _ => format!(
                "{e} before its first group finished (nothing to keep): the same command starts \
                 it again"
            ),
        })
    }

    fn line(&self, value: &serde_json::Value) {
        json_line(value);
    }

    fn note(&self, text: &str) {
        if self.json || !self.quiet {
            self.bar.suspend(|| crate::tell!("{text}"));
        }
    }

    pub(super) fn event(&mut self, event: RunEvent<'_>) {
        match event {
            RunEvent::Resumed {
                groups: n,
                other_finish,
                torn_tail,
            } => {
                self.resumed = n;
                self.bar.set_position(n as u64);
                self.bar.reset_eta();
                // Said even with --quiet: what became of the journal's bytes is the archive's
                // business, and this is the one line about it.
                if let Some(t) = torn_tail {
                    self.bar.suspend(|| {
                        crate::tell!(
                            "the journal's last record ({} bytes at byte {}) is incomplete, as a \
                             run stopped while writing it leaves it: dropped, and its group runs \
                             again",
                            t.bytes,
                            t.offset
                        );
                    });
                }
                let finish = if other_finish {
                    " (its run had another [dsp] table, which only the finish reads: this run \
                     finishes with its own)"
                } else {
                    ""
                };
                self.note(&format!(
                    "resuming after {n} groups read back from the journal{finish}"
                ));
                if self.json {
                    self.line(&serde_json::json!({
                        "event": "resumed",
                        "groups": n,
                        "other_finish": other_finish,
                        "torn_tail_bytes": torn_tail.map(|t| t.bytes),
                    }));
                }
            }
            RunEvent::Context(r) => {
                self.context += r.len();
                self.context_span = Some(match &self.context_span {
                    Some(span) => r.start.min(span.start)..r.end.max(span.end),
                    None => r.clone(),
                });
                self.note(&format!(
                    "running groups {}..{} for the slope history before the shard",
                    r.start, r.end
                ));
                self.bar.set_length(r.len() as u64);
                self.bar.set_position(0);
                self.bar.reset_eta();
                self.bar
                    .set_message(format!("groups before the shard ({}..{})", r.start, r.end));
                if self.json {
                    self.line(&serde_json::json!({"event": "context", "first_group": r.start, "end_group": r.end}));
                }
            }
            RunEvent::ContextGroup(_) => {
                self.context_done += 1;
                self.bar.inc(1);
            }
            RunEvent::Groups(_) => {
                self.groups_started = Some(Instant::now());
                self.bar.set_length(self.total as u64);
                self.bar.set_position(self.resumed as u64);
                self.bar.reset_eta();
                self.bar.set_message("groups");
            }
            RunEvent::Group {
                outcome,
                done,
                total,
            } => {
                self.done = done;
                self.bar.set_position(done as u64);
                if self.json {
                    let elapsed = self.started.elapsed().as_secs_f64();
                    // The rate of the range's own groups, over their own time.
                    let own = self
                        .groups_started
                        .map_or(elapsed, |t| t.elapsed().as_secs_f64());
                    let run = (done - self.resumed) as f64;
                    let rate = if own > 0.0 { run / own } else { 0.0 };
                    let eta = if rate > 0.0 {
                        (total - done) as f64 / rate
                    } else {
                        0.0
                    };
                    self.line(&serde_json::json!({
                        "event": "group", "group": outcome.group, "done": done, "total": total,
                        "elapsed_secs": elapsed, "groups_per_sec": rate, "eta_secs": eta,
                        "failed": outcome.signal.is_none(),
                    }));
                }
            }
        }
    }

    pub(super) fn summary(&self, groups_run: usize) -> RunProgress {
        self.bar.finish_and_clear();
        let elapsed = self.started.elapsed().as_secs_f64();
        let n = groups_run + self.context;
        RunProgress {
            groups_run,
            resumed_groups: self.resumed,
            context_groups: self.context,
            elapsed_secs: elapsed,
            groups_per_sec: if elapsed > 0.0 {
                n as f64 / elapsed
            } else {
                0.0
            },
        }
    }
}
