//! Benchmarks of the ground-truth generator: one paper-sized 12-frame group, plain and dual focus.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use groovescope::synth::{DamageConfig, Groove, SynthConfig, tone};

fn bench_groups(c: &mut Criterion) {
    let sound = tone(1000.0, 0.02, 44_100);
    let plain = SynthConfig {
        max_groups: Some(1),
        damage: DamageConfig {
            scratches_per_mm: 2.0,
            dust_per_mm2: 20.0,
            missing_wall_chunks_per_mm: 0.5,
            ..DamageConfig::default()
        },
        ..SynthConfig::default()
    };
    let Ok(groove) = Groove::new(&sound, &plain) else {
        return;
    };
    let mut g = c.benchmark_group("synth");
    g.sample_size(10);
    g.bench_function("group_1280x1024x12", |b| {
        b.iter(|| black_box(groove.render_group(0)));
    });
    g.bench_function("frame_1280x1024", |b| {
        b.iter(|| black_box(groove.render_frame(0, 3)));
    });
    let dual = SynthConfig {
        max_groups: Some(1),
        ..SynthConfig::dual_focus_demo()
    };
    if let Ok(groove) = Groove::new(&sound, &dual) {
        g.bench_function("dual_focus_frame_1280x1024", |b| {
            b.iter(|| black_box(groove.render_frame(0, 3)));
        });
    }
    g.finish();
}

criterion_group!(benches, bench_groups);
criterion_main!(benches);
