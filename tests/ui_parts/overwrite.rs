//! Workbench tests of replacing files (review item 1): a native save dialog that already asked
//! before replacing the file (zenity's `--confirm-overwrite`, the desktop portal's own
//! question) is not followed by the app's question; the in-app path field, where no dialog
//! asked, still asks; nothing the dialog did not ask about is replaced without a question.

use std::path::Path;

use egui_kittest::kittest::Queryable;
use groovescope::app::dialogs::{DialogAnswer, DialogKind};
use groovescope::app::files::Confirm;
use groovescope::io::wav::WavBits;

use super::gui_common::*;

fn bits_of(wav: &Path) -> u16 {
    hound::WavReader::open(wav).unwrap().spec().bits_per_sample
}

#[test]
fn a_native_dialog_that_asked_before_replacing_is_not_asked_again() {
    let (tmp, mut h) = settled_on(&lateral_scan());
    wb_mut(&mut h).reconstruct(None);
    settle(&mut h);
    let wav = tmp.path().join("out.wav");
    wb_mut(&mut h).set_export_bits(WavBits::Int16);
    wb_mut(&mut h).request_export_wav(wav.clone(), false);
    h.run_ok();
    assert_eq!(bits_of(&wav), 16);
    // The native dialog asked already: the file is replaced at once, and the message says so.
    wb_mut(&mut h).set_export_bits(WavBits::Float32);
    wb_mut(&mut h).answer_dialog(
        DialogKind::ExportWav(false),
        DialogAnswer::Picked(wav.clone()),
    );
    h.run_ok();
    assert!(
        wb(&h).confirm().is_none(),
        "asked again after the native dialog"
    );
    assert_eq!(bits_of(&wav), 32);
    assert_last_message(&h, "replaced");
    // A report lying beside a new WAV: the dialog asked nothing, so the app asks.
    let lone = tmp.path().join("lone.wav");
    std::fs::write(lone.with_extension("json"), "{}").unwrap();
    wb_mut(&mut h).answer_dialog(
        DialogKind::ExportWav(false),
        DialogAnswer::Picked(lone.clone()),
    );
    h.run_ok();
    assert!(matches!(wb(&h).confirm(), Some(Confirm::ExportWav { .. })));
    h.get_by_label("Cancel").click();
    h.run_ok();
    assert!(!lone.exists());
    // A name picked without `.wav`: the dialog asked about `take`, not the `take.wav` written.
    let take = tmp.path().join("take");
    std::fs::copy(&wav, take.with_extension("wav")).unwrap();
    wb_mut(&mut h).answer_dialog(
        DialogKind::ExportWav(false),
        DialogAnswer::Picked(take.clone()),
    );
    h.run_ok();
    assert!(matches!(wb(&h).confirm(), Some(Confirm::ExportWav { .. })));
    h.get_by_label("Cancel").click();
    h.run_ok();
    // The in-app path field (no native dialog can open in the tests) asks before replacing.
    wb_mut(&mut h).set_export_bits(WavBits::Int16);
    wb_mut(&mut h).show_dialog(DialogKind::ExportWav(false));
    h.run_ok();
    assert!(wb(&h).path_prompt().is_some(), "the in-app path field");
    h.get_by_label("type the file's path:").focus();
    h.run_ok();
    h.key_press_modifiers(egui::Modifiers::COMMAND, egui::Key::A);
    h.get_by_label("type the file's path:")
        .type_text(&wav.display().to_string());
    h.run_ok();
    h.get_by_label("OK").click();
    h.run_ok();
    assert!(
        matches!(wb(&h).confirm(), Some(Confirm::ExportWav { .. })),
        "the path field must ask"
    );
    assert_eq!(bits_of(&wav), 32, "not replaced before the answer");
    h.get_by_label("Replace").click();
    h.run_ok();
    assert_eq!(bits_of(&wav), 16);
}

#[test]
fn a_native_dialog_that_asked_replaces_a_preset_without_asking_again() {
    let (tmp, mut h) = settled_on(&lateral_scan());
    let preset = tmp.path().join("p.toml");
    std::fs::write(&preset, "# old\n").unwrap();
    wb_mut(&mut h).answer_dialog(DialogKind::SavePreset, DialogAnswer::Picked(preset.clone()));
    h.run_ok();
    assert!(
        wb(&h).confirm().is_none(),
        "asked again after the native dialog"
    );
    assert!(std::fs::read_to_string(&preset).unwrap().contains("[flow]"));
}
