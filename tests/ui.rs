//! Workbench UI tests: egui_kittest drives the real app (open, navigate, tune, rerun, reconstruct,
//! export, play) headless, and snapshots every view (`UPDATE_SNAPSHOTS=1` rewrites them).

#![cfg(feature = "gui")]
#![allow(clippy::unwrap_used)] // tests may panic

mod gui_common;
#[path = "ui_parts/layout.rs"]
mod layout;
#[path = "ui_parts/no_scan.rs"]
mod no_scan;
#[path = "ui_parts/overwrite.rs"]
mod overwrite;
#[path = "ui_parts/still_ab.rs"]
mod still_ab;
#[path = "ui_parts/still_mode.rs"]
mod still_mode;

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use egui_kittest::SnapshotOptions;
use egui_kittest::kittest::Queryable;
use groovescope::app::View;
use groovescope::io::wav::WavBits;
use groovescope::pipeline::Stage;
use groovescope::pipeline::dsp::EqCurve;
use groovescope::playback::{AudioStatus, DeviceChoice};
use groovescope::synth::SynthConfig;
use gui_common::*;

#[test]
fn opens_the_demo_scan_and_steps_through_groups() {
    let scan = demo_scan();
    let (_tmp, mut h) = settled_on(&scan);
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

/// Leaves group 1 of `scan` 4 frames.
fn cut_short(scan: &Path) {
    for t in 4..7 {
        std::fs::remove_file(scan.join(format!("group_001/f{t:02}.png"))).unwrap();
    }
}

/// Removes group 1's folder from `scan`.
fn skip_group(scan: &Path) {
    std::fs::remove_dir_all(scan.join("group_001")).unwrap();
}

#[test]
fn bad_input_gives_a_message_and_keeps_the_scan() {
    let good = lateral_scan();
    let (tmp, mut h) = settled_on(&good);
    // Not a scan.
    let not_scan = tmp.path().join("holiday_photos");
    std::fs::create_dir_all(&not_scan).unwrap();
    assert!(wb_mut(&mut h).open_scan(&not_scan).is_err());
    settle(&mut h);
    assert_last_message(&h, "scan.toml is missing");
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
    // A group in the middle that cannot run, cut short or skipped by the numbering: the scan
    // opens, the group keeps its place and says why, and the others still run.
    let damages = [
        ("short", cut_short as fn(&Path), "4 frames", None),
        (
            "holey",
            skip_group,
            "group folder is missing",
            Some("numbering skips 1 group folder among groups 0..3 (group_001"),
        ),
    ];
    for (name, damage, says, on_open) in damages {
        let scan = tmp.path().join(name);
        write_scan(&scan, 3);
        damage(&scan);
        wb_mut(&mut h).open_scan(&scan).unwrap();
        settle(&mut h);
        assert_eq!(wb(&h).scan().unwrap().dir, scan);
        assert_eq!(wb(&h).scan().unwrap().groups.len(), 3);
        if let Some(warned) = on_open {
            let said = wb(&h)
                .messages()
                .iter()
                .any(|m| m.error && m.text.contains(warned));
            assert!(said, "{:?}", wb(&h).messages());
        }
        h.get_by_label("next >").click();
        settle(&mut h);
        assert_eq!(wb(&h).group(), 1);
        let msg = last_message(&h);
        assert!(msg.contains(says) && msg.contains("group_001"), "{msg}");
        // Every stage says it failed and why: none waits as stale for a run that cannot come.
        for s in Stage::ALL {
            let status = wb(&h).stage_status(s);
            assert_eq!(status.word(), "failed", "{name}: {s:?}");
            assert!(format!("{status:?}").contains(says), "{name}: {status:?}");
        }
        h.get_by_label("next >").click();
        settle(&mut h);
        assert_eq!(wb(&h).group(), 2);
        assert!(wb(&h).frames().is_some(), "frames of group 2 are loaded");
    }
    // An unreadable frame in group 1, mended on disk: any stage's rerun reads the frames again.
    let scan = tmp.path().join("mended");
    write_scan(&scan, 3);
    let frame = scan.join("group_001/f03.png");
    let good_frame = std::fs::read(&frame).unwrap();
    std::fs::write(&frame, b"not a png").unwrap();
    wb_mut(&mut h).open_scan(&scan).unwrap();
    settle(&mut h);
    h.get_by_label("next >").click();
    settle(&mut h);
    assert_eq!(wb(&h).stage_status(Stage::Orientation).word(), "failed");
    std::fs::write(&frame, good_frame).unwrap();
    wb_mut(&mut h).rerun(Stage::Orientation);
    settle(&mut h);
    assert!(wb(&h).frames().is_some(), "group 1's frames are read again");
    assert_eq!(wb(&h).stage_status(Stage::Derivatives).word(), "fresh");
    // An invalid preset.
    let preset = tmp.path().join("bad.toml");
    std::fs::write(&preset, "[flow]\nlambda = \"soft\"\n").unwrap();
    let before = wb(&h).params().clone();
    assert!(wb_mut(&mut h).load_preset_from(&preset).is_err());
    h.run_ok();
    assert_last_message(&h, "bad.toml");
    assert_eq!(wb(&h).params(), &before);
}

#[test]
fn changing_lambda_reruns_flow_onward_and_the_flow_view_updates() {
    let (_tmp, mut h) = settled_on(&lateral_scan());
    wb_mut(&mut h).set_view(View::Flow);
    h.run_ok();
    for s in [Stage::Derivatives, Stage::Flow] {
        assert_eq!(wb(&h).stage_status(s).word(), "fresh", "{s:?}");
    }
    let derivs = wb(&h).cache().derivatives().cloned().unwrap();
    let flows = wb(&h).cache().flows().cloned().unwrap();
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
        Arc::ptr_eq(&derivs, c.derivatives().unwrap()),
        "derivatives kept"
    );
    assert!(!Arc::ptr_eq(&flows, c.flows().unwrap()), "flow recomputed");
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
    let (_tmp, mut h) = settled_on(&demo_scan());
    let runs = Stage::ALL.map(|s| wb(&h).stage_runs(s));
    let flows = wb(&h).cache().flows().cloned().unwrap();
    let mut p = wb(&h).params().clone();
    p.hough.theta_min_deg += 5.0;
    wb_mut(&mut h).set_params(p);
    assert_eq!(
        wb(&h).cache().first_stale(wb(&h).params()),
        Some(Stage::Stripes)
    );
    settle(&mut h);
    assert!(
        wb(&h).cache().stripes().is_some(),
        "the dual-focus path ran"
    );
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
    assert!(Arc::ptr_eq(&flows, wb(&h).cache().flows().unwrap()));
}

#[test]
fn reconstructs_exports_a_wav_and_reads_it_back() {
    let scan = demo_scan();
    let (tmp, mut h) = settled_on(&scan);
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
    let (first, _) = clip.group_span_secs(clip.groups.start + 2).unwrap();
    let (_, last) = clip.group_span_secs(clip.groups.start + 3).unwrap();
    let clip_groups = [clip.groups.start, clip.groups.end];
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
    let (description, _, _, history) =
        groovescope::io::bwf::read_bext(&std::fs::read(&wav).unwrap()).unwrap();
    assert!(description.contains("lateral-cut disc at"), "{description}");
    assert!(history[1].contains(",W=16,"), "{history:?}");
    // A selection's sidecar names the groups its stretch covers, not the whole clip's.
    let part = tmp.path().join("part.wav");
    wb_mut(&mut h).set_selection(Some((first + 1e-4, last - 1e-4)));
    wb_mut(&mut h).request_export_wav(part.clone(), true);
    h.run_ok();
    let sidecar: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(part.with_extension("json")).unwrap())
            .unwrap();
    let groups: [usize; 2] = serde_json::from_value(sidecar["groups"].clone()).unwrap();
    assert!(
        groups[0] > clip_groups[0] && groups[1] <= clip_groups[0] + 5,
        "{groups:?} of {clip_groups:?}"
    );
    assert_eq!(sidecar["clip_groups"], serde_json::json!(clip_groups));
    wb_mut(&mut h).set_selection(None);
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

/// Per-pixel colour difference a snapshot tolerates (software rendering may differ a little
/// from machine to machine).
const SNAPSHOT_THRESHOLD: f32 = 4.0;
/// Pixels beyond [`SNAPSHOT_THRESHOLD`] a snapshot tolerates. Nothing on screen depends on the
/// clock (`hide_timings`), so a run renders the same pixels as the last; a one-label change is
/// about 100 pixels and moved wall lines or curves thousands, so this catches both.
const SNAPSHOT_MAX_FAILED_PIXELS: usize = 60;

/// Masks the menu bar and the status bar (they name temporary folders), then snapshots.
fn snapshot(h: &mut H, name: &str) {
    let opts = SnapshotOptions::new()
        .threshold(SNAPSHOT_THRESHOLD)
        .max_failed_pixels(SNAPSHOT_MAX_FAILED_PIXELS);
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
    let (_tmp, mut h) = settled_on(&lateral_scan());
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
    let (_tmp, mut h) = settled_on(&demo_scan());
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
    let (tmp, mut h) = settled_on(&lateral_scan());
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

/// A two-group quick-test scan (`frames_per_group` frames each) with its own preset.toml, the
/// defaults but for the flow's λ.
fn scan_with_lambda_preset(name: &str, frames_per_group: usize, lambda: f32) -> PathBuf {
    let scan = rendered_scan(
        name,
        SynthConfig {
            frames_per_group,
            max_groups: Some(2),
            ..SynthConfig::quick_test()
        },
    );
    let mut preset = groovescope::pipeline::PipelineParams::default();
    preset.flow.lambda = lambda;
    std::fs::write(scan.join("preset.toml"), preset.to_toml_string().unwrap()).unwrap();
    scan
}

#[test]
fn per_disc_preset_loads_on_open_and_metadata_saves_back() {
    let scan = scan_with_lambda_preset("own", 7, 0.125);
    let (_tmp, mut h) = settled_on(&scan);
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

/// Stage outputs a scan's group 0 ends with, as text (`{:?}` reads floats back to the same bits).
fn group_outputs(h: &H) -> String {
    let c = wb(h).cache();
    format!("{:?}|{:?}|{:?}", c.depth(), c.orientation(), c.signal())
}

/// Issue 20: settings never leak from one disc into the next.
#[test]
fn a_second_scan_without_a_preset_runs_on_the_defaults_and_says_so() {
    let a = scan_with_lambda_preset("with-preset", 8, 0.2);
    let b = lateral_scan();
    let (_tmp, mut h) = settled_on(&a);
    assert_eq!(
        wb(&h).params().flow.lambda,
        0.2,
        "scan A runs on its preset"
    );
    wb_mut(&mut h).open_scan(&b).unwrap();
    settle(&mut h);
    assert_eq!(wb(&h).scan().unwrap().dir, b);
    assert_eq!(
        wb(&h).params(),
        &groovescope::pipeline::PipelineParams::default(),
        "scan B has no preset: the defaults"
    );
    h.get_by_label("parameters: defaults");
    assert_eq!(wb(&h).can_undo_redo(), (false, false), "no history from A");
    assert!(
        wb(&h)
            .messages()
            .iter()
            .any(|m| m.text.contains("running on the defaults")),
        "it says which"
    );
    // B gives what a fresh launch on B gives.
    let switched = group_outputs(&h);
    let tmp2 = tempfile::tempdir().unwrap();
    let mut fresh = harness(options(tmp2.path(), Some(b), DeviceChoice::Off));
    settle(&mut fresh);
    assert!(
        switched == group_outputs(&fresh),
        "scan B after scan A differs from a fresh launch on B"
    );
    // And back to A: its preset again, said so.
    wb_mut(&mut h).open_scan(&a).unwrap();
    settle(&mut h);
    assert_eq!(wb(&h).params().flow.lambda, 0.2);
    h.get_by_label_contains("parameters: preset");
}

/// Issue 20: with changed knobs, opening another scan asks once; "Cancel" keeps everything.
#[test]
fn switching_scans_with_unsaved_knobs_asks_once() {
    let tmp = tempfile::tempdir().unwrap();
    let a = lateral_scan();
    let b = tmp.path().join("other");
    write_scan(&b, 2);
    let mut h = harness(options(tmp.path(), Some(a.clone()), DeviceChoice::Off));
    settle(&mut h);
    let mut p = wb(&h).params().clone();
    p.flow.lambda *= 2.0;
    wb_mut(&mut h).set_params(p.clone());
    settle(&mut h);
    h.get_by_label("parameters: modified from the defaults");
    wb_mut(&mut h).open_scan(&b).unwrap();
    h.run_ok();
    assert!(matches!(
        wb(&h).confirm(),
        Some(groovescope::app::files::Confirm::SwitchScan(_))
    ));
    h.get_by_label("Cancel").click();
    settle(&mut h);
    assert_eq!(wb(&h).scan().unwrap().dir, a);
    assert_eq!(wb(&h).params(), &p);
    wb_mut(&mut h).open_scan(&b).unwrap();
    h.run_ok();
    h.get_by_label("Open anyway").click();
    settle(&mut h);
    assert_eq!(wb(&h).scan().unwrap().dir, b);
    assert!(wb(&h).confirm().is_none(), "asked once");
}

/// Issue 20: where no native dialog can open (no portal, no zenity: the test process is such a
/// machine), the app says so and offers its own path field, which works.
#[test]
fn a_dialog_failure_shows_a_message_and_the_path_field() {
    let scan = lateral_scan();
    let (tmp, mut h) = settled_on(&scan);
    h.get_by_label("File").click();
    h.run_ok();
    h.get_by_label("Save preset…").click();
    h.run_ok();
    assert_last_message(&h, "no file dialog can open here");
    assert!(
        h.get_all_by_label_contains("no file dialog can open here")
            .count()
            >= 1
    );
    let prompt = wb(&h).path_prompt().expect("the path field");
    assert_eq!(
        prompt.text,
        scan.join("preset.toml").display().to_string(),
        "it starts in the scan's folder with the scan's preset name"
    );
    let target = tmp.path().join("typed.toml");
    let field = h.get_by_label("type the file's path:");
    field.focus();
    h.run_ok();
    h.key_press_modifiers(egui::Modifiers::COMMAND, egui::Key::A);
    h.get_by_label("type the file's path:")
        .type_text(&target.display().to_string());
    h.run_ok();
    h.get_by_label("OK").click();
    h.run_ok();
    assert!(target.is_file(), "{}", last_message(&h));
    assert!(wb(&h).path_prompt().is_none());
    h.get_by_label_contains("parameters: preset");
}

/// Issue 20: a drag that starts on a Hough window's edge resizes the window (and does not
/// pan the plot), although egui reports the drag only once the pointer has left the edge.
#[test]
fn a_drag_that_starts_on_a_hough_edge_resizes_the_window() {
    let (_tmp, mut h) = settled_on(&demo_scan());
    wb_mut(&mut h).set_view(View::Hough);
    h.run_ok();
    let before = wb(&h)
        .hough_window_rects()
        .first()
        .copied()
        .expect("a window");
    let theta = wb(&h).params().hough.window_theta_deg;
    let start = egui::pos2(before.right(), before.center().y);
    h.hover_at(start);
    h.step();
    h.drag_at(start);
    h.step();
    for dx in [3.0, 8.0, 14.0, 20.0] {
        h.hover_at(start + egui::vec2(dx, 0.0));
        h.step();
    }
    h.drop_at(start + egui::vec2(20.0, 0.0));
    h.step();
    settle(&mut h);
    let after = wb(&h).hough_window_rects().first().copied().unwrap();
    assert!(
        wb(&h).params().hough.window_theta_deg > theta,
        "the window grew: {} → {}",
        theta,
        wb(&h).params().hough.window_theta_deg
    );
    assert!(
        (after.center().x - before.center().x).abs() < 1.0,
        "the plot did not pan: {before:?} → {after:?}"
    );
    assert!(
        (after.right() - (start.x + 20.0)).abs() < 2.0,
        "the edge followed the pointer: {before:?} → {after:?}"
    );
}

/// Issue 20: saving a preset does not move the parameter list (the next click would hit the
/// wrong knob); neither does loading one or changing a knob.
#[test]
fn the_parameter_list_does_not_move_when_a_preset_is_saved() {
    let (tmp, mut h) = settled_on(&lateral_scan());
    let place = |h: &H| h.get_by_label("λ (smoothness)").rect();
    let before = place(&h);
    let preset = tmp
        .path()
        .join("a-rather-long-folder-name")
        .join("disc-preset.toml");
    std::fs::create_dir_all(preset.parent().unwrap()).unwrap();
    wb_mut(&mut h).save_preset_to(&preset, false).unwrap();
    h.run_ok();
    assert_eq!(place(&h), before, "saving moved the list");
    h.get_by_label_contains("parameters: preset");
    let mut p = wb(&h).params().clone();
    p.hough.window_rho_px += 1.0;
    wb_mut(&mut h).set_params(p);
    settle(&mut h);
    h.get_by_label_contains("parameters: modified since preset");
    assert_eq!(place(&h), before, "a change moved the list");
    wb_mut(&mut h).load_preset_from(&preset).unwrap();
    settle(&mut h);
    assert_eq!(place(&h), before, "loading moved the list");
}

/// Issue 20: the health strip has one cell per group, filled by the reconstruction, and a
/// click on a cell shows that group; the waveform's time axis maps to the same groups.
#[test]
fn the_health_strip_has_one_cell_per_group_and_a_click_navigates() {
    let (_tmp, mut h) = settled_on(&demo_scan());
    let groups = wb(&h).scan().unwrap().groups.len();
    let cells = |h: &H| h.get_all_by_label_contains("health of group ").count();
    assert_eq!(cells(&h), groups, "one cell per group before a clip");
    wb_mut(&mut h).reconstruct(None);
    settle(&mut h);
    assert_eq!(cells(&h), groups);
    let health = wb(&h).health().clone();
    assert!((0..groups).all(|g| health.cell(g).is_some_and(|c| c.ran)));
    let target = groups / 2;
    h.get_by_label(&format!("health of group {target}")).click();
    settle(&mut h);
    assert_eq!(wb(&h).group(), target);
    let clip = wb(&h).clip().unwrap();
    for g in 0..groups {
        let (a, b) = clip.group_span_secs(g).expect("each group has a span");
        assert!(a <= b && a >= -1e-9, "group {g}: {a}..{b}");
        assert_eq!(clip.group_at_secs((a + b) / 2.0), Some(g));
    }
}

/// Issue 20: after a change, the previous clip stays for A/B; "reconstruct around" runs only
/// the groups near the one shown; the plain 16-bit export writes 16-bit 44.1 kHz.
#[test]
fn the_previous_clip_stays_for_ab_and_a_range_around_the_group_reconstructs() {
    let (tmp, mut h) = settled_on(&demo_scan());
    wb_mut(&mut h).reconstruct(None);
    settle(&mut h);
    let first = wb(&h).clip().unwrap().recovered.samples.clone();
    wb_mut(&mut h).set_group(4);
    settle(&mut h);
    let mut p = wb(&h).params().clone();
    p.dsp.lowpass_hz = 2000.0;
    wb_mut(&mut h).set_params(p);
    settle(&mut h);
    wb_mut(&mut h).reconstruct_around(1);
    settle(&mut h);
    let clip = wb(&h).clip().unwrap();
    assert_eq!(clip.groups, 3..6);
    let buffers = wb(&h).player().buffers().unwrap();
    assert_eq!(buffers.sources.len(), 3, "clip, previous clip, reference");
    let laid = &buffers.sources[1][0];
    assert_eq!(laid.len(), clip.recovered.samples.len());
    // The previous clip is the first one, laid on the new clip's time axis.
    assert!(laid.iter().any(|v| *v != 0.0));
    assert!(laid.iter().all(|v| first.contains(v) || *v == 0.0));
    let plain = &groovescope::app::export::EXPORT_FORMATS[1];
    wb_mut(&mut h).set_export_format(plain);
    let wav = tmp.path().join("plain.wav");
    wb_mut(&mut h).request_export_wav(wav.clone(), false);
    h.run_ok();
    let spec = hound::WavReader::open(&wav).unwrap().spec();
    assert_eq!((spec.bits_per_sample, spec.sample_rate), (16, 44_100));
    let sidecar = std::fs::read_to_string(wav.with_extension("json")).unwrap();
    assert!(sidecar.contains("\"params_state\""), "{sidecar}");
    assert!(
        sidecar.contains("\"filters\": \"DC block 10 Hz"),
        "{sidecar}"
    );
    assert!(sidecar.contains("\"modified\": true"), "{sidecar}");
}

/// The custom 78 EQ curve: its numbers are rows of the filter / EQ section, editing one sets
/// its knob, and the exported sidecar names the curve the clip went through.
#[test]
fn the_custom_eq_curve_is_set_in_the_panel_and_recorded_in_the_export() {
    let (tmp, mut h) = settled_on(&demo_scan());
    // The section lies below the panel's fold.
    h.get_by_label("filter / EQ (clip)").click_accesskit();
    h.run_ok();
    let mut p = wb(&h).params().clone();
    p.dsp.eq = EqCurve::Custom;
    wb_mut(&mut h).set_params(p);
    h.run_ok();
    h.get_by_label("custom: turnover (Hz)")
        .set_value_accesskit(300.0);
    h.step();
    h.get_by_label("custom: roll-off at 10 kHz (dB)")
        .set_value_accesskit(16.0);
    h.step();
    let dsp = wb(&h).params().dsp.clone();
    assert_eq!(
        (dsp.eq, dsp.eq_turnover_hz, dsp.eq_rolloff_db),
        (EqCurve::Custom, 300.0, 16.0)
    );
    wb_mut(&mut h).reconstruct(None);
    settle(&mut h);
    assert_eq!(wb(&h).clip().unwrap().params.dsp, dsp);
    let wav = tmp.path().join("custom-eq.wav");
    wb_mut(&mut h).request_export_wav(wav.clone(), false);
    h.run_ok();
    let sidecar = std::fs::read_to_string(wav.with_extension("json")).unwrap();
    assert!(
        sidecar.contains("playback EQ 300 Hz turnover, bass shelf 50 Hz, −16 dB at 10 kHz"),
        "{sidecar}"
    );
}

/// A change of the `[dsp]` table alone refinishes the clip from the groups it kept: no group
/// runs again, and the sound is the one a whole reconstruction with the new params makes. A
/// change of any other knob runs the groups again.
#[test]
fn a_filter_change_refinishes_the_clip_without_running_its_groups() {
    use groovescope::engine::{ReconstructOptions, reconstruct};
    let (_tmp, mut h) = settled_on(&demo_scan());
    wb_mut(&mut h).reconstruct(None);
    settle(&mut h);
    let first = wb(&h).clip().unwrap();
    assert!(!first.refinished && first.groups_before_finish.is_some());
    let mut p = wb(&h).params().clone();
    p.dsp.eq = EqCurve::Riaa;
    p.dsp.lowpass_hz = 5000.0;
    wb_mut(&mut h).set_params(p.clone());
    h.run_ok();
    h.get_by_label_contains("only the finish runs again");
    wb_mut(&mut h).reconstruct(None);
    settle(&mut h);
    assert_last_message(&h, "no group ran again");
    let clip = wb(&h).clip().unwrap();
    assert!(clip.refinished);
    assert_eq!(clip.params, p);
    let scan = groovescope::io::Scan::open(&demo_scan()).unwrap();
    let opts = ReconstructOptions {
        params: p.clone(),
        groups: None,
        keep_going: true,
    };
    let whole = reconstruct(&scan, &opts, &mut |_| {}, &Default::default()).unwrap();
    assert_eq!(clip.recon.audio.channels, whole.audio.channels);
    assert_eq!(clip.recon.gain_per_mm_s, whole.gain_per_mm_s);
    assert_eq!(
        clip.recon.scores.as_ref().map(|s| s.snr_db),
        whole.scores.as_ref().map(|s| s.snr_db)
    );
    p.orientation.neighbourhood_px += 20;
    wb_mut(&mut h).set_params(p);
    h.run_ok();
    wb_mut(&mut h).reconstruct(None);
    settle(&mut h);
    assert!(!wb(&h).clip().unwrap().refinished);
}

/// Issue 20: the arrow keys step through the group's frames.
#[test]
fn arrow_keys_step_frames() {
    let (_tmp, mut h) = settled_on(&lateral_scan());
    let f = wb(&h).frame();
    h.key_press(egui::Key::ArrowRight);
    h.run_ok();
    assert_eq!(wb(&h).frame(), f + 1);
    h.key_press(egui::Key::ArrowLeft);
    h.key_press(egui::Key::ArrowLeft);
    h.run_ok();
    assert_eq!(wb(&h).frame(), f - 1);
}

/// Issue 20: while a reconstruction runs, "play so far" hands the player the groups finished
/// so far; the whole clip replaces them when it is done.
#[test]
fn the_groups_finished_so_far_can_be_played_while_reconstructing() {
    let (_tmp, mut h) = settled_on(&demo_scan());
    wb_mut(&mut h).reconstruct(None);
    wb_mut(&mut h).play_so_far();
    let mut partial_len = None;
    let t0 = Instant::now();
    while wb(&h).is_reconstructing() || !wb(&h).is_idle() {
        h.step();
        if wb(&h).clip().is_none()
            && let Some(b) = wb(&h).player().buffers().filter(|b| !b.is_empty())
        {
            partial_len = partial_len.or(Some(b.len()));
        }
        assert!(t0.elapsed() < TIMEOUT);
        std::thread::sleep(Duration::from_millis(2));
    }
    h.run_ok();
    let full = wb(&h).clip().unwrap().recon.audio.len();
    let partial = partial_len.expect("the groups so far reached the player");
    assert!(partial > 0 && partial < full, "{partial} of {full}");
    assert_eq!(wb(&h).player().buffers().unwrap().len(), full);
}

/// The edges view says what the edge stage read, border by border: on the demo scan every
/// border is seen on at least 90 % of the group's samples, and the frames' pixel noise reads
/// near the σ they were rendered with. With the flow method alone the stage
/// does not run, and the view says so.
#[test]
fn the_edges_view_shows_each_border_read_or_why_none() {
    use egui_kittest::kittest::NodeT;
    let (_tmp, mut h) = settled_on(&demo_scan());
    wb_mut(&mut h).set_view(View::Edges);
    h.run_ok();
    let node = h.get_by_label_contains("seen: left land");
    let line = node
        .accesskit_node()
        .label()
        .or_else(|| node.accesskit_node().value())
        .unwrap()
        .to_string();
    let seen: Vec<(usize, usize)> = line
        .split("seen: ")
        .nth(1)
        .unwrap()
        .split(", ")
        .map(|part| {
            let frac = part.split_whitespace().find(|w| w.contains('/')).unwrap();
            let (a, b) = frac.split_once('/').unwrap();
            (a.parse().unwrap(), b.parse().unwrap())
        })
        .collect();
    assert_eq!(seen.len(), 4, "{line}");
    // The demo was rendered 8-bit with σ = 0.5 grey levels of noise: under the noisy threshold.
    let noise: f64 = line
        .split("pixel noise ")
        .nth(1)
        .and_then(|t| t.split_whitespace().next())
        .and_then(|t| t.parse().ok())
        .unwrap();
    assert!((0.35..0.65).contains(&noise), "{line}");
    assert!(line.contains("at most ±24 px"), "{line}");
    assert!(
        seen.iter().all(|&(a, b)| b > 50 && 10 * a >= 9 * b),
        "{line}"
    );
    h.get_by_label_contains("a lateral cut: both walls move as one");
    let mut p = wb(&h).params().clone();
    p.method = groovescope::pipeline::Method::Flow;
    wb_mut(&mut h).set_params(p);
    settle(&mut h);
    h.run_ok();
    h.get_by_label_contains("the flow method alone reads none");
}
