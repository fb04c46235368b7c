//! Workbench tests of the still mode (issue 17 item 3): a generated still opens in the still
//! window with the settings its `truth.toml` gives, its grooves are found and one decoded off
//! the UI thread; picking another groove gives that groove's tone; the decode cancels; the
//! sound plays (or says why not) and exports without overwriting; a still with no groove says
//! so, naming the file.

use std::path::{Path, PathBuf};

use egui_kittest::kittest::Queryable;
use groovescope::io::Cut;
use groovescope::pipeline::still::Axis;
use groovescope::pipeline::still::measure::dominant_frequency_hz;
use groovescope::playback::DeviceChoice;
use groovescope::synth::still::{StillConfig, StillScene, write_still};

use super::gui_common::*;

/// A small generated still (3 grooves, a tone on each) in `dir`: the image and each groove's
/// tone (Hz).
fn small_still(dir: &Path, axis: Axis) -> (PathBuf, Vec<f64>) {
    let cfg = StillConfig {
        length_px: 1200,
        across_px: 400,
        grooves: 3,
        axis,
        cut: Cut::Lateral,
        text: "GS".into(),
        ..StillConfig::default()
    };
    let scene = StillScene::new(&cfg, None).unwrap();
    let out = dir.join(format!("still-{axis:?}"));
    let summary = write_still(&scene, &out).unwrap();
    let tones = scene
        .grooves
        .iter()
        .map(|g| g.tones_hz.unwrap().0)
        .collect();
    (summary.image, tones)
}

fn on_still(still: &Path) -> (tempfile::TempDir, H) {
    let tmp = tempfile::tempdir().unwrap();
    let mut opts = options(tmp.path(), None, DeviceChoice::Off);
    opts.still = Some(still.to_path_buf());
    let mut h = harness(opts);
    assert!(wb(&h).still_open(), "the still window opens");
    settle(&mut h);
    (tmp, h)
}

fn dominant(h: &H) -> f64 {
    let run = wb(h).still_doc().unwrap().run.clone().unwrap();
    dominant_frequency_hz(&run.audio.channels[0], f64::from(run.audio.sample_rate_hz)).unwrap()
}

#[test]
fn a_still_opens_its_grooves_are_found_and_another_one_picked() {
    let dir = tempfile::tempdir().unwrap();
    for axis in [Axis::Vertical, Axis::Horizontal] {
        let (image, tones) = small_still(dir.path(), axis);
        let (_tmp, mut h) = on_still(&image);
        let doc = wb(&h).still_doc().expect("the still opened");
        assert_eq!(doc.setup.axis, axis, "the axis comes from truth.toml");
        let found = doc.found.clone().expect("grooves found");
        assert_eq!(found.grooves.grooves.len(), 3, "{axis:?}");
        let run = doc.run.clone().expect("a groove decoded");
        // truth.toml names the middle groove (the one at the configured radius).
        assert_eq!(run.analysis.chosen, 1, "{axis:?}");
        let got = dominant(&h);
        assert!(
            (got / tones[1] - 1.0).abs() < 0.01,
            "{axis:?}: {got} vs {}",
            tones[1]
        );
        assert_last_message(&h, "groove 2 of 3 decoded");
        // The groove buttons decode another groove, in the background, without finding the
        // grooves again.
        h.get_by_label("groove 3").click();
        h.step();
        assert!(wb(&h).is_decoding_still(), "it decodes off the UI thread");
        settle(&mut h);
        let doc = wb(&h).still_doc().unwrap();
        assert!(std::sync::Arc::ptr_eq(doc.found.as_ref().unwrap(), &found));
        assert_eq!(doc.run.as_ref().unwrap().analysis.chosen, 2);
        let got = dominant(&h);
        assert!(
            (got / tones[2] - 1.0).abs() < 0.01,
            "{axis:?}: {got} vs {}",
            tones[2]
        );
    }
}

#[test]
fn a_still_decode_cancels_and_keeps_what_was_there() {
    let dir = tempfile::tempdir().unwrap();
    let (image, _) = small_still(dir.path(), Axis::Vertical);
    let (_tmp, mut h) = on_still(&image);
    let before = wb(&h).still_doc().unwrap().run.clone().unwrap();
    // New settings: the grooves must be found again, and that is what is cancelled.
    wb_mut(&mut h).still_setup_mut().unwrap().um_per_px *= 1.01;
    wb_mut(&mut h).decode_still_groove(None);
    wb_mut(&mut h).cancel_still();
    settle(&mut h);
    assert_eq!(last_message(&h), "still decode cancelled");
    let doc = wb(&h).still_doc().unwrap();
    assert!(std::sync::Arc::ptr_eq(doc.run.as_ref().unwrap(), &before));
}

#[test]
fn the_groove_plays_or_says_why_and_exports_without_overwriting() {
    let dir = tempfile::tempdir().unwrap();
    let (image, _) = small_still(dir.path(), Axis::Horizontal);
    let (tmp, mut h) = on_still(&image);
    h.get_by_label("Listen").click();
    h.run_ok();
    let samples = wb(&h)
        .still_doc()
        .unwrap()
        .run
        .as_ref()
        .unwrap()
        .audio
        .channels[0]
        .len();
    let buffers = wb(&h).player().buffers().unwrap();
    assert_eq!(buffers.sources.len(), 1);
    assert_eq!(
        buffers.sources[0][0].len(),
        samples,
        "the player holds the groove"
    );
    assert_last_message(&h, "audio unavailable");
    let wav = tmp.path().join("groove.wav");
    wb_mut(&mut h).export_still_to(&wav, false).unwrap();
    let back = groovescope::io::wav::read_wav(&wav).unwrap();
    assert_eq!(back.channels[0].len(), samples);
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(tmp.path().join("groove.json")).unwrap())
            .unwrap();
    assert_eq!(report["groove"], 2);
    assert_eq!(report["axis"], "horizontal");
    // Again: the workbench asks, and "no" keeps the file.
    let before = std::fs::read(&wav).unwrap();
    wb_mut(&mut h).request_export_still(wav.clone());
    h.run_ok();
    h.get_by_label("Cancel").click();
    h.run_ok();
    assert_eq!(last_message(&h), "not replaced");
    assert_eq!(std::fs::read(&wav).unwrap(), before);
    assert!(wb_mut(&mut h).export_still_to(&wav, false).is_err());
}

#[test]
fn a_still_without_grooves_says_so_and_names_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let flat = dir.path().join("flat.png");
    image::GrayImage::from_pixel(300, 900, image::Luma([128u8]))
        .save(&flat)
        .unwrap();
    let (_tmp, h) = on_still(&flat);
    let msg = last_message(&h);
    assert!(msg.contains("no groove found"), "{msg}");
    assert!(msg.contains("flat.png"), "{msg}");
    let doc = wb(&h).still_doc().expect("the image is open");
    assert!(doc.found.is_none() && doc.run.is_none());
    // The window says so too, not only the status bar.
    assert!(
        doc.problem.as_deref() == Some(msg.as_str()),
        "{:?}",
        doc.problem
    );
    assert!(
        h.query_all_by_label(&msg).count() >= 2,
        "the still window shows {msg}"
    );
}
