//! The decoders side by side on one scan: the flow method (the engine as `reconstruct` runs it),
//! the edge method (per-group velocity, and border tracks stitched over the clip) and the fused
//! decoder, each finished and scored the way the engine finishes and scores its own sound.

use std::path::Path;
use std::sync::atomic::AtomicBool;

use super::{AccuracyError, case_err};
use crate::engine::{
    MAX_EVAL_LAG_SECS, ReconstructOptions, aligned_reference, bridge_short_gaps, reconstruct,
};
use crate::io::wav::Audio;
use crate::io::{Scan, load_group};
use crate::pipeline::PipelineParams;
use crate::pipeline::audio_signal::{GroupSignal, StitchedSignal, resample, stitch};
use crate::pipeline::dsp::apply_dsp;
use crate::pipeline::edges::{EdgeParams, decode_border_signal, detect_edges};
use crate::pipeline::eval::{Scores, evaluate};
use crate::pipeline::fusion::{Fused, FusionParams, fuse};
use crate::pipeline::sampling::native_spacing_um;

/// Scores of every decoder on one scan.
#[derive(Clone, Debug)]
pub struct MethodScores {
    /// The flow method (`reconstruct`).
    pub flow: Scores,
    /// Edges, each group differentiated on its own and stitched as the engine stitches flow.
    pub edges_per_group: Scores,
    /// Edges, the border tracks stitched over the clip, then combined and differentiated.
    pub edges: Scores,
    /// The fused decoder (flow with the clip-stitched edges).
    pub fused: Scores,
    /// What the fusion found (crossovers, weights).
    pub fusion: Fused,
    /// Warnings of the edge stage (lost borders, gaps).
    pub edge_warnings: Vec<String>,
    /// Flow, edge and reference velocity (mm/s, mono) on the flow's stitched grid, when the
    /// reference's scale is known (for spectra of each method's error).
    pub debug: Option<(Vec<f64>, Vec<f64>, Vec<f64>)>,
}

/// Resamples, filters and levels a stitched velocity signal as the engine does, then scores
/// its mono mix against the scan's reference.
///
/// # Errors
/// A resampling, DSP or reference error, named by `case`.
pub fn finish_and_score(
    case: &str,
    stitched: &StitchedSignal,
    scan: &Scan,
    params: &PipelineParams,
) -> Result<(Audio, Scores), AccuracyError> {
    let out_rate = params.sound.output_rate_hz;
    let mut channels = Vec::with_capacity(stitched.channels.len());
    for ch in &stitched.channels {
        let mut y =
            resample(ch, stitched.native_rate_hz, out_rate).map_err(|e| case_err(case, e))?;
        apply_dsp(&mut y, f64::from(out_rate), &params.dsp).map_err(|e| case_err(case, e))?;
        channels.push(y);
    }
    let peak =
        channels.iter().flatten().fold(
            0.0f32,
            |m, v| if v.is_finite() { m.max(v.abs()) } else { m },
        );
    let gain = if peak > 0.0 { 0.89 / peak } else { 1.0 };
    for v in channels.iter_mut().flatten() {
        *v = if v.is_finite() { *v * gain } else { 0.0 };
    }
    let audio = Audio {
        sample_rate_hz: out_rate,
        channels,
    };
    let Some(reference) = &scan.reference else {
        return Err(case_err(
            case,
            "the scan has no reference.wav to score against",
        ));
    };
    let aligned = aligned_reference(&audio, stitched, scan.meta.groove_speed_mm_s(0), reference)
        .map_err(|e| case_err(case, e))?;
    let max_lag = (MAX_EVAL_LAG_SECS * f64::from(out_rate)) as usize;
    let scores = evaluate(&audio.mono(), &aligned, max_lag, out_rate)
        .ok_or_else(|| case_err(case, "too little overlap with reference.wav to score"))?;
    Ok((audio, scores))
}

/// Per group: the edge method's velocity and displacement signals, and notes.
type EdgeSignals = (Vec<GroupSignal>, Vec<GroupSignal>, Vec<String>);

/// The edge method's signals of a whole scan: per-group velocity and border tracks.
///
/// # Errors
/// A load or stage error, named by `case`.
pub fn edge_signals(
    case: &str,
    scan: &Scan,
    params: &PipelineParams,
    edges: &EdgeParams,
) -> Result<EdgeSignals, AccuracyError> {
    let mut velocity = Vec::new();
    let mut borders = Vec::new();
    let mut warnings = Vec::new();
    for entry in &scan.groups {
        let frames = load_group(entry).map_err(|e| case_err(case, e))?;
        let e = detect_edges(&frames, 0, entry.index, &scan.meta, &params.sound, edges)
            .map_err(|e| case_err(case, e))?;
        warnings.extend(e.warnings.iter().cloned());
        velocity.push(e.to_group_signal());
        borders.push(e.border_signal());
    }
    Ok((velocity, borders, warnings))
}

/// Runs every decoder on the scan in `dir` and scores each against its reference.
///
/// # Errors
/// Any load, stage or scoring error, named by `case`.
pub fn score_methods(
    case: &str,
    dir: &Path,
    params: &PipelineParams,
    edges: &EdgeParams,
    fusion: &FusionParams,
) -> Result<MethodScores, AccuracyError> {
    let scan = Scan::open(dir).map_err(|e| case_err(case, e))?;
    let opts = ReconstructOptions {
        params: params.clone(),
        groups: None,
        keep_going: true,
    };
    let rec = reconstruct(&scan, &opts, &mut |_| {}, &AtomicBool::new(false))
        .map_err(|e| case_err(case, e))?;
    let flow = rec
        .scores
        .ok_or_else(|| case_err(case, "the scan has no reference.wav to score against"))?;
    let (velocity, borders, edge_warnings) = edge_signals(case, &scan, params, edges)?;
    let spacing = native_spacing_um(&scan.meta, &params.sound);
    let mut per_group = stitch(&velocity, spacing).map_err(|e| case_err(case, e))?;
    bridge_short_gaps(&mut per_group);
    let (_, edges_per_group) = finish_and_score(case, &per_group, &scan, params)?;
    let stitched_borders = stitch(&borders, spacing).map_err(|e| case_err(case, e))?;
    let decoded = decode_border_signal(
        &stitched_borders,
        scan.meta.record.cut,
        scan.meta.groove_speed_mm_s(0),
        edges,
    )
    .map_err(|e| case_err(case, e))?;
    let (_, edge_scores) = finish_and_score(case, &decoded.velocity, &scan, params)?;
    let fused = fuse(&rec.stitched, &decoded.velocity, &scan.meta, fusion)
        .map_err(|e| case_err(case, e))?;
    let (_, fused_scores) = finish_and_score(case, &fused.signal, &scan, params)?;
    let debug = common_grid(&scan, &rec.stitched, &decoded.velocity);
    Ok(MethodScores {
        flow,
        edges_per_group,
        edges: edge_scores,
        fused: fused_scores,
        fusion: fused,
        edge_warnings,
        debug,
    })
}

/// Flow, edges and reference (mm/s, mono) on the flow's grid: the reference is read at the
/// native rate with `[synth_info] reference_unit_mm_s`.
fn common_grid(
    scan: &Scan,
    flow: &StitchedSignal,
    edges: &StitchedSignal,
) -> Option<(Vec<f64>, Vec<f64>, Vec<f64>)> {
    let unit = scan
        .meta
        .extra
        .get("synth_info")?
        .get("reference_unit_mm_s")?
        .as_float()?;
    let reference = crate::io::wav::read_wav(scan.reference.as_ref()?).ok()?;
    let mono = reference.mono();
    let rate = f64::from(reference.sample_rate_hz);
    let vt_um_s = scan.meta.groove_speed_mm_s(0) * 1000.0;
    let spacing = flow.spacing_um;
    let mono_of = |s: &StitchedSignal, i: usize| -> f64 {
        let k = s.channels.len().max(1) as f64;
        s.channels
            .iter()
            .map(|c| c.get(i).map_or(0.0, |&v| f64::from(v)))
            .sum::<f64>()
            / k
    };
    let off = ((edges.start_um - flow.start_um) / spacing).round() as i64;
    let n = flow.channels.first().map_or(0, Vec::len);
    let (mut f, mut e, mut r) = (Vec::new(), Vec::new(), Vec::new());
    for i in 0..n {
        let Ok(j) = usize::try_from(i as i64 - off) else {
            continue;
        };
        if j >= edges.channels.first().map_or(0, Vec::len) {
            continue;
        }
        let s_um = flow.start_um + i as f64 * spacing;
        let t = s_um / vt_um_s * rate;
        let k = t.floor() as usize;
        let (Some(&a), Some(&b)) = (mono.get(k), mono.get(k + 1)) else {
            continue;
        };
        let frac = t - k as f64;
        r.push((f64::from(a) * (1.0 - frac) + f64::from(b) * frac) * unit);
        f.push(mono_of(flow, i));
        e.push(mono_of(edges, j));
    }
    Some((f, e, r))
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;

    /// Scores every decoder on the scan in `$GROOVESCOPE_SCAN` (a measurement, not a test).
    #[test]
    #[ignore = "measurement: needs a rendered scan in GROOVESCOPE_SCAN"]
    fn measure_scan() {
        let Ok(dir) = std::env::var("GROOVESCOPE_SCAN") else {
            return;
        };
        let mut params = PipelineParams::default();
        params.dsp.lowpass = std::env::var("GROOVESCOPE_LOWPASS").is_ok();
        params.dsp.dc_block = std::env::var("GROOVESCOPE_NODC").is_err();
        let m = score_methods(
            "scan",
            Path::new(&dir),
            &params,
            &EdgeParams::default(),
            &FusionParams::default(),
        )
        .unwrap();
        for (name, s) in [
            ("flow", &m.flow),
            ("edges per group", &m.edges_per_group),
            ("edges", &m.edges),
            ("fused", &m.fused),
        ] {
            eprintln!(
                "{name:16} r {:.4} SNR {:6.2} dB lag {}",
                s.r, s.snr_db, s.lag_samples
            );
        }
        for b in &m.fusion.blocks {
            eprintln!(
                "block {:5} ch {} crossover {:7.0} Hz, flow noise {:.3} edge noise {:.3} mm/s, w {:?}",
                b.start_sample,
                b.channel,
                b.crossover_hz,
                b.flow_noise_mm_s,
                b.edge_noise_mm_s,
                b.edge_weights
            );
        }
        eprintln!("warnings: {:?}", m.edge_warnings);
        if let Some((f, e, r)) = &m.debug {
            let bands = [
                0.0, 250.0, 500.0, 1000.0, 2000.0, 4000.0, 8000.0, 16000.0, 22050.0,
            ];
            let spec = |x: &[f64]| band_powers(x, 44_100.0, &bands);
            let ef: Vec<f64> = f.iter().zip(r).map(|(a, b)| a - b).collect();
            let ee: Vec<f64> = e.iter().zip(r).map(|(a, b)| a - b).collect();
            let d: Vec<f64> = f.iter().zip(e).map(|(a, b)| a - b).collect();
            for (name, v) in [
                ("ref", r.clone()),
                ("flow err", ef),
                ("edge err", ee),
                ("F-E", d),
            ] {
                let p = spec(&v);
                eprintln!(
                    "{name:9} {}",
                    p.iter()
                        .map(|x| format!("{:8.3}", x.sqrt()))
                        .collect::<Vec<_>>()
                        .join(" ")
                );
            }
        }
    }

    /// RMS power in each band (Hz edges) of `x` at `rate`, by a Hann-windowed periodogram over
    /// 512-sample blocks.
    fn band_powers(x: &[f64], rate: f64, edges: &[f64]) -> Vec<f64> {
        use crate::pipeline::dsp::fft_in_place;
        let n = 512;
        let mut acc = vec![0.0; n / 2];
        let mut blocks = 0;
        let mut start = 0;
        while start + n <= x.len() {
            let mut re: Vec<f64> = (0..n)
                .map(|i| {
                    let w = 0.5 - 0.5 * (2.0 * std::f64::consts::PI * i as f64 / n as f64).cos();
                    w * x[start + i]
                })
                .collect();
            let mut im = vec![0.0; n];
            fft_in_place(&mut re, &mut im);
            for k in 0..n / 2 {
                acc[k] += (re[k] * re[k] + im[k] * im[k]) / (0.375 * n as f64) * 2.0 / n as f64;
            }
            blocks += 1;
            start += n / 2;
        }
        edges
            .windows(2)
            .map(|w| {
                (0..n / 2)
                    .filter(|&k| {
                        let f = k as f64 * rate / n as f64;
                        f >= w[0] && f < w[1]
                    })
                    .map(|k| acc[k] / f64::from(blocks.max(1)))
                    .sum()
            })
            .collect()
    }
}
