//! End to end against ground truth: the generator renders a tone scan, the CLI reconstructs it, the report's scores are checked.
#![allow(clippy::unwrap_used)] // tests may panic

mod common;

use std::sync::atomic::AtomicBool;

use common::{groovescope, stderr};
use groovescope::synth::{SynthConfig, render_scan, tone};

/// The demo's camera scaled for speed: 0.78 µm pixels, 320×384 frames, 7 frames a group, a
/// 16⅔ rpm transcription disc at 60 mm, and the dual-focus cover glass of paper §9.
fn small_dual_focus() -> SynthConfig {
    SynthConfig {
        width_px: 320,
        height_px: 384,
        pixel_pitch_um: 0.78,
        frame_step_um: 1.56,
        frames_per_group: 7,
        group_overlap_px: 24,
        rpm: 16.667,
        radius_mm: 60.0,
        bit_depth: 8,
        noise_sigma_8bit: 0.5,
        max_groups: Some(8),
        ..SynthConfig::dual_focus_demo()
    }
}

#[test]
fn dual_focus_tone_scan_reconstructs_the_tone() {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("scan");
    let sound = tone(700.0, 0.03, 48_000);
    render_scan(
        &sound,
        &small_dual_focus(),
        &scan,
        &|_, _| {},
        &AtomicBool::new(false),
    )
    .unwrap();
    let wav = dir.path().join("out.wav");
    let report = dir.path().join("report.json");
    let out = groovescope(&[
        "reconstruct",
        scan.to_str().unwrap(),
        "--out",
        wav.to_str().unwrap(),
        "--report",
        report.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let reader = hound::WavReader::open(&wav).unwrap();
    assert_eq!(reader.spec().sample_rate, 44_100);
    assert_eq!(reader.spec().channels, 1);
    assert!(reader.duration() > 500, "{} samples", reader.duration());
    let rep: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    assert_eq!(rep["path"], "dual-focus");
    let r = rep["scores"]["r"].as_f64().unwrap();
    let snr = rep["scores"]["snr_db"].as_f64().unwrap();
    eprintln!("dual-focus 700 Hz tone: r = {r:.3}, SNR = {snr:.1} dB");
    assert!(r > 0.8, "r = {r}");
    assert!(snr > 2.0, "SNR = {snr}");
}
