//! Benchmarks of the depth path on 1280×1024 frames: Kalman depth over six flow fields, wall finding and the robust wall fits of one group.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use groovescope::image::Image;
use groovescope::io::Geometry;
use groovescope::pipeline::depth::{DepthMap, DepthParams, estimate_depth};
use groovescope::pipeline::optical_flow::FlowField;
use groovescope::pipeline::orientation::{OrientationParams, orient_from_depth};
use groovescope::pipeline::walls::{WallParams, find_walls};

const WIDTH: usize = 1280;
const HEIGHT: usize = 1024;
/// Flow fields per group fed to the Kalman filter.
const FLOWS: usize = 6;
/// Spacing of the sample columns (one 44.1 kHz sample ≈ 55 px at 78 rpm).
const SAMPLE_SPACING_PX: usize = 55;

fn geometry() -> Geometry {
    Geometry {
        focal_px: 4000.0 / 0.39,
        pixel_pitch_um: 0.39,
        working_distance_um: 4000.0,
        frame_step_um: 0.78,
    }
}

/// A deterministic Gaussian source (xorshift64* + Box–Muller).
struct Rng(u64);

impl Rng {
    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
    }

    fn gauss(&mut self) -> f64 {
        let u1 = self.uniform().max(1e-300);
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * self.uniform()).cos()
    }
}

/// Depth seen at pixel (x, y) with the camera at X = `cam_um`: an 80 µm deep 45° groove with a
/// 10 µm bottom, displaced laterally by a 1 kHz-like sine.
fn groove_z(x: usize, y: usize, cam_um: f64, g: &Geometry) -> f64 {
    let (cx, cy) = ((WIDTH as f64 - 1.0) / 2.0, (HEIGHT as f64 - 1.0) / 2.0);
    let (px, py) = ((x as f64 - cx) / g.focal_px, (y as f64 - cy) / g.focal_px);
    let (land, depth, half_bottom) = (g.working_distance_um, 80.0, 5.0);
    let mut z = land;
    for _ in 0..8 {
        let d = 10.0 * (std::f64::consts::TAU * (px * z + cam_um) / 900.0).sin();
        let inner = depth + half_bottom - (py * z - d).abs();
        z = land + inner.clamp(0.0, depth);
    }
    z
}

fn flows(g: &Geometry) -> Vec<FlowField> {
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    (0..FLOWS)
        .map(|k| {
            let cam = k as f64 * g.frame_step_um;
            let u = Image::from_fn(WIDTH, HEIGHT, |x, y| {
                let z = groove_z(x, y, cam, g);
                (-g.focal_px * g.frame_step_um / z + 0.01 * rng.gauss()) as f32
            });
            FlowField::exact(u, k)
        })
        .collect()
}

fn noisy_depth(g: &Geometry) -> DepthMap {
    let mut rng = Rng(7);
    DepthMap {
        z_um: Image::from_fn(WIDTH, HEIGHT, |x, y| {
            (groove_z(x, y, 0.0, g) + 0.5 * rng.gauss()) as f32
        }),
        variance: Image::filled(WIDTH, HEIGHT, 0.25),
        frame_index: 0,
        warnings: Vec::new(),
    }
}

/// CPU seconds this process has used (user + system), from /proc/self/stat (Linux).
fn cpu_secs() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return f64::NAN;
    };
    // Fields after the ")" that closes the command name: state is field 3, utime 14, stime 15.
    let Some(rest) = stat.rsplit(')').next() else {
        return f64::NAN;
    };
    let f: Vec<f64> = rest
        .split_whitespace()
        .skip(11)
        .take(2)
        .filter_map(|v| v.parse().ok())
        .collect();
    f.iter().sum::<f64>() / 100.0
}

/// Prints wall and CPU time per call of `f` over `n` calls (the machine may be shared, so CPU
/// time is the steadier figure).
fn report(name: &str, n: u32, mut f: impl FnMut()) {
    if std::env::var("DEPTH_BENCH_ONLY").is_ok_and(|only| only != name) {
        return;
    }
    let (t0, c0) = (std::time::Instant::now(), cpu_secs());
    for _ in 0..n {
        f();
    }
    let (wall, cpu) = (t0.elapsed().as_secs_f64(), cpu_secs() - c0);
    eprintln!(
        "{name}: {:.1} ms wall, {:.1} ms CPU per call",
        wall * 1e3 / f64::from(n),
        cpu * 1e3 / f64::from(n)
    );
}

fn bench_depth(c: &mut Criterion) {
    let g = geometry();
    let fl = flows(&g);
    for (name, params) in [
        ("kalman", DepthParams::default()),
        (
            "kalman without median",
            DepthParams {
                median_px: 1,
                ..DepthParams::default()
            },
        ),
        (
            "average",
            DepthParams {
                kalman: false,
                ..DepthParams::default()
            },
        ),
    ] {
        report(name, 3, || {
            black_box(estimate_depth(&fl, &g, &params).ok());
        });
    }
    if std::env::var_os("DEPTH_BENCH_PARTS").is_some() {
        let one = DepthParams {
            median_px: 1,
            ..DepthParams::default()
        };
        report("kalman, 1 flow, no median", 3, || {
            black_box(estimate_depth(&fl[..1], &g, &one).ok());
        });
        let mut blind = fl.clone();
        for f in &mut blind {
            f.confidence.data.fill(0.0);
        }
        report("kalman, 6 flows, prediction only", 3, || {
            black_box(estimate_depth(&blind, &g, &one).ok());
        });
    }
    let mut group = c.benchmark_group("depth");
    group.sample_size(10);
    group.bench_function("kalman_6x1280x1024", |b| {
        b.iter(|| estimate_depth(black_box(&fl), &g, &DepthParams::default()));
    });
    let avg = DepthParams {
        kalman: false,
        ..DepthParams::default()
    };
    group.bench_function("average_6x1280x1024", |b| {
        b.iter(|| estimate_depth(black_box(&fl), &g, &avg));
    });
    group.finish();
}

fn bench_walls_and_fits(c: &mut Criterion) {
    let g = geometry();
    let depth = noisy_depth(&g);
    let Ok(walls) = find_walls(&depth, &g, &WallParams::default()) else {
        eprintln!("no walls in the benchmark groove");
        return;
    };
    let columns: Vec<f32> = (0..)
        .map(|i| (25 + i * SAMPLE_SPACING_PX) as f32)
        .take_while(|&x| x < (WIDTH - 25) as f32)
        .collect();
    let params = OrientationParams::default();
    if let Ok(o) = orient_from_depth(&depth, &walls, &columns, &g, &params) {
        let fits: Vec<_> = o
            .walls
            .iter()
            .flat_map(|w| w.samples.iter().filter_map(|s| s.fit))
            .collect();
        let points = o.weight_map.data.iter().filter(|v| v.is_finite()).count();
        let rounds: u32 = fits.iter().map(|f| f.iterations).sum();
        eprintln!(
            "{} walls, {} samples, {} fits, {points} distinct pixels, mean rounds {:.1}",
            o.walls.len(),
            columns.len(),
            fits.len(),
            f64::from(rounds) / fits.len().max(1) as f64
        );
    }
    report("find_walls", 5, || {
        black_box(find_walls(&depth, &g, &WallParams::default()).ok());
    });
    report("orient_from_depth robust", 5, || {
        black_box(orient_from_depth(&depth, &walls, &columns, &g, &params).ok());
    });
    let mut group = c.benchmark_group("walls");
    group.sample_size(10);
    group.bench_function("find_walls_1280x1024", |b| {
        b.iter(|| find_walls(black_box(&depth), &g, &WallParams::default()));
    });
    group.bench_function("orient_from_depth_group", |b| {
        b.iter(|| orient_from_depth(black_box(&depth), &walls, &columns, &g, &params));
    });
    let plain = OrientationParams {
        robust: false,
        ..OrientationParams::default()
    };
    group.bench_function("orient_from_depth_group_least_squares", |b| {
        b.iter(|| orient_from_depth(black_box(&depth), &walls, &columns, &g, &plain));
    });
    group.finish();
}

criterion_group!(benches, bench_depth, bench_walls_and_fits);
criterion_main!(benches);
