//! Edge stage tests on rendered grooves: displacement, depth, velocity and channels against the
//! generator's truth.

use std::f64::consts::SQRT_2;

use super::predict::first_after;
use super::*;
use crate::pipeline::audio_signal::{SoundParams, StitchedSignal};
use crate::synth::{Groove, SynthConfig, scan_meta, stereo, tone};

/// The paper's optics on 640×320 px frames: a 90 µm wide, 35 µm deep groove.
fn config(cut: Cut) -> SynthConfig {
    SynthConfig {
        width_px: 640,
        height_px: 320,
        group_overlap_px: 60,
        groove_top_width_um: 90.0,
        groove_depth_um: 35.0,
        peak_velocity_mm_s: 20.0,
        cut,
        max_groups: Some(2),
        ..SynthConfig::default()
    }
}

/// The truth averaged over each sample's stretch (what a border sample measures).
fn boxed(g: &Groove, s: f64, spacing: f64, f: impl Fn(&crate::synth::GrooveTruth) -> f64) -> f64 {
    let n = 64;
    (0..n)
        .map(|i| f(&g.truth(s - 0.5 * spacing + (i as f64 + 0.5) / n as f64 * spacing)))
        .sum::<f64>()
        / n as f64
}

fn run(g: &Groove, group: usize) -> Edges {
    let meta = scan_meta(g).unwrap();
    let frames = g.render_group(group);
    detect_edges(
        &frames,
        0,
        group,
        &meta,
        &SoundParams::default(),
        &EdgeParams::default(),
    )
    .unwrap()
}

#[test]
fn lateral_displacement_depth_and_velocity_match_the_truth() {
    let g = Groove::new(&tone(1500.0, 0.01, 48_000), &config(Cut::Lateral)).unwrap();
    let e = run(&g, 1);
    assert!(e.warnings.is_empty(), "{:?}", e.warnings);
    assert!(
        (e.bottom_depth_um - 35.0).abs() < 1.0,
        "depth {}",
        e.bottom_depth_um
    );
    assert!(
        e.positions_um.len() >= 10,
        "{} samples",
        e.positions_um.len()
    );
    // Positions lie on the global grid.
    for (i, &p) in e.positions_um.iter().enumerate() {
        let j = (p / e.spacing_um).round();
        assert!((p - j * e.spacing_um).abs() < 1e-9);
        assert_eq!(j as i64, e.first_sample + i as i64);
    }
    let (mut worst_d, mut sq_v, mut sq_ref) = (0.0f64, 0.0, 0.0);
    for (i, &s) in e.positions_um.iter().enumerate() {
        let want = boxed(&g, s, e.spacing_um, |t| t.displacement_um);
        for w in &e.walls {
            worst_d = worst_d.max((w.displacement_um[i] - want).abs());
        }
        let v = e.walls[0].velocity_mm_s[i] * SQRT_2;
        let vt = g.truth(s).lateral_velocity_mm_s;
        if i >= 2 && i + 2 < e.positions_um.len() {
            sq_v += (v - vt).powi(2);
            sq_ref += vt * vt;
        }
    }
    assert!(worst_d < 0.08, "worst displacement error {worst_d} µm");
    let snr = 10.0 * (sq_ref / sq_v).log10();
    eprintln!("worst displacement error {worst_d:.4} µm, velocity SNR {snr:.1} dB");
    assert!(snr > 20.0, "velocity SNR {snr:.1} dB");
}

#[test]
fn group_signal_matches_the_flow_conventions() {
    let g = Groove::new(&tone(1000.0, 0.01, 48_000), &config(Cut::Lateral)).unwrap();
    let e = run(&g, 0);
    let sig = e.to_group_signal();
    assert_eq!(sig.channels.len(), 1);
    assert_eq!(sig.positions_um, e.positions_um);
    // Lateral mono is the groove's lateral velocity itself, in mm/s, with its sign.
    let mut dot = 0.0;
    let mut norm = 0.0;
    for (&p, &v) in sig.positions_um.iter().zip(&sig.channels[0]) {
        if v.is_finite() {
            let t = g.truth(p).lateral_velocity_mm_s;
            dot += f64::from(v) * t;
            norm += t * t;
        }
    }
    let gain = dot / norm;
    assert!((gain - 1.0).abs() < 0.05, "gain {gain}");
    let borders = e.border_signal();
    assert_eq!(borders.channels.len(), BorderChannels::COUNT);
}

/// The brief's bar: stereo walls with different tones kept apart.
#[test]
fn stereo_walls_with_different_tones_are_kept_apart() {
    let (fl, fr) = (3000.0, 800.0);
    let sound = stereo(&tone(fl, 0.01, 48_000), &tone(fr, 0.01, 48_000));
    let g = Groove::new(&sound, &config(Cut::Stereo)).unwrap();
    let e = run(&g, 1);
    let sig = e.to_group_signal();
    assert_eq!(sig.channels.len(), 2);
    // Least-squares gains of each channel on both walls' true velocities (Vt·tan θ) jointly:
    // over a few samples the two tones are far from orthogonal.
    let vt = e.groove_speed_mm_s;
    let inside = 2..sig.positions_um.len() - 2;
    let gains = |ch: usize| {
        crate::pipeline::test_support::two_gains(inside.clone().map(|i| {
            let t = g.truth(sig.positions_um[i]);
            let lr = (t.left_tan_theta * vt, t.right_tan_theta * vt);
            (lr, f64::from(sig.channels[ch][i]))
        }))
    };
    let (ll, lr) = gains(0);
    let (rl, rr) = gains(1);
    eprintln!("left channel: {ll:.3} of left, {lr:.3} of right; right: {rl:.3}, {rr:.3}");
    assert!(
        (ll - 1.0).abs() < 0.1 && (rr - 1.0).abs() < 0.1,
        "{ll} {rr}"
    );
    assert!(lr.abs() < 0.06 && rl.abs() < 0.06, "crosstalk {lr} {rl}");
}

#[test]
fn a_border_lost_over_the_whole_group_is_a_gap_not_an_error() {
    let g = Groove::new(&tone(1000.0, 0.01, 48_000), &config(Cut::Lateral)).unwrap();
    let meta = scan_meta(&g).unwrap();
    let flat = vec![Image::filled(640, 320, 0.3); 12];
    let e = detect_edges(
        &flat,
        0,
        0,
        &meta,
        &SoundParams::default(),
        &EdgeParams::default(),
    )
    .unwrap();
    assert!(!e.warnings.is_empty());
    assert!(
        e.walls
            .iter()
            .all(|w| w.displacement_um.iter().all(|v| v.is_nan()))
    );
    assert_eq!(
        e.gaps[0].iter().map(ExactSizeIterator::len).sum::<usize>(),
        e.positions_um.len()
    );
    assert!(e.to_group_signal().channels[0].iter().all(|v| v.is_nan()));
}

#[test]
fn bad_input_is_an_error() {
    let g = Groove::new(&tone(1000.0, 0.01, 48_000), &config(Cut::Lateral)).unwrap();
    let meta = scan_meta(&g).unwrap();
    let p = EdgeParams::default();
    let s = SoundParams::default();
    assert!(detect_edges(&[], 0, 0, &meta, &s, &p).is_err());
    let mixed = vec![Image::filled(64, 64, 0.1), Image::filled(64, 65, 0.1)];
    assert!(detect_edges(&mixed, 0, 0, &meta, &s, &p).is_err());
    let bad = EdgeParams {
        bin_px: f64::NAN,
        ..EdgeParams::default()
    };
    let e = detect_edges(&[Image::filled(64, 64, 0.1)], 0, 0, &meta, &s, &bad).unwrap_err();
    assert!(e.to_string().contains("edges.bin_px"), "{e}");
}

#[test]
#[ignore = "exploration: prints the tracks"]
fn explore_tracks() {
    let g = Groove::new(&tone(1500.0, 0.01, 48_000), &config(Cut::Lateral)).unwrap();
    let e = run(&g, 1);
    eprintln!(
        "depth {} first {} n {}",
        e.bottom_depth_um,
        e.first_sample,
        e.positions_um.len()
    );
    eprintln!("constants {:?}", e.constants_um);
    for (i, &s) in e.positions_um.iter().enumerate() {
        let want = boxed(&g, s, e.spacing_um, |t| t.displacement_um);
        let ys: Vec<String> = e
            .borders
            .iter()
            .map(|b| {
                format!(
                    "{:8.3}/{:.3}/{:.2}",
                    b.y_um[i] - e.constants_um[b.id as usize] - want,
                    b.std_error_um[i],
                    b.weight[i]
                )
            })
            .collect();
        eprintln!(
            "{i:2} s {s:8.2} d {:8.3} err {:7.4} v {:8.3} truth {:8.3} | {}",
            e.walls[0].displacement_um[i],
            e.walls[0].displacement_um[i] - want,
            e.walls[0].velocity_mm_s[i] * SQRT_2,
            g.truth(s).lateral_velocity_mm_s,
            ys.join(" ")
        );
    }
}

/// Per-border displacement errors against the truth on a rendered tone scan in
/// `$GROOVESCOPE_SCAN` (tone `$GROOVESCOPE_TONE` Hz, `synth --duration` `$GROOVESCOPE_SECS`).
#[test]
#[ignore = "measurement: needs a rendered scan"]
fn explore_scan_borders() {
    let (Ok(dir), Ok(freq), Ok(secs)) = (
        std::env::var("GROOVESCOPE_SCAN"),
        std::env::var("GROOVESCOPE_TONE"),
        std::env::var("GROOVESCOPE_SECS"),
    ) else {
        return;
    };
    let scan = crate::io::Scan::open(std::path::Path::new(&dir)).unwrap();
    let cfg: SynthConfig = scan
        .meta
        .extra
        .get("synth")
        .unwrap()
        .clone()
        .try_into()
        .unwrap();
    let g = Groove::new(
        &tone(
            freq.parse().unwrap(),
            secs.parse().unwrap(),
            crate::synth::BUILTIN_RATE_HZ,
        ),
        &cfg,
    )
    .unwrap();
    let params = EdgeParams {
        refine: std::env::var("GROOVESCOPE_NOREFINE").is_err(),
        ..EdgeParams::default()
    };
    let groups: usize = std::env::var("GROOVESCOPE_GROUPS").map_or(3, |v| v.parse().unwrap());
    let mut sq = [[0.0f64; 2]; 5];
    let mut cnt = [[0usize; 2]; 5];
    for entry in scan.groups.iter().take(groups) {
        let frames = crate::io::load_group(entry).unwrap();
        let t = std::time::Instant::now();
        let e = detect_edges(
            &frames,
            0,
            entry.index,
            &scan.meta,
            &SoundParams::default(),
            &params,
        )
        .unwrap();
        eprintln!(
            "group {} {:.0} ms depth {:.2}",
            entry.index,
            t.elapsed().as_secs_f64() * 1e3,
            e.bottom_depth_um
        );
        let verbose = std::env::var("GROOVESCOPE_VERBOSE").is_ok();
        for (i, &s) in e.positions_um.iter().enumerate() {
            let want = boxed(&g, s, e.spacing_um, |t| t.displacement_um);
            let slope = g.truth(s).lateral_velocity_mm_s.abs() / e.groove_speed_mm_s;
            if verbose {
                let b = &e.borders[0];
                let geo =
                    geometry::FrameGeometry::new(&scan.meta, frames[0].width, frames[0].height);
                let want_row = geo.row_at(want + e.constants_um[0], b.z_um);
                let plain = b.fits[i].as_ref().map_or(f64::NAN, |f| f.row_px);
                let refined = geo.row_at(b.y_um[i], b.z_um);
                eprintln!(
                    "  {i:2} slope {slope:.4} truth {want_row:9.3} plain {:+.3} refined {:+.3} width {:.2}",
                    plain - want_row,
                    refined - want_row,
                    b.fits[i].as_ref().map_or(f64::NAN, |f| f.fit.width_px)
                );
            }
            let flat = usize::from(slope > 0.01);
            for b in &e.borders {
                let err = b.y_um[i] - e.constants_um[b.id as usize] - want;
                if err.is_finite() {
                    sq[b.id as usize][flat] += err * err;
                    cnt[b.id as usize][flat] += 1;
                }
            }
            let err = e.walls[0].displacement_um[i] - want;
            if err.is_finite() {
                sq[4][flat] += err * err;
                cnt[4][flat] += 1;
            }
        }
    }
    for (k, name) in ["LL", "LC", "RC", "RL", "d"].iter().enumerate() {
        eprintln!(
            "{name}: rms error {:.4} µm where level ({} samples), {:.4} µm where sloped ({})",
            (sq[k][0] / cnt[k][0].max(1) as f64).sqrt(),
            cnt[k][0],
            (sq[k][1] / cnt[k][1].max(1) as f64).sqrt(),
            cnt[k][1]
        );
    }
}

#[test]
fn the_interpolants_search_is_the_partition_point() {
    // Evenly spaced points with gaps, and uneven ones; queries inside, outside, on points, NaN.
    let even: Vec<(f64, f64)> = (0..40)
        .filter(|j| j % 7 != 3)
        .map(|j| (f64::from(j) * 21.3 - 100.0, 0.0))
        .collect();
    let uneven: Vec<(f64, f64)> = (0..30).map(|j| (f64::from(j * j) * 0.7, 0.0)).collect();
    for pts in [even, uneven, vec![(5.0, 1.0)]] {
        let s0 = pts[0].0;
        let step = if pts.len() > 1 {
            (pts[pts.len() - 1].0 - s0) / (pts.len() - 1) as f64
        } else {
            1.0
        };
        let mut queries: Vec<f64> = (-200..1000).map(|k| f64::from(k) * 0.77).collect();
        queries.extend(pts.iter().map(|p| p.0));
        queries.extend([f64::NAN, f64::INFINITY, f64::NEG_INFINITY]);
        for s in queries {
            assert_eq!(
                first_after(&pts, s, s0, step),
                pts.partition_point(|p| p.0 <= s),
                "s = {s}"
            );
        }
    }
}

/// The four borders of a 500 Hz tone at 44.1 kHz (16 µm of displacement, their constants
/// apart), each with `extra(j)` µm on sample `j` and a standard error of 0.05 µm.
fn four_borders_on_a_tone(n: usize, extra: impl Fn(usize) -> f64) -> StitchedSignal {
    let d = |j: usize| 16.0 * (std::f64::consts::TAU * 500.0 / 44_100.0 * j as f64).sin();
    let mut channels = Vec::new();
    for c in [-90.0, -20.0, 20.0, 90.0] {
        #[allow(clippy::cast_possible_truncation)] // the stitched tracks are f32
        let y = (0..n).map(|j| (c + d(j) + extra(j)) as f32).collect();
        channels.push(y);
        channels.push(vec![0.05_f32; n]);
    }
    StitchedSignal {
        start_um: 0.0,
        spacing_um: 21.3,
        native_rate_hz: 44_100.0,
        channels,
        gaps: Vec::new(),
    }
}

#[test]
fn a_sample_all_four_borders_misplace_is_no_click_in_the_decoded_velocity() {
    // A 500 Hz tone at 44.1 kHz, 16 µm of displacement, the four borders' constants apart; at
    // sample 300 every border is 0.4 µm off, which their combination cannot see.
    let stitched = four_borders_on_a_tone(600, |j| if j == 300 { 0.4 } else { 0.0 });
    let click = |despike_sigmas: f64| {
        let params = EdgeParams {
            despike_sigmas,
            burst_sigmas: 0.0,
            ..EdgeParams::default()
        };
        let decoded = decode_border_signal(stitched.clone(), Cut::Lateral, 1.0, &params).unwrap();
        let v = &decoded.velocity.channels[0];
        // The velocity's deviation from its neighbours' mean around the spike, against the
        // same far from it.
        let bump = |j: usize| (f64::from(v[j]) - 0.5 * f64::from(v[j - 2] + v[j + 2])).abs();
        ((298..=302).map(bump).fold(0.0, f64::max), decoded.despiked)
    };
    let (kept, none) = click(0.0);
    let (taken, found) = click(EdgeParams::default().despike_sigmas);
    assert!(none.iter().all(Vec::is_empty));
    assert_eq!(found, [vec![300], vec![300]]);
    assert!(
        taken < 0.05 * kept,
        "click {taken} against {kept} without the despike"
    );
}

#[test]
fn a_five_sample_bump_all_four_borders_read_is_no_click_in_the_decoded_velocity() {
    // The same 500 Hz tone with a little jitter; at samples 300–304 every border reads a bump
    // of up to 3 µm (a flake's rim taken for the borders), within the groove's slope limit.
    let bump = |j: usize| match j {
        300..=304 => [1.0, 2.5, 3.0, 2.2, 0.8][j - 300],
        _ => 0.0,
    };
    let jitter = |j: usize| 0.02 * ((j * 7919 % 101) as f64 / 50.0 - 1.0);
    let decode = |with_bump: bool, burst_sigmas: f64| {
        let stitched =
            four_borders_on_a_tone(800, |j| jitter(j) + if with_bump { bump(j) } else { 0.0 });
        let params = EdgeParams {
            burst_sigmas,
            ..EdgeParams::default()
        };
        decode_border_signal(stitched, Cut::Lateral, 1.0, &params).unwrap()
    };
    let on = EdgeParams::default().burst_sigmas;
    let truth = decode(false, on);
    assert!(truth.bursts.iter().all(Vec::is_empty));
    // The velocity's largest distance from the bump-free track's around the bump.
    let worst = |decoded: &DecodedEdges| {
        let (v, t) = (&decoded.velocity.channels[0], &truth.velocity.channels[0]);
        (290..315)
            .map(|j| f64::from(v[j] - t[j]).abs())
            .fold(0.0, f64::max)
    };
    let peak = truth.velocity.channels[0]
        .iter()
        .fold(0.0_f32, |m, v| m.max(v.abs()));
    let kept = decode(true, 0.0);
    let taken = decode(true, on);
    assert!(kept.bursts.iter().all(Vec::is_empty));
    assert_eq!(taken.burst_samples().0, 1, "{:?}", taken.bursts);
    let (with, without) = (worst(&taken), worst(&kept));
    assert!(
        without > f64::from(peak) / 10.0,
        "the bump: {without} against a peak of {peak}"
    );
    assert!(
        with < 0.05 * without,
        "click {with} against {without} without the burst despike"
    );
}
