//! The bundled still demo (assets/demo-still): it decodes to at least 3 s of speech that matches
//! its reference, `groovescope` with no subcommand and no display writes that WAV and its report
//! in the current folder, and `synth-still` with the committed config remakes it byte for byte.
#![allow(clippy::unwrap_used)] // tests may panic

use std::path::{Path, PathBuf};
use std::process::Command;

use groovescope::io::wav::read_wav;
use groovescope::pipeline::PipelineParams;
use groovescope::still::demo::{DEMO_STILL, read_generated_still};
use groovescope::still::{decode_still_file, score_still};

fn demo_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(DEMO_STILL)
}

/// Measured on the committed still (5 Dec 2026): r 0.931, envelope r 0.931, SNR 8.7 dB.
const MIN_R: f64 = 0.9;
const MIN_ENVELOPE_R: f64 = 0.9;
const MIN_SNR_DB: f64 = 7.0;

#[test]
fn demo_still_decodes_to_three_seconds_of_its_speech() {
    let demo = read_generated_still(&demo_dir()).unwrap();
    assert_eq!(
        demo.groove, 2,
        "the speech is cut into the middle of three turns"
    );
    let reference = read_wav(&demo.reference).unwrap();
    assert!(reference.duration_secs() >= 3.0);
    let run = decode_still_file(
        &demo.image,
        &demo.setup,
        Some(demo.groove),
        &PipelineParams::default(),
    )
    .unwrap();
    let secs = run.audio.duration_secs();
    assert!(secs >= 3.0, "the demo plays {secs:.3} s");
    assert!(run.warnings.is_empty(), "{:?}", run.warnings);
    let scores = score_still(&run.audio, &demo.reference).unwrap();
    let s = scores[0].as_ref().unwrap();
    let env = s.envelope_r.unwrap();
    assert!(
        s.r >= MIN_R && env >= MIN_ENVELOPE_R && s.snr_db >= MIN_SNR_DB,
        "r {:.3}, envelope r {env:.3}, SNR {:.1} dB",
        s.r,
        s.snr_db
    );
}

#[test]
fn no_subcommand_without_a_display_writes_the_demo_wav_and_report_here() {
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_groovescope"))
        .current_dir(dir.path())
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let wav = dir.path().join("groovescope-demo.wav");
    let report = dir.path().join("groovescope-demo.report.json");
    assert!(stdout.contains("groovescope-demo.wav"), "{stdout}");
    assert!(stdout.contains("groovescope-demo.report.json"), "{stdout}");
    assert!(stdout.contains("vs reference: r = "), "{stdout}");
    assert!(read_wav(&wav).unwrap().duration_secs() >= 3.0);
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    assert_eq!(json["groove"], 2);
    // The strip holds three turns (truth.toml); the third one's last blocks, by the image's
    // edge, once counted as a fourth groove.
    let found = json["grooves_found"].as_array().unwrap();
    assert_eq!(found.len(), 3, "{:?}", json["grooves_found"]);
    assert!(json["scores"][0]["r"].as_f64().unwrap() >= MIN_R, "{json}");
    // A Broadcast WAV: the plain PCM format chunk (tag 1, mono, 24 bits), then a `bext`
    // chunk that says what it is, what made it and how.
    let bytes = std::fs::read(&wav).unwrap();
    assert_eq!(&bytes[12..24], b"fmt \x10\0\0\0\x01\0\x01\0");
    assert_eq!(&bytes[34..40], b"\x18\0bext");
    let (description, originator, reference, history) =
        groovescope::io::bwf::read_bext(&bytes).unwrap();
    assert_eq!(originator, "groovescope");
    assert!(
        description
            .contains("disc at 16.667 rpm in groove 2 of a still image at 6 um a pixel: still.png"),
        "{description}"
    );
    assert_eq!(reference.len(), 32, "{reference}");
    assert_eq!(history.len(), 2, "{history:?}");
    assert!(
        history[1].starts_with("A=PCM,F=44100,W=24,M=mono,T=groovescope ")
            && history[1].contains("still decoder; DC block 10 Hz")
            && history[1].contains("low-pass 3000 Hz")
            && history[1].contains("-3 dB at 3000 Hz"),
        "{history:?}"
    );
}

#[test]
fn a_display_variable_with_no_server_behind_it_still_decodes_the_demo() {
    // As over ssh with a stale DISPLAY: nothing listens on display 87.
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_groovescope"))
        .current_dir(dir.path())
        .env("DISPLAY", ":87")
        .env_remove("WAYLAND_DISPLAY")
        .env("XDG_RUNTIME_DIR", dir.path())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains("cannot open the workbench window") && stderr.contains("instead"),
        "{stderr}"
    );
    assert!(!stderr.contains(".rs:"), "no source paths: {stderr}");
    assert!(dir.path().join("groovescope-demo.wav").is_file());
}

#[test]
fn synth_still_with_the_committed_config_remakes_the_demo_byte_for_byte() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    let remade = dir.path().join("demo-still");
    let out = Command::new(env!("CARGO_BIN_EXE_groovescope"))
        .arg("synth-still")
        .arg(root.join("assets/demo-speech.wav"))
        .args(["--preset", "demo", "--quiet", "--config"])
        .arg(root.join("assets/demo-still.toml"))
        .arg("--out")
        .arg(&remade)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut names: Vec<_> = std::fs::read_dir(demo_dir())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    names.sort();
    assert_eq!(names.len(), 5, "{names:?}");
    for name in names {
        let a = std::fs::read(demo_dir().join(&name)).unwrap();
        let b = std::fs::read(remade.join(&name)).unwrap();
        assert!(a == b, "{name:?} differs from the committed one");
    }
}
