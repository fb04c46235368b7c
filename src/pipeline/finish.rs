//! Clip finishing: group signals in, sound out — stitch, bridge short gaps, resample, DSP, normalise.
//!
//! Whole-scan reconstruction (`engine`) and the merge of shard parts (`side::merge`) both end
//! here, so a merged side is the same sound, bit for bit, as a one-process run: the input is
//! the ordered list of group signals, nothing else.
//!
//! [`finish_method_clip`] finishes by the params' method: the flow signals as they are; the
//! edges' border tracks stitched over the clip, then combined and differentiated
//! ([`decode_border_signal`]); or both fused per band ([`fuse`]). The edges and fused sound,
//! and a still's ([`channels_to_output`]), run the DC block and the low-pass zero-phase
//! (forward and backward over the clip, [`FilterPhase`]), so the waveform keeps its shape
//! through them; the flow method keeps the causal filters (its output as before).

use std::ops::Range;

use serde::Serialize;

use super::audio_signal::{GroupSignals, SignalPack, StitchedSignal, resample, stitch};
use super::dsp::{FilterPhase, apply_dsp_with};
use super::edges::decode_border_signal;
use super::edges::robust::Combined;
use super::fusion::{EdgeNoise, FusionBlock, GroupFusion, fuse};
use super::{Method, PipelineParams, StageError};
use crate::meta::ScanMeta;

/// How `method`'s sound runs the DC block and the low-pass: the flow method causal (its
/// output as before), the edges and fused sound zero-phase (see the module docs).
#[must_use]
pub fn filter_phase(method: Method) -> FilterPhase {
    match method {
        Method::Flow => FilterPhase::Causal,
        Method::Edges | Method::Fused => FilterPhase::ZeroPhase,
    }
}

/// The filters `method`'s sound goes through, in words, for its report
/// ([`super::dsp::describe_chain`]).
#[must_use]
pub fn describe_filters(dsp: &super::dsp::DspParams, method: Method) -> String {
    super::dsp::describe_chain(dsp, filter_phase(method))
}

/// How a still's sound runs them ([`channels_to_output`]).
pub const STILL_FILTER_PHASE: FilterPhase = FilterPhase::ZeroPhase;

/// The filters a still's sound goes through, in words (as [`describe_filters`] for a scan's).
#[must_use]
pub fn describe_still_filters(dsp: &super::dsp::DspParams) -> String {
    super::dsp::describe_chain(dsp, STILL_FILTER_PHASE)
}

/// Gaps up to this many native samples are bridged by linear interpolation; longer ones stay silent.
pub const BRIDGE_GAP_SAMPLES: usize = 4;

/// A finished clip: output-rate channels after DSP and normalisation, and what led there.
#[derive(Clone, Debug, PartialEq)]
pub struct FinishedClip {
    /// Output sample rate (Hz).
    pub sample_rate_hz: u32,
    /// One buffer per channel at the output rate, scaled to output level (non-finite → 0).
    pub channels: Vec<Vec<f32>>,
    /// The stitched native-rate signal (velocity, mm/s), short gaps bridged.
    pub stitched: StitchedSignal,
    /// Gain applied to velocity (mm/s) to reach the output level.
    pub gain_per_mm_s: f64,
    /// Short gaps bridged, long gaps left silent: one line each.
    pub warnings: Vec<String>,
    /// How the `fused` method weighed the two decoders (None for the others).
    pub fusion: Option<FusionReport>,
}

/// What the fused decoder found: every analysis block, and the blocks mapped onto the groups.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FusionReport {
    /// Per group (and channel): the crossover, the edge weights, the shares one method alone had.
    pub groups: Vec<GroupFusion>,
    /// Every analysis block of every channel.
    pub blocks: Vec<FusionBlock>,
}

/// A clip's group signals as the method needs them, in group order. Finishing takes them
/// over, so each is freed as soon as it has been stitched.
#[derive(Clone, Debug, Default)]
pub struct ClipSignals {
    /// The flow method's velocity per group (read by `flow` and `fused`).
    pub flow: SignalPack,
    /// The edge stage's border tracks per group ([`super::edges::Edges::border_signal`]; read
    /// by `edges` and `fused`).
    pub borders: SignalPack,
    /// Groove length (µm) of the clip's groups that gave no sound before its first group with
    /// sound and after its last: the clip is extended over them as silence (listed as gaps),
    /// so the sound keeps its place and length.
    pub silent_ends_um: [f64; 2],
}

/// `signal` extended by `ends_um` (µm before its start, after its end; rounded to whole
/// samples) of silence, each listed as a gap.
fn extend_with_silence(signal: &mut StitchedSignal, ends_um: [f64; 2]) {
    let samples = |um: f64| {
        let k = (um / signal.spacing_um).round();
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // checked finite, ≥ 0
        if k.is_finite() && k >= 1.0 {
            k as usize
        } else {
            0
        }
    };
    let (lead, trail) = (samples(ends_um[0]), samples(ends_um[1]));
    if lead == 0 && trail == 0 {
        return;
    }
    let n = signal.channels.first().map_or(0, Vec::len);
    for ch in &mut signal.channels {
        let mut padded = vec![0.0; lead];
        padded.extend_from_slice(ch);
        padded.resize(lead + n + trail, 0.0);
        *ch = padded;
    }
    #[allow(clippy::cast_precision_loss)] // sample counts ≤ 2^28
    {
        signal.start_um -= lead as f64 * signal.spacing_um;
    }
    let mut gaps: Vec<Range<usize>> = Vec::with_capacity(signal.gaps.len() + 2);
    let mut push = |r: Range<usize>| match gaps.last_mut() {
        Some(last) if last.end >= r.start => last.end = last.end.max(r.end),
        _ => gaps.push(r),
    };
    if lead > 0 {
        push(0..lead);
    }
    for g in &signal.gaps {
        push(g.start + lead..g.end + lead);
    }
    if trail > 0 {
        push(lead + n..lead + n + trail);
    }
    signal.gaps = gaps;
}

/// Each group's middle (µm) and groove speed (mm/s), in group order.
fn group_speeds<S: GroupSignals + ?Sized>(groups: &S) -> Vec<(f64, f64)> {
    groups
        .views()
        .filter_map(|g| {
            let (a, b) = (g.positions_um.first()?, g.positions_um.last()?);
            Some((0.5 * (a + b), g.groove_speed_mm_s))
        })
        .collect()
}

/// Groove speed (mm/s) at each sample of `grid` from the groups' speeds at their middles
/// ([`group_speeds`]), linearly between them and constant beyond the ends.
fn groove_speed_along(mids: &[(f64, f64)], grid: &StitchedSignal) -> Vec<f64> {
    let n = grid.channels.first().map_or(0, Vec::len);
    (0..n)
        .map(|i| {
            let s = grid.start_um + i as f64 * grid.spacing_um;
            let k = mids.partition_point(|m| m.0 <= s);
            match (k.checked_sub(1).and_then(|j| mids.get(j)), mids.get(k)) {
                (Some(&(s0, v0)), Some(&(s1, v1))) if s1 > s0 => {
                    v0 + (v1 - v0) * (s - s0) / (s1 - s0)
                }
                (Some(&(_, v)), _) | (None, Some(&(_, v))) => v,
                (None, None) => 0.0,
            }
        })
        .collect()
}

/// What the edge method mended in a clip's displacement tracks.
#[derive(Clone, Copy, Debug, Default)]
struct EdgeRepairs {
    /// Samples put back on the curve as isolated outliers (`edges::despike`).
    despiked: usize,
    /// Short bursts put back on the curve (`edges::bursts`), and the samples they hold.
    bursts: (usize, usize),
    /// Samples of excursions solved again or left as gaps (`edges::plausible`).
    excursion_samples: usize,
}

impl EdgeRepairs {
    /// A warning line for each repair made.
    fn warnings(self, params: &PipelineParams) -> Vec<String> {
        // The plural ending, possessive, verb and pronoun for `n` of something.
        let plural = |n: usize| {
            if n == 1 {
                ("", "its", "was", "it")
            } else {
                ("s", "their", "were", "them")
            }
        };
        let mut out = Vec::new();
        if self.despiked > 0 {
            let (s, its, _, _) = plural(self.despiked);
            out.push(format!(
                "{} isolated displacement sample{s} put back on the curve through {its} \
                 neighbours (edges.despike_sigmas = {})",
                self.despiked, params.edges.despike_sigmas
            ));
        }
        let (bursts, burst_samples) = self.bursts;
        if bursts > 0 {
            let (s, _, _, _) = plural(burst_samples);
            let (bs, _, _, them) = plural(bursts);
            out.push(format!(
                "{burst_samples} displacement sample{s} in {bursts} short burst{bs} put back on \
                 the curve through the samples around {them} (edges.burst_sigmas = {})",
                params.edges.burst_sigmas
            ));
        }
        if self.excursion_samples > 0 {
            let (s, _, was, them) = plural(self.excursion_samples);
            out.push(format!(
                "{} displacement sample{s} moved faster than a groove can and {was} solved again \
                 from the track around {them}, or left as gap{s} (edges.max_slope = {})",
                self.excursion_samples, params.edges.max_slope
            ));
        }
        out
    }
}

/// The edge method's velocity over the clip: the border tracks stitched, combined,
/// differentiated, and scaled by the groove speed at each sample. With it, `with_noise`, each
/// channel's displacement noise on the same grid ([`edge_noise`]; only the fused decoder reads
/// it), and what was mended in the displacement tracks.
fn edge_velocity(
    borders: SignalPack,
    spacing_um: f64,
    meta: &ScanMeta,
    params: &PipelineParams,
    with_noise: bool,
) -> Result<(StitchedSignal, Option<EdgeNoise>, EdgeRepairs), StageError> {
    let stitched = stitch(&borders, spacing_um)?;
    let mids = group_speeds(&borders);
    // The groups' tracks are stitched: a side's merge needs their memory for the decode.
    drop(borders);
    let decoded = decode_border_signal(stitched, meta.record.cut, 1.0, &params.edges)?;
    let repairs = EdgeRepairs {
        despiked: decoded.despiked_samples(),
        bursts: decoded.burst_samples(),
        excursion_samples: decoded
            .combined
            .excursions
            .iter()
            .map(ExactSizeIterator::len)
            .sum(),
    };
    let mut velocity = decoded.velocity;
    let speed = groove_speed_along(&mids, &velocity);
    for ch in &mut velocity.channels {
        for (v, vt) in ch.iter_mut().zip(&speed) {
            #[allow(clippy::cast_possible_truncation)] // velocities are stored as f32
            let scaled = (f64::from(*v) * vt) as f32;
            *v = scaled;
        }
    }
    let noise =
        with_noise.then(|| edge_noise(&velocity, &decoded.combined, &speed, spacing_um, params));
    Ok((velocity, noise, repairs))
}

/// Each channel of `velocity`'s displacement noise in velocity units (`σ_d·Vt·sin α/Δ`, with
/// `speed` the groove speed Vt at each sample), from the combined borders' standard errors and
/// raised by their scatter ([`EdgeNoise`]).
fn edge_noise(
    velocity: &StitchedSignal,
    combined: &Combined,
    speed: &[f64],
    spacing_um: f64,
    params: &PipelineParams,
) -> EdgeNoise {
    let sin_a = params.edges.wall_angle_deg.to_radians().sin();
    let [left, right] = &combined.walls_se_um;
    // Stereo: each wall its channel; mono cuts: √2 times a wall's (the walls share d).
    let mono: Vec<f64>;
    let per_channel: Vec<(&[f64], f64)> = if velocity.channels.len() == 2 {
        vec![(left, 1.0), (right, 1.0)]
    } else {
        mono = left
            .iter()
            .zip(right)
            .map(|(&l, &r)| match (l.is_finite(), r.is_finite()) {
                (true, true) => l.max(r),
                (true, false) => l,
                (false, _) => r,
            })
            .collect();
        vec![(&mono, std::f64::consts::SQRT_2)]
    };
    #[allow(clippy::cast_possible_truncation)] // noise levels are stored as f32
    let sigma = |se: &[f64], gain: f64, raised: bool| -> Vec<f32> {
        se.iter()
            .zip(speed)
            .zip(&combined.scatter)
            .map(|((&e, &vt), &f)| {
                let fitted = (e * gain * vt * sin_a / spacing_um) as f32;
                if raised {
                    fitted * f.sqrt() as f32
                } else {
                    fitted
                }
            })
            .collect()
    };
    let signal = |raised: bool| StitchedSignal {
        channels: per_channel
            .iter()
            .map(|&(se, gain)| sigma(se, gain, raised))
            .collect(),
        gaps: Vec::new(),
        start_um: velocity.start_um,
        spacing_um: velocity.spacing_um,
        native_rate_hz: velocity.native_rate_hz,
    };
    EdgeNoise {
        fitted: signal(false),
        scattered: signal(true),
    }
}

/// Finishes a clip by `params.method` (see the module docs), extended over its silent ends
/// ([`ClipSignals::silent_ends_um`]), then as [`finish_clip`] does: bridge short gaps,
/// resample, DSP, normalise. `flow` signals with no silent ends give `flow`'s sound exactly as
/// [`finish_clip`] would.
///
/// # Errors
/// [`StageError`] when the signals the method reads are missing or do not stitch, or the
/// resampling or DSP fails.
pub fn finish_method_clip(
    signals: ClipSignals,
    meta: &ScanMeta,
    params: &PipelineParams,
) -> Result<FinishedClip, StageError> {
    let spacing_um = super::sampling::native_spacing_um(meta, &params.sound);
    let ends_um = signals.silent_ends_um;
    let (mut velocity, fusion, repairs) = match params.method {
        Method::Flow => (
            stitch(&signals.flow, spacing_um)?,
            None,
            EdgeRepairs::default(),
        ),
        Method::Edges => {
            let (velocity, _, n) = edge_velocity(signals.borders, spacing_um, meta, params, false)?;
            (velocity, None, n)
        }
        Method::Fused => {
            let ClipSignals { flow, borders, .. } = signals;
            let (velocity, noise, repairs) =
                edge_velocity(borders, spacing_um, meta, params, true)?;
            let flow_velocity = stitch(&flow, spacing_um)?;
            drop(flow);
            let fused = fuse(
                &flow_velocity,
                &velocity,
                noise.as_ref(),
                meta,
                &params.fusion,
            )?;
            let report = FusionReport {
                groups: fused.groups,
                blocks: fused.blocks,
            };
            (fused.signal, Some(report), repairs)
        }
    };
    extend_with_silence(&mut velocity, ends_um);
    let mut clip = finish_stitched(velocity, params, filter_phase(params.method))?;
    clip.fusion = fusion;
    clip.warnings.extend(repairs.warnings(params));
    Ok(clip)
}

/// Finishes a clip from its group signals (in group order) on a native grid of `spacing_um`:
/// stitches them ([`stitch`]), bridges gaps of at most [`BRIDGE_GAP_SAMPLES`]
/// ([`bridge_short_gaps`]), resamples each channel to `sound.output_rate_hz`, applies the DSP
/// chain, and scales to output level: with `sound.normalize_peak` > 0 the largest finite
/// |sample| becomes it (silence keeps gain 1), else `sound.full_scale_mm_s` maps to 1.0.
///
/// # Errors
/// [`StageError`] when stitching, resampling or the DSP chain fails (no signals, bad params).
pub fn finish_clip<S: GroupSignals + ?Sized>(
    signals: &S,
    spacing_um: f64,
    params: &PipelineParams,
) -> Result<FinishedClip, StageError> {
    finish_stitched(
        stitch(signals, spacing_um)?,
        params,
        filter_phase(Method::Flow),
    )
}

/// A stitched velocity signal finished: short gaps bridged, resampled, DSP (the DC block and
/// low-pass run as `phase` says), normalised.
fn finish_stitched(
    mut stitched: StitchedSignal,
    params: &PipelineParams,
    phase: FilterPhase,
) -> Result<FinishedClip, StageError> {
    let mut warnings = Vec::new();
    let bridged = bridge_short_gaps(&mut stitched);
    if bridged > 0 {
        warnings.push(format!(
            "{bridged} short gaps (≤ {BRIDGE_GAP_SAMPLES} native samples) bridged by interpolation"
        ));
    }
    let len = stitched.channels.first().map_or(0, Vec::len);
    for gap in &stitched.gaps {
        let n = gap.len();
        // A few samples at the very start or end are where the stitch grid's first or last
        // points fall just outside what the groups decoded (the last sample of many clips),
        // not groove that was lost: silent, as the edge of any clip is, and not worth a line
        // that would teach the operator to pass over the gap warnings.
        if n <= BRIDGE_GAP_SAMPLES && (gap.start == 0) != (gap.end >= len) {
            continue;
        }
        let samples = if n == 1 { "sample" } else { "samples" };
        warnings.push(format!(
            "gap of {n} native {samples} at sample {} filled with silence",
            gap.start
        ));
    }
    let (channels, gain_per_mm_s) =
        channels_to_output_with(&stitched.channels, stitched.native_rate_hz, params, phase)?;
    Ok(FinishedClip {
        sample_rate_hz: params.sound.output_rate_hz,
        channels,
        stitched,
        gain_per_mm_s,
        warnings,
        fusion: None,
    })
}

/// Native-rate channels to output sound: each resampled to `sound.output_rate_hz`, through the
/// DSP chain (zero-phase), then scaled to output level by `SoundParams::scale_to_output`.
/// Returns the channels and the gain per mm/s. The still decoder finishes its sound here.
///
/// # Errors
/// [`StageError`] for an unusable rate, filter or scale setting.
pub fn channels_to_output(
    channels: &[Vec<f32>],
    native_rate_hz: f64,
    params: &PipelineParams,
) -> Result<(Vec<Vec<f32>>, f64), StageError> {
    channels_to_output_with(channels, native_rate_hz, params, STILL_FILTER_PHASE)
}

/// [`channels_to_output`] with the DC block and low-pass run as `phase` says.
fn channels_to_output_with(
    channels: &[Vec<f32>],
    native_rate_hz: f64,
    params: &PipelineParams,
    phase: FilterPhase,
) -> Result<(Vec<Vec<f32>>, f64), StageError> {
    let out_rate = params.sound.output_rate_hz;
    let mut out = Vec::with_capacity(channels.len());
    for ch in channels {
        let mut y = resample(ch, native_rate_hz, out_rate)?;
        apply_dsp_with(&mut y, f64::from(out_rate), &params.dsp, phase)?;
        out.push(y);
    }
    let gain_per_mm_s = params.sound.scale_to_output(&mut out)?;
    Ok((out, gain_per_mm_s))
}

/// Bridges gaps of at most [`BRIDGE_GAP_SAMPLES`] with data on both sides by linear
/// interpolation, removes them from `gaps`, and returns how many were bridged.
pub fn bridge_short_gaps(signal: &mut StitchedSignal) -> usize {
    let mut bridged = 0;
    let mut kept = Vec::new();
    let n = signal.channels.first().map_or(0, Vec::len);
    for gap in std::mem::take(&mut signal.gaps) {
        if gap.len() > BRIDGE_GAP_SAMPLES || gap.start == 0 || gap.end >= n {
            kept.push(gap);
            continue;
        }
        let (a, b) = (gap.start - 1, gap.end);
        for ch in &mut signal.channels {
            let (Some(&va), Some(&vb)) = (ch.get(a), ch.get(b)) else {
                continue;
            };
            for k in gap.clone() {
                let t = (k - a) as f32 / (b - a) as f32;
                if let Some(v) = ch.get_mut(k) {
                    *v = va + (vb - va) * t;
                }
            }
        }
        bridged += 1;
    }
    signal.gaps = kept;
    bridged
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;
    use crate::pipeline::audio_signal::GroupSignal;

    fn stitched(values: Vec<f32>, gaps: Vec<std::ops::Range<usize>>) -> StitchedSignal {
        StitchedSignal {
            start_um: 0.0,
            spacing_um: 1.0,
            native_rate_hz: 1000.0,
            channels: vec![values],
            gaps,
        }
    }

    #[test]
    fn repair_warnings_agree_with_their_counts() {
        let warnings = |despiked, bursts, excursion_samples| {
            EdgeRepairs {
                despiked,
                bursts,
                excursion_samples,
            }
            .warnings(&PipelineParams::default())
        };
        let w = warnings(1, (1, 3), 1);
        assert!(
            w[0].starts_with("1 isolated displacement sample put back"),
            "{w:?}"
        );
        assert!(
            w[1].contains("in 1 short burst put back on the curve through the samples around it ("),
            "{w:?}"
        );
        assert!(w[2].contains("sample moved faster than a groove can and was solved again from the track around it, or left as gap ("), "{w:?}");
        let w = warnings(2, (2, 6), 5);
        assert!(
            w[1].contains(
                "in 2 short bursts put back on the curve through the samples around them ("
            ),
            "{w:?}"
        );
        assert!(w[2].contains("5 displacement samples moved faster than a groove can and were solved again from the track around them, or left as gaps ("), "{w:?}");
        assert!(warnings(0, (0, 0), 0).is_empty());
    }

    #[test]
    fn a_short_gap_is_bridged_linearly_and_a_long_one_stays() {
        let mut s = stitched(
            vec![1.0, 0.0, 0.0, 4.0, 5.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 7.0],
            vec![1..3, 5..11],
        );
        assert_eq!(bridge_short_gaps(&mut s), 1);
        assert_eq!(&s.channels[0][..4], &[1.0, 2.0, 3.0, 4.0]);
        assert_eq!(s.gaps, vec![5..11]);
    }

    /// A lost stretch is said; the grid's last point beyond the decoded samples is not.
    #[test]
    fn gaps_are_said_but_not_a_few_samples_at_the_clips_ends() {
        let values = (0..2000)
            .map(|i| (f64::from(i) * 0.05).sin() as f32)
            .collect();
        let mut s = stitched(values, vec![0..2, 500..510, 1999..2000]);
        s.native_rate_hz = 44_100.0;
        let finished =
            finish_stitched(s, &PipelineParams::default(), filter_phase(Method::Flow)).unwrap();
        let gaps: Vec<&String> = finished
            .warnings
            .iter()
            .filter(|w| w.starts_with("gap of"))
            .collect();
        assert_eq!(
            gaps,
            ["gap of 10 native samples at sample 500 filled with silence"]
        );
    }

    #[test]
    fn gaps_at_either_end_are_not_bridged() {
        let mut s = stitched(vec![0.0, 1.0, 2.0, 0.0], vec![0..1, 3..4]);
        assert_eq!(bridge_short_gaps(&mut s), 0);
        assert_eq!(s.gaps.len(), 2);
    }

    #[test]
    fn a_tone_comes_out_normalised_to_the_peak_asked_for() {
        // Two overlapping groups of a 1 kHz velocity tone on a 44.1 kHz native grid.
        let spacing_um = 939_336.0 / 44_100.0;
        let group = |g: usize, first: usize| GroupSignal {
            group: g,
            positions_um: (first..first + 300)
                .map(|k| k as f64 * spacing_um)
                .collect(),
            channels: vec![
                (first..first + 300)
                    .map(|k| (k as f32 * 0.1425).sin() * 20.0)
                    .collect(),
            ],
            groove_speed_mm_s: 939.336,
        };
        let mut params = PipelineParams::default();
        params.sound.normalize_peak = 0.5;
        let clip = finish_clip(&[group(0, 0), group(1, 250)], spacing_um, &params).unwrap();
        assert_eq!(clip.sample_rate_hz, params.sound.output_rate_hz);
        let peak = clip.channels[0].iter().fold(0.0f32, |m, v| m.max(v.abs()));
        assert!((peak - 0.5).abs() < 1e-6, "{peak}");
        assert!(clip.stitched.gaps.is_empty());
        assert!(finish_clip(&Vec::new(), spacing_um, &params).is_err());
    }
}
