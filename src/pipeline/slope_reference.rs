//! The clip-level wall-slope reference: per wall side, the median cross-groove slope of the groups before this one, an input of the orientation stage.
//!
//! The orientation stage rejects fits whose cross-groove slope |b| strays from their group's
//! median; a group whose fits are mostly wrong (a flaked chunk longer than half a group) passes
//! that check. Groups of a clip run in order, so the engine keeps the medians of the
//! [`SLOPE_HISTORY`] groups before each one ([`SlopeHistory`]) and hands the orientation stage
//! their median ([`SlopeReference`]) once there are [`SLOPE_REFERENCE_MIN_GROUPS`] and most of
//! them agree with it (a clip that starts on damage sets no reference). The reference is part
//! of the orientation stage's cache key, so a result made with one is never shown as made
//! without it.

use std::collections::VecDeque;

use super::orientation::{Orientation, reject_slopes_against};
use super::walls::WallSide;

/// Groups needed before their median is used as a reference.
pub const SLOPE_REFERENCE_MIN_GROUPS: usize = 8;
/// Groups the reference looks back over.
pub const SLOPE_HISTORY: usize = 64;
/// Share of those groups that must agree with their median for it to be used.
pub const SLOPE_AGREEMENT: f64 = 0.6;

/// Per wall side, the agreed median |b| of the groups before this one (sides without an agreed
/// median are absent: their fits are not checked against the clip).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SlopeReference {
    /// (side, median |b|), at most one entry per side.
    pub sides: Vec<(WallSide, f64)>,
}

impl SlopeReference {
    /// The reference median for `side`, if there is one.
    #[must_use]
    pub fn get(&self, side: WallSide) -> Option<f64> {
        self.sides.iter().find(|(s, _)| *s == side).map(|&(_, m)| m)
    }
}

/// Each wall side's own median |b| of the last [`SLOPE_HISTORY`] groups, oldest first.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SlopeHistory {
    medians: Vec<(WallSide, VecDeque<f64>)>,
}

impl SlopeHistory {
    /// The reference for the next group: each side whose history holds enough groups that
    /// mostly lie within `max_change` (relative) of their median.
    #[must_use]
    pub fn reference(&self, max_change: f64) -> SlopeReference {
        SlopeReference {
            sides: self
                .medians
                .iter()
                .filter_map(|(side, h)| agreed_median(h, max_change).map(|m| (*side, m)))
                .collect(),
        }
    }

    /// Adds one group's own medians (per side, from its fits before the clip check).
    pub fn push(&mut self, own: &[(WallSide, f64)]) {
        for &(side, m) in own {
            let history = match self.medians.iter().position(|(s, _)| *s == side) {
                Some(i) => &mut self.medians[i].1,
                None => {
                    self.medians.push((side, VecDeque::new()));
                    let last = self.medians.len() - 1;
                    &mut self.medians[last].1
                }
            };
            if history.len() == SLOPE_HISTORY {
                history.pop_front();
            }
            history.push_back(m);
        }
    }
}

/// Turns every fit of `orientation` whose |b| strays from its wall side's `reference` by more
/// than `max_change` (relative) into a gap, counting them in `rejected_fits`; returns how many.
pub fn check_against(
    orientation: &mut Orientation,
    reference: &SlopeReference,
    max_change: f64,
) -> usize {
    if max_change <= 0.0 {
        return 0;
    }
    let mut rejected = 0;
    for wall in &mut orientation.walls {
        if let Some(m) = reference.get(wall.side) {
            rejected += reject_slopes_against(&mut wall.samples, m, max_change);
        }
    }
    orientation.rejected_fits += rejected;
    rejected
}

/// The median of `history` when it holds enough groups and most lie within `max_change` of it.
fn agreed_median(history: &VecDeque<f64>, max_change: f64) -> Option<f64> {
    if history.len() < SLOPE_REFERENCE_MIN_GROUPS {
        return None;
    }
    let m = super::median(history.iter().copied().collect())?;
    let agree = history
        .iter()
        .filter(|&&v| (v - m).abs() <= max_change * m)
        .count();
    (agree as f64 >= SLOPE_AGREEMENT * history.len() as f64).then_some(m)
}

#[cfg(test)]
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
        let mut h = SlopeHistory::default();
        for k in 0..SLOPE_REFERENCE_MIN_GROUPS {
            h.push(&[(WallSide::Right, [0.38, 0.37, 0.39][k % 3_usize])]);
        }
        let reference = h.reference(0.25);
        // A group locked onto a flaked chunk: its own median agrees with its fits, the clip's
        // does not.
        let mut bad = group(-1.0);
        assert_eq!(check_against(&mut bad, &reference, 0.25), 10);
        assert_eq!(bad.rejected_fits, 10);
        assert!(bad.walls[0].samples.iter().all(|s| s.fit.is_none()));
        // Good groups still pass; no check without a slope limit.
        assert_eq!(check_against(&mut group(-0.4), &reference, 0.25), 0);
        assert_eq!(check_against(&mut group(-1.0), &reference, 0.0), 0);
    }

    #[test]
    fn a_reference_needs_enough_agreeing_groups() {
        let mut h = SlopeHistory::default();
        for k in 0..SLOPE_REFERENCE_MIN_GROUPS {
            assert_eq!(h.reference(0.25), SlopeReference::default(), "group {k}");
            h.push(&[(WallSide::Right, [0.38, 0.37, 0.39][k % 3_usize])]);
        }
        assert_eq!(h.reference(0.25).get(WallSide::Right), Some(0.38));
        assert_eq!(h.reference(0.25).get(WallSide::Left), None);
        // A clip that starts on damage: no agreed median.
        let mut h = SlopeHistory::default();
        for b in [1.0, 0.38, 0.6, 0.37, 1.4, 0.39, 0.8, 0.38] {
            h.push(&[(WallSide::Left, b)]);
        }
        assert_eq!(h.reference(0.25).get(WallSide::Left), None);
    }

    #[test]
    fn the_history_keeps_the_last_groups_only() {
        let mut h = SlopeHistory::default();
        for _ in 0..SLOPE_HISTORY {
            h.push(&[(WallSide::Left, 1.0)]);
        }
        for _ in 0..SLOPE_HISTORY {
            h.push(&[(WallSide::Left, 0.5)]);
        }
        assert_eq!(h.reference(0.1).get(WallSide::Left), Some(0.5));
    }
}
