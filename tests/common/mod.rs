//! Shared helpers for integration tests: tiny scans on disk and the binary's path.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use groovescope::accuracy::render_tone;
use groovescope::image::Image;
use groovescope::io::save_grey_png;
use groovescope::synth::SynthConfig;

/// Minimal valid scan.toml text.
pub const SCAN_TOML: &str = r#"format = 1
[record]
rpm = 78.0
radius_mm = 115.0
cut = "lateral"
[camera]
pixel_pitch_um = 0.39
working_distance_mm = 4.0
[motion]
frame_step_um = 0.78
group_step_um = 4.0
"#;

/// Writes a scan of `groups` groups of `frames` textured frames (`w`×`h`) under `dir`.
pub fn write_scan(dir: &Path, groups: usize, frames: usize, w: usize, h: usize) -> PathBuf {
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(dir.join("scan.toml"), SCAN_TOML).unwrap();
    for g in 0..groups {
        let gd = dir.join(format!("g{g:05}"));
        std::fs::create_dir_all(&gd).unwrap();
        for k in 0..frames {
            let img = Image::from_fn(w, h, |x, y| {
                let xs = x as f32 + 2.0 * k as f32;
                0.5 + 0.2 * (xs * 0.31).sin() * (y as f32 * 0.23).cos()
            });
            save_grey_png(&img, &gd.join(format!("f{k:03}.png")), false, false).unwrap();
        }
    }
    dir.to_path_buf()
}

/// Runs the groovescope binary.
pub fn groovescope(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_groovescope"))
        .args(args)
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .output()
        .unwrap()
}

/// The arguments of `plan SCAN --shards 2 --probe-groups 0 --out OUT`: two shards, no probe.
pub fn two_shard_plan<'a>(scan: &'a str, out: &'a str) -> [&'a str; 8] {
    [
        "plan",
        scan,
        "--shards",
        "2",
        "--probe-groups",
        "0",
        "--out",
        out,
    ]
}

/// Sends the child a Ctrl-C (SIGINT).
pub fn ctrl_c(child: &std::process::Child) {
    let pid = child.id().to_string();
    // By its full path: the workbench harness empties `PATH` for the whole test process.
    let kill = ["/usr/bin/kill", "/bin/kill"]
        .into_iter()
        .find(|p| Path::new(p).exists())
        .unwrap_or("kill");
    let sent = Command::new(kill).args(["-INT", &pid]).status().unwrap();
    assert!(sent.success(), "kill -INT {pid}");
}

/// Runs groovescope with `args`, one of which names `fifo` (a named pipe this makes) as an
/// input file, and presses Ctrl-C while the command waits there: once it has opened the
/// pipe (so its Ctrl-C handler is in place) and before it has read a byte. Then `content` is
/// written and the pipe closed, and the command runs on with Ctrl-C pressed.
pub fn ctrl_c_while_reading(args: &[&str], fifo: &Path, content: &[u8]) -> Output {
    use std::io::Write as _;
    use std::process::Stdio;
    use std::time::{Duration, Instant};
    assert!(Command::new("mkfifo").arg(fifo).status().unwrap().success());
    let mut child = Command::new(env!("CARGO_BIN_EXE_groovescope"))
        .args(args)
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Opening the write end waits for the command to open the read end.
    let (tx, rx) = std::sync::mpsc::channel();
    let path = fifo.to_path_buf();
    std::thread::Builder::new()
        .name("pipe writer".into())
        .spawn(move || {
            let _ = tx.send(std::fs::OpenOptions::new().write(true).open(path));
        })
        .unwrap();
    let started = Instant::now();
    let mut writer = loop {
        if let Ok(opened) = rx.recv_timeout(Duration::from_millis(20)) {
            break opened.unwrap();
        }
        let ended = child.try_wait().unwrap().is_some();
        if ended || started.elapsed() > Duration::from_secs(120) {
            // Free the waiting writer, then show what the command said.
            let _ = std::fs::File::open(fifo);
            let _ = child.kill();
            let o = child.wait_with_output().unwrap();
            panic!("never opened {}: {}", fifo.display(), stderr(&o));
        }
    };
    ctrl_c(&child);
    writer.write_all(content).unwrap();
    drop(writer);
    child.wait_with_output().unwrap()
}

/// The groups the progress record of the partial store `partial` counts (0 while it has none).
pub fn groups_checked(partial: &Path) -> usize {
    std::fs::read(partial.join(groovescope::io::zarr::PROGRESS_FILE))
        .ok()
        .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok())
        .and_then(|v| v["groups_checked"].as_u64())
        .map_or(0, |n| n as usize)
}

/// A groovescope command that writes a store through a partial store (`pack`,
/// `import-video` into a store): `command` then `args`, writing `partial`.
pub struct StoreRun<'a> {
    /// The subcommand.
    pub command: &'a str,
    /// Its arguments.
    pub args: &'a [&'a str],
    /// The partial store it writes.
    pub partial: &'a Path,
}

impl StoreRun<'_> {
    /// Starts the command and returns once its progress record counts `at_least` groups (the
    /// command is still running).
    pub fn until(&self, at_least: usize) -> std::process::Child {
        use std::process::Stdio;
        use std::time::{Duration, Instant};
        let mut child = Command::new(env!("CARGO_BIN_EXE_groovescope"))
            .arg(self.command)
            .args(self.args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let started = Instant::now();
        while groups_checked(self.partial) < at_least {
            let ended = child.try_wait().unwrap().is_some();
            if ended || started.elapsed() > Duration::from_secs(120) {
                let _ = child.kill();
                let o = child.wait_with_output().unwrap();
                panic!(
                    "{} ended or stalled before {at_least} groups: {}",
                    self.command,
                    stderr(&o)
                );
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        child
    }

    /// Runs it until `at_least` groups are counted, presses Ctrl-C, and checks that it failed
    /// with one line that holds every `said`, says how many groups it kept and where, and how
    /// to go on. Returns the groups kept.
    pub fn ctrl_c_keeps(&self, at_least: usize, said: &[&str]) -> usize {
        let child = self.until(at_least);
        // Twice at once, as `timeout -s INT` sends it (to the command, then to its process
        // group): one interrupt, not a second that stops the command at once.
        ctrl_c(&child);
        ctrl_c(&child);
        let o = child.wait_with_output().unwrap();
        let e = stderr(&o);
        let kept = groups_checked(self.partial);
        assert!(
            !o.status.success()
                && said.iter().all(|w| e.contains(w))
                && e.contains(&format!("the {kept} "))
                && e.contains(self.partial.to_str().unwrap())
                && e.contains("--resume")
                && e.trim().lines().count() == 1,
            "{e}"
        );
        assert!(kept >= at_least, "{kept}");
        kept
    }

    /// Runs it without `--quiet` and with `--resume`, and checks that it finished, said it
    /// took over `resumed` of `total` groups, and left no partial store.
    pub fn resume_to_the_end(&self, resumed: usize, total: usize) {
        let mut all = vec![self.command];
        all.extend(
            self.args
                .iter()
                .filter(|a| **a != "--quiet" && **a != "--resume"),
        );
        all.push("--resume");
        let o = groovescope(&all);
        assert!(o.status.success(), "{}", stderr(&o));
        let said = String::from_utf8_lossy(&o.stdout);
        assert!(
            said.contains(&format!("resumed: {resumed} of {total} groups")),
            "{said}"
        );
        assert!(
            !self.partial.exists(),
            "the partial store is renamed into place"
        );
    }
}

/// Runs `groovescope reconstruct SCAN --out OUT --quiet` with `extra`.
pub fn reconstruct(scan: &Path, out: &Path, extra: &[&str]) -> Output {
    let (scan, out) = (scan.to_str().unwrap(), out.to_str().unwrap());
    let mut args = vec!["reconstruct", scan, "--out", out, "--quiet"];
    args.extend_from_slice(extra);
    groovescope(&args)
}

/// The names in `dir`, sorted.
pub fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// Stderr as text.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Asserts that `o` failed with one line of stderr holding every `wanted`; returns the line.
#[allow(dead_code)] // not every test binary uses it
pub fn failed_with(o: &Output, wanted: &[&str]) -> String {
    let err = stderr(o);
    assert!(!o.status.success(), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(wanted.iter().all(|w| err.contains(w)), "{err}");
    err
}

/// A temporary folder holding a copy of the demo ([`demo_copy`]); the folder goes when the
/// first value is dropped.
#[allow(dead_code)] // not every test binary uses it
pub fn demo_in_tempdir() -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let demo = demo_copy(dir.path());
    (dir, demo)
}

/// A temporary folder holding a copy of the demo scan ([`demo_copy`]) and an empty folder
/// `out` beside it for a run's outputs: (the folder, the scan, `out`).
pub fn demo_and_out_folder(out: &str) -> (tempfile::TempDir, PathBuf, PathBuf) {
    let (dir, demo) = demo_in_tempdir();
    let out = dir.path().join(out);
    std::fs::create_dir(&out).unwrap();
    (dir, demo, out)
}

/// A scan of `groups` groups of `frames` textured frames (`w`×`h`, [`write_scan`]) in `scan` of a
/// fresh temporary folder; the folder goes when the first value is dropped.
pub fn scan_in_tempdir(
    groups: usize,
    frames: usize,
    w: usize,
    h: usize,
) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let scan = write_scan(&dir.path().join("scan"), groups, frames, w, h);
    (dir, scan)
}

/// A copy of the bundled demo scan (13 dual-focus groups of 7 frames, with `reference.wav`)
/// in `dir/demo`, for tests that damage or lock it.
pub fn demo_copy(dir: &Path) -> PathBuf {
    fn copy_dir(from: &Path, to: &Path) {
        std::fs::create_dir_all(to).unwrap();
        for entry in std::fs::read_dir(from).unwrap() {
            let p = entry.unwrap().path();
            let dest = to.join(p.file_name().unwrap());
            if p.is_dir() {
                copy_dir(&p, &dest);
            } else {
                std::fs::copy(&p, &dest).unwrap();
            }
        }
    }
    let out = dir.join("demo");
    copy_dir(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/demo"),
        &out,
    );
    out
}

/// Writes `samples` as a mono 32-bit float WAV at `rate` Hz, as they are: NaN and infinity
/// too, which groovescope's own writer never writes.
pub fn write_raw_wav(path: &Path, rate: u32, samples: &[f32]) {
    let spec = hound::WavSpec {
        channels: 1,
        sample_rate: rate,
        bits_per_sample: 32,
        sample_format: hound::SampleFormat::Float,
    };
    let mut w = hound::WavWriter::create(path, spec).unwrap();
    for &v in samples {
        w.write_sample(v).unwrap();
    }
    w.finalize().unwrap();
}

/// xorshift64*: a fixed, seedable stream for mutation and monkey tests.
pub struct Rng(pub u64);

impl Rng {
    /// The next 64 random bits.
    pub fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// A number in `0..n` (0 when `n` is 0).
    pub fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// Asserts that one of `warnings` contains every one of `parts`; `context` leads the failure
/// message.
pub fn assert_warned(warnings: &[String], parts: &[&str], context: &str) {
    assert!(
        warnings.iter().any(|w| parts.iter().all(|p| w.contains(p))),
        "{context}: no warning with {parts:?} in {warnings:?}"
    );
}

/// A scan of a `hz` tone (case name `label`) rendered with `cfg` into a fresh temporary folder,
/// which lives as long as the returned guard.
pub fn tone_scan(label: &str, hz: f64, cfg: &SynthConfig) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("scan");
    render_tone(label, hz, cfg, &scan).unwrap();
    (dir, scan)
}
