//! Benchmark of the dual-focus stripe stage on one synthetic 1280×1024 frame (about 5% of pixels in focus).

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use groovescope::io::scan::{DualFocusMeta, GlassSide};
use groovescope::pipeline::derivatives::Derivatives;
use groovescope::pipeline::hough::{HoughParams, segment_stripes, synthetic_input};
use groovescope::pipeline::optical_flow::FlowField;

const WIDTH: usize = 1280;
const HEIGHT: usize = 1024;
/// Fraction of pixels that are stray in-focus noise.
const NOISE_FRACTION: f32 = 0.04;

/// Three 3-px stripes that wiggle by ±6 px along x, plus stray in-focus pixels.
fn frame() -> (Derivatives, FlowField) {
    let mut state = 0x2545_f491_4f6c_dd1d_u64;
    let mut rand = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    let stripes = [(300.0_f32, 0.02_f32), (520.0, -0.01), (640.0, 0.015)];
    synthetic_input(WIDTH, HEIGHT, 0.5, |x, y| {
        let xf = x as f32;
        let on = stripes.iter().any(|&(row, slope)| {
            let centre = row + slope * (xf - 640.0) + 6.0 * (xf * 0.01).sin();
            (y as f32 - centre).abs() <= 1.0
        });
        on || rand() < NOISE_FRACTION
    })
}

/// Process CPU time (user + system) in seconds, from /proc (Linux); `None` elsewhere.
fn process_cpu_s() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    let rest = stat.get(stat.rfind(')')? + 2..)?;
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let ticks: f64 = fields.get(11)?.parse::<f64>().ok()? + fields.get(12)?.parse::<f64>().ok()?;
    // USER_HZ is 100 on Linux.
    Some(ticks / 100.0)
}

fn bench(c: &mut Criterion) {
    let (d, f) = frame();
    let dual = DualFocusMeta {
        focus_distance_mm: 4.05,
        glass_thickness_mm: 0.11,
        glass_index: 1.515,
        glass_side: GlassSide::Top,
        glass_edge_row: 580.0,
    };
    // The stripes wiggle by ±6 px: search peaks on ±8 px ρ bands (see `peak_rho_band_px`).
    let params = HoughParams {
        peak_rho_band_px: 8.0,
        min_votes_per_column: 1.0,
        ..HoughParams::default()
    };
    let in_focus = d.iy.data.iter().filter(|&&v| v > 0.0).count();
    println!(
        "in focus: {in_focus} px ({:.1}%)",
        100.0 * in_focus as f64 / (WIDTH * HEIGHT) as f64
    );
    match segment_stripes(&d, &f, &dual, &params) {
        Ok(s) => println!(
            "peaks at rows {:?}",
            s.peaks
                .iter()
                .map(|p| p.row_at_px(639.5).round())
                .collect::<Vec<_>>()
        ),
        Err(e) => panic!("the benchmark frame must give three stripes: {e}"),
    }
    // CPU time per call summed over all threads: on a busy shared machine wall time mostly measures
    // the other processes, CPU time / cores is the uncontended wall-time estimate.
    const CPU_RUNS: u32 = 50;
    if let Some(c0) = process_cpu_s() {
        let t0 = std::time::Instant::now();
        for _ in 0..CPU_RUNS {
            black_box(segment_stripes(black_box(&d), black_box(&f), &dual, &params).is_ok());
        }
        let wall_ms = t0.elapsed().as_secs_f64() * 1e3 / f64::from(CPU_RUNS);
        if let Some(c1) = process_cpu_s() {
            println!(
                "cpu {:.1} ms per call over all threads ({} rayon threads), wall {wall_ms:.1} ms",
                (c1 - c0) * 1e3 / f64::from(CPU_RUNS),
                rayon::current_num_threads()
            );
        }
    }
    c.bench_function("segment_stripes 1280x1024", |b| {
        b.iter(|| segment_stripes(black_box(&d), black_box(&f), &dual, &params));
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
