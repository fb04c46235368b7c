//! The decoders side by side on one scan: the flow, edge and fused methods, each run by the
//! engine as `reconstruct --method` runs it, and scored against the scan's reference.

use std::path::Path;

use super::{AccuracyError, case_err};
use crate::engine::{ReconstructOptions, Reconstruction, reconstruct};
use crate::io::Scan;
use crate::pipeline::audio_signal::StitchedSignal;
use crate::pipeline::edges::EdgeParams;
use crate::pipeline::eval::Scores;
use crate::pipeline::finish::FusionReport;
use crate::pipeline::fusion::FusionParams;
use crate::pipeline::{Method, PipelineParams};

/// Scores of every decoder on one scan.
#[derive(Clone, Debug)]
pub struct MethodScores {
    /// The flow method.
    pub flow: Scores,
    /// The edge method (border tracks stitched over the clip, combined, differentiated).
    pub edges: Scores,
    /// The fused decoder.
    pub fused: Scores,
    /// What the fusion found (crossovers, weights).
    pub fusion: Option<FusionReport>,
    /// Warnings of the edge method's run (lost borders, gaps).
    pub edge_warnings: Vec<String>,
    /// Flow, edge and reference velocity (mm/s, mono) on the flow's stitched grid, when the
    /// reference's scale is known (for spectra of each method's error).
    pub debug: Option<(Vec<f64>, Vec<f64>, Vec<f64>)>,
}

/// One method's reconstruction of `scan`.
fn run(
    case: &str,
    scan: &Scan,
    params: &PipelineParams,
    method: Method,
) -> Result<(Reconstruction, Scores), AccuracyError> {
    let opts = ReconstructOptions {
        params: PipelineParams {
            method,
            ..params.clone()
        },
        groups: None,
        keep_going: true,
    };
    let rec = reconstruct(scan, &opts, &mut |_| {}, crate::job::interrupted())
        .map_err(|e| case_err(case, format!("{}: {e}", method.name())))?;
    let scores = rec
        .scores
        .ok_or_else(|| case_err(case, "the scan has no reference.wav to score against"))?;
    Ok((rec, scores))
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
    let params = PipelineParams {
        edges: edges.clone(),
        fusion: fusion.clone(),
        ..params.clone()
    };
    let (flow_rec, flow) = run(case, &scan, &params, Method::Flow)?;
    let (edge_rec, edge_scores) = run(case, &scan, &params, Method::Edges)?;
    let (fused_rec, fused) = run(case, &scan, &params, Method::Fused)?;
    let debug = common_grid(&scan, &flow_rec.stitched, &edge_rec.stitched);
    Ok(MethodScores {
        flow,
        edges: edge_scores,
        fused,
        fusion: fused_rec.fusion,
        edge_warnings: edge_rec.warnings,
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
        for (name, s) in [("flow", &m.flow), ("edges", &m.edges), ("fused", &m.fused)] {
            eprintln!(
                "{name:16} r {:.4} SNR {:6.2} dB lag {}",
                s.r,
                s.snr_db,
                s.lag_text(3)
            );
        }
        for b in m.fusion.iter().flat_map(|f| &f.blocks) {
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
