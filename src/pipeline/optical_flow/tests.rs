//! Unit tests of the flow stage: known shifts, tilted planes, the groove constraint's Euler–Lagrange equations; the fast solver against the reference and its blocking in the sub-modules.

use super::*;
use crate::pipeline::derivatives::{DerivativeMode, DerivativeParams, compute_derivatives};
use crate::pipeline::test_support::assert_each_edit_is_refused;
use proptest::prelude::*;

mod reference;
mod solver;

/// splitmix64, for reproducible textures.
struct Rng(u64);

impl Rng {
    fn next_f64(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1_u64 << 53) as f64
    }
}

/// A smooth random texture: a sum of plane waves with wavelengths in [8, 32] px.
struct Texture(Vec<[f64; 4]>);

impl Texture {
    fn new(seed: u64) -> Self {
        let mut rng = Rng(seed);
        let n = 48;
        let waves = (0..n)
            .map(|_| {
                let wavelength = 8.0 + 24.0 * rng.next_f64();
                let dir = std::f64::consts::TAU * rng.next_f64();
                let k = std::f64::consts::TAU / wavelength;
                let phase = std::f64::consts::TAU * rng.next_f64();
                [k * dir.cos(), k * dir.sin(), phase, 0.5 / (n as f64).sqrt()]
            })
            .collect();
        Self(waves)
    }

    fn at(&self, x: f64, y: f64) -> f32 {
        let s: f64 = self
            .0
            .iter()
            .map(|[kx, ky, ph, a]| a * (kx * x + ky * y + ph).sin())
            .sum();
        (0.5 + s) as f32
    }
}

/// Frames of the texture translating by (sx, sy) px per frame.
fn translating(w: usize, h: usize, frames: usize, sx: f64, sy: f64, seed: u64) -> Vec<Image> {
    let tex = Texture::new(seed);
    (0..frames)
        .map(|k| {
            let t = k as f64;
            Image::from_fn(w, h, |x, y| tex.at(x as f64 - sx * t, y as f64 - sy * t))
        })
        .collect()
}

/// Frames of a plane tilted across y (∂Z/∂Y = `slope`) under a camera moving along x by
/// `step` px per frame at the depth of the centre row: u(y) = −step·(1 − slope·yc/f).
fn tilted_plane(w: usize, h: usize, frames: usize, step: f64, slope: f64, f: f64) -> Vec<Image> {
    let tex = Texture::new(7);
    let (xc0, yc0) = ((w as f64 - 1.0) * 0.5, (h as f64 - 1.0) * 0.5);
    (0..frames)
        .map(|k| {
            Image::from_fn(w, h, |x, y| {
                let (xc, yc) = (x as f64 - xc0, y as f64 - yc0);
                let z = f / (1.0 - slope * yc / f);
                let (wx, wy) = (xc * z / f, yc * z / f);
                tex.at(wx + step * k as f64, wy)
            })
        })
        .collect()
}

fn true_u_tilted(y: usize, h: usize, step: f64, slope: f64, f: f64) -> f64 {
    let yc = y as f64 - (h as f64 - 1.0) * 0.5;
    -step * (1.0 - slope * yc / f)
}

/// Mean |u − eu(x, y)| and |v − ev| over the interior (margin px from each border).
fn mean_abs_err(
    flow: &FlowField,
    margin: usize,
    eu: impl Fn(usize, usize) -> f64,
    ev: f64,
) -> (f64, f64) {
    let (w, h) = (flow.u.width, flow.u.height);
    let (mut su, mut sv, mut n) = (0.0, 0.0, 0.0);
    for y in margin..h - margin {
        for x in margin..w - margin {
            su += (f64::from(flow.u.data[y * w + x]) - eu(x, y)).abs();
            sv += (f64::from(flow.v.data[y * w + x]) - ev).abs();
            n += 1.0;
        }
    }
    (su / n, sv / n)
}

fn params(method: FlowMethod) -> FlowParams {
    FlowParams {
        method,
        ..FlowParams::default()
    }
}

fn no_prewarp() -> DerivativeParams {
    DerivativeParams {
        mode: DerivativeMode::Simoncelli,
        prewarp: false,
        ..DerivativeParams::default()
    }
}

/// Middle derivative set of a 12-frame group.
fn middle(frames: &[Image], land: f64, dp: &DerivativeParams) -> Derivatives {
    let mut sets = compute_derivatives(frames, land, dp).unwrap();
    let k = sets.len() / 2;
    sets.swap_remove(k)
}

const MARGIN_PX: usize = 8;

#[test]
fn translation_recovered_by_every_method() {
    let (w, h) = (96, 80);
    for &(sx, sy) in &[
        (0.3, 0.0),
        (0.7, 0.0),
        (1.0, 0.0),
        (0.0, 0.3),
        (0.0, 0.7),
        (0.0, 1.0),
        (0.5, -0.5),
    ] {
        let frames = translating(w, h, 12, sx, sy, 1);
        let d = middle(&frames, 0.0, &no_prewarp());
        // Jacobi converges about half as fast as Gauss–Seidel: give it more sweeps.
        for (method, solver, iterations) in [
            (FlowMethod::HornSchunck, Solver::GaussSeidel, 100),
            (FlowMethod::HornSchunck, Solver::Jacobi, 300),
            (FlowMethod::LucasKanade, Solver::GaussSeidel, 1),
        ] {
            let p = FlowParams {
                solver,
                max_iterations: iterations,
                ..params(method)
            };
            let flow = compute_flow(&d, 1e4, None, &p).unwrap();
            let (eu, ev) = mean_abs_err(&flow, MARGIN_PX, |_, _| sx, sy);
            eprintln!(
                "shift ({sx}, {sy}) {method:?} {solver:?}: mean |du| {eu:.5} |dv| {ev:.5} in {} iterations",
                flow.iterations
            );
            assert!(
                eu <= 0.01 && ev <= 0.01,
                "{method:?} {solver:?} ({sx},{sy}): {eu} {ev}"
            );
        }
    }
}

#[test]
fn prewarp_recovers_large_land_flow() {
    let (w, h) = (96, 80);
    for land in [-2.0, -2.3, -2.5, -3.0] {
        let frames = translating(w, h, 12, land, 0.0, 3);
        let d = middle(&frames, land, &DerivativeParams::default());
        assert!((f64::from(d.base_flow_px) - land).abs() < 1e-6);
        for method in [FlowMethod::HornSchunck, FlowMethod::LucasKanade] {
            let flow = compute_flow(&d, 1e4, None, &params(method)).unwrap();
            let (eu, ev) = mean_abs_err(&flow, MARGIN_PX, |_, _| land, 0.0);
            eprintln!("prewarp land {land} {method:?}: mean |du| {eu:.5} |dv| {ev:.5}");
            assert!(eu <= 0.01 && ev <= 0.01, "{land} {method:?}: {eu} {ev}");
        }
    }
}

/// Least-squares line through the interior row means of u: (value at the centre row, slope).
fn row_profile(flow: &FlowField, margin: usize) -> (f64, f64) {
    let (w, h) = (flow.u.width, flow.u.height);
    let yc = (h as f64 - 1.0) * 0.5;
    let (mut sy, mut syy, mut su, mut syu, mut n) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for y in margin..h - margin {
        let mean: f64 = flow.u.row(y)[margin..w - margin]
            .iter()
            .map(|&v| f64::from(v))
            .sum::<f64>()
            / (w - 2 * margin) as f64;
        let t = y as f64 - yc;
        sy += t;
        syy += t * t;
        su += mean;
        syu += t * mean;
        n += 1.0;
    }
    let slope = (n * syu - sy * su) / (n * syy - sy * sy);
    ((su - slope * sy) / n, slope)
}

const TILT_FOCAL_PX: f64 = 400.0;

#[test]
fn tilted_plane_gives_linear_u_profile() {
    let (w, h) = (96, 96);
    for (slope, prewarp) in [(1.0, false), (-1.0, false), (1.0, true)] {
        let frames = tilted_plane(w, h, 12, 1.0, slope, TILT_FOCAL_PX);
        let dp = DerivativeParams {
            prewarp,
            ..DerivativeParams::default()
        };
        let d = middle(&frames, -1.0, &dp);
        let flow = compute_flow(&d, TILT_FOCAL_PX, None, &params(FlowMethod::HornSchunck)).unwrap();
        let (centre, fitted) = row_profile(&flow, MARGIN_PX);
        let expected = slope / TILT_FOCAL_PX;
        let (eu, ev) = mean_abs_err(
            &flow,
            MARGIN_PX,
            |_, y| true_u_tilted(y, h, 1.0, slope, TILT_FOCAL_PX),
            0.0,
        );
        eprintln!(
            "tilt {slope} prewarp {prewarp}: u(centre) {centre:.5} slope {fitted:.6} (true {expected:.6}) mean |du| {eu:.5} |dv| {ev:.5}"
        );
        assert!((centre + 1.0).abs() < 0.005, "{centre}");
        assert!(
            (fitted - expected).abs() < 0.05 * expected.abs(),
            "{fitted} vs {expected}"
        );
        assert!(eu < 0.01 && ev < 0.01, "{eu} {ev}");
    }
}

#[test]
fn groove_constraint_is_not_worse_on_a_wall() {
    let (w, h) = (96, 96);
    for slope in [1.0, -1.0] {
        let frames = tilted_plane(w, h, 12, 1.0, slope, TILT_FOCAL_PX);
        let d = middle(&frames, -1.0, &DerivativeParams::default());
        let truth = |_: usize, y: usize| true_u_tilted(y, h, 1.0, slope, TILT_FOCAL_PX);
        let plain =
            compute_flow(&d, TILT_FOCAL_PX, None, &params(FlowMethod::HornSchunck)).unwrap();
        let walls = WallSideMap {
            width: w,
            height: h,
            sign: vec![slope as i8; w * h],
        };
        let mut errs = vec![mean_abs_err(&plain, MARGIN_PX, truth, 0.0).0];
        // A stiff constraint (γ = 10λ) couples rows strongly and needs more sweeps.
        for (weight, iterations, tolerance_px) in [(1.0, 100, 1e-5), (10.0, 1000, 0.0)] {
            let p = FlowParams {
                groove_weight: weight,
                max_iterations: iterations,
                tolerance_px,
                ..params(FlowMethod::GrooveHornSchunck)
            };
            let given = compute_flow(&d, TILT_FOCAL_PX, Some(&walls), &p).unwrap();
            let estimated = compute_flow(&d, TILT_FOCAL_PX, None, &p).unwrap();
            errs.push(mean_abs_err(&given, MARGIN_PX, truth, 0.0).0);
            errs.push(mean_abs_err(&estimated, MARGIN_PX, truth, 0.0).0);
        }
        eprintln!(
            "tilt {slope}: |du| plain, groove(γ=λ, given/estimated walls), groove(γ=10λ, ...): {errs:?}"
        );
        for &e in &errs[1..] {
            assert!(e <= errs[0] * 1.02 + 1e-5, "{errs:?}");
        }
    }
}

#[test]
fn box_mean_matches_the_in_image_window_mean() {
    for (w, h) in [(1, 1), (3, 2), (9, 5), (40, 11)] {
        let im = Image::from_fn(w, h, |x, y| ((x * 7 + y * 13) % 11) as f32 - 4.0);
        let (rx, ry) = (4, 2);
        let got = box_mean(&im, rx, ry);
        for y in 0..h {
            for x in 0..w {
                let (x0, x1) = (x.saturating_sub(rx), (x + rx).min(w - 1));
                let (y0, y1) = (y.saturating_sub(ry), (y + ry).min(h - 1));
                let vals: Vec<f64> = (y0..=y1)
                    .flat_map(|yy| (x0..=x1).map(move |xx| (xx, yy)))
                    .map(|(xx, yy)| f64::from(im.data[yy * w + xx]))
                    .collect();
                let want = vals.iter().sum::<f64>() / vals.len() as f64;
                assert!(
                    (got[y * w + x] - want).abs() < 1e-9,
                    "{w}x{h} at ({x}, {y})"
                );
            }
        }
    }
}

#[test]
fn wall_sides_estimated_from_parallax() {
    let (w, h) = (96, 96);
    for (slope, want) in [(1.0, 1_i8), (-1.0, -1), (0.0, 0)] {
        let frames = tilted_plane(w, h, 12, 1.0, slope, TILT_FOCAL_PX);
        let d = middle(&frames, -1.0, &DerivativeParams::default());
        let flow = compute_flow(&d, TILT_FOCAL_PX, None, &params(FlowMethod::HornSchunck)).unwrap();
        let map = estimate_wall_sides(&flow, TILT_FOCAL_PX).unwrap();
        assert_eq!((map.width, map.height, map.sign.len()), (w, h, w * h));
        let m = 2 * MARGIN_PX;
        let (mut hits, mut n) = (0, 0);
        for y in m..h - m {
            for x in m..w - m {
                hits += usize::from(map.sign[y * w + x] == want);
                n += 1;
            }
        }
        let frac = hits as f64 / n as f64;
        eprintln!("tilt {slope}: {frac:.3} of interior pixels got c = {want}");
        assert!(frac > 0.9, "{frac}");
    }
    assert!(estimate_wall_sides(&compute_flow_dummy(), f64::NAN).is_err());
}

#[test]
fn wall_presolve_converges_whatever_the_groove_tolerance_and_cap() {
    // A loose τ or a low cap must not cut short the plain pass the wall sides are
    // estimated from: the groove flow still starts from a plain pass run to the wall
    // tolerance.
    let (w, h) = (96, 96);
    let frames = tilted_plane(w, h, 12, 1.0, 1.0, TILT_FOCAL_PX);
    let d = middle(&frames, -1.0, &DerivativeParams::default());
    let plain = compute_flow(
        &d,
        TILT_FOCAL_PX,
        None,
        &FlowParams {
            tolerance_px: WALL_PRESOLVE_TOLERANCE_PX,
            ..params(FlowMethod::HornSchunck)
        },
    )
    .unwrap();
    assert!(
        plain.iterations > 2 * MAX_BLOCK_ITERATIONS as u32,
        "{}",
        plain.iterations
    );
    assert!(
        plain.iterations < WALL_PRESOLVE_MAX_ITERATIONS,
        "{}",
        plain.iterations
    );
    for (tolerance_px, max_iterations) in [(1e-3, 100), (1e-5, 20)] {
        let p = FlowParams {
            tolerance_px,
            max_iterations,
            ..params(FlowMethod::GrooveHornSchunck)
        };
        let groove = compute_flow(&d, TILT_FOCAL_PX, None, &p).unwrap();
        eprintln!(
            "plain pass {} iterations; groove at τ = {tolerance_px}, cap {max_iterations}: {} in all",
            plain.iterations, groove.iterations
        );
        assert!(
            groove.iterations > plain.iterations,
            "{}",
            groove.iterations
        );
    }
}

fn compute_flow_dummy() -> FlowField {
    FlowField {
        u: Image::zeros(4, 4),
        v: Image::zeros(4, 4),
        confidence: Image::zeros(4, 4),
        iterations: 0,
        converged: false,
        frame_index: 0,
    }
}

/// The groove energy of the module docs, evaluated directly (f64).
#[allow(clippy::too_many_arguments)]
fn energy(
    d: &Derivatives,
    sign: &[i8],
    u: &[f64],
    v: &[f64],
    lambda: f64,
    gamma: f64,
    f: f64,
) -> f64 {
    let (w, h) = (d.ix.width, d.ix.height);
    let b = f64::from(d.base_flow_px);
    let mut e = 0.0;
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let r = f64::from(d.ix.data[i]) * u[i]
                + f64::from(d.iy.data[i]) * v[i]
                + f64::from(d.it.data[i]);
            e += r * r;
            if x + 1 < w {
                e += 0.25 * lambda * ((u[i + 1] - u[i]).powi(2) + (v[i + 1] - v[i]).powi(2));
            }
            if y + 1 < h {
                let j = i + w;
                e += 0.25 * lambda * (v[j] - v[i]).powi(2);
                if sign[i] != 0 && sign[i] == sign[j] {
                    let c = f64::from(sign[i]);
                    let ym = y as f64 + 0.5 - (h as f64 - 1.0) * 0.5;
                    let k = c / (f - c * ym);
                    let re = u[j] - u[i] + k * (0.5 * (u[i] + u[j]) + b);
                    e += (0.25 * lambda + gamma) * re * re;
                } else {
                    e += 0.25 * lambda * (u[j] - u[i]).powi(2);
                }
            }
        }
    }
    e
}

#[test]
fn groove_solution_satisfies_euler_lagrange() {
    let (w, h) = (14, 12);
    let frames = tilted_plane(w, h, 7, 1.0, 1.0, 40.0);
    let d = middle(&frames, -1.0, &DerivativeParams::default());
    // Stripes of wall sides, including land (0) rows and a side change.
    let sign: Vec<i8> = (0..w * h)
        .map(|i| match i / w {
            0..=2 => 0,
            3..=6 => 1,
            7 => 0,
            _ => -1,
        })
        .collect();
    let walls = WallSideMap {
        width: w,
        height: h,
        sign: sign.clone(),
    };
    let (focal, lambda, weight) = (20.0, 0.05, 3.0);
    for solver in [Solver::GaussSeidel, Solver::Jacobi] {
        let p = FlowParams {
            solver,
            lambda,
            groove_weight: weight,
            max_iterations: MAX_FLOW_ITERATIONS,
            tolerance_px: 0.0,
            ..params(FlowMethod::GrooveHornSchunck)
        };
        let flow = compute_flow(&d, focal, Some(&walls), &p).unwrap();
        let base = f64::from(d.base_flow_px);
        let mut u: Vec<f64> = flow.u.data.iter().map(|&x| f64::from(x) - base).collect();
        let mut v: Vec<f64> = flow.v.data.iter().map(|&x| f64::from(x)).collect();
        let gamma = f64::from(weight) * f64::from(lambda);
        let en = |u: &[f64], v: &[f64]| energy(&d, &sign, u, v, f64::from(lambda), gamma, focal);
        let step = 1e-4;
        let mut worst: f64 = 0.0;
        let mut scale: f64 = 0.0;
        // All rows (top and bottom are free boundaries); the mirrored outer columns
        // minimise the energy with half weights there, so they are left out.
        for y in 0..h {
            for x in 1..w - 1 {
                let i = y * w + x;
                for comp in 0..2 {
                    let field = if comp == 0 { &mut u } else { &mut v };
                    let keep = field[i];
                    field[i] = keep + step;
                    let ep = en(&u, &v);
                    let field = if comp == 0 { &mut u } else { &mut v };
                    field[i] = keep - step;
                    let em = en(&u, &v);
                    let field = if comp == 0 { &mut u } else { &mut v };
                    field[i] = keep;
                    worst = worst.max(((ep - em) / (2.0 * step)).abs());
                    // Gradient size at the zero flow, for scale.
                    let i_t = f64::from(d.it.data[i]);
                    let g = if comp == 0 {
                        d.ix.data[i]
                    } else {
                        d.iy.data[i]
                    };
                    scale = scale.max((2.0 * f64::from(g) * i_t).abs());
                }
            }
        }
        eprintln!("{solver:?}: worst interior |∂E/∂(u,v)| {worst:.3e} vs {scale:.3e} at zero flow");
        assert!(worst < 1e-4 * scale, "{worst} vs {scale}");
    }
}

#[test]
fn invalid_params_are_rejected() {
    let frames = translating(16, 16, 7, 0.3, 0.0, 1);
    let d = middle(&frames, 0.0, &no_prewarp());
    // Each edit makes the defaults invalid.
    let edits: [fn(&mut FlowParams); 10] = [
        |p| p.lambda = f32::NAN,
        |p| p.lambda = 0.0,
        |p| p.lambda = -1.0,
        |p| p.max_iterations = 0,
        |p| p.tolerance_px = f32::NAN,
        |p| p.gradient_threshold = -1.0,
        |p| p.lk_window_px = 8,
        |p| p.lk_window_px = 1,
        |p| p.groove_weight = f32::INFINITY,
        |p| p.sor_omega = 2.0,
    ];
    assert_each_edit_is_refused(&edits, |p| compute_flow(&d, 1e4, None, p));
    assert!(matches!(
        compute_flow(&d, f64::NAN, None, &FlowParams::default()),
        Err(StageError::InvalidParam { .. })
    ));
    let walls = WallSideMap {
        width: 3,
        height: 3,
        sign: vec![0; 9],
    };
    assert!(matches!(
        compute_flow(&d, 1e4, Some(&walls), &FlowParams::default()),
        Err(StageError::BadInput { .. })
    ));
    let mut short = d.clone();
    short.it.data.pop();
    assert!(compute_flow(&short, 1e4, None, &params(FlowMethod::HornSchunck)).is_err());
}

#[test]
fn confidence_is_gradient_magnitude_above_threshold() {
    let frames = translating(24, 20, 7, 0.3, 0.0, 2);
    let mut d = middle(&frames, 0.0, &no_prewarp());
    for k in 0..24 {
        d.ix.data[k] = 0.0;
        d.iy.data[k] = 0.0;
    }
    let p = params(FlowMethod::HornSchunck);
    let flow = compute_flow(&d, 1e4, None, &p).unwrap();
    assert!(flow.confidence.data[..24].iter().all(|&c| c == 0.0));
    let i = 10 * 24 + 10;
    let g = d.ix.data[i].hypot(d.iy.data[i]);
    assert!((flow.confidence.data[i] - g).abs() < 1e-6);
    assert!(flow.converged && flow.iterations < p.max_iterations);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]
    #[test]
    fn flow_has_input_size_and_no_nan(
        w in 2_usize..24,
        h in 2_usize..24,
        seed in 0_u64..1000,
        method in 0_usize..3,
        jacobi in any::<bool>(),
        amp in 0.0_f32..3.0,
    ) {
        let mut rng = Rng(seed);
        let mut img = || Image::from_fn(w, h, |_, _| amp * (rng.next_f64() as f32 - 0.5));
        let d = Derivatives {
            ix: img(),
            iy: img(),
            it: img(),
            image: Image::zeros(w, h),
            frame_index: 3,
            base_flow_px: -2.0,
        };
        let p = FlowParams {
            method: [FlowMethod::GrooveHornSchunck, FlowMethod::HornSchunck, FlowMethod::LucasKanade][method],
            solver: if jacobi { Solver::Jacobi } else { Solver::GaussSeidel },
            max_iterations: 30,
            ..FlowParams::default()
        };
        let flow = compute_flow(&d, 50.0, None, &p).unwrap();
        for im in [&flow.u, &flow.v, &flow.confidence] {
            prop_assert_eq!((im.width, im.height, im.data.len()), (w, h, w * h));
            prop_assert!(im.data.iter().all(|x| x.is_finite()));
        }
        prop_assert_eq!(flow.frame_index, 3);
    }
}
