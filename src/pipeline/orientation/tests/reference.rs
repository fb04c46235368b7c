//! The fast robust plane fit against the plain reference (`reference.rs`): the same rounds and stops, the planes equal to within the rounding of two ways of solving the same normal equations.

use super::*;
use crate::pipeline::orientation::reference::fit_plane_reference;

/// A plane with noise, a share of gross outliers and an offset far from the origin.
fn points(outlier_share: f64, seed: u64) -> Vec<[f64; 3]> {
    let mut rng = Rng::new(seed);
    let (a, b, c) = (0.03, 0.9, 4040.0);
    let mut pts = Vec::new();
    for i in 0..70 {
        for j in 0..50 {
            let (x, y) = (f64::from(i) * 0.5 + 310.0, f64::from(j) * 0.5 - 15.0);
            let z = if rng.uniform() < outlier_share {
                c + 100.0 * (rng.uniform() - 0.5)
            } else {
                a * x + b * y + c + 0.01 * rng.gauss()
            };
            pts.push([x, y, z]);
        }
    }
    pts
}

#[test]
fn robust_fit_matches_the_reference() {
    let base = OrientationParams::default();
    let cases = [
        (
            "least squares",
            0.3,
            OrientationParams {
                robust: false,
                ..base.clone()
            },
        ),
        ("robust, 30 % outliers", 0.3, base.clone()),
        ("robust, clean", 0.0, base.clone()),
        (
            "robust, 3 rounds",
            0.3,
            OrientationParams {
                max_iterations: 3,
                ..base.clone()
            },
        ),
        (
            "robust, converged early",
            0.1,
            OrientationParams {
                residual_tolerance_um: 0.05,
                ..base.clone()
            },
        ),
    ];
    let (mut worst_slope, mut worst_rel) = (0.0_f64, 0.0_f64);
    for (seed, (name, share, params)) in cases.into_iter().enumerate() {
        let pts = points(share, seed as u64 + 1);
        let fast = fit_plane(&pts, &params).unwrap();
        let reference = fit_plane_reference(&pts, &params).unwrap();
        assert_eq!(
            (fast.iterations, fast.stop, fast.outlier_fraction),
            (
                reference.iterations,
                reference.stop,
                reference.outlier_fraction
            ),
            "{name}"
        );
        let slope = (fast.a - reference.a)
            .abs()
            .max((fast.b - reference.b).abs());
        let rel = ((fast.c - reference.c) / reference.c)
            .abs()
            .max(((fast.residual_um - reference.residual_um) / reference.residual_um).abs());
        (worst_slope, worst_rel) = (worst_slope.max(slope), worst_rel.max(rel));
        // Measured: slopes within 3.1e-15, offset and residual within 2.2e-14 relative.
        assert!(
            slope < 1e-12 && rel < 1e-12,
            "{name}: {slope:.1e} {rel:.1e}"
        );
    }
    eprintln!(
        "IRLS fit, fast − reference: slopes {worst_slope:.1e}, offset and residual {worst_rel:.1e} relative"
    );
}
