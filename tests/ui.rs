//! Workbench UI tests: egui_kittest drives the real app (open, navigate, tune, rerun, reconstruct,
//! export, play) headless, and snapshots every view (`UPDATE_SNAPSHOTS=1` rewrites them).

#![cfg(feature = "gui")]
#![allow(clippy::unwrap_used)] // tests may panic

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Once, OnceLock};
use std::time::{Duration, Instant};

use egui_kittest::kittest::Queryable;
use egui_kittest::{Harness, SnapshotOptions};
use groovescope::app::{View, Workbench, WorkbenchOptions};
use groovescope::image::Image;
use groovescope::io::wav::WavBits;
use groovescope::pipeline::Stage;
use groovescope::playback::{AudioStatus, DeviceChoice};
use groovescope::synth::SynthConfig;

/// Longest wait for the worker or a reconstruction.
const TIMEOUT: Duration = Duration::from_secs(300);
/// Window size of every harness (points).
const SIZE: [f32; 2] = [1280.0, 800.0];

static ALSA: Once = Once::new();

/// Points ALSA at a silent null sink (no sound card here; never assert on timing).
fn quiet_audio() {
    ALSA.call_once(|| {
        let conf = Path::new(env!("CARGO_TARGET_TMPDIR")).join("alsa-null.conf");
        std::fs::write(
            &conf,
            "</usr/share/alsa/alsa.conf>\npcm.!default { type null }\n",
        )
        .unwrap();
        // SAFETY: runs once, before any test touches ALSA or reads the environment.
        unsafe { std::env::set_var("ALSA_CONFIG_PATH", &conf) };
    });
}

const SCAN_TOML: &str = "format = 1
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
fn write_scan(dir: &Path, groups: usize) {
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
fn rendered_scan(name: &str, cfg: SynthConfig) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("ui-scans-{}", std::process::id()))
        .join(name);
    let _ = std::fs::remove_dir_all(&dir);
    let sound = groovescope::synth::tone(440.0, 0.2, 44_100);
    groovescope::synth::render_scan(&sound, &cfg, &dir, &|_, _| {}, &AtomicBool::new(false))
        .unwrap();
    dir
}

/// A small synthetic lateral scan on the depth path: 3 groups of 8 frames of 256×320 px of a
/// 440 Hz tone, with `reference.wav`.
fn lateral_scan() -> PathBuf {
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

/// The bundled demo scan (dual focus, with `reference.wav`); when it is missing, a small
/// synthetic dual-focus scan (2 groups of 8 frames of 320×700 px) stands in.
fn demo_scan() -> PathBuf {
    static SCAN: OnceLock<PathBuf> = OnceLock::new();
    SCAN.get_or_init(|| {
        let demo = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/demo");
        if demo.join("scan.toml").is_file() {
            return demo;
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

fn options(tmp: &Path, scan: Option<PathBuf>, audio: DeviceChoice) -> WorkbenchOptions {
    WorkbenchOptions {
        scan,
        config_dir: Some(tmp.join("config")),
        audio,
        ..WorkbenchOptions::default()
    }
}

/// The workbench and the eframe frame it draws into (the harness owns both).
struct App {
    wb: Option<Workbench>,
    frame: eframe::Frame,
}

type H = Harness<'static, App>;

/// A harness running the real workbench: `App::ui` every step, as eframe would.
fn harness(opts: WorkbenchOptions) -> H {
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

fn wb(h: &H) -> &Workbench {
    h.state().wb.as_ref().unwrap()
}

fn wb_mut(h: &mut H) -> &mut Workbench {
    h.state_mut().wb.as_mut().unwrap()
}

/// Steps the app until the worker (and any reconstruction) is done.
fn settle(h: &mut H) {
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

fn last_message(h: &H) -> String {
    wb(h)
        .messages()
        .last()
        .map(|m| m.text.clone())
        .unwrap_or_default()
}

#[test]
fn opens_the_demo_scan_and_steps_through_groups() {
    let tmp = tempfile::tempdir().unwrap();
    let scan = demo_scan();
    let mut h = harness(options(tmp.path(), Some(scan.clone()), DeviceChoice::Off));
    settle(&mut h);
    let groups = wb(&h).scan().unwrap().groups.len();
    assert!(groups >= 2);
    assert_eq!(wb(&h).group(), 0);
    assert!(wb(&h).frames().is_some(), "frames of group 0 are loaded");
    h.get_by_label("next >").click();
    settle(&mut h);
    assert_eq!(wb(&h).group(), 1);
    h.get_by_label(&format!("group 1 / {}", groups - 1));
    assert!(wb(&h).frames().is_some(), "frames of group 1 are loaded");
    assert_eq!(wb(&h).stage_status(Stage::Derivatives).word(), "fresh");
    h.get_by_label("< previous").click();
    settle(&mut h);
    assert_eq!(wb(&h).group(), 0);
    // The scan is remembered for next time.
    assert_eq!(
        wb(&h).recent().first().cloned(),
        Some(scan.canonicalize().unwrap())
    );
}

#[test]
fn bad_input_gives_a_message_and_keeps_the_scan() {
    let tmp = tempfile::tempdir().unwrap();
    let good = lateral_scan();
    let mut h = harness(options(tmp.path(), Some(good.clone()), DeviceChoice::Off));
    settle(&mut h);
    // Not a scan.
    let not_scan = tmp.path().join("holiday_photos");
    std::fs::create_dir_all(&not_scan).unwrap();
    assert!(wb_mut(&mut h).open_scan(&not_scan).is_err());
    settle(&mut h);
    assert!(
        last_message(&h).contains("scan.toml is missing"),
        "{}",
        last_message(&h)
    );
    assert_eq!(wb(&h).scan().unwrap().dir, good);
    h.get_by_label_contains("scan.toml is missing");
    // A broken frame in the first group.
    let broken = tmp.path().join("broken");
    write_scan(&broken, 2);
    std::fs::write(broken.join("group_000/f03.png"), b"not a png").unwrap();
    wb_mut(&mut h).open_scan(&broken).unwrap();
    settle(&mut h);
    let msg = last_message(&h);
    assert!(
        msg.contains("f03.png") && msg.contains("stays open"),
        "{msg}"
    );
    assert_eq!(wb(&h).scan().unwrap().dir, good);
    // An invalid preset.
    let preset = tmp.path().join("bad.toml");
    std::fs::write(&preset, "[flow]\nlambda = \"soft\"\n").unwrap();
    let before = wb(&h).params().clone();
    assert!(wb_mut(&mut h).load_preset_from(&preset).is_err());
    h.run_ok();
    assert!(last_message(&h).contains("bad.toml"));
    assert_eq!(wb(&h).params(), &before);
}

#[test]
fn changing_lambda_reruns_flow_onward_and_the_flow_view_updates() {
    let tmp = tempfile::tempdir().unwrap();
    let scan = lateral_scan();
    let mut h = harness(options(tmp.path(), Some(scan), DeviceChoice::Off));
    settle(&mut h);
    wb_mut(&mut h).set_view(View::Flow);
    h.run_ok();
    for s in [Stage::Derivatives, Stage::Flow] {
        assert_eq!(wb(&h).stage_status(s).word(), "fresh", "{s:?}");
    }
    let derivs = wb(&h).cache().derivatives.clone().unwrap();
    let flows = wb(&h).cache().flows.clone().unwrap();
    let runs = Stage::ALL.map(|s| wb(&h).stage_runs(s));
    let lambda = wb(&h).params().flow.lambda;
    h.get_by_label("λ (smoothness)")
        .set_value_accesskit(f64::from(lambda) * 4.0);
    h.step();
    assert!((wb(&h).params().flow.lambda - lambda * 4.0).abs() < 1e-6);
    assert_ne!(wb(&h).stage_status(Stage::Flow).word(), "fresh");
    assert_eq!(wb(&h).stage_status(Stage::Derivatives).word(), "fresh");
    settle(&mut h);
    let c = wb(&h).cache();
    assert!(
        Arc::ptr_eq(&derivs, c.derivatives.as_ref().unwrap()),
        "derivatives kept"
    );
    assert!(
        !Arc::ptr_eq(&flows, c.flows.as_ref().unwrap()),
        "flow recomputed"
    );
    assert_eq!(wb(&h).stage_runs(Stage::Derivatives), runs[0]);
    assert_eq!(wb(&h).stage_runs(Stage::Flow), runs[1] + 1);
    assert_eq!(wb(&h).stage_status(Stage::Flow).word(), "fresh");
    h.get_by_label("flow: fresh");
    // Undo brings the old λ back and reruns flow again.
    wb_mut(&mut h).undo();
    settle(&mut h);
    assert_eq!(wb(&h).params().flow.lambda, lambda);
    assert_eq!(wb(&h).stage_runs(Stage::Flow), runs[1] + 2);
}

#[test]
fn changing_a_hough_range_reruns_stripes_onward_but_not_derivatives_or_flow() {
    let tmp = tempfile::tempdir().unwrap();
    let scan = demo_scan();
    let mut h = harness(options(tmp.path(), Some(scan), DeviceChoice::Off));
    settle(&mut h);
    let runs = Stage::ALL.map(|s| wb(&h).stage_runs(s));
    let flows = wb(&h).cache().flows.clone().unwrap();
    let mut p = wb(&h).params().clone();
    p.hough.theta_min_deg += 5.0;
    wb_mut(&mut h).set_params(p);
    assert_eq!(
        wb(&h).cache().first_stale(wb(&h).params()),
        Some(Stage::Stripes)
    );
    settle(&mut h);
    assert!(wb(&h).cache().stripes.is_some(), "the dual-focus path ran");
    let after = Stage::ALL.map(|s| wb(&h).stage_runs(s));
    assert_eq!(
        &after[..3],
        &runs[..3],
        "derivatives, flow and depth did not rerun"
    );
    assert_eq!(
        after[Stage::Stripes.index()],
        runs[Stage::Stripes.index()] + 1
    );
    assert!(Arc::ptr_eq(&flows, wb(&h).cache().flows.as_ref().unwrap()));
}

#[test]
fn reconstructs_exports_a_wav_and_reads_it_back() {
    let tmp = tempfile::tempdir().unwrap();
    let scan = demo_scan();
    let mut h = harness(options(tmp.path(), Some(scan), DeviceChoice::Off));
    settle(&mut h);
    wb_mut(&mut h).set_view(View::Waveform);
    h.run_ok();
    h.get_by_label("Reconstruct clip").click();
    h.step();
    assert!(wb(&h).is_reconstructing());
    settle(&mut h);
    let clip = wb(&h).clip().expect("a clip");
    let clip_len = clip.recon.audio.len();
    assert!(clip_len > 0);
    assert!(clip.reference.is_some(), "the scan has reference.wav");
    let wav = tmp.path().join("out.wav");
    wb_mut(&mut h).set_export_bits(WavBits::Int16);
    wb_mut(&mut h).request_export_wav(wav.clone(), false);
    h.run_ok();
    let reader = hound::WavReader::open(&wav).unwrap();
    assert_eq!(reader.spec().bits_per_sample, 16);
    assert_eq!(
        reader.len() as usize,
        clip_len * usize::from(reader.spec().channels)
    );
    let sidecar = std::fs::read_to_string(wav.with_extension("json")).unwrap();
    assert!(
        sidecar.contains("[flow]") && sidecar.contains("lambda"),
        "{sidecar}"
    );
    // A second export asks before replacing; "no" leaves the file alone.
    let before = std::fs::read(&wav).unwrap();
    wb_mut(&mut h).set_export_bits(WavBits::Float32);
    wb_mut(&mut h).request_export_wav(wav.clone(), false);
    h.run_ok();
    h.get_by_label("Replace");
    h.get_by_label("Cancel").click();
    h.run_ok();
    assert!(wb(&h).confirm().is_none());
    assert_eq!(std::fs::read(&wav).unwrap(), before);
    // "Replace" writes the new encoding.
    wb_mut(&mut h).request_export_wav(wav.clone(), false);
    h.run_ok();
    h.get_by_label("Replace").click();
    h.run_ok();
    assert_eq!(
        hound::WavReader::open(&wav).unwrap().spec().bits_per_sample,
        32
    );
}

#[test]
fn without_an_audio_device_the_play_controls_say_so() {
    let tmp = tempfile::tempdir().unwrap();
    let scan = lateral_scan();
    let mut h = harness(options(
        tmp.path(),
        Some(scan),
        DeviceChoice::Named("groovescope-no-such-device".into()),
    ));
    settle(&mut h);
    assert!(matches!(
        wb(&h).player().status(),
        AudioStatus::Unavailable(_)
    ));
    wb_mut(&mut h).set_view(View::Waveform);
    h.run_ok();
    // Said in the play controls and in the status bar; no play button to press.
    let said = h.get_all_by_label_contains("audio unavailable:").count();
    assert_eq!(said, 2);
    assert!(h.query_by_label("Play").is_none());
    // Everything else still works.
    h.get_by_label("next >").click();
    settle(&mut h);
    assert_eq!(wb(&h).group(), 1);
}

#[test]
fn plays_through_the_null_sink() {
    let tmp = tempfile::tempdir().unwrap();
    let scan = lateral_scan();
    let mut h = harness(options(tmp.path(), Some(scan), DeviceChoice::Default));
    settle(&mut h);
    if let AudioStatus::Unavailable(why) = wb(&h).player().status() {
        // Some machines have no ALSA at all; the message path is covered above.
        eprintln!("skipping playback: {why}");
        return;
    }
    wb_mut(&mut h).reconstruct(None);
    settle(&mut h);
    wb_mut(&mut h).set_view(View::Waveform);
    h.run_ok();
    h.get_by_label("Play").click();
    h.step();
    assert!(wb(&h).player().is_playing() || wb(&h).player().position_secs() == 0.0);
    h.get_by_label("Stop").click();
    h.step();
    assert!(!wb(&h).player().is_playing());
}

/// Masks the menu bar and the status bar (they name temporary folders), then snapshots.
fn snapshot(h: &mut H, name: &str) {
    let opts = SnapshotOptions::new()
        .threshold(4.0)
        .max_failed_pixels(4000);
    let bar = 34.0;
    h.mask(egui::Rect::from_min_max(
        egui::pos2(0.0, 0.0),
        egui::pos2(SIZE[0], bar),
    ));
    h.mask(egui::Rect::from_min_max(
        egui::pos2(0.0, SIZE[1] - bar),
        egui::pos2(SIZE[0], SIZE[1]),
    ));
    h.snapshot_options(name, &opts);
}

/// Snapshots of every view but Hough and stripes (with a tolerance: software rendering varies a
/// little), on the lateral scan: the depth path and the whole clip.
#[test]
fn snapshots_of_the_depth_path_views() {
    let tmp = tempfile::tempdir().unwrap();
    let mut h = harness(options(tmp.path(), Some(lateral_scan()), DeviceChoice::Off));
    settle(&mut h);
    wb_mut(&mut h).reconstruct(None);
    settle(&mut h);
    for v in View::ALL {
        if matches!(v, View::Hough | View::Stripes) {
            continue;
        }
        wb_mut(&mut h).set_view(v);
        h.run_ok();
        snapshot(&mut h, v.name());
    }
}

/// Snapshots of the Hough and stripes views (and the overview) on the dual-focus demo scan.
#[test]
fn snapshots_of_the_dual_focus_views() {
    let tmp = tempfile::tempdir().unwrap();
    let mut h = harness(options(tmp.path(), Some(demo_scan()), DeviceChoice::Off));
    settle(&mut h);
    for (v, name) in [
        (View::Hough, "hough"),
        (View::Stripes, "stripes"),
        (View::Overview, "overview_dual_focus"),
    ] {
        wb_mut(&mut h).set_view(v);
        h.run_ok();
        snapshot(&mut h, name);
    }
}

#[test]
fn exports_a_view_as_png_and_round_trips_a_preset() {
    let tmp = tempfile::tempdir().unwrap();
    let mut h = harness(options(tmp.path(), Some(lateral_scan()), DeviceChoice::Off));
    settle(&mut h);
    // A view as PNG: a capture of the view's area.
    let png = tmp.path().join("flow.png");
    wb_mut(&mut h).capture_view(png.clone(), View::Flow, false);
    let t0 = Instant::now();
    while !png.exists() && t0.elapsed() < TIMEOUT {
        h.step();
        std::thread::sleep(Duration::from_millis(5));
    }
    let img = image::open(&png).unwrap().to_rgba8();
    assert!(
        img.width() > 200 && img.height() > 200,
        "{:?}",
        img.dimensions()
    );
    assert!(img.width() < SIZE[0] as u32, "cropped to the view");
    // Presets: save, change, load back (an undoable change), never overwrite silently.
    let preset = tmp.path().join("disc.toml");
    wb_mut(&mut h).save_preset_to(&preset, false).unwrap();
    assert!(wb_mut(&mut h).save_preset_to(&preset, false).is_err());
    let saved = wb(&h).params().clone();
    let mut p = saved.clone();
    p.flow.lambda *= 3.0;
    p.hough.window_rho_px += 2.0;
    wb_mut(&mut h).set_params(p.clone());
    settle(&mut h);
    wb_mut(&mut h).load_preset_from(&preset).unwrap();
    assert_eq!(wb(&h).params(), &saved);
    wb_mut(&mut h).undo();
    assert_eq!(wb(&h).params(), &p);
    settle(&mut h);
}

#[test]
fn per_disc_preset_loads_on_open_and_metadata_saves_back() {
    let tmp = tempfile::tempdir().unwrap();
    let scan = rendered_scan(
        "own",
        SynthConfig {
            frames_per_group: 7,
            max_groups: Some(2),
            ..SynthConfig::quick_test()
        },
    );
    let mut preset = groovescope::pipeline::PipelineParams::default();
    preset.flow.lambda = 0.125;
    std::fs::write(scan.join("preset.toml"), preset.to_toml_string().unwrap()).unwrap();
    let mut h = harness(options(tmp.path(), Some(scan.clone()), DeviceChoice::Off));
    settle(&mut h);
    assert_eq!(
        wb(&h).params().flow.lambda,
        0.125,
        "the scan's preset.toml was loaded"
    );
    // The metadata form's save path: validated, written atomically, the group reruns with it.
    let runs = wb(&h).stage_runs(Stage::Derivatives);
    let mut meta = wb(&h).scan().unwrap().meta.clone();
    meta.record.rpm = 45.0;
    wb_mut(&mut h).save_meta(meta.clone()).unwrap();
    settle(&mut h);
    let back = groovescope::io::Scan::open(&scan).unwrap();
    assert_eq!(back.meta.record.rpm, 45.0);
    assert!(
        back.meta.extra.contains_key("synth"),
        "unknown tables are kept"
    );
    assert_eq!(wb(&h).stage_runs(Stage::Derivatives), runs + 1);
    let mut bad = meta;
    bad.camera.pixel_pitch_um = -1.0;
    assert!(wb_mut(&mut h).save_meta(bad).is_err());
    assert_eq!(
        groovescope::io::Scan::open(&scan)
            .unwrap()
            .meta
            .camera
            .pixel_pitch_um,
        back.meta.camera.pixel_pitch_um
    );
}
