//! Faults while running and concurrent writers: frames that vanish after the scan opened, an output folder removed mid-run, a full disk (for the WAV and for the journal), two runs on one output (issue 19).

#![allow(clippy::unwrap_used)] // tests may panic

mod common;

use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use common::{demo_copy, names, stderr};
use groovescope::engine::{EngineError, ReconstructOptions, reconstruct};
use groovescope::io::Scan;
use groovescope::io::lock::{OutputLock, lock_path};
use groovescope::io::wav::{Audio, WavBits, read_wav, write_wav};

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn run(
    scan: &Scan,
    groups: std::ops::Range<usize>,
    keep_going: bool,
) -> Result<groovescope::engine::Reconstruction, EngineError> {
    let opts = ReconstructOptions {
        groups: Some(groups),
        keep_going,
        ..ReconstructOptions::default()
    };
    reconstruct(scan, &opts, &mut |_| {}, &AtomicBool::new(false))
}

#[test]
fn a_frame_deleted_or_truncated_after_the_scan_opened_is_named_and_keep_going_fills_a_gap() {
    let dir = tempfile::tempdir().unwrap();
    let demo = demo_copy(dir.path());
    let scan = Scan::open(&demo).unwrap();
    let frame = demo.join("g00002/f003.png");
    let good = std::fs::read(&frame).unwrap();
    for damage in ["deleted", "truncated"] {
        if damage == "deleted" {
            std::fs::remove_file(&frame).unwrap();
        } else {
            std::fs::write(&frame, &good[..good.len() / 2]).unwrap();
        }
        let err = run(&scan, 0..4, false).unwrap_err().to_string();
        assert!(err.contains("g00002/f003.png"), "{damage}: {err}");
        let rec = run(&scan, 0..4, true).unwrap();
        common::assert_warned(&rec.warnings, &["group 2", "f003.png"], damage);
        assert!(!rec.audio.is_empty());
    }
    std::fs::write(&frame, &good).unwrap();
    assert!(run(&scan, 0..4, false).is_ok());
}

#[test]
fn an_output_folder_removed_mid_run_ends_with_one_line_and_leaves_nothing() {
    let (dir, demo, out_dir) = common::demo_and_out_folder("out");
    let wav = out_dir.join("clip.wav");
    let child = Command::new(env!("CARGO_BIN_EXE_groovescope"))
        .args(["reconstruct", s(&demo), "--out", s(&wav), "--quiet"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The run locks its output before any work: once the lock is there, the folder goes.
    let started = Instant::now();
    while !lock_path(&wav).exists() {
        assert!(started.elapsed() < Duration::from_secs(30), "no lock seen");
        std::thread::sleep(Duration::from_millis(1));
    }
    std::fs::remove_dir_all(&out_dir).unwrap();
    let o = child.wait_with_output().unwrap();
    let err = stderr(&o);
    assert!(!o.status.success(), "{err}");
    assert!(
        err.contains("clip.wav") && err.contains("No such file"),
        "{err}"
    );
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(!out_dir.exists());
    assert_eq!(names(dir.path()), vec!["demo".to_string()]);
}

/// A tmpfs of `size` (`256k`) mounted on a fresh folder, unmounted on drop.
struct SmallDisk {
    dir: tempfile::TempDir,
}

impl SmallDisk {
    fn mount(size: &str) -> Option<Self> {
        let dir = tempfile::tempdir().ok()?;
        let ok = Command::new("mount")
            .args([
                "-t",
                "tmpfs",
                "-o",
                &format!("size={size}"),
                "tmpfs",
                s(dir.path()),
            ])
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|st| st.success());
        ok.then_some(Self { dir })
    }
}

impl Drop for SmallDisk {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg(self.dir.path()).status();
    }
}

#[test]
fn a_full_disk_is_one_clear_error_leaves_no_partial_file_and_keeps_the_old_one() {
    let Some(disk) = SmallDisk::mount("256k") else {
        eprintln!("skipped: cannot mount a tmpfs here (needs root)");
        return;
    };
    let target = disk.dir.path().join("clip.wav");
    std::fs::write(&target, b"the operator's earlier export").unwrap();
    // 100,000 stereo frames of 24 bits: 600 KB, more than the disk holds.
    let audio = Audio {
        sample_rate_hz: 48_000,
        channels: vec![vec![0.25; 100_000]; 2],
    };
    for overwrite in [true, false] {
        let msg = write_wav(&target, &audio, WavBits::Int24, overwrite)
            .unwrap_err()
            .to_string();
        assert!(msg.contains("clip.wav"), "{msg}");
        if overwrite {
            assert!(msg.contains("No space left"), "{msg}");
        }
        assert_eq!(
            std::fs::read(&target).unwrap(),
            b"the operator's earlier export"
        );
        assert_eq!(names(disk.dir.path()), vec!["clip.wav".to_string()]);
    }
    let fresh = disk.dir.path().join("new.wav");
    let msg = write_wav(&fresh, &audio, WavBits::Int24, false)
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("new.wav") && msg.contains("No space left"),
        "{msg}"
    );
    assert_eq!(names(disk.dir.path()), vec!["clip.wav".to_string()]);
}

#[test]
fn a_disk_filled_by_the_journal_stops_the_run_with_its_groups_kept_for_resume() {
    // 16 KiB holds the journal of about two of the demo's 13 groups.
    let Some(disk) = SmallDisk::mount("16k") else {
        eprintln!("skipped: cannot mount a tmpfs here (needs root)");
        return;
    };
    let demo = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/demo");
    let o = common::reconstruct(&demo, &disk.dir.path().join("side.wav"), &[]);
    common::failed_with(
        &o,
        &[
            "cannot write the journal",
            "No space left",
            "finished groups are kept in",
            "--resume",
        ],
    );
    assert_eq!(o.status.code(), Some(1), "an exit of its own");
    assert_eq!(names(disk.dir.path()), ["side.wav.journal"]);
    // Room made (the journal moved to a roomier disk), --resume ends with the bytes of a
    // run that never stopped.
    let roomy = tempfile::tempdir().unwrap();
    std::fs::copy(
        disk.dir.path().join("side.wav.journal"),
        roomy.path().join("side.wav.journal"),
    )
    .unwrap();
    let out = roomy.path().join("side.wav");
    let o = common::reconstruct(&demo, &out, &["--resume"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let whole = roomy.path().join("whole.wav");
    assert!(common::reconstruct(&demo, &whole, &[]).status.success());
    assert!(std::fs::read(&out).unwrap() == std::fs::read(&whole).unwrap());
}

#[test]
fn a_second_reconstruct_to_an_output_in_use_is_refused_and_racing_runs_never_tear_it() {
    let dir = tempfile::tempdir().unwrap();
    let demo = demo_copy(dir.path());
    let wav = dir.path().join("clip.wav");
    // Held by another run (or window): refused at once, nothing written.
    let held = OutputLock::acquire(&wav).unwrap();
    let o = common::groovescope(&["reconstruct", s(&demo), "--out", s(&wav), "--quiet"]);
    let err = stderr(&o);
    assert!(!o.status.success());
    assert!(
        err.contains("another groovescope") && err.contains("clip.wav"),
        "{err}"
    );
    assert!(!wav.exists());
    drop(held);

    // One run alone, for the expected bytes.
    let alone = dir.path().join("alone.wav");
    let o = common::groovescope(&["reconstruct", s(&demo), "--out", s(&alone), "--quiet"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let expected = std::fs::read(&alone).unwrap();

    // Two runs racing for one output (and one report), replacing it: each finishes or is
    // refused, and what is left is one whole run's WAV.
    let report = dir.path().join("clip.json");
    let start = || {
        Command::new(env!("CARGO_BIN_EXE_groovescope"))
            .args([
                "reconstruct",
                s(&demo),
                "--out",
                s(&wav),
                "--report",
                s(&report),
            ])
            .args(["--quiet", "--force"])
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    let (a, b) = (start(), start());
    let outputs = [a.wait_with_output().unwrap(), b.wait_with_output().unwrap()];
    assert!(outputs.iter().any(|o| o.status.success()));
    for o in outputs.iter().filter(|o| !o.status.success()) {
        assert!(stderr(o).contains("another groovescope"), "{}", stderr(o));
    }
    assert_eq!(
        std::fs::read(&wav).unwrap(),
        expected,
        "a torn or mixed WAV"
    );
    assert!(!read_wav(&wav).unwrap().is_empty());
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    assert!(json.is_object());
    assert_eq!(
        names(dir.path()),
        vec!["alone.wav", "clip.json", "clip.wav", "demo"]
    );
}

// The workbench's preset saving exists only in the gui build.
#[cfg(feature = "gui")]
#[test]
fn two_windows_saving_one_preset_or_exporting_one_file_do_not_interleave() {
    let dir = tempfile::tempdir().unwrap();
    let preset = dir.path().join("preset.toml");
    let params = groovescope::pipeline::PipelineParams::default();
    let held = OutputLock::acquire(&preset).unwrap();
    let msg = groovescope::app::tuning::save_preset(&params, &preset, true).unwrap_err();
    assert!(
        msg.contains("another groovescope") && msg.contains("preset.toml"),
        "{msg}"
    );
    assert!(!preset.exists());
    drop(held);
    groovescope::app::tuning::save_preset(&params, &preset, false).unwrap();
    assert_eq!(names(dir.path()), vec!["preset.toml".to_string()]);
}

/// Sets the modification time of `dir` and of each entry directly in it to two hours ago.
fn age_two_hours(dir: &Path) {
    let old = std::time::SystemTime::now() - Duration::from_secs(7200);
    let mut paths: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    paths.push(dir.to_path_buf());
    for p in paths {
        std::fs::File::open(&p).unwrap().set_modified(old).unwrap();
    }
}

/// A `synth` killed with `kill -9` cannot remove its hidden `.NAME.synth-PID.tmp` folder: a
/// rerun into the same place names it (it was kept in silence), and once nothing has written
/// to it for an hour (another machine's run may use the same name) a rerun removes it, saying
/// so. The rerun is never blocked.
#[test]
fn a_synth_killed_outright_leaves_a_folder_the_next_run_names_and_then_removes() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("s");
    let mut child = Command::new(env!("CARGO_BIN_EXE_groovescope"))
        .args([
            "synth",
            "--preset",
            "paper",
            "--tone",
            "1000",
            "--duration",
            "1",
        ])
        .args(["--max-groups", "400", "--quiet", "--out", s(&out)])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let temp = dir.path().join(format!(".s.synth-{}.tmp", child.id()));
    let start = Instant::now();
    // Killed once its first group is written into the hidden folder.
    while !temp.join("g000").is_dir() && !temp.join("g00000").is_dir() {
        assert!(start.elapsed() < Duration::from_secs(120), "no group yet");
        assert!(child.try_wait().unwrap().is_none(), "ended before the kill");
        std::thread::sleep(Duration::from_millis(20));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(temp.is_dir() && !out.exists());
    let quick = |out: &Path| {
        let args = ["synth", "--preset", "quick", "--tone", "1000", "--quiet"];
        common::groovescope(&[&args[..], &["--out", s(out)]].concat())
    };
    let o = quick(&out);
    let e = stderr(&o);
    assert!(o.status.success(), "{e}");
    assert!(
        e.contains("kept the unfinished folder of an earlier generator run")
            && e.contains(&temp.display().to_string()),
        "{e}"
    );
    assert!(temp.is_dir() && out.join("scan.toml").is_file());
    age_two_hours(&temp);
    std::fs::remove_dir_all(&out).unwrap();
    let o = quick(&out);
    let e = stderr(&o);
    assert!(o.status.success(), "{e}");
    assert!(
        e.contains("removed an unfinished folder left by an earlier, killed generator run")
            && e.contains(&temp.display().to_string()),
        "{e}"
    );
    assert!(!temp.exists() && out.join("scan.toml").is_file());
}
