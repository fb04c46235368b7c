//! Undo/redo of parameter changes; a burst of edits to one stage (a slider drag) is one step.

use std::time::{Duration, Instant};

use crate::pipeline::{PipelineParams, Stage};

/// Edits to the same stage closer together than this merge into one undo step.
pub const COALESCE_WINDOW: Duration = Duration::from_millis(600);

/// Most undo steps kept.
pub const MAX_UNDO: usize = 200;

/// Undo and redo stacks of whole parameter sets.
#[derive(Clone, Debug, Default)]
pub struct History {
    undo: Vec<PipelineParams>,
    redo: Vec<PipelineParams>,
    last_edit: Option<(Instant, Stage)>,
}

impl History {
    /// Records that `before` was replaced by a change to `stage` at `now`.
    pub fn record(&mut self, before: &PipelineParams, stage: Option<Stage>, now: Instant) {
        let merge = matches!(
            (self.last_edit, stage),
            (Some((t, s)), Some(st)) if s == st && now.saturating_duration_since(t) < COALESCE_WINDOW
        );
        if !merge {
            self.undo.push(before.clone());
            if self.undo.len() > MAX_UNDO {
                self.undo.remove(0);
            }
        }
        self.redo.clear();
        self.last_edit = stage.map(|s| (now, s));
    }

    /// Ends the current burst, so the next edit is its own step.
    pub fn seal(&mut self) {
        self.last_edit = None;
    }

    /// The params to go back to from `current` (None when there is nothing to undo).
    pub fn undo(&mut self, current: &PipelineParams) -> Option<PipelineParams> {
        let prev = self.undo.pop()?;
        self.redo.push(current.clone());
        self.last_edit = None;
        Some(prev)
    }

    /// The params to go forward to from `current` (None when there is nothing to redo).
    pub fn redo(&mut self, current: &PipelineParams) -> Option<PipelineParams> {
        let next = self.redo.pop()?;
        self.undo.push(current.clone());
        self.last_edit = None;
        Some(next)
    }

    /// True when [`History::undo`] would return something.
    #[must_use]
    pub fn can_undo(&self) -> bool {
        !self.undo.is_empty()
    }

    /// True when [`History::redo`] would return something.
    #[must_use]
    pub fn can_redo(&self) -> bool {
        !self.redo.is_empty()
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;

    fn with_lambda(l: f32) -> PipelineParams {
        let mut p = PipelineParams::default();
        p.flow.lambda = l;
        p
    }

    #[test]
    fn drag_burst_is_one_step_and_redo_is_cleared_by_new_edits() {
        let mut h = History::default();
        let t0 = Instant::now();
        h.record(&with_lambda(1.0), Some(Stage::Flow), t0);
        h.record(
            &with_lambda(2.0),
            Some(Stage::Flow),
            t0 + Duration::from_millis(100),
        );
        h.record(
            &with_lambda(3.0),
            Some(Stage::Flow),
            t0 + Duration::from_millis(200),
        );
        let back = h.undo(&with_lambda(4.0)).unwrap();
        assert_eq!(back.flow.lambda, 1.0);
        assert!(!h.can_undo());
        let fwd = h.redo(&back).unwrap();
        assert_eq!(fwd.flow.lambda, 4.0);
        h.undo(&fwd).unwrap();
        h.record(&with_lambda(1.0), Some(Stage::Stripes), t0);
        assert!(!h.can_redo());
    }

    #[test]
    fn edits_to_other_stages_or_after_a_pause_are_separate() {
        let mut h = History::default();
        let t0 = Instant::now();
        h.record(&with_lambda(1.0), Some(Stage::Flow), t0);
        h.record(&with_lambda(2.0), Some(Stage::Stripes), t0);
        h.record(
            &with_lambda(3.0),
            Some(Stage::Stripes),
            t0 + 2 * COALESCE_WINDOW,
        );
        h.seal();
        h.record(
            &with_lambda(4.0),
            Some(Stage::Stripes),
            t0 + 2 * COALESCE_WINDOW,
        );
        let mut cur = with_lambda(5.0);
        let mut seen = Vec::new();
        while let Some(p) = h.undo(&cur) {
            seen.push(p.flow.lambda);
            cur = p;
        }
        assert_eq!(seen, vec![4.0, 3.0, 2.0, 1.0]);
    }
}
