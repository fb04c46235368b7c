//! From per-column bands to a wall line: bands that disagree with their neighbours dropped, trimmed, voids filled.

use super::*;

/// Keeps each column's band only when it agrees with the median band of the nearby columns.
pub(super) fn reject_spurious(
    tops: &[f32],
    bottoms: &[f32],
    window: usize,
) -> Vec<Option<(f32, f32)>> {
    let n = tops.len();
    let half = window / 2;
    (0..n)
        .into_par_iter()
        .map_init(
            || (Vec::new(), Vec::new()),
            |(ts, bs), x| {
                let (Some(&t), Some(&b)) = (tops.get(x), bottoms.get(x)) else {
                    return None;
                };
                if !(t.is_finite() && b.is_finite()) {
                    return None;
                }
                let lo = x.saturating_sub(half);
                let hi = (x + half).min(n - 1);
                ts.clear();
                bs.clear();
                for j in lo..=hi {
                    if let (Some(&tj), Some(&bj)) = (tops.get(j), bottoms.get(j))
                        && tj.is_finite()
                        && bj.is_finite()
                    {
                        ts.push(tj);
                        bs.push(bj);
                    }
                }
                if (ts.len() as f32) < MIN_WINDOW_SHARE * (hi + 1 - lo) as f32 {
                    return None;
                }
                let (mt, mb) = (median_in_place(ts)?, median_in_place(bs)?);
                let tol = MIN_TOLERANCE_PX.max(TOLERANCE_SHARE * (mb - mt));
                ((t - mt).abs() <= tol && (b - mb).abs() <= tol).then_some((t, b))
            },
        )
        .collect()
}

/// Builds a [`WallLine`] from per-column bands: trims, then fills voids by linear
/// interpolation (nearest value past the ends). None when no column has a band.
pub(super) fn build_line(
    side: WallSide,
    bands: &[Option<(f32, f32)>],
    trim_px: usize,
) -> Option<WallLine> {
    let trim = trim_px as f32;
    let mut rows: Vec<f32> = Vec::with_capacity(bands.len());
    let mut half: Vec<f32> = Vec::with_capacity(bands.len());
    for b in bands {
        let (r, h) = match *b {
            Some((t, btm)) if (btm - t) / 2.0 - trim >= 0.0 => {
                ((t + btm) / 2.0, (btm - t) / 2.0 - trim)
            }
            _ => (f32::NAN, f32::NAN),
        };
        rows.push(r);
        half.push(h);
    }
    let known: Vec<usize> = (0..rows.len())
        .filter(|&x| rows.get(x).is_some_and(|r| r.is_finite()))
        .collect();
    let (&first, &last) = (known.first()?, known.last()?);
    let mut filled = vec![false; rows.len()];
    let mut k = 0; // index into `known` of the last known column at or before x
    for x in 0..rows.len() {
        if rows.get(x).is_some_and(|r| r.is_finite()) {
            while known.get(k + 1).is_some_and(|&j| j <= x) {
                k += 1;
            }
            continue;
        }
        let (a, b) = if x < first {
            (first, first)
        } else if x > last {
            (last, last)
        } else {
            (
                known.get(k).copied().unwrap_or(first),
                known.get(k + 1).copied().unwrap_or(last),
            )
        };
        let t = if b > a {
            (x - a) as f32 / (b - a) as f32
        } else {
            0.0
        };
        let lerp = |v: &[f32]| {
            let (va, vb) = (
                v.get(a).copied().unwrap_or(f32::NAN),
                v.get(b).copied().unwrap_or(f32::NAN),
            );
            va + (vb - va) * t
        };
        let (r, h) = (lerp(&rows), lerp(&half));
        if let (Some(ro), Some(ho), Some(fo)) =
            (rows.get_mut(x), half.get_mut(x), filled.get_mut(x))
        {
            *ro = r;
            *ho = h;
            *fo = true;
        }
    }
    Some(WallLine {
        side,
        rows,
        half_width_px: half,
        depth_um: None,
        projection_depth_um: None,
        filled,
    })
}
