//! From border tracks to sound: fit screening, robust outlier rejection, marked and
//! interpolated gaps, displacement to velocity along the groove's arc, and a uniform signal at
//! Vt / pixel.
//!
//! - **Screening**: a fit whose contrast is under half or over twice its border's median, whose
//!   residual is over three times the median (plus a grey level floor) or whose standard error
//!   is over four times the median is dropped (dust, text, scratches).
//! - **Consistency** (robust σ from the median absolute deviation, `outlier_sigmas` of them):
//!   in a lateral cut all four borders move together, so each border is compared with the
//!   median of the line's borders after their slowly varying offsets (medians over
//!   [`OFFSET_BLOCK_LINES`]) are taken out; in a stereo cut the bottom borders move with the
//!   mid (L + R)/2 only, so the two bottoms must agree with each other, and their mean with the
//!   mean of the land borders; when only the land borders disagree, the one whose fit is
//!   further from its border's typical fit is dropped.
//! - **Channels**: lateral: the inverse-variance mean of the borders' motions; stereo: each
//!   wall's land border (rebuilt from the other land border and the bottoms where it is lost).
//!   Displacement counts toward the left-hand side of the direction time runs; the left wall is
//!   the wall on that side.
//! - **Gaps**: lines without a value are listed and bridged linearly.
//! - **Velocity**: v = cos²θ·Vt·∂d/∂n, with θ the groove's angle to the lines (its centre path
//!   smoothed over `path_smoothing_um`): cross displacement → perpendicular, lines → arc
//!   length; stereo channels × sin(wall angle). The signal is then interpolated (4-point
//!   Lagrange) onto a uniform arc-length grid of one pixel, i.e. Vt / pixel samples per second.

use super::track::BorderTracks;
use super::{Axis, StillError, StillParams, StillSetup};
use crate::io::Cut;
use crate::pipeline::median;

/// Lines per block of the slowly varying border offsets.
pub const OFFSET_BLOCK_LINES: usize = 256;
/// Floor of a border's robust σ (px): below it, noise is not what rejects a fit.
const SIGMA_FLOOR_PX: f64 = 0.02;
/// MAD to σ for normal noise.
const MAD_TO_SIGMA: f64 = 1.4826;
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

/// Lines of one channel without a value, bridged by interpolation.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize)]
pub struct LineGap {
    /// Channel (0: mono or left, 1: right).
    pub channel: usize,
    /// First line (in time order).
    pub start_line: usize,
    /// Lines.
    pub lines: usize,
}

/// The sound of one groove of a still.
#[derive(Clone, Debug, PartialEq)]
pub struct StillSignal {
    /// Samples per second: Vt / pixel size.
    pub native_rate_hz: f64,
    /// Velocity (mm/s) per channel (1 lateral, 2 stereo: left wall, right wall), uniform in
    /// arc length, in time order.
    pub channels: Vec<Vec<f32>>,
    /// Displacement toward the left-hand side per channel and line (px, time order, offsets
    /// not removed, gaps bridged).
    pub displacement_px: Vec<Vec<f64>>,
    /// Gaps bridged.
    pub gaps: Vec<LineGap>,
    /// Per border (land|wall, wall|bottom, bottom|wall, wall|land across the image): lines
    /// fitted, fits dropped by screening, fits rejected as outliers.
    pub border_counts: [[usize; 3]; 4],
    /// The left wall is the high-cross one (right of a vertical still, bottom of a horizontal).
    pub left_wall_high_cross: bool,
}

/// Medians over blocks of `block` values, interpolated linearly between block centres.
fn slow_median(v: &[f64], block: usize) -> Vec<f64> {
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

/// Robust σ of the finite values (MAD around 0), floored.
fn robust_sigma(r: &[f64]) -> f64 {
    median(r.iter().filter(|x| x.is_finite()).map(|x| x.abs()).collect())
        .map_or(SIGMA_FLOOR_PX, |m| (MAD_TO_SIGMA * m).max(SIGMA_FLOOR_PX))
}

/// Border `i`'s screened positions and how many were dropped; with each kept fit's deviation
/// from its border's typical fit (the larger of its contrast's log-ratio and residual ratio).
fn screened(tracks: &BorderTracks, i: usize) -> (Vec<f64>, Vec<f64>, usize) {
    let fits: Vec<_> = tracks.fits.iter().map(|f| f[i]).collect();
    let med = |g: &dyn Fn(&super::track::BorderFit) -> f64| median(fits.iter().flatten().map(g).collect());
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
fn reject_lateral(x: &mut [Vec<f64>; 4], k: f64, rejected: &mut [usize; 4]) -> Vec<f64> {
    let lines = x[0].len();
    let present: Vec<usize> = (0..4).filter(|&i| x[i].iter().any(|v| v.is_finite())).collect();
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
            if moved.len() < 3.min(present.len()) || moved.len() < 2 {
                continue;
            }
            let Some(d) = median_mid(&moved) else { continue };
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
fn reject_stereo(
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
        let rel: Vec<f64> = bottom_mid.iter().zip(&land_mid).map(|(b, l)| b - l).collect();
        bottom_mid_off = slow_median(&rel, OFFSET_BLOCK_LINES);
        let mres: Vec<f64> = rel.iter().zip(&bottom_mid_off).map(|(a, b)| a - b).collect();
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
                // The bottoms agree: a land border is off; drop the less typical fit.
                let drop = match (dev[0][n], dev[3][n]) {
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
    let lo: Vec<f64> = (0..lines)
        .map(|n| if x[0][n].is_finite() { x[0][n] } else { rebuild(&x[3], n) })
        .collect();
    let hi: Vec<f64> = (0..lines)
        .map(|n| if x[3][n].is_finite() { x[3][n] } else { rebuild(&x[0], n) })
        .collect();
    [lo, hi]
}

/// The slow median of `a − b` at line `n` over its offset block.
fn slow_at(a: &[f64], b: &[f64], n: usize) -> f64 {
    let block = n / OFFSET_BLOCK_LINES;
    let lo = block * OFFSET_BLOCK_LINES;
    let hi = (lo + OFFSET_BLOCK_LINES).min(a.len());
    median((lo..hi).map(|j| a[j] - b[j]).filter(|v| v.is_finite()).collect()).unwrap_or(f64::NAN)
}

/// Bridges the NaN runs of `v` linearly (held at the ends) and lists them.
fn bridge(v: &mut [f64], channel: usize, gaps: &mut Vec<LineGap>) -> bool {
    let n = v.len();
    let Some(first) = v.iter().position(|x| x.is_finite()) else {
        return false;
    };
    let mut last_good = first;
    if first > 0 {
        gaps.push(LineGap { channel, start_line: 0, lines: first });
        let f = v[first];
        v[..first].fill(f);
    }
    let mut i = first + 1;
    while i < n {
        if v[i].is_finite() {
            last_good = i;
            i += 1;
            continue;
        }
        let start = i;
        while i < n && !v[i].is_finite() {
            i += 1;
        }
        gaps.push(LineGap { channel, start_line: start, lines: i - start });
        let a = v[last_good];
        if i < n {
            let b = v[i];
            let span = (i - last_good) as f64;
            for j in start..i {
                v[j] = a + (b - a) * (j - last_good) as f64 / span;
            }
        } else {
            v[start..].fill(a);
        }
    }
    true
}

/// Interim differentiator (per sample) until the shared designed one lands: the five-point
/// central difference (−x₊₂ + 8x₊₁ − 8x₋₁ + x₋₂)/12, exact to 4th order, three- and two-point
/// differences at the ends.
fn differentiate(x: &[f64]) -> Vec<f64> {
    let n = x.len();
    (0..n)
        .map(|i| {
            let at = |d: isize| x[(i as isize + d) as usize];
            if i >= 2 && i + 2 < n {
                (-at(2) + 8.0 * at(1) - 8.0 * at(-1) + at(-2)) / 12.0
            } else if i >= 1 && i + 1 < n {
                0.5 * (at(1) - at(-1))
            } else if i + 1 < n {
                at(1) - at(0)
            } else if i >= 1 {
                at(0) - at(-1)
            } else {
                0.0
            }
        })
        .collect()
}

/// 4-point Lagrange interpolation of `(s, v)` (s increasing) at `q`.
fn lagrange(s: &[f64], v: &[f64], q: f64) -> f64 {
    let n = s.len();
    let i = s.partition_point(|x| *x <= q).clamp(1, n.max(2) - 1);
    let lo = i.saturating_sub(2).min(n.saturating_sub(4));
    let hi = (lo + 4).min(n);
    let mut out = 0.0;
    for j in lo..hi {
        let mut w = 1.0;
        for m in lo..hi {
            if m != j {
                w *= (q - s[m]) / (s[j] - s[m]);
            }
        }
        out += w * v[j];
    }
    out
}

/// Moving average over `2·half + 1` samples (shrinking at the ends).
fn moving_average(v: &[f64], half: usize) -> Vec<f64> {
    let n = v.len();
    let mut prefix = Vec::with_capacity(n + 1);
    prefix.push(0.0);
    for x in v {
        prefix.push(prefix.last().copied().unwrap_or(0.0) + x);
    }
    (0..n)
        .map(|i| {
            let (a, b) = (i.saturating_sub(half), (i + half + 1).min(n));
            (prefix[b] - prefix[a]) / (b - a) as f64
        })
        .collect()
}

/// Decodes a groove's border tracks into its sound (see the module docs).
///
/// # Errors
/// [`StillError::NoGroove`] when no line of a channel could be measured.
pub fn decode_borders(
    tracks: &BorderTracks,
    setup: &StillSetup,
    params: &StillParams,
) -> Result<StillSignal, StillError> {
    setup.validate()?;
    let lines = tracks.lines;
    let mut border_counts = [[0usize; 3]; 4];
    let mut x: [Vec<f64>; 4] = Default::default();
    let mut dev: [Vec<f64>; 4] = Default::default();
    for i in 0..4 {
        border_counts[i][0] = tracks.fits.iter().filter(|f| f[i].is_some()).count();
        let (xi, di, dropped) = screened(tracks, i);
        x[i] = xi;
        dev[i] = di;
        border_counts[i][1] = dropped;
    }
    let mut rejected = [0usize; 4];
    let k = params.outlier_sigmas;
    // Left-hand side of the direction time runs, in cross coordinates.
    let left_sign = match (setup.axis, setup.reverse) {
        (Axis::Vertical, false) | (Axis::Horizontal, true) => 1.0,
        _ => -1.0,
    };
    let mut channels_cross: Vec<Vec<f64>> = match setup.cut {
        Cut::Stereo => {
            let [lo, hi] = reject_stereo(&mut x, &dev, k, &mut rejected);
            if left_sign > 0.0 { vec![hi, lo] } else { vec![lo, hi] }
        }
        _ => vec![reject_lateral(&mut x, k, &mut rejected)],
    };
    for i in 0..4 {
        border_counts[i][2] = rejected[i];
    }
    if setup.reverse {
        for c in &mut channels_cross {
            c.reverse();
        }
    }
    let mut gaps = Vec::new();
    for (c, v) in channels_cross.iter_mut().enumerate() {
        if !bridge(v, c, &mut gaps) {
            return Err(StillError::NoGroove {
                looked: format!(
                    "the groove was found but none of its {lines} lines gave a usable border{}",
                    if c == 1 { " for the right wall" } else { "" }
                ),
            });
        }
    }
    // The path's angle to the lines, time order.
    let mut centre: Vec<f64> = tracks.predicted.iter().map(|p| 0.5 * (p[0] + p[3])).collect();
    if setup.reverse {
        centre.reverse();
    }
    let half = (0.5 * params.path_smoothing_um / setup.um_per_px).round() as usize;
    let path = moving_average(&centre, half);
    let slope: Vec<f64> = (0..lines)
        .map(|n| {
            let a = path[n.saturating_sub(1)];
            let b = path[(n + 1).min(lines - 1)];
            let span = ((n + 1).min(lines - 1) - n.saturating_sub(1)).max(1) as f64;
            (b - a) / span
        })
        .collect();
    let sec: Vec<f64> = slope.iter().map(|s| s.hypot(1.0)).collect();
    let mut arc = Vec::with_capacity(lines);
    let mut s = 0.0;
    for n in 0..lines {
        if n > 0 {
            s += 0.5 * (sec[n - 1] + sec[n]);
        }
        arc.push(s);
    }
    let vt_mm_s = setup.groove_speed_um_s() / 1000.0;
    let wall_gain = if setup.cut == Cut::Stereo {
        params.wall_angle_deg.to_radians().sin()
    } else {
        1.0
    };
    let grid = arc.last().copied().unwrap_or(0.0).floor() as usize + 1;
    let mut channels = Vec::with_capacity(channels_cross.len());
    let mut displacement_px = Vec::with_capacity(channels_cross.len());
    for cross in &channels_cross {
        let d: Vec<f64> = cross.iter().map(|v| left_sign * v).collect();
        let dd = differentiate(&d);
        let v: Vec<f64> = dd
            .iter()
            .zip(&sec)
            .map(|(g, s)| g / (s * s) * vt_mm_s * wall_gain)
            .collect();
        let uniform: Vec<f32> = (0..grid).map(|q| lagrange(&arc, &v, q as f64) as f32).collect();
        channels.push(uniform);
        displacement_px.push(d);
    }
    Ok(StillSignal {
        native_rate_hz: setup.groove_speed_um_s() / setup.um_per_px,
        channels,
        displacement_px,
        gaps,
        border_counts,
        left_wall_high_cross: left_sign > 0.0,
    })
}
