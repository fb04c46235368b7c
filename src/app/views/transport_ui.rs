//! The waveform view's controls: reconstruct (the whole clip, a range, or around the current
//! group) with progress and cancel, the export format and buttons, and the transport (play,
//! which source is heard — the clip, the previous clip, the reference — loop, volume).

use egui::{Color32, Ui};

use super::cancel_button;
use crate::app::clip_state::{ClipState, SOURCE_CLIP, SOURCE_PREVIOUS, SOURCE_REFERENCE};
use crate::app::export::EXPORT_FORMATS;
use crate::io::wav::WavBits;
use crate::playback::{AudioStatus, Player};

/// Groups on either side of the current one that "reconstruct around" covers by default.
pub const AROUND_GROUPS: usize = 10;

/// What the operator asked for in the waveform view.
#[derive(Clone, Debug, PartialEq)]
pub enum WaveAction {
    /// Reconstruct these groups (None: all).
    Reconstruct(Option<std::ops::Range<usize>>),
    /// Reconstruct the groups within this many of the current one.
    ReconstructAround(usize),
    /// Play the groups the running reconstruction has finished so far.
    PlaySoFar,
    /// Show this group (clicked in the waveform).
    Group(usize),
    /// Cancel the running reconstruction.
    Cancel,
    /// Export WAV (the selection only when true).
    ExportWav(bool),
    /// Show a message.
    Message(String),
}

/// State of the waveform view.
#[derive(Clone, Debug)]
pub struct WaveViewState {
    /// Selected stretch (seconds).
    pub selection: Option<(f64, f64)>,
    /// Where the current drag started.
    pub drag_from: Option<f64>,
    /// Loop the selection while playing.
    pub loop_selection: bool,
    /// Draw the reference.
    pub show_reference: bool,
    /// Draw the envelopes.
    pub show_envelopes: bool,
    /// WAV encoding for export.
    pub bits: WavBits,
    /// Sample rate for export (None: the clip's).
    pub export_rate_hz: Option<u32>,
    /// Groups on either side of the current one for "reconstruct around".
    pub around: usize,
    /// Draw the previous clip.
    pub show_previous: bool,
    /// Reconstruct a range of groups only.
    pub use_range: bool,
    /// That range (start, end inclusive).
    pub range: (usize, usize),
    /// Where the view's toolbar (reconstruct, transport, scores) ended last frame (y, points):
    /// the tool windows open below it.
    pub toolbar_bottom: f32,
}

impl Default for WaveViewState {
    fn default() -> Self {
        Self {
            selection: None,
            drag_from: None,
            loop_selection: true,
            show_reference: true,
            show_envelopes: true,
            bits: EXPORT_FORMATS[0].bits,
            export_rate_hz: EXPORT_FORMATS[0].rate_hz,
            around: AROUND_GROUPS,
            show_previous: true,
            use_range: false,
            range: (0, 0),
            toolbar_bottom: 0.0,
        }
    }
}

/// Colour of notes about audio.
const AUDIO_NOTE: Color32 = Color32::from_rgb(235, 150, 60);

/// Play, pause, stop, the source heard, loop, volume and position.
pub fn transport_ui(
    ui: &mut Ui,
    player: &mut Player,
    clips: &ClipState,
    state: &mut WaveViewState,
    actions: &mut Vec<WaveAction>,
) {
    ui.horizontal(|ui| {
        if let AudioStatus::Unavailable(why) = player.status() {
            ui.colored_label(AUDIO_NOTE, format!("audio unavailable: {why}"));
            return;
        }
        let clip = clips.clip.as_deref();
        let ready = player.buffers().is_some_and(|b| !b.is_empty());
        if player.is_playing() {
            if ui.button("Pause").clicked() {
                player.pause();
            }
        } else if ui.add_enabled(ready, egui::Button::new("Play")).clicked()
            && let Err(e) = player.play()
        {
            actions.push(WaveAction::Message(e));
        }
        if ui.add_enabled(ready, egui::Button::new("Stop")).clicked() {
            player.stop();
        }
        ui.separator();
        if clips.still_heard {
            ui.weak("(the still window's groove; reconstruct to hear the clip again)");
            return;
        }
        if let Some([a, b]) = clips.comparison_heard {
            // The player holds a method comparison (source 0: A, 1: B).
            let mut source = player.source().min(1);
            ui.selectable_value(&mut source, 0, format!("A: {}", a.name()));
            ui.selectable_value(&mut source, 1, format!("B: {}", b.name()));
            player.set_source(source);
            ui.weak("(the method comparison; reconstruct to hear the clip again)");
            return;
        }
        let has_prev = clips
            .previous
            .as_ref()
            .is_some_and(|(_, laid)| laid.is_some());
        let has_ref = clip.is_some_and(|c| c.reference.is_some());
        let mut source = player.source();
        if (source == SOURCE_PREVIOUS && !has_prev) || (source == SOURCE_REFERENCE && !has_ref) {
            source = SOURCE_CLIP;
        }
        ui.selectable_value(&mut source, SOURCE_CLIP, "A: this clip");
        ui.add_enabled_ui(has_prev, |ui| {
            ui.selectable_value(&mut source, SOURCE_PREVIOUS, "B: previous clip")
                .on_disabled_hover_text(match &clips.previous {
                    Some((_, None)) => "the previous clip has another sample rate",
                    _ => "reconstruct again after a change to compare with this clip",
                });
        });
        ui.add_enabled_ui(has_ref, |ui| {
            ui.selectable_value(&mut source, SOURCE_REFERENCE, "R: reference")
        });
        player.set_source(source);
        ui.separator();
        if ui
            .checkbox(&mut state.loop_selection, "loop selection")
            .changed()
            || ready
        {
            player.set_loop(state.selection.filter(|_| state.loop_selection));
        }
        let mut vol = player.volume();
        if ui
            .add(egui::Slider::new(&mut vol, 0.0..=2.0).text("volume"))
            .changed()
        {
            player.set_volume(vol);
        }
        if let Some(c) = clip {
            ui.label(format!(
                "{:.2} / {:.2} s",
                player.position_secs(),
                c.recon.audio.duration_secs()
            ));
        }
        if let Some(e) = player.stream_error() {
            ui.colored_label(AUDIO_NOTE, format!("audio: {e}"));
        }
    });
}

/// What a running reconstruction is at, in words for its progress bar.
fn run_progress_text(r: &crate::app::recon::ReconRun) -> String {
    if r.refinishing {
        return format!("{} groups: finishing with the new filters…", r.total);
    }
    let eta = r
        .eta()
        .map_or("…".into(), |d| format!("{:.0} s left", d.as_secs_f64()));
    format!("group {} / {} · {eta}", r.done, r.total)
}

/// Why nothing can be reconstructed with no scan open.
pub const NO_SCAN_TO_RECONSTRUCT: &str =
    "no scan open: nothing to reconstruct (File > Open scan…, or drop a scan folder here)";

/// Reconstruct (all, a range, around the current group) or its progress and cancel; the
/// export format and buttons.
pub fn clip_controls_ui(
    ui: &mut Ui,
    clips: &ClipState,
    groups: usize,
    current_group: usize,
    state: &mut WaveViewState,
    actions: &mut Vec<WaveAction>,
) {
    ui.horizontal_wrapped(|ui| {
        if let Some(r) = &clips.run {
            ui.add(
                egui::ProgressBar::new(r.fraction())
                    .desired_width(240.0)
                    .text(run_progress_text(r)),
            );
            if cancel_button(ui, r.cancelling(), "Cancel") {
                actions.push(WaveAction::Cancel);
            }
            let asked = r.partial_pending();
            if ui
                .add_enabled(
                    !asked && r.done > 0,
                    egui::Button::new(if asked { "preparing…" } else { "Play so far" }),
                )
                .on_hover_text("the groups finished so far, as the whole clip will sound")
                .clicked()
            {
                actions.push(WaveAction::PlaySoFar);
            }
        } else {
            // With no scan (no groups) there is nothing to reconstruct: the buttons say why.
            let open = groups > 0;
            if ui
                .add_enabled(open, egui::Button::new("Reconstruct clip"))
                .on_disabled_hover_text(NO_SCAN_TO_RECONSTRUCT)
                .clicked()
            {
                let range = state.use_range.then(|| {
                    state.range.0.min(state.range.1)..state.range.1.max(state.range.0) + 1
                });
                actions.push(WaveAction::Reconstruct(range));
            }
            ui.add_enabled(
                open,
                egui::Checkbox::new(&mut state.use_range, "only groups"),
            );
            let last = groups.saturating_sub(1);
            let from = ui.label("from");
            ui.add_enabled(
                open && state.use_range,
                egui::DragValue::new(&mut state.range.0).range(0..=last),
            )
            .labelled_by(from.id);
            let to = ui.label("to");
            ui.add_enabled(
                open && state.use_range,
                egui::DragValue::new(&mut state.range.1).range(0..=last),
            )
            .labelled_by(to.id);
            ui.separator();
            if ui
                .add_enabled(
                    open,
                    egui::Button::new(format!("Reconstruct around group {current_group}")),
                )
                .on_hover_text("only the groups near the one shown: quick to hear a change")
                .on_disabled_hover_text(NO_SCAN_TO_RECONSTRUCT)
                .clicked()
            {
                actions.push(WaveAction::ReconstructAround(state.around));
            }
            let l = ui.label("±");
            ui.add_enabled(
                open,
                egui::DragValue::new(&mut state.around).range(0..=groups),
            )
            .labelled_by(l.id);
        }
        ui.separator();
        let wav = ui.label("WAV");
        let current = EXPORT_FORMATS
            .iter()
            .find(|f| f.bits == state.bits && f.rate_hz == state.export_rate_hz)
            .map_or("custom", |f| f.name);
        egui::ComboBox::from_id_salt("wav_format")
            .selected_text(current)
            .show_ui(ui, |ui| {
                for f in &EXPORT_FORMATS {
                    let chosen = f.bits == state.bits && f.rate_hz == state.export_rate_hz;
                    if ui
                        .selectable_label(chosen, f.name)
                        .on_hover_text(f.reason)
                        .clicked()
                    {
                        state.bits = f.bits;
                        state.export_rate_hz = f.rate_hz;
                    }
                }
            })
            .response
            .labelled_by(wav.id);
        let ready = clips.clip.is_some();
        if ui
            .add_enabled(ready, egui::Button::new("Export WAV…"))
            .clicked()
        {
            actions.push(WaveAction::ExportWav(false));
        }
        if ui
            .add_enabled(
                ready && state.selection.is_some(),
                egui::Button::new("Export selection…"),
            )
            .clicked()
        {
            actions.push(WaveAction::ExportWav(true));
        }
    });
}
