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
use crate::meta::Cut;

mod pack;
mod resample;
mod stitch;
#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests unwrap known-good results
mod tests;

pub use pack::{GroupSignals, SignalPack, SignalView};
pub use resample::{read_from, resample};
pub use stitch::{StitchedSignal, stitch};

/// Two sample columns closer than this (px) are the same column when the walls are combined.
const SAME_COLUMN_TOL_PX: f64 = 1e-3;

/// Knobs of the sound stage.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SoundParams {
    #[doc = knob!("sound.output_rate_hz")]
    pub output_rate_hz: u32,
    #[doc = knob!("sound.native_spacing_um")]
    pub native_spacing_um: f64,
    #[doc = knob!("sound.normalize_peak")]
    pub normalize_peak: f32,
    #[doc = knob!("sound.full_scale_mm_s")]
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
    /// Checks every sound knob.
    ///
    /// # Errors
    /// [`StageError::InvalidParam`] naming the first bad key.
    pub fn validate(&self) -> Result<(), StageError> {
        if !matches!(self.output_rate_hz, 8_000..=192_000) {
            return Err(StageError::InvalidParam {
                name: "sound.output_rate_hz".into(),
                problem: format!(
                    "{} Hz is not a usable rate (8000..192000)",
                    self.output_rate_hz
                ),
            });
        }
        check_range("sound.native_spacing_um", self.native_spacing_um, 0.0, 1e6)?;
        check_range(
            "sound.normalize_peak",
            f64::from(self.normalize_peak),
            0.0,
            1.0,
        )?;
        check_range("sound.full_scale_mm_s", self.full_scale_mm_s, 1e-9, 1e9)
    }

    /// Scales velocity channels (mm/s) to output level in place and returns the gain applied
    /// (per mm/s): with `normalize_peak` > 0 the largest finite |sample| over all channels
    /// becomes it (silence is left alone, gain 1); with 0 `full_scale_mm_s` maps to 1.0. Each
    /// sample is scaled in f64 and rounded once; non-finite samples become 0.
    ///
    /// # Errors
    /// [`StageError::InvalidParam`] when the params are invalid ([`SoundParams::validate`]).
    pub fn scale_to_output(&self, channels: &mut [Vec<f32>]) -> Result<f64, StageError> {
        self.validate()?;
        let peak =
            channels.iter().flatten().fold(
                0.0_f32,
                |m, v| if v.is_finite() { m.max(v.abs()) } else { m },
            );
        let gain_per_mm_s = if self.normalize_peak > 0.0 {
            if peak > 0.0 {
                f64::from(self.normalize_peak / peak)
            } else {
                1.0
            }
        } else {
            1.0 / self.full_scale_mm_s
        };
        for v in channels.iter_mut().flatten() {
            *v = if v.is_finite() {
                (f64::from(*v) * gain_per_mm_s) as f32
            } else {
                0.0
            };
        }
        Ok(gain_per_mm_s)
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

impl GroupSignal {
    /// A one-channel signal of `group` whose sample at each of `positions_um` is
    /// `velocity(position)` (mm/s), at groove speed `groove_speed_mm_s`.
    #[must_use]
    pub fn mono_from_fn(
        group: usize,
        positions_um: Vec<f64>,
        groove_speed_mm_s: f64,
        velocity: impl Fn(f64) -> f32,
    ) -> Self {
        let channel = positions_um.iter().map(|&p| velocity(p)).collect();
        Self {
            group,
            positions_um,
            channels: vec![channel],
            groove_speed_mm_s,
        }
    }
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
