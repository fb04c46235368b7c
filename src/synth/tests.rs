//! Tests of the rendered scans against known geometry: image motion, parallax, border rows,
//! focus stripes, determinism, errors and the reference sound.

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::AtomicBool;

use super::*;
use crate::image::Image;
use crate::io::Cut;
use crate::io::scan::Scan;
use crate::io::wav::read_wav;
use crate::job::Job;
use crate::test_support::path_in_temp_dir;

mod probes;

fn silence(secs: f64) -> Audio {
    Audio {
        sample_rate_hz: 48_000,
        channels: vec![vec![0.0; (secs * 48_000.0) as usize]],
    }
}

fn clean(cfg: SynthConfig) -> SynthConfig {
    SynthConfig {
        noise_sigma_8bit: 0.0,
        bit_depth: 16,
        ..cfg
    }
}

/// Catmull-Rom sample of row `y` of `img` at fractional column `x`.
fn cubic(img: &Image, x: f64, y: usize) -> f64 {
    let i = x.floor() as isize;
    let t = x - i as f64;
    let p = |k: isize| f64::from(img.clamped(i + k, y as isize));
    let (p0, p1, p2, p3) = (p(-1), p(0), p(1), p(2));
    p1 + 0.5
        * t
        * (p2 - p0 + t * (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3 + t * (3.0 * (p1 - p2) + p3 - p0)))
}

/// Global horizontal shift δ with b(x) ≈ a(x + δ) over `rows` × `cols`: the mean of the
/// forward and backward Gauss–Newton estimates, which cancels the interpolation bias.
fn shift_between(
    a: &Image,
    b: &Image,
    rows: std::ops::Range<usize>,
    cols: std::ops::Range<usize>,
) -> f64 {
    // Gauss–Newton for δ with `to(x) ≈ from(x + δ)` over `rows` × `cols`.
    let one_way = |from: &Image, to: &Image, cols: std::ops::Range<usize>| {
        let mut delta = 0.0;
        for _ in 0..20 {
            let (mut num, mut den) = (0.0, 0.0);
            for y in rows.clone() {
                for x in cols.clone() {
                    let xf = x as f64 + delta;
                    let g = 0.5 * (cubic(from, xf + 1.0, y) - cubic(from, xf - 1.0, y));
                    let r = f64::from(to.get(x, y).unwrap()) - cubic(from, xf, y);
                    num += g * r;
                    den += g * g;
                }
            }
            let step = num / den;
            delta += step;
            if step.abs() < 1e-7 {
                break;
            }
        }
        delta
    };
    let forward = one_way(a, b, cols.clone());
    let back_cols = (cols.start + 3)..(cols.end + 3).min(a.width);
    let backward = one_way(b, a, back_cols);
    0.5 * (forward - backward)
}

/// Asserts that rows 0..25 (land) of `b` are those of `a` moved by `shift_px` toward −x, to
/// within one 16-bit step.
fn assert_land_moved(a: &Image, b: &Image, shift_px: usize) {
    for y in 0..25 {
        for x in 0..250 {
            let (va, vb) = (a.get(x + shift_px, y).unwrap(), b.get(x, y).unwrap());
            assert!(
                (va - vb).abs() <= 1.0 / 65_535.0 + 1e-7,
                "({x},{y}) {va} {vb}"
            );
        }
    }
}

#[test]
fn flat_land_moves_by_frame_step_over_pitch() {
    let cfg = clean(SynthConfig::quick_test());
    let g = Groove::new(&tone(1000.0, 0.01, 48_000), &cfg).unwrap();
    let (a, b) = (g.render_frame(0, 3), g.render_frame(0, 4));
    // Rows 0..25 are land (the groove's edge is ≥ 13 µm = 33 px away); 0.78/0.39 = 2 px exactly.
    assert_land_moved(&a, &b, 2);
    assert!(a.data != b.data);
    // A non-integer step: 0.52 µm = 4/3 px, so frame 3 is frame 0 moved by exactly 4 px, and
    // the sub-pixel shift of one frame is 1.333 px (a coarse texture keeps the cubic
    // interpolation of the estimator nearly unbiased).
    let cfg = SynthConfig {
        frame_step_um: 0.52,
        texture_scale_um: 8.0,
        ..cfg
    };
    let g = Groove::new(&tone(1000.0, 0.01, 48_000), &cfg).unwrap();
    let (f0, f1, f3) = (
        g.render_frame(0, 0),
        g.render_frame(0, 1),
        g.render_frame(0, 3),
    );
    assert_land_moved(&f0, &f3, 4);
    let d = shift_between(&f0, &f1, 0..25, 10..240);
    assert!((d - 0.52 / 0.39).abs() < 0.002, "{d}");
}

#[test]
fn deeper_surfaces_move_less_parallax() {
    let cfg = clean(SynthConfig {
        texture_scale_um: 8.0,
        ..SynthConfig::quick_test()
    });
    let g = Groove::new(&silence(0.01), &cfg).unwrap();
    let (a, b) = (g.render_frame(0, 5), g.render_frame(0, 6));
    let land = shift_between(&a, &b, 0..25, 10..240);
    // The flat bottom is 20 µm wide at 35 µm depth: rows cy ± 20 are bottom.
    let bottom = shift_between(&a, &b, 140..180, 10..240);
    let want = 2.0 * 4000.0 / 4035.0;
    assert!((land - 2.0).abs() < 1e-3, "{land}");
    assert!((bottom - want).abs() < 0.002, "{bottom} vs {want}");
}

#[derive(Debug, PartialEq, Clone, Copy)]
enum Class {
    Land,
    Wall,
    Bottom,
}

#[test]
fn a_constant_velocity_groove_puts_its_borders_where_geometry_says() {
    // Square wave: +1 then −1, so the velocity is +peak over the first half (a straight,
    // slanted groove: d(s) = d(0) + (V/Vt)·s).
    let mut samples = vec![1.0f32; 480];
    samples.extend(vec![-1.0f32; 480]);
    let sound = Audio {
        sample_rate_hz: 48_000,
        channels: vec![samples],
    };
    let cfg = SynthConfig {
        texture_contrast: 0.0,
        noise_sigma_8bit: 0.0,
        bit_depth: 8,
        ..SynthConfig::quick_test()
    };
    let g = Groove::new(&sound, &cfg).unwrap();
    let slope = 20.0 / (std::f64::consts::TAU * 78.0 / 60.0 * 115.0);
    let d0 = g.truth(0.0).displacement_um;
    for s in [10.0, 100.0, 200.0] {
        let d = g.truth(s).displacement_um;
        assert!((d - d0 - slope * s).abs() < 1e-9, "{s}: {d}");
    }
    let (p, wd, t, flat) = (0.39, 4000.0, 45.0, 10.0);
    let (cx, cy) = (127.5, 159.5);
    let classify = |v: f32| {
        let v = f64::from(v);
        let near = |l: f64| (v - l).abs() < 0.6 / 255.0;
        if near(0.15) {
            Class::Land
        } else if near(0.75) {
            Class::Wall
        } else if near(0.10) {
            Class::Bottom
        } else {
            panic!("unexpected grey {v}")
        }
    };
    let img = g.render_frame(1, 4);
    let cam_s = g.land_s_um(1, 4, cx);
    let mut walls_seen = 0;
    for x in [0usize, 60, 128, 255] {
        let s_land = cam_s + (x as f64 - cx) * p;
        let z_bottom = wd + 35.0;
        let s_bottom = cam_s + (x as f64 - cx) * p * z_bottom / wd;
        let d_land = d0 + slope * s_land;
        let d_bottom = d0 + slope * s_bottom;
        // Row boundaries: land ≤ r1 < wall < r2 ≤ bottom ≤ r3 < wall < r4 ≤ land.
        let r1 = cy + (d_land - t) / p;
        let r2 = cy + (d_bottom - flat) * wd / (p * z_bottom);
        let r3 = cy + (d_bottom + flat) * wd / (p * z_bottom);
        let r4 = cy + (d_land + t) / p;
        for r in 0..320usize {
            let rf = r as f64;
            if [r1, r2, r3, r4].iter().any(|b| (rf - b).abs() < 1e-3) {
                continue;
            }
            let want = if rf <= r1 || rf >= r4 {
                Class::Land
            } else if rf >= r2 && rf <= r3 {
                Class::Bottom
            } else {
                Class::Wall
            };
            let got = classify(img.get(x, r).unwrap());
            assert_eq!(
                got, want,
                "column {x}, row {r}: borders {r1:.3} {r2:.3} {r3:.3} {r4:.3}"
            );
            walls_seen += usize::from(got == Class::Wall);
        }
    }
    assert!(walls_seen > 4 * 150, "{walls_seen}");
}

#[test]
fn dual_focus_shows_three_sharp_stripes_where_expected() {
    let cfg = SynthConfig {
        width_px: 96,
        height_px: 700,
        group_overlap_px: 10,
        noise_sigma_8bit: 0.0,
        ..SynthConfig::dual_focus_demo()
    };
    let g = Groove::new(&silence(0.01), &cfg).unwrap();
    let edge = g.optics().glass_edge_row.unwrap();
    let img = g.render_frame(0, 0);
    // Row sharpness: mean |horizontal difference|.
    let sharp: Vec<f64> = (0..700)
        .map(|y| {
            let r = img.row(y);
            r.windows(2)
                .map(|w| f64::from((w[1] - w[0]).abs()))
                .sum::<f64>()
                / 95.0
        })
        .collect();
    let (wd, p, cy, t) = (3970.0, 0.39, 349.5, 120.0);
    let (z1, z2) = (30.0, 30.0 + 110.0 * (1.0 - 1.0 / 1.515));
    // Under the glass a record point at y appears at row cy + y·WD/(p·Zf) (paraxial).
    let left_glass = cy + (-t + z2) * wd / (p * 4000.0);
    let right_glass = cy + (t - z2) * wd / (p * 4000.0);
    let right_plain = cy + (t - z1) * wd / (p * (wd + z1));
    assert!(
        right_glass < edge && edge < right_plain,
        "{right_glass} {edge} {right_plain}"
    );
    let peak_near = |row: f64| {
        let lo = (row - 6.0) as usize;
        (lo..lo + 13).map(|y| sharp[y]).fold(0.0f64, f64::max)
    };
    if std::env::var("SYNTH_DEBUG").is_ok() {
        let z = g.render_frame_detail(0, 0);
        for y in (0..700).step_by(4) {
            eprintln!(
                "{y} {:.4} z={:.1} sigma={:.2}",
                sharp[y],
                z.z_um.get(40, y).unwrap(),
                z.blur_sigma_px.get(40, y).unwrap()
            );
        }
        eprintln!("edge {edge} {left_glass} {right_glass} {right_plain}");
    }
    let background = sharp.iter().copied().fold(0.0f64, |m, v| m.max(v)) * 0.1;
    for (name, row) in [
        ("left/glass", left_glass),
        ("right/glass", right_glass),
        ("right/plain", right_plain),
    ] {
        let pk = peak_near(row);
        assert!(
            pk > 0.5 * sharp.iter().copied().fold(0.0f64, f64::max),
            "{name} at {row:.1}: {pk}"
        );
        // Away from the stripe (25–50 rows) the wall is blurred.
        let away = ((row + 25.0) as usize..(row + 50.0) as usize)
            .filter(|&y| (y as f64 - edge).abs() > 3.0)
            .map(|y| sharp[y])
            .fold(0.0f64, f64::max);
        assert!(away < 0.35 * pk, "{name}: {away} vs {pk}");
    }
    // The land, far from every focal plane, has nearly no gradient.
    assert!(sharp[5] < background, "{} {background}", sharp[5]);
}

fn files_of(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                let rel = p.strip_prefix(dir).unwrap().to_string_lossy().into_owned();
                out.push((rel, std::fs::read(&p).unwrap()));
            }
        }
    }
    out.sort();
    out
}

/// `sound` rendered with `cfg` (reporting to `job`) as the scan `scan` of a fresh temporary
/// folder, which lives as long as the returned guard: the guard, the scan and what was written.
fn scan_in_temp_dir(
    sound: &Audio,
    cfg: &SynthConfig,
    job: Job<'_>,
) -> (tempfile::TempDir, PathBuf, SynthSummary) {
    let (dir, out) = path_in_temp_dir("scan");
    let sum = render_scan(sound, cfg, &out, job).unwrap();
    (dir, out, sum)
}

fn tiny_damaged() -> SynthConfig {
    SynthConfig {
        width_px: 96,
        group_overlap_px: 10,
        frames_per_group: 7,
        noise_sigma_8bit: 2.0,
        max_groups: Some(2),
        damage: DamageConfig {
            scratches_per_mm: 20.0,
            dust_per_mm2: 2000.0,
            missing_wall_chunks_per_mm: 10.0,
            chunk_length_um: 30.0,
            ..DamageConfig::default()
        },
        ..SynthConfig::quick_test()
    }
}

#[test]
fn scans_are_deterministic_and_seeds_matter() {
    let dir = tempfile::tempdir().unwrap();
    let sound = tone(440.0, 0.01, 44_100);
    let cfg = tiny_damaged();
    for name in ["a", "b"] {
        render_scan(&sound, &cfg, &dir.path().join(name), Job::unwatched()).unwrap();
    }
    let (a, b) = (
        files_of(&dir.path().join("a")),
        files_of(&dir.path().join("b")),
    );
    assert_eq!(a.len(), 2 * 7 + 2);
    assert_eq!(a, b);
    let other = SynthConfig { seed: 2, ..cfg };
    let g = Groove::new(&sound, &other).unwrap();
    let f = g.render_frame(0, 0);
    let g0 = Groove::new(&sound, &tiny_damaged()).unwrap();
    assert_ne!(f, g0.render_frame(0, 0));
    assert!(g0.damage_features() > 3);
}

#[test]
fn scan_folder_loads_and_reference_matches_the_scanned_length() {
    let sound = tone(1000.0, 0.02, 44_100);
    let calls = Mutex::new(Vec::new());
    let progress = |d: usize, t: usize| calls.lock().unwrap().push((d, t));
    let cfg = SynthConfig {
        max_groups: Some(3),
        frames_per_group: 7,
        ..SynthConfig::quick_test()
    };
    let (_dir, out, sum) = scan_in_temp_dir(&sound, &cfg, Job::reporting(&progress));
    assert_eq!(*calls.lock().unwrap(), vec![(0, 3), (1, 3), (2, 3), (3, 3)]);
    let scan = Scan::open(&out).unwrap();
    assert_eq!(scan.groups.len(), 3);
    assert_eq!(scan.groups[0].frame_count(), 7);
    assert!((scan.meta.motion.group_step_um - 216.0 * 0.39).abs() < 1e-9);
    let back: SynthConfig = scan.meta.extra["synth"].clone().try_into().unwrap();
    assert_eq!(back, cfg);
    let vt = scan.meta.groove_speed_mm_s(0) * 1000.0;
    let length = 2.0 * 216.0 * 0.39 + 256.0 * 0.39 + 6.0 * 0.78;
    assert!((sum.scan_length_um - length).abs() < 1e-9);
    let reference = read_wav(scan.reference.as_ref().unwrap()).unwrap();
    assert_eq!(reference.sample_rate_hz, 44_100);
    assert_eq!(reference.channels.len(), 1);
    let want = (length / vt * 44_100.0).floor() as usize + 1;
    assert_eq!(reference.len(), want);
    assert!((reference.duration_secs() - length / vt).abs() <= 1.0 / 44_100.0);
    // Samples are the cutter velocity over the peak: the tone at full scale.
    for (i, v) in reference.channels[0].iter().enumerate() {
        let want = (std::f64::consts::TAU * 1000.0 * i as f64 / 44_100.0).sin();
        assert!((f64::from(*v) - want).abs() < 2e-3, "{i}");
    }
    let frame = crate::io::load_frame(&scan.groups[1].frame_path(2).unwrap()).unwrap();
    let g = Groove::new(&sound, &cfg).unwrap();
    assert_eq!(frame, g.render_frame(1, 2));
}

#[test]
fn errors_name_the_problem_and_nothing_is_overwritten() {
    let dir = tempfile::tempdir().unwrap();
    let sound = tone(1000.0, 0.01, 44_100);
    let busy = dir.path().join("busy");
    std::fs::create_dir(&busy).unwrap();
    std::fs::write(busy.join("keep.txt"), b"mine").unwrap();
    let e = render_scan(&sound, &SynthConfig::quick_test(), &busy, Job::unwatched()).unwrap_err();
    assert!(matches!(e, SynthError::OutputExists { .. }), "{e}");
    assert_eq!(files_of(&busy).len(), 1);
    let bad = SynthConfig {
        frame_step_um: -1.0,
        ..SynthConfig::quick_test()
    };
    let e = render_scan(&sound, &bad, &dir.path().join("x"), Job::unwatched()).unwrap_err();
    assert!(e.to_string().contains("synth.frame_step_um"), "{e}");
    assert!(!dir.path().join("x").exists());
    let not_wav = dir.path().join("song.wav");
    std::fs::write(&not_wav, b"RIFF but not really").unwrap();
    // The quick-test scan of the sound in `wav`, to `out`: refused.
    let refused_wav = |wav: &Path, out: &str| {
        Groove::from_wav(wav, &SynthConfig::quick_test())
            .and_then(|groove| write_scan(&groove, &dir.path().join(out), Job::unwatched()))
            .unwrap_err()
    };
    let e = refused_wav(&not_wav, "y");
    assert!(e.to_string().contains("song.wav"), "{e}");
    let short = dir.path().join("short.wav");
    crate::io::wav::write_wav(
        &short,
        &tone(1000.0, 0.00004, 44_100),
        crate::io::wav::WavBits::Int16,
        false,
    )
    .unwrap();
    let e = refused_wav(&short, "z");
    let msg = e.to_string();
    assert!(
        msg.contains("too short") && msg.contains("short.wav"),
        "{msg}"
    );
    // Cancelled: the new folder is gone again, and an empty one is left empty.
    let c = dir.path().join("cancelled");
    let e = render_scan(
        &sound,
        &SynthConfig::quick_test(),
        &c,
        Job::new(&|_, _| {}, &AtomicBool::new(true)),
    )
    .unwrap_err();
    assert!(matches!(e, SynthError::Cancelled));
    assert!(!c.exists());
    std::fs::create_dir(&c).unwrap();
    let cancel_later = AtomicBool::new(false);
    let e = render_scan(
        &sound,
        &SynthConfig::quick_test(),
        &c,
        Job::new(
            &|done, _| {
                if done == 1 {
                    // Mid-run the output folder holds nothing (a run killed now would leave
                    // no half scan there): the groups go into a hidden folder beside it.
                    assert_eq!(std::fs::read_dir(&c).unwrap().count(), 0);
                    let staged = format!(".cancelled.synth-{}.tmp", std::process::id());
                    assert!(dir.path().join(staged).join("g00000").is_dir());
                    cancel_later.store(true, std::sync::atomic::Ordering::Relaxed);
                }
            },
            &cancel_later,
        ),
    )
    .unwrap_err();
    assert!(matches!(e, SynthError::Cancelled));
    assert_eq!(std::fs::read_dir(&c).unwrap().count(), 0, "untouched");
    let left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().ends_with(".tmp"))
        .collect();
    assert!(left.is_empty(), "{left:?}");
}

#[test]
fn stereo_and_vertical_scans_write_their_channels() {
    let s = stereo(&tone(500.0, 0.01, 44_100), &tone(800.0, 0.01, 44_100));
    let cfg = SynthConfig {
        cut: Cut::Stereo,
        max_groups: Some(1),
        frames_per_group: 7,
        ..SynthConfig::quick_test()
    };
    let (_dir, out, _) = scan_in_temp_dir(&s, &cfg, Job::unwatched());
    let r = read_wav(&out.join("reference.wav")).unwrap();
    assert_eq!(r.channels.len(), 2);
    let scan = Scan::open(&out).unwrap();
    assert_eq!(scan.meta.record.cut, Cut::Stereo);
    let v = SynthConfig {
        cut: Cut::Vertical,
        ..cfg
    };
    let g = Groove::new(&tone(500.0, 0.01, 44_100), &v).unwrap();
    let t = g.truth(40.0);
    assert_eq!(t.lateral_velocity_mm_s, 0.0);
    assert!((t.left_tan_theta + t.right_tan_theta).abs() < 1e-12);
}

#[test]
fn dual_focus_scan_metadata_and_a_missing_chunk_render_dark() {
    let cfg = SynthConfig {
        width_px: 64,
        height_px: 700,
        group_overlap_px: 8,
        frames_per_group: 7,
        max_groups: Some(1),
        ..SynthConfig::dual_focus_fig20()
    };
    let (_dir, out, sum) = scan_in_temp_dir(&silence(0.01), &cfg, Job::unwatched());
    let text = std::fs::read_to_string(out.join("scan.toml")).unwrap();
    if std::env::var("SYNTH_DEBUG").is_ok() {
        eprintln!("{text}");
    }
    let scan = Scan::open(&out).unwrap();
    let df = scan.meta.dual_focus.as_ref().unwrap();
    assert_eq!(df.glass_side, crate::io::scan::GlassSide::Top);
    assert_eq!(Some(df.glass_edge_row), sum.glass_edge_row);
    assert!((df.focal_distances_mm().1 - 4.037).abs() < 0.001);
    assert!(scan.meta.extra.contains_key("synth_info"));

    // The preset's chunk removes the upper part of the right wall over a stretch: compare a
    // sharp, texture-free render inside and outside it.
    let chunk = &cfg.damage.chunks[0];
    let flat = SynthConfig {
        numerical_aperture: 0.0,
        dual_focus: None,
        texture_contrast: 0.0,
        noise_sigma_8bit: 0.0,
        max_groups: None,
        ..cfg.clone()
    };
    let g = Groove::new(&silence(0.01), &flat).unwrap();
    let group_of = |s: f64| (s / flat.group_step_um()).floor() as usize;
    let inside = group_of(chunk.start_um + 0.5 * chunk.length_um);
    let outside = group_of(chunk.start_um + chunk.length_um + 100.0);
    let (a, b) = (g.render_frame(inside, 0), g.render_frame(outside, 0));
    // Right wall 20 µm below the land (fraction 0.45 of 100 µm reaches 45 µm): row of y = 100 µm.
    let row = (349.5 + 100.0 * 3970.0 / (0.39 * 3990.0)) as usize;
    let (mean_in, mean_out) = (
        a.row(row).iter().sum::<f32>() / 64.0,
        b.row(row).iter().sum::<f32>() / 64.0,
    );
    assert!(mean_out > 0.7 && mean_in < 0.2, "{mean_in} {mean_out}");
}

#[test]
fn a_stereo_sound_for_a_one_channel_cut_is_mixed_and_said() {
    let mono = tone(1000.0, 0.01, 48_000);
    let stereo = Audio {
        channels: vec![mono.channels[0].clone(), mono.channels[0].clone()],
        ..mono.clone()
    };
    let lateral = SynthConfig {
        cut: Cut::Lateral,
        ..SynthConfig::quick_test()
    };
    let said = |g: &Groove| g.warnings().iter().any(|w| w.contains("2 channels"));
    let g = Groove::new(&stereo, &lateral).unwrap();
    assert!(said(&g), "{:?}", g.warnings());
    assert_eq!(g.reference().channels.len(), 1);
    assert!(!said(&Groove::new(&mono, &lateral).unwrap()));
    let stereo_cut = SynthConfig {
        cut: Cut::Stereo,
        ..lateral
    };
    assert!(!said(&Groove::new(&stereo, &stereo_cut).unwrap()));
}
