//! Hostile input: metadata that contradicts the scan, and files that ask for more than the limits (issue 19).

#![allow(clippy::unwrap_used)] // tests may panic

mod common;

use std::path::Path;
use std::sync::atomic::AtomicBool;

use common::{
    SCAN_TOML, demo_copy, failed_with, groovescope, scan_in_tempdir, stderr, two_shard_plan,
    write_scan,
};
use groovescope::engine::{ReconstructOptions, reconstruct};
use groovescope::io::limits::{MAX_FRAMES_PER_GROUP, MAX_TOML_BYTES, MAX_WAV_SAMPLES};
use groovescope::io::{Scan, load_frame, load_group_frames};

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Writes `text` to `params` and runs `groovescope reconstruct SCAN --params PARAMS` to `x.wav`
/// beside it: the run must fail without writing the output, in one line holding every `wanted`.
fn refused_reconstruct(scan: &Path, params: &Path, text: &str, wanted: &[&str]) {
    std::fs::write(params, text).unwrap();
    let out = params.with_file_name("x.wav");
    let o = groovescope(&[
        "reconstruct",
        s(scan),
        "--out",
        s(&out),
        "--params",
        s(params),
        "--quiet",
    ]);
    assert!(!o.status.success());
    assert!(!out.exists());
    let err = stderr(&o);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(wanted.iter().all(|w| err.contains(w)), "{err}");
}

/// Asserts that `dir` does not open as a scan, with an error holding every `wanted`.
fn refused_open(dir: &Path, wanted: &[&str]) {
    let msg = Scan::open(dir).unwrap_err().to_string();
    assert!(wanted.iter().all(|w| msg.contains(w)), "{msg}");
}

#[test]
fn a_per_group_radius_list_of_the_wrong_length_names_the_key_and_both_numbers() {
    let (_dir, scan) = scan_in_tempdir(2, 7, 32, 16);
    let spiral = |radii: &str| {
        let text = SCAN_TOML.replace(
            "cut = \"lateral\"\n",
            &format!("cut = \"lateral\"\ngroup_radius_mm = [{radii}]\n"),
        );
        std::fs::write(scan.join("scan.toml"), text).unwrap();
    };
    spiral("115.0, 114.9, 114.8");
    refused_open(
        &scan,
        &[
            "record.group_radius_mm has 3 entries but the scan has 2 groups",
            "scan.toml",
        ],
    );
    spiral("115.0");
    refused_open(&scan, &["has 1 entries"]);
    spiral("115.0, 114.9");
    let opened = Scan::open(&scan).unwrap();
    assert!((opened.meta.radius_mm(1) - 114.9).abs() < 1e-12);
}

#[test]
fn a_glass_edge_outside_the_frame_names_the_key_and_both_numbers() {
    let (_dir, scan) = scan_in_tempdir(1, 7, 32, 16);
    let dual = |row: &str| {
        let text = format!(
            "{SCAN_TOML}[dual_focus]\nfocus_distance_mm = 4.0\nglass_thickness_mm = 0.11\nglass_index = 1.515\nglass_edge_row = {row}\n"
        );
        std::fs::write(scan.join("scan.toml"), text).unwrap();
    };
    dual("40.0");
    refused_open(
        &scan,
        &[
            "dual_focus.glass_edge_row = 40",
            "last row is 15",
            "scan.toml",
        ],
    );
    dual("8.0");
    assert!(Scan::open(&scan).is_ok());
}

#[test]
fn a_group_step_longer_than_a_group_sees_names_the_key_and_both_numbers() {
    // 32 px frames of 0.39 µm less 8 px margins each side: 15 px = 5.85 µm sampled per group.
    let (dir, scan) = scan_in_tempdir(2, 7, 32, 16);
    let text = SCAN_TOML.replace("group_step_um = 4.0", "group_step_um = 460.2");
    std::fs::write(scan.join("scan.toml"), &text).unwrap();
    refused_open(&scan, &["motion.group_step_um = 460.2", "5.85"]);
    // One group has no neighbour to overlap.
    let single = write_scan(&dir.path().join("single"), 1, 7, 32, 16);
    std::fs::write(single.join("scan.toml"), &text).unwrap();
    assert!(Scan::open(&single).is_ok());
}

#[test]
fn a_frame_step_past_the_frame_width_names_the_key_and_both_numbers() {
    // 32 px frames of 0.39 µm: a 12.48 µm step moves the land the whole 32 px.
    let (_dir, scan) = scan_in_tempdir(1, 7, 32, 16);
    for step in ["12.48", "1e30"] {
        let text = SCAN_TOML.replace("frame_step_um = 0.78", &format!("frame_step_um = {step}"));
        std::fs::write(scan.join("scan.toml"), &text).unwrap();
        refused_open(&scan, &["motion.frame_step_um", "32 px", "scan.toml"]);
    }
    let text = SCAN_TOML.replace("frame_step_um = 0.78", "frame_step_um = 12.0");
    std::fs::write(scan.join("scan.toml"), &text).unwrap();
    assert!(Scan::open(&scan).is_ok());
}

#[test]
fn an_unreadable_reference_is_a_warning_naming_it_and_the_reconstruction_goes_on() {
    let dir = tempfile::tempdir().unwrap();
    let demo = demo_copy(dir.path());
    let reference = demo.join("reference.wav");
    std::fs::write(&reference, b"RIFF\x10\0\0\0WAVEjunk").unwrap();
    let opts = ReconstructOptions {
        groups: Some(0..4),
        ..ReconstructOptions::default()
    };
    // Corrupt, then a folder of that name (once skipped without a word).
    for corrupt in [true, false] {
        if !corrupt {
            std::fs::remove_file(&reference).unwrap();
            std::fs::create_dir(&reference).unwrap();
        }
        let scan = Scan::open(&demo).unwrap();
        let rec = reconstruct(&scan, &opts, &mut |_| {}, &AtomicBool::new(false)).unwrap();
        assert!(rec.scores.is_none());
        assert!(!rec.audio.is_empty());
        // The fused decoder's report names the clip's groups only (group 3's frames reach past
        // group 4's start, which once listed a group 4 that never ran).
        let fused: Vec<usize> = rec.fusion.unwrap().groups.iter().map(|g| g.group).collect();
        assert_eq!(fused, [0, 1, 2, 3]);
        common::assert_warned(
            &rec.warnings,
            &["reference not scored", "reference.wav"],
            "missing reference",
        );
    }
}

/// Writes `audio` over the WAV at `path` (16-bit).
fn replace_wav(path: &Path, audio: &groovescope::io::wav::Audio) {
    groovescope::io::wav::write_wav(path, audio, groovescope::io::wav::WavBits::Int16, true)
        .unwrap();
}

#[test]
fn a_stereo_reference_is_scored_as_its_mono_mix_and_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let demo = demo_copy(dir.path());
    let reference = demo.join("reference.wav");
    let mono = groovescope::io::wav::read_wav(&reference).unwrap();
    let stereo = groovescope::io::wav::Audio {
        channels: vec![mono.channels[0].clone(), mono.channels[0].clone()],
        ..mono.clone()
    };
    replace_wav(&reference, &stereo);
    let opts = ReconstructOptions {
        groups: Some(0..4),
        ..ReconstructOptions::default()
    };
    let scan = Scan::open(&demo).unwrap();
    let rec = reconstruct(&scan, &opts, &mut |_| {}, &AtomicBool::new(false)).unwrap();
    // Both channels the same: the mix is the mono reference, and so are the scores.
    assert!(rec.scores.is_some_and(|s| s.r > 0.9), "{:?}", rec.scores);
    common::assert_warned(
        &rec.warnings,
        &["reference.wav has 2 channels", "mono mix"],
        "stereo reference",
    );
}

#[test]
fn a_long_reference_is_scored_on_the_clip_and_a_tiny_rate_is_refused() {
    // A reference resampled whole to the clip's rate: 2^22 samples at 8 kHz is nine minutes,
    // and a few thousand samples "at 2 Hz" were hours of sound (a fuzzed scan folder hung on
    // that); only the clip's stretch is resampled now, and a rate no recording has is refused.
    let dir = tempfile::tempdir().unwrap();
    let demo = demo_copy(dir.path());
    let reference = demo.join("reference.wav");
    let write = |rate: u32, n: usize| {
        let audio = groovescope::io::wav::Audio {
            sample_rate_hz: rate,
            channels: vec![(0..n).map(|i| ((i % 7) as f32 - 3.0) / 4.0).collect()],
        };
        replace_wav(&reference, &audio);
    };
    let opts = ReconstructOptions {
        groups: Some(0..2),
        ..ReconstructOptions::default()
    };
    write(8000, 1 << 22);
    let scan = Scan::open(&demo).unwrap();
    let rec = reconstruct(&scan, &opts, &mut |_| {}, &AtomicBool::new(false)).unwrap();
    assert!(!rec.audio.is_empty());
    // What is resampled ends 10 s after the clip (the clip starts near the reference's start),
    // not nine minutes later.
    let (aligned, _) = groovescope::engine::aligned_reference(
        &rec.audio,
        &rec.stitched,
        scan.meta.groove_speed_mm_s(0),
        &reference,
    )
    .unwrap();
    let rate = f64::from(rec.audio.sample_rate_hz);
    let most = (rec.audio.duration_secs() + 11.0) * rate;
    assert!(
        (aligned.len() as f64) <= most,
        "{} samples aligned, at most {most}",
        aligned.len()
    );
    assert!(
        aligned.len() > rec.audio.channels[0].len(),
        "the clip's stretch is all there"
    );
    write(2, 4000);
    let rec = reconstruct(&scan, &opts, &mut |_| {}, &AtomicBool::new(false)).unwrap();
    assert!(rec.scores.is_none());
    common::assert_warned(
        &rec.warnings,
        &["reference not scored", "2 Hz", "reference.wav"],
        "2 Hz reference",
    );
}

/// A valid 16×12 grey PNG whose header claims `w`×`h` (its checksum fixed up).
fn png_claiming(w: u32, h: u32) -> Vec<u8> {
    let img = image::GrayImage::from_fn(16, 12, |x, y| image::Luma([(x * 7 + y) as u8]));
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png).unwrap();
    let mut png = out.into_inner();
    png[16..20].copy_from_slice(&w.to_be_bytes());
    png[20..24].copy_from_slice(&h.to_be_bytes());
    let crc = crc32fast::hash(&png[12..29]);
    png[29..33].copy_from_slice(&crc.to_be_bytes());
    png
}

#[test]
fn a_50000_by_50000_png_header_is_refused_before_decoding() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("huge.png");
    std::fs::write(&p, png_claiming(50_000, 50_000)).unwrap();
    let msg = load_frame(&p).unwrap_err().to_string();
    assert!(
        msg.contains("50000×50000") && msg.contains("16384") && msg.contains("huge.png"),
        "{msg}"
    );
    // Past the pixel limit with both sides inside the side limit.
    std::fs::write(&p, png_claiming(16_000, 16_000)).unwrap();
    let msg = load_frame(&p).unwrap_err().to_string();
    assert!(
        msg.contains("256000000 pixels") && msg.contains("67108864"),
        "{msg}"
    );
    // Outside a group's decoded window the header check refuses it too.
    let scan = write_scan(&dir.path().join("scan"), 1, 8, 32, 16);
    let frame = scan.join("g00000/f000.png");
    std::fs::write(&frame, png_claiming(50_000, 50_000)).unwrap();
    let opened = Scan::open(&scan);
    let msg = match opened {
        Ok(scan) => load_group_frames(&scan.groups[0], 1..8)
            .unwrap_err()
            .to_string(),
        Err(e) => e.to_string(),
    };
    assert!(
        msg.contains("50000×50000") && msg.contains("f000.png"),
        "{msg}"
    );
}

#[test]
fn a_wav_header_announcing_more_samples_than_the_limit_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("long.wav");
    let mut wav = Vec::new();
    wav.extend_from_slice(b"RIFF");
    wav.extend_from_slice(&u32::MAX.to_le_bytes());
    wav.extend_from_slice(b"WAVEfmt ");
    wav.extend_from_slice(&16u32.to_le_bytes());
    wav.extend_from_slice(&1u16.to_le_bytes()); // PCM
    wav.extend_from_slice(&1u16.to_le_bytes()); // mono
    wav.extend_from_slice(&48_000u32.to_le_bytes());
    wav.extend_from_slice(&96_000u32.to_le_bytes());
    wav.extend_from_slice(&2u16.to_le_bytes());
    wav.extend_from_slice(&16u16.to_le_bytes());
    wav.extend_from_slice(b"data");
    wav.extend_from_slice(&0xFFFF_FFF0u32.to_le_bytes());
    wav.extend_from_slice(&[0u8; 64]);
    std::fs::write(&p, &wav).unwrap();
    let msg = groovescope::io::wav::read_wav(&p).unwrap_err().to_string();
    assert!(
        msg.contains(&MAX_WAV_SAMPLES.to_string()) && msg.contains("long.wav"),
        "{msg}"
    );
}

#[test]
fn a_params_file_past_the_toml_limit_is_refused_naming_it() {
    let (dir, scan) = scan_in_tempdir(1, 7, 32, 16);
    let params = dir.path().join("big.toml");
    let mut text = String::from("[flow]\nlambda = 0.5\n");
    while text.len() as u64 <= MAX_TOML_BYTES {
        text += "# padding padding padding padding padding padding padding padding\n";
    }
    refused_reconstruct(
        &scan,
        &params,
        &text,
        &["big.toml", &MAX_TOML_BYTES.to_string()],
    );
}

#[test]
fn a_group_with_more_frames_than_the_limit_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("scan");
    let group = scan.join("g00000");
    std::fs::create_dir_all(&group).unwrap();
    std::fs::write(scan.join("scan.toml"), SCAN_TOML).unwrap();
    for k in 0..=MAX_FRAMES_PER_GROUP {
        std::fs::write(group.join(format!("f{k:05}.png")), b"").unwrap();
    }
    refused_open(
        &scan,
        &[
            format!("more than {MAX_FRAMES_PER_GROUP} frames").as_str(),
            "g00000",
        ],
    );
}

#[test]
fn a_hough_accumulator_past_the_limit_is_refused_before_any_group_runs() {
    let dir = tempfile::tempdir().unwrap();
    let demo = demo_copy(dir.path());
    let params = dir.path().join("fine.toml");
    refused_reconstruct(
        &demo,
        &params,
        "[hough]\ntheta_step_deg = 0.001\nrho_step_px = 0.02\n",
        &[
            "hough.theta_step_deg = 0.001",
            "67108864",
            "384-row",
            "fine.toml",
        ],
    );
}

#[test]
fn a_flow_iteration_cap_past_the_limit_is_refused_naming_the_key() {
    // Found by the monkey test: 10³⁰ typed into the iterations field became 4,294,967,295
    // iterations, and with τ = 0 the flow stage never finished.
    let (dir, scan) = scan_in_tempdir(1, 7, 32, 16);
    let params = dir.path().join("slow.toml");
    refused_reconstruct(
        &scan,
        &params,
        "[flow]\nmax_iterations = 4294967295\ntolerance_px = 0.0\n",
        &["flow.max_iterations", "4294967295", "10000", "slow.toml"],
    );
}

/// Runs the groovescope binary under a 4 GB address-space limit, so that a run that would
/// allocate without bound fails at once instead of exhausting the machine.
fn groovescope_capped(args: &[&str]) -> std::process::Output {
    std::process::Command::new("sh")
        .arg("-c")
        .arg("ulimit -v 4000000; exec \"$0\" \"$@\"")
        .arg(env!("CARGO_BIN_EXE_groovescope"))
        .args(args)
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .output()
        .unwrap()
}

#[test]
fn a_groove_speed_off_by_a_unit_is_refused_naming_the_keys_before_any_group() {
    // A radius written in metres (0.06) or a speed far too slow asked for hundreds of samples a
    // pixel: sampling the demo's 13 groups then tried to allocate 391 GB and aborted.
    let (dir, demo) = common::demo_in_tempdir();
    let meta = demo.join("scan.toml");
    let text = std::fs::read_to_string(&meta).unwrap();
    let out = dir.path().join("x.wav");
    for (key, from, to) in [
        (
            "record.radius_mm = 0.06",
            "radius_mm = 60.0",
            "radius_mm = 0.06",
        ),
        ("record.rpm = 0.001", "rpm = 16.667", "rpm = 0.001"),
    ] {
        assert!(text.contains(from), "{text}");
        std::fs::write(&meta, text.replacen(from, to, 1)).unwrap();
        for args in [
            vec!["reconstruct", s(&demo), "--out", s(&out), "--quiet"],
            vec!["plan", s(&demo), "--shards", "2", "--out", s(&out)],
            // With no probe group the plan still checks it: its shards would all fail.
            two_shard_plan(s(&demo), s(&out)).to_vec(),
        ] {
            failed_with(
                &groovescope_capped(&args),
                &[key, "samples a pixel", "scan.toml"],
            );
            assert!(!out.exists());
        }
    }
    // Past any record: refused when the scan opens, the number short.
    std::fs::write(
        &meta,
        text.replacen("radius_mm = 60.0", "radius_mm = 1e308", 1),
    )
    .unwrap();
    refused_open(
        &demo,
        &[
            "record.radius_mm must be at most 1000, got 1e308",
            "scan.toml",
        ],
    );
    // The same through the params: named as the params' key.
    std::fs::write(&meta, &text).unwrap();
    let params = dir.path().join("fine.toml");
    std::fs::write(&params, "[sound]\nnative_spacing_um = 0.001\n").unwrap();
    let args = [
        "reconstruct",
        s(&demo),
        "--out",
        s(&out),
        "--params",
        s(&params),
    ];
    failed_with(
        &groovescope_capped(&args),
        &["sound.native_spacing_um", "samples a pixel"],
    );
    assert!(!out.exists());
}

#[test]
fn the_dual_focus_path_on_a_scan_without_a_cover_glass_is_refused_before_any_group() {
    // It used to run every group, each failing in the stripe stage, then say no group made
    // sound.
    let (dir, scan) = scan_in_tempdir(3, 7, 64, 48);
    let out = dir.path().join("x.wav");
    let args = [
        "reconstruct",
        s(&scan),
        "--path",
        "dual-focus",
        "--out",
        s(&out),
    ];
    failed_with(
        &groovescope(&args),
        &["dual-focus needs a [dual_focus] table", "scan"],
    );
    assert!(!out.exists() && !dir.path().join("x.wav.journal").exists());
}
