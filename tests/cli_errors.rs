//! Bad input through the CLI: one clear line naming the file and the problem, a failing exit code, no partial output.
#![allow(clippy::unwrap_used)] // tests may panic

mod common;

use common::{SCAN_TOML, groovescope, scan_in_tempdir, stderr, write_scan};

fn s(p: &std::path::Path) -> &str {
    p.to_str().unwrap()
}

/// Runs the command, which must succeed and say `part` on standard error.
fn succeeded_saying(args: &[&str], part: &str) -> std::process::Output {
    let out = groovescope(args);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains(part), "{}", stderr(&out));
    out
}

#[test]
fn params_prints_toml_that_parses_back() {
    let out = groovescope(&["params"]);
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    let parsed = groovescope::pipeline::PipelineParams::from_toml_str(&text).unwrap();
    assert_eq!(parsed, groovescope::pipeline::PipelineParams::default());
    assert!(text.contains("lambda"));
}

/// Standard output that cannot be written is one line, never a panic: a full disk under `>`
/// is an error naming standard output; a reader that went away (`| head`) is none, and the
/// transfer is written all the same. A full standard error loses its lines, never a panic.
#[test]
fn standard_output_full_or_closed_is_no_panic() {
    use std::process::{Command, Stdio};
    let run = |args: &[&str], stdout: Stdio| {
        Command::new(env!("CARGO_BIN_EXE_groovescope"))
            .args(args)
            .stdout(stdout)
            .output()
            .unwrap()
    };
    let full = || Stdio::from(std::fs::File::create("/dev/full").unwrap());
    let o = run(&["params"], full());
    assert!(!o.status.success());
    assert_eq!(
        stderr(&o).trim(),
        "error: cannot write to standard output: No space left on device (os error 28)"
    );
    let dir = tempfile::tempdir().unwrap();
    let demo = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/demo");
    let wav = dir.path().join("o.wav");
    // The pipe's reader is gone before the command starts, so every write meets EPIPE.
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    let o = run(
        &["reconstruct", s(&demo), "--out", s(&wav)],
        Stdio::from(writer),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!stderr(&o).contains("panicked") && wav.is_file());
    // Standard error full: the error line is lost, the exit status still says it (101 was a
    // panic on the write).
    let o = Command::new(env!("CARGO_BIN_EXE_groovescope"))
        .args(["eval", s(&dir.path().join("none.wav")), s(&wav)])
        .stderr(full())
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
}

#[test]
fn missing_scan_folder_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("nope");
    let wav = dir.path().join("o.wav");
    let out = groovescope(&["reconstruct", s(&scan), "--out", s(&wav), "--quiet"]);
    assert!(!out.status.success());
    let err = stderr(&out);
    assert!(
        err.contains("nope") && err.contains("no such folder"),
        "{err}"
    );
    assert!(!wav.exists());
}

#[test]
fn missing_metadata_key_names_key_and_file() {
    let (dir, scan) = scan_in_tempdir(1, 7, 32, 16);
    std::fs::write(
        scan.join("scan.toml"),
        SCAN_TOML.replace("rpm = 78.0\n", ""),
    )
    .unwrap();
    let wav = dir.path().join("o.wav");
    let out = groovescope(&["reconstruct", s(&scan), "--out", s(&wav), "--quiet"]);
    assert!(!out.status.success());
    let err = stderr(&out);
    assert!(err.contains("rpm") && err.contains("scan.toml"), "{err}");
    assert_eq!(err.lines().count(), 1, "one line: {err}");
    assert!(!wav.exists());
}

#[test]
fn nan_parameter_names_key_and_file() {
    let (dir, scan) = scan_in_tempdir(1, 7, 32, 16);
    let wav = dir.path().join("o.wav");
    // (params file, its text, what the error must name)
    for (name, text, wanted) in [
        (
            "p.toml",
            "[flow]\nlambda = nan\n",
            &["flow.lambda", "p.toml"][..],
        ),
        (
            "n.toml",
            "[orientation]\nsigma_start_um = -1.0\n",
            &["orientation.sigma_start_um"],
        ),
        ("u.toml", "[flow]\nlamda = 1.0\n", &["lamda"]),
        // Valid alone, too fine for this scan's pixels: checked once the scan is open.
        (
            "fine.toml",
            "[sound]\nnative_spacing_um = 0.00001\n",
            &["sound.native_spacing_um", "fine.toml"],
        ),
    ] {
        let params = dir.path().join(name);
        std::fs::write(&params, text).unwrap();
        let out = groovescope(&[
            "reconstruct",
            s(&scan),
            "--out",
            s(&wav),
            "--params",
            s(&params),
            "--quiet",
        ]);
        assert!(!out.status.success(), "{name}");
        let err = stderr(&out);
        assert!(wanted.iter().all(|w| err.contains(w)), "{name}: {err}");
    }
    assert!(!wav.exists());
}

#[test]
fn corrupt_frame_is_named() {
    let (dir, scan) = scan_in_tempdir(2, 7, 32, 16);
    let bad = scan.join("g00001").join("f003.png");
    std::fs::write(&bad, b"\x89PNG garbage").unwrap();
    let wav = dir.path().join("o.wav");
    let out = groovescope(&["reconstruct", s(&scan), "--out", s(&wav), "--quiet"]);
    assert!(!out.status.success());
    let err = stderr(&out);
    assert!(err.contains("f003.png") && err.contains("g00001"), "{err}");
    assert!(!wav.exists(), "no partial output");
}

#[test]
fn mixed_sizes_and_too_few_frames_are_named() {
    let (dir, scan) = scan_in_tempdir(1, 7, 32, 16);
    let odd = groovescope::image::Image::filled(20, 16, 0.5);
    let p = scan.join("g00000").join("f006.png");
    std::fs::remove_file(&p).unwrap();
    groovescope::io::save_grey_png(&odd, &p, false, false).unwrap();
    let wav = dir.path().join("o.wav");
    let out = groovescope(&["reconstruct", s(&scan), "--out", s(&wav), "--quiet"]);
    let err = stderr(&out);
    assert!(
        !out.status.success() && err.contains("f006.png") && err.contains("20x16"),
        "{err}"
    );

    let few = write_scan(&dir.path().join("few"), 1, 5, 32, 16);
    let out = groovescope(&["reconstruct", s(&few), "--out", s(&wav), "--quiet"]);
    let err = stderr(&out);
    assert!(
        !out.status.success() && err.contains("5 frames") && err.contains("g00000"),
        "{err}"
    );
}

#[test]
fn empty_scan_and_not_a_scan() {
    let dir = tempfile::tempdir().unwrap();
    // A scan.toml and no group folder.
    let empty = write_scan(&dir.path().join("empty"), 0, 0, 0, 0);
    let wav = dir.path().join("o.wav");
    let out = groovescope(&["reconstruct", s(&empty), "--out", s(&wav), "--quiet"]);
    assert!(
        stderr(&out).contains("no group folders"),
        "{}",
        stderr(&out)
    );
    let plain = dir.path().join("plain");
    std::fs::create_dir_all(&plain).unwrap();
    let out = groovescope(&["reconstruct", s(&plain), "--out", s(&wav), "--quiet"]);
    assert!(
        stderr(&out).contains("scan.toml is missing"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn existing_output_is_never_overwritten_without_force() {
    let (dir, scan) = scan_in_tempdir(1, 7, 32, 16);
    let wav = dir.path().join("keep.wav");
    std::fs::write(&wav, b"precious").unwrap();
    let out = groovescope(&["reconstruct", s(&scan), "--out", s(&wav), "--quiet"]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("keep.wav") && stderr(&out).contains("--force"));
    assert_eq!(std::fs::read(&wav).unwrap(), b"precious");
}

#[test]
fn eval_rejects_non_wav() {
    let dir = tempfile::tempdir().unwrap();
    let a = dir.path().join("a.wav");
    std::fs::write(&a, b"RIFFjunk").unwrap();
    let out = groovescope(&["eval", s(&a), s(&a)]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("a.wav"), "{}", stderr(&out));
}

/// Sounds further apart than the ±5 ms searched score as noise: `eval` says so and names
/// `--max-lag-ms`, with which they score as the same sound.
#[test]
fn eval_says_when_the_sounds_may_lie_further_apart_than_it_searched() {
    let dir = tempfile::tempdir().unwrap();
    // A chirp-like signal with no period the search could mistake for a lag.
    let x: Vec<f32> = (0..44_100)
        .map(|i| (i as f32 * i as f32 * 1e-6).sin() * 0.4)
        .collect();
    let late: Vec<f32> = std::iter::repeat_n(0.0, 5000).chain(x.clone()).collect();
    let (a, b) = (dir.path().join("ref.wav"), dir.path().join("late.wav"));
    common::write_raw_wav(&a, 44_100, &x);
    common::write_raw_wav(&b, 44_100, &late[..44_100]);
    succeeded_saying(&["eval", s(&b), s(&a)], "--max-lag-ms looks further");
    let o = groovescope(&["eval", s(&b), s(&a), "--max-lag-ms", "200"]);
    assert!(!stderr(&o).contains("warning"), "{}", stderr(&o));
    let said = String::from_utf8_lossy(&o.stdout);
    assert!(said.contains("r            1.0000"), "{said}");
}

#[test]
fn eval_scores_stereo_per_channel_and_refuses_nan_samples() {
    use groovescope::io::wav::{Audio, WavBits, write_wav};
    let dir = tempfile::tempdir().unwrap();
    let sine: Vec<f32> = (0..22_050)
        .map(|i| (i as f32 * 0.0713).sin() * (1.0 + (i as f32 * 0.0004).sin()) * 0.4)
        .collect();
    let minus: Vec<f32> = sine.iter().map(|v| -v).collect();
    // Left = −right: mixed to mono this pair is silence.
    let pair = dir.path().join("pair.wav");
    let audio = Audio {
        sample_rate_hz: 44_100,
        channels: vec![sine.clone(), minus],
    };
    write_wav(&pair, &audio, WavBits::Float32, false).unwrap();
    let out = groovescope(&["eval", s(&pair), s(&pair), "--json"]);
    assert!(out.status.success(), "{}", stderr(&out));
    // One object whatever the channels (a stereo pair's scores came as a bare array).
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let channels = json["channels"].as_array().unwrap();
    assert_eq!(channels.len(), 2);
    assert!(
        channels.iter().all(|c| c["r"].as_f64().unwrap() > 0.9999),
        "{json}"
    );
    assert!(
        json["r"].is_null() && json["mixed_to_mono"] == false,
        "{json}"
    );
    // Channels that do not pair up are mixed, and it says so.
    let mono = dir.path().join("mono.wav");
    common::write_raw_wav(&mono, 44_100, &sine);
    // Mono: the one pair's scores at the top level as before, and in `channels`.
    let out = groovescope(&["eval", s(&mono), s(&mono), "--json"]);
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json["channels"].as_array().unwrap().len(), 1, "{json}");
    assert_eq!(json["samples"], json["channels"][0]["samples"], "{json}");
    assert!(json["r"].as_f64().unwrap() > 0.9999, "{json}");
    let out = groovescope(&["eval", s(&pair), s(&mono), "--json"]);
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(json["mixed_to_mono"] == true && json["channels"].as_array().unwrap().len() == 1);
    let o = succeeded_saying(
        &["eval", s(&pair), s(&mono)],
        "2 channels and the reference 1: scored as their mono mixes",
    );
    // ... which cancel: that is said, not a lag to look further for.
    let err = stderr(&o);
    assert!(
        err.contains("the mono mix of its channels is silent (they cancel): ")
            && err.contains("pair.wav")
            && !err.contains("--max-lag-ms"),
        "{err}"
    );
    let silent = dir.path().join("silent.wav");
    common::write_raw_wav(&silent, 44_100, &vec![0.0; 22_050]);
    succeeded_saying(
        &["eval", s(&silent), s(&mono)],
        "nothing to score: it is silent: ",
    );
    let mut bad = sine;
    bad[100] = f32::NAN;
    let nan = dir.path().join("nan.wav");
    common::write_raw_wav(&nan, 44_100, &bad);
    let out = groovescope(&["eval", s(&nan), s(&pair)]);
    assert!(!out.status.success());
    let err = stderr(&out);
    assert!(err.contains("NaN") && err.contains("nan.wav"), "{err}");
}

#[test]
fn a_land_flow_past_the_frame_is_named_not_silently_zero() {
    let dir = tempfile::tempdir().unwrap();
    let group = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/demo/g00000");
    let mut args: Vec<String> = vec!["flow".into()];
    args.extend((0..7).map(|k| s(&group.join(format!("f{k:03}.png"))).to_string()));
    let out = dir.path().join("x.flo");
    args.extend([
        "--out".into(),
        s(&out).into(),
        "--land-flow-px".into(),
        "1e30".into(),
    ]);
    let run = groovescope(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(!run.status.success());
    let err = stderr(&run);
    assert!(
        err.contains("land_flow_px: 1.0e30 px per frame") && err.contains("320 px wide"),
        "{err}"
    );
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(!out.exists());
}

#[test]
fn a_config_key_of_the_wrong_name_type_or_range_is_named_with_its_file() {
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&[&str], &str, &str); 8] = [
        (
            &["synth", "--tone", "440"],
            "[synth]\n# a test\nwidth_px = 64\nheight_pxx = 9\n",
            "synth.height_pxx (line 4): unknown field `height_pxx`",
        ),
        (
            &["synth", "--tone", "440"],
            "[synth]\nwidth_px = \"wide\"\n",
            "synth.width_px (line 2): invalid type: string \"wide\"",
        ),
        (
            &["synth-scene", "cube"],
            "frames = 30\nkind = \"cube\"\n",
            "kind (line 2): unknown field `kind`",
        ),
        // A key above the table was dropped unread (the preset's seed used, no word said).
        (
            &["synth", "--tone", "440"],
            "seed = 3\n[synth]\nwidth_px = 64\n",
            "`seed` (line 1) is outside the [synth] table",
        ),
        (
            &["synth-still"],
            "# mine\nseed = 3\n[still]\nseed = 4\n",
            "`seed` (line 2) is outside the [still] table",
        ),
        (
            &["synth-scene", "cube"],
            "frames = 30\n[scene]\nwidth_px = 64\n",
            "`frames` (line 1) is outside the [scene] table",
        ),
        // A whole scan.toml: its other tables are no generator settings.
        (
            &["synth", "--tone", "440"],
            "[record]\nrpm = 78.0\n[synth]\nwidth_px = 64\n",
            "`record` (line 1) is outside the [synth] table",
        ),
        // In range is checked on the merged settings, which have no lines.
        (
            &["synth-scene", "cube"],
            "width_px = 0\n",
            "scene.width_px: must lie in [8, 8192], got 0",
        ),
    ];
    for (k, (command, text, wanted)) in cases.into_iter().enumerate() {
        let config = dir.path().join(format!("c{k}.toml"));
        std::fs::write(&config, text).unwrap();
        let out = dir.path().join(format!("out{k}"));
        let mut args = command.to_vec();
        args.extend(["--out", s(&out), "--config", s(&config)]);
        let run = groovescope(&args);
        common::failed_with(&run, &[wanted, &format!("c{k}.toml")]);
        assert!(!out.exists());
    }
}

/// A limit on the groups that cuts the sound short is said, naming the limit (the quick
/// preset's two groups hold 0.2 ms of a 0.2 s tone).
#[test]
fn synth_says_when_a_group_limit_cuts_the_sound_short() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("s");
    let tone = [
        "synth",
        "--preset",
        "quick",
        "--tone",
        "1000",
        "--duration",
        "0.2",
    ];
    let o = groovescope(&[&tone[..], &["--out", s(&out), "--quiet"]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    let err = stderr(&o);
    assert!(
        err.contains("stopped at the quick preset's max_groups = 2 groups"),
        "{err}"
    );
    let more = dir.path().join("s4");
    let o = groovescope(&[&tone[..], &["--out", s(&more), "--max-groups", "4"]].concat());
    assert!(
        stderr(&o).contains("stopped at --max-groups = 4 groups"),
        "{}",
        stderr(&o)
    );
}

/// Every command that reads a scan reads a folder or a Zarr store, and its help says so
/// (`reconstruct --help` said "Scan folder"); `pack` converts a folder only, and says that.
#[test]
fn a_scan_arguments_help_names_both_forms() {
    for command in ["reconstruct", "inspect", "plan", "gui"] {
        let o = groovescope(&[command, "--help"]);
        let help = String::from_utf8_lossy(&o.stdout).into_owned();
        let scan = help
            .lines()
            .find(|l| l.trim_start().starts_with("<SCAN>") || l.trim_start().starts_with("[SCAN]"))
            .unwrap_or_else(|| panic!("{command}: {help}"));
        assert!(scan.contains("Zarr store"), "{command}: {scan}");
    }
    let o = groovescope(&["pack", "--help"]);
    assert!(String::from_utf8_lossy(&o.stdout).contains("Scan folder to convert"));
}
