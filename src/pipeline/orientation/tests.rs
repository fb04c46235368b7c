//! Tests of the orientation stage: exact and noisy planes, outliers, the AVX2 pass, both paths, and flow → depth → walls → tan θ end to end.

use super::*;

mod reference;

#[test]
fn fits_with_a_wall_slope_far_from_the_median_become_gaps() {
    let sample = |x: f32, a: f64, b: f64| OrientationSample {
        x_px: x,
        tan_theta: tan_theta(&test_fit(a, b)),
        fit: Some(test_fit(a, b)),
    };
    // Modulation moves b by a few per cent; a fit locked onto damage turns the wall steep.
    let mut s = vec![
        sample(0.0, 0.01, -0.38),
        sample(3.0, 0.05, -0.39),
        sample(6.0, 0.8, -1.2),
        sample(9.0, -0.04, -0.37),
        sample(12.0, 0.0, -0.38),
        gap(15.0),
    ];
    assert_eq!(reject_implausible_slopes(&mut s, 0.25), 1);
    assert!(s[2].fit.is_none() && s[2].tan_theta.is_nan());
    assert_eq!(s[2].x_px, 6.0);
    assert!(s.iter().filter(|x| x.fit.is_some()).count() == 4);
    // 0 turns the check off.
    let mut t = vec![
        sample(0.0, 0.0, -0.38),
        sample(1.0, 0.0, -0.38),
        sample(2.0, 0.8, -1.2),
    ];
    assert_eq!(reject_implausible_slopes(&mut t, 0.0), 0);
    assert!(t[2].fit.is_some());
}
use crate::pipeline::walls::test_support::{Groove, Rng, paper_geometry};

fn params() -> OrientationParams {
    OrientationParams::default()
}

#[test]
fn irls_pass_gives_the_same_bits_on_avx2() {
    let mut set = PointSet::default();
    let mut seed = 7_u64;
    let mut next = || {
        seed = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
        (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    // 4·m + 3 points, so the tail after the whole chunks is used too.
    for _ in 0..103 {
        let (x, y) = (next() * 40.0, next() * 40.0);
        set.x.push(x);
        set.y.push(y);
        set.z
            .push(0.3 * x - 0.2 * y + next() * if next() > 0.3 { 5.0 } else { 0.1 });
    }
    let w_old: Vec<f64> = (0..103).map(|_| next() + 0.5).collect();
    let (mut a, mut b) = (vec![0.0; 103], vec![0.0; 103]);
    let plane = [0.25, -0.15, 0.05];
    let sa = irls_pass(&set, plane, 0.7, &w_old, &mut a, Isa::Portable);
    let sb = irls_pass(&set, plane, 0.7, &w_old, &mut b, Isa::detect());
    assert_eq!(sa.map(f64::to_bits), sb.map(f64::to_bits));
    assert_eq!(
        a.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        b.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
    );
    assert!(sa[0] > 0.0 && sa[0] < 103.0);
}

#[test]
fn exact_plane_is_recovered_by_both_modes() {
    let mut pts = Vec::new();
    for i in 0..20 {
        for j in 0..15 {
            let (x, y) = (f64::from(i) * 1.3 - 7.0, f64::from(j) * 0.9 + 100.0);
            pts.push([x, y, 4000.0 + 0.02 * x - 0.7 * y]);
        }
    }
    for robust in [false, true] {
        let fit = fit_plane(&pts, &OrientationParams { robust, ..params() }).unwrap();
        assert!((fit.a - 0.02).abs() < 1e-9, "{fit:?}");
        assert!((fit.b + 0.7).abs() < 1e-9, "{fit:?}");
        assert!((fit.c - 4000.0).abs() < 1e-6, "{fit:?}");
        assert_eq!(fit.outlier_fraction, 0.0);
        let want = if robust {
            StopReason::Converged
        } else {
            StopReason::LeastSquares
        };
        assert_eq!(fit.stop, want);
    }
}

#[test]
fn robust_fit_rejects_thirty_percent_gross_outliers() {
    let mut rng = Rng::new(7);
    let (a, b, c) = (0.03, 0.9, 4040.0);
    let mut pts = Vec::new();
    let mut outliers = 0;
    for i in 0..80 {
        for j in 0..60 {
            let (x, y) = (f64::from(i) * 0.5 - 20.0, f64::from(j) * 0.5 - 15.0);
            let z = if rng.uniform() < 0.3 {
                outliers += 1;
                c + 100.0 * (rng.uniform() - 0.5)
            } else {
                a * x + b * y + c + 0.01 * rng.gauss()
            };
            pts.push([x, y, z]);
        }
    }
    let robust = fit_plane(&pts, &params()).unwrap();
    let plain = fit_plane(
        &pts,
        &OrientationParams {
            robust: false,
            ..params()
        },
    )
    .unwrap();
    let err_r = (robust.a - a).abs().max((robust.b - b).abs());
    let err_p = (plain.a - a).abs().max((plain.b - b).abs());
    assert!(err_r < 1e-3, "robust {robust:?}");
    assert!(
        err_p > 10.0 * 1e-3 && err_p > 10.0 * err_r,
        "plain {plain:?}"
    );
    let share = f64::from(outliers) / pts.len() as f64;
    assert!(
        (robust.outlier_fraction - share).abs() < 0.03,
        "{robust:?} vs {share}"
    );
    assert!(robust.iterations > 1);
}

#[test]
fn fit_plane_rejects_bad_input() {
    let p = params();
    assert!(fit_plane(&[[0.0, 0.0, 1.0], [1.0, 0.0, 1.0]], &p).is_err());
    let line: Vec<[f64; 3]> = (0..10)
        .map(|i| [f64::from(i), 2.0 * f64::from(i), 1.0])
        .collect();
    assert!(fit_plane(&line, &p).is_err());
    let ok = [[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]];
    assert!(fit_plane(&ok, &p).is_ok());
    assert!(
        fit_plane(
            &[[f64::NAN, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]],
            &p
        )
        .is_err()
    );
    let bad = OrientationParams {
        sigma_decay: f64::NAN,
        ..params()
    };
    assert!(matches!(
        fit_plane(&ok, &bad),
        Err(StageError::InvalidParam { .. })
    ));
    let bad = OrientationParams {
        max_iterations: 0,
        ..params()
    };
    assert!(matches!(
        fit_plane(&ok, &bad),
        Err(StageError::InvalidParam { .. })
    ));
}

/// Lateral displacement d(X) = s·X of the whole groove: the left wall is
/// Z = K + (Y − d(X)) (a = −s, b = +1), the right wall Z = K′ − (Y − d(X)) (a = +s, b = −1),
/// so tan θ = −a·sign(b)/√(1 + b²) = s/√2 on both walls.
#[test]
fn tan_theta_sign_of_a_lateral_displacement() {
    let s = 0.05;
    let want = s / 2f64.sqrt();
    let mut left = Vec::new();
    let mut right = Vec::new();
    for i in 0..30 {
        for j in 0..30 {
            let (x, y) = (f64::from(i) - 15.0, f64::from(j) - 15.0);
            left.push([x, y, 4040.0 + (y - s * x)]);
            right.push([x, y, 4040.0 - (y - s * x)]);
        }
    }
    let fl = fit_plane(&left, &params()).unwrap();
    let fr = fit_plane(&right, &params()).unwrap();
    assert!(fl.b > 0.0 && fr.b < 0.0);
    assert!((tan_theta(&fl) - want).abs() < 1e-9, "{}", tan_theta(&fl));
    assert!((tan_theta(&fr) - want).abs() < 1e-9, "{}", tan_theta(&fr));
    // A displacement the other way flips the sign.
    let neg: Vec<[f64; 3]> = left
        .iter()
        .map(|p| [p[0], p[1], 4040.0 + (p[1] + s * p[0])])
        .collect();
    assert!((tan_theta(&fit_plane(&neg, &params()).unwrap()) + want).abs() < 1e-9);
}

fn hand_lines(g: &Groove, width: usize, height: usize, margin_px: f32) -> Vec<WallLine> {
    [WallSide::Left, WallSide::Right]
        .into_iter()
        .map(|side| {
            let (rows, hws): (Vec<f32>, Vec<f32>) = (0..width)
                .map(|x| {
                    let (row, hw) = g.wall_band_px(side, x, width, height);
                    (row as f32, hw as f32 - margin_px)
                })
                .unzip();
            WallLine {
                side,
                rows,
                half_width_px: hws,
                depth_um: None,
                projection_depth_um: None,
                filled: vec![false; width],
            }
        })
        .collect()
}

/// The depth map of a `w` × `h` px view of a groove displaced by `s`·X under the paper's
/// optics (walls of tan θ = ±s/√2), and its true wall lines 4 px inside their bands.
fn sliding_groove(s: f64, w: usize, h: usize) -> (DepthMap, Vec<WallLine>) {
    let g = Groove::new(paper_geometry(), move |x_um| s * x_um);
    (g.depth_map(w, h), hand_lines(&g, w, h, 4.0))
}

#[test]
fn depth_path_recovers_a_constant_wall_slope_on_both_walls() {
    let geom = paper_geometry();
    let s = 0.05;
    let (w, h) = (360, 640);
    let (depth, walls) = sliding_groove(s, w, h);
    let columns = [60.0_f32, 180.0, 300.0];
    let out = orient_from_depth(&depth, &walls, &columns, &geom, &params()).unwrap();
    assert_eq!(out.walls.len(), 2);
    let want = s / 2f64.sqrt();
    for wall in &out.walls {
        assert_eq!(wall.samples.len(), 3);
        for smp in &wall.samples {
            let fit = smp.fit.unwrap();
            assert!(
                (smp.tan_theta - want).abs() < 2e-4,
                "{:?} {smp:?}",
                wall.side
            );
            assert_eq!(fit.b > 0.0, wall.side == WallSide::Left);
        }
    }
    let used = out.weight_map.data.iter().filter(|v| v.is_finite()).count();
    assert!(used > 3 * 2 * 100 * 50, "{used}");
    assert!(out.outlier_fraction < 0.01);
    // Opposite displacement, opposite sign.
    let (depth2, walls2) = sliding_groove(-s, w, h);
    let out2 = orient_from_depth(&depth2, &walls2, &columns, &geom, &params()).unwrap();
    for wall in &out2.walls {
        for smp in &wall.samples {
            assert!((smp.tan_theta + want).abs() < 2e-4, "{smp:?}");
        }
    }
}

#[test]
fn depth_path_leaves_gaps_and_checks_sizes() {
    let geom = paper_geometry();
    let (depth, mut walls) = sliding_groove(0.0, 200, 640);
    for r in &mut walls[0].rows[..120] {
        *r = f32::NAN;
    }
    let out =
        orient_from_depth(&depth, &walls, &[40.0, 150.0, f32::NAN], &geom, &params()).unwrap();
    let left = &out.walls[0].samples;
    assert!(left[0].fit.is_none() && left[0].tan_theta.is_nan());
    assert!(left[1].fit.is_some() && left[1].tan_theta.abs() < 1e-4);
    assert!(left[2].fit.is_none());
    walls[1].rows.pop();
    assert!(matches!(
        orient_from_depth(&depth, &walls, &[40.0], &geom, &params()),
        Err(StageError::BadInput { .. })
    ));
}

/// An iso-depth line at depth z on a wall Z = K ± (Y − s·X): Y = ±(z − K) + s·X, so
/// row(x) = cy + f·Y/z with X = (x − cx)·z/f.
fn iso_line(
    side: WallSide,
    z: f64,
    k: f64,
    s: f64,
    width: usize,
    height: usize,
    f: f64,
) -> WallLine {
    let (cx, cy) = ((width as f64 - 1.0) / 2.0, (height as f64 - 1.0) / 2.0);
    let sign = if side == WallSide::Left { 1.0 } else { -1.0 };
    let rows = (0..width)
        .map(|x| {
            let big_x = (x as f64 - cx) * z / f;
            let big_y = sign * (z - k) + s * big_x;
            (cy + f * big_y / z) as f32
        })
        .collect();
    WallLine {
        side,
        rows,
        half_width_px: vec![0.0; width],
        depth_um: Some(z),
        projection_depth_um: Some(z),
        filled: vec![false; width],
    }
}

#[test]
fn line_path_recovers_the_slope_from_two_iso_depth_lines() {
    let geom = paper_geometry();
    let f = geom.focal_px;
    let (w, h) = (400, 600);
    let s = 0.04;
    let want = s / 2f64.sqrt();
    let lines = vec![
        iso_line(WallSide::Left, 4030.0, 4050.0, s, w, h, f),
        iso_line(WallSide::Left, 4060.0, 4050.0, s, w, h, f),
        iso_line(WallSide::Right, 4030.0, 4050.0, s, w, h, f),
        iso_line(WallSide::Right, 4060.0, 4050.0, s, w, h, f),
    ];
    let out = orient_from_lines(&lines, w, h, &[100.0, 250.0], &geom, &params()).unwrap();
    assert_eq!(out.walls.len(), 2);
    for wall in &out.walls {
        for smp in &wall.samples {
            // Rows are stored as f32 (≈ 3e-5 px), a tiny error on a 30 µm lever.
            assert!(
                (smp.tan_theta - want).abs() < 1e-4,
                "{:?} {smp:?}",
                wall.side
            );
        }
    }
    assert!(out.weight_map.data.iter().any(|v| v.is_finite()));
    // One line on the right: that wall is a gap, the left still works.
    let partial = vec![lines[0].clone(), lines[1].clone(), lines[2].clone()];
    let out = orient_from_lines(&partial, w, h, &[100.0], &geom, &params()).unwrap();
    assert!(out.walls[1].samples[0].fit.is_none());
    assert!(out.walls[0].samples[0].fit.is_some());
    // Two lines at the same depth on each wall: no wall is usable.
    let same = vec![lines[0].clone(), lines[0].clone(), lines[2].clone()];
    assert!(matches!(
        orient_from_lines(&same, w, h, &[100.0], &geom, &params()),
        Err(StageError::NotFound { .. })
    ));
}

#[allow(clippy::unwrap_used)] // Tests fail loudly on purpose.
mod end_to_end {
    use super::*;
    use crate::pipeline::depth::{DepthParams, estimate_depth};
    use crate::pipeline::optical_flow::FlowField;
    use crate::pipeline::walls::test_support::{Groove, Rng, paper_geometry};
    use crate::pipeline::walls::{WallParams, find_walls};

    /// Flows of a laterally sliding groove (with flow noise) → Kalman depth → walls → fits.
    fn run(noise_px: f64, seed: u64) -> Vec<(WallSide, f64)> {
        let geom = paper_geometry();
        let s = 0.05;
        let g = Groove::new(geom, move |x_um| s * x_um);
        let (w, h) = (300, 560);
        let mut rng = Rng::new(seed);
        let fu = geom.focal_px * geom.frame_step_um;
        let flows: Vec<FlowField> = (0..6)
            .map(|k| {
                let cam = f64::from(k) * geom.frame_step_um;
                let u = Image::from_fn(w, h, |x, y| {
                    let z = g.z_px_from(x as f64, y as f64, w, h, cam);
                    (-fu / z + noise_px * rng.gauss()) as f32
                });
                FlowField::exact(u, k as usize)
            })
            .collect();
        let depth = estimate_depth(&flows, &geom, &DepthParams::default()).unwrap();
        let walls = find_walls(&depth, &geom, &WallParams::default()).unwrap();
        let out = orient_from_depth(
            &depth,
            &walls,
            &[75.0, 150.0, 225.0],
            &geom,
            &OrientationParams::default(),
        )
        .unwrap();
        out.walls
            .iter()
            .flat_map(|wo| wo.samples.iter().map(move |smp| (wo.side, smp.tan_theta)))
            .collect()
    }

    #[test]
    fn sliding_groove_gives_its_slope_from_flow_to_tan_theta() {
        let want = 0.05 / 2f64.sqrt();
        for (noise, tol) in [(0.0, 1e-5), (0.002, 5e-3)] {
            let got = run(noise, 5);
            eprintln!("noise {noise}: {got:?} want {want}");
            assert_eq!(got.len(), 6);
            for (side, t) in got {
                assert!(
                    (t - want).abs() < tol,
                    "noise {noise} {side:?}: {t} vs {want}"
                );
            }
        }
    }
}
