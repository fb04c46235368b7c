//! Benchmarks of the still decoder on the 1000 × 4000 px test still (7 grooves, all
//! artefacts): the pure decoder in memory, and the whole `still` command's work from a PNG file
//! (two streamed passes, DSP, normalisation). Target: ≤ 0.5 s.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use groovescope::pipeline::PipelineParams;
use groovescope::pipeline::still::{StillParams, StillSetup, analyse_still};
use groovescope::still::decode_still_file;
use groovescope::synth::still::{StillConfig, StillScene, render_still, write_still};

fn benches(c: &mut Criterion) {
    groovescope::alloc::keep_freed_buffers();
    let cfg = StillConfig::default();
    let Ok(scene) = StillScene::new(&cfg, None) else {
        return;
    };
    let image = render_still(&scene).image;
    let setup = StillSetup {
        axis: cfg.axis,
        um_per_px: cfg.um_per_px,
        rpm: cfg.rpm,
        radius_mm: scene.grooves[3].radius_mm,
        cut: cfg.cut,
        reverse: false,
    };
    let params = StillParams::default();
    let mut group = c.benchmark_group("still 1000x4000");
    group.sample_size(10);
    group.bench_function("decode in memory (groove 4)", |b| {
        b.iter(|| analyse_still(black_box(&image), &setup, Some(4), &params));
    });
    let Ok(dir) = tempfile::tempdir() else {
        return;
    };
    let Ok(summary) = write_still(&scene, &dir.path().join("s")) else {
        return;
    };
    let pipeline = PipelineParams::default();
    group.bench_function("decode the PNG file (groove 4, DSP)", |b| {
        b.iter(|| decode_still_file(black_box(&summary.image), &setup, Some(4), &pipeline));
    });
    group.finish();
}

criterion_group!(still, benches);
criterion_main!(still);
