//! Tests of the border model: sub-pixel steps, seeds, bounds and bad parameters.

use super::*;
use crate::synth::noise::Rng;

/// A step from `lo` to `hi` at `mu` blurred by a Gaussian of σ = `blur`, integrated over
/// each pixel's aperture (16 sub-samples), as a camera records it.
fn blurred_step(n: usize, mu: f64, blur: f64, lo: f64, hi: f64) -> Vec<f64> {
    (0..n)
        .map(|i| {
            let mut acc = 0.0;
            for k in 0..16 {
                let x = i as f64 - 0.5 + (k as f64 + 0.5) / 16.0;
                acc += lo + (hi - lo) * normal_cdf((x - mu) / blur);
            }
            acc / 16.0
        })
        .collect()
}

#[test]
fn a_noiseless_blurred_step_is_found_exactly() {
    let p = BorderParams::default();
    for &blur in &[0.4, 1.0, 2.5] {
        for k in 0..10 {
            let mu = 20.0 + k as f64 * 0.1;
            let prof: Vec<f32> = blurred_step(40, mu, blur, 0.15, 0.75)
                .iter()
                .map(|&v| v as f32)
                .collect();
            let b = find_border(&prof, None, Polarity::Rising, &p).unwrap();
            // The model is point-sampled; a pixel's 1 px aperture on a sharp edge (σ below
            // half a pixel) is not quite an erf, which costs a few thousandths of a pixel.
            let tol = if blur < 0.5 { 5e-3 } else { 2e-4 };
            assert!((b.position_px - mu).abs() < tol, "{blur} {mu}: {b:?}");
            assert!((b.contrast() - 0.6).abs() < 1e-3, "{b:?}");
        }
    }
}

/// The brief's bar: a blurred step with σ = 1 grey level of noise (8-bit scale) is found
/// within 0.02 px, averaged over the 55 columns of one output sample as the edge stage
/// averages them; and a single column's error matches the standard error it reports.
#[test]
fn a_noisy_blurred_step_is_found_within_two_hundredths_of_a_pixel() {
    let p = BorderParams::default();
    let sigma = 1.0 / 255.0;
    let mut rng = Rng::new(7);
    let (mut worst, mut sq_err, mut sq_se, mut n) = (0.0f64, 0.0, 0.0, 0.0);
    for trial in 0..60 {
        let blur = [0.5, 1.0, 2.0][trial % 3];
        let mu = 15.0 + 0.037 * trial as f64;
        let clean = blurred_step(32, mu, blur, 0.15, 0.75);
        // One column: its error against the standard error it reports.
        let col: Vec<f32> = clean
            .iter()
            .map(|&v| (v + sigma * rng.gaussian()) as f32)
            .collect();
        let b = find_border(&col, None, Polarity::Rising, &p).unwrap();
        sq_err += (b.position_px - mu).powi(2);
        sq_se += b.std_error_px.powi(2);
        n += 1.0;
        // 55 columns averaged into one profile.
        let mut avg = vec![0.0f64; clean.len()];
        for _ in 0..55 {
            for (a, &v) in avg.iter_mut().zip(&clean) {
                *a += (v + sigma * rng.gaussian()) / 55.0;
            }
        }
        let prof: Vec<f32> = avg.iter().map(|&v| v as f32).collect();
        let b = find_border(&prof, None, Polarity::Rising, &p).unwrap();
        worst = worst.max((b.position_px - mu).abs());
    }
    let ratio = (sq_err / sq_se).sqrt();
    eprintln!(
        "55-column worst {worst:.4} px; one column rms {:.4} px, error/standard error {ratio:.2}",
        (sq_err / n).sqrt()
    );
    assert!(worst < 0.02, "worst error {worst} px");
    assert!(
        (0.6..1.6).contains(&ratio),
        "error / standard error = {ratio}"
    );
    assert!(
        (sq_err / n).sqrt() < 0.02,
        "single-column rms {}",
        (sq_err / n).sqrt()
    );
}

#[test]
fn polarity_picks_the_asked_border() {
    // Dark, bright band, dark: a rising border at 10.3, a falling one at 25.6.
    let rise = blurred_step(40, 10.3, 0.8, 0.1, 0.8);
    let fall = blurred_step(40, 25.6, 0.8, 0.0, 0.7);
    let prof: Vec<f32> = rise
        .iter()
        .zip(&fall)
        .map(|(&a, &b)| (a - b) as f32)
        .collect();
    let p = BorderParams::default();
    let r = find_border(&prof, None, Polarity::Rising, &p).unwrap();
    let f = find_border(&prof, None, Polarity::Falling, &p).unwrap();
    assert!((r.position_px - 10.3).abs() < 1e-3, "{r:?}");
    assert!((f.position_px - 25.6).abs() < 1e-3, "{f:?}");
    assert!(r.contrast() > 0.0 && f.contrast() < 0.0);
}

#[test]
fn flat_or_short_profiles_have_no_border() {
    let p = BorderParams::default();
    assert!(find_border(&[0.5; 30], None, Polarity::Either, &p).is_none());
    assert!(find_border(&[0.1, 0.9], None, Polarity::Either, &p).is_none());
    assert!(find_border(&[], None, Polarity::Either, &p).is_none());
    let nan = vec![f32::NAN; 20];
    assert!(find_border(&nan, None, Polarity::Either, &p).is_none());
    // A faint step below the contrast floor.
    let faint: Vec<f32> = blurred_step(30, 14.0, 1.0, 0.5, 0.51)
        .iter()
        .map(|&v| v as f32)
        .collect();
    assert!(find_border(&faint, None, Polarity::Either, &p).is_none());
    // Weights of the wrong length are refused.
    assert!(find_border(&faint, Some(&[1.0; 3]), Polarity::Either, &p).is_none());
}

#[test]
fn zero_weights_skip_samples() {
    // A spike on the bright side would pull the levels; a zero weight hides it.
    let mut prof: Vec<f32> = blurred_step(30, 12.4, 1.0, 0.2, 0.7)
        .iter()
        .map(|&v| v as f32)
        .collect();
    prof[14] = 0.0;
    let mut w = vec![1.0f32; 30];
    w[14] = 0.0;
    let b = find_border(&prof, Some(&w), Polarity::Rising, &BorderParams::default()).unwrap();
    assert!((b.position_px - 12.4).abs() < 1e-3, "{b:?}");
}

#[test]
fn binned_points_at_any_abscissa_fit() {
    // Quarter-pixel bins of a sharp step, weights = pixel counts, as the stage's slanted
    // profiles give them.
    let pts: Vec<ProfilePoint> = (0..48)
        .map(|k| {
            let x = -6.0 + k as f64 * 0.25;
            ProfilePoint {
                x_px: x,
                value: if x < 0.37 { 0.1 } else { 0.9 },
                weight: 3.0 + (k % 4) as f64,
            }
        })
        .collect();
    let b = fit_border(
        &pts,
        BorderSeed {
            position_px: 0.0,
            width_px: 1.0,
        },
        &BorderParams::default(),
    )
    .unwrap();
    assert!((b.position_px - 0.37).abs() < 0.13, "{b:?}");
    assert!(b.width_px <= 0.31, "{b:?}");
}

/// A fit whose width wants to leave its bounds settles on the bound well within its
/// iterations, at the position the bounded model puts it: a hard step (width below the 0.3 px
/// floor) and one blurred far beyond a 1 px ceiling
/// (before the bounded step, such fits ran to `max_iterations`).
#[test]
fn a_width_on_its_bound_does_not_stall_the_fit() {
    let fit = |pts: &[ProfilePoint], params: &BorderParams| {
        fit_border(
            pts,
            BorderSeed {
                position_px: 0.0,
                width_px: 1.0,
            },
            params,
        )
        .unwrap()
    };
    let params = BorderParams::default();
    // Texture on the levels, as a record's surface gives them.
    let mut rng = Rng::new(11);
    let mut texture = move || 1.0 + 0.05 * rng.gaussian();
    let hard: Vec<ProfilePoint> = (0..64)
        .map(|k| {
            let x = -8.0 + (f64::from(k) + 0.5) * 0.25;
            ProfilePoint {
                x_px: x,
                value: if x < 0.4 { 0.1 } else { 0.9 } * texture(),
                weight: 1.0,
            }
        })
        .collect();
    let b = fit(&hard, &params);
    assert_eq!(b.width_px, params.min_width_px, "{b:?}");
    assert!(b.iterations < params.max_iterations, "{b:?}");
    assert!((b.position_px - 0.4).abs() < 0.13, "{b:?}");
    let narrow = BorderParams {
        max_width_px: 1.0,
        ..BorderParams::default()
    };
    let wide: Vec<ProfilePoint> = (0..64)
        .map(|k| {
            let x = -8.0 + (f64::from(k) + 0.5) * 0.25;
            ProfilePoint {
                x_px: x,
                value: (0.1 + 0.8 * normal_cdf(x / 3.0)) * texture(),
                weight: 1.0,
            }
        })
        .collect();
    let b = fit(&wide, &narrow);
    assert_eq!(b.width_px, narrow.max_width_px, "{b:?}");
    assert!(b.iterations < narrow.max_iterations, "{b:?}");
    // The band is symmetric about the step, so the bounded fit keeps its centre, within the
    // texture's error.
    assert!(b.position_px.abs() < 3.0 * b.std_error_px, "{b:?}");
}

#[test]
fn params_are_checked() {
    let good = BorderParams::default();
    good.validate("edges.border").unwrap();
    let bad = BorderParams {
        max_width_px: 0.1,
        ..good.clone()
    };
    assert!(bad.validate("edges.border").is_err());
    let bad = BorderParams {
        max_iterations: 0,
        ..good
    };
    let e = bad.validate("edges.border").unwrap_err();
    assert!(e.to_string().contains("edges.border.max_iterations"), "{e}");
}
