//! Tests of the wall finder: wiggling, blurred and noisy grooves, dust and voids, flat maps, one visible wall.

use super::test_support::{Groove, Rng, paper_geometry};
use super::*;

/// Width of the wiggling grooves' depth maps, px.
const W: usize = 400;
/// Height of the wiggling grooves' depth maps, px.
const H: usize = 600;

/// A groove under the paper's optics displaced by a sine of `amplitude_um` and `wavelength_um`
/// along it, and its `W` × `H` depth map.
fn wiggling_groove(amplitude_um: f64, wavelength_um: f64) -> (Groove, DepthMap) {
    let g = Groove::sine(paper_geometry(), amplitude_um, wavelength_um);
    let depth = g.depth_map(W, H);
    (g, depth)
}

/// Checks each line of a `W` × `H` map against the true band: centre within `tol_px` in at
/// least `share` of the columns, half height close to the true one less the trim.
fn check_against_truth(lines: &[WallLine], g: &Groove, tol_px: f64, share: f64) {
    assert_eq!(lines.len(), 2);
    assert_eq!(lines[0].side, WallSide::Left);
    assert_eq!(lines[1].side, WallSide::Right);
    let trim = WallParams::default().trim_px as f64;
    for line in lines {
        assert_eq!(line.rows.len(), W);
        let mut good = 0;
        let mut bad = Vec::new();
        for x in 0..W {
            let (row, hw) = g.wall_band_px(line.side, x, W, H);
            let got = f64::from(line.rows[x]);
            assert!(got.is_finite());
            if (got - row).abs() <= tol_px
                && (f64::from(line.half_width_px[x]) - (hw - trim)).abs() <= 4.0
            {
                good += 1;
            } else if bad.len() < 10 {
                bad.push(format!(
                    "x {x}: row {got} vs {row}, hw {} vs {}",
                    line.half_width_px[x],
                    hw - trim
                ));
            }
        }
        assert!(
            good as f64 >= share * W as f64,
            "{:?}: {good} of {W}; {bad:?}",
            line.side
        );
    }
}

#[test]
fn finds_both_walls_of_a_wiggling_groove() {
    let (g, depth) = wiggling_groove(15.0, 120.0);
    for method in [WallMethod::DepthLevels, WallMethod::SlopeRuns] {
        let params = WallParams {
            method,
            ..WallParams::default()
        };
        let lines = find_walls(&depth, &g.geom, &params).unwrap();
        check_against_truth(&lines, &g, 1.0, 0.98);
        assert!(
            lines
                .iter()
                .all(|l| l.depth_um.is_none() && l.projection_depth_um.is_none())
        );
    }
}

#[test]
fn depth_levels_find_the_walls_of_a_blurred_noisy_map() {
    // What the Kalman filter gives: the groove profile rounded by a wide blur, noise of a
    // few µm, and deep spikes on the bottom.
    let (g, sharp) = wiggling_groove(8.0, 140.0);
    let mut depth = sharp.clone();
    depth.z_um.data = smooth_nan(&sharp.z_um.data, W, H, 12);
    let mut rng = Rng::new(11);
    for v in &mut depth.z_um.data {
        *v += 2.0 * rng.gauss() as f32;
    }
    for k in 0..12 {
        let (cx, cy) = (20 + 33 * k, 300 + (k % 3) * 6);
        for y in cy - 4..cy + 4 {
            for x in cx - 4..cx + 4 {
                depth.z_um.data[y * W + x] += 25.0;
            }
        }
    }
    let lines = find_walls(&depth, &g.geom, &WallParams::default()).unwrap();
    check_against_truth(&lines, &g, 3.0, 0.95);
}

#[test]
fn rejects_noise_dust_and_fills_voids() {
    let (g, mut depth) = wiggling_groove(10.0, 150.0);
    let mut rng = Rng::new(3);
    for v in &mut depth.z_um.data {
        *v += rng.gauss() as f32;
    }
    // A dust particle: a raised 25×25 patch on the land; a hole; a dead stripe of columns.
    for y in 30..55 {
        for x in 100..125 {
            depth.z_um.data[y * W + x] -= 40.0;
        }
    }
    for y in 280..300 {
        for x in 300..330 {
            depth.z_um.data[y * W + x] = f32::NAN;
        }
    }
    for y in 0..H {
        for x in 200..212 {
            depth.z_um.data[y * W + x] = f32::NAN;
        }
    }
    let lines = find_walls(&depth, &g.geom, &WallParams::default()).unwrap();
    check_against_truth(&lines, &g, 2.0, 0.95);
    for line in &lines {
        assert!(line.filled[205], "{:?}", line.side);
        assert!(!line.filled[50], "{:?}", line.side);
    }
}

#[test]
fn flat_map_has_no_walls_and_params_are_checked() {
    let geom = paper_geometry();
    let depth = DepthMap {
        z_um: crate::image::Image::filled(50, 80, 4000.0),
        variance: crate::image::Image::zeros(50, 80),
        frame_index: 0,
        warnings: Vec::new(),
    };
    assert!(matches!(
        find_walls(&depth, &geom, &WallParams::default()),
        Err(StageError::NotFound { .. })
    ));
    let bad = WallParams {
        min_slope: f32::NAN,
        ..WallParams::default()
    };
    assert!(matches!(
        find_walls(&depth, &geom, &bad),
        Err(StageError::InvalidParam { .. })
    ));
    let bad = WallParams {
        column_window_px: 0,
        ..WallParams::default()
    };
    assert!(matches!(
        find_walls(&depth, &geom, &bad),
        Err(StageError::InvalidParam { .. })
    ));
}

#[test]
fn a_single_visible_wall_is_still_returned() {
    let geom = paper_geometry();
    let g = Groove::new(geom, |_| 0.0);
    let (w, h) = (120, 600);
    let full = g.depth_map(w, h);
    // Keep only the upper 280 rows: land, the left wall and part of the bottom.
    let top = 280;
    let depth = DepthMap {
        z_um: crate::image::Image::from_vec(w, top, full.z_um.data[..w * top].to_vec()).unwrap(),
        variance: crate::image::Image::zeros(w, top),
        frame_index: 0,
        warnings: Vec::new(),
    };
    let lines = find_walls(&depth, &geom, &WallParams::default()).unwrap();
    assert_eq!(lines.len(), 1);
    assert_eq!(lines[0].side, WallSide::Left);
}
