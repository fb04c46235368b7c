//! Journaled runs of a range of groups: a whole reconstruction or one shard, resumable after a kill.

use std::ops::Range;
use std::path::Path;
use std::sync::atomic::AtomicBool;

use super::journal::Journal;
use super::record::Record;
use super::{RunIdentity, SideError};
use crate::engine::slope_reference::SLOPE_HISTORY;
use crate::engine::{EngineError, GroupOutcome, SlopeMode, SlopeReference, run_groups};
use crate::io::Scan;
use crate::pipeline::PipelineParams;

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

/// What a journaled run gave.
#[derive(Debug)]
pub struct RangeResult {
    /// Every group of the range, in order (those read back from the journal first).
    pub groups: Vec<GroupOutcome>,
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
    /// The journal held this many finished groups; the run continues after them.
    Resumed(usize),
    /// Running groups before the range for the slope history.
    Context(Range<usize>),
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

/// Runs `run`, journaling every finished group; with `resume` it continues a journal left by
/// the same run (and refuses one from another).
///
/// # Errors
/// [`SideError`]: a journal there without `--resume` or `--force`, a journal from another
/// run, or the engine's error.
pub fn run_range(
    run: &RangeRun<'_>,
    on_event: &mut dyn FnMut(RunEvent<'_>),
    cancel: &AtomicBool,
) -> Result<RangeResult, SideError> {
    run.params.validate().map_err(EngineError::from)?;
    let exists = run.journal.exists();
    let (mut journal, records) = if exists && run.resume {
        Journal::resume(run.journal, &run.identity)?
    } else if exists && !run.force {
        return Err(SideError::refused(
            "an interrupted run's journal is here: continue it with --resume, \
             or start over with --force",
            run.journal,
        ));
    } else {
        (Journal::create(run.journal, &run.identity)?, Vec::new())
    };
    let mut seed = None;
    let mut groups: Vec<GroupOutcome> = Vec::with_capacity(run.range.len());
    for record in records {
        match record {
            Record::Seed(h) if groups.is_empty() => seed = Some(h),
            Record::Group(g) if g.group == run.range.start + groups.len() => groups.push(g),
            _ => break,
        }
    }
    let resumed = groups.len();
    if resumed > 0 || seed.is_some() {
        on_event(RunEvent::Resumed(resumed));
    }
    let mut slopes = SlopeReference::default();
    let mut context_groups = 0;
    if run.shard {
        slopes = match seed {
            Some(h) => SlopeReference::from_history(&h),
            None => {
                let (s, n) = seed_before(run, on_event, cancel)?;
                context_groups = n;
                journal.append(&Record::Seed(s.history()))?;
                s
            }
        };
    }
    for g in &groups {
        slopes.record(&g.slopes);
    }
    let total = run.range.len();
    let next = run.range.start + resumed;
    run_groups(
        run.scan,
        next..run.range.end,
        run.params,
        run.keep_going,
        &mut slopes,
        SlopeMode::Check,
        cancel,
        &mut |outcome| {
            journal
                .append(&Record::Group(outcome.clone()))
                .map_err(|e| {
                    EngineError::Load(crate::io::LoadError::Io {
                        problem: e.to_string(),
                        path: run.journal.to_path_buf(),
                    })
                })?;
            groups.push(outcome);
            if let Some(o) = groups.last() {
                on_event(RunEvent::Group {
                    outcome: o,
                    done: groups.len(),
                    total,
                });
            }
            Ok(())
        },
    )?;
    journal.sync()?;
    Ok(RangeResult {
        groups,
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
/// group 0 if need be. Returns the reference and how many groups it ran.
///
/// # Errors
/// The engine's error for a group before the range (as the one-process run would fail there).
pub fn seed_before(
    run: &RangeRun<'_>,
    on_event: &mut dyn FnMut(RunEvent<'_>),
    cancel: &AtomicBool,
) -> Result<(SlopeReference, usize), SideError> {
    let start = run.range.start;
    if start == 0 || run.params.orientation.max_wall_slope_change <= 0.0 {
        return Ok((SlopeReference::default(), 0));
    }
    // Entries per group, earliest block first once done.
    let mut blocks: Vec<Vec<GroupOutcome>> = Vec::new();
    let mut lo = start;
    let mut step = SLOPE_HISTORY;
    loop {
        let block_lo = lo.saturating_sub(step);
        on_event(RunEvent::Context(block_lo..lo));
        let mut block = Vec::with_capacity(lo - block_lo);
        let mut scratch = SlopeReference::default();
        run_groups(
            run.scan,
            block_lo..lo,
            run.params,
            run.keep_going,
            &mut scratch,
            SlopeMode::RecordOnly,
            cancel,
            &mut |o| {
                block.push(o);
                Ok(())
            },
        )?;
        blocks.push(block);
        lo = block_lo;
        let mut reference = SlopeReference::default();
        for g in blocks.iter().rev().flatten() {
            reference.record(&g.slopes);
        }
        if lo == 0 || reference.is_settled() {
            let ran = start - lo;
            return Ok((reference, ran));
        }
        step = CONTEXT_STEP_MIN_GROUPS.max(SLOPE_HISTORY - shortest_side(&reference));
    }
}

/// Medians held by the wall side with the fewest.
fn shortest_side(reference: &SlopeReference) -> usize {
    let history = reference.history();
    [
        crate::pipeline::walls::WallSide::Left,
        crate::pipeline::walls::WallSide::Right,
    ]
    .iter()
    .map(|side| {
        history
            .iter()
            .find(|(s, _)| s == side)
            .map_or(0, |(_, h)| h.len())
    })
    .min()
    .unwrap_or(0)
}
