//! The edge decoder's outputs as sound: per-group velocity signals, and the border tracks
//! stitched over the whole clip and decoded there.
//!
//! Channels follow [`crate::pipeline::audio_signal::group_signal`] exactly, from each wall's
//! velocity `V = Vt·tan θ`: stereo `(V_L, V_R)`; lateral `(V_L + V_R)/√2`, or `√2·V` of the one
//! wall there is; vertical `(V_R − V_L)/√2`, or `∓√2·V`. So edges and flow agree in sign and
//! scale sample for sample.
//!
//! Differentiating each group alone needs one-sided filters at its ends, where groups overlap
//! and cross-fade. The border tracks (record `y`, absolute, µm) stitch across groups without
//! that: [`Edges::border_signal`] gives them with their standard errors as eight channels, the
//! engine's stitcher puts them on one grid, and [`decode_border_signal`] combines and
//! differentiates the whole clip at once (the border constants then come from the whole clip).

use std::f64::consts::SQRT_2;
use std::ops::Range;

use super::bursts::despike_bursts;
use super::despike::despike;
use super::differentiator::{DifferentiatorParams, differentiate};
use super::robust::{CombineParams, Combined, combine_borders, nan_runs};
use super::{EdgeParams, Edges};
use crate::meta::Cut;
use crate::pipeline::StageError;
use crate::pipeline::audio_signal::{GroupSignal, StitchedSignal};

/// Layout of [`Edges::border_signal`]: channel `2·b` holds border `b`'s record `y` (µm) and
/// channel `2·b + 1` its standard error (µm; 0 or NaN = not seen), `b` in
/// [`super::BorderId`] order.
pub struct BorderChannels;

impl BorderChannels {
    /// Channels in a border signal.
    pub const COUNT: usize = 8;
}

/// Each wall's velocity `Vt·sin α·∂y/∂s` (mm/s) from its displacement track (µm), `scale` being
/// `Vt·sin α` over the sample spacing. A lateral cut's walls are one track (`e = 0`), so it is
/// differentiated once for both.
pub(super) fn wall_velocities(
    walls_um: &[Vec<f64>; 2],
    cut: Cut,
    scale: f64,
    params: &DifferentiatorParams,
) -> [Vec<f64>; 2] {
    let velocity = |w: &[f64]| -> Vec<f64> {
        differentiate(w, params)
            .into_iter()
            .map(|v| v * scale)
            .collect()
    };
    let left = velocity(&walls_um[0]);
    let right = if cut == Cut::Lateral {
        left.clone()
    } else {
        velocity(&walls_um[1])
    };
    [left, right]
}

/// Velocity channels by cut from the walls' velocities (NaN = gap).
fn channels_by_cut(cut: Cut, left: &[f64], right: &[f64]) -> Vec<Vec<f32>> {
    #[allow(clippy::cast_possible_truncation)] // velocities are stored as f32
    let f = |v: f64| v as f32;
    match cut {
        Cut::Stereo => vec![
            left.iter().map(|&v| f(v)).collect(),
            right.iter().map(|&v| f(v)).collect(),
        ],
        Cut::Lateral | Cut::Vertical => {
            let sign_l = if cut == Cut::Lateral { 1.0 } else { -1.0 };
            let mono = left
                .iter()
                .zip(right)
                .map(|(&l, &r)| {
                    f(match (l.is_finite(), r.is_finite()) {
                        (true, true) => (sign_l * l + r) / SQRT_2,
                        (true, false) => sign_l * SQRT_2 * l,
                        (false, true) => SQRT_2 * r,
                        (false, false) => f64::NAN,
                    })
                })
                .collect();
            vec![mono]
        }
    }
}

impl Edges {
    /// The group's velocity samples by cut (mm/s, NaN = gap), on the same positions as the flow
    /// method's group signal.
    #[must_use]
    pub fn to_group_signal(&self) -> GroupSignal {
        let empty = Vec::new();
        let wall = |i: usize| self.walls.get(i).map_or(&empty, |w| &w.velocity_mm_s);
        GroupSignal {
            group: self.group,
            positions_um: self.positions_um.clone(),
            channels: channels_by_cut(self.cut, wall(0), wall(1)),
            groove_speed_mm_s: self.groove_speed_mm_s,
        }
    }

    /// The four border tracks and their standard errors as one stitchable signal (see
    /// [`BorderChannels`]); a border not seen at a sample is NaN in both its channels.
    #[must_use]
    pub fn border_signal(&self) -> GroupSignal {
        #[allow(clippy::cast_possible_truncation)] // µm tracks are stored as f32
        let f = |v: f64| v as f32;
        let mut channels = Vec::with_capacity(BorderChannels::COUNT);
        for b in &self.borders {
            // Sized exactly: a whole run keeps every group's tracks until the clip is finished.
            let n = b.y_um.len();
            let (mut y, mut se) = (Vec::with_capacity(n), Vec::with_capacity(n));
            for (&yv, &sv) in b.y_um.iter().zip(&b.std_error_um) {
                let seen = yv.is_finite() && sv.is_finite() && sv > 0.0;
                y.push(if seen { f(yv) } else { f32::NAN });
                se.push(if seen { f(sv) } else { f32::NAN });
            }
            channels.push(y);
            channels.push(se);
        }
        GroupSignal {
            group: self.group,
            positions_um: self.positions_um.clone(),
            channels,
            groove_speed_mm_s: self.groove_speed_mm_s,
        }
    }
}

/// A whole clip decoded from its stitched border tracks.
#[derive(Clone, Debug, PartialEq)]
pub struct DecodedEdges {
    /// The borders combined (constants from the whole clip).
    pub combined: Combined,
    /// Velocity by cut (mm/s, gaps filled with 0 and listed), on the stitched grid.
    pub velocity: StitchedSignal,
    /// Per output channel: sample ranges without a value.
    pub channel_gaps: Vec<Vec<Range<usize>>>,
    /// Per wall: the displacement samples put back on the curve as isolated outliers.
    pub despiked: [Vec<usize>; 2],
    /// Per wall: the short bursts of displacement samples put back on the curve (`bursts`).
    pub bursts: [Vec<Range<usize>>; 2],
}

impl DecodedEdges {
    /// The samples at which either wall's displacement was put back on the curve.
    #[must_use]
    pub fn despiked_samples(&self) -> usize {
        let [left, right] = &self.despiked;
        let mut all: Vec<usize> = left.iter().chain(right).copied().collect();
        all.sort_unstable();
        all.dedup();
        all.len()
    }

    /// The bursts of either wall put back on the curve, and the samples they hold (where both
    /// walls have one, counted once).
    #[must_use]
    pub fn burst_samples(&self) -> (usize, usize) {
        let [left, right] = &self.bursts;
        let mut all: Vec<Range<usize>> = left.iter().chain(right).cloned().collect();
        all.sort_by_key(|b| (b.start, b.end));
        all.dedup();
        let bursts = all.len();
        let samples = crate::pipeline::merge_ranges(all)
            .iter()
            .map(ExactSizeIterator::len)
            .sum();
        (bursts, samples)
    }
}

/// Combines and differentiates border tracks stitched over a clip (eight channels as
/// [`Edges::border_signal`] gives them; the stitcher's gap fill, a zero standard error, counts
/// as not seen) into velocity by `cut`.
///
/// # Errors
/// [`StageError::BadInput`] when the signal does not have eight channels of one length.
pub fn decode_border_signal(
    mut stitched: StitchedSignal,
    cut: Cut,
    groove_speed_mm_s: f64,
    params: &EdgeParams,
) -> Result<DecodedEdges, StageError> {
    let n = stitched.channels.first().map_or(0, Vec::len);
    if stitched.channels.len() != BorderChannels::COUNT
        || stitched.channels.iter().any(|c| c.len() != n)
    {
        return Err(StageError::BadInput {
            stage: "edges",
            problem: format!(
                "a border signal has {} channels of one length, got {}",
                BorderChannels::COUNT,
                stitched.channels.len()
            ),
        });
    }
    // Sized up front: a side's merge holds millions of samples, and growing by doubling
    // would keep up to twice each track.
    let mut ys: [Vec<f64>; 4] = std::array::from_fn(|_| Vec::with_capacity(n));
    let mut ses: [Vec<f64>; 4] = std::array::from_fn(|_| Vec::with_capacity(n));
    for b in 0..4 {
        // Each pair of channels is freed once read: a side's merge holds millions of samples.
        let y = std::mem::take(&mut stitched.channels[2 * b]);
        let se = std::mem::take(&mut stitched.channels[2 * b + 1]);
        for (&yv, &sv) in y.iter().zip(&se) {
            let seen = yv.is_finite() && sv.is_finite() && sv > 0.0;
            ys[b].push(if seen { f64::from(yv) } else { f64::NAN });
            ses[b].push(if seen { f64::from(sv) } else { f64::NAN });
        }
    }
    let mut combined = combine_borders(
        &ys,
        &ses,
        &CombineParams::from_edges(cut, params, stitched.spacing_um),
    );
    let alpha = params.wall_angle_deg.to_radians();
    let scale = groove_speed_mm_s * alpha.sin() / stitched.spacing_um;
    let [left, right] = &mut combined.walls_um;
    // Isolated outliers, then short bursts of them, put back on the curve.
    let mend = |track: &mut [f64]| {
        let spikes = despike(track, params.despike_sigmas);
        (spikes, despike_bursts(track, params.burst_sigmas))
    };
    let (left_spikes, left_bursts) = mend(left);
    let (right_spikes, right_bursts) = if cut == Cut::Lateral {
        // A lateral cut's walls are one track (`e = 0`): one pass serves both.
        right.clone_from(left);
        (left_spikes.clone(), left_bursts.clone())
    } else {
        mend(right)
    };
    let despiked = [left_spikes, right_spikes];
    let bursts = [left_bursts, right_bursts];
    let [left_v, right_v] = wall_velocities(&combined.walls_um, cut, scale, &params.differentiator);
    let mut channels = channels_by_cut(cut, &left_v, &right_v);
    let mut channel_gaps = Vec::with_capacity(channels.len());
    for ch in &mut channels {
        let as_f64: Vec<f64> = ch.iter().map(|&v| f64::from(v)).collect();
        channel_gaps.push(nan_runs(&as_f64));
        for v in ch.iter_mut() {
            if !v.is_finite() {
                *v = 0.0;
            }
        }
    }
    let gaps = crate::pipeline::merge_ranges(channel_gaps.iter().flatten().cloned().collect());
    Ok(DecodedEdges {
        combined,
        velocity: StitchedSignal {
            start_um: stitched.start_um,
            spacing_um: stitched.spacing_um,
            native_rate_hz: stitched.native_rate_hz,
            channels,
            gaps,
        },
        channel_gaps,
        despiked,
        bursts,
    })
}
