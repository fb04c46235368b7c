//! Outlier rejection on a groove's border tracks: fit screening, continuity (short runs that
//! jump off a border's course), and consistency between the borders of each line.
//!
//! - **Screening**: a fit whose contrast is under half or over twice its border's median, whose
//!   residual is over three times the median (plus a grey level floor) or whose standard error
//!   is over four times the median is dropped (dust, text, scratches).
//! - **Continuity**: each border's track is cut wherever it jumps by more than
//!   `outlier_sigmas` robust σ of its line-to-line steps (and at least [`JUMP_FLOOR_PX`]); runs of
//!   at least [`ANCHOR_LINES`] lines are its course, and a shorter run is kept only when it
//!   stays within that jump of the course interpolated across it (text and specks lock the fit
//!   onto their own edges for a few lines).
//! - **Consistency** (robust σ from the median absolute deviation): in a lateral cut all four
//!   borders move together, so each border is compared with the median of the line's borders
//!   after their slowly varying offsets (medians over [`OFFSET_BLOCK_LINES`]) are taken out (two
//!   that disagree are both dropped); in a stereo cut the bottom borders move with the mid
//!   (L + R)/2 only, so the two bottoms must agree with each other, and their mean with the
//!   mean of the land borders; when only the land borders disagree, the one whose fit is
//!   further from its border's typical fit is dropped.

use super::track::BorderTracks;
use crate::pipeline::median;

/// Lines per block of the slowly varying border offsets.
pub const OFFSET_BLOCK_LINES: usize = 256;
/// Floor of a border's robust σ (px): below it, noise is not what rejects a fit.
const SIGMA_FLOOR_PX: f64 = 0.02;
/// Fit screening limits (see the module docs).
const CONTRAST_RANGE: (f64, f64) = (0.5, 2.0);
/// See [`CONTRAST_RANGE`].
const RESIDUAL_FACTOR: f64 = 3.0;
/// See [`CONTRAST_RANGE`] (grey level).
const RESIDUAL_FLOOR: f64 = 0.01;
/// See [`CONTRAST_RANGE`].
const STD_ERROR_FACTOR: f64 = 4.0;
/// Consistency rounds.
const ROUNDS: usize = 2;
/// Smallest jump (px) that cuts a border's track.
pub const JUMP_FLOOR_PX: f64 = 1.0;
/// Runs at least this long are a border's course.
pub const ANCHOR_LINES: usize = 48;
/// Lines on each side of a line whose course [`local_residual`] fits, and lines next to it
/// it leaves out (a speck spoils several neighbouring lines).
const LOCAL_HALF: usize = 32;
/// See [`LOCAL_HALF`].
const LOCAL_HOLE: usize = 6;
/// One land border leaves its course this many times more than the other: it is the bad one.
const LOCAL_RATIO: f64 = 2.0;
/// Missing lines a run may bridge and stay one run.
const RUN_BRIDGE_LINES: usize = 3;

/// Continuity: drops the short runs of `x` that jump off its course (see the module docs);
/// returns how many values were dropped.
pub(crate) fn reject_jumps(x: &mut [f64], k: f64) -> usize {
    let finite: Vec<usize> = (0..x.len()).filter(|&n| x[n].is_finite()).collect();
    let steps: Vec<f64> = finite
        .windows(2)
        .filter(|w| w[1] - w[0] == 1)
        .map(|w| x[w[1]] - x[w[0]])
        .collect();
    let jump = (k * robust_sigma(&steps)).max(JUMP_FLOOR_PX);
    // Runs: (first, last) line, continuous within `jump` per line across short holes.
    let mut runs: Vec<(usize, usize)> = Vec::new();
    for &n in &finite {
        match runs.last_mut() {
            Some((_, last))
                if n - *last <= RUN_BRIDGE_LINES + 1
                    && (x[n] - x[*last]).abs() <= jump * (n - *last) as f64 =>
            {
                *last = n;
            }
            _ => runs.push((n, n)),
        }
    }
    let len = |r: &(usize, usize)| r.1 - r.0 + 1;
    let longest = runs.iter().map(len).max().unwrap_or(0);
    let anchor = |r: &(usize, usize)| len(r) >= ANCHOR_LINES.min(longest);
    let anchors: Vec<(usize, usize)> = runs.iter().copied().filter(anchor).collect();
    let mut dropped = 0;
    for r in runs.iter().filter(|r| !anchor(r)) {
        let before = anchors
            .iter()
            .rev()
            .find(|a| a.1 < r.0)
            .map(|a| (a.1, x[a.1]));
        let after = anchors.iter().find(|a| a.0 > r.1).map(|a| (a.0, x[a.0]));
        let course = |n: usize| match (before, after) {
            (Some((na, a)), Some((nb, b))) => a + (b - a) * (n - na) as f64 / (nb - na) as f64,
            (Some((_, a)), None) => a,
            (None, Some((_, b))) => b,
            (None, None) => x[n],
        };
        let off = median(
            (r.0..=r.1)
                .filter(|&n| x[n].is_finite())
                .map(|n| x[n] - course(n))
                .collect(),
        )
        .unwrap_or(0.0);
        if off.abs() > jump {
            for v in &mut x[r.0..=r.1] {
                if v.is_finite() {
                    *v = f64::NAN;
                    dropped += 1;
                }
            }
        }
    }
    dropped
}

/// Medians over blocks of `block` values, interpolated linearly between block centres.
pub(crate) fn slow_median(v: &[f64], block: usize) -> Vec<f64> {
    let centres: Vec<(f64, f64)> = v
        .chunks(block)
        .enumerate()
        .filter_map(|(b, c)| {
            let m = median(c.iter().copied().filter(|x| x.is_finite()).collect())?;
            Some(((b * block) as f64 + 0.5 * (c.len() as f64 - 1.0), m))
        })
        .collect();
    (0..v.len())
        .map(|n| {
            let x = n as f64;
            let i = centres.partition_point(|c| c.0 <= x);
            match (centres.get(i.wrapping_sub(1)), centres.get(i)) {
                (Some(a), Some(b)) => a.1 + (x - a.0) / (b.0 - a.0) * (b.1 - a.1),
                (Some(a), None) | (None, Some(a)) => a.1,
                (None, None) => f64::NAN,
            }
        })
        .collect()
}

/// Robust σ of the finite values (MAD around 0), floored at [`SIGMA_FLOOR_PX`].
pub(crate) fn robust_sigma(r: &[f64]) -> f64 {
    crate::pipeline::robust_sigma(r, SIGMA_FLOOR_PX)
}

/// Border `i`'s screened positions and how many were dropped; with each kept fit's deviation
/// from its border's typical fit (the larger of its contrast's log-ratio and residual ratio).
pub(crate) fn screened(tracks: &BorderTracks, i: usize) -> (Vec<f64>, Vec<f64>, usize) {
    let fits: Vec<_> = tracks.fits.iter().map(|f| f[i]).collect();
    let med = |g: &dyn Fn(&super::track::BorderFit) -> f64| {
        median(fits.iter().flatten().map(g).collect())
    };
    let (Some(c), Some(r), Some(s)) = (
        med(&|b| b.contrast.abs()),
        med(&|b| b.residual_rms),
        med(&|b| b.std_error_px),
    ) else {
        return (vec![f64::NAN; fits.len()], vec![f64::NAN; fits.len()], 0);
    };
    let mut dropped = 0;
    let mut x = Vec::with_capacity(fits.len());
    let mut dev = Vec::with_capacity(fits.len());
    for f in &fits {
        let Some(b) = f else {
            x.push(f64::NAN);
            dev.push(f64::NAN);
            continue;
        };
        let ratio = b.contrast.abs() / c.max(f64::MIN_POSITIVE);
        let ok = (CONTRAST_RANGE.0..=CONTRAST_RANGE.1).contains(&ratio)
            && b.residual_rms <= RESIDUAL_FACTOR * r + RESIDUAL_FLOOR
            && b.std_error_px <= STD_ERROR_FACTOR * s;
        if ok {
            x.push(b.position_px);
            dev.push(ratio.ln().abs().max(b.residual_rms / (r + RESIDUAL_FLOOR)));
        } else {
            dropped += 1;
            x.push(f64::NAN);
            dev.push(f64::NAN);
        }
    }
    (x, dev, dropped)
}

/// Lateral cut: each border against the median motion of the line's borders.
pub(crate) fn reject_lateral(x: &mut [Vec<f64>; 4], k: f64, rejected: &mut [usize; 4]) -> Vec<f64> {
    let lines = x[0].len();
    let present: Vec<usize> = (0..4)
        .filter(|&i| x[i].iter().any(|v| v.is_finite()))
        .collect();
    let mut offsets: Vec<Vec<f64>> = vec![vec![0.0; lines]; 4];
    let mut sigmas = [SIGMA_FLOOR_PX; 4];
    for _ in 0..ROUNDS {
        let mean: Vec<f64> = (0..lines)
            .map(|n| {
                let v: Vec<f64> = present.iter().map(|&i| x[i][n]).collect();
                if v.iter().all(|a| a.is_finite()) {
                    v.iter().sum::<f64>() / v.len() as f64
                } else {
                    f64::NAN
                }
            })
            .collect();
        for &i in &present {
            let rel: Vec<f64> = x[i].iter().zip(&mean).map(|(a, m)| a - m).collect();
            offsets[i] = slow_median(&rel, OFFSET_BLOCK_LINES);
        }
        let mut resid: Vec<Vec<f64>> = vec![vec![f64::NAN; lines]; 4];
        for n in 0..lines {
            let moved: Vec<f64> = present
                .iter()
                .map(|&i| x[i][n] - offsets[i][n])
                .filter(|v| v.is_finite())
                .collect();
            // Two borders that disagree are both rejected (their residuals are ±half the gap).
            if moved.len() < 2 {
                continue;
            }
            let Some(d) = median_mid(&moved) else {
                continue;
            };
            for &i in &present {
                resid[i][n] = x[i][n] - offsets[i][n] - d;
            }
        }
        for &i in &present {
            sigmas[i] = robust_sigma(&resid[i]);
            for n in 0..lines {
                if resid[i][n].abs() > k * sigmas[i] {
                    x[i][n] = f64::NAN;
                    rejected[i] += 1;
                }
            }
        }
    }
    (0..lines)
        .map(|n| {
            let (mut s, mut w) = (0.0, 0.0);
            for &i in &present {
                let v = x[i][n] - offsets[i][n];
                if v.is_finite() {
                    let wi = 1.0 / (sigmas[i] * sigmas[i]);
                    s += wi * v;
                    w += wi;
                }
            }
            if w > 0.0 { s / w } else { f64::NAN }
        })
        .collect()
}

/// The median of a few values (mean of the middle two for an even count).
fn median_mid(v: &[f64]) -> Option<f64> {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let n = s.len();
    match n {
        0 => None,
        _ if n % 2 == 1 => Some(s[n / 2]),
        _ => Some(0.5 * (s[n / 2 - 1] + s[n / 2])),
    }
}

/// Stereo cut: the bottoms against each other and their mean against the lands' mean; returns
/// the low-cross and high-cross walls' land border positions (rebuilt where lost).
pub(crate) fn reject_stereo(
    x: &mut [Vec<f64>; 4],
    dev: &[Vec<f64>; 4],
    k: f64,
    rejected: &mut [usize; 4],
) -> [Vec<f64>; 2] {
    let lines = x[0].len();
    let has_bottoms = x[1].iter().any(|v| v.is_finite()) && x[2].iter().any(|v| v.is_finite());
    if !has_bottoms {
        return [x[0].clone(), x[3].clone()];
    }
    let mut bottom_mid_off = vec![f64::NAN; lines];
    for _ in 0..ROUNDS {
        // The bottoms agree with each other.
        let width: Vec<f64> = (0..lines).map(|n| x[2][n] - x[1][n]).collect();
        let wslow = slow_median(&width, OFFSET_BLOCK_LINES);
        let wres: Vec<f64> = width.iter().zip(&wslow).map(|(a, b)| a - b).collect();
        let ws = robust_sigma(&wres);
        let land_mid: Vec<f64> = (0..lines).map(|n| 0.5 * (x[0][n] + x[3][n])).collect();
        let bottom_mid: Vec<f64> = (0..lines).map(|n| 0.5 * (x[1][n] + x[2][n])).collect();
        let rel: Vec<f64> = bottom_mid
            .iter()
            .zip(&land_mid)
            .map(|(b, l)| b - l)
            .collect();
        bottom_mid_off = slow_median(&rel, OFFSET_BLOCK_LINES);
        let mres: Vec<f64> = rel
            .iter()
            .zip(&bottom_mid_off)
            .map(|(a, b)| a - b)
            .collect();
        let ms = robust_sigma(&mres);
        for n in 0..lines {
            if wres[n].abs() > k * ws {
                // One bottom is off: drop the one further from what the lands say.
                let b1_off = slow_at(&x[1], &land_mid, n);
                let b2_off = slow_at(&x[2], &land_mid, n);
                let e1 = (x[1][n] - land_mid[n] - b1_off).abs();
                let e2 = (x[2][n] - land_mid[n] - b2_off).abs();
                let drop = if e1.is_finite() && e2.is_finite() {
                    if e1 > e2 { vec![1] } else { vec![2] }
                } else {
                    vec![1, 2]
                };
                for i in drop {
                    x[i][n] = f64::NAN;
                    rejected[i] += 1;
                }
            } else if mres[n].abs() > k * ms {
                // The bottoms agree: a land border is off. Drop the one that leaves its own
                // course more (or, when that does not tell, the less typical fit).
                let (e0, e3) = (local_residual(&x[0], n), local_residual(&x[3], n));
                let drop =
                    match (dev[0][n], dev[3][n]) {
                        _ if e0.is_finite() && e3.is_finite() && e0 > LOCAL_RATIO * e3 => vec![0],
                        _ if e0.is_finite() && e3.is_finite() && e3 > LOCAL_RATIO * e0 => vec![3],
                        (a, b) if a.is_finite() && b.is_finite() && (a - b).abs() > 0.1 => {
                            if a > b { vec![0] } else { vec![3] }
                        }
                        _ => vec![0, 3],
                    };
                for i in drop {
                    x[i][n] = f64::NAN;
                    rejected[i] += 1;
                }
            }
        }
    }
    // A lost land border from the other one and the bottoms: lo + hi = 2·(bottom mid − offset).
    let rebuild = |other: &[f64], n: usize| {
        let mid = 0.5 * (x[1][n] + x[2][n]) - bottom_mid_off[n];
        2.0 * mid - other[n]
    };
    // Land border `own` where it was found, else rebuilt from land border `other`.
    let kept_or_rebuilt = |own: usize, other: usize| -> Vec<f64> {
        (0..lines)
            .map(|n| {
                if x[own][n].is_finite() {
                    x[own][n]
                } else {
                    rebuild(&x[other], n)
                }
            })
            .collect()
    };
    [kept_or_rebuilt(0, 3), kept_or_rebuilt(3, 0)]
}

/// |x[n] − q(n)| for the least-squares quadratic q through the finite values within
/// [`LOCAL_HALF`] lines of `n` but more than [`LOCAL_HOLE`] away; NaN with too few of them.
fn local_residual(x: &[f64], n: usize) -> f64 {
    let lo = n.saturating_sub(LOCAL_HALF);
    let hi = (n + LOCAL_HALF + 1).min(x.len());
    let mut m = [[0.0f64; 3]; 3];
    let mut r = [0.0f64; 3];
    let mut count = 0;
    for (j, &y) in x.iter().enumerate().take(hi).skip(lo) {
        if j.abs_diff(n) <= LOCAL_HOLE || !y.is_finite() {
            continue;
        }
        let u = (j as f64 - n as f64) / LOCAL_HALF as f64;
        let p = [1.0, u, u * u];
        for a in 0..3 {
            r[a] += p[a] * y;
            for b in 0..3 {
                m[a][b] += p[a] * p[b];
            }
        }
        count += 1;
    }
    if count < 8 || !x.get(n).is_some_and(|v| v.is_finite()) {
        return f64::NAN;
    }
    // q(0) is the constant coefficient: Cramer's rule on its column.
    let det = |m: &[[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(&m);
    if d.abs() < 1e-12 {
        return f64::NAN;
    }
    let mut m0 = m;
    for (row, v) in m0.iter_mut().zip(r) {
        row[0] = v;
    }
    (x[n] - det(&m0) / d).abs()
}

/// The slow median of `a − b` at line `n` over its offset block.
fn slow_at(a: &[f64], b: &[f64], n: usize) -> f64 {
    let block = n / OFFSET_BLOCK_LINES;
    let lo = block * OFFSET_BLOCK_LINES;
    let hi = (lo + OFFSET_BLOCK_LINES).min(a.len());
    median(
        (lo..hi)
            .map(|j| a[j] - b[j])
            .filter(|v| v.is_finite())
            .collect(),
    )
    .unwrap_or(f64::NAN)
}
