//! End to end against ground truth: the generator renders a tone scan, the CLI reconstructs it, the report's scores are checked.
#![allow(clippy::unwrap_used)] // tests may panic

mod common;

use common::{groovescope, stderr};
use groovescope::accuracy::small_dual_focus;
use groovescope::job::Job;
use groovescope::synth::{BUILTIN_RATE_HZ, render_scan, tone};

#[test]
fn dual_focus_tone_scan_reconstructs_the_tone() {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("scan");
    let sound = tone(700.0, 0.03, BUILTIN_RATE_HZ);
    render_scan(&sound, &small_dual_focus(8), &scan, Job::unwatched()).unwrap();
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
    // The default method, fused, filters zero-phase; the report says so.
    assert_eq!(
        rep["filters"],
        "DC block 10 Hz (first-order high-pass, forward and backward); low-pass 3000 Hz \
         (2nd-order Butterworth, forward and backward: −3 dB at 3000 Hz, 24 dB an octave above)"
    );
    let r = rep["scores"]["r"].as_f64().unwrap();
    let snr = rep["scores"]["snr_db"].as_f64().unwrap();
    eprintln!("dual-focus 700 Hz tone: r = {r:.3}, SNR = {snr:.1} dB");
    assert!(r > 0.8, "r = {r}");
    assert!(snr > 2.0, "SNR = {snr}");
}

#[test]
fn inspect_dumps_every_stage_and_the_accumulator_when_segmentation_fails() {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("scan");
    render_scan(
        &tone(700.0, 0.01, BUILTIN_RATE_HZ),
        &small_dual_focus(1),
        &scan,
        Job::unwatched(),
    )
    .unwrap();
    let inspect = |out: &std::path::Path, extra: &[&str]| {
        let mut args = vec![
            "inspect",
            scan.to_str().unwrap(),
            "--group",
            "0",
            "--out",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        groovescope(&args)
    };
    let ok = dir.path().join("ok");
    let out = inspect(&ok, &[]);
    assert!(out.status.success(), "{}", stderr(&out));
    for f in [
        "frame.png",
        "flow.png",
        "in_focus.png",
        "hough.png",
        "stripes.png",
        "samples.csv",
        "edges.png",
        "edges.csv",
    ] {
        assert!(ok.join(f).is_file(), "{f} missing");
    }
    // The edge stage's samples: a header, then one row a sample with a border found.
    let csv = std::fs::read_to_string(ok.join("edges.csv")).unwrap();
    let mut lines = csv.lines();
    let header = lines.next().unwrap();
    assert!(
        header.starts_with("sample,s_um,left_land_border_y_um,"),
        "{header}"
    );
    let columns = header.split(',').count();
    let rows: Vec<&str> = lines.collect();
    assert!(rows.len() > 10 && rows.iter().all(|r| r.split(',').count() == columns));
    assert!(
        rows.iter().any(|r| r
            .split(',')
            .nth(2)
            .is_some_and(|y| y.parse::<f64>().unwrap().is_finite())),
        "no border found: {csv}"
    );
    // Windows so wide that the stripes cannot be told apart: the group fails, and the
    // accumulator with its peaks is still written, so the operator can see why.
    let params = dir.path().join("wide.toml");
    std::fs::write(&params, "[hough]\nwindow_rho_px = 150.0\n").unwrap();
    let bad = dir.path().join("bad");
    let out = inspect(&bad, &["--params", params.to_str().unwrap()]);
    assert!(!out.status.success());
    let err = stderr(&out);
    assert!(err.contains("group 0") && err.contains("stripes"), "{err}");
    assert!(bad.join("hough.png").is_file() && bad.join("in_focus.png").is_file());
    assert!(!bad.join("samples.csv").exists());
    // The failing run over the good one's folder: what it could not redo is named as an
    // earlier run's, and kept.
    let out = inspect(&ok, &["--params", params.to_str().unwrap(), "--force"]);
    assert!(!out.status.success());
    let err = stderr(&out);
    assert!(
        err.contains("samples.csv") && err.contains("not from this run"),
        "{err}"
    );
    assert!(ok.join("samples.csv").is_file());
}
