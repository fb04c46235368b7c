//! Stretches of a wall's displacement track that move faster than a groove can, found and solved again from the track around them.
//!
//! The robust combination solves each sample on its own, from a median start over its
//! borders. Where damage takes out or moves most of a sample's borders at once (a dust grain
//! on the bottom corners while a flake moves a land), the start can fall among the wrong
//! borders and the solve follows them: the track leaves the groove by tens of µm for a few
//! samples, and the differentiator turns each such excursion into a click far louder than the
//! sound, which the output's normalisation then makes the loudest thing in the clip.
//!
//! A groove cannot do that. The cutting stylus moves the groove sideways by at most
//! `max_slope` µm per µm along it (a slope of 1 is a 45° wall of the modulation itself; a loud
//! record's is about 0.1, `../shared/PHYSICS.md`), so between samples `k` apart its
//! displacement changes by at most `max_slope·Δ·k`, `Δ` the samples' spacing along the groove.
//! Allowing the track's own sample-to-sample noise on top (`NOISE_SIGMAS` times the robust
//! σ of its first differences), the track splits at every step larger than that into
//! stretches that are each plausible on their own. The groove is the long ones: a stretch
//! of at most `max_excursion` samples next to a longer one is an excursion. Its samples are
//! solved again with the Lorentzian started from the cubic through the two samples of the
//! long stretches on each side (so the borders that agree with the groove around it carry the
//! solve), and a sample whose new value is still out of reach of its kept neighbours is left
//! as a gap, which is bridged when short or else filled by the other decoder in the fused
//! method.

use std::ops::Range;

use super::robust::{CombineParams, Solution, Solves};
use crate::meta::Cut;

/// Allowed step beyond the slope's, in robust σs of the track's first differences.
pub const NOISE_SIGMAS: f64 = 6.0;

/// The runs of samples of `track` (NaN = gap) that form excursions (see the module docs):
/// stretches of at most `max_excursion` finite samples, split from their neighbours by steps
/// larger than `max_step·k + allowance` (`k` samples apart; [`allowance`] gives the module's),
/// next to a stretch longer than `max_excursion`. Each run spans from the excursion's first to
/// its last sample.
#[must_use]
pub fn excursions(
    track: &[f64],
    max_step: f64,
    allowance: f64,
    max_excursion: usize,
) -> Vec<Range<usize>> {
    if max_step.is_nan() || max_step <= 0.0 || max_excursion == 0 {
        return Vec::new();
    }
    // Stretches of finite samples, each plausible from one sample to the next.
    let mut stretches: Vec<Range<usize>> = Vec::new();
    let mut last: Option<usize> = None;
    for (j, &v) in track.iter().enumerate() {
        if !v.is_finite() {
            continue;
        }
        match (last, stretches.last_mut()) {
            (Some(i), Some(s)) if (v - track[i]).abs() <= max_step * (j - i) as f64 + allowance => {
                s.end = j + 1;
            }
            _ => stretches.push(j..j + 1),
        }
        last = Some(j);
    }
    let finite = |s: &Range<usize>| track[s.clone()].iter().filter(|v| v.is_finite()).count();
    let long: Vec<bool> = stretches
        .iter()
        .map(|s| finite(s) > max_excursion)
        .collect();
    if !long.iter().any(|&l| l) {
        // No stretch to trust more than another.
        return Vec::new();
    }
    // Short stretches, merged into one run while they follow each other, kept where a long
    // stretch lies on either side of the run.
    let mut runs: Vec<(Range<usize>, bool)> = Vec::new();
    for (i, s) in stretches.iter().enumerate() {
        if long[i] {
            if let Some(run) = runs.last_mut() {
                run.1 = true;
            }
            continue;
        }
        let after_long = i > 0 && long[i - 1];
        match runs.last_mut() {
            Some((r, beside)) if i > 0 && !long[i - 1] => {
                r.end = s.end;
                *beside |= after_long;
            }
            _ => runs.push((s.clone(), after_long)),
        }
    }
    runs.into_iter()
        .filter(|(_, beside)| *beside)
        .map(|(r, _)| r)
        .collect()
}

/// Robust σ (1.4826·median |Δ|) of the differences Δ between consecutive finite samples of
/// `track`; 0 with fewer than two.
fn difference_sigma(track: &[f64]) -> f64 {
    let diffs: Vec<f64> = track
        .windows(2)
        .filter_map(|w| {
            let d = w[1] - w[0];
            d.is_finite().then_some(d)
        })
        .collect();
    crate::pipeline::robust_sigma(&diffs, 0.0)
}

/// Whether `v` at sample `j` is within reach of the finite samples of `track` nearest before
/// and after `run` (the kept neighbours of an excursion).
#[must_use]
pub fn within_reach(
    track: &[f64],
    run: &Range<usize>,
    j: usize,
    v: f64,
    max_step: f64,
    allowance: f64,
) -> bool {
    let before = track[..run.start].iter().rposition(|x| x.is_finite());
    let after = track
        .get(run.end..)
        .and_then(|t| t.iter().position(|x| x.is_finite()))
        .map(|k| run.end + k);
    let reach = |i: usize| {
        let k = i.abs_diff(j) as f64;
        (v - track[i]).abs() <= max_step * k + allowance
    };
    v.is_finite() && before.is_none_or(reach) && after.is_none_or(reach)
}

/// The start of an excursion sample's new solve: the cubic through the two finite samples of
/// `track` before `run` and the two after it (fewer where the track has fewer: the line
/// through two, or the nearest one), at `j`.
#[must_use]
pub fn start_value(track: &[f64], run: &Range<usize>, j: usize) -> Option<f64> {
    let mut nodes: Vec<(f64, f64)> = track[..run.start]
        .iter()
        .enumerate()
        .rev()
        .filter(|(_, v)| v.is_finite())
        .take(2)
        .map(|(i, &v)| (i as f64, v))
        .collect();
    nodes.reverse();
    nodes.extend(
        track
            .iter()
            .enumerate()
            .skip(run.end)
            .filter(|(_, v)| v.is_finite())
            .take(2)
            .map(|(i, &v)| (i as f64, v)),
    );
    match nodes.as_slice() {
        [] => None,
        [(_, v)] => Some(*v),
        _ => Some(crate::pipeline::lagrange(&nodes, j as f64)),
    }
}

/// The allowance on top of the slope's step for `track`: [`NOISE_SIGMAS`] robust σs of its
/// first differences.
#[must_use]
pub fn allowance(track: &[f64]) -> f64 {
    NOISE_SIGMAS * difference_sigma(track)
}

/// Wall `side`'s displacement from a sample's `d` and `e`: `d ∓ e` (`d` alone on a lateral
/// cut).
fn wall_value(side: usize, d: f64, e: f64, lateral: bool) -> f64 {
    match (lateral, side) {
        (true, _) => d,
        (false, 0) => d - e,
        (false, _) => d + e,
    }
}

/// The walls' tracks ([`wall_value`] per sample).
fn wall_tracks(d: &[f64], e: &[f64], lateral: bool) -> [Vec<f64>; 2] {
    std::array::from_fn(|side| {
        d.iter()
            .zip(e)
            .map(|(&dj, &ej)| wall_value(side, dj, ej, lateral))
            .collect()
    })
}

/// Finds the walls' excursions in the combination's solves ([`excursions`]) and solves their
/// samples again with `solve(j, start)`, started from the track around them
/// ([`start_value`]); a sample still out of reach of the kept samples on either side
/// ([`within_reach`]) becomes a gap. Returns the excursions (none when `p.max_step_um` is 0).
pub(super) fn resolve_excursions(
    s: &mut Solves,
    p: &CombineParams,
    solve: impl Fn(usize, (f64, f64)) -> Option<Solution>,
) -> Vec<Range<usize>> {
    if p.max_step_um.is_nan() || p.max_step_um <= 0.0 {
        return Vec::new();
    }
    let lateral = p.cut == Cut::Lateral;
    let walls = wall_tracks(&s.d, &s.e, lateral);
    let sides = if lateral { 1 } else { 2 };
    let allow: Vec<f64> = walls[..sides].iter().map(|w| allowance(w)).collect();
    let runs = crate::pipeline::merge_ranges(
        walls[..sides]
            .iter()
            .zip(&allow)
            .flat_map(|(w, &a)| excursions(w, p.max_step_um, a, p.max_excursion))
            .collect(),
    );
    for run in &runs {
        for j in run.clone() {
            let start = start_value(&s.d, run, j).map(|d0| {
                let e0 = if lateral {
                    Some(0.0)
                } else {
                    start_value(&s.e, run, j)
                };
                (d0, e0.unwrap_or(f64::NAN))
            });
            let kept = start.and_then(|de| solve(j, de)).filter(|&(dj, ej, _, _)| {
                (0..sides).all(|side| {
                    let v = wall_value(side, dj, ej, lateral);
                    within_reach(&walls[side], run, j, v, p.max_step_um, allow[side])
                })
            });
            s.store(j, kept, lateral);
        }
    }
    runs
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;

    /// A 1 kHz tone's displacement, 3 µm peak, at 2.3 µm a sample along a groove moving at
    /// 105 mm/s (44.1 kHz), with a little noise.
    fn tone(n: usize) -> Vec<f64> {
        (0..n)
            .map(|j| {
                3.0 * (std::f64::consts::TAU * 1000.0 * j as f64 / 44_100.0).sin()
                    + 0.02 * (((j * 37) % 11) as f64 - 5.0) / 5.0
            })
            .collect()
    }

    #[test]
    fn excursions_are_found_and_the_groove_is_not() {
        let mut t = tone(400);
        // Nothing but the groove: no excursion, even for a loud tone (0.43 µm a sample here).
        assert!(excursions(&t, 2.3, allowance(&t), 16).is_empty());
        // One sample 40 µm off, and five that climb 10 then 25 µm off (as on the damaged scan).
        t[100] += 40.0;
        t[200] += 10.0;
        for v in &mut t[201..205] {
            *v += 25.0;
        }
        t[150] = f64::NAN;
        let found = excursions(&t, 2.3, allowance(&t), 16);
        assert_eq!(found, vec![100..101, 200..205], "{found:?}");
        // Off (no slope bound), nothing.
        assert!(excursions(&t, 0.0, allowance(&t), 16).is_empty());
    }

    #[test]
    fn a_long_stretch_is_kept_and_a_track_of_short_ones_left_alone() {
        let mut t = tone(200);
        // 40 samples at another level: longer than max_excursion, so not an excursion.
        for v in &mut t[50..90] {
            *v += 30.0;
        }
        assert!(excursions(&t, 2.3, allowance(&t), 16).is_empty());
        // Every sample jumps: no long stretch to trust, nothing done.
        let zigzag: Vec<f64> = (0..100)
            .map(|j| if j % 2 == 0 { 0.0 } else { 50.0 })
            .collect();
        assert!(excursions(&zigzag, 2.3, allowance(&zigzag), 16).is_empty());
    }

    #[test]
    fn the_start_is_the_cubic_across_and_reach_is_judged_from_both_sides() {
        let t: Vec<f64> = (0..10)
            .map(|j| if (4..6).contains(&j) { 99.0 } else { j as f64 })
            .collect();
        let run = 4..6;
        assert!((start_value(&t, &run, 4).unwrap() - 4.0).abs() < 1e-9);
        assert!((start_value(&t, &run, 5).unwrap() - 5.0).abs() < 1e-9);
        // Within 1.5 µm of sample 3 (one step) and 3 µm of sample 6 (two steps).
        assert!(within_reach(&t, &run, 4, 4.2, 1.5, 0.0));
        // 3.5 µm from sample 3 is beyond one step (plus no allowance), though near sample 6.
        assert!(!within_reach(&t, &run, 4, 6.5, 1.5, 0.0));
        assert!(within_reach(&t, &run, 4, 6.5, 1.5, 2.0));
        assert!(!within_reach(&t, &run, 4, f64::NAN, 1.5, 0.0));
    }
}
