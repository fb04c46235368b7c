//! Tests of the fine fit: a sloped border in every frame, a dust speck rejected, a stretch no
//! frame sees.

use super::*;
use crate::io::scan::test_support::scan_meta;
use crate::meta::ScanMeta;

pub(in crate::pipeline::edges) fn meta() -> ScanMeta {
    scan_meta(40.0)
}

/// Frames of a land/wall border at record y(s) = `y0 + slope·s` (µm), blurred by 0.7 px,
/// with a bright speck `speck` columns wide across it at groove position 20 µm.
pub(in crate::pipeline::edges) fn frames(
    geo: &FrameGeometry,
    y0: f64,
    slope: f64,
    speck: usize,
) -> Vec<Image> {
    (0..6)
        .map(|k| {
            let cam = geo.cam_s_um(0, k);
            Image::from_fn(geo.width, geo.height, |x, r| {
                let s = geo.s_at(cam, x as f64, geo.working_distance_um);
                let y = geo.y_at(r as f64, geo.working_distance_um);
                let edge = y0 + slope * s;
                let mut v = 0.15 + 0.6 * normal_cdf((y - edge) / (0.7 * 0.39));
                // The speck is fixed to the record: the same groove position in every frame.
                if speck > 0
                    && (s - 20.0).abs() < 0.5 * speck as f64 * 0.39
                    && (y - edge).abs() < 2.0
                {
                    v = 1.0;
                }
                v as f32
            })
        })
        .collect()
}

fn run(speck: usize, rounds: u32) -> (f64, SampleBorder, FrameGeometry) {
    let geo = FrameGeometry::new(&meta(), 120, 60);
    let (y0, slope) = (0.7, 0.03);
    let imgs = frames(&geo, y0, slope, speck);
    let list: Vec<(&Image, f64, usize)> = imgs
        .iter()
        .enumerate()
        .map(|(k, f)| (f, geo.cam_s_um(0, k), k))
        .collect();
    let predict = |s: f64| y0 + slope * s + 0.3; // a prediction 0.3 µm off
    let task = SampleTask {
        s_lo_um: 10.0,
        s_hi_um: 31.3,
        z_um: geo.working_distance_um,
        predict_y: &predict,
    };
    let params = EdgeParams {
        column_rounds: rounds,
        ..EdgeParams::default()
    };
    let got = fit_gathered(&list, 3, &geo, &task, &params, true).unwrap();
    // The truth: the border averaged over the stretch, in rows.
    let y_mean = y0 + slope * 20.65;
    (geo.row_at(y_mean, geo.working_distance_um), got, geo)
}

#[test]
fn a_sloped_border_is_found_in_every_frame() {
    let (want, got, _) = run(0, 3);
    assert!((got.row_px - want).abs() < 0.01, "{} vs {want}", got.row_px);
    assert_eq!(got.frames.len(), 6);
    for f in &got.frames {
        assert!((f.row_px - want).abs() < 0.02, "{f:?} vs {want}");
    }
    assert_eq!(got.rounds, 1);
}

#[test]
fn a_dust_speck_across_the_border_is_rejected() {
    // Without the robust rounds the speck pulls the border; with them it is weighted out.
    let (want, plain, _) = run(6, 1);
    let (_, robust, _) = run(6, 3);
    let plain_err = (plain.row_px - want).abs();
    let robust_err = (robust.row_px - want).abs();
    assert!(plain_err > 0.05, "the speck should matter: {plain_err}");
    assert!(
        robust_err < 0.02,
        "robust error {robust_err} (plain {plain_err})"
    );
    assert!(robust.rounds > 1);
    let rejected = robust.column_weights.iter().filter(|c| c.1 < 0.5).count();
    assert!((4..=10).contains(&rejected), "{rejected} columns rejected");
}

#[test]
fn a_stretch_outside_every_frame_is_none() {
    let geo = FrameGeometry::new(&meta(), 120, 60);
    let imgs = frames(&geo, 0.7, 0.0, 0);
    let list: Vec<(&Image, f64, usize)> = vec![(&imgs[0], geo.cam_s_um(0, 0), 0)];
    let predict = |_: f64| 0.7;
    let task = SampleTask {
        s_lo_um: 500.0,
        s_hi_um: 521.3,
        z_um: geo.working_distance_um,
        predict_y: &predict,
    };
    assert!(fit_sample(&list, 0, &geo, &task, &EdgeParams::default()).is_none());
}
