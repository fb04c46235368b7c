//! Tests of the derivative stage: normalised filters, ramps, a translating pattern, pre-warping, bad input.

use super::*;
use proptest::prelude::*;

mod reference;

fn simoncelli(prewarp: bool) -> DerivativeParams {
    DerivativeParams {
        mode: DerivativeMode::Simoncelli,
        prewarp,
        ..DerivativeParams::default()
    }
}

/// `n` frames of `w` × `h` whose pixel (x, y) in frame k is `value(x, y, k)`.
fn frames_from(
    n: usize,
    w: usize,
    h: usize,
    value: impl Fn(usize, usize, usize) -> f32,
) -> Vec<Image> {
    (0..n)
        .map(|k| Image::from_fn(w, h, |x, y| value(x, y, k)))
        .collect()
}

#[test]
fn filters_are_normalised() {
    assert!((P5.iter().sum::<f32>() - 1.0).abs() < 1e-6);
    let moment: f32 = D5
        .iter()
        .enumerate()
        .map(|(j, &t)| t * (j as f32 - 2.0))
        .sum();
    assert!((moment - 1.0).abs() < 1e-6);
    let d7 = fold_preblur(&D5);
    let m7: f32 = d7
        .iter()
        .enumerate()
        .map(|(j, &t)| t * (j as f32 - 3.0))
        .sum();
    assert!((m7 - 1.0).abs() < 1e-6 && d7[3].abs() < 1e-9);
    assert!((fold_preblur(&P5).iter().sum::<f32>() - 1.0).abs() < 1e-6);
}

#[test]
fn ramps_give_positive_unit_derivatives() {
    let (w, h) = (20, 16);
    let frames = frames_from(9, w, h, |x, y, k| {
        0.01 * x as f32 + 0.02 * y as f32 + 0.03 * k as f32
    });
    for mode in [DerivativeMode::Simoncelli, DerivativeMode::TwoFrame] {
        let p = DerivativeParams {
            mode,
            prewarp: false,
            ..DerivativeParams::default()
        };
        let sets = compute_derivatives(&frames, -2.0, &p).unwrap();
        let expected = if mode == DerivativeMode::Simoncelli {
            3
        } else {
            8
        };
        assert_eq!(sets.len(), expected);
        for d in &sets {
            assert_eq!(d.base_flow_px, 0.0);
            // Interior pixel, away from clamped borders.
            let (x, y) = (10, 8);
            assert!((d.ix.get(x, y).unwrap() - 0.01).abs() < 1e-6);
            assert!((d.iy.get(x, y).unwrap() - 0.02).abs() < 1e-6);
            assert!((d.it.get(x, y).unwrap() - 0.03).abs() < 1e-6);
        }
    }
    let sets = compute_derivatives(&frames, -2.0, &simoncelli(false)).unwrap();
    let idx: Vec<usize> = sets.iter().map(|d| d.frame_index).collect();
    assert_eq!(idx, vec![3, 4, 5]);
    // The smoothed image of a ramp is the ramp (p5 is symmetric and sums to 1).
    let c = &sets[1];
    let want = 0.01 * 10.0 + 0.02 * 8.0 + 0.03 * 4.0;
    assert!((c.image.get(10, 8).unwrap() - want).abs() < 1e-5);
}

#[test]
fn analytic_translating_pattern() {
    // I = sin(a(x − u·t))·cos(b·y).
    let (a, b, u) = (
        std::f64::consts::TAU / 32.0,
        std::f64::consts::TAU / 40.0,
        0.5,
    );
    let (w, h) = (80, 64);
    let frames = frames_from(7, w, h, |x, y, k| {
        ((a * (x as f64 - u * k as f64)).sin() * (b * y as f64).cos()) as f32
    });
    let sets = compute_derivatives(&frames, 0.0, &simoncelli(false)).unwrap();
    assert_eq!(sets.len(), 1);
    let d = &sets[0];
    assert_eq!(d.frame_index, 3);
    let t = 3.0;
    let (mut worst_x, mut worst_y, mut worst_t, mut worst_flow) =
        (0.0_f64, 0.0_f64, 0.0_f64, 0.0_f64);
    for y in 4..h - 4 {
        for x in 4..w - 4 {
            let (xf, yf) = (x as f64, y as f64);
            let phase = a * (xf - u * t);
            let ix = a * phase.cos() * (b * yf).cos();
            let iy = -b * phase.sin() * (b * yf).sin();
            let it = -u * ix;
            let got = |im: &Image| f64::from(im.get(x, y).unwrap());
            worst_x = worst_x.max((got(&d.ix) - ix).abs());
            worst_y = worst_y.max((got(&d.iy) - iy).abs());
            worst_t = worst_t.max((got(&d.it) - it).abs());
            // The ratio It/Ix is what the flow uses: it must be much closer than the gains.
            if ix.abs() > 0.5 * a {
                worst_flow = worst_flow.max((-got(&d.it) / got(&d.ix) - u).abs());
            }
        }
    }
    // p5 smooths a 32 px (40 px) wave by ~3 % (2 %): allow 6 % of the amplitude.
    assert!(worst_x < 0.06 * a, "Ix off by {worst_x}");
    assert!(worst_y < 0.06 * b, "Iy off by {worst_y}");
    assert!(worst_t < 0.06 * a * u, "It off by {worst_t}");
    assert!(worst_flow < 0.005 * u, "It/Ix off by {worst_flow}");
}

#[test]
fn integer_prewarp_aligns_exactly() {
    let (w, h) = (40, 12);
    // Content moves 2 px toward −x per frame.
    let frames = frames_from(12, w, h, |x, y, k| {
        (0.37 * (x + 2 * k) as f32).sin() + 0.1 * y as f32
    });
    let sets = compute_derivatives(&frames, -2.0, &simoncelli(true)).unwrap();
    assert_eq!(sets.len(), 6);
    for d in &sets {
        assert_eq!(d.base_flow_px, -2.0);
        // Interior: no shifted sample was clamped (|shift| ≤ 6 px).
        for y in 0..h {
            for x in 8..w - 8 {
                assert!(d.it.get(x, y).unwrap().abs() < 1e-5);
            }
        }
    }
    let shift = RowShift::new(-2.0, w);
    assert!(shift.weights.is_none());
    let src: Vec<f32> = (0..w).map(|x| x as f32).collect();
    let mut dst = vec![0.0; w];
    shift.apply(&src, &mut dst);
    assert_eq!(&dst[..3], &[0.0, 0.0, 0.0]);
    assert_eq!(dst[10], 8.0);
}

#[test]
fn cubic_shift_is_exact_on_cubics_and_clamps() {
    let w = 30;
    let f = |x: f64| 0.5 + 0.1 * x - 0.01 * x * x + 0.0005 * x * x * x;
    let src: Vec<f32> = (0..w).map(|x| f(x as f64) as f32).collect();
    let mut dst = vec![0.0; w];
    for s in [0.25, -1.5, 3.7] {
        RowShift::new(s, w).apply(&src, &mut dst);
        for (x, &got) in dst.iter().enumerate().take(w - 6).skip(3) {
            // Catmull–Rom reproduces quadratics exactly; cubic terms leave a small error.
            let want = f(x as f64 + s);
            assert!(
                (f64::from(got) - want).abs() < 2e-3,
                "{s} {x}: {got} vs {want}"
            );
        }
    }
    RowShift::new(1e9, w).apply(&src, &mut dst);
    assert!(dst.iter().all(|&v| v == src[w - 1]));
    RowShift::new(-1e9, w).apply(&src, &mut dst);
    assert!(dst.iter().all(|&v| v == src[0]));
}

#[test]
fn bad_input_is_rejected() {
    let frame = Image::zeros(8, 6);
    let six = vec![frame.clone(); 6];
    assert!(matches!(
        compute_derivatives(&six, 0.0, &simoncelli(true)),
        Err(StageError::BadInput { .. })
    ));
    let one = vec![frame.clone(); 1];
    let two_frame = DerivativeParams {
        mode: DerivativeMode::TwoFrame,
        prewarp: true,
        ..DerivativeParams::default()
    };
    assert!(compute_derivatives(&one, 0.0, &two_frame).is_err());
    assert_eq!(compute_derivatives(&six, 0.0, &two_frame).unwrap().len(), 5);
    let mut mixed = vec![frame.clone(); 7];
    mixed[4] = Image::zeros(8, 5);
    assert!(matches!(
        compute_derivatives(&mixed, 0.0, &simoncelli(true)),
        Err(StageError::BadInput { .. })
    ));
    let seven = vec![frame; 7];
    for bad in [f64::NAN, f64::INFINITY] {
        assert!(matches!(
            compute_derivatives(&seven, bad, &simoncelli(false)),
            Err(StageError::InvalidParam { .. })
        ));
    }
    assert!(compute_derivatives(&[], 0.0, &simoncelli(false)).is_err());
    // ±3 frames × 30 px pre-warps a 7-frame window past both sides of a 160 px frame: refused
    // naming the land flow, where it used to give all-zero derivatives.
    let wide = vec![Image::zeros(160, 6); 7];
    match compute_derivatives(&wide, -30.0, &simoncelli(true)) {
        Err(StageError::InvalidParam { name, problem }) => {
            assert_eq!(name, "land_flow_px");
            assert!(problem.contains("160 px wide"), "{problem}");
        }
        other => panic!("{other:?}"),
    }
    assert!(compute_derivatives(&wide, -30.0, &simoncelli(false)).is_ok());
    assert!(compute_derivatives(&wide, -20.0, &simoncelli(true)).is_ok());
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]
    #[test]
    fn outputs_match_input_size_and_are_finite(
        w in 1_usize..20,
        h in 1_usize..20,
        n in 7_usize..10,
        land in -8.0_f64..8.0,
        prewarp in any::<bool>(),
        two in any::<bool>(),
        seed in 0_u32..1000,
    ) {
        let frames = frames_from(n, w, h, |x, y, k| {
            let v = (x * 31 + y * 17 + k * 7 + seed as usize) % 23;
            v as f32 / 23.0
        });
        let p = DerivativeParams {
            mode: if two { DerivativeMode::TwoFrame } else { DerivativeMode::Simoncelli },
            prewarp,
            ..DerivativeParams::default()
        };
        let sets = match compute_derivatives(&frames, land, &p) {
            // A pre-warp wider than the frame is refused, naming the land flow.
            Err(StageError::InvalidParam { name, .. }) if prewarp && name == "land_flow_px" => {
                let half_window = if two { 1.0 } else { 3.0 };
                // The shift, the cubic's reach and the filter radius.
                prop_assert!(land.abs() * half_window + 5.0 >= w as f64 / 2.0);
                return Ok(());
            }
            r => r.unwrap(),
        };
        prop_assert_eq!(sets.len(), if two { n - 1 } else { n - 6 });
        for d in &sets {
            for im in [&d.ix, &d.iy, &d.it, &d.image] {
                prop_assert_eq!((im.width, im.height, im.data.len()), (w, h, w * h));
                prop_assert!(im.data.iter().all(|v| v.is_finite()));
            }
        }
    }
}
