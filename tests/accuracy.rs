//! Fast versions of the accuracy suite: each asserts a bar against the generator's ground truth.
#![allow(clippy::unwrap_used)] // tests may panic

mod common;

use common::{groovescope, stderr};
use groovescope::accuracy::{
    scene_depth_table, score_scan, small_dual_focus, small_lateral, sound_params,
    two_sample_window_px,
};
use groovescope::pipeline::walls::WallMethod;
use groovescope::pipeline::{Method, PathChoice, PipelineParams};
use groovescope::synth::{SceneConfig, SceneKind, SynthConfig};

#[test]
fn sphere_depth_error_beats_the_papers_kalman() {
    // Paper Table 2: mean relative error ≈ 7–9% at frame 27; the goal is ≤ 3%.
    let rows = scene_depth_table(
        SceneKind::Sphere,
        &SceneConfig::default(),
        &[27],
        &PipelineParams::default(),
    )
    .unwrap();
    let r = rows[0].object;
    eprintln!(
        "sphere frame 27: mean {:.2}% ± {:.2}, < 5%: {:.1}%, {} px",
        r.mean, r.sigma, r.below_5, r.pixels
    );
    assert!(r.pixels > 5000, "{} pixels", r.pixels);
    assert!(r.mean < 4.0, "mean error {:.2}%", r.mean);
    assert!(r.below_5 > 70.0, "{:.1}% below 5%", r.below_5);
}

#[test]
fn dual_focus_tone_reaches_its_snr_bar() {
    let cfg = small_dual_focus(8);
    let (_dir, scan) = common::tone_scan("1.5 kHz", 1500.0, &cfg);
    let (s, _) = score_scan(
        "1.5 kHz",
        &scan,
        &sound_params(two_sample_window_px(&cfg), true),
    )
    .unwrap();
    eprintln!(
        "1.5 kHz dual-focus tone: r {:.3}, SNR {:.1} dB",
        s.r, s.snr_db
    );
    assert!(s.r > 0.9, "r = {:.3}", s.r);
    assert!(s.snr_db > 6.0, "SNR = {:.1} dB", s.snr_db);
}

#[test]
fn depth_path_tone_reaches_its_bar() {
    // No cover glass: flow → Kalman depth → walls → orientation, with the default params.
    let (_dir, scan) = common::tone_scan("1 kHz", 1000.0, &small_lateral(6));
    let params = PipelineParams {
        path: PathChoice::Depth,
        method: Method::Flow,
        ..PipelineParams::default()
    };
    let (s, _) = score_scan("1 kHz", &scan, &params).unwrap();
    let mut slope_runs = params.clone();
    slope_runs.walls.method = WallMethod::SlopeRuns;
    let (old, _) = score_scan("1 kHz", &scan, &slope_runs).unwrap();
    eprintln!(
        "1 kHz depth-path tone: r {:.3}, SNR {:.1} dB (walls by slope runs: r {:.3})",
        s.r, s.snr_db, old.r
    );
    assert!(s.r > 0.9, "r = {:.3}", s.r);
    assert!(s.snr_db > 6.0, "SNR = {:.1} dB", s.snr_db);
}

#[test]
fn robust_fit_beats_least_squares_on_a_missing_wall() {
    // Paper Fig. 20: the upper 45% of one wall missing from 300 to 1300 µm.
    let cfg = SynthConfig {
        max_groups: Some(4),
        ..SynthConfig::dual_focus_fig20()
    };
    let (_dir, scan) = common::tone_scan("Fig. 20", 1000.0, &cfg);
    let robust = score_scan("Fig. 20", &scan, &sound_params(100, true))
        .unwrap()
        .0;
    let ls = score_scan("Fig. 20", &scan, &sound_params(100, false))
        .unwrap()
        .0;
    eprintln!(
        "Fig. 20: robust r {:.3}, least squares r {:.3}",
        robust.r, ls.r
    );
    assert!(robust.r > 0.6, "robust r = {:.3}", robust.r);
    assert!(
        robust.r > ls.r + 0.1,
        "robust {:.3} vs LS {:.3}",
        robust.r,
        ls.r
    );
}

#[test]
fn accuracy_refuses_to_overwrite_a_report() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("report.md");
    std::fs::write(&out, "mine").unwrap();
    let o = groovescope(&["accuracy", "--quick", "--out", out.to_str().unwrap()]);
    assert!(!o.status.success());
    let err = stderr(&o);
    assert!(
        err.contains("report.md") && err.contains("--force"),
        "{err}"
    );
    assert_eq!(std::fs::read_to_string(&out).unwrap(), "mine");
    // A folder is refused before the suite runs, --force or not (it used to run the whole
    // suite, then fail to write).
    let o = groovescope(&[
        "accuracy",
        "--quick",
        "--force",
        "--out",
        dir.path().to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let err = stderr(&o);
    assert!(
        err.contains("is a folder") && !err.contains("tone"),
        "{err}"
    );
}

#[test]
fn ctrl_c_stops_the_suite_without_a_report_and_removes_its_work_folder() {
    use std::io::{BufRead, BufReader, Read};
    use std::process::{Command, Stdio};
    let dir = tempfile::tempdir().unwrap();
    // The suite renders its scans (150 MB for --quick) in a temporary folder under TMPDIR.
    let tmp = dir.path().join("tmp");
    std::fs::create_dir(&tmp).unwrap();
    let out = dir.path().join("report.md");
    let mut child = Command::new(env!("CARGO_BIN_EXE_groovescope"))
        .args(["accuracy", "--quick", "--out", out.to_str().unwrap()])
        .env("TMPDIR", &tmp)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut err = BufReader::new(child.stderr.take().unwrap());
    // The first finished case: the handler is in place and scans lie in the work folder.
    let mut first = String::new();
    err.read_line(&mut first).unwrap();
    assert!(first.contains("tone"), "{first}");
    assert!(std::fs::read_dir(&tmp).unwrap().next().is_some());
    common::ctrl_c(&child);
    let mut rest = String::new();
    err.read_to_string(&mut rest).unwrap();
    let status = child.wait().unwrap();
    // An exit of its own (status 1), not death by the signal.
    assert_eq!(status.code(), Some(1), "{rest}");
    assert!(rest.contains("cancelled"), "{rest}");
    assert!(!out.exists());
    assert_eq!(
        std::fs::read_dir(&tmp).unwrap().count(),
        0,
        "work folder left"
    );
}
