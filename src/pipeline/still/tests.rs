//! Tests of the still decoder on small generated stills with known wall tones.

use super::*;
use crate::synth::still::StillConfig;
use crate::synth::test_support::still_scene_and_image;

fn dominant_hz(x: &[f32], rate: f64) -> f64 {
    measure::dominant_frequency_hz(x, rate).unwrap()
}

fn small(axis: Axis, cut: Cut) -> StillConfig {
    StillConfig {
        length_px: 3000,
        across_px: 400,
        grooves: 3,
        axis,
        cut,
        text: "GS 1 UM/PX".into(),
        ..StillConfig::default()
    }
}

#[test]
fn every_groove_of_a_small_still_gives_its_tone() {
    for axis in [Axis::Vertical, Axis::Horizontal] {
        let cfg = small(axis, Cut::Lateral);
        let (scene, img) = still_scene_and_image(&cfg);
        for k in 0..3 {
            let setup = scene.setup(k).unwrap();
            let a = analyse_still(&img, &setup, Some(k + 1), &StillParams::default()).unwrap();
            assert_eq!(a.grooves.grooves.len(), 3, "{axis:?}");
            let want = scene.grooves[k].tones_hz.unwrap().0;
            let got = dominant_hz(&a.signal.channels[0], a.signal.native_rate_hz);
            assert!(
                (got / want - 1.0).abs() < 0.01,
                "{axis:?} groove {k}: {got} vs {want}"
            );
        }
    }
}

#[test]
fn stereo_walls_keep_their_own_tones() {
    let cfg = small(Axis::Vertical, Cut::Stereo);
    let (scene, img) = still_scene_and_image(&cfg);
    let k = 1;
    let a = analyse_still(
        &img,
        &scene.setup(k).unwrap(),
        Some(k + 1),
        &StillParams::default(),
    )
    .unwrap();
    let (fl, fr) = scene.grooves[k].tones_hz.unwrap();
    let rate = a.signal.native_rate_hz;
    let gl = dominant_hz(&a.signal.channels[0], rate);
    let gr = dominant_hz(&a.signal.channels[1], rate);
    assert!((gl / fl - 1.0).abs() < 0.01, "left {gl} vs {fl}");
    assert!((gr / fr - 1.0).abs() < 0.01, "right {gr} vs {fr}");
}

#[test]
fn the_wrong_axis_an_empty_image_and_a_missing_groove_are_reported() {
    let cfg = small(Axis::Vertical, Cut::Lateral);
    let (scene, img) = still_scene_and_image(&cfg);
    let mut setup = scene.setup(0).unwrap();
    setup.axis = Axis::Horizontal;
    let e = analyse_still(&img, &setup, None, &StillParams::default()).unwrap_err();
    assert!(matches!(e, StillError::AxisContradicts { .. }), "{e}");
    assert!(e.to_string().contains("--axis vertical"), "{e}");
    setup.axis = Axis::Vertical;
    let e = analyse_still(&img, &setup, Some(4), &StillParams::default()).unwrap_err();
    assert_eq!(
        e,
        StillError::GrooveOutOfRange {
            asked: 4,
            found: 3,
            side: "left"
        }
    );
    let flat = Image::filled(300, 300, 0.5);
    let e = analyse_still(&flat, &setup, None, &StillParams::default()).unwrap_err();
    assert!(
        matches!(e, StillError::NoGroove { .. }) && e.to_string().contains("columns 0–299"),
        "{e}"
    );
}
