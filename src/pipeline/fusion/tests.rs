//! Fused decoder tests: it beats both inputs on synthetic noises of the two kinds, reconstructs
//! agreeing inputs exactly, fills each method's gaps from the other and checks its inputs.

use super::*;
use crate::io::scan::test_support::scan_meta;
use crate::meta::ScanMeta;
use crate::synth::noise::Rng;

fn meta() -> ScanMeta {
    scan_meta(460.2)
}

/// [`fuse`] of `flow` and `edges` with no edge noise track, the test scan and default params.
fn fuse_default(flow: &StitchedSignal, edges: &StitchedSignal) -> Result<Fused, StageError> {
    fuse(flow, edges, None, &meta(), &FusionParams::default())
}

fn signal(start_sample: i64, channels: Vec<Vec<f32>>) -> StitchedSignal {
    StitchedSignal {
        start_um: start_sample as f64 * 21.3,
        spacing_um: 21.3,
        native_rate_hz: 44_100.0,
        channels,
        gaps: Vec::new(),
    }
}

/// A two-tone signal, the same plus flat noise (flow-like), and plus white noise through the
/// edge decoder's differentiator (edge-like: flat in displacement, so `σ²·ω²` in velocity).
fn inputs(n: usize, flow_sigma: f64, edge_sigma: f64) -> (Vec<f64>, Vec<f32>, Vec<f32>) {
    use crate::pipeline::edges::differentiator::{DifferentiatorParams, differentiate};
    let mut rng = Rng::new(3);
    let truth: Vec<f64> = (0..n)
        .map(|i| {
            let t = i as f64 / 44_100.0;
            30.0 * (2.0 * PI * 700.0 * t).sin() + 10.0 * (2.0 * PI * 4100.0 * t).sin()
        })
        .collect();
    let flow: Vec<f32> = truth
        .iter()
        .map(|&v| (v + flow_sigma * rng.gaussian()) as f32)
        .collect();
    let white: Vec<f64> = (0..n).map(|_| edge_sigma * rng.gaussian()).collect();
    let plain = DifferentiatorParams {
        aperture_samples: 0.0,
        ..DifferentiatorParams::default()
    };
    let edge_noise = differentiate(&white, &plain);
    let edges: Vec<f32> = truth
        .iter()
        .zip(&edge_noise)
        .map(|(&v, &e)| (v + e) as f32)
        .collect();
    (truth, flow, edges)
}

fn error_power(x: &[f32], truth: &[f64], range: Range<usize>) -> f64 {
    range
        .map(|i| (f64::from(x[i]) - truth[i]).powi(2))
        .sum::<f64>()
}

/// `x` with `k` times the truth added: a reading whose gain is off by `k`.
fn gain_off(x: &[f32], truth: &[f64], k: f64) -> Vec<f32> {
    x.iter()
        .zip(truth)
        .map(|(&v, &t)| v + (k * t) as f32)
        .collect()
}

/// Error powers of the flow input, the edge input and the fused output against `truth`, 300
/// samples in from each end.
fn error_powers(flow: &[f32], edges: &[f32], fused: &Fused, truth: &[f64]) -> (f64, f64, f64) {
    let inner = 300..truth.len() - 300;
    (
        error_power(flow, truth, inner.clone()),
        error_power(edges, truth, inner.clone()),
        error_power(&fused.signal.channels[0], truth, inner),
    )
}

#[test]
fn fusion_beats_both_inputs() {
    let n = 8192;
    let (truth, flow, edges) = inputs(n, 2.0, 2.0);
    let fused = fuse_default(
        &signal(100, vec![flow.clone()]),
        &signal(100, vec![edges.clone()]),
    )
    .unwrap();
    let (ef, ee, eu) = error_powers(&flow, &edges, &fused, &truth);
    eprintln!("error power: flow {ef:.0}, edges {ee:.0}, fused {eu:.0}");
    assert!(eu < 0.6 * ef.min(ee), "fused {eu} vs flow {ef}, edges {ee}");
    // Flow noise σ² = 4, edge noise 4·ω²: equal at ω = 1 rad/sample, i.e. 7.0 kHz.
    let mut xs: Vec<f64> = fused.blocks.iter().map(|b| b.crossover_hz).collect();
    xs.sort_by(f64::total_cmp);
    let median = xs[xs.len() / 2];
    assert!(
        (5_500.0..9_000.0).contains(&median),
        "crossover {median} Hz"
    );
    assert!(!fused.groups.is_empty());
    let w = &fused.groups[fused.groups.len() / 2].edge_weights[0];
    assert!(w[0] > 0.9 && w[3] < w[0], "{w:?}");
}

#[test]
fn agreeing_inputs_come_back_unchanged() {
    let n = 1000;
    let (truth, _, _) = inputs(n, 0.0, 0.0);
    let x: Vec<f32> = truth.iter().map(|&v| v as f32).collect();
    let fused = fuse_default(&signal(7, vec![x.clone()]), &signal(7, vec![x.clone()])).unwrap();
    assert_eq!(fused.signal.channels[0].len(), n);
    for (a, b) in fused.signal.channels[0].iter().zip(&x) {
        assert!((a - b).abs() < 1e-3, "{a} vs {b}");
    }
    assert!(fused.signal.gaps.is_empty());
}

#[test]
fn a_few_lone_samples_at_an_end_are_cut_and_a_longer_run_is_kept() {
    let n = 1000;
    let (truth, _, _) = inputs(n, 0.0, 0.0);
    let x: Vec<f32> = truth.iter().map(|&v| v as f32).collect();
    // The flow reaches 3 samples past the edges at the end (a wild last one) and 2 before them
    // at the start: both are overhangs, so the clip is the edges' own.
    let mut flow = vec![0.0f32, 0.0];
    flow.extend(&x);
    flow.extend([0.0, 0.0, 40.0]);
    let fused = fuse_default(&signal(5, vec![flow.clone()]), &signal(7, vec![x.clone()])).unwrap();
    assert_eq!(fused.signal.start_um, 7.0 * 21.3);
    assert_eq!(fused.signal.channels[0].len(), n);
    for (a, b) in fused.signal.channels[0].iter().zip(&x) {
        assert!((a - b).abs() < 1e-3, "{a} vs {b}");
    }
    // Twelve samples past the edges are the flow's to fill.
    flow.extend([0.0; 7]);
    let fused = fuse_default(&signal(7, vec![flow]), &signal(7, vec![x])).unwrap();
    assert_eq!(fused.signal.channels[0].len(), n + 12);
}

#[test]
#[allow(clippy::single_range_in_vec_init)] // one gap in each signal, on purpose
fn each_method_fills_the_others_gaps() {
    let n = 4096;
    let (truth, flow, edges) = inputs(n, 2.0, 0.5);
    let mut f = signal(0, vec![flow]);
    f.gaps = vec![1000..1600];
    let mut e = signal(0, vec![edges.clone()]);
    e.gaps = vec![3000..3100];
    // The edge signal also starts later: the grids are aligned by position.
    let e_late = StitchedSignal {
        start_um: 10.0 * 21.3,
        channels: vec![edges[10..].to_vec()],
        gaps: vec![2990..3090],
        ..e
    };
    let fused = fuse_default(&f, &e_late).unwrap();
    let out = &fused.signal.channels[0];
    assert_eq!(out.len(), n);
    // Deep inside the flow's gap the output is the edge signal.
    for i in 1100..1500 {
        assert!((f64::from(out[i]) - f64::from(edges[i])).abs() < 0.5, "{i}");
    }
    // Inside the edges' gap it tracks the truth about as well as the flow does.
    let err = error_power(out, &truth, 3020..3080) / 60.0;
    assert!(err < 6.0, "{err}");
    assert!(fused.signal.gaps.is_empty());
    let g = &fused.groups[0];
    assert!(g.edges_only[0] > 0.0 || fused.groups.iter().any(|g| g.edges_only[0] > 0.0));
}

#[test]
fn mismatched_inputs_are_refused() {
    let a = signal(0, vec![vec![0.0; 100]]);
    let two = signal(0, vec![vec![0.0; 100], vec![0.0; 100]]);
    assert!(fuse_default(&a, &two).is_err());
    let mut other = a.clone();
    other.spacing_um = 20.0;
    assert!(fuse_default(&a, &other).is_err());
    let bad = FusionParams {
        block_samples: 100,
        ..FusionParams::default()
    };
    assert!(fuse(&a, &a, None, &meta(), &bad).is_err());
}

#[test]
fn the_group_report_covers_each_sampled_group_once_whatever_the_step() {
    let n = 1000;
    let (truth, _, _) = inputs(n, 0.0, 0.0);
    let x: Vec<f32> = truth.iter().map(|&v| v as f32).collect();
    let s = signal(3, vec![x]);
    // 1000 samples of 21.3 µm from 63.9 µm on, in groups of 460.2 µm: groups 0 to 46.
    let fused = fuse_default(&s, &s).unwrap();
    let groups: Vec<usize> = fused.groups.iter().map(|g| g.group).collect();
    assert_eq!(groups, (0..=46).collect::<Vec<_>>());
    // A step far shorter than a sample (the fuzzer's scan asked for 2⁶⁴ groups): the group
    // numbers no longer fit a usize, so nothing is reported, with no overflow and no endless
    // loop. At a step of 1 nm each sample is a group of its own (but perhaps the first, whose
    // group's span the rounding of the boundaries can leave empty). scan.toml now refuses a
    // step under 1e-9 µm; the stage still takes metadata made in code.
    let mut tiny = scan_meta(460.2);
    tiny.motion.group_step_um = 1e-300;
    let fused = fuse(&s, &s, None, &tiny, &FusionParams::default()).unwrap();
    assert!(fused.groups.is_empty());
    let fused = fuse(&s, &s, None, &scan_meta(1e-3), &FusionParams::default()).unwrap();
    assert!(
        (n - 1..=n).contains(&fused.groups.len()),
        "{}",
        fused.groups.len()
    );
    assert!(fused.groups.windows(2).all(|w| w[0].group < w[1].group));
}

/// A flow with a third of its samples missing everywhere (a rough scan's rejected fits) leaves
/// no block clean enough to lend its spectrum; the gappy blocks lend theirs instead, so a flow
/// that reads the sound inverted and noisy is weighed down rather than averaged in at one half.
#[test]
fn a_flow_gappy_everywhere_still_gets_its_noise_measured() {
    let n = 4096;
    let (truth, flow, edges) = inputs(n, 20.0, 0.5);
    let mut f = signal(0, vec![gain_off(&flow, &truth, -1.5)]);
    // Runs of 2 to 10 samples missing, 4 to 20 apart: every block is about a third filled.
    let mut rng = Rng::new(11);
    let mut at = 0;
    while at < n {
        let (gap, run) = (rng.range(2.0, 10.0) as usize, rng.range(4.0, 20.0) as usize);
        f.gaps.push(at..(at + gap).min(n));
        at += gap + run;
    }
    let fills = f.gaps.iter().map(ExactSizeIterator::len).sum::<usize>();
    assert!((0.2..0.45).contains(&(fills as f64 / n as f64)), "{fills}");
    let e = signal(0, vec![edges.clone()]);
    let fused = fuse_default(&f, &e).unwrap();
    // Every block has a noise model (a block without one is left out of the list).
    assert_eq!(fused.blocks.len(), 4096 / 128 + 1);
    assert!(fused.blocks.iter().all(|b| b.crossover_hz.is_finite()));
    let (_, ee, eu) = error_powers(&f.channels[0], &edges, &fused, &truth);
    assert!(eu < 1.2 * ee, "fused {eu} vs edges {ee}");
}

/// A flow that under-reads the sound by a fifth (an error that follows the signal) beside edges
/// whose noise rises far above the sound's high tone: the edges' noise must not read as signal
/// the flow missed. Standing the edges' own periodogram for the signal, as the fusion did
/// before, left 0.101 of the better input's error power; the periodograms' geometric mean leaves
/// 0.054.
#[test]
fn noisy_edges_do_not_pass_for_signal_the_flow_missed() {
    let n = 8192;
    let (truth, flow, edges) = inputs(n, 1.0, 6.0);
    let under = gain_off(&flow, &truth, -0.2);
    let fused = fuse_default(
        &signal(0, vec![under.clone()]),
        &signal(0, vec![edges.clone()]),
    )
    .unwrap();
    let (ef, ee, eu) = error_powers(&under, &edges, &fused, &truth);
    assert!(
        eu < 0.075 * ef.min(ee),
        "fused {eu} vs flow {ef}, edges {ee}"
    );
}
