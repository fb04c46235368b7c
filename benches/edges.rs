//! The edge stage on one 12-frame 1280×1024 group (issue 17's ≤ 20 ms target), on the depth-path camera and the dual-focus camera.
//!
//! `cargo bench --no-default-features --bench edges` (add `-- --quick` for a short run). The
//! groups are rendered by the synth generator (the paper's camera) into a temporary folder.

use std::hint::black_box;
use std::path::Path;
use std::sync::atomic::AtomicBool;

use criterion::{Criterion, criterion_group, criterion_main};
use groovescope::image::Image;
use groovescope::io::{Scan, ScanMeta, load_group};
use groovescope::pipeline::PipelineParams;
use groovescope::pipeline::edges::detect_edges;
use groovescope::synth::{SynthConfig, render_scan, tone};

/// Renders one group of `cfg` into `dir` and loads its frames.
fn group(dir: &Path, cfg: SynthConfig) -> (ScanMeta, Vec<Image>) {
    let cfg = SynthConfig {
        max_groups: Some(1),
        ..cfg
    };
    render_scan(
        &tone(1000.0, 0.05, 44_100),
        &cfg,
        dir,
        &|_, _| {},
        &AtomicBool::new(false),
    )
    .expect("synthetic scan");
    let scan = Scan::open(dir).expect("scan");
    let frames = load_group(&scan.groups[0]).expect("frames");
    (scan.meta, frames)
}

fn bench(c: &mut Criterion) {
    // As the `groovescope` binary does at start-up.
    groovescope::alloc::keep_freed_buffers();
    let tmp = tempfile::tempdir().expect("tempdir");
    let params = PipelineParams::default();
    let mut g = c.benchmark_group("edges_12x1280x1024");
    g.sample_size(10);
    for (name, cfg) in [
        ("depth_camera", SynthConfig::default()),
        ("dual_focus_camera", SynthConfig::dual_focus_demo()),
    ] {
        let (meta, frames) = group(&tmp.path().join(name), cfg);
        assert_eq!(frames.len(), 12, "{name}: frames per group");
        assert_eq!(
            (frames[0].width, frames[0].height),
            (1280, 1024),
            "{name}: frame size"
        );
        g.bench_function(format!("{name}: edge stage"), |b| {
            b.iter(|| {
                black_box(
                    detect_edges(&frames, 0, 0, &meta, &params.sound, &params.edges)
                        .map(|e| e.positions_um.len()),
                )
            });
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
