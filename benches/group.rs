//! One whole 12-frame 1280×1024 group through every stage (issue 2's ≤ 0.5 s target), on the depth path and on the dual-focus path (with the flow field, as the workbench shows it, and as `reconstruct` runs it), plus decoding the group's PNG frames.
//!
//! `cargo bench --no-default-features --bench group` (add `-- --quick` for a short run). The
//! groups are rendered by the synth generator (the paper's camera) into a temporary folder.

mod common;

use std::hint::black_box;

use common::render_group;
use criterion::{Criterion, criterion_group, criterion_main};
use groovescope::engine::run_group;
use groovescope::io::load_group;
use groovescope::pipeline::slope_reference::SlopeReference;
use groovescope::pipeline::{Method, PipelineParams, Stage, StageCache};
use groovescope::synth::SynthConfig;

fn bench(c: &mut Criterion) {
    // As the `groovescope` binary does at start-up.
    groovescope::alloc::keep_freed_buffers();
    let tmp = tempfile::tempdir().expect("tempdir");
    // The flow method's stages (the edge stage has its own bench, benches/edges.rs).
    let params = PipelineParams {
        method: Method::Flow,
        ..PipelineParams::default()
    };
    let mut g = c.benchmark_group("group_12x1280x1024");
    g.sample_size(10);
    for (name, cfg) in [
        ("depth_path", SynthConfig::default()),
        ("dual_focus", SynthConfig::dual_focus_demo()),
    ] {
        let (scan, input) = render_group(&tmp.path().join(name), cfg, 1000.0);
        assert_eq!(input.frames.len(), 12, "{name}: frames per group");
        g.bench_function(format!("{name}: every stage"), |b| {
            b.iter(|| {
                let mut cache = StageCache::default();
                let r = cache.run_from(Stage::Derivatives, &input, &params, &mut |_, _| true);
                black_box((r.is_ok(), cache))
            });
        });
        // What `reconstruct` runs: on the dual-focus path the flow stage gives only the in-focus
        // map (the depth path is the same as above).
        if name == "dual_focus" {
            g.bench_function(
                format!("{name}: every stage, as reconstruct runs it"),
                |b| {
                    b.iter(|| {
                        black_box(
                            run_group(&input, &params, &SlopeReference::default())
                                .2
                                .is_ok(),
                        )
                    });
                },
            );
        }
        g.bench_function(format!("{name}: decode 12 PNG frames"), |b| {
            b.iter(|| black_box(load_group(&scan.groups[0]).map(|f| f.len())));
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
