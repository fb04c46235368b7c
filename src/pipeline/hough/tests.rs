//! Tests of the stripe stage: scenes with known lines, the windows, the centroid lines, the glass sides, bad input.

use super::*;
use crate::pipeline::test_support::assert_each_edit_is_refused;

/// A tiny deterministic generator (tests only).
struct Lcg(u64);
impl Lcg {
    fn next_f32(&mut self) -> f32 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        ((self.0 >> 40) as f32) / (1u64 << 24) as f32
    }
}

/// One stripe: rows centred on `row_at(x)` ± `half` px.
struct Line {
    theta_deg: f32,
    rho_px: f32,
}

impl Line {
    fn row_at(&self, x: usize, width: usize) -> f32 {
        let x0 = (width as f32 - 1.0) * 0.5;
        let (s, c) = self.theta_deg.to_radians().sin_cos();
        (self.rho_px + (x as f32 - x0) * s) / c
    }
}

/// Derivatives whose gradient is 1 on the stripes (and at noise pixels), 0 elsewhere;
/// flow confidence 1 everywhere. `void` columns are left out of every stripe except the first.
fn scene(
    width: usize,
    height: usize,
    lines: &[Line],
    half: f32,
    noise: f32,
    void: std::ops::Range<usize>,
) -> (Derivatives, FlowField) {
    let mut rng = Lcg(7);
    synthetic_input(width, height, 1.0, |x, y| {
        let on_line = lines.iter().enumerate().any(|(i, l)| {
            (i == 0 || !void.contains(&x)) && (y as f32 - l.row_at(x, width)).abs() <= half
        });
        on_line || rng.next_f32() < noise
    })
}

fn dual(side: GlassSide) -> DualFocusMeta {
    DualFocusMeta {
        focus_distance_mm: 4.05,
        glass_thickness_mm: 0.11,
        glass_index: 1.515,
        glass_side: side,
        glass_edge_row: 100.0,
    }
}

fn three_lines() -> Vec<Line> {
    vec![
        Line {
            theta_deg: 2.0,
            rho_px: 40.0,
        },
        Line {
            theta_deg: -3.0,
            rho_px: 95.0,
        },
        Line {
            theta_deg: 1.0,
            rho_px: 150.0,
        },
    ]
}

#[test]
fn focus_shift_of_the_paper_glass() {
    let d = dual(GlassSide::Top);
    assert!(
        (d.focus_shift_mm() - 0.0374).abs() < 5e-5,
        "{}",
        d.focus_shift_mm()
    );
    let (plain, glass) = d.focal_distances_mm();
    assert_eq!(plain, 4.05);
    assert!((glass - plain - 0.0374).abs() < 5e-5);
}

#[test]
fn hough_finds_three_known_lines_in_noise() {
    let lines = three_lines();
    let (d, f) = scene(400, 200, &lines, 1.0, 0.03, 0..0);
    let params = HoughParams::default();
    let s = segment_stripes(&d, &f, &dual(GlassSide::Top), &params).unwrap();
    assert_eq!(s.peaks.len(), 3);
    for (p, l) in s.peaks.iter().zip(&lines) {
        let dt = (p.theta_rad.to_degrees() - l.theta_deg).abs();
        assert!(dt <= params.theta_step_deg, "θ {p:?} vs {}", l.theta_deg);
        assert!(
            (p.rho_px - l.rho_px).abs() <= params.rho_step_px,
            "ρ {p:?} vs {}",
            l.rho_px
        );
    }
    // The lines follow the stripes: the gated centroid ignores the noise in the windows.
    for (line, &k) in s.lines.iter().zip(&s.line_peaks) {
        let truth = &lines[k];
        let mut worst = 0.0_f32;
        let mut total = 0.0_f32;
        for x in 0..400 {
            let e = (line.rows[x] - truth.row_at(x, 400)).abs();
            worst = worst.max(e);
            total += e;
            assert!(!line.filled[x]);
        }
        // Pixel quantisation of a 3-px stripe alone gives up to ±0.5 px.
        assert!(worst < 1.0, "line {k} off by {worst} px");
        assert!(
            total / 400.0 < 0.3,
            "line {k} mean error {} px",
            total / 400.0
        );
    }
    // Sub-bin: the stripe rows on a pure θ bin give ρ within a fraction of a bin.
    assert!((s.peaks[2].rho_px - 150.0).abs() < 0.5);
}

#[test]
fn a_bent_stripe_gives_one_peak_not_two() {
    // A stripe bent at the centre column (±8°, as a strongly modulated groove curves within
    // a frame) votes for two tangents, both stronger than the short straight stripes below
    // it; the tangents cross inside the frame, so only one may become a
    // peak.
    let (w, h) = (400, 200);
    let x0 = (w as f32 - 1.0) * 0.5;
    let bent = |x: usize| 40.0 + (x as f32 - x0).abs() * 8f32.to_radians().tan();
    let (d, f) = synthetic_input(w, h, 1.0, |x, y| {
        let y = y as f32;
        let short = (150..250).contains(&x);
        (y - bent(x)).abs() <= 1.0 || (short && (y == 110.0 || y == 160.0))
    });
    let s = segment_stripes(&d, &f, &dual(GlassSide::Top), &HoughParams::default()).unwrap();
    let rows: Vec<f32> = s.peaks.iter().map(|p| p.row_at_px(x0)).collect();
    assert_eq!(rows.len(), 3, "{rows:?}");
    assert!((rows[0] - 40.0).abs() < 3.0, "{rows:?}");
    assert!((rows[1] - 110.0).abs() < 1.0, "{rows:?}");
    assert!((rows[2] - 160.0).abs() < 1.0, "{rows:?}");
}

#[test]
fn pure_hough_votes_land_in_the_right_bin() {
    let params = HoughParams::default();
    let width = 101;
    let pts: Vec<FocusPoint> = (0..width)
        .map(|x| FocusPoint {
            xc: x as f32 - 50.0,
            y: 30.0 + (x as f32 - 50.0) * 10f32.to_radians().tan(),
            index: 0,
        })
        .collect();
    let acc = vote(&pts, 1, width, 80, &params);
    assert_eq!(acc.theta_bins(), 91);
    assert_eq!(acc.rho_bins, 80);
    // θ = 10° is bin 55; ρ = 30·cos10° = 29.54 -> bin 30.
    assert_eq!(acc.get(55, 30), width as u32);
    // Away from the true line its butterfly gives other local maxima of about 101·step/sin Δθ.
    let peaks = find_peaks(&acc, &params, 60);
    assert_eq!(peaks.len(), 1);
    assert!((peaks[0].theta_rad.to_degrees() - 10.0).abs() < 1e-4);
    assert!((peaks[0].row_at_px(50.0) - 30.0).abs() < 0.6);
}

#[test]
fn points_in_overlapping_windows_are_discarded() {
    // Two stripes 20 px apart with ±15 px windows: their windows overlap between them.
    let lines = vec![
        Line {
            theta_deg: 0.0,
            rho_px: 30.0,
        },
        Line {
            theta_deg: 0.0,
            rho_px: 90.0,
        },
        Line {
            theta_deg: 0.0,
            rho_px: 110.0,
        },
    ];
    let (mut d, f) = scene(120, 160, &lines, 1.0, 0.0, 0..0);
    // A lone in-focus pixel halfway between the two close stripes, and one far away.
    d.iy.data[100 * 120 + 60] = 1.0;
    d.iy.data[60 * 120 + 60] = 1.0;
    let s = segment_stripes(&d, &f, &dual(GlassSide::Top), &HoughParams::default()).unwrap();
    assert_eq!(s.labels[100 * 120 + 60], label::DISCARDED);
    assert_eq!(s.labels[60 * 120 + 60], label::UNASSIGNED);
    assert_eq!(s.labels[30 * 120 + 5], 0);
    assert_eq!(s.labels[90 * 120 + 60], 1);
    assert_eq!(s.labels[110 * 120 + 60], 2);
    assert_eq!(s.labels[5 * 120 + 5], label::NONE);
    // At the far columns a stripe pixel's curve sweeps ±59·sin 4° ≈ ±4 px: still only its window.
    assert_eq!(s.labels[110 * 120 + 119], 2);
    // A pixel 6 px below the middle stripe lies 14 px from the bottom one: in both windows.
    d.iy.data[96 * 120 + 60] = 1.0;
    let s = segment_stripes(&d, &f, &dual(GlassSide::Top), &HoughParams::default()).unwrap();
    assert_eq!(s.labels[96 * 120 + 60], label::DISCARDED);
    assert_eq!(s.in_focus.data[96 * 120 + 60], 1.0);
}

#[test]
fn curve_range_matches_brute_force() {
    for &(xc, y, a, b) in &[
        (100.0, 50.0, -0.2, 0.1),
        (-300.0, 10.0, -0.5, 0.5),
        (0.0, 80.0, -0.1, 0.1),
        (500.0, 1.0, -1.5, -1.4),
        (500.0, 1.0, -1.5, 1.4),
        (-20.0, -600.0, -1.0, 1.0),
        (3.0, 0.0, 1.0, 2.0),
    ] {
        let half = (b - a) / 2.0;
        let peak = Peak {
            theta_rad: (a + half) as f32,
            rho_px: 0.0,
            votes: 1,
            x_origin_px: 0.0,
            window_theta_rad: half as f32,
            window_rho_px: 1.0,
        };
        let (lo, hi) = WindowTest::new(&peak).rho_range(xc, y);
        let mut blo = f64::MAX;
        let mut bhi = f64::MIN;
        for i in 0..=10_000 {
            let t = a + (b - a) * f64::from(i) / 10_000.0;
            let r = -xc * t.sin() + y * t.cos();
            blo = blo.min(r);
            bhi = bhi.max(r);
        }
        assert!(
            (lo - blo).abs() < 1e-3 && (hi - bhi).abs() < 1e-3,
            "{xc} {y}"
        );
    }
}

#[test]
fn a_rho_band_finds_the_mean_line_of_wiggling_stripes() {
    // Three 3-px stripes that wiggle ±6 px (two periods across 1280 px), in 4% noise.
    let (w, h) = (1280, 800);
    let rows = [200.0_f32, 420.0, 540.0];
    let mut rng = Lcg(11);
    let (d, f) = synthetic_input(w, h, 1.0, |x, y| {
        let wave = 6.0 * (x as f32 * 0.01).sin();
        let on = rows.iter().any(|&r| (y as f32 - r - wave).abs() <= 1.0);
        on || rng.next_f32() < 0.04
    });
    let params = HoughParams {
        peak_rho_band_px: 8.0,
        min_votes_per_column: 1.0,
        ..HoughParams::default()
    };
    let s = segment_stripes(&d, &f, &dual(GlassSide::Top), &params).unwrap();
    // The mean of 6·sin(0.01·x) over the frame is about 0.3 px.
    for (p, &r) in s.peaks.iter().zip(&rows) {
        assert!(p.theta_rad.abs() <= 1f32.to_radians() + 1e-6, "{p:?}");
        assert!((p.row_at_px(639.5) - r).abs() < 2.0, "{p:?} vs {r}");
    }
    // The centroid lines follow the wiggle itself.
    for (line, &k) in s.lines.iter().zip(&s.line_peaks) {
        for x in (0..w).step_by(50) {
            let truth = rows[k] + 6.0 * (x as f32 * 0.01).sin();
            assert!(
                (line.rows[x] - truth).abs() < 1.0,
                "x {x}: {} vs {truth}",
                line.rows[x]
            );
        }
    }
}

#[test]
fn densest_run_skips_stray_rows() {
    let rows = [3.0, 40.0, 41.0, 42.0, 50.0, 51.0, 58.0, 59.0];
    assert_eq!(densest_run(&rows, 3.0, 0.0), Some((41.0, 3)));
    // A tie goes to the run nearer the prior.
    assert_eq!(
        densest_run(&[10.0, 11.0, 30.0, 31.0], 2.0, 29.0),
        Some((30.5, 2))
    );
    assert_eq!(densest_run(&[], 2.0, 0.0), None);
}

#[test]
fn void_is_filled_on_the_peak_line() {
    let lines = three_lines();
    let (d, f) = scene(400, 200, &lines, 1.0, 0.0, 150..190);
    let s = segment_stripes(&d, &f, &dual(GlassSide::Top), &HoughParams::default()).unwrap();
    assert_eq!(s.line_peaks, vec![1, 2]);
    for (line, &k) in s.lines.iter().zip(&s.line_peaks) {
        let peak = &s.peaks[k];
        for x in 0..400 {
            assert_eq!(line.filled[x], (150..190).contains(&x), "x {x}");
            let truth = lines[k].row_at(x, 400);
            if line.filled[x] {
                assert_eq!(line.rows[x], peak.row_at_px(x as f32));
                assert!((line.rows[x] - truth).abs() < 1.0);
            } else {
                // Without noise the centroid sits on the stripe (pixel rounding only).
                assert!((line.rows[x] - truth).abs() < 0.6, "x {x}");
                assert!((line.half_width_px[x] - 1.5).abs() < 0.6);
            }
            assert!(line.rows[x].is_finite());
        }
    }
}

/// The three lines (a little noise) segmented under a cover glass on `side`.
fn three_stripes_under_glass(side: GlassSide) -> (DualFocusMeta, Stripes) {
    let (d, f) = scene(400, 200, &three_lines(), 1.0, 0.01, 0..0);
    let meta = dual(side);
    let s = segment_stripes(&d, &f, &meta, &HoughParams::default()).unwrap();
    (meta, s)
}

#[test]
fn kept_lines_get_the_right_depths_for_glass_on_top() {
    let (meta, s) = three_stripes_under_glass(GlassSide::Top);
    assert_eq!(s.dropped, 0);
    assert_eq!(s.line_peaks, vec![1, 2]);
    let shift_um = meta.focus_shift_mm() * 1000.0;
    let (a, b) = (&s.lines[0], &s.lines[1]);
    assert!((a.depth_um.unwrap() - (4050.0 + shift_um)).abs() < 1e-6);
    assert!((b.depth_um.unwrap() - 4050.0).abs() < 1e-6);
    assert_eq!(a.projection_depth_um, Some(4050.0));
    assert_eq!(b.projection_depth_um, Some(4050.0));
    assert_eq!(a.side, WallSide::Right);
    assert_eq!(b.side, WallSide::Right);
    // The upper kept line is the one under the glass.
    assert!(a.rows[200] < b.rows[200]);
}

#[test]
fn glass_at_the_bottom_mirrors_the_choice() {
    let (_, s) = three_stripes_under_glass(GlassSide::Bottom);
    assert_eq!(s.dropped, 2);
    assert_eq!(s.line_peaks, vec![0, 1]);
    assert!((s.lines[0].depth_um.unwrap() - 4050.0).abs() < 1e-6);
    assert!(s.lines[1].depth_um.unwrap() > 4087.0);
    assert!(s.lines.iter().all(|l| l.side == WallSide::Left));
}

#[test]
fn two_stripes_are_not_enough() {
    let lines = three_lines();
    let (d, f) = scene(400, 200, &lines[..2], 1.0, 0.03, 0..0);
    let err = segment_stripes(&d, &f, &dual(GlassSide::Top), &HoughParams::default()).unwrap_err();
    match err {
        StageError::NotFound { problem, .. } => {
            assert!(problem.starts_with("found 2 stripes, need 3"), "{problem}");
        }
        other => panic!("{other:?}"),
    }
    // Blurred everywhere (no gradient): nothing found.
    let (mut d, f) = scene(64, 64, &lines[..1], 1.0, 0.0, 0..0);
    d.iy = Image::zeros(64, 64);
    let err = segment_stripes(&d, &f, &dual(GlassSide::Top), &HoughParams::default()).unwrap_err();
    assert!(err.to_string().contains("found 0 stripes"), "{err}");
}

#[test]
fn pixels_without_flow_are_not_in_focus() {
    let (d, mut f) = scene(400, 200, &three_lines(), 1.0, 0.0, 0..0);
    f.confidence = Image::zeros(400, 200);
    assert!(matches!(
        segment_stripes(&d, &f, &dual(GlassSide::Top), &HoughParams::default()),
        Err(StageError::NotFound { .. })
    ));
}

#[test]
fn subsampled_votes_find_the_same_peaks() {
    let lines = three_lines();
    let (d, f) = scene(400, 200, &lines, 1.0, 0.03, 0..0);
    let full = segment_stripes(&d, &f, &dual(GlassSide::Top), &HoughParams::default()).unwrap();
    let params = HoughParams {
        max_vote_points: 1000,
        ..HoughParams::default()
    };
    let sub = segment_stripes(&d, &f, &dual(GlassSide::Top), &params).unwrap();
    assert!(sub.accumulator.vote_stride > 1);
    for (a, b) in full.peaks.iter().zip(&sub.peaks) {
        assert_eq!(a.theta_rad, b.theta_rad);
        assert!((a.rho_px - b.rho_px).abs() <= 1.0);
    }
}

#[test]
fn invalid_params_and_inputs_are_rejected() {
    let (d, f) = scene(40, 30, &three_lines(), 1.0, 0.0, 0..0);
    let meta = dual(GlassSide::Top);
    // Each edit makes the defaults invalid.
    let edits: [fn(&mut HoughParams); 6] = [
        |p| p.gradient_threshold = f32::NAN,
        |p| {
            p.theta_min_deg = 10.0;
            p.theta_max_deg = -10.0;
        },
        |p| p.theta_step_deg = 0.0,
        |p| p.rho_step_px = 0.0,
        |p| p.window_rho_px = -1.0,
        |p| p.peak_count = 2,
    ];
    assert_each_edit_is_refused(&edits, |p| segment_stripes(&d, &f, &meta, p));
    let mut bad_meta = meta.clone();
    bad_meta.glass_index = 0.5;
    assert!(matches!(
        segment_stripes(&d, &f, &bad_meta, &HoughParams::default()),
        Err(StageError::InvalidParam { .. })
    ));
    let mut f2 = f.clone();
    f2.confidence = Image::zeros(10, 10);
    assert!(matches!(
        segment_stripes(&d, &f2, &meta, &HoughParams::default()),
        Err(StageError::BadInput { .. })
    ));
}
