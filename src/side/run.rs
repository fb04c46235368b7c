//! Journaled runs of a range of groups: a whole reconstruction or one shard, resumable after a kill.

use std::ops::Range;
use std::path::Path;
use std::sync::atomic::AtomicBool;

use super::journal::{Journal, Resumed, TornTail};
use super::record::Record;
use super::{RunIdentity, SideError};
use crate::engine::{EngineError, GroupOutcome, GroupStream, SlopeEntry, SlopeMode, run_groups};
use crate::io::Scan;
use crate::pipeline::PipelineParams;
use crate::pipeline::slope_reference::{SLOPE_HISTORY, SlopeHistory};
use crate::pipeline::walls::WallSide;

/// Every wall side a slope history is kept for.
const SIDES: [WallSide; 2] = [WallSide::Left, WallSide::Right];

/// A slope history as a journal keeps it: per wall side, the medians it holds, oldest first.
pub type SlopeSeed = Vec<(WallSide, Vec<f64>)>;

/// The history that recording `entries` (group by group, oldest first) leaves: per side, its
/// last [`SLOPE_HISTORY`] medians.
#[must_use]
pub fn seed_of<'a>(entries: impl Iterator<Item = &'a [SlopeEntry]>) -> SlopeSeed {
    let mut seed: SlopeSeed = Vec::new();
    for group in entries {
        for &(side, m) in group {
            let idx = match seed.iter().position(|(s, _)| *s == side) {
                Some(i) => i,
                None => {
                    seed.push((side, Vec::new()));
                    seed.len() - 1
                }
            };
            if let Some((_, values)) = seed.get_mut(idx) {
                values.push(m);
            }
        }
    }
    for (_, values) in &mut seed {
        let drop = values.len().saturating_sub(SLOPE_HISTORY);
        values.drain(..drop);
    }
    seed
}

/// The history holding `seed`.
#[must_use]
pub fn history_from(seed: &SlopeSeed) -> SlopeHistory {
    let mut h = SlopeHistory::default();
    for (side, values) in seed {
        for &v in values {
            h.push(&[(*side, v)]);
        }
    }
    h
}

/// Medians held by the wall side with the fewest.
fn shortest_side(seed: &SlopeSeed) -> usize {
    SIDES
        .iter()
        .map(|side| {
            seed.iter()
                .find(|(s, _)| s == side)
                .map_or(0, |(_, h)| h.len())
        })
        .min()
        .unwrap_or(0)
}

/// Fewest groups run in each further step back when the groups before a shard left its slope
/// history short (failed groups, a wall not found).
const CONTEXT_STEP_MIN_GROUPS: usize = 8;

/// A run of a range of groups, journaled.
#[derive(Debug)]
pub struct RangeRun<'a> {
    /// The scan.
    pub scan: &'a Scan,
    /// The params.
    pub params: &'a PipelineParams,
    /// Unreadable groups become gaps.
    pub keep_going: bool,
    /// The groups to run.
    pub range: Range<usize>,
    /// A shard: rebuild the slope history of the groups before `range` first. A whole run
    /// starts with none, as one process does.
    pub shard: bool,
    /// The journal file.
    pub journal: &'a Path,
    /// What the journal belongs to.
    pub identity: RunIdentity,
    /// Continue from the journal if there is one.
    pub resume: bool,
    /// Discard a journal left by an interrupted run instead of refusing.
    pub force: bool,
}

/// What a journaled run gave (its groups went to the caller's sink as they finished).
#[derive(Debug)]
pub struct RangeResult {
    /// Groups of the range handed to the sink, in order (those read back from the journal
    /// first).
    pub groups: usize,
    /// Groups read back from the journal.
    pub resumed: usize,
    /// Groups before the range run for the slope history (0 when resumed past that point).
    pub context_groups: usize,
    /// The journal, still on disk: remove it once the output is in place.
    pub journal: Journal,
}

/// Events a journaled run reports.
#[derive(Clone, Debug)]
pub enum RunEvent<'a> {
    /// The journal held finished groups; the run continues after them.
    Resumed {
        /// Groups read back.
        groups: usize,
        /// The journal's run had another `[dsp]` table: this run finishes with its own.
        other_finish: bool,
        /// The torn last record a run stopped while writing it left, cut off the journal
        /// (its group runs again).
        torn_tail: Option<TornTail>,
    },
    /// Running groups before the range for the slope history.
    Context(Range<usize>),
    /// A group before the range finished (its slope entries kept, nothing else).
    ContextGroup(usize),
    /// The range's own groups (after those read back) start running now: what came before
    /// (the groups before the range) is not their time.
    Groups(Range<usize>),
    /// A group of the range finished (`done` of `total`, counting resumed ones).
    Group {
        /// The group.
        outcome: &'a GroupOutcome,
        /// Groups of the range finished.
        done: usize,
        /// Groups in the range.
        total: usize,
    },
}

/// Runs `run`, journaling every finished group and handing it to `sink` in group order (the
/// journal's groups first), so the caller keeps only what it needs of each; with `resume` it
/// continues a journal left by the same run (and refuses one from another).
///
/// # Errors
/// [`SideError`]: a journal there without `--resume` or `--force`, a journal from another
/// run, or the engine's error.
pub fn run_range(
    run: &RangeRun<'_>,
    on_event: &mut dyn FnMut(RunEvent<'_>),
    sink: &mut dyn FnMut(GroupOutcome),
    cancel: &AtomicBool,
) -> Result<RangeResult, SideError> {
    run.params.validate_for_clip().map_err(EngineError::from)?;
    let exists = run.journal.exists();
    let resumed = if exists && run.resume {
        Journal::resume(run.journal, &run.identity)?
    } else if exists && !run.force {
        return Err(SideError::refused(
            "an interrupted run's journal is here: continue it with --resume, \
             or start over with --force",
            run.journal,
        ));
    } else {
        Resumed {
            journal: Journal::create(run.journal, &run.identity)?,
            seed: None,
            groups: Vec::new(),
            other_finish: false,
            torn_tail: None,
        }
    };
    let Resumed {
        mut journal,
        seed,
        groups: resumed_groups,
        other_finish,
        torn_tail,
    } = resumed;
    let resumed = resumed_groups.len();
    if resumed > 0 || seed.is_some() || torn_tail.is_some() {
        on_event(RunEvent::Resumed {
            groups: resumed,
            other_finish,
            torn_tail,
        });
    }
    let mut context_groups = 0;
    let mut slopes = if run.shard {
        let seed = match seed {
            Some(h) => h,
            None => {
                let (s, n) = seed_before(run, on_event, cancel)?;
                context_groups = n;
                journal.append(&Record::Seed(s.clone()))?;
                s
            }
        };
        history_from(&seed)
    } else {
        SlopeHistory::default()
    };
    for g in resumed_groups {
        slopes.push(&g.slopes);
        sink(g);
    }
    let mut done = resumed;
    let total = run.range.len();
    let next = run.range.start + resumed;
    on_event(RunEvent::Groups(next..run.range.end));
    run_groups(
        &GroupStream {
            scan: run.scan,
            params: run.params,
            keep_going: run.keep_going,
            mode: SlopeMode::Check,
        },
        next..run.range.end,
        &mut slopes,
        cancel,
        &mut |outcome| {
            journal
                .append(&Record::Group(outcome.clone()))
                .map_err(|e| match e {
                    // The engine's callback speaks EngineError; the journal's error already
                    // names its file, and is the output's, not the scan's.
                    SideError::Load(load) => EngineError::Output(load),
                    SideError::Engine(engine) => engine,
                    SideError::Refused { problem, path } => {
                        EngineError::Output(crate::io::LoadError::Io { problem, path })
                    }
                })?;
            done += 1;
            on_event(RunEvent::Group {
                outcome: &outcome,
                done,
                total,
            });
            sink(outcome);
            Ok(())
        },
    )?;
    journal.sync()?;
    Ok(RangeResult {
        groups: done,
        resumed,
        context_groups,
        journal,
    })
}

/// The slope history a one-process run holds when it reaches `run.range.start`, rebuilt by
/// running groups before it for their entries alone. A group's entries depend on its own
/// frames only, so the last [`SLOPE_HISTORY`] medians per wall side are the same whichever
/// group this starts from: it runs the [`SLOPE_HISTORY`] groups before the range, then steps
/// further back while a wall side holds fewer (failed groups, a wall not found), down to
/// group 0 if need be. Returns the history and how many groups it ran.
///
/// # Errors
/// The engine's error for a group before the range (as the one-process run would fail there).
pub fn seed_before(
    run: &RangeRun<'_>,
    on_event: &mut dyn FnMut(RunEvent<'_>),
    cancel: &AtomicBool,
) -> Result<(SlopeSeed, usize), SideError> {
    let start = run.range.start;
    if start == 0 || run.params.orientation.max_wall_slope_change <= 0.0 {
        return Ok((Vec::new(), 0));
    }
    // Entries per group, one block per step back (the latest block first).
    let mut blocks: Vec<Vec<Vec<SlopeEntry>>> = Vec::new();
    let mut lo = start;
    let mut step = SLOPE_HISTORY;
    loop {
        let block_lo = lo.saturating_sub(step);
        on_event(RunEvent::Context(block_lo..lo));
        let mut block = Vec::with_capacity(lo - block_lo);
        let mut scratch = SlopeHistory::default();
        run_groups(
            &GroupStream {
                scan: run.scan,
                params: run.params,
                keep_going: run.keep_going,
                mode: SlopeMode::RecordOnly,
            },
            block_lo..lo,
            &mut scratch,
            cancel,
            &mut |o| {
                on_event(RunEvent::ContextGroup(o.group));
                block.push(o.slopes);
                Ok(())
            },
        )?;
        blocks.push(block);
        lo = block_lo;
        let seed = seed_of(blocks.iter().rev().flatten().map(Vec::as_slice));
        let short = shortest_side(&seed);
        if lo == 0 || short >= SLOPE_HISTORY {
            return Ok((seed, start - lo));
        }
        step = CONTEXT_STEP_MIN_GROUPS.max(SLOPE_HISTORY - short);
    }
}
