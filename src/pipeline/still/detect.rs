//! Groove detection on the block profiles: walls against local light levels, walls paired into
//! grooves at their bottoms, grooves linked from block to block into numbered tracks.
//!
//! In each block profile the *local* dark and bright levels (the 10th and 90th percentiles in
//! a window of two of the widest grooves looked for, on a coarse grid, interpolated) set a
//! threshold halfway between them, so uneven light does not move it; walls are the runs below
//! it (above it for bright walls), their ends located at the sub-pixel threshold crossing. Two
//! neighbouring walls form a groove when the gap between them is a bottom: gaps between walls
//! fall into two sizes (bottoms and lands) told apart by a two-means split of their logarithms
//! over the whole image, which must alternate across a block; when they do not split, a lone groove's narrow gap (under half a wall)
//! is a bottom, and otherwise every run is a whole groove whose bottom is not seen (two runs a
//! narrow gap apart that together are a groove's width are one groove that noise cut in two). Grooves are
//! then linked from block to block to the nearest track within a share of their spacing
//! (greedy, nearest pairs first), tolerating gaps of `max_gap_blocks`; they are numbered by
//! their position across the image with the common drift taken out.

use std::ops::Range;

use super::link::{absorb_pieces, centre, common_drift, interpolate, link, merge_fragments, width};
use super::profile::Profiles;
use super::{Axis, StillError, StillParams, StillSetup, WallTone};
use crate::pipeline::StageError;
use crate::pipeline::{median, sampled_quantiles};

/// Dark and bright level quantiles of the local light window.
const LEVEL_QUANTILES: (f64, f64) = (0.1, 0.9);
/// Tiles per light window (the levels are computed on this coarse grid and interpolated).
const TILES_PER_WINDOW: usize = 4;
/// Two gap clusters are bottoms and lands when their centres differ by at least this factor.
const GAP_CLUSTER_RATIO: f64 = 1.6;
/// The smaller gap cluster must hold at least this share of the gaps.
const GAP_CLUSTER_SHARE: f64 = 0.2;
/// Two clusters are not bottoms and lands when more than this share of the pairs of gaps side
/// by side in a block both fall in the small one (a wall with a "bottom" on either side): they
/// are lands, and the wide gaps where a groove was not seen (text, an edge).
const PAIRED_BOTTOMS_SHARE: f64 = 0.25;
/// Without two clusters, gaps under this share of the median wall are bottoms.
const LONE_BOTTOM_SHARE: f64 = 0.5;
/// Linking tolerance as a share of the groove spacing (or of the width for a lone groove).
const LINK_SHARE: f64 = 0.3;
/// A groove in a block whose width is off the image's median by more than this share is a
/// wrong pairing (a stereo groove's width swings by twice its walls' swing, so this is wide).
const WIDTH_TOLERANCE: f64 = 0.6;
/// A track whose median width is off the image's median by more than this share is a run of
/// wrong pairings, not a groove: a groove's width holds to a few per cent along it (the
/// generator's stills, the demo, stereo), while a track that pairs a wall with a dust speck
/// or a wall's own edges runs at about half the width. Wide of both, so a groove cut wider
/// than its neighbours is kept.
const TRACK_WIDTH_TOLERANCE: f64 = 0.4;
/// Along-to-across gradient energy above which the axis contradicts the image.
const AXIS_RATIO: f64 = 1.2;
/// A still whose bright level (see [`GrooveMap::brightness_gain`]) is under this share of full
/// scale is lifted to it for the border fits: the generator's stills and the demo sit at about
/// 0.68, so a well-exposed still is read as it is.
pub const BRIGHT_LEVEL: f64 = 0.5;
/// Most profile values the bright level is measured on (evenly spaced).
const BRIGHT_SAMPLES: usize = 1 << 20;
/// Grooves within this share of the best coverage count as complete when choosing one.
const COMPLETE_SHARE: f64 = 0.9;

/// A wall run in one profile: sub-pixel ends (cross px).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Run {
    a: f64,
    b: f64,
}

/// One groove across the image: its borders in every block where it was found.
#[derive(Clone, Debug, PartialEq)]
pub struct GrooveTrack {
    /// `--groove` number (from 1, from the image's left or top).
    pub number: usize,
    /// Its four borders (land|wall, wall|bottom, bottom|wall, wall|land; cross px) per block;
    /// the inner two are NaN when the bottom is not seen; `None` where it was not found.
    pub blocks: Vec<Option<[f64; 4]>>,
    /// Share of the blocks it was found in.
    pub coverage: f64,
    /// Position across the image with the common drift taken out (cross px).
    pub position_px: f64,
    /// Median width at the land (px).
    pub width_px: f64,
}

impl GrooveTrack {
    /// The groove's predicted borders along the image: [`GroovePath::at`] any line.
    #[must_use]
    pub fn path(&self, map: &GrooveMap) -> GroovePath {
        GroovePath {
            found: self
                .blocks
                .iter()
                .enumerate()
                .filter_map(|(b, v)| v.map(|v| (map.block_centres[b], v)))
                .collect(),
            drift_per_line: map.drift_px_per_block / map.block_lines.max(1) as f64,
        }
    }

    /// The four borders at `line` ([`GroovePath::at`]; for many lines, take [`Self::path`]
    /// once).
    #[must_use]
    pub fn predict(&self, map: &GrooveMap, line: f64) -> [f64; 4] {
        self.path(map).at(line)
    }
}

/// A groove's borders in the blocks it was found in, and the image's drift per line.
#[derive(Clone, Debug, PartialEq)]
pub struct GroovePath {
    /// (block centre line, borders) of the blocks the groove was found in, in line order.
    found: Vec<(f64, [f64; 4])>,
    /// The image's common drift, cross px a line.
    drift_per_line: f64,
}

impl GroovePath {
    /// The four borders at `line`, interpolated linearly between the centres of the blocks
    /// the groove was found in, and carried on along the image's common drift before the first
    /// and after the last (a groove that drifts off the image is followed off it, not held at
    /// its last place, where the next turn drifts in); NaN when it was never found.
    #[must_use]
    pub fn at(&self, line: f64) -> [f64; 4] {
        let beyond = match (self.found.first(), self.found.last()) {
            (Some(&(first, _)), _) if line < first => line - first,
            (_, Some(&(last, _))) if line > last => line - last,
            _ => 0.0,
        };
        interpolate(&self.found, line).map(|v| v + self.drift_per_line * beyond)
    }
}

/// The runs of lines on which a groove's `predicted` borders (one per line) lie wholly outside
/// an image `cross` samples across (both land borders past the same edge): lines with no
/// sound in this still.
#[must_use]
pub fn outside_image(predicted: &[[f64; 4]], cross: usize) -> Vec<Range<usize>> {
    let last = cross as f64 - 1.0;
    let mut runs: Vec<Range<usize>> = Vec::new();
    for (n, g) in predicted.iter().enumerate() {
        if !(g[3] < 0.0 || g[0] > last) {
            continue;
        }
        match runs.last_mut() {
            Some(r) if r.end == n => r.end = n + 1,
            _ => runs.push(n..n + 1),
        }
    }
    runs
}

/// Every groove found in a still.
#[derive(Clone, Debug, PartialEq)]
pub struct GrooveMap {
    /// Which way the grooves run.
    pub axis: Axis,
    /// Lines along the grooves.
    pub lines: usize,
    /// Cross samples per line.
    pub cross: usize,
    /// Lines per block.
    pub block_lines: usize,
    /// Line at the centre of every block.
    pub block_centres: Vec<f64>,
    /// The grooves, in `--groove` order.
    pub grooves: Vec<GrooveTrack>,
    /// The grooves' common drift across the image (cross px a block, the median slope of the
    /// tracks): how a groove is followed past the blocks it was found in.
    pub drift_px_per_block: f64,
    /// Gain on the grey values of the border fits: [`BRIGHT_LEVEL`] over the still's bright
    /// level (the 90th percentile of its block profiles) where that is lower, else 1, so that a
    /// dim still (12 bits stored in 16, an under-exposed micrograph) meets the fits' grey-level
    /// thresholds as a well-exposed one does.
    pub brightness_gain: f64,
    /// Whether the bottoms are seen (two walls per groove) or each groove is one dark band.
    pub bottoms_visible: bool,
    /// Gradient energy along the lines over that across them.
    pub energy_ratio: f64,
}

/// The `q` quantile of the finite values in `v` (reordered).
fn quantile(v: &mut [f32], q: f64) -> Option<f32> {
    let last = v.len().checked_sub(1)?;
    let k = ((last as f64 * q).round() as usize).min(last);
    Some(*v.select_nth_unstable_by(k, f32::total_cmp).1)
}

/// Local dark and bright levels of a profile on a coarse grid, interpolated to every sample.
fn local_levels(p: &[f32], window: usize) -> Vec<(f32, f32)> {
    let n = p.len();
    let window = window.clamp(8, n.max(8));
    let tile = (window / TILES_PER_WINDOW).max(2);
    let tiles = n.div_ceil(tile);
    let mut buf = Vec::with_capacity(window);
    let grid: Vec<(f64, f32, f32)> = (0..tiles)
        .filter_map(|t| {
            let centre = (t as f64 + 0.5) * tile as f64;
            let lo = (centre - 0.5 * window as f64).max(0.0) as usize;
            let hi = ((centre + 0.5 * window as f64) as usize).min(n);
            buf.clear();
            buf.extend(p.get(lo..hi)?.iter().copied().filter(|v| v.is_finite()));
            let dark = quantile(&mut buf, LEVEL_QUANTILES.0)?;
            let bright = quantile(&mut buf, LEVEL_QUANTILES.1)?;
            Some((centre - 0.5, dark, bright))
        })
        .collect();
    (0..n)
        .map(|c| {
            let x = c as f64;
            let i = grid.partition_point(|g| g.0 <= x);
            match (grid.get(i.wrapping_sub(1)), grid.get(i)) {
                (Some(a), Some(b)) => {
                    let t = ((x - a.0) / (b.0 - a.0)) as f32;
                    (a.1 + t * (b.1 - a.1), a.2 + t * (b.2 - a.2))
                }
                (Some(a), None) | (None, Some(a)) => (a.1, a.2),
                (None, None) => (f32::NAN, f32::NAN),
            }
        })
        .collect()
}

/// The wall runs of one profile (whole runs only: a run touching the image's edge is cut off).
fn wall_runs(
    p: &[f32],
    tone: WallTone,
    window: usize,
    min_wall_px: f64,
    min_contrast: f64,
) -> Vec<Run> {
    // Bright walls are dark walls of the negated profile.
    let v: Vec<f32> = match tone {
        WallTone::Dark => p.to_vec(),
        WallTone::Bright => p.iter().map(|x| -x).collect(),
    };
    let levels = local_levels(&v, window);
    let thr: Vec<f32> = levels
        .iter()
        .map(|&(d, b)| {
            let enough = f64::from(b - d) >= min_contrast * f64::from(b.abs().max(d.abs()));
            if enough { 0.5 * (d + b) } else { f32::NAN }
        })
        .collect();
    let is_wall = |c: usize| matches!((v.get(c), thr.get(c)), (Some(x), Some(t)) if x < t);
    let mut runs = Vec::new();
    let mut c = 0;
    let n = v.len();
    while c < n {
        if !is_wall(c) {
            c += 1;
            continue;
        }
        let s = c;
        while c < n && is_wall(c) {
            c += 1;
        }
        let e = c - 1;
        if s == 0 || e + 1 >= n {
            continue;
        }
        let cross = |i: usize, j: usize| {
            let (vi, vj, t) = (f64::from(v[i]), f64::from(v[j]), f64::from(thr[i]));
            let f = if (vj - vi).abs() > 1e-12 {
                ((t - vi) / (vj - vi)).clamp(0.0, 1.0)
            } else {
                0.5
            };
            i as f64 + f * (j as f64 - i as f64)
        };
        let run = Run {
            a: cross(s - 1, s),
            b: cross(e, e + 1),
        };
        if run.b - run.a >= min_wall_px {
            runs.push(run);
        }
    }
    runs
}

/// Splits `ln(gap)` into two clusters; `(small centre, large centre, small share)`.
fn two_means(gaps: &[f64]) -> Option<(f64, f64, f64)> {
    let logs: Vec<f64> = gaps.iter().filter(|g| **g > 0.0).map(|g| g.ln()).collect();
    let (mut lo, mut hi) = logs
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
    if logs.len() < 2 || hi - lo < 1e-9 {
        return None;
    }
    let mut share = 0.0;
    for _ in 0..50 {
        let mid = 0.5 * (lo + hi);
        let (mut s0, mut n0, mut s1, mut n1) = (0.0, 0usize, 0.0, 0usize);
        for &v in &logs {
            if v < mid {
                s0 += v;
                n0 += 1;
            } else {
                s1 += v;
                n1 += 1;
            }
        }
        if n0 == 0 || n1 == 0 {
            return None;
        }
        (lo, hi) = (s0 / n0 as f64, s1 / n1 as f64);
        share = n0 as f64 / logs.len() as f64;
    }
    Some((lo.exp(), hi.exp(), share))
}

/// Finds, links and numbers the grooves of a still.
///
/// # Errors
/// [`StillError::AxisContradicts`] when the image's structure runs across the given axis,
/// [`StillError::NoGroove`] (saying where it looked) when nothing groove-like is found.
pub fn detect_grooves(
    profiles: &Profiles,
    setup: &StillSetup,
    params: &StillParams,
) -> Result<GrooveMap, StillError> {
    params.validate()?;
    setup.validate()?;
    let energy_ratio = profiles.energy_along / profiles.energy_across.max(f64::MIN_POSITIVE);
    if energy_ratio > AXIS_RATIO {
        let other = match profiles.axis {
            Axis::Vertical => Axis::Horizontal,
            Axis::Horizontal => Axis::Vertical,
        };
        return Err(StillError::AxisContradicts {
            given: profiles.axis.name(),
            found: other.name(),
            ratio: energy_ratio,
        });
    }
    let px_per_um = 1.0 / setup.um_per_px;
    let max_width_px = params.max_groove_width_um * px_per_um;
    let window = (2.0 * max_width_px).ceil() as usize;
    let min_wall_px = (params.min_wall_width_um * px_per_um).max(1.5);
    if max_width_px < 2.0 * min_wall_px {
        // A groove holds two walls: a narrower one is looked for in vain.
        return Err(StageError::InvalidParam {
            name: "still.max_groove_width_um".into(),
            problem: format!(
                "{} µm is {max_width_px:.1} px here, too narrow for two walls of at least \
                 {min_wall_px:.1} px (still.min_wall_width_um, never under 1.5 px)",
                params.max_groove_width_um
            ),
        }
        .into());
    }
    let runs: Vec<Vec<Run>> = (0..profiles.blocks)
        .map(|b| {
            wall_runs(
                profiles.block(b),
                params.walls,
                window,
                min_wall_px,
                params.min_contrast,
            )
        })
        .collect();
    let gaps: Vec<f64> = runs
        .iter()
        .flat_map(|r| r.windows(2).map(|w| w[1].a - w[0].b))
        .collect();
    let wall_median = median(runs.iter().flatten().map(|r| r.b - r.a).collect()).unwrap_or(0.0);
    // Bottoms and lands alternate across a block: a wall has a bottom on one side only.
    let alternate = |limit: f64| {
        let (mut both, mut pairs) = (0usize, 0usize);
        for w in runs.iter().flat_map(|r| r.windows(3)) {
            pairs += 1;
            if w[1].a - w[0].b < limit && w[2].a - w[1].b < limit {
                both += 1;
            }
        }
        both as f64 <= PAIRED_BOTTOMS_SHARE * pairs as f64
    };
    let bottom_limit = two_means(&gaps)
        .filter(|&(small, large, share)| {
            large >= GAP_CLUSTER_RATIO * small && share >= GAP_CLUSTER_SHARE
        })
        .map(|(small, large, _)| (small * large).sqrt())
        .filter(|&limit| alternate(limit))
        .or_else(|| {
            median(gaps.clone())
                .filter(|g| *g < LONE_BOTTOM_SHARE * wall_median)
                .map(|_| LONE_BOTTOM_SHARE * wall_median)
        });
    let per_block: Vec<Vec<[f64; 4]>> = runs
        .iter()
        .map(|r| {
            let mut grooves = Vec::new();
            let mut i = 0;
            while i < r.len() {
                match (bottom_limit, r.get(i + 1)) {
                    (Some(limit), Some(next)) if next.a - r[i].b < limit => {
                        grooves.push([r[i].a, r[i].b, next.a, next.b]);
                        i += 2;
                    }
                    (Some(_), _) => i += 1,
                    // One band cut in two by a bright speck of noise or the sliver of a
                    // bottom: halves a narrow gap apart that together are a groove's width.
                    (None, Some(next))
                        if next.a - r[i].b < LONE_BOTTOM_SHARE * wall_median
                            && next.b - r[i].a <= (1.0 + TRACK_WIDTH_TOLERANCE) * wall_median =>
                    {
                        grooves.push([r[i].a, f64::NAN, f64::NAN, next.b]);
                        i += 2;
                    }
                    (None, _) => {
                        grooves.push([r[i].a, f64::NAN, f64::NAN, r[i].b]);
                        i += 1;
                    }
                }
            }
            grooves.retain(|g| width(g) <= max_width_px);
            grooves
        })
        .collect();
    let centres = |gs: &Vec<[f64; 4]>| -> Vec<f64> { gs.iter().map(centre).collect() };
    let spacing = median(
        per_block
            .iter()
            .flat_map(|gs| {
                centres(gs)
                    .windows(2)
                    .map(|w| w[1] - w[0])
                    .collect::<Vec<_>>()
            })
            .collect(),
    );
    let image_width = median(per_block.iter().flatten().map(width).collect()).unwrap_or(0.0);
    // How far a width is off the image's, as a share of it.
    let off_width = |w: f64| (w / image_width.max(f64::MIN_POSITIVE) - 1.0).abs();
    // Pieces of grooves broken up by text or damage pair into grooves of the wrong width.
    let per_block: Vec<Vec<[f64; 4]>> = per_block
        .into_iter()
        .map(|mut gs| {
            gs.retain(|g| off_width(width(g)) <= WIDTH_TOLERANCE);
            gs
        })
        .collect();
    let tol = spacing
        .map_or(0.5 * image_width, |s| LINK_SHARE * s)
        .max(2.0);
    let mut tracks: Vec<Vec<Option<[f64; 4]>>> = link(&per_block, tol, params.max_gap_blocks);
    merge_fragments(&mut tracks, tol, params.max_gap_blocks);
    let drift = common_drift(&tracks);
    absorb_pieces(&mut tracks, tol, drift);
    tracks.retain(|t| {
        let track_width = median(t.iter().flatten().map(width).collect());
        t.iter().flatten().count() >= params.min_track_blocks
            && track_width.is_some_and(|w| off_width(w) <= TRACK_WIDTH_TOLERANCE)
    });
    if tracks.is_empty() {
        let (lines_name, cross_name) = profiles.axis.names();
        return Err(StillError::NoGroove {
            looked: format!(
                "looked for {} walls {min_wall_px:.1}–{max_width_px:.0} px wide with at least {:.0} % contrast \
                 to the local light, across {cross_name} 0–{} in {} blocks of {} {lines_name}; found {} wall runs",
                match params.walls {
                    WallTone::Dark => "dark",
                    WallTone::Bright => "bright",
                },
                100.0 * params.min_contrast,
                profiles.cross - 1,
                profiles.blocks,
                profiles.block_lines,
                runs.iter().map(Vec::len).sum::<usize>()
            ),
        });
    }
    // Again over the grooves as they stand (pieces joined, short tracks dropped).
    let drift = common_drift(&tracks);
    let mid_block = 0.5 * (profiles.blocks as f64 - 1.0);
    let mut grooves: Vec<GrooveTrack> = tracks
        .into_iter()
        .map(|blocks| {
            let found: Vec<(usize, [f64; 4])> = blocks
                .iter()
                .enumerate()
                .filter_map(|(b, g)| g.map(|g| (b, g)))
                .collect();
            let n = found.len() as f64;
            let position_px = found
                .iter()
                .map(|(b, g)| centre(g) - drift * (*b as f64 - mid_block))
                .sum::<f64>()
                / n;
            GrooveTrack {
                number: 0,
                coverage: n / profiles.blocks as f64,
                position_px,
                width_px: median(found.iter().map(|(_, g)| width(g)).collect()).unwrap_or(0.0),
                blocks,
            }
        })
        .collect();
    grooves.sort_by(|a, b| a.position_px.total_cmp(&b.position_px));
    for (i, g) in grooves.iter_mut().enumerate() {
        g.number = i + 1;
    }
    Ok(GrooveMap {
        axis: profiles.axis,
        lines: profiles.lines,
        cross: profiles.cross,
        block_lines: profiles.block_lines,
        block_centres: (0..profiles.blocks)
            .map(|b| profiles.block_centre_line(b))
            .collect(),
        grooves,
        drift_px_per_block: drift,
        brightness_gain: brightness_gain(&profiles.data),
        bottoms_visible: bottom_limit.is_some(),
        energy_ratio,
    })
}

/// [`GrooveMap::brightness_gain`] of a still whose block profiles are `profiles`.
fn brightness_gain(profiles: &[f32]) -> f64 {
    let bright = LEVEL_QUANTILES.1;
    match sampled_quantiles(profiles, bright, bright, BRIGHT_SAMPLES) {
        Some((_, level)) if level > 0.0 && f64::from(level) < BRIGHT_LEVEL => {
            BRIGHT_LEVEL / f64::from(level)
        }
        _ => 1.0,
    }
}

/// The index in `map.grooves` of groove number `asked`, or without one the most complete
/// groove nearest the middle of the image.
///
/// # Errors
/// [`StillError::GrooveOutOfRange`] saying how many were found.
pub fn choose_groove(map: &GrooveMap, asked: Option<usize>) -> Result<usize, StillError> {
    let found = map.grooves.len();
    let side = match map.axis {
        Axis::Vertical => "left",
        Axis::Horizontal => "top",
    };
    if let Some(n) = asked {
        return if (1..=found).contains(&n) {
            Ok(n - 1)
        } else {
            Err(StillError::GrooveOutOfRange {
                asked: n,
                found,
                side,
            })
        };
    }
    let best = map.grooves.iter().map(|g| g.coverage).fold(0.0, f64::max);
    let middle = 0.5 * (map.cross as f64 - 1.0);
    map.grooves
        .iter()
        .enumerate()
        .filter(|(_, g)| g.coverage >= COMPLETE_SHARE * best)
        .min_by(|(_, a), (_, b)| {
            (a.position_px - middle)
                .abs()
                .total_cmp(&(b.position_px - middle).abs())
        })
        .map(|(i, _)| i)
        .ok_or(StillError::GrooveOutOfRange {
            asked: 0,
            found,
            side,
        })
}
