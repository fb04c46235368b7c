//! Tests of the still generator: geometry against its own truth, coverage, determinism, files.

use super::*;
use crate::synth::noise::Rng;
use crate::synth::test_support::still_scene_and_image;
use crate::test_support::path_in_temp_dir;

/// A small clean still: 3 grooves, no artefacts, levels 0 (walls) and 1 (land, bottom).
fn clean(axis: Axis, cut: Cut) -> StillConfig {
    StillConfig {
        length_px: 400,
        across_px: 320,
        axis,
        cut,
        grooves: 3,
        drift_um: 40.0,
        wander_um: 5.0,
        land_level: 1.0,
        bottom_level: 1.0,
        wall_level: 0.0,
        wall_level_spread: 0.0,
        rim_fraction: 0.0,
        texture: 0.0,
        illumination_unevenness: 0.0,
        dust_per_mpx: 0.0,
        text: String::new(),
        blur_sigma_px: 0.0,
        noise_sigma: 0.0,
        bit_depth: 16,
        ..StillConfig::default()
    }
}

/// Dominant frequency (cycles per sample) of a border track.
fn dominant_cycles(x: &[f64]) -> f64 {
    let v: Vec<f32> = x.iter().map(|&v| v as f32).collect();
    crate::pipeline::still::measure::dominant_frequency_hz(&v, 1.0).unwrap()
}

#[test]
fn walls_cover_exactly_their_width() {
    for axis in [Axis::Vertical, Axis::Horizontal] {
        let cfg = clean(axis, Cut::Lateral);
        let (scene, img) = still_scene_and_image(&cfg);
        assert_eq!(
            (img.width, img.height),
            match axis {
                Axis::Vertical => (320, 400),
                Axis::Horizontal => (400, 320),
            }
        );
        for line in [3, 150, 399] {
            let px = |m: usize| match axis {
                Axis::Vertical => img.data[line * img.width + m],
                Axis::Horizontal => img.data[m * img.width + line],
            };
            for k in 0..3 {
                let b = scene.borders_px(k, line);
                // Dark share of the pixels between the lands = the walls' width, in pixels
                // (the sub-lines average the border over the line: allow for its slope).
                let lo = (b[0] - 3.0).floor() as usize;
                let hi = (b[3] + 3.0).ceil() as usize;
                let dark: f64 = (lo..=hi).map(|m| 1.0 - f64::from(px(m))).sum();
                let want = (b[1] - b[0]) + (b[3] - b[2]);
                assert!(
                    (dark - want).abs() < 0.02,
                    "{axis:?} line {line} groove {k}: {dark} vs {want}"
                );
            }
        }
    }
}

#[test]
fn borders_carry_each_wall_tone() {
    for axis in [Axis::Vertical, Axis::Horizontal] {
        // No drift: a slow ramp under 3–20 cycles would bias the frequency estimate.
        let cfg = StillConfig {
            length_px: 3000,
            drift_um: 0.0,
            wander_um: 0.0,
            curved: false,
            ..clean(axis, Cut::Stereo)
        };
        let scene = StillScene::new(&cfg, None).unwrap();
        let left = scene.left_wall_index();
        for (k, g) in scene.grooves.iter().enumerate() {
            let (fl, fr) = g.tones_hz.unwrap();
            let rate = g.vt_um_s / cfg.um_per_px;
            let border = |i: usize| -> Vec<f64> {
                (0..cfg.length_px)
                    .map(|n| scene.borders_px(k, n)[i])
                    .collect()
            };
            // The left wall's land border is index 3 (high X) when the left side is +X.
            let (l_land, r_land) = if left == 1 { (3, 0) } else { (0, 3) };
            let got_l = dominant_cycles(&border(l_land)) * rate;
            let got_r = dominant_cycles(&border(r_land)) * rate;
            assert!(
                (got_l / fl - 1.0).abs() < 2e-3,
                "{axis:?} {k}: {got_l} vs {fl}"
            );
            assert!(
                (got_r / fr - 1.0).abs() < 2e-3,
                "{axis:?} {k}: {got_r} vs {fr}"
            );
        }
    }
}

#[test]
fn a_positive_sound_moves_the_groove_to_the_left_hand_side() {
    // A rising velocity ramp: the displacement grows, so the groove moves steadily toward the
    // inner (left-hand) side: +X for a vertical still, −X for a horizontal one.
    let rate = 48_000;
    let sound = Audio {
        sample_rate_hz: rate,
        channels: vec![vec![1.0; 48_000]],
    };
    for (axis, sign) in [(Axis::Vertical, 1.0), (Axis::Horizontal, -1.0)] {
        let cfg = StillConfig {
            drift_um: 0.0,
            wander_um: 0.0,
            curved: false,
            grooves: 1,
            peak_velocity_mm_s: 5.0,
            ..clean(axis, Cut::Lateral)
        };
        // A constant sound has no AC part; give it a step so the mean is not the whole sound.
        let mut s = sound.clone();
        for v in &mut s.channels[0][..24_000] {
            *v = -1.0;
        }
        let scene = StillScene::new(
            &StillConfig {
                start_secs: 0.5,
                ..cfg
            },
            Some(&s),
        )
        .unwrap();
        let a = scene.borders_px(0, 0)[0];
        let b = scene.borders_px(0, 399)[0];
        assert!((b - a) * sign > 0.5, "{axis:?}: {a} → {b}");
    }
}

#[test]
fn same_seed_same_pixels_and_artefacts_change_them() {
    // A small still with the default artefacts, rendered with `seed`.
    let render = |seed: u32| {
        let cfg = StillConfig {
            length_px: 300,
            across_px: 300,
            grooves: 2,
            seed,
            ..StillConfig::default()
        };
        render_still(&StillScene::new(&cfg, None).unwrap())
    };
    let seed = StillConfig::default().seed;
    let (a, b) = (render(seed), render(seed));
    assert_eq!(a.image.data, b.image.data);
    assert!(a.dust_particles > 0 && a.text_box.is_some());
    let other = render(seed + 1);
    assert_ne!(a.image.data, other.image.data);
    // 8-bit levels only.
    assert!(
        a.image
            .data
            .iter()
            .all(|v| (v * 255.0 - (v * 255.0).round()).abs() < 1e-3)
    );
    // The text is white on a black shadow.
    let [x0, y0, x1, y1] = a.text_box.unwrap();
    let inside: Vec<f32> = (y0..y1)
        .flat_map(|y| (x0..x1).map(move |x| (x, y)))
        .map(|(x, y)| a.image.data[y * a.image.width + x])
        .collect();
    assert!(inside.contains(&1.0) && inside.contains(&0.0));
}

#[test]
fn grooves_that_would_touch_are_refused() {
    let cfg = StillConfig {
        peak_velocity_mm_s: 400.0,
        ..clean(Axis::Vertical, Cut::Lateral)
    };
    let err = StillScene::new(&cfg, None).unwrap_err().to_string();
    assert!(err.contains("come") && err.contains("close"), "{err}");
    let bad = StillConfig {
        tones_hz: vec![1000.0],
        ..clean(Axis::Vertical, Cut::Stereo)
    };
    assert!(
        StillScene::new(&bad, None)
            .unwrap_err()
            .to_string()
            .contains("tones_hz")
    );
    let vertical = StillConfig {
        cut: Cut::Vertical,
        ..clean(Axis::Vertical, Cut::Lateral)
    };
    assert!(StillScene::new(&vertical, None).is_err());
}

#[test]
fn references_follow_the_wall_velocities() {
    let cfg = clean(Axis::Horizontal, Cut::Stereo);
    let scene = StillScene::new(&cfg, None).unwrap();
    let a = groove_reference(&scene, 1, 48_000);
    assert_eq!(a.channels.len(), 2);
    let g = &scene.grooves[1];
    let secs = (cfg.length_px as f64 - 1.0) * cfg.um_per_px / g.vt_um_s;
    assert!((a.len() as f64 - secs * 48_000.0).abs() < 2.0 + secs * 48_000.0 * 0.01);
    let mut rng = Rng::new(3);
    for _ in 0..20 {
        let i = (rng.uniform() * (a.len() - 1) as f64) as usize;
        let t = scene.time_secs(1, 0.5 * cfg.um_per_px) + i as f64 / 48_000.0;
        let want = g.left.at(t).1 / (cfg.peak_velocity_mm_s * 1000.0);
        assert!((f64::from(a.channels[0][i]) - want).abs() < 1e-5);
    }
}

#[test]
fn write_still_writes_image_sounds_and_truth() {
    let (_dir, out) = path_in_temp_dir("s");
    let cfg = StillConfig {
        length_px: 200,
        across_px: 320,
        grooves: 3,
        format: "tiff".into(),
        bit_depth: 16,
        ..StillConfig::default()
    };
    let scene = StillScene::new(&cfg, None).unwrap();
    let summary = write_still(&scene, &out).unwrap();
    assert!(summary.image.ends_with("still.tif"));
    let text = std::fs::read_to_string(out.join("truth.toml")).unwrap();
    let back: StillSidecar = toml::from_str(&text).unwrap();
    assert_eq!(back.truth.grooves.len(), 3);
    assert_eq!(back.still, cfg);
    for k in 1..=3 {
        assert!(out.join(format!("groove{k}.wav")).is_file());
    }
    let mut r = crate::io::still::StillReader::open(&summary.image).unwrap();
    let mut rows = Vec::new();
    assert_eq!(r.read_rows(&mut rows, 1000).unwrap(), 200);
    let direct = render_still(&scene).image;
    let worst = rows
        .iter()
        .zip(&direct.data)
        .fold(0.0f32, |m, (a, b)| m.max((a - b).abs()));
    assert!(worst < 1e-6, "{worst}");
    // A second write into the same folder is refused.
    assert!(write_still(&scene, &out).is_err());
}
