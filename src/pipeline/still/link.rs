//! Grooves linked from block to block into tracks: greedy nearest linking, then pieces of one
//! groove joined (end to start across a gap, or a shorter piece running along a longer track).

use crate::pipeline::median;

/// Most blocks a piece of a groove may share with the track it joins (see `absorb_pieces`).
const MAX_SHARED_BLOCKS: usize = 2;
/// Share of a piece's blocks that must lie near a longer track for it to join (see
/// `absorb_pieces`): the first block of a piece is often a wrong pairing.
const NEAR_SHARE: f64 = 0.75;

/// The middle of a groove's four borders: halfway between its land borders.
pub(super) fn centre(g: &[f64; 4]) -> f64 {
    0.5 * (g[0] + g[3])
}

/// A groove's width at the land: between its outer borders.
pub(super) fn width(g: &[f64; 4]) -> f64 {
    g[3] - g[0]
}

/// The four borders at `line` from `found` (line, borders) pairs in line order: linear
/// between them, held at the ends; NaN when there are none.
pub(super) fn interpolate(found: &[(f64, [f64; 4])], line: f64) -> [f64; 4] {
    let Some(&(first_line, first)) = found.first() else {
        return [f64::NAN; 4];
    };
    if line <= first_line {
        return first;
    }
    let i = found.partition_point(|(l, _)| *l <= line);
    match (found.get(i.wrapping_sub(1)), found.get(i)) {
        (Some(&(l0, v0)), Some(&(l1, v1))) => {
            let t = (line - l0) / (l1 - l0).max(1e-9);
            std::array::from_fn(|k| v0[k] + t * (v1[k] - v0[k]))
        }
        (Some(&(_, v)), None) => v,
        _ => first,
    }
}

/// The image's common drift (px a block): the median slope of the tracks.
pub(super) fn common_drift(tracks: &[Vec<Option<[f64; 4]>>]) -> f64 {
    median(tracks.iter().filter_map(|t| slope(t)).collect()).unwrap_or(0.0)
}

/// Builds tracks from the grooves of every block (greedy nearest linking).
pub(super) fn link(
    per_block: &[Vec<[f64; 4]>],
    tol: f64,
    max_gap: usize,
) -> Vec<Vec<Option<[f64; 4]>>> {
    let blocks = per_block.len();
    struct Building {
        blocks: Vec<Option<[f64; 4]>>,
        last_block: usize,
        last_centre: f64,
    }
    let mut tracks: Vec<Building> = Vec::new();
    for (b, grooves) in per_block.iter().enumerate() {
        let mut pairs = Vec::new();
        for (t, tr) in tracks.iter().enumerate() {
            let lost = b - tr.last_block;
            if lost > max_gap + 1 {
                continue;
            }
            let reach = tol * (1.0 + 0.25 * (lost - 1) as f64);
            for (g, gr) in grooves.iter().enumerate() {
                let d = (centre(gr) - tr.last_centre).abs();
                if d < reach {
                    pairs.push((d, t, g));
                }
            }
        }
        pairs.sort_by(|x, y| x.0.total_cmp(&y.0));
        let mut track_used = vec![false; tracks.len()];
        let mut groove_used = vec![false; grooves.len()];
        for (_, t, g) in pairs {
            if track_used[t] || groove_used[g] {
                continue;
            }
            track_used[t] = true;
            groove_used[g] = true;
            let tr = &mut tracks[t];
            tr.blocks[b] = Some(grooves[g]);
            tr.last_block = b;
            tr.last_centre = centre(&grooves[g]);
        }
        for (g, gr) in grooves.iter().enumerate() {
            if !groove_used[g] {
                let mut v = vec![None; blocks];
                v[b] = Some(*gr);
                tracks.push(Building {
                    blocks: v,
                    last_block: b,
                    last_centre: centre(gr),
                });
            }
        }
    }
    tracks.into_iter().map(|t| t.blocks).collect()
}

/// Takes track `b` out of `tracks` to join it to track `a`: `a`'s index after the removal,
/// and the piece.
fn take_piece(
    tracks: &mut Vec<Vec<Option<[f64; 4]>>>,
    a: usize,
    b: usize,
) -> (usize, Vec<Option<[f64; 4]>>) {
    let piece = tracks.remove(b);
    (if b < a { a - 1 } else { a }, piece)
}

/// Puts `piece`'s grooves into `track`'s empty blocks; in a block both hold, the groove whose
/// width is nearer `keep_width` stays.
fn join_into(track: &mut [Option<[f64; 4]>], piece: Vec<Option<[f64; 4]>>, keep_width: f64) {
    for (slot, g) in track.iter_mut().zip(piece) {
        match (slot.as_ref(), g) {
            (None, Some(g)) => *slot = Some(g),
            (Some(s), Some(g))
                if (width(&g) - keep_width).abs() < (width(s) - keep_width).abs() =>
            {
                *slot = Some(g);
            }
            _ => {}
        }
    }
}

/// Joins tracks that are pieces of one groove: one ends (at most one block after the other
/// starts) within the gap allowance before the other starts, near where it starts. Where both
/// hold a block, the groove nearer the joined track's median width is kept.
pub(super) fn merge_fragments(tracks: &mut Vec<Vec<Option<[f64; 4]>>>, tol: f64, max_gap: usize) {
    let ends = |t: &[Option<[f64; 4]>]| -> Option<((usize, f64), (usize, f64))> {
        let first = t.iter().position(Option::is_some)?;
        let last = t.iter().rposition(Option::is_some)?;
        Some(((first, centre(&t[first]?)), (last, centre(&t[last]?))))
    };
    loop {
        let mut join = None;
        'search: for a in 0..tracks.len() {
            let Some((_, (a_last, a_c))) = ends(&tracks[a]) else {
                continue;
            };
            for (b, track_b) in tracks.iter().enumerate() {
                if a == b {
                    continue;
                }
                let Some(((b_first, b_c), (b_last, _))) = ends(track_b) else {
                    continue;
                };
                let gap = b_first as i64 - a_last as i64;
                if b_last > a_last && (-1..=max_gap as i64 + 1).contains(&gap) {
                    let reach = tol * (1.0 + 0.25 * gap.max(0) as f64);
                    if (b_c - a_c).abs() < reach {
                        join = Some((a, b));
                        break 'search;
                    }
                }
            }
        }
        let Some((a, b)) = join else { return };
        let (a, piece) = take_piece(tracks, a, b);
        // The groove nearer the median width of host and piece together stays.
        let widths: Vec<f64> = tracks[a]
            .iter()
            .chain(&piece)
            .flatten()
            .map(width)
            .collect();
        join_into(&mut tracks[a], piece, median(widths).unwrap_or(0.0));
    }
}

/// Joins a shorter track to a longer one it runs along while sharing at most
/// [`MAX_SHARED_BLOCKS`] blocks with it: a piece of the same groove that [`merge_fragments`]
/// does not join, either cut off on both sides by a stretch longer than the gap allowance
/// (text burnt in across it), overlapping the longer track's end by more than one block (a
/// groove near the image edge found twice in a few blocks), or starting where dust had led
/// the longer track astray for a few blocks. Left alone it counts as a groove of its own,
/// lying on top of the real one.
///
/// The piece runs along the longer track when at least [`NEAR_SHARE`] of its blocks lie
/// within `tol` of where the longer one runs: interpolated between its blocks, and past its
/// ends along the image's common `drift` (px a block) from its median drift-free position,
/// since a groove runs on across the image and its last blocks may be the strayed ones.
pub(super) fn absorb_pieces(tracks: &mut Vec<Vec<Option<[f64; 4]>>>, tol: f64, drift: f64) {
    let found = |t: &[Option<[f64; 4]>]| -> Vec<(f64, [f64; 4])> {
        t.iter()
            .enumerate()
            .filter_map(|(b, g)| g.map(|g| (b as f64, g)))
            .collect()
    };
    // Where a track runs at a block, from its found blocks (in block order).
    let runs_at = |host: &[(f64, [f64; 4])], level: f64, block: f64| -> f64 {
        match (host.first(), host.last()) {
            (Some(first), Some(last)) if (first.0..=last.0).contains(&block) => {
                centre(&interpolate(host, block))
            }
            _ => level + drift * block,
        }
    };
    loop {
        let mut join = None;
        let seen: Vec<_> = tracks.iter().map(|t| found(t)).collect();
        let levels: Vec<f64> = seen
            .iter()
            .map(|s| median(s.iter().map(|(b, g)| centre(g) - drift * b).collect()).unwrap_or(0.0))
            .collect();
        'search: for (b, (piece, own)) in tracks.iter().zip(&seen).enumerate() {
            for (a, (track, host)) in tracks.iter().zip(&seen).enumerate() {
                if a == b || host.len() <= own.len() {
                    continue;
                }
                let shared = piece
                    .iter()
                    .zip(track)
                    .filter(|(p, t)| p.is_some() && t.is_some())
                    .count();
                if shared > MAX_SHARED_BLOCKS {
                    continue;
                }
                let near = own
                    .iter()
                    .filter(|(block, g)| (centre(g) - runs_at(host, levels[a], *block)).abs() < tol)
                    .count();
                if near as f64 >= NEAR_SHARE * own.len() as f64 {
                    join = Some((a, b));
                    break 'search;
                }
            }
        }
        let Some((a, b)) = join else { return };
        let (a, piece) = take_piece(tracks, a, b);
        // The groove nearer the longer host's own median width stays (a piece may begin with
        // a wrong pairing).
        let w = median(tracks[a].iter().flatten().map(width).collect()).unwrap_or(0.0);
        join_into(&mut tracks[a], piece, w);
    }
}

/// Least-squares slope of centre against block over the found blocks.
pub(super) fn slope(blocks: &[Option<[f64; 4]>]) -> Option<f64> {
    let pts: Vec<(f64, f64)> = blocks
        .iter()
        .enumerate()
        .filter_map(|(b, g)| g.map(|g| (b as f64, centre(&g))))
        .collect();
    let n = pts.len() as f64;
    if pts.len() < 4 {
        return None;
    }
    let (mx, my) = pts
        .iter()
        .fold((0.0, 0.0), |(a, b), p| (a + p.0 / n, b + p.1 / n));
    let (sxy, sxx) = pts.iter().fold((0.0, 0.0), |(a, b), p| {
        (a + (p.0 - mx) * (p.1 - my), b + (p.0 - mx).powi(2))
    });
    (sxx > 0.0).then(|| sxy / sxx)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A groove at `centre` px (4 px wide) in `blocks`.
    fn track(centre: f64, blocks: &[usize], len: usize) -> Vec<Option<[f64; 4]>> {
        (0..len)
            .map(|b| {
                blocks.contains(&b).then_some([
                    centre - 2.0,
                    centre - 1.0,
                    centre + 1.0,
                    centre + 2.0,
                ])
            })
            .collect()
    }

    #[test]
    fn pieces_of_a_groove_join_it_and_other_grooves_do_not() {
        let host: Vec<usize> = (0..10).chain(20..28).collect();
        let mut tracks = vec![
            track(50.0, &host, 30),
            // In the host's hole.
            track(50.5, &[13, 14, 15], 30),
            // The next groove, 20 px on: apart in blocks but not near.
            track(70.0, &[12, 13], 30),
            // Sharing three of the host's blocks: another groove, whatever its position.
            track(51.0, &[7, 8, 9, 10], 30),
            // Past the host's end, sharing its last two blocks: the same groove.
            track(49.5, &[26, 27, 28, 29], 30),
        ];
        absorb_pieces(&mut tracks, 6.0, 0.0);
        assert_eq!(tracks.len(), 3, "{tracks:?}");
        let joined = tracks[0].iter().flatten().count();
        assert_eq!(joined, host.len() + 3 + 2);
        assert!(tracks[0][14].is_some_and(|g| (g[0] - 48.5).abs() < 1e-9));
        assert!(tracks[0][29].is_some_and(|g| (g[0] - 47.5).abs() < 1e-9));
    }

    #[test]
    fn a_piece_past_a_strayed_end_joins_along_the_drift_despite_a_wrong_first_block() {
        // A groove drifting 1 px a block whose track strayed 9 px for its last three blocks
        // (dust), and the rest of the groove found as a piece that starts with a wrong
        // pairing 12 px off. Held at the track's end the piece would lie 10–40 px off.
        let drift = 1.0;
        let on_groove = |b: usize| 50.0 + drift * b as f64;
        let mut host = vec![None; 40];
        for (b, slot) in host.iter_mut().enumerate().take(13) {
            let c = on_groove(b) - if b >= 10 { 9.0 } else { 0.0 };
            *slot = Some([c - 2.0, c - 1.0, c + 1.0, c + 2.0]);
        }
        let mut piece = vec![None; 40];
        for (b, slot) in piece.iter_mut().enumerate().skip(12).take(12) {
            let c = on_groove(b) + if b == 12 { 12.0 } else { 0.0 };
            *slot = Some([c - 2.0, c - 1.0, c + 1.0, c + 2.0]);
        }
        let neighbour = track(90.0, &(14..22).collect::<Vec<_>>(), 40);
        let mut tracks = vec![host.clone(), piece.clone(), neighbour];
        absorb_pieces(&mut tracks, 6.0, drift);
        assert_eq!(tracks.len(), 2, "{tracks:?}");
        assert_eq!(tracks[0].iter().flatten().count(), 24);
        // Without the drift the piece stays a groove of its own.
        let mut tracks = vec![host, piece];
        absorb_pieces(&mut tracks, 6.0, 0.0);
        assert_eq!(tracks.len(), 2);
    }
}
