//! The edge stage on one 12-frame 1280×1024 group (issue 17's ≤ 20 ms target), on the depth-path camera and the dual-focus camera.
//!
//! `cargo bench --no-default-features --bench edges` (add `-- --quick` for a short run). The
//! groups are rendered by the synth generator (the paper's camera) into a temporary folder.

mod common;

use std::hint::black_box;

use common::render_group;
use criterion::{Criterion, criterion_group, criterion_main};
use groovescope::pipeline::edges::{EdgeParams, detect_edges};
use groovescope::pipeline::{GroupInput, PipelineParams, frames_read};
use groovescope::synth::SynthConfig;

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
        let (_, GroupInput { frames, meta, .. }) =
            render_group(&tmp.path().join(name), cfg, 1000.0);
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
        // With `edges.all_frames` off: the flow stages' frames (on the dual-focus path their
        // middle window of 7; on the depth path all 12, the same work as above).
        let lean = PipelineParams {
            edges: EdgeParams {
                all_frames: false,
                ..params.edges.clone()
            },
            ..params.clone()
        };
        let window = frames_read(frames.len(), &meta, &lean);
        if window.len() < frames.len() {
            let held = &frames[window.clone()];
            g.bench_function(format!("{name}: edge stage, flow window"), |b| {
                b.iter(|| {
                    black_box(
                        detect_edges(held, window.start, 0, &meta, &lean.sound, &lean.edges)
                            .map(|e| e.positions_um.len()),
                    )
                });
            });
        }
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
