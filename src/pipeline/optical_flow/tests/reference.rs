//! The fast Horn–Schunck solves against the plain f64 reference (`reference.rs`): the same iteration, so after the same sweeps the two differ only by the f32 rounding of the fast path.

use super::*;
use crate::pipeline::optical_flow::reference::{GrooveConstraint, Sweep, horn_schunck};

/// Largest |fast − reference| over u and v (px).
fn max_diff(flow: &FlowField, (u, v): &(Vec<f64>, Vec<f64>)) -> f64 {
    let pairs = flow.u.data.iter().zip(u).chain(flow.v.data.iter().zip(v));
    pairs
        .map(|(&a, &b)| (f64::from(a) - b).abs())
        .fold(0.0, f64::max)
}

/// Fixed sweeps (τ = 0 measures nothing, so the cap is what stops both).
const SWEEPS: u32 = 40;

#[test]
fn plain_horn_schunck_matches_the_reference() {
    let mut worst: f64 = 0.0;
    for (w, h) in [
        (31, 29),
        (40, 64),
        (2, 2),
        (3, 5),
        (17, 9),
        (64, 6),
        (33, 4),
    ] {
        let frames = translating(w, h, 7, 0.4, -0.2, 9);
        let d = middle(&frames, 0.0, &no_prewarp());
        for (solver, omega, sweep) in [
            (Solver::GaussSeidel, 1.0, Sweep::GaussSeidel { omega: 1.0 }),
            (Solver::GaussSeidel, 1.7, Sweep::GaussSeidel { omega: 1.7 }),
            (Solver::Jacobi, 1.0, Sweep::Jacobi),
        ] {
            let p = FlowParams {
                solver,
                sor_omega: omega,
                max_iterations: SWEEPS,
                tolerance_px: 0.0,
                ..params(FlowMethod::HornSchunck)
            };
            let fast = compute_flow(&d, 1e4, None, &p).unwrap();
            let reference = horn_schunck(&d, None, f64::from(p.lambda), sweep, SWEEPS as usize);
            let diff = max_diff(&fast, &reference);
            worst = worst.max(diff);
            // Measured: at most 1.7e-7 px (flows of about 0.4 px).
            assert!(diff < 1e-6, "{w}x{h} {solver:?} ω {omega}: {diff}");
        }
    }
    eprintln!("plain Horn–Schunck, fast − reference: at most {worst:.2e} px");
}

#[test]
fn groove_horn_schunck_matches_the_reference() {
    let (w, h, focal_px) = (37, 230, 100.0);
    let frames = tilted_plane(w, h, 7, 0.6, 1.0, focal_px);
    let walls = WallSideMap {
        width: w,
        height: h,
        sign: (0..w * h).map(|i| [0, 1, -1][(i / w / 40) % 3]).collect(),
    };
    let prewarp = DerivativeParams {
        prewarp: true,
        ..no_prewarp()
    };
    let mut worst: f64 = 0.0;
    // Without and with a base flow B (pre-warped by the land motion), so the k·B terms count.
    for d in [
        middle(&frames, 0.0, &no_prewarp()),
        middle(&frames, -0.6, &prewarp),
    ] {
        for omega in [1.0, 1.7] {
            let p = FlowParams {
                sor_omega: omega,
                max_iterations: SWEEPS,
                tolerance_px: 0.0,
                ..params(FlowMethod::GrooveHornSchunck)
            };
            let fast = compute_flow(&d, focal_px, Some(&walls), &p).unwrap();
            let groove = GrooveConstraint {
                walls: &walls,
                focal_px,
                groove_weight: f64::from(p.groove_weight),
            };
            let reference = horn_schunck(
                &d,
                Some(groove),
                f64::from(p.lambda),
                Sweep::GaussSeidel {
                    omega: f64::from(omega),
                },
                SWEEPS as usize,
            );
            let diff = max_diff(&fast, &reference);
            worst = worst.max(diff);
            // Measured: at most 7.2e-6 px (flows of about 0.6 px; the f32 groove factors
            // round more than the plain ones).
            assert!(diff < 2e-5, "B {} ω {omega}: {diff}", d.base_flow_px);
        }
    }
    eprintln!("groove Horn–Schunck, fast − reference: at most {worst:.2e} px");
}
