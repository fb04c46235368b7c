//! Tests of the groove model: a continuous profile with the right slopes, truth that follows the sound and the wall rule, stereo channels, bad sounds.

use super::*;
use crate::synth::sounds::{stereo, tone};

fn quick(cut: Cut) -> SynthConfig {
    SynthConfig {
        cut,
        ..SynthConfig::quick_test()
    }
}

#[test]
fn profile_is_continuous_with_the_right_slopes() {
    let cfg = SynthConfig {
        bottom_radius_um: 15.0,
        ..SynthConfig::default()
    };
    let p = Profile::new(&cfg);
    assert!((p.eval(0.0).0 - 70.0).abs() < 1e-9);
    assert!(p.eval(90.0).0.abs() < 1e-9);
    assert!((p.eval(-60.0).1 - 1.0).abs() < 1e-9);
    assert!((p.eval(60.0).1 + 1.0).abs() < 1e-9);
    let mut prev = p.eval(-100.0).0;
    for i in 1..4000 {
        let u = -100.0 + i as f64 * 0.05;
        let (v, d) = p.eval(u);
        assert!((v - prev).abs() < 0.06, "jump at {u}");
        assert!(d.abs() <= 1.0 + 1e-9);
        prev = v;
    }
}

#[test]
fn truth_follows_the_tone_and_wall_rule() {
    let sound = tone(1000.0, 0.01, 48_000);
    let g = Groove::new(&sound, &quick(Cut::Lateral)).unwrap();
    let vt = g.groove_speed_mm_s();
    let mut peak = 0.0f64;
    for i in 0..2000 {
        let t = g.truth(i as f64 * 0.5);
        peak = peak.max(t.lateral_velocity_mm_s.abs());
        let want = t.lateral_velocity_mm_s / vt * std::f64::consts::FRAC_1_SQRT_2;
        assert!((t.left_tan_theta - want).abs() < 1e-12);
        assert!((t.right_tan_theta - want).abs() < 1e-12);
    }
    assert!((peak - 20.0).abs() < 0.2, "{peak}");
    // The displacement is the integral of the velocity: amplitude V/(2πf) (over a scan
    // longer than a period, centred by its extremes).
    let long = SynthConfig {
        max_groups: None,
        ..quick(Cut::Lateral)
    };
    let g = Groove::new(&sound, &long).unwrap();
    assert!(g.scan_length_um() > 3000.0);
    let ds: Vec<f64> = (0..12_000)
        .map(|i| g.truth(i as f64 * 0.25).displacement_um)
        .collect();
    let hi = ds.iter().copied().fold(f64::MIN, f64::max);
    let lo = ds.iter().copied().fold(f64::MAX, f64::min);
    assert!((hi + lo).abs() < 0.05, "centred: {lo} {hi}");
    let amp = 0.5 * (hi - lo);
    let want = 20_000.0 / (std::f64::consts::TAU * 1000.0);
    assert!((amp - want).abs() < 0.05 * want, "{amp} {want}");
}

#[test]
fn stereo_left_channel_moves_only_the_left_wall() {
    let l = tone(700.0, 0.01, 48_000);
    let silent = crate::io::wav::Audio {
        sample_rate_hz: 48_000,
        channels: vec![vec![0.0; l.len()]],
    };
    let g = Groove::new(&stereo(&l, &silent), &quick(Cut::Stereo)).unwrap();
    let mut moved = 0.0f64;
    for i in 0..1000 {
        let s = i as f64 * 0.7;
        let t = g.truth(s);
        assert!(t.right_tan_theta.abs() < 1e-12, "{t:?}");
        moved = moved.max(t.left_tan_theta.abs());
        // The right wall's surface stays put: depth at fixed (s, y) on it is unchanged.
        let y_right = 30.0; // inside the right wall band (10..45 µm from the centre)
        let (p, _) = g.profile.eval(y_right - t.displacement_um);
        let z = p + t.depth_offset_um;
        let (p0, _) = g.profile.eval(y_right - g.truth(0.0).displacement_um);
        let z0 = p0 + g.truth(0.0).depth_offset_um;
        assert!((z - z0).abs() < 1e-9, "{s}: {z} vs {z0}");
    }
    assert!(moved > 0.005, "{moved}");
    assert_eq!(g.reference().channels.len(), 2);
}

#[test]
fn bad_sounds_and_steep_walls_are_errors() {
    let empty = crate::io::wav::Audio {
        sample_rate_hz: 48_000,
        channels: vec![vec![]],
    };
    assert!(matches!(
        Groove::new(&empty, &quick(Cut::Lateral)),
        Err(SynthError::Sound { .. })
    ));
    let short = tone(100.0, 0.00005, 48_000);
    let e = Groove::new(&short, &quick(Cut::Lateral)).unwrap_err();
    assert!(e.to_string().contains("too short"), "{e}");
    let loud = SynthConfig {
        peak_velocity_mm_s: 2000.0,
        ..quick(Cut::Lateral)
    };
    let e = Groove::new(&tone(200.0, 0.01, 48_000), &loud).unwrap_err();
    assert!(e.to_string().contains("leaves the frame"), "{e}");
    let steep = SynthConfig {
        wall_angle_deg: 88.0,
        groove_depth_um: 1.0,
        working_distance_mm: 0.5,
        ..quick(Cut::Lateral)
    };
    let e = Groove::new(&tone(1000.0, 0.01, 48_000), &steep).unwrap_err();
    assert!(e.to_string().contains("steeper than the optics"), "{e}");
}
