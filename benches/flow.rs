//! Benchmarks of the derivative and optical-flow stages on full 1280×1024 frames.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use groovescope::image::Image;
use groovescope::pipeline::derivatives::{DerivativeParams, Derivatives, compute_derivatives};
use groovescope::pipeline::optical_flow::{
    FlowMethod, FlowParams, Solver, WallSideMap, compute_flow,
};

const WIDTH: usize = 1280;
const HEIGHT: usize = 1024;
const FRAMES: usize = 12;
/// Land flow of the paper's optics (0.78 µm step / 0.39 µm per px).
const LAND_FLOW_PX: f64 = -2.0;
const FOCAL_PX: f64 = 10_256.0;

/// A smooth random texture: uniform noise box-blurred three times (radius 2).
fn texture(width: usize, height: usize, seed: u64) -> Vec<f32> {
    let mut state = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
    let mut data: Vec<f32> = (0..width * height)
        .map(|_| {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (state >> 40) as f32 / (1_u64 << 24) as f32
        })
        .collect();
    let r = 2_isize;
    for _ in 0..3 {
        let src = data.clone();
        for y in 0..height as isize {
            for x in 0..width as isize {
                let mut acc = 0.0;
                for dy in -r..=r {
                    for dx in -r..=r {
                        let xx = (x + dx).clamp(0, width as isize - 1) as usize;
                        let yy = (y + dy).clamp(0, height as isize - 1) as usize;
                        acc += src[yy * width + xx];
                    }
                }
                data[y as usize * width + x as usize] = acc / 25.0;
            }
        }
    }
    data
}

/// A group whose content moves by `LAND_FLOW_PX` per frame.
fn group() -> Vec<Image> {
    let margin = FRAMES * 3;
    let big_w = WIDTH + margin;
    let tex = texture(big_w, HEIGHT, 1);
    (0..FRAMES)
        .map(|k| {
            let off = (-LAND_FLOW_PX) as usize * k;
            Image::from_fn(WIDTH, HEIGHT, |x, y| tex[y * big_w + x + off])
        })
        .collect()
}

fn middle(frames: &[Image]) -> Derivatives {
    let mut sets =
        compute_derivatives(frames, LAND_FLOW_PX, &DerivativeParams::default()).unwrap_or_default();
    let k = sets.len() / 2;
    sets.swap_remove(k)
}

fn benches(c: &mut Criterion) {
    // As the `groovescope` binary does at start-up.
    groovescope::alloc::keep_freed_buffers();
    let frames = group();
    let mut g = c.benchmark_group("flow_1280x1024");
    g.sample_size(10);
    g.bench_function("derivatives_simoncelli_12_frames", |b| {
        b.iter(|| {
            compute_derivatives(
                black_box(&frames),
                LAND_FLOW_PX,
                &DerivativeParams::default(),
            )
        })
    });
    let fractional = -2.3;
    g.bench_function("derivatives_simoncelli_12_frames_subpixel_prewarp", |b| {
        b.iter(|| compute_derivatives(black_box(&frames), fractional, &DerivativeParams::default()))
    });
    let d = middle(&frames);
    // Exactly 100 iterations: no early stop.
    let fixed = |method, solver, omega| FlowParams {
        method,
        solver,
        sor_omega: omega,
        max_iterations: 100,
        tolerance_px: 0.0,
        ..FlowParams::default()
    };
    for (name, p) in [
        (
            "hs_gauss_seidel_100_iterations",
            fixed(FlowMethod::HornSchunck, Solver::GaussSeidel, 1.0),
        ),
        (
            "hs_sor_100_iterations",
            fixed(FlowMethod::HornSchunck, Solver::GaussSeidel, 1.7),
        ),
        (
            "hs_jacobi_100_iterations",
            fixed(FlowMethod::HornSchunck, Solver::Jacobi, 1.0),
        ),
        (
            "lucas_kanade_7px",
            fixed(FlowMethod::LucasKanade, Solver::GaussSeidel, 1.0),
        ),
    ] {
        g.bench_function(name, |b| {
            b.iter(|| compute_flow(black_box(&d), FOCAL_PX, None, &p))
        });
    }
    // Walls: a groove band across the middle (upper wall +1, lower wall −1).
    let walls = WallSideMap {
        width: WIDTH,
        height: HEIGHT,
        sign: (0..WIDTH * HEIGHT)
            .map(|i| match i / WIDTH {
                300..=499 => 1,
                524..=723 => -1,
                _ => 0,
            })
            .collect(),
    };
    let groove = fixed(FlowMethod::GrooveHornSchunck, Solver::GaussSeidel, 1.7);
    g.bench_function("groove_hs_given_walls_100_iterations", |b| {
        b.iter(|| compute_flow(black_box(&d), FOCAL_PX, Some(&walls), &groove))
    });
    let defaults = FlowParams::default();
    g.bench_function("groove_hs_defaults_estimated_walls", |b| {
        b.iter(|| compute_flow(black_box(&d), FOCAL_PX, None, &defaults))
    });
    g.finish();
}

criterion_group!(flow, benches);
criterion_main!(flow);
