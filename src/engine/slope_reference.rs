//! The clip-level wall-slope reference: each group's fits checked against the median slope of the groups before it.

use std::collections::VecDeque;
use std::sync::Arc;

use crate::pipeline::orientation::{Orientation, median_wall_slope, reject_slopes_against};
use crate::pipeline::walls::WallSide;
use crate::pipeline::{GroupInput, PipelineParams, Stage, StageCache, StageError};

/// Groups needed before their median is used as a reference.
pub const SLOPE_REFERENCE_MIN_GROUPS: usize = 8;
/// Group medians the reference looks back over, per wall side.
pub const SLOPE_HISTORY: usize = 64;
/// Share of those groups that must agree with their median for it to be used.
const SLOPE_AGREEMENT: f64 = 0.6;
/// Every wall side a history is kept for.
const SIDES: [WallSide; 2] = [WallSide::Left, WallSide::Right];

/// What one group adds to the history: per wall it measured, its own median |b| (None when it
/// has too few fits). It depends on that group alone, never on the groups before it.
pub type SlopeEntry = (WallSide, Option<f64>);

/// The clip's recent wall slopes: per wall side, the median |b| of the last groups' fits.
///
/// The orientation stage rejects fits whose cross-groove slope strays from their group's
/// median; a group whose fits are mostly wrong (a flaked chunk longer than half a group) passes
/// that check. Groups run in order, so the engine also checks each group against the median of
/// the [`SLOPE_HISTORY`] group medians before it, once there are [`SLOPE_REFERENCE_MIN_GROUPS`]
/// and most of them agree with that median (a clip that starts on damage sets no reference),
/// and reruns the sound stage when that rejects fits.
///
/// A shard that starts inside a scan gets the same history by [`SlopeReference::record`]ing the
/// entries of the groups before its range ([`SlopeReference::is_settled`] says when enough are
/// in); a resumed run replays the entries its journal kept.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SlopeReference {
    medians: Vec<(WallSide, VecDeque<f64>)>,
}

impl SlopeReference {
    /// Checks the group in `cache` against the reference (when there is one), turning strays
    /// into gaps and rerunning the sound stage if any were, then adds the group's own medians.
    ///
    /// # Errors
    /// The sound stage's error on that rerun.
    pub fn check(
        &mut self,
        cache: &mut StageCache,
        input: &GroupInput,
        params: &PipelineParams,
    ) -> Result<(), StageError> {
        let max_change = params.orientation.max_wall_slope_change;
        let Some(out) = cache.orientation.as_mut() else {
            return Ok(());
        };
        if max_change <= 0.0 {
            return Ok(());
        }
        // The engine's cache holds the only reference, so this does not copy the output.
        let orientation = &mut Arc::make_mut(out).orientation;
        let rejected = self.apply(orientation, max_change);
        if rejected > 0 {
            orientation.rejected_fits += rejected;
            cache.run_from(Stage::Sound, input, params, &mut |_, _| true)?;
        }
        Ok(())
    }

    /// The entries [`SlopeReference::check`] adds for the group in `cache` (none when the
    /// check is off or the group has no orientation). Computed before the check changes it.
    #[must_use]
    pub fn entries_of(cache: &StageCache, params: &PipelineParams) -> Vec<SlopeEntry> {
        if params.orientation.max_wall_slope_change <= 0.0 {
            return Vec::new();
        }
        cache
            .orientation
            .as_ref()
            .map(|o| {
                o.orientation
                    .walls
                    .iter()
                    .map(|w| (w.side, median_wall_slope(&w.samples)))
                    .collect()
            })
            .unwrap_or_default()
    }

    /// Adds a group's entries without checking anything (a group before a shard's range, or
    /// one replayed from a journal).
    pub fn record(&mut self, entries: &[SlopeEntry]) {
        for &(side, own) in entries {
            self.push(side, own);
        }
    }

    /// True when every wall side holds [`SLOPE_HISTORY`] medians: then groups further back
    /// cannot change the reference.
    #[must_use]
    pub fn is_settled(&self) -> bool {
        SIDES.iter().all(|side| {
            self.medians
                .iter()
                .find(|(s, _)| s == side)
                .is_some_and(|(_, h)| h.len() >= SLOPE_HISTORY)
        })
    }

    /// The history per wall side, oldest first (for a journal).
    #[must_use]
    pub fn history(&self) -> Vec<(WallSide, Vec<f64>)> {
        self.medians
            .iter()
            .map(|(s, h)| (*s, h.iter().copied().collect()))
            .collect()
    }

    /// A reference holding `history` (as [`SlopeReference::history`] gave it).
    #[must_use]
    pub fn from_history(history: &[(WallSide, Vec<f64>)]) -> Self {
        let mut r = Self::default();
        for (side, values) in history {
            let h = r.history_mut(*side);
            for &v in values.iter().rev().take(SLOPE_HISTORY).rev() {
                h.push_back(v);
            }
        }
        r
    }

    fn history_mut(&mut self, side: WallSide) -> &mut VecDeque<f64> {
        let idx = match self.medians.iter().position(|(s, _)| *s == side) {
            Some(i) => i,
            None => {
                self.medians.push((side, VecDeque::new()));
                self.medians.len() - 1
            }
        };
        &mut self.medians[idx].1
    }

    fn push(&mut self, side: WallSide, own: Option<f64>) {
        let history = self.history_mut(side);
        if let Some(m) = own {
            if history.len() == SLOPE_HISTORY {
                history.pop_front();
            }
            history.push_back(m);
        }
    }

    /// Checks one group's walls against the reference (when there is one), turning strays into
    /// gaps, then adds the group's own median to the history. Returns the fits rejected.
    fn apply(&mut self, orientation: &mut Orientation, max_change: f64) -> usize {
        let mut rejected = 0;
        for wall in &mut orientation.walls {
            let own = median_wall_slope(&wall.samples);
            if let Some(r) = agreed_median(self.history_mut(wall.side), max_change) {
                rejected += reject_slopes_against(&mut wall.samples, r, max_change);
            }
            self.push(wall.side, own);
        }
        rejected
    }
}

/// The median of `history` when it holds enough groups and most lie within `max_change` of it.
fn agreed_median(history: &VecDeque<f64>, max_change: f64) -> Option<f64> {
    if history.len() < SLOPE_REFERENCE_MIN_GROUPS {
        return None;
    }
    let m = crate::pipeline::median(history.iter().copied().collect())?;
    let agree = history
        .iter()
        .filter(|&&v| (v - m).abs() <= max_change * m)
        .count();
    (agree as f64 >= SLOPE_AGREEMENT * history.len() as f64).then_some(m)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;
    use crate::image::Image;
    use crate::pipeline::orientation::{OrientationSample, WallOrientation, test_fit};

    fn group(b: f64) -> Orientation {
        let fit = test_fit(0.01, b);
        let samples = (0..10)
            .map(|i| OrientationSample {
                x_px: i as f32,
                tan_theta: 0.01,
                fit: Some(fit),
            })
            .collect();
        Orientation {
            walls: vec![WallOrientation {
                side: WallSide::Right,
                samples,
            }],
            weight_map: Image::zeros(1, 1),
            outlier_fraction: 0.0,
            rejected_fits: 0,
        }
    }

    #[test]
    fn a_group_whose_wall_slope_strays_from_the_clip_becomes_gaps() {
        let mut r = SlopeReference::default();
        // The first groups set the reference; nothing is rejected before there are eight.
        for k in 0..SLOPE_REFERENCE_MIN_GROUPS {
            let b = [-0.38, -0.37, -0.39][k % 3];
            assert_eq!(r.apply(&mut group(b), 0.25), 0);
        }
        // A group locked onto a flaked chunk: its own median agrees with its fits, the clip's
        // does not.
        let mut bad = group(-1.0);
        assert_eq!(r.apply(&mut bad, 0.25), 10);
        assert!(bad.walls[0].samples.iter().all(|s| s.fit.is_none()));
        // Good groups still pass.
        assert_eq!(r.apply(&mut group(-0.4), 0.25), 0);
    }

    #[test]
    fn a_clip_that_starts_on_damage_sets_no_reference() {
        // Half the first groups are wrong in different ways: no median is agreed on, so no
        // group is judged by it.
        let mut r = SlopeReference::default();
        for b in [-1.0, -0.38, -0.6, -0.37, -1.4, -0.39, -0.8, -0.38] {
            assert_eq!(r.apply(&mut group(b), 0.25), 0);
        }
        assert_eq!(r.apply(&mut group(-0.38), 0.25), 0);
        assert_eq!(r.apply(&mut group(-1.0), 0.25), 0);
    }

    #[test]
    fn recorded_entries_give_the_same_history_as_checked_groups() {
        let (mut checked, mut recorded) = (SlopeReference::default(), SlopeReference::default());
        for k in 0..100 {
            let mut o = group(-0.3 - 0.001 * f64::from(k % 7));
            let entries: Vec<SlopeEntry> = o
                .walls
                .iter()
                .map(|w| (w.side, median_wall_slope(&w.samples)))
                .collect();
            checked.apply(&mut o, 0.25);
            recorded.record(&entries);
        }
        assert_eq!(checked, recorded);
        assert_eq!(SlopeReference::from_history(&recorded.history()), recorded);
        // Only the right wall was measured: the left has no history, so not settled.
        assert!(!recorded.is_settled());
        recorded.record(&vec![(WallSide::Left, Some(0.3)); SLOPE_HISTORY]);
        assert!(recorded.is_settled());
    }
}
