//! The fused decoder: the flow method's and the edge method's velocity combined per frequency band, weighted by each one's measured noise.
//!
//! The flow method reads the wall tilt, whose noise is flat in velocity; the edge method reads
//! the borders' displacement, whose noise is flat in displacement and so rises 6 dB per octave
//! in velocity. Each therefore wins below or above a crossover, which depends on the optics and
//! the damage and is measured, never assumed:
//! 1. Both stitched signals are put on one grid (the scan's global sample grid); where one has a
//!    gap (a wall's edges missing, a rejected flow fit) the other fills it.
//! 2. A short-time Fourier transform (periodic √Hann windows of `block_samples`, half-overlapping,
//!    which reconstruct exactly) of both. Each block's noise levels come from the periodogram of
//!    their difference, averaged over `smoothing_blocks` blocks on each side and fitted by
//!    [`noise::fit_noise`]: flow noise `b` flat plus `c·|S|²` following the signal, edge noise
//!    `a·ω²`, `a` known from the border fits' standard errors, raised by how much more the
//!    borders scatter where the flow is within reach ([`noise::fit_with_scatter`], [`EdgeNoise`]).
//!    Blocks where more than [`MAX_FILLED_SHARE`] of the samples were filled from the
//!    other method lend no spectrum, unless none near a block does: then blocks filled up to
//!    [`MAX_GAPPY_FILLED_SHARE`] lend theirs, corrected for the gaps (a flow with a third of
//!    its fits rejected would otherwise leave the whole clip at equal weights).
//! 3. Each bin is the Wiener combination `w·E + (1 − w)·F` with `w = N_F/(N_F + a·ω²)`,
//!    `N_F = b + c·|F_k|·|E_k|` (the geometric mean of the block's own periodograms standing for
//!    the signal power, as it does in the fit), and the blocks are added back.
//!
//! Stereo channels fuse separately (each wall gives its channel). The report lists every block's
//! crossover and edge weights, and maps the blocks onto the scan's groups.

pub mod noise;

use std::f64::consts::PI;
use std::ops::Range;

use serde::{Deserialize, Serialize};

use self::noise::{NoiseModel, fit_with_scatter};
use super::audio_signal::StitchedSignal;
use super::dsp::ComplexFft;
use super::edges::robust::false_runs;
use super::{StageError, check_range};
use crate::meta::ScanMeta;

/// Blocks lend their spectrum to the noise estimate only when less than this share of their
/// samples was filled from the other method.
pub const MAX_FILLED_SHARE: f64 = 0.1;
/// Where no block within `smoothing_blocks` of a block lends its spectrum, blocks with up to
/// this share of filled samples do, their difference periodogram divided by the share of the
/// window's energy where both methods have data (the filled samples' difference is zero, so
/// it reads low by about that share). Without them a flow whose fits are rejected all along
/// leaves every block without a model, and the clip is fused at equal weights.
pub const MAX_GAPPY_FILLED_SHARE: f64 = 0.5;
/// An end of the clip where one method reaches at most this many samples past the other ends
/// with the other. Those lone samples are an overhang of the two grids, not a group's sound, and
/// one from the method that reads the scan poorly (the flow method on the small dual-focus
/// camera, about 3 dB) became a click that the zero-phase low-pass spread over the clip's last
/// 20 samples: the fused 500 Hz tone there scored 18.4 dB against the edges' 40.2 dB.
pub const MAX_END_OVERHANG: u64 = 4;
/// Frequencies (Hz) at which the report gives the edge weight (away from the signal: the
/// flat noise levels' weight, without the flow's signal-following error).
pub const REPORT_FREQS_HZ: [f64; 4] = [500.0, 1000.0, 2000.0, 5000.0];

/// Knobs of the fused decoder.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FusionParams {
    #[doc = knob!("fusion.block_samples")]
    pub block_samples: usize,
    #[doc = knob!("fusion.smoothing_blocks")]
    pub smoothing_blocks: usize,
}

impl Default for FusionParams {
    fn default() -> Self {
        Self {
            block_samples: 256,
            smoothing_blocks: 4,
        }
    }
}

impl FusionParams {
    /// Checks every knob.
    ///
    /// # Errors
    /// [`StageError::InvalidParam`] naming the bad key.
    pub fn validate(&self) -> Result<(), StageError> {
        if !(16..=65_536).contains(&self.block_samples) || !self.block_samples.is_power_of_two() {
            return Err(StageError::InvalidParam {
                name: "fusion.block_samples".into(),
                problem: format!(
                    "{} is not a power of two in [16, 65536]",
                    self.block_samples
                ),
            });
        }
        if self.smoothing_blocks > 1024 {
            return Err(StageError::InvalidParam {
                name: "fusion.smoothing_blocks".into(),
                problem: format!("{} is above 1024", self.smoothing_blocks),
            });
        }
        Ok(())
    }
}

/// One analysis block of one channel.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FusionBlock {
    /// Output channel.
    pub channel: usize,
    /// First sample of the block on the fused grid (may be negative for the first block).
    pub start_sample: i64,
    /// Crossover frequency (Hz): edges weigh more below it, flow above.
    pub crossover_hz: f64,
    /// Edge weight at each of [`REPORT_FREQS_HZ`].
    pub edge_weights: Vec<f64>,
    /// Flow noise (mm/s rms over the whole band).
    pub flow_noise_mm_s: f64,
    /// Edge noise (mm/s rms over the whole band).
    pub edge_noise_mm_s: f64,
}

/// The fusion as it fell on one group.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct GroupFusion {
    /// Group index.
    pub group: usize,
    /// Crossover (Hz) of the block the group's middle falls in, per channel.
    pub crossover_hz: Vec<f64>,
    /// Edge weight at [`REPORT_FREQS_HZ`] there, per channel.
    pub edge_weights: Vec<Vec<f64>>,
    /// Share of the group's samples where only the edges had data, per channel.
    pub edges_only: Vec<f64>,
    /// Share where only the flow had data, per channel.
    pub flow_only: Vec<f64>,
}

/// The fused signal and how it was made.
#[derive(Clone, Debug, PartialEq)]
pub struct Fused {
    /// Velocity (mm/s), on the union of both grids; gaps (neither method) are 0 and listed.
    pub signal: StitchedSignal,
    /// Every analysis block of every channel.
    pub blocks: Vec<FusionBlock>,
    /// The blocks mapped onto the scan's groups.
    pub groups: Vec<GroupFusion>,
}

/// Which samples of a channel have data.
fn valid_mask(signal: &StitchedSignal, len: usize) -> Vec<bool> {
    let mut m = vec![true; len];
    for g in &signal.gaps {
        for v in m.iter_mut().take(g.end.min(len)).skip(g.start) {
            *v = false;
        }
    }
    m
}

/// A channel of `signal` placed on the fused grid starting at global index `origin`, `n` long.
fn place(signal: &StitchedSignal, ch: usize, origin: i64, n: usize) -> (Vec<f64>, Vec<bool>) {
    let mut v = vec![0.0; n];
    let mut ok = vec![false; n];
    let Some(data) = signal.channels.get(ch) else {
        return (v, ok);
    };
    let mask = valid_mask(signal, data.len());
    let offset = (signal.start_um / signal.spacing_um).round() as i64 - origin;
    for (i, (&x, &good)) in data.iter().zip(&mask).enumerate() {
        let Ok(j) = usize::try_from(i as i64 + offset) else {
            continue;
        };
        if j < n && good && x.is_finite() {
            v[j] = f64::from(x);
            ok[j] = true;
        }
    }
    (v, ok)
}

/// Periodic √Hann window of length `n` (its squares at half overlap sum to one).
fn sqrt_hann(n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| (0.5 - 0.5 * (2.0 * PI * i as f64 / n as f64).cos()).sqrt())
        .collect()
}

/// One block's spectra: flow (re, im), edges (re, im), and its [`Filled`] shares.
type BlockSpectra = (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>, Filled);

/// How much of a block was filled from the other method.
#[derive(Clone, Copy, Debug)]
struct Filled {
    /// Share of its samples where one method was missing.
    samples: f64,
    /// Share of its window's energy where both methods had data.
    both_energy: f64,
}

/// Inverse FFT (normalised) by the conjugate trick.
fn ifft_in_place(fft: &ComplexFft, re: &mut [f64], im: &mut [f64]) {
    for v in im.iter_mut() {
        *v = -*v;
    }
    fft.forward(re, im);
    let n = re.len() as f64;
    for (r, i) in re.iter_mut().zip(im.iter_mut()) {
        *r /= n;
        *i = -*i / n;
    }
}

/// One channel fused: the output samples, the blocks' models.
struct ChannelFusion {
    out: Vec<f64>,
    blocks: Vec<(i64, Option<NoiseModel>)>,
}

/// Each analysis block's edge noise level `a` (its power at ω is `a·ω²`) from per-sample
/// displacement noise `sigma` (velocity units per radian per sample): `Σ w_k²·σ_k²` over the
/// block's window, the missing samples taking the mean of the others. None where none is known.
fn block_edge_levels(
    sigma: &[f64],
    known: &[bool],
    starts: &[i64],
    window: &[f64],
) -> Vec<Option<f64>> {
    starts
        .iter()
        .map(|&s| {
            let (mut sum, mut w_known, mut w_all) = (0.0, 0.0, 0.0);
            for (k, &w) in window.iter().enumerate() {
                let Ok(i) = usize::try_from(s + k as i64) else {
                    continue;
                };
                if i >= sigma.len() {
                    continue;
                }
                w_all += w * w;
                if known[i] {
                    sum += w * w * sigma[i] * sigma[i];
                    w_known += w * w;
                }
            }
            (w_known > 0.0).then(|| sum * w_all / w_known)
        })
        .collect()
}

/// The signal power at a bin as the flow's signal-following error is fitted to and weighed by:
/// the geometric mean of the two readings' periodograms, `|F|·|E|` (the magnitude of their
/// cross-spectrum). The edges' own periodogram would count all of their noise as signal: where
/// the edge noise is the larger (speech's quiet high band, a damaged wall) it would read as
/// signal the flow missed and hand the edges the weight; in the mean it counts half as many
/// decibels. Not the cross-spectrum's real part, which would drop the noise but vanishes where
/// the flow's reading of a band is delayed or rotated against the edges', while the error it
/// follows does not.
fn signal_power(fr: f64, fi: f64, er: f64, ei: f64) -> f64 {
    fr.hypot(fi) * er.hypot(ei)
}

fn fuse_channel(
    flow: &[f64],
    flow_ok: &[bool],
    edges: &[f64],
    edges_ok: &[bool],
    edge_sigma: Option<[(&[f64], &[bool]); 2]>,
    block: usize,
    smoothing: usize,
) -> ChannelFusion {
    let n = flow.len();
    // Each method's gaps filled by the other.
    let f: Vec<f64> = (0..n)
        .map(|i| if flow_ok[i] { flow[i] } else { edges[i] })
        .collect();
    let e: Vec<f64> = (0..n)
        .map(|i| if edges_ok[i] { edges[i] } else { flow[i] })
        .collect();
    let hop = block / 2;
    let window = sqrt_hann(block);
    // One plan for every block's forward and inverse transform.
    let fft = ComplexFft::new(block);
    // Blocks start every hop from −hop so that every sample is covered by two blocks.
    let starts: Vec<i64> = (0..)
        .map(|k: i64| k * hop as i64 - hop as i64)
        .take_while(|&s| s < n as i64)
        .collect();
    let spectra: Vec<BlockSpectra> = starts
        .iter()
        .map(|&s| {
            let (mut fr, mut fi) = (vec![0.0; block], vec![0.0; block]);
            let (mut er, mut ei) = (vec![0.0; block], vec![0.0; block]);
            let mut filled = 0usize;
            let mut inside = 0usize;
            let (mut energy, mut both_energy) = (0.0, 0.0);
            for (k, &w) in window.iter().enumerate() {
                let Ok(i) = usize::try_from(s + k as i64) else {
                    continue;
                };
                if i >= n {
                    continue;
                }
                inside += 1;
                energy += w * w;
                if flow_ok[i] && edges_ok[i] {
                    both_energy += w * w;
                } else {
                    filled += 1;
                }
                fr[k] = w * f[i];
                er[k] = w * e[i];
            }
            fft.forward(&mut fr, &mut fi);
            fft.forward(&mut er, &mut ei);
            let share = Filled {
                samples: if inside > 0 {
                    filled as f64 / inside as f64
                } else {
                    1.0
                },
                both_energy: if energy > 0.0 {
                    both_energy / energy
                } else {
                    0.0
                },
            };
            (fr, fi, er, ei, share)
        })
        .collect();
    // Difference periodograms and signal powers of the blocks that may lend them
    // (positive-frequency bins 1..=N/2): the clean ones as measured, the gappy ones with the
    // difference scaled up by the energy its gaps took out.
    let half = block / 2;
    type Periodograms = (Vec<f64>, Vec<f64>);
    let periodograms = |(fr, fi, er, ei, _): &BlockSpectra, scale: f64| -> Periodograms {
        (1..=half)
            .map(|k| {
                (
                    ((fr[k] - er[k]).powi(2) + (fi[k] - ei[k]).powi(2)) * scale,
                    signal_power(fr[k], fi[k], er[k], ei[k]),
                )
            })
            .unzip()
    };
    let diff: Vec<Option<Periodograms>> = spectra
        .iter()
        .map(|b| (b.4.samples <= MAX_FILLED_SHARE).then(|| periodograms(b, 1.0)))
        .collect();
    let gappy: Vec<Option<Periodograms>> = spectra
        .iter()
        .map(|b| {
            (b.4.samples > MAX_FILLED_SHARE
                && b.4.samples <= MAX_GAPPY_FILLED_SHARE
                && b.4.both_energy > 0.0)
                .then(|| periodograms(b, 1.0 / b.4.both_energy))
        })
        .collect();
    let omega: Vec<f64> = (1..=half)
        .map(|k| 2.0 * PI * k as f64 / block as f64)
        .collect();
    // The known edge levels per block: from the fits' standard errors, and with the scatter.
    let edge_levels = edge_sigma.map(|sigmas| {
        sigmas.map(|(sigma, known)| block_edge_levels(sigma, known, &starts, &window))
    });
    let models: Vec<Option<NoiseModel>> = (0..spectra.len())
        .map(|b| {
            let lo = b.saturating_sub(smoothing);
            let hi = (b + smoothing + 1).min(diff.len());
            // The known edge levels, averaged over the same blocks as the spectra.
            let mean_level = |levels: &[Option<f64>]| {
                let (sum, known) = levels[lo..hi]
                    .iter()
                    .flatten()
                    .fold((0.0, 0usize), |(s, k), v| (s + v, k + 1));
                (known > 0).then(|| sum / known as f64)
            };
            let (edge, scattered) = edge_levels
                .as_ref()
                .map_or((None, None), |[f, s]| (mean_level(f), mean_level(s)));
            let mut acc = vec![0.0; half];
            let mut sig = vec![0.0; half];
            let mut count = 0usize;
            // The clean blocks near it lend their spectra; where there are none, the gappy ones.
            let lenders = if diff[lo..hi].iter().any(Option::is_some) {
                &diff[lo..hi]
            } else {
                &gappy[lo..hi]
            };
            for (d, e) in lenders.iter().flatten() {
                for ((a, v), (sa, sv)) in acc.iter_mut().zip(d).zip(sig.iter_mut().zip(e)) {
                    *a += v;
                    *sa += sv;
                }
                count += 1;
            }
            if count == 0 {
                return None;
            }
            for (a, sa) in acc.iter_mut().zip(&mut sig) {
                *a /= count as f64;
                *sa /= count as f64;
            }
            fit_with_scatter(&omega, &acc, &sig, edge, scattered)
        })
        .collect();
    // A block with no model of its own takes the nearest block's.
    let nearest = |b: usize| -> Option<NoiseModel> {
        (0..models.len())
            .filter_map(|k| models[k].map(|m| (k.abs_diff(b), m)))
            .min_by_key(|x| x.0)
            .map(|x| x.1)
    };
    let mut out = vec![0.0; n];
    let mut block_models = Vec::with_capacity(spectra.len());
    for (b, ((fr, fi, er, ei, _), &s)) in spectra.iter().zip(&starts).enumerate() {
        let model = models[b].or_else(|| nearest(b));
        block_models.push((s, model));
        let (mut re, mut im) = (vec![0.0; block], vec![0.0; block]);
        for k in 0..block {
            // Bin k and its mirror share a frequency.
            let kk = if k <= half { k } else { block - k };
            let omega = 2.0 * PI * kk as f64 / block as f64;
            // The block's own periodograms stand for the signal power at the bin.
            let signal = signal_power(fr[k], fi[k], er[k], ei[k]);
            let w = model.map_or(0.5, |m| m.edge_weight(omega, signal));
            re[k] = w * er[k] + (1.0 - w) * fr[k];
            im[k] = w * ei[k] + (1.0 - w) * fi[k];
        }
        ifft_in_place(&fft, &mut re, &mut im);
        for (k, (&v, &w)) in re.iter().zip(&window).enumerate() {
            if let Ok(i) = usize::try_from(s + k as i64)
                && i < n
            {
                out[i] += v * w;
            }
        }
    }
    ChannelFusion {
        out,
        blocks: block_models,
    }
}

/// The edge method's displacement noise per sample, on the edge signal's grid, in velocity
/// units (mm/s per radian per sample: the edge noise power at ω is its square times ω²; NaN
/// where unknown), one channel per output channel.
#[derive(Clone, Debug, PartialEq)]
pub struct EdgeNoise {
    /// From the border fits' standard errors.
    pub fitted: StitchedSignal,
    /// The same raised by how much more the borders scatter from sample to sample
    /// ([`crate::pipeline::edges::robust::scatter`]), which the fit may take instead
    /// ([`noise::fit_with_scatter`]).
    pub scattered: StitchedSignal,
}

/// Fuses the flow method's and the edge method's stitched velocity (mm/s, same spacing and
/// channel count; any start on the scan's grid) — see the module docs. With `edge_noise` the edge
/// noise level is known ([`EdgeNoise`]) and only the flow's is fitted.
///
/// # Errors
/// [`StageError::InvalidParam`] for bad params, [`StageError::BadInput`] when the signals'
/// spacing, rate or channel count differ or one is empty.
pub fn fuse(
    flow: &StitchedSignal,
    edges: &StitchedSignal,
    edge_noise: Option<&EdgeNoise>,
    meta: &ScanMeta,
    params: &FusionParams,
) -> Result<Fused, StageError> {
    params.validate()?;
    let bad = |problem: String| StageError::BadInput {
        stage: "fusion",
        problem,
    };
    check_range("flow spacing (µm)", flow.spacing_um, 1e-9, 1e9)?;
    if (flow.spacing_um - edges.spacing_um).abs() > 1e-9 * flow.spacing_um {
        return Err(bad(format!(
            "the flow and edge signals are sampled {} µm and {} µm apart",
            flow.spacing_um, edges.spacing_um
        )));
    }
    if flow.channels.len() != edges.channels.len() || flow.channels.is_empty() {
        return Err(bad(format!(
            "the flow signal has {} channels, the edge signal {}",
            flow.channels.len(),
            edges.channels.len()
        )));
    }
    let spacing = flow.spacing_um;
    let index = |s: &StitchedSignal| (s.start_um / spacing).round() as i64;
    let len = |s: &StitchedSignal| s.channels.first().map_or(0, Vec::len) as i64;
    let (starts, ends) = (
        [index(flow), index(edges)],
        [index(flow) + len(flow), index(edges) + len(edges)],
    );
    // The union of both grids, less an end where one method reaches only a few samples past
    // the other: that end is the inner one.
    let end_at = |outer: i64, inner: i64| {
        if (outer - inner).unsigned_abs() <= MAX_END_OVERHANG {
            inner
        } else {
            outer
        }
    };
    let origin = end_at(starts[0].min(starts[1]), starts[0].max(starts[1]));
    let end = end_at(ends[0].max(ends[1]), ends[0].min(ends[1]));
    let n = usize::try_from(end - origin).unwrap_or(0);
    if n == 0 {
        return Err(bad("both signals are empty".into()));
    }
    let block = params.block_samples.min(n.next_power_of_two() / 2).max(16);
    let rate = flow.native_rate_hz;
    let hz = |omega: f64| omega / (2.0 * PI) * rate;
    let mut channels = Vec::with_capacity(flow.channels.len());
    let mut blocks = Vec::new();
    let mut masks = Vec::new();
    let mut per_channel_models = Vec::new();
    for ch in 0..flow.channels.len() {
        let (fv, fok) = place(flow, ch, origin, n);
        let (ev, eok) = place(edges, ch, origin, n);
        let sigma = edge_noise.map(|s| {
            [
                place(&s.fitted, ch, origin, n),
                place(&s.scattered, ch, origin, n),
            ]
        });
        let fused = fuse_channel(
            &fv,
            &fok,
            &ev,
            &eok,
            sigma
                .as_ref()
                .map(|s| s.each_ref().map(|(v, ok)| (v.as_slice(), ok.as_slice()))),
            block,
            params.smoothing_blocks,
        );
        let any: Vec<bool> = fok.iter().zip(&eok).map(|(a, b)| *a || *b).collect();
        #[allow(clippy::cast_possible_truncation)] // velocities are stored as f32
        let samples: Vec<f32> = fused
            .out
            .iter()
            .zip(&any)
            .map(|(&v, &ok)| if ok { v as f32 } else { 0.0 })
            .collect();
        channels.push(samples);
        for &(start, model) in &fused.blocks {
            let Some(m) = model else { continue };
            let rms = |p: &dyn Fn(f64) -> f64| {
                let half = block / 2;
                let sum: f64 = (1..=half)
                    .map(|k| p(2.0 * PI * k as f64 / block as f64))
                    .sum();
                // Periodogram of √Hann-windowed blocks: power per bin ≈ σ²·N/2 for white noise.
                (2.0 * sum / (block as f64 * half as f64)).sqrt()
            };
            blocks.push(FusionBlock {
                channel: ch,
                start_sample: start,
                crossover_hz: hz(m.crossover_rad()),
                edge_weights: REPORT_FREQS_HZ
                    .iter()
                    .map(|f| m.edge_weight(2.0 * PI * f / rate, 0.0))
                    .collect(),
                flow_noise_mm_s: rms(&|_| m.flow),
                edge_noise_mm_s: rms(&|w| m.edge_at(w)),
            });
        }
        masks.push((fok, eok, any));
        per_channel_models.push(fused.blocks);
    }
    let mut gaps: Vec<Range<usize>> = Vec::new();
    for (_, _, any) in &masks {
        gaps.extend(false_runs(any.iter().copied()));
    }
    let merged = crate::pipeline::merge_ranges(gaps);
    let start_um = origin as f64 * spacing;
    let groups = map_groups(
        &masks,
        &per_channel_models,
        start_um,
        spacing,
        block,
        meta,
        rate,
    );
    Ok(Fused {
        signal: StitchedSignal {
            start_um,
            spacing_um: spacing,
            native_rate_hz: rate,
            channels,
            gaps: merged,
        },
        blocks,
        groups,
    })
}

type Masks = (Vec<bool>, Vec<bool>, Vec<bool>);

/// The groups, in order, that samples `0..n` (at `start_um + i·spacing`) can fall in: each
/// sample's group and its two neighbours, so that rounding at a boundary loses none. A
/// group whose span holds a sample is always among them, and there are at most 3·n, however
/// the metadata sizes the step (a step of 1e-300 µm once asked for 2⁶⁴ groups).
fn candidate_groups(n: usize, start_um: f64, spacing: f64, step: f64) -> Vec<usize> {
    let mut groups: Vec<usize> = Vec::new();
    for i in 0..n {
        let g = ((start_um + i as f64 * spacing) / step).floor().max(0.0) as usize;
        for c in [g.saturating_sub(1), g, g.saturating_add(1)] {
            if groups.last().is_none_or(|&l| c > l) {
                groups.push(c);
            }
        }
    }
    groups
}

/// The blocks' crossovers and weights as they fell on each group of the scan.
fn map_groups(
    masks: &[Masks],
    models: &[Vec<(i64, Option<NoiseModel>)>],
    start_um: f64,
    spacing: f64,
    block: usize,
    meta: &ScanMeta,
    rate: f64,
) -> Vec<GroupFusion> {
    let step = meta.motion.group_step_um;
    let n = masks.first().map_or(0, |m| m.0.len());
    if step <= 0.0 || n == 0 {
        return Vec::new();
    }
    candidate_groups(n, start_um, spacing, step)
        .into_iter()
        .filter_map(|g| {
            let lo = ((g as f64 * step - start_um) / spacing).max(0.0) as usize;
            let hi = ((g as f64 + 1.0) * step - start_um) / spacing;
            let hi = hi.max(0.0) as usize;
            let hi = hi.min(n);
            if lo >= hi {
                return None;
            }
            let mid = (lo + hi) as i64 / 2;
            let mut report = GroupFusion {
                group: g,
                crossover_hz: Vec::new(),
                edge_weights: Vec::new(),
                edges_only: Vec::new(),
                flow_only: Vec::new(),
            };
            for ((fok, eok, _), blocks) in masks.iter().zip(models) {
                let model = blocks
                    .iter()
                    .filter(|(s, _)| *s <= mid && mid < *s + block as i64)
                    .min_by_key(|(s, _)| (mid - (*s + block as i64 / 2)).abs())
                    .and_then(|(_, m)| *m);
                report
                    .crossover_hz
                    .push(model.map_or(f64::NAN, |m| m.crossover_rad() / (2.0 * PI) * rate));
                report.edge_weights.push(
                    REPORT_FREQS_HZ
                        .iter()
                        .map(|f| {
                            model.map_or(f64::NAN, |m| m.edge_weight(2.0 * PI * f / rate, 0.0))
                        })
                        .collect(),
                );
                let len = (hi - lo) as f64;
                report
                    .edges_only
                    .push((lo..hi).filter(|&i| eok[i] && !fok[i]).count() as f64 / len);
                report
                    .flow_only
                    .push((lo..hi).filter(|&i| fok[i] && !eok[i]).count() as f64 / len);
            }
            Some(report)
        })
        .collect()
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests;
