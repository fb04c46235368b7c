//! Band-limited resampling to the output rate (rubato's windowed sinc) with its delay removed exactly.

use std::f64::consts::PI;

use super::*;
use crate::pipeline::dsp::{end_level, odd_extension, reflect_after, reflect_before};

/// Sinc length of the resampler (input samples) when upsampling; scaled by the ratio when
/// downsampling so the filter spans as many output samples.
pub(super) const SINC_LEN_BASE: usize = 256;
/// Cap on the downsampling sinc length.
pub(super) const SINC_LEN_MAX: usize = 4096;
/// Oversampling of the tabulated sinc (cubic interpolation between table entries).
pub(super) const SINC_OVERSAMPLING: usize = 128;
/// Input frames per resampler call.
pub(super) const RESAMPLE_CHUNK: usize = 4096;
/// Leading zeros tried so that the resampler's delay is a whole number of output samples.
pub(super) const DELAY_PAD_SEARCH: usize = 4096;
/// Most output samples the leading samples may cost. Each costs `ratio` output samples, so
/// upsampling by more than 16 tries fewer counts (without this, 0.002 rpm typed for a still
/// made the resampler compute 20 million samples of leading silence). The delay left over is
/// still under half an output sample, which is under 1/(2·ratio) of an *input* sample, and
/// the signal's band lies below half the input rate.
pub(super) const DELAY_PAD_MAX_OUTPUT: f64 = 65_536.0;

/// How many leading-zero counts to try at `ratio` (output rate / input rate).
pub(super) fn pad_search_len(ratio: f64) -> usize {
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // at most the search
    let affordable = (DELAY_PAD_MAX_OUTPUT / ratio).floor().max(1.0) as usize;
    affordable.min(DELAY_PAD_SEARCH)
}

/// Delay of rubato's `SincFixedIn` (cubic sinc-table interpolation) in input samples: output n
/// is the input at time n/ratio − delay, with delay = 1 − 1/ratio − 1/oversampling (its first
/// output lies one output step after its start index, and the cubic table lookup is one table
/// step late). Measured, and checked by the `resampler_delay_is_exact` test for up- and
/// downsampling.
pub(super) fn resampler_delay_in(ratio: f64) -> f64 {
    #[allow(clippy::cast_precision_loss)] // small
    let table_step = 1.0 / SINC_OVERSAMPLING as f64;
    1.0 - 1.0 / ratio - table_step
}

/// Band-limited resampling of one channel from `from_hz` to `to_hz` (rubato windowed-sinc,
/// cubic between table entries). The output has round(n·to/from) samples, aligned with the
/// input (output k is the input at time k/to): the resampler's latency is removed, its fractional
/// part by leading samples chosen so that the delay is a whole number of output samples (to
/// within about 1/`DELAY_PAD_SEARCH` sample for irrational ratios; upsampling by more than 16
/// tries fewer counts, so that the lead costs at most `DELAY_PAD_MAX_OUTPUT` output samples).
/// The lead and a tail as long are the clip's odd reflection about its ends
/// (`dsp::odd_extension`), so the filter meets no step at either end. Non-finite samples count
/// as 0.
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

    // Leading samples so that (delay + pad)·ratio is (nearly) a whole number of output samples.
    // The delay may be negative (downsampling): start the search where it no longer is, and
    // no nearer than the filter reaches (half its length), where the output can afford it.
    let delay_in = resampler_delay_in(ratio);
    let reach = (sinc_len / 2 + 1).min(pad_search_len(ratio));
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // a few samples
    let min_pad = ((-delay_in).ceil().max(0.0) as usize).max(reach);
    let frac_off = |pad: usize| {
        #[allow(clippy::cast_precision_loss)]
        let d = (delay_in + pad as f64) * ratio;
        (d - d.round()).abs()
    };
    let pad = (min_pad..min_pad + pad_search_len(ratio))
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

    // The clip continued past each end by its odd reflection, not by silence: a band-limited
    // filter over a step to silence rings through the clip's first and last samples (a 1 kHz
    // tone of 8 ms, 48 → 44.1 kHz, came out 33.5 dB clean; reflected, 63.7 dB).
    // The tail reaches as far as the filter (two samples more for the resampler's delay). A
    // reflection reads only the samples it mirrors, so only the ends are cleaned for it.
    let tail_len = reach + 2;
    let cleaned = |part: &[f32]| part.iter().map(clean).collect::<Vec<f32>>();
    let n = samples.len();
    // Downsampling, the reflections pivot on each end's level over about one output sample's
    // span of input samples (`dsp::end_level`), not on the end sample: a noisy end sample
    // (a still's border fit at 8 lines an output sample) was otherwise the first and last
    // output samples' value, unfiltered.
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // a few samples
    let span = ((1.0 / ratio).round() as usize).clamp(1, n);
    let head = cleaned(&samples[..(pad + 1).max(span).min(n)]);
    let end = cleaned(&samples[n - (tail_len + 1).max(span).min(n)..]);
    let lead = reflect_before(&head, pad, end_level(head.iter().take(span).copied()));
    let tail = reflect_after(
        &end,
        tail_len,
        end_level(end.iter().rev().take(span).copied()),
    );
    let mut input: Vec<f64> = Vec::with_capacity(pad + n + tail_len);
    input.extend(lead.iter().map(|&v| f64::from(v)));
    input.extend(samples.iter().map(|v| f64::from(clean(v))));
    input.extend(tail.iter().map(|&v| f64::from(v)));
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

/// Taps on each side of [`read_from`]'s fractional-delay interpolator.
const DELAY_HALF_TAPS: usize = 32;

/// `samples` read from position `start` (in samples, ≥ 0, may be fractional) on: output `k` is
/// the band-limited value at `start + k` — a whole `start` is an exact slice, a fractional one
/// is interpolated by a Blackman-windowed sinc of 2·32 taps (past either end the samples are
/// continued by their odd reflection, `dsp::odd_extension`). Used to align a reference sound to a
/// clip that starts between its samples.
#[must_use]
pub fn read_from(samples: &[f32], start: f64) -> Vec<f32> {
    if !start.is_finite() || start < 0.0 {
        return samples.to_vec();
    }
    let whole = start.floor();
    let frac = start - whole;
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // checked ≥ 0 above
    let first = whole as usize;
    let tail = samples.get(first..).unwrap_or(&[]);
    if frac < 1e-9 {
        return tail.to_vec();
    }
    // Taps for offsets m = −(H−1)..=H from the integer position: sinc(m − frac)·window.
    let half = DELAY_HALF_TAPS as f64;
    let taps: Vec<(isize, f64)> = (1 - DELAY_HALF_TAPS as isize..=DELAY_HALF_TAPS as isize)
        .map(|m| {
            #[allow(clippy::cast_precision_loss)] // |m| ≤ 32
            let t = m as f64 - frac;
            let sinc = (PI * t).sin() / (PI * t);
            // Blackman window over (−H, H).
            let u = (t + half) / (2.0 * half);
            let w = 0.42 - 0.5 * (2.0 * PI * u).cos() + 0.08 * (4.0 * PI * u).cos();
            (m, sinc * w)
        })
        .collect();
    // The samples continued past each end by their odd reflection, as `resample` does.
    let (lead, after) = odd_extension(samples, DELAY_HALF_TAPS);
    let extended: Vec<f32> = lead
        .into_iter()
        .chain(samples.iter().copied())
        .chain(after)
        .collect();
    (0..tail.len())
        .map(|k| {
            let acc: f64 = taps
                .iter()
                .filter_map(|&(m, w)| {
                    let i = (first + DELAY_HALF_TAPS).checked_add_signed(k as isize + m)?;
                    extended.get(i).map(|&v| w * f64::from(v))
                })
                .sum();
            #[allow(clippy::cast_possible_truncation)] // audio samples are f32
            let v = acc as f32;
            v
        })
        .collect()
}
