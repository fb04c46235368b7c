//! Sound from wall tilt: V = Vt·tan θ per wall, channels by cut, stitching of overlapping groups and resampling.
//!
//! Stitching puts every group on one uniform grid of groove positions. Each group is
//! interpolated onto the grid points inside its span by a cubic Lagrange polynomial through
//! the four nearest samples (linear or quadratic where the group ends or a gap is near). Cubic
//! rather than linear because groups sample the groove at different sub-grid offsets: linear
//! interpolation attenuates a tone by a different amount in each group (−2% at 3 kHz and a half
//! sample offset), which is an amplitude modulation at the group rate, i.e. a buzz; the cubic's
//! error is ~100× smaller. Where groups overlap their values are cross-faded: a group's weight
//! ramps linearly from 0 at its first/last sample to 1 over the length of its overlap with its
//! neighbours, and the weights are normalised, so two overlapping groups fade linearly into each
//! other over their whole overlap and a seam never clicks.

use std::f64::consts::SQRT_2;
use std::ops::Range;

use rubato::{
    Resampler, SincFixedIn, SincInterpolationParameters, SincInterpolationType, WindowFunction,
    calculate_cutoff,
};
use serde::{Deserialize, Serialize};

use super::orientation::{Orientation, OrientationSample};
use super::walls::WallSide;
use super::{StageError, check_range};
use crate::io::Cut;

/// Two sample columns closer than this (px) are the same column when the walls are combined.
const SAME_COLUMN_TOL_PX: f64 = 1e-3;
/// Smallest cross-fade weight inside a group's span (its very first/last sample would get 0,
/// which would leave a point covered only there without data).
const MIN_FADE_WEIGHT: f64 = 1e-6;
/// Largest stitched signal (samples per channel), against runaway allocations from a tiny spacing.
const MAX_STITCH_SAMPLES: f64 = 268_435_456.0;
/// Grid points this close (in spacings) outside a group's span still count as inside it.
const SPAN_TOL_SPACINGS: f64 = 1e-9;
/// Sinc length of the resampler (input samples) when upsampling; scaled by the ratio when
/// downsampling so the filter spans as many output samples.
const SINC_LEN_BASE: usize = 256;
/// Cap on the downsampling sinc length.
const SINC_LEN_MAX: usize = 4096;
/// Oversampling of the tabulated sinc (cubic interpolation between table entries).
const SINC_OVERSAMPLING: usize = 128;
/// Input frames per resampler call.
const RESAMPLE_CHUNK: usize = 4096;
/// Leading zeros tried so that the resampler's delay is a whole number of output samples.
const DELAY_PAD_SEARCH: usize = 4096;

/// Knobs of the sound stage.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SoundParams {
    /// Output sample rate (44 100 or 48 000 Hz).
    pub output_rate_hz: u32,
    /// Spacing of the native (pre-resampling) samples along the groove; 0 = one output sample.
    pub native_spacing_um: f64,
    /// Peak level after normalisation (0 < p ≤ 1); 0 keeps velocity scaled by `full_scale_mm_s`.
    pub normalize_peak: f32,
    /// Velocity mapped to full scale when not normalising (mm/s).
    pub full_scale_mm_s: f64,
}

impl Default for SoundParams {
    fn default() -> Self {
        Self {
            output_rate_hz: 44_100,
            native_spacing_um: 0.0,
            normalize_peak: 0.89,
            full_scale_mm_s: 100.0,
        }
    }
}

impl SoundParams {
    /// The native grid spacing to stitch on (µm): `native_spacing_um`, or when that is 0 the
    /// groove length of one output sample, Vt·1000/`output_rate_hz` (then no resampling is needed).
    ///
    /// # Errors
    /// [`StageError::InvalidParam`] for a negative/NaN spacing, a zero rate or a non-positive Vt.
    pub fn spacing_um(&self, groove_speed_mm_s: f64) -> Result<f64, StageError> {
        check_range(
            "sound.native_spacing_um",
            self.native_spacing_um,
            0.0,
            f64::MAX,
        )?;
        if self.native_spacing_um > 0.0 {
            return Ok(self.native_spacing_um);
        }
        check_range(
            "groove_speed_mm_s",
            groove_speed_mm_s,
            f64::MIN_POSITIVE,
            f64::MAX,
        )?;
        if self.output_rate_hz == 0 {
            return Err(StageError::InvalidParam {
                name: "sound.output_rate_hz".to_string(),
                problem: "0 Hz".to_string(),
            });
        }
        Ok(groove_speed_mm_s * 1000.0 / f64::from(self.output_rate_hz))
    }

    /// Scales velocity channels (mm/s) to output level in place and returns the gain applied:
    /// with `normalize_peak` > 0 the largest |sample| over all channels becomes it (silence is
    /// left alone, gain 1); with 0 `full_scale_mm_s` maps to 1.0. Non-finite samples become 0.
    ///
    /// # Errors
    /// [`StageError::InvalidParam`] when `normalize_peak` is outside [0, 1] or NaN, or
    /// `full_scale_mm_s` is not positive while not normalising.
    pub fn scale_to_output(&self, channels: &mut [Vec<f32>]) -> Result<f32, StageError> {
        check_range(
            "sound.normalize_peak",
            f64::from(self.normalize_peak),
            0.0,
            1.0,
        )?;
        for v in channels.iter_mut().flatten() {
            if !v.is_finite() {
                *v = 0.0;
            }
        }
        let gain = if self.normalize_peak > 0.0 {
            let peak = channels
                .iter()
                .flatten()
                .fold(0.0f32, |m, v| m.max(v.abs()));
            if peak > 0.0 {
                self.normalize_peak / peak
            } else {
                1.0
            }
        } else {
            check_range(
                "sound.full_scale_mm_s",
                self.full_scale_mm_s,
                f64::MIN_POSITIVE,
                f64::MAX,
            )?;
            #[allow(clippy::cast_possible_truncation)] // a gain
            let g = (1.0 / self.full_scale_mm_s) as f32;
            g
        };
        for v in channels.iter_mut().flatten() {
            *v *= gain;
        }
        Ok(gain)
    }
}

/// The sound of one group: wall velocity (mm/s) at positions along the groove.
#[derive(Clone, Debug, PartialEq)]
pub struct GroupSignal {
    /// Group index.
    pub group: usize,
    /// Groove position of each sample (µm from the scan start), increasing.
    pub positions_um: Vec<f64>,
    /// One buffer per output channel (1 mono, 2 stereo), velocity in mm/s; NaN = gap.
    pub channels: Vec<Vec<f32>>,
    /// Groove speed Vt at this group (mm/s).
    pub groove_speed_mm_s: f64,
}

/// One wall's samples as (column, tan θ) sorted by column; NaN tan θ marks a gap.
fn wall_track(samples: &[OrientationSample]) -> Vec<(f64, f64)> {
    let mut track: Vec<(f64, f64)> = samples
        .iter()
        .filter(|s| s.x_px.is_finite())
        .map(|s| {
            let t = if s.fit.is_some() && s.tan_theta.is_finite() {
                s.tan_theta
            } else {
                f64::NAN
            };
            (f64::from(s.x_px), t)
        })
        .collect();
    track.sort_by(|a, b| a.0.total_cmp(&b.0));
    track
}

/// tan θ of a wall track at column `x`: its sample there, else linear interpolation between
/// its neighbours (NaN if either is a gap or `x` is outside the track).
fn track_at(track: &[(f64, f64)], x: f64) -> f64 {
    let i = track.partition_point(|s| s.0 < x - SAME_COLUMN_TOL_PX);
    let Some(&(xi, ti)) = track.get(i) else {
        return f64::NAN;
    };
    if (xi - x).abs() <= SAME_COLUMN_TOL_PX {
        return ti;
    }
    let Some(&(xp, tp)) = i.checked_sub(1).and_then(|j| track.get(j)) else {
        return f64::NAN;
    };
    tp + (ti - tp) * (x - xp) / (xi - xp)
}

/// Turns a group's wall orientation into velocity samples.
///
/// Stereo: left wall → channel 0, right wall → channel 1 (a wall not measured gives a NaN
/// channel). Lateral: (tanθ_L + tanθ_R)/√2 where both walls are measured, √2·tanθ of the one
/// wall where only one is (a lateral groove displacement d(X) gives tanθ_L = tanθ_R = d′/√2, so
/// both read d′). Vertical: (tanθ_R − tanθ_L)/√2, or ±√2·tanθ of one wall. Velocity = Vt·that.
/// Samples are taken at the union of both walls' columns (a wall without a sample at a column
/// is linearly interpolated between its neighbours); a gap (no fit, NaN) stays NaN. Column x
/// maps to `column0_um + x·um_per_px`.
///
/// # Errors
/// [`StageError`] when the orientation has no wall, a wall appears twice, or a number is
/// NaN or non-positive.
pub fn group_signal(
    group: usize,
    orientation: &Orientation,
    cut: Cut,
    column0_um: f64,
    um_per_px: f64,
    groove_speed_mm_s: f64,
) -> Result<GroupSignal, StageError> {
    check_range("column0_um", column0_um, f64::MIN, f64::MAX)?;
    check_range("um_per_px", um_per_px, f64::MIN_POSITIVE, f64::MAX)?;
    check_range(
        "groove_speed_mm_s",
        groove_speed_mm_s,
        f64::MIN_POSITIVE,
        f64::MAX,
    )?;
    if orientation.walls.is_empty() {
        return Err(StageError::NotFound {
            stage: "sound",
            problem: format!("group {group}: no wall orientation to make sound from"),
        });
    }
    let mut left: Option<Vec<(f64, f64)>> = None;
    let mut right: Option<Vec<(f64, f64)>> = None;
    for wall in &orientation.walls {
        let slot = match wall.side {
            WallSide::Left => &mut left,
            WallSide::Right => &mut right,
        };
        if slot.is_some() {
            return Err(StageError::BadInput {
                stage: "sound",
                problem: format!("group {group}: the {:?} wall appears twice", wall.side),
            });
        }
        *slot = Some(wall_track(&wall.samples));
    }
    let mut columns: Vec<f64> = left
        .iter()
        .chain(right.iter())
        .flat_map(|t| t.iter().map(|s| s.0))
        .collect();
    columns.sort_by(f64::total_cmp);
    columns.dedup_by(|b, a| (*b - *a).abs() <= SAME_COLUMN_TOL_PX);

    let at = |track: &Option<Vec<(f64, f64)>>, x: f64| {
        track.as_deref().map_or(f64::NAN, |t| track_at(t, x))
    };
    let vt = groove_speed_mm_s;
    #[allow(clippy::cast_possible_truncation)] // velocities are stored as f32
    let to_f32 = |v: f64| (v * vt) as f32;
    let n = columns.len();
    let channels = match cut {
        Cut::Stereo => {
            let mut l = Vec::with_capacity(n);
            let mut r = Vec::with_capacity(n);
            for &x in &columns {
                l.push(to_f32(at(&left, x)));
                r.push(to_f32(at(&right, x)));
            }
            vec![l, r]
        }
        Cut::Lateral | Cut::Vertical => {
            let sign_l = if cut == Cut::Lateral { 1.0 } else { -1.0 };
            let mono = columns
                .iter()
                .map(|&x| {
                    let (tl, tr) = (at(&left, x), at(&right, x));
                    let v = match (tl.is_finite(), tr.is_finite()) {
                        (true, true) => (sign_l * tl + tr) / SQRT_2,
                        (true, false) => sign_l * SQRT_2 * tl,
                        (false, true) => SQRT_2 * tr,
                        (false, false) => f64::NAN,
                    };
                    to_f32(v)
                })
                .collect();
            vec![mono]
        }
    };
    let positions_um = columns
        .iter()
        .map(|&x| column0_um + x * um_per_px)
        .collect();
    Ok(GroupSignal {
        group,
        positions_um,
        channels,
        groove_speed_mm_s,
    })
}

/// A continuous signal on a uniform grid of groove positions.
#[derive(Clone, Debug, PartialEq)]
pub struct StitchedSignal {
    /// Position of sample 0 (µm).
    pub start_um: f64,
    /// Sample spacing (µm).
    pub spacing_um: f64,
    /// Native sample rate = Vt / spacing (Hz).
    pub native_rate_hz: f64,
    /// Channels, velocity mm/s (gaps filled with 0 and listed in `gaps`).
    pub channels: Vec<Vec<f32>>,
    /// Sample ranges where at least one channel had no data (filled with silence), merged.
    pub gaps: Vec<Range<usize>>,
}

/// Lagrange interpolation at `p` through the nodes `(x, y)` (2 to 4 of them).
fn lagrange(nodes: &[(f64, f64)], p: f64) -> f64 {
    let mut sum = 0.0;
    for (i, &(xi, yi)) in nodes.iter().enumerate() {
        let mut basis = 1.0;
        for (j, &(xj, _)) in nodes.iter().enumerate() {
            if i != j {
                basis *= (p - xj) / (xi - xj);
            }
        }
        sum += basis * yi;
    }
    sum
}

/// Value of one group channel at `p`, which lies in segment `[pos[j], pos[j+1]]`: a cubic through
/// four consecutive finite samples around the segment (centred j−1..=j+2 where possible,
/// one-sided at a group end or next to a gap), else a quadratic, else linear. None when either
/// segment end is a gap.
fn interpolate(pos: &[f64], val: &[f32], j: usize, p: f64) -> Option<f64> {
    let ok = |k: usize| val.get(k).is_some_and(|v| v.is_finite());
    if !ok(j) || !ok(j + 1) {
        return None;
    }
    // Candidate first nodes, most centred first, for 4 then 3 nodes.
    let window = [(4usize, 1usize), (4, 0), (4, 2), (3, 1), (3, 0), (2, 0)]
        .into_iter()
        .find_map(|(len, back)| {
            let lo = j.checked_sub(back)?;
            (lo..lo + len).all(ok).then_some((lo, len))
        });
    let (lo, len) = window.unwrap_or((j, 2));
    let mut nodes = [(0.0, 0.0); 4];
    for (node, k) in nodes.iter_mut().zip(lo..lo + len) {
        *node = (*pos.get(k)?, f64::from(*val.get(k)?));
    }
    Some(lagrange(&nodes[..len], p))
}

/// Stitches group signals onto one uniform grid from the smallest to the largest sample
/// position, cross-fading where groups overlap so seams do not click (see the module docs).
/// Grid points no group covers are 0 and listed in `gaps`. The native rate uses the mean Vt.
///
/// # Errors
/// [`StageError`] when there are no groups or samples, channel counts or lengths differ, a
/// position is NaN, or the spacing is not positive.
#[allow(clippy::too_many_lines)] // one pass: validate, size the grid, accumulate, normalise
pub fn stitch(groups: &[GroupSignal], spacing_um: f64) -> Result<StitchedSignal, StageError> {
    check_range(
        "sound.native_spacing_um",
        spacing_um,
        f64::MIN_POSITIVE,
        f64::MAX,
    )?;
    let bad = |problem: String| StageError::BadInput {
        stage: "stitch",
        problem,
    };
    let Some(first) = groups.first() else {
        return Err(bad("no groups".to_string()));
    };
    let n_channels = first.channels.len();
    if n_channels == 0 {
        return Err(bad(format!("group {} has no channel", first.group)));
    }
    let (mut lo_um, mut hi_um) = (f64::INFINITY, f64::NEG_INFINITY);
    let (mut vt_sum, mut vt_count) = (0.0, 0.0);
    for g in groups {
        if g.channels.len() != n_channels {
            return Err(bad(format!(
                "group {} has {} channels, group {} has {n_channels}",
                g.group,
                g.channels.len(),
                first.group
            )));
        }
        if g.channels.iter().any(|c| c.len() != g.positions_um.len()) {
            return Err(bad(format!(
                "group {}: channel and position lengths differ",
                g.group
            )));
        }
        if g.positions_um.iter().any(|p| !p.is_finite())
            || g.positions_um.windows(2).any(|w| w[1] < w[0])
        {
            return Err(bad(format!(
                "group {}: positions must be finite and increasing",
                g.group
            )));
        }
        if let (Some(&a), Some(&b)) = (g.positions_um.first(), g.positions_um.last()) {
            lo_um = lo_um.min(a);
            hi_um = hi_um.max(b);
        }
        if g.groove_speed_mm_s.is_finite() && g.groove_speed_mm_s > 0.0 {
            vt_sum += g.groove_speed_mm_s;
            vt_count += 1.0;
        }
    }
    if !lo_um.is_finite() {
        return Err(bad("no samples in any group".to_string()));
    }
    if vt_count == 0.0 {
        return Err(bad("no group has a positive groove speed".to_string()));
    }
    let steps = ((hi_um - lo_um) / spacing_um + SPAN_TOL_SPACINGS).floor();
    if steps.is_nan() || steps >= MAX_STITCH_SAMPLES {
        return Err(StageError::InvalidParam {
            name: "sound.native_spacing_um".to_string(),
            problem: format!(
                "{spacing_um} µm over {} µm makes more than {MAX_STITCH_SAMPLES} samples",
                hi_um - lo_um
            ),
        });
    }
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // checked above
    let n = steps as usize + 1;

    // Each group's cross-fade ramp: its longest overlap with another group, at least one spacing
    // and at most half its span.
    let spans: Vec<(f64, f64)> = groups
        .iter()
        .map(|g| match (g.positions_um.first(), g.positions_um.last()) {
            (Some(&a), Some(&b)) => (a, b),
            _ => (f64::NAN, f64::NAN),
        })
        .collect();
    let mut order: Vec<usize> = (0..groups.len())
        .filter(|&i| spans[i].0.is_finite())
        .collect();
    order.sort_by(|&a, &b| spans[a].0.total_cmp(&spans[b].0));
    let mut overlap = vec![0.0f64; groups.len()];
    for (k, &i) in order.iter().enumerate() {
        for &j in &order[k + 1..] {
            if spans[j].0 >= spans[i].1 {
                break;
            }
            let ov = spans[i].1.min(spans[j].1) - spans[j].0;
            overlap[i] = overlap[i].max(ov);
            overlap[j] = overlap[j].max(ov);
        }
    }

    let mut sums = vec![vec![0.0f64; n]; n_channels];
    let mut weights = vec![vec![0.0f64; n]; n_channels];
    let tol_um = SPAN_TOL_SPACINGS * spacing_um;
    for (gi, g) in groups.iter().enumerate() {
        let (a, b) = spans[gi];
        if !a.is_finite() || g.positions_um.len() < 2 {
            // A lone sample: it lands on the nearest grid point only if it is on one.
            if let (Some(&p), true) = (g.positions_um.first(), g.positions_um.len() == 1) {
                let k = ((p - lo_um) / spacing_um).round();
                if ((lo_um + k * spacing_um) - p).abs() <= tol_um {
                    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                    let k = k as usize;
                    for (c, ch) in g.channels.iter().enumerate() {
                        if let Some(&v) = ch.first().filter(|v| v.is_finite())
                            && k < n
                        {
                            sums[c][k] += MIN_FADE_WEIGHT * f64::from(v);
                            weights[c][k] += MIN_FADE_WEIGHT;
                        }
                    }
                }
            }
            continue;
        }
        let ramp_um = overlap[gi]
            .max(spacing_um)
            .min(((b - a) / 2.0).max(spacing_um));
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // inside 0..n
        let k0 = ((a - lo_um - tol_um) / spacing_um).ceil().max(0.0) as usize;
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let k1 = (((b - lo_um + tol_um) / spacing_um).floor().max(0.0) as usize).min(n - 1);
        let pos = &g.positions_um;
        let mut j = 0usize;
        #[allow(clippy::cast_precision_loss)] // grid indices ≤ 2^28
        for k in k0..=k1 {
            let p = (lo_um + k as f64 * spacing_um).clamp(a, b);
            while j + 2 < pos.len() && pos[j + 1] < p {
                j += 1;
            }
            let w = ((p - a).min(b - p) / ramp_um).clamp(MIN_FADE_WEIGHT, 1.0);
            for (c, ch) in g.channels.iter().enumerate() {
                if let Some(v) = interpolate(pos, ch, j, p) {
                    sums[c][k] += w * v;
                    weights[c][k] += w;
                }
            }
        }
    }

    let mut gaps: Vec<Range<usize>> = Vec::new();
    let mut channels = vec![vec![0.0f32; n]; n_channels];
    for k in 0..n {
        let mut missing = false;
        for c in 0..n_channels {
            let w = weights[c][k];
            if w > 0.0 {
                #[allow(clippy::cast_possible_truncation)] // audio samples are f32
                {
                    channels[c][k] = (sums[c][k] / w) as f32;
                }
            } else {
                missing = true;
            }
        }
        if missing {
            match gaps.last_mut() {
                Some(r) if r.end == k => r.end = k + 1,
                _ => gaps.push(k..k + 1),
            }
        }
    }
    let mean_vt = vt_sum / vt_count;
    Ok(StitchedSignal {
        start_um: lo_um,
        spacing_um,
        native_rate_hz: mean_vt * 1000.0 / spacing_um,
        channels,
        gaps,
    })
}

/// Delay of rubato's `SincFixedIn` (cubic sinc-table interpolation) in input samples: output n
/// is the input at time n/ratio − delay, with delay = 1 − 1/ratio − 1/oversampling (its first
/// output lies one output step after its start index, and the cubic table lookup is one table
/// step late). Measured, and checked by the `resampler_delay_is_exact` test for up- and
/// downsampling.
fn resampler_delay_in(ratio: f64) -> f64 {
    #[allow(clippy::cast_precision_loss)] // small
    let table_step = 1.0 / SINC_OVERSAMPLING as f64;
    1.0 - 1.0 / ratio - table_step
}

/// Band-limited resampling of one channel from `from_hz` to `to_hz` (rubato windowed-sinc,
/// cubic between table entries). The output has round(n·to/from) samples, aligned with the
/// input (output k is the input at time k/to): the resampler's latency is removed, its fractional
/// part by leading zeros chosen so that the delay is a whole number of output samples (to within
/// 1/`DELAY_PAD_SEARCH` sample for irrational ratios). Non-finite samples count as 0.
///
/// # Errors
/// [`StageError`] on non-positive or NaN rates, or a resampler failure.
pub fn resample(samples: &[f32], from_hz: f64, to_hz: u32) -> Result<Vec<f32>, StageError> {
    check_range("from_hz", from_hz, f64::MIN_POSITIVE, f64::MAX)?;
    if to_hz == 0 {
        return Err(StageError::InvalidParam {
            name: "sound.output_rate_hz".to_string(),
            problem: "0 Hz".to_string(),
        });
    }
    let clean = |v: &f32| if v.is_finite() { *v } else { 0.0 };
    let ratio = f64::from(to_hz) / from_hz;
    if samples.is_empty() {
        return Ok(Vec::new());
    }
    if (ratio - 1.0).abs() < 1e-12 {
        return Ok(samples.iter().map(clean).collect());
    }
    let fail = |e: &dyn std::fmt::Display| StageError::BadInput {
        stage: "resample",
        problem: e.to_string(),
    };
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // bounded by the cap
    let sinc_len = if ratio < 1.0 {
        ((SINC_LEN_BASE as f64 / ratio).ceil() as usize).min(SINC_LEN_MAX)
    } else {
        SINC_LEN_BASE
    }
    .div_ceil(8)
        * 8;
    let window = WindowFunction::BlackmanHarris2;
    let params = SincInterpolationParameters {
        sinc_len,
        f_cutoff: calculate_cutoff(sinc_len, window),
        interpolation: SincInterpolationType::Cubic,
        oversampling_factor: SINC_OVERSAMPLING,
        window,
    };
    let mut resampler =
        SincFixedIn::<f64>::new(ratio, 1.0, params, RESAMPLE_CHUNK, 1).map_err(|e| fail(&e))?;

    // Leading zeros so that (delay + pad)·ratio is (nearly) a whole number of output samples.
    // The delay may be negative (downsampling): start the search where it no longer is.
    let delay_in = resampler_delay_in(ratio);
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // a few samples
    let min_pad = (-delay_in).ceil().max(0.0) as usize;
    let frac_off = |pad: usize| {
        #[allow(clippy::cast_precision_loss)]
        let d = (delay_in + pad as f64) * ratio;
        (d - d.round()).abs()
    };
    let pad = (min_pad..min_pad + DELAY_PAD_SEARCH)
        .min_by(|&a, &b| frac_off(a).total_cmp(&frac_off(b)))
        .unwrap_or(min_pad);
    #[allow(
        clippy::cast_precision_loss,
        clippy::cast_possible_truncation,
        clippy::cast_sign_loss
    )]
    let delay_out = ((delay_in + pad as f64) * ratio).round() as usize;
    #[allow(
        clippy::cast_precision_loss,
        clippy::cast_possible_truncation,
        clippy::cast_sign_loss
    )]
    let target = (samples.len() as f64 * ratio).round() as usize;
    let needed = delay_out + target;

    let mut input = vec![0.0f64; pad];
    input.extend(samples.iter().map(|v| f64::from(clean(v))));
    let mut out: Vec<f64> = Vec::with_capacity(needed + RESAMPLE_CHUNK);
    let mut buf = resampler.output_buffer_allocate(true);
    let mut chunks = input.chunks_exact(RESAMPLE_CHUNK);
    for chunk in chunks.by_ref() {
        let (_, written) = resampler
            .process_into_buffer(&[chunk], &mut buf, None)
            .map_err(|e| fail(&e))?;
        out.extend_from_slice(buf.first().and_then(|b| b.get(..written)).unwrap_or(&[]));
    }
    let rest = chunks.remainder();
    if !rest.is_empty() {
        let (_, written) = resampler
            .process_partial_into_buffer(Some(&[rest]), &mut buf, None)
            .map_err(|e| fail(&e))?;
        out.extend_from_slice(buf.first().and_then(|b| b.get(..written)).unwrap_or(&[]));
    }
    // Flush the latency with silence; each call yields about RESAMPLE_CHUNK·ratio samples.
    let max_flushes = needed / (RESAMPLE_CHUNK / 2).max(1) + 4;
    for _ in 0..max_flushes {
        if out.len() >= needed {
            break;
        }
        let (_, written) = resampler
            .process_partial_into_buffer(None::<&[&[f64]]>, &mut buf, None)
            .map_err(|e| fail(&e))?;
        out.extend_from_slice(buf.first().and_then(|b| b.get(..written)).unwrap_or(&[]));
    }
    #[allow(clippy::cast_possible_truncation)] // audio samples are f32
    let result = out
        .get(delay_out..needed)
        .ok_or_else(|| fail(&"resampler produced too few samples"))?
        .iter()
        .map(|&v| v as f32)
        .collect();
    Ok(result)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests unwrap known-good results
mod tests {
    use super::*;
    use crate::image::Image;
    use crate::pipeline::dsp::magnitude_spectrum;
    use crate::pipeline::orientation::{PlaneFit, StopReason, WallOrientation};
    use std::f64::consts::PI;

    const VT_MM_S: f64 = 939.0;

    fn fit() -> PlaneFit {
        PlaneFit {
            a: 0.0,
            b: 1.0,
            c: 0.0,
            iterations: 1,
            outlier_fraction: 0.0,
            residual_um: 0.0,
            stop: StopReason::LeastSquares,
        }
    }

    fn wall(side: WallSide, xs: &[f32], tans: &[f64]) -> WallOrientation {
        WallOrientation {
            side,
            samples: xs
                .iter()
                .zip(tans)
                .map(|(&x_px, &tan_theta)| OrientationSample {
                    x_px,
                    tan_theta,
                    fit: tan_theta.is_finite().then(fit),
                })
                .collect(),
        }
    }

    fn orientation(walls: Vec<WallOrientation>) -> Orientation {
        Orientation {
            walls,
            weight_map: Image::zeros(1, 1),
            outlier_fraction: 0.0,
            rejected_fits: 0,
        }
    }

    #[test]
    fn lateral_motion_reads_the_same_from_one_or_both_walls() {
        let d = [0.02, -0.05, 0.1]; // d′ = lateral slope
        let t: Vec<f64> = d.iter().map(|v| v / SQRT_2).collect();
        let xs = [100.0f32, 155.0, 210.0];
        let both = orientation(vec![
            wall(WallSide::Left, &xs, &t),
            wall(WallSide::Right, &xs, &t),
        ]);
        let left = orientation(vec![wall(WallSide::Left, &xs, &t)]);
        let right = orientation(vec![wall(WallSide::Right, &xs, &t)]);
        for o in [&both, &left, &right] {
            let g = group_signal(3, o, Cut::Lateral, 1000.0, 0.39, VT_MM_S).unwrap();
            assert_eq!(g.channels.len(), 1);
            for (v, dv) in g.channels[0].iter().zip(d) {
                assert!(
                    (f64::from(*v) - VT_MM_S * dv).abs() < 1e-3,
                    "{v} vs {}",
                    VT_MM_S * dv
                );
            }
            assert_eq!(g.group, 3);
            assert!((g.positions_um[1] - (1000.0 + 155.0 * 0.39)).abs() < 1e-9);
        }
        // Pure lateral motion has no vertical component.
        let g = group_signal(0, &both, Cut::Vertical, 0.0, 0.39, VT_MM_S).unwrap();
        assert!(g.channels[0].iter().all(|v| v.abs() < 1e-4));
    }

    #[test]
    fn vertical_and_stereo_channels() {
        // Vertical motion h′: the walls tilt oppositely, tanθ_R = −tanθ_L = h′/√2.
        let h = [0.03, -0.07];
        let xs = [10.0f32, 60.0];
        let tr: Vec<f64> = h.iter().map(|v| v / SQRT_2).collect();
        let tl: Vec<f64> = tr.iter().map(|v| -v).collect();
        let o = orientation(vec![
            wall(WallSide::Right, &xs, &tr),
            wall(WallSide::Left, &xs, &tl),
        ]);
        let g = group_signal(0, &o, Cut::Vertical, 0.0, 1.0, VT_MM_S).unwrap();
        for (v, hv) in g.channels[0].iter().zip(h) {
            assert!((f64::from(*v) - VT_MM_S * hv).abs() < 1e-3);
        }
        for one in [
            orientation(vec![wall(WallSide::Left, &xs, &tl)]),
            orientation(vec![wall(WallSide::Right, &xs, &tr)]),
        ] {
            let g = group_signal(0, &one, Cut::Vertical, 0.0, 1.0, VT_MM_S).unwrap();
            for (v, hv) in g.channels[0].iter().zip(h) {
                assert!((f64::from(*v) - VT_MM_S * hv).abs() < 1e-3);
            }
        }
        // Stereo: left wall → ch0, right wall → ch1; a missing wall is a NaN channel.
        let g = group_signal(0, &o, Cut::Stereo, 0.0, 1.0, VT_MM_S).unwrap();
        assert!((f64::from(g.channels[0][0]) - VT_MM_S * tl[0]).abs() < 1e-3);
        assert!((f64::from(g.channels[1][1]) - VT_MM_S * tr[1]).abs() < 1e-3);
        let one = orientation(vec![wall(WallSide::Right, &xs, &tr)]);
        let g = group_signal(0, &one, Cut::Stereo, 0.0, 1.0, VT_MM_S).unwrap();
        assert!(g.channels[0].iter().all(|v| v.is_nan()));
        assert!(g.channels[1].iter().all(|v| v.is_finite()));
    }

    #[test]
    fn gaps_columns_and_errors() {
        // Walls sampled at different columns, unsorted, with a gap.
        let l = wall(
            WallSide::Left,
            &[200.0, 100.0, 300.0],
            &[0.1, 0.1, f64::NAN],
        );
        let r = wall(WallSide::Right, &[150.0, 250.0], &[0.1, 0.1]);
        let g = group_signal(0, &orientation(vec![l, r]), Cut::Lateral, 0.0, 1.0, 1.0).unwrap();
        assert_eq!(g.positions_um, vec![100.0, 150.0, 200.0, 250.0, 300.0]);
        // Column 300: left is a gap, right has no sample there → right... outside its track → NaN.
        let expected = [
            SQRT_2 * 0.1,
            2.0 * 0.1 / SQRT_2,
            2.0 * 0.1 / SQRT_2,
            SQRT_2 * 0.1,
        ];
        for (v, e) in g.channels[0].iter().zip(expected) {
            assert!((f64::from(*v) - e).abs() < 1e-6, "{v} vs {e}");
        }
        assert!(g.channels[0][4].is_nan());
        // A sample without a fit is a gap even if tan θ is finite.
        let mut w = wall(WallSide::Left, &[0.0, 1.0], &[0.1, 0.1]);
        w.samples[1].fit = None;
        let g = group_signal(0, &orientation(vec![w]), Cut::Lateral, 0.0, 1.0, 1.0).unwrap();
        assert!(g.channels[0][0].is_finite() && g.channels[0][1].is_nan());
        // Errors.
        assert!(group_signal(0, &orientation(vec![]), Cut::Lateral, 0.0, 1.0, 1.0).is_err());
        let twice = orientation(vec![
            wall(WallSide::Left, &[0.0], &[0.0]),
            wall(WallSide::Left, &[0.0], &[0.0]),
        ]);
        assert!(group_signal(0, &twice, Cut::Lateral, 0.0, 1.0, 1.0).is_err());
        let ok = orientation(vec![wall(WallSide::Left, &[0.0], &[0.0])]);
        assert!(group_signal(0, &ok, Cut::Lateral, f64::NAN, 1.0, 1.0).is_err());
        assert!(group_signal(0, &ok, Cut::Lateral, 0.0, 0.0, 1.0).is_err());
        assert!(group_signal(0, &ok, Cut::Lateral, 0.0, 1.0, -939.0).is_err());
    }

    /// Groups like real ones: `per_group` samples `sample_um` apart, each group starting
    /// `step_um` after the previous plus a fraction of a sample that differs per group.
    fn groups_of(
        count: usize,
        per_group: usize,
        sample_um: f64,
        step_um: f64,
        velocity: impl Fn(f64) -> f64,
        bias: impl Fn(usize) -> f64,
    ) -> Vec<GroupSignal> {
        (0..count)
            .map(|k| {
                // A low-discrepancy fraction in [0, 1).
                let frac = (k as f64 * 0.618_034).fract();
                let start = 5.0 + k as f64 * step_um + frac * sample_um;
                let positions_um: Vec<f64> = (0..per_group)
                    .map(|j| start + j as f64 * sample_um)
                    .collect();
                let ch = positions_um
                    .iter()
                    .map(|&p| (velocity(p) + bias(k)) as f32)
                    .collect();
                GroupSignal {
                    group: k,
                    positions_um,
                    channels: vec![ch],
                    groove_speed_mm_s: VT_MM_S,
                }
            })
            .collect()
    }

    /// Sine velocity of `freq_hz` at Vt (wavelength Vt/f along the groove), amplitude 50 mm/s.
    fn sine(freq_hz: f64) -> impl Fn(f64) -> f64 {
        let wavelength_um = VT_MM_S * 1000.0 / freq_hz;
        move |p: f64| 50.0 * (2.0 * PI * p / wavelength_um).sin()
    }

    #[test]
    fn stitched_sine_matches_within_1e_3() {
        // Paper-like numbers: 21.3 µm samples, 24 per group (≈ 490 µm), 460 µm group step.
        let spacing = VT_MM_S * 1000.0 / 44_100.0;
        for (freq, tol) in [(1000.0, 1e-3), (2000.0, 1e-3), (3000.0, 2e-3)] {
            let groups = groups_of(60, 24, 21.3, 460.0, sine(freq), |_| 0.0);
            let s = stitch(&groups, spacing).unwrap();
            assert!(s.gaps.is_empty(), "{:?}", s.gaps);
            assert!((s.native_rate_hz - 44_100.0).abs() < 1e-6);
            let f = sine(freq);
            let mut worst = 0.0f64;
            for (k, &v) in s.channels[0].iter().enumerate() {
                let p = s.start_um + k as f64 * spacing;
                worst = worst.max((f64::from(v) - f(p)).abs() / 50.0);
            }
            assert!(worst < tol, "{freq} Hz: worst relative error {worst}");
        }
    }

    /// Peak level (dB) over the median of its neighbourhood, around each harmonic of
    /// `period_samples`, ignoring bins near `skip_hz`.
    fn seam_line_db(x: &[f32], rate: f64, period_samples: f64, skip_hz: f64) -> f64 {
        let spec = magnitude_spectrum(x, rate);
        let bin_hz = spec[1].0;
        let mut worst = f64::MIN;
        for h in 1..=4 {
            let f = h as f64 * rate / period_samples;
            if f >= rate / 2.0 - 200.0 {
                break;
            }
            let centre = (f / bin_hz).round() as usize;
            let peak = spec[centre - 2..=centre + 2]
                .iter()
                .map(|b| b.1)
                .fold(f64::MIN, f64::max);
            let mut floor: Vec<f64> = spec
                [centre.saturating_sub(60)..(centre + 60).min(spec.len())]
                .iter()
                .filter(|b| (b.0 - f).abs() > 6.0 * bin_hz && (b.0 - skip_hz).abs() > 200.0)
                .map(|b| b.1)
                .collect();
            floor.sort_by(f64::total_cmp);
            worst = worst.max(peak - floor[floor.len() / 2]);
        }
        worst
    }

    #[test]
    fn per_group_bias_makes_no_seam_buzz() {
        let spacing = VT_MM_S * 1000.0 / 44_100.0;
        let step_um = 460.0;
        // Common tilt bias plus a small random part per group (as real groups have).
        let bias = |k: usize| 4.0 + 1.5 * ((k as f64 * 12.9898).sin() * 43_758.545).fract();
        let groups = groups_of(400, 24, 21.3, step_um, sine(1000.0), bias);
        let s = stitch(&groups, spacing).unwrap();
        assert!(s.gaps.is_empty());
        let period = step_um / spacing; // ≈ 21.6 samples: the buzz a bad stitch makes
        let mean =
            s.channels[0].iter().map(|&v| f64::from(v)).sum::<f64>() / s.channels[0].len() as f64;
        let x: Vec<f32> = s.channels[0]
            .iter()
            .map(|&v| (f64::from(v) - mean) as f32)
            .collect();
        let line = seam_line_db(&x, s.native_rate_hz, period, 1000.0);
        assert!(line < 10.0, "seam line {line} dB above the floor");
        // Control: a one-sample click of the bias size at every seam shows up far above the bar.
        let mut clicky = x.clone();
        for g in &groups[1..] {
            let k = ((g.positions_um[0] - s.start_um) / spacing).round() as usize;
            clicky[k] += 4.0;
        }
        let line = seam_line_db(&clicky, s.native_rate_hz, period, 1000.0);
        assert!(line > 20.0, "control click line only {line} dB");
    }

    #[test]
    fn missing_group_is_silence_and_a_gap() {
        let spacing = 20.0;
        let mut groups = groups_of(5, 25, 20.0, 460.0, |_| 1.0, |_| 0.0);
        groups.remove(2);
        let s = stitch(&groups, spacing).unwrap();
        assert_eq!(s.gaps.len(), 1, "{:?}", s.gaps);
        let gap = s.gaps[0].clone();
        // Group 1 ends near 5 + 460 + 0.24·20 + 480; group 3 starts near 5 + 1380 + ...
        let end1 = groups[1].positions_um.last().copied().unwrap();
        let start3 = groups[2].positions_um[0];
        let expected = (((end1 - s.start_um) / spacing).floor() as usize + 1)
            ..(((start3 - s.start_um) / spacing).ceil() as usize);
        assert_eq!(gap, expected);
        assert!(s.channels[0][gap.clone()].iter().all(|&v| v == 0.0));
        assert!(
            s.channels[0][..gap.start]
                .iter()
                .all(|&v| (v - 1.0).abs() < 1e-6)
        );
        assert!(
            s.channels[0][gap.end..]
                .iter()
                .all(|&v| (v - 1.0).abs() < 1e-6)
        );
        // A group of NaN (no fit) is a gap too, and other groups' overlap still fills its edges.
        let mut groups = groups_of(3, 25, 20.0, 460.0, |_| 1.0, |_| 0.0);
        groups[1].channels[0].iter_mut().for_each(|v| *v = f32::NAN);
        let s = stitch(&groups, spacing).unwrap();
        assert_eq!(s.gaps.len(), 1);
        assert!(s.gaps[0].len() > 15 && s.gaps[0].len() < 23, "{:?}", s.gaps);
    }

    #[test]
    fn stereo_gap_in_one_channel_is_listed() {
        let mut groups = groups_of(3, 25, 20.0, 460.0, |_| 1.0, |_| 0.0);
        for g in &mut groups {
            let c = g.channels[0].clone();
            g.channels.push(c);
        }
        groups[1].channels[1].iter_mut().for_each(|v| *v = f32::NAN);
        let s = stitch(&groups, 20.0).unwrap();
        assert_eq!(s.gaps.len(), 1);
        let r = s.gaps[0].clone();
        assert!(
            s.channels[0][r.clone()]
                .iter()
                .all(|&v| (v - 1.0).abs() < 1e-6)
        );
        assert!(s.channels[1][r].iter().all(|&v| v == 0.0));
    }

    #[test]
    fn stitch_rejects_bad_input() {
        let g = groups_of(2, 5, 20.0, 80.0, |_| 0.0, |_| 0.0);
        assert!(stitch(&[], 20.0).is_err());
        assert!(stitch(&g, 0.0).is_err());
        assert!(stitch(&g, f64::NAN).is_err());
        assert!(stitch(&g, 1e-9).is_err()); // absurd sample count
        let mut two = g.clone();
        let extra = two[1].channels[0].clone();
        two[1].channels.push(extra);
        assert!(stitch(&two, 20.0).is_err());
        let mut nan = g.clone();
        nan[0].positions_um[1] = f64::NAN;
        assert!(stitch(&nan, 20.0).is_err());
        let mut short = g;
        short[0].channels[0].pop();
        assert!(stitch(&short, 20.0).is_err());
    }

    fn tone(n: usize, freq: f64, rate: f64, amp: f64) -> Vec<f32> {
        (0..n)
            .map(|i| (amp * (2.0 * PI * freq * i as f64 / rate).sin()) as f32)
            .collect()
    }

    /// Least-squares amplitude and phase of `freq` in `x` at `rate`, over `range`.
    fn fit_sine(x: &[f32], freq: f64, rate: f64, range: Range<usize>) -> (f64, f64, f64) {
        let (mut ss, mut sc, mut cc, mut xs, mut xc) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for i in range.clone() {
            let (s, c) = (2.0 * PI * freq * i as f64 / rate).sin_cos();
            let v = f64::from(x[i]);
            ss += s * s;
            sc += s * c;
            cc += c * c;
            xs += v * s;
            xc += v * c;
        }
        let det = ss * cc - sc * sc;
        let a = (xs * cc - xc * sc) / det;
        let b = (xc * ss - xs * sc) / det;
        let mut resid = 0.0f64;
        for i in range {
            let (s, c) = (2.0 * PI * freq * i as f64 / rate).sin_cos();
            resid = resid.max((f64::from(x[i]) - a * s - b * c).abs());
        }
        ((a * a + b * b).sqrt(), b.atan2(a), resid)
    }

    #[test]
    fn resampled_tone_keeps_frequency_amplitude_and_timing() {
        let (from, to) = (43_800.0, 44_100u32);
        let x = tone(43_800, 1000.0, from, 0.5);
        let y = resample(&x, from, to).unwrap();
        assert_eq!(y.len(), 44_100);
        // Fit a 1 kHz sine at the output rate, away from the ends: amplitude within 1%, phase 0
        // (no delay), and a tiny residual (a wrong frequency would leave a large one).
        let (amp, phase, resid) = fit_sine(&y, 1000.0, f64::from(to), 2000..42_000);
        assert!((amp - 0.5).abs() < 0.005, "amplitude {amp}");
        assert!(phase.abs() < 0.003, "phase {phase} rad");
        assert!(resid < 0.005, "residual {resid}");
        // Frequency from zero crossings over the interior: within 1%.
        let crossings: Vec<usize> = (2001..42_000)
            .filter(|&i| y[i - 1] < 0.0 && y[i] >= 0.0)
            .collect();
        let per =
            (crossings[crossings.len() - 1] - crossings[0]) as f64 / (crossings.len() - 1) as f64;
        let f = f64::from(to) / per;
        assert!((f - 1000.0).abs() < 10.0, "{f} Hz");
    }

    #[test]
    fn resampler_delay_is_exact() {
        // Several ratios, up and down: a 500 Hz tone must come out in phase to < 1/100 sample.
        for &(from, to) in &[
            (44_714.285, 44_100u32),
            (43_800.0, 48_000),
            (96_000.0, 44_100),
            (200_000.0, 44_100),
        ] {
            let n = (from * 0.5) as usize;
            let x = tone(n, 500.0, from, 1.0);
            let y = resample(&x, from, to).unwrap();
            let expected = (n as f64 * f64::from(to) / from).round() as usize;
            assert_eq!(y.len(), expected);
            let m = y.len();
            let (amp, phase, _) = fit_sine(&y, 500.0, f64::from(to), m / 4..3 * m / 4);
            let shift_samples = phase / (2.0 * PI * 500.0) * f64::from(to);
            assert!(
                shift_samples.abs() < 0.01,
                "{from}->{to}: {shift_samples} samples"
            );
            assert!((amp - 1.0).abs() < 0.005, "{from}->{to}: amplitude {amp}");
        }
    }

    #[test]
    fn downsampling_removes_what_does_not_fit() {
        // 1 kHz + 30 kHz at 200 kHz to 44.1 kHz: the 30 kHz tone must not alias to 14.1 kHz.
        let from = 200_000.0;
        let n = 100_000;
        let x: Vec<f32> = tone(n, 1000.0, from, 0.5)
            .iter()
            .zip(tone(n, 30_000.0, from, 0.5))
            .map(|(a, b)| a + b)
            .collect();
        let y = resample(&x, from, 44_100).unwrap();
        let m = y.len();
        let (amp, _, _) = fit_sine(&y, 14_100.0, 44_100.0, m / 4..3 * m / 4);
        assert!(amp < 1e-3, "alias amplitude {amp}");
        let (amp, _, _) = fit_sine(&y, 1000.0, 44_100.0, m / 4..3 * m / 4);
        assert!((amp - 0.5).abs() < 0.005, "{amp}");
    }

    #[test]
    fn orientation_to_output_rate_end_to_end() {
        // A lateral 1 kHz tone read from both walls of 80 groups (1280 px frames, 0.39 µm/px,
        // a sample every 40 px, 1180 px group step), stitched on a 15 µm grid and resampled to
        // 44.1 kHz: it must line up with the analytic tone sample for sample.
        let um_per_px = 0.39;
        let wavelength_um = VT_MM_S * 1000.0 / 1000.0;
        let slope = |p_um: f64| 0.05 * (2.0 * PI * p_um / wavelength_um).cos(); // d′(X)
        let groups: Vec<GroupSignal> = (0..80)
            .map(|k| {
                let column0_um = k as f64 * 1180.0 * um_per_px;
                let xs: Vec<f32> = (0..32).map(|i| 7.0 + 40.0 * i as f32).collect();
                let t: Vec<f64> = xs
                    .iter()
                    .map(|&x| slope(column0_um + f64::from(x) * um_per_px) / SQRT_2)
                    .collect();
                let o = orientation(vec![
                    wall(WallSide::Left, &xs, &t),
                    wall(WallSide::Right, &xs, &t),
                ]);
                group_signal(k, &o, Cut::Lateral, column0_um, um_per_px, VT_MM_S).unwrap()
            })
            .collect();
        let s = stitch(&groups, 15.0).unwrap();
        assert!(s.gaps.is_empty());
        let y = resample(&s.channels[0], s.native_rate_hz, 44_100).unwrap();
        let expected: Vec<f32> = (0..y.len())
            .map(|k| {
                let p = s.start_um + k as f64 * VT_MM_S * 1000.0 / 44_100.0;
                (VT_MM_S * slope(p)) as f32
            })
            .collect();
        // Skip the resampler's edge transients.
        let scores = crate::pipeline::eval::evaluate(
            &y[200..y.len() - 200],
            &expected[200..y.len() - 200],
            10,
            44_100,
        )
        .unwrap();
        assert_eq!(scores.lag_samples, 0, "{scores:?}");
        assert!(scores.r > 0.999_999 && scores.snr_db > 60.0, "{scores:?}");
    }

    #[test]
    fn spacing_and_output_level() {
        let p = SoundParams::default();
        assert!((p.spacing_um(VT_MM_S).unwrap() - VT_MM_S * 1000.0 / 44_100.0).abs() < 1e-12);
        let fixed = SoundParams {
            native_spacing_um: 5.0,
            ..SoundParams::default()
        };
        assert_eq!(fixed.spacing_um(f64::NAN).unwrap(), 5.0);
        assert!(p.spacing_um(0.0).is_err());
        let bad = SoundParams {
            native_spacing_um: -1.0,
            ..SoundParams::default()
        };
        assert!(bad.spacing_um(VT_MM_S).is_err());

        let mut ch = vec![vec![10.0f32, -40.0], vec![f32::NAN, 20.0]];
        let g = p.scale_to_output(&mut ch).unwrap();
        assert!((g - 0.89 / 40.0).abs() < 1e-7);
        assert!((ch[0][1] + 0.89).abs() < 1e-6 && ch[1][0] == 0.0);
        let raw = SoundParams {
            normalize_peak: 0.0,
            full_scale_mm_s: 50.0,
            ..SoundParams::default()
        };
        let mut ch = vec![vec![25.0f32]];
        assert!((raw.scale_to_output(&mut ch).unwrap() - 0.02).abs() < 1e-9);
        assert!((ch[0][0] - 0.5).abs() < 1e-6);
        let mut silent = vec![vec![0.0f32; 4]];
        assert_eq!(p.scale_to_output(&mut silent).unwrap(), 1.0);
        let nan = SoundParams {
            normalize_peak: f32::NAN,
            ..SoundParams::default()
        };
        assert!(nan.scale_to_output(&mut silent).is_err());
        let zero_fs = SoundParams {
            normalize_peak: 0.0,
            full_scale_mm_s: 0.0,
            ..SoundParams::default()
        };
        assert!(zero_fs.scale_to_output(&mut silent).is_err());
    }

    #[test]
    fn resample_lengths_and_errors() {
        for n in [1usize, 2, 7, 100, 4095, 4096, 4097, 10_007] {
            let x = vec![0.25f32; n];
            let y = resample(&x, 43_000.0, 44_100).unwrap();
            assert_eq!(
                y.len(),
                (n as f64 * 44_100.0 / 43_000.0).round() as usize,
                "n = {n}"
            );
            assert!(y.iter().all(|v| v.is_finite()));
        }
        assert!(resample(&[], 43_000.0, 44_100).unwrap().is_empty());
        assert_eq!(
            resample(&[1.0, f32::NAN], 44_100.0, 44_100).unwrap(),
            vec![1.0, 0.0]
        );
        assert!(resample(&[1.0], 0.0, 44_100).is_err());
        assert!(resample(&[1.0], -1.0, 44_100).is_err());
        assert!(resample(&[1.0], f64::NAN, 44_100).is_err());
        assert!(resample(&[1.0], f64::INFINITY, 44_100).is_err());
        assert!(resample(&[1.0], 44_100.0, 0).is_err());
    }
}
