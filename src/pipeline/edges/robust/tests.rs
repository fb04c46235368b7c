//! Tests of the robust combination: rejection, stereo offsets, stretch weights, and the
//! excursion and multi-start solves.

use super::*;

fn params(cut: Cut) -> CombineParams {
    CombineParams {
        cut,
        sigma_um: 0.5,
        floor_um: 0.01,
        max_bridge: 3,
        weight_window: 0,
        max_step_um: 0.0,
        max_excursion: 0,
        restart: true,
    }
}

/// Border tracks of a groove moving by `d(j)` and `e(j)`, with a small deterministic jitter.
fn tracks(n: usize, d: impl Fn(usize) -> f64, e: impl Fn(usize) -> f64) -> [Vec<f64>; 4] {
    let c = [-90.0, -20.0, 20.0, 90.0];
    std::array::from_fn(|b| {
        (0..n)
            .map(|j| {
                let jitter = 0.01 * ((j * 7 + b * 13) % 5) as f64 - 0.02;
                c[b] + 3.0 + d(j) + K[b] * e(j) + jitter
            })
            .collect()
    })
}

#[test]
fn lateral_walls_follow_the_displacement_and_a_flaked_border_is_rejected() {
    let n = 40;
    let d = |j: usize| 5.0 * (j as f64 * 0.4).sin();
    let mut y = tracks(n, d, |_| 0.0);
    // A flake: the left land border jumps 30 µm for samples 10..17.
    for v in &mut y[0][10..17] {
        *v += 30.0;
    }
    let se: [Vec<f64>; 4] = std::array::from_fn(|_| vec![0.02; n]);
    let c = combine_borders(&y, &se, &params(Cut::Lateral));
    for j in 0..n {
        // The groove's centre: the lands are symmetric (constants ±90 → centre 3.0 + d).
        let want = 3.0 + d(j);
        for side in 0..2 {
            assert!(
                (c.walls_um[side][j] - want).abs() < 0.05,
                "{j}: {}",
                c.walls_um[side][j]
            );
        }
    }
    for j in 10..17 {
        assert!(
            c.border_weights[0][j] < REJECTED_WEIGHT,
            "{j}: {}",
            c.border_weights[0][j]
        );
    }
    assert!(c.border_weights[1][12] > 0.5);
    assert!(c.gaps[0].is_empty() && c.gaps[1].is_empty());
}

#[test]
fn a_stretch_where_most_borders_are_off_is_solved_again_from_the_track_around_it() {
    // As on a heavily damaged scan: for five samples dust moves the right bottom corner
    // 25 µm, a flake moves the left land 45 µm and the right land is not seen, so the
    // median start falls on the wrong borders; only the left bottom corner is right.
    let n = 120;
    let d = |j: usize| 2.0 * (j as f64 * 0.15).sin();
    let mut y = tracks(n, d, |_| 0.0);
    let stretch = 50..55;
    y[0][stretch.clone()].iter_mut().for_each(|v| *v += 45.0);
    y[2][stretch.clone()].iter_mut().for_each(|v| *v += 25.0);
    y[3][stretch].fill(f64::NAN);
    let se: [Vec<f64>; 4] = std::array::from_fn(|_| vec![0.02; n]);
    let off = combine_borders(&y, &se, &params(Cut::Lateral));
    assert!(off.excursions.is_empty());
    assert!(
        (off.walls_um[0][52] - (3.0 + d(52))).abs() > 10.0,
        "the median start fails"
    );
    // Samples 1 µm apart along the groove, slopes up to 1: the track may move 1 µm a sample.
    let p = CombineParams {
        max_step_um: 1.0,
        max_excursion: 16,
        ..params(Cut::Lateral)
    };
    let c = combine_borders(&y, &se, &p);
    assert_eq!(c.excursions, vec![50..55]);
    for j in 0..n {
        let want = 3.0 + d(j);
        // One border alone carries the excursion: its own jitter (±0.02 µm) and constant.
        let tol = if (50..55).contains(&j) { 0.1 } else { 0.05 };
        assert!(
            (c.walls_um[0][j] - want).abs() < tol,
            "{j}: {}",
            c.walls_um[0][j]
        );
    }
    assert!(c.border_weights[1][52] > 0.5 && c.border_weights[2][52] < REJECTED_WEIGHT);
}

#[test]
fn two_borders_that_agree_outvote_one_read_precisely() {
    // Laterally, z = y − c per border: the left land 40 µm off (a flake), the left bottom
    // 5 µm off (dust) but read four times as precisely, the two right borders on the
    // groove. The median of the four (2.5 µm) starts the Lorentzian where the precise
    // border's weight carries it.
    let sigma = 0.5;
    let obs = [
        (0, 40.0, 100.0),
        (1, 5.0, 400.0),
        (2, 0.0, 100.0),
        (3, 0.0, 100.0),
    ];
    let from_median = iterate_sample(&obs, true, sigma, median_start(&obs, true).unwrap());
    assert!(
        (from_median.unwrap().0 - 5.0).abs() < 0.3,
        "{from_median:?}"
    );
    // `edges.restart_solves = false`: the median start alone, as before.
    let median_only = solve_sample(&obs, true, sigma, Start::Median { restart: false });
    assert_eq!(format!("{median_only:?}"), format!("{from_median:?}"));
    let restart = Start::Median { restart: true };
    let (d, _, _, rel) = solve_sample(&obs, true, sigma, restart).unwrap();
    assert!(d.abs() < 0.3, "d {d}");
    assert!(
        rel[1] < REJECTED_WEIGHT && rel[2] > 0.5 && rel[3] > 0.5,
        "{rel:?}"
    );
    // Borders that agree: the median start's solve, to the bit.
    let clean = [
        (0, 0.1, 100.0),
        (1, -0.1, 400.0),
        (2, 0.05, 100.0),
        (3, 0.0, 100.0),
    ];
    // (Debug text: the covariance holds NaN, which equals nothing.)
    assert_eq!(
        format!("{:?}", solve_sample(&clean, true, sigma, restart)),
        format!(
            "{:?}",
            iterate_sample(&clean, true, sigma, median_start(&clean, true).unwrap())
        )
    );
}

#[test]
fn stereo_walls_move_apart_with_the_vertical_offset() {
    let n = 30;
    let d = |j: usize| 2.0 * (j as f64 * 0.3).sin();
    let e = |j: usize| 1.5 * (j as f64 * 0.7).cos();
    let y = tracks(n, d, e);
    let se: [Vec<f64>; 4] = std::array::from_fn(|_| vec![0.02; n]);
    let c = combine_borders(&y, &se, &params(Cut::Stereo));
    // The constants' gauge puts the groove centre at the lands' midpoint; e's offset is
    // its median, so compare e and the walls about their first sample.
    for j in 0..n {
        assert!((c.d_um[j] - (3.0 + d(j))).abs() < 0.05, "{j}");
        let de = (c.e_um[j] - c.e_um[0]) - (e(j) - e(0));
        assert!(de.abs() < 0.05, "{j}: {de}");
        for (side, sign) in [(0, -1.0), (1, 1.0)] {
            let got = c.walls_um[side][j] - c.walls_um[side][0];
            let want = d(j) - d(0) + sign * (e(j) - e(0));
            assert!((got - want).abs() < 0.07, "{side} {j}: {got} vs {want}");
        }
    }
    assert!(crate::pipeline::median(c.e_um.clone()).unwrap().abs() < 1e-9);
}

#[test]
fn stretch_weights_keep_the_mix_steady_where_standard_errors_scatter() {
    // Four borders with the same true noise (0.1 µm) whose fits' standard errors scatter
    // by a factor of up to 4 from sample to sample, independently of their errors: per-
    // sample weights then mix the borders unevenly, a stretch's weights do not.
    let n = 400;
    let mut state = 12_345u64;
    let mut uniform = move || {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let d = |j: usize| 4.0 * (j as f64 * 0.05).sin();
    let c = [-90.0, -20.0, 20.0, 90.0];
    let mut y: [Vec<f64>; 4] = Default::default();
    let mut se: [Vec<f64>; 4] = Default::default();
    for b in 0..4 {
        for j in 0..n {
            // Sum of four uniforms: near-normal noise of σ 0.1 µm.
            let z = (0..4).map(|_| uniform() - 0.5).sum::<f64>() * 0.1 * 3f64.sqrt();
            y[b].push(c[b] + d(j) + z);
            se[b].push(0.1 * 4f64.powf(2.0 * uniform() - 1.0));
        }
    }
    let rms_error = |window: usize| {
        let p = CombineParams {
            weight_window: window,
            ..params(Cut::Lateral)
        };
        let comb = combine_borders(&y, &se, &p);
        let err: Vec<f64> = (0..n).map(|j| comb.d_um[j] - d(j)).collect();
        let mean = err.iter().sum::<f64>() / n as f64;
        (err.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / n as f64).sqrt()
    };
    let (own, stretch) = (rms_error(0), rms_error(32));
    // Equal weights would give 0.1/√4 = 0.05 µm.
    assert!(stretch < 0.058, "stretch weights: {stretch:.4} µm");
    assert!(
        own > 1.15 * stretch,
        "own {own:.4} µm, stretch {stretch:.4} µm"
    );
}

#[test]
fn missing_samples_become_gaps_or_are_bridged() {
    let n = 30;
    let mut y = tracks(n, |j| 0.1 * j as f64, |_| 0.0);
    for b in &mut y {
        b[8] = f64::NAN; // one sample: bridged
        for v in &mut b[15..25] {
            *v = f64::NAN; // ten: a gap
        }
    }
    let se: [Vec<f64>; 4] = std::array::from_fn(|_| vec![0.02; n]);
    let c = combine_borders(&y, &se, &params(Cut::Lateral));
    assert_eq!(c.bridged[0], vec![8..9]);
    assert_eq!(c.gaps[0], vec![15..25]);
    assert!((c.walls_um[0][8] - (3.0 + 0.8)).abs() < 0.05);
    assert!(c.walls_um[0][20].is_nan());
}

#[test]
fn bridging_needs_two_samples_on_each_side() {
    let mut v = vec![0.0, f64::NAN, 2.0, 3.0, 4.0, f64::NAN, f64::NAN, 7.0, 8.0];
    let (gaps, bridged) = bridge_gaps(&mut v, 3);
    assert_eq!(gaps, vec![1..2]);
    assert_eq!(bridged, vec![5..7]);
    assert!((v[5] - 5.0).abs() < 1e-12 && (v[6] - 6.0).abs() < 1e-12);
}
