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

/// `v` less its centred moving mean over `window` samples (slow trends out, such as the
/// slow-path fit's residual where a groove is held), where the window fits.
fn detrended(v: &[f64], window: usize) -> Vec<f64> {
    let half = window / 2;
    (half..v.len() - half)
        .map(|i| v[i] - v[i - half..=i + half].iter().sum::<f64>() / (2 * half + 1) as f64)
        .collect()
}

/// Root mean square.
fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}

#[test]
fn a_groove_that_drifts_off_the_image_is_silent_there_not_its_neighbour() {
    // The grooves drift 500 µm across a 400 µm strip: the outer grooves leave the image for
    // about a quarter of it at opposite ends, and their neighbours drift into their places.
    let cfg = StillConfig {
        length_px: 6000,
        across_px: 400,
        grooves: 3,
        axis: Axis::Horizontal,
        drift_um: 500.0,
        wander_um: 0.0,
        ..StillConfig::default()
    };
    let (scene, img) = still_scene_and_image(&cfg);
    for k in [0, 2] {
        let setup = scene.setup(k).unwrap();
        let a = analyse_still(&img, &setup, Some(k + 1), &StillParams::default()).unwrap();
        let outside = detect::outside_image(&a.borders.predicted, a.grooves.cross);
        let lines: usize = outside.iter().map(ExactSizeIterator::len).sum();
        // Wholly outside once its centre is 28 µm past the edge: it starts 100 µm in and
        // drifts ±250 µm, so on (250 − 128)/500 = 24 % of the lines.
        assert_eq!(outside.len(), 1, "groove {}: {outside:?}", k + 1);
        let share = lines as f64 / 6000.0;
        assert!((share - 0.244).abs() < 0.04, "groove {}: {share}", k + 1);
        // There the displacement is held (silent); before, it was the next groove's sound.
        let want = scene.grooves[k].tones_hz.unwrap().0;
        // One period: its mean holds none of the tone but all of a ramp.
        let window = 2 * (0.5 * a.signal.native_rate_hz / want).round() as usize + 1;
        let d = &a.signal.displacement_px[0];
        let run = &outside[0];
        let inside = if run.start == 0 {
            &d[run.end + 200..]
        } else {
            &d[..run.start - 200]
        };
        let off = rms(&detrended(&d[run.start + 50..run.end - 50], window));
        let inside = detrended(inside, window);
        let on = rms(&inside);
        assert!(off < 0.1 * on, "groove {}: off {off} vs on {on}", k + 1);
        let inside_f32: Vec<f32> = inside.iter().map(|&x| x as f32).collect();
        let got = dominant_hz(&inside_f32, a.signal.native_rate_hz);
        assert!(
            (got / want - 1.0).abs() < 0.02,
            "groove {}: {got} vs {want}",
            k + 1
        );
    }
}

/// The demo still's strip (72 px across at 6 µm/px, three grooves), 20 000 px long.
fn short_demo_strip() -> StillConfig {
    StillConfig {
        length_px: 20_000,
        ..StillConfig::demo()
    }
}

#[test]
fn heavy_noise_does_not_cut_a_groove_in_two() {
    // The demo strip's grooves are 10 px bands whose 1 px bottom is lighter than the walls:
    // under 15 % noise a bright speck on it cut a band into two runs in some blocks, each taken
    // for a groove, and the strip read as eight grooves with the first chosen.
    let (scene, img) = still_scene_and_image(&StillConfig {
        noise_sigma: 0.15,
        ..short_demo_strip()
    });
    let setup = scene.setup(1).unwrap();
    let a = analyse_still(&img, &setup, None, &StillParams::default()).unwrap();
    let found: Vec<(usize, f64)> = a
        .grooves
        .grooves
        .iter()
        .map(|g| (g.number, g.coverage))
        .collect();
    assert_eq!(found.len(), 3, "{found:?}");
    assert!(found.iter().all(|(_, c)| *c > 0.9), "{found:?}");
    assert_eq!(a.chosen, 1);
    let want = scene.grooves[1].tones_hz.unwrap().0;
    let got = dominant_hz(&a.signal.channels[0], a.signal.native_rate_hz);
    assert!((got / want - 1.0).abs() < 0.01, "{got} vs {want}");
}

/// Pearson correlation of two equally long signals.
fn correlation(a: &[f32], b: &[f32]) -> f64 {
    let n = a.len().min(b.len());
    let mean = |v: &[f32]| v[..n].iter().map(|&x| f64::from(x)).sum::<f64>() / n as f64;
    let (ma, mb) = (mean(a), mean(b));
    let (mut ab, mut aa, mut bb) = (0.0, 0.0, 0.0);
    for (&x, &y) in a[..n].iter().zip(&b[..n]) {
        let (x, y) = (f64::from(x) - ma, f64::from(y) - mb);
        ab += x * y;
        aa += x * x;
        bb += y * y;
    }
    ab / (aa * bb).sqrt()
}

#[test]
fn a_dim_still_decodes_as_the_same_still_well_exposed() {
    // 12 bits stored in 16: every grey level a sixteenth of full scale, in steps of 1/65535.
    let (scene, img) = still_scene_and_image(&short_demo_strip());
    let mut dim = img.clone();
    for v in &mut dim.data {
        *v = (f64::from(*v) * 4095.0 / 65535.0 * 65535.0).round() as f32 / 65535.0;
    }
    let setup = scene.setup(1).unwrap();
    let params = StillParams::default();
    let full = analyse_still(&img, &setup, Some(2), &params).unwrap();
    let low = analyse_still(&dim, &setup, Some(2), &params).unwrap();
    // This strip's gaps once split into its lands and a few wider gaps, taken for bottoms and
    // lands: its three grooves read as one 28 px groove.
    assert_eq!(full.grooves.grooves.len(), 3);
    assert_eq!(low.grooves.grooves.len(), 3);
    assert_eq!(full.grooves.brightness_gain, 1.0);
    assert!(
        low.grooves.brightness_gain > 10.0,
        "{}",
        low.grooves.brightness_gain
    );
    let bridged = |a: &StillAnalysis| a.signal.gaps.iter().map(|g| g.lines).sum::<usize>();
    assert!(
        bridged(&low) <= bridged(&full) + 100,
        "{} vs {} lines bridged",
        bridged(&low),
        bridged(&full)
    );
    let r = correlation(&full.signal.channels[0], &low.signal.channels[0]);
    assert!(r > 0.98, "r {r}");
}
