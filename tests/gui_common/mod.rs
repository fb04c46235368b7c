//! Shared helpers of the workbench tests: the headless harness around the real workbench,
//! the test scans (rendered once per test process), settling and messages.

#![allow(dead_code)] // each test file uses its own subset
#![allow(clippy::unwrap_used)] // tests may panic

use std::path::{Path, PathBuf};
use std::sync::{Once, OnceLock};
use std::time::{Duration, Instant};

/// The plain integration-test helpers (the demo copy, the binary, tiny scans).
#[path = "../common/mod.rs"]
pub mod common;

use egui_kittest::Harness;
use groovescope::app::{Workbench, WorkbenchOptions};
use groovescope::image::Image;
use groovescope::job::Job;
use groovescope::playback::DeviceChoice;
use groovescope::synth::SynthConfig;

/// Longest wait for the worker or a reconstruction.
pub const TIMEOUT: Duration = Duration::from_secs(300);
/// Window size of every harness (points).
pub const SIZE: [f32; 2] = [1280.0, 800.0];

static ALSA: Once = Once::new();

/// Points ALSA at a silent null sink (no sound card here; never assert on timing), and makes
/// the process a bare desktop-less machine for file dialogs: no session bus (so no desktop
/// portal) and a `PATH` without `zenity`, so no test ever opens a real dialog and every dialog
/// takes the path a bare Debian install takes.
pub fn quiet_audio() {
    ALSA.call_once(|| {
        let tmp = Path::new(env!("CARGO_TARGET_TMPDIR"));
        let conf = tmp.join("alsa-null.conf");
        std::fs::write(
            &conf,
            "</usr/share/alsa/alsa.conf>\npcm.!default { type null }\n",
        )
        .unwrap();
        let no_tools = tmp.join("no-tools");
        std::fs::create_dir_all(&no_tools).unwrap();
        // A runtime folder of our own: no session bus socket in it.
        let runtime = tmp.join(format!("runtime-{}", std::process::id()));
        std::fs::create_dir_all(&runtime).unwrap();
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(&runtime, std::fs::Permissions::from_mode(0o700)).unwrap();
        }
        // SAFETY: runs once, before any test touches ALSA, dialogs or reads the environment
        // (every test calls it before building a workbench).
        unsafe {
            std::env::set_var("ALSA_CONFIG_PATH", &conf);
            std::env::set_var("PATH", &no_tools);
            std::env::remove_var("DBUS_SESSION_BUS_ADDRESS");
            std::env::set_var("XDG_RUNTIME_DIR", &runtime);
        }
    });
}

pub const SCAN_TOML: &str = "format = 1
[record]
rpm = 78.0
radius_mm = 115.0
cut = \"lateral\"
[camera]
pixel_pitch_um = 0.39
working_distance_mm = 4.0
[motion]
frame_step_um = 0.78
group_step_um = 10.0
";

/// A hand-made scan for bad-input tests: `groups` groups of 7 textured frames.
pub fn write_scan(dir: &Path, groups: usize) {
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(dir.join("scan.toml"), SCAN_TOML).unwrap();
    for g in 0..groups {
        let gdir = dir.join(format!("group_{g:03}"));
        std::fs::create_dir_all(&gdir).unwrap();
        for t in 0..7 {
            let img = Image::from_fn(64, 48, |x, y| {
                (0.5 + 0.3 * ((x + 2 * t) as f32 * 0.37 + y as f32 * 0.11).sin()).clamp(0.0, 1.0)
            });
            groovescope::io::save_grey_png(&img, &gdir.join(format!("f{t:02}.png")), false, true)
                .unwrap();
        }
    }
}

/// Renders a synthetic scan once per test process (under the target's temporary folder).
pub fn rendered_scan(name: &str, cfg: SynthConfig) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("ui-scans-{}", std::process::id()))
        .join(name);
    let _ = std::fs::remove_dir_all(&dir);
    let sound = groovescope::synth::tone(440.0, 0.2, 44_100);
    groovescope::synth::render_scan(&sound, &cfg, &dir, Job::unwatched()).unwrap();
    dir
}

/// A small synthetic lateral scan on the depth path: 3 groups of 8 frames of 256×320 px of a
/// 440 Hz tone, with `reference.wav`.
pub fn lateral_scan() -> PathBuf {
    static SCAN: OnceLock<PathBuf> = OnceLock::new();
    SCAN.get_or_init(|| {
        rendered_scan(
            "lateral",
            SynthConfig {
                frames_per_group: 8,
                max_groups: Some(3),
                ..SynthConfig::quick_test()
            },
        )
    })
    .clone()
}

/// A copy of the bundled demo scan (dual focus, with `reference.wav`), made once per test
/// process, so that a test saving metadata, presets or exports beside it never changes the
/// bundled one; when it is missing, a small synthetic dual-focus scan (2 groups of 8 frames of
/// 320×700 px) stands in.
pub fn demo_scan() -> PathBuf {
    static SCAN: OnceLock<PathBuf> = OnceLock::new();
    SCAN.get_or_init(|| {
        let demo = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/demo");
        if demo.join("scan.toml").is_file() {
            let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
                .join(format!("ui-scans-{}", std::process::id()));
            std::fs::create_dir_all(&dir).unwrap();
            return common::demo_copy(&dir);
        }
        rendered_scan(
            "dual",
            SynthConfig {
                width_px: 320,
                height_px: 700,
                group_overlap_px: 10,
                frames_per_group: 8,
                max_groups: Some(2),
                ..SynthConfig::dual_focus_demo()
            },
        )
    })
    .clone()
}

pub fn options(tmp: &Path, scan: Option<PathBuf>, audio: DeviceChoice) -> WorkbenchOptions {
    WorkbenchOptions {
        scan,
        config_dir: Some(tmp.join("config")),
        audio,
        hide_timings: true,
        ..WorkbenchOptions::default()
    }
}

/// A harness on `scan` (sound off) that has settled, and the temporary folder its settings
/// live in (keep it for the test's length).
pub fn settled_on(scan: &Path) -> (tempfile::TempDir, H) {
    let tmp = tempfile::tempdir().unwrap();
    let mut h = harness(options(
        tmp.path(),
        Some(scan.to_path_buf()),
        DeviceChoice::Off,
    ));
    settle(&mut h);
    (tmp, h)
}

/// The workbench and the eframe frame it draws into (the harness owns both).
pub struct App {
    pub wb: Option<Workbench>,
    pub frame: eframe::Frame,
}

pub type H = Harness<'static, App>;

/// A harness running the real workbench: `App::ui` every step, as eframe would.
pub fn harness(opts: WorkbenchOptions) -> H {
    quiet_audio();
    let mut h = Harness::builder()
        .with_size(egui::vec2(SIZE[0], SIZE[1]))
        .with_max_steps(40)
        .build_ui_state(
            |ui, app: &mut App| {
                if let Some(wb) = &mut app.wb {
                    eframe::App::logic(wb, ui.ctx(), &mut app.frame);
                    eframe::App::ui(wb, ui, &mut app.frame);
                }
            },
            App {
                wb: None,
                frame: eframe::Frame::_new_kittest(),
            },
        );
    let ctx = h.ctx.clone();
    h.state_mut().wb = Some(Workbench::new(&ctx, opts).unwrap());
    h.run_ok();
    h
}

pub fn wb(h: &H) -> &Workbench {
    h.state().wb.as_ref().unwrap()
}

pub fn wb_mut(h: &mut H) -> &mut Workbench {
    h.state_mut().wb.as_mut().unwrap()
}

/// Steps the app until the worker (and any reconstruction) is done.
pub fn settle(h: &mut H) {
    let t0 = Instant::now();
    loop {
        h.step();
        let s = wb(h);
        if s.is_idle() && !s.is_reconstructing() {
            break;
        }
        assert!(t0.elapsed() < TIMEOUT, "the workbench did not settle");
        std::thread::sleep(Duration::from_millis(5));
    }
    h.run_ok();
}

pub fn last_message(h: &H) -> String {
    wb(h)
        .messages()
        .last()
        .map(|m| m.text.clone())
        .unwrap_or_default()
}

/// Asserts that the workbench's last message contains `part`.
pub fn assert_last_message(h: &H, part: &str) {
    let last = last_message(h);
    assert!(
        last.contains(part),
        "{part:?} not in the last message {last:?}"
    );
}
