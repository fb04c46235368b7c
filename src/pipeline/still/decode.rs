//! From border tracks to sound: outliers rejected ([`super::clean`]), gaps marked and bridged,
//! the slow path taken out, displacement turned into velocity along the groove's arc, and a
//! uniform signal at Vt / pixel.
//!
//! - **Channels**: lateral: the inverse-variance mean of the borders' motions; stereo: each
//!   wall's land border (rebuilt from the other land border and the bottoms where it is lost).
//!   Displacement counts toward the left-hand side of the direction time runs; the left wall is
//!   the wall on that side.
//! - **Gaps**: lines without a value are listed and bridged linearly.
//! - **Path**: skew, the record's curvature and slow drift move the whole groove across the
//!   image; that slow part of each channel is a least-squares quadratic over windows of
//!   `path_window_um` (half-overlapping, blended linearly; one quadratic for a shorter still)
//!   and is taken out. Its slope gives the groove's angle θ to the lines.
//! - **Velocity**: v = cos²θ·Vt·∂d/∂n: cross displacement → perpendicular, lines → arc length;
//!   stereo channels × sin(wall angle). The signal is then interpolated (4-point Lagrange)
//!   onto a uniform arc-length grid of one pixel, i.e. Vt / pixel samples per second.

use super::clean::{reject_jumps, reject_lateral, reject_stereo, screened};
use super::track::BorderTracks;
use super::{Axis, StillError, StillParams, StillSetup};
use crate::meta::Cut;
use crate::pipeline::StageError;

/// Path windows overlap by half; a window's weight falls linearly from its centre.
const PATH_WINDOW_OVERLAP: usize = 2;
/// Fewest lines the slow-path window may span (`still.path_window_um` over the pixel size).
const MIN_PATH_WINDOW_LINES: usize = 64;

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
    /// Displacement toward the left-hand side per channel and line (px, time order, the slow
    /// path taken out, gaps bridged).
    pub displacement_px: Vec<Vec<f64>>,
    /// Gaps bridged.
    pub gaps: Vec<LineGap>,
    /// Per border (land|wall, wall|bottom, bottom|wall, wall|land across the image): lines
    /// fitted, fits dropped by screening, fits rejected as outliers.
    pub border_counts: [[usize; 3]; 4],
    /// Lines of each channel rejected for jumping off its course after the borders were combined.
    pub channel_rejected: Vec<usize>,
    /// The left wall is the high-cross one (right of a vertical still, bottom of a horizontal).
    pub left_wall_high_cross: bool,
}

/// Bridges the NaN runs of `v` linearly (held at the ends) and lists them.
fn bridge(v: &mut [f64], channel: usize, gaps: &mut Vec<LineGap>) -> bool {
    let n = v.len();
    let Some(first) = v.iter().position(|x| x.is_finite()) else {
        return false;
    };
    let mut last_good = first;
    if first > 0 {
        gaps.push(LineGap {
            channel,
            start_line: 0,
            lines: first,
        });
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
        gaps.push(LineGap {
            channel,
            start_line: start,
            lines: i - start,
        });
        let a = v[last_good];
        if i < n {
            let b = v[i];
            let span = (i - last_good) as f64;
            for (j, vj) in v.iter_mut().enumerate().take(i).skip(start) {
                *vj = a + (b - a) * (j - last_good) as f64 / span;
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

/// [`crate::pipeline::lagrange`] of `(s, v)` (s increasing) at `q` through the (up to) four
/// samples around it.
fn lagrange_near(s: &[f64], v: &[f64], q: f64) -> f64 {
    let n = s.len();
    let i = s.partition_point(|x| *x <= q).clamp(1, n.max(2) - 1);
    let lo = i.saturating_sub(2).min(n.saturating_sub(4));
    let hi = (lo + 4).min(n);
    let mut nodes = [(0.0, 0.0); 4];
    for (node, j) in nodes.iter_mut().zip(lo..hi) {
        *node = (s[j], v[j]);
    }
    crate::pipeline::lagrange(&nodes[..hi - lo], q)
}

/// Least-squares quadratic through `v[range]`, evaluated there: (values, slopes per sample).
fn quadratic_fit(v: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let n = v.len();
    let half = 0.5 * (n as f64 - 1.0);
    let scale = half.max(1.0);
    // Normal equations in u = (i − half)/scale ∈ [−1, 1].
    let mut m = [[0.0f64; 3]; 3];
    let mut r = [0.0f64; 3];
    for (i, &y) in v.iter().enumerate() {
        let u = (i as f64 - half) / scale;
        let p = [1.0, u, u * u];
        for a in 0..3 {
            r[a] += p[a] * y;
            for b in 0..3 {
                m[a][b] += p[a] * p[b];
            }
        }
    }
    let det = |m: &[[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(&m);
    let coef: [f64; 3] = if n >= 3 && d.abs() > 1e-12 {
        std::array::from_fn(|k| {
            let mut mk = m;
            for row in 0..3 {
                mk[row][k] = r[row];
            }
            det(&mk) / d
        })
    } else {
        [v.iter().sum::<f64>() / n.max(1) as f64, 0.0, 0.0]
    };
    (0..n)
        .map(|i| {
            let u = (i as f64 - half) / scale;
            (
                coef[0] + coef[1] * u + coef[2] * u * u,
                (coef[1] + 2.0 * coef[2] * u) / scale,
            )
        })
        .unzip()
}

/// The slow path of `v`: quadratics over half-overlapping windows of `window` samples blended
/// linearly (one quadratic when `v` is no longer): (values, slopes per sample).
fn slow_path(v: &[f64], window: usize) -> (Vec<f64>, Vec<f64>) {
    let n = v.len();
    if n <= window.max(3) {
        return quadratic_fit(v);
    }
    let hop = (window / PATH_WINDOW_OVERLAP).max(1);
    let mut starts: Vec<usize> = (0..)
        .map(|k| k * hop)
        .take_while(|s| s + window < n)
        .collect();
    starts.push(n - window);
    let (mut val, mut slope, mut weight) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    for &s0 in &starts {
        let (f, g) = quadratic_fit(&v[s0..s0 + window]);
        let centre = s0 as f64 + 0.5 * (window as f64 - 1.0);
        for i in 0..window {
            let w = (1.0 - ((s0 + i) as f64 - centre).abs() / (0.5 * window as f64)).max(1e-6);
            val[s0 + i] += w * f[i];
            slope[s0 + i] += w * g[i];
            weight[s0 + i] += w;
        }
    }
    for i in 0..n {
        val[i] /= weight[i];
        slope[i] /= weight[i];
    }
    (val, slope)
}

/// Decodes a groove's border tracks into its sound (see the module docs).
///
/// # Errors
/// [`StillError::NoBorders`] when no line of a channel could be measured.
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
    for i in 0..4 {
        rejected[i] += reject_jumps(&mut x[i], k);
    }
    // Left-hand side of the direction time runs, in cross coordinates.
    let left_sign = match (setup.axis, setup.reverse) {
        (Axis::Vertical, false) | (Axis::Horizontal, true) => 1.0,
        _ => -1.0,
    };
    let mut channels_cross: Vec<Vec<f64>> = match setup.cut {
        Cut::Stereo => {
            let [lo, hi] = reject_stereo(&mut x, &dev, k, &mut rejected);
            if left_sign > 0.0 {
                vec![hi, lo]
            } else {
                vec![lo, hi]
            }
        }
        _ => vec![reject_lateral(&mut x, k, &mut rejected)],
    };
    for i in 0..4 {
        border_counts[i][2] = rejected[i];
    }
    // The combined channels too: a few lines where the surviving borders agree on a wrong
    // place (text over the whole groove) jump off the channel's course.
    let channel_rejected: Vec<usize> = channels_cross
        .iter_mut()
        .map(|c| reject_jumps(c, k))
        .collect();
    if setup.reverse {
        for c in &mut channels_cross {
            c.reverse();
        }
    }
    let mut gaps = Vec::new();
    for (c, v) in channels_cross.iter_mut().enumerate() {
        if !bridge(v, c, &mut gaps) {
            return Err(StillError::NoBorders {
                lines,
                wall: if c == 1 { " for the right wall" } else { "" },
                min_contrast: params.border.min_contrast,
            });
        }
    }
    let window = (params.path_window_um / setup.um_per_px).round() as usize;
    if window < MIN_PATH_WINDOW_LINES {
        // A quadratic over so few lines follows the sound itself and takes it all out.
        return Err(StillError::Param(StageError::InvalidParam {
            name: "still.path_window_um".into(),
            problem: format!(
                "{} µm spans {window} lines of {} µm; the slow-path fit needs at least \
                 {MIN_PATH_WINDOW_LINES}, or it removes the sound with the path",
                params.path_window_um, setup.um_per_px
            ),
        }));
    }
    let paths: Vec<(Vec<f64>, Vec<f64>)> = channels_cross
        .iter()
        .map(|c| slow_path(c, window))
        .collect();
    // The groove's angle to the lines: the mean slope of its channels' paths.
    let sec: Vec<f64> = (0..lines)
        .map(|n| {
            let s = paths.iter().map(|p| p.1[n]).sum::<f64>() / paths.len().max(1) as f64;
            s.hypot(1.0)
        })
        .collect();
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
    for (cross, (path, _)) in channels_cross.iter().zip(&paths) {
        let d: Vec<f64> = cross
            .iter()
            .zip(path)
            .map(|(v, p)| left_sign * (v - p))
            .collect();
        let dd = differentiate(&d);
        let v: Vec<f64> = dd
            .iter()
            .zip(&sec)
            .map(|(g, s)| g / (s * s) * vt_mm_s * wall_gain)
            .collect();
        let uniform: Vec<f32> = (0..grid)
            .map(|q| lagrange_near(&arc, &v, q as f64) as f32)
            .collect();
        channels.push(uniform);
        displacement_px.push(d);
    }
    Ok(StillSignal {
        native_rate_hz: setup.native_rate_hz(),
        channels,
        displacement_px,
        gaps,
        border_counts,
        channel_rejected,
        left_wall_high_cross: left_sign > 0.0,
    })
}
