//! Waveform view: the recovered clip (filling in while it reconstructs), the reference, envelopes,
//! spectrum and scores, with the transport (play, A/B, loop, volume) and export controls.

use std::sync::Arc;

use egui::{Color32, Ui};
use egui_plot::{Legend, Line, LineStyle, Plot, PlotPoints, Span, VLine};

use super::{AXIS_WIDTH_PT, empty_note};
use crate::app::recon::{Clip, ReconRun};
use crate::io::wav::WavBits;
use crate::pipeline::audio_signal::GroupSignal;
use crate::playback::{AudioStatus, Player};

/// Most points per drawn line (min/max pairs per screen column beyond this).
const MAX_DRAWN_POINTS: usize = 4000;
/// Drags shorter than this (seconds) count as clicks.
const MIN_SELECTION_SECS: f64 = 1e-3;

/// Colour of the recovered sound.
pub const RECOVERED_COLOUR: Color32 = Color32::from_rgb(110, 190, 255);
/// Colour of the reference sound.
pub const REFERENCE_COLOUR: Color32 = Color32::from_rgb(255, 160, 70);

/// What the operator asked for in the waveform view.
#[derive(Clone, Debug, PartialEq)]
pub enum WaveAction {
    /// Reconstruct these groups (None: all).
    Reconstruct(Option<std::ops::Range<usize>>),
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
    /// Reconstruct a range of groups only.
    pub use_range: bool,
    /// That range (start, end inclusive).
    pub range: (usize, usize),
}

impl Default for WaveViewState {
    fn default() -> Self {
        Self {
            selection: None,
            drag_from: None,
            loop_selection: true,
            show_reference: true,
            show_envelopes: true,
            bits: WavBits::Int24,
            use_range: false,
            range: (0, 0),
        }
    }
}

/// Min/max decimation of `samples` (at `rate_hz`) over the visible `[t0, t1]` seconds.
#[must_use]
pub fn decimate(samples: &[f32], rate_hz: f64, t0: f64, t1: f64, columns: usize) -> Vec<[f64; 2]> {
    if samples.is_empty() || rate_hz <= 0.0 {
        return Vec::new();
    }
    let n = samples.len();
    let a = ((t0 * rate_hz).floor().max(0.0) as usize).min(n - 1);
    let b = ((t1 * rate_hz).ceil().max(0.0) as usize + 1).clamp(a + 1, n);
    let visible = &samples[a..b];
    let columns = columns.max(1);
    if visible.len() <= 2 * columns {
        return visible
            .iter()
            .enumerate()
            .map(|(i, v)| [(a + i) as f64 / rate_hz, f64::from(*v)])
            .collect();
    }
    let per = visible.len().div_ceil(columns);
    let mut out = Vec::with_capacity(2 * columns);
    for (c, chunk) in visible.chunks(per).enumerate() {
        let (lo, hi) = chunk
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(l, h), v| {
                if v.is_finite() {
                    (l.min(*v), h.max(*v))
                } else {
                    (l, h)
                }
            });
        if lo <= hi {
            let t = (a + c * per) as f64 / rate_hz;
            out.push([t, f64::from(lo)]);
            out.push([t, f64::from(hi)]);
        }
    }
    out
}

/// The live waveform of groups finished so far: velocity normalised to its peak, against time.
#[must_use]
pub fn partial_points(signals: &[Arc<GroupSignal>]) -> Vec<Vec<[f64; 2]>> {
    let Some(first) = signals
        .iter()
        .find_map(|s| s.positions_um.first().map(|p| (*p, s.groove_speed_mm_s)))
    else {
        return Vec::new();
    };
    let peak = signals
        .iter()
        .flat_map(|s| s.channels.first().into_iter().flatten())
        .fold(
            0.0_f32,
            |m, v| if v.is_finite() { m.max(v.abs()) } else { m },
        );
    let scale = if peak > 0.0 {
        1.0 / f64::from(peak)
    } else {
        1.0
    };
    let speed_um_s = first.1 * 1000.0;
    signals
        .iter()
        .filter_map(|s| {
            let ch = s.channels.first()?;
            Some(
                s.positions_um
                    .iter()
                    .zip(ch)
                    .filter(|(_, v)| v.is_finite())
                    .map(|(p, v)| [(p - first.0) / speed_um_s, f64::from(*v) * scale])
                    .collect(),
            )
        })
        .collect()
}

/// Envelope points at the middle of each block (the last block may be short).
fn envelope_lines(
    env: &[f32],
    block: usize,
    len: usize,
    rate: f64,
) -> (Vec<[f64; 2]>, Vec<[f64; 2]>) {
    let t = |i: usize| {
        let start = i * block;
        let n = block.min(len.saturating_sub(start));
        (start as f64 + n as f64 / 2.0) / rate
    };
    let up = env
        .iter()
        .enumerate()
        .map(|(i, v)| [t(i), f64::from(*v)])
        .collect();
    let down = env
        .iter()
        .enumerate()
        .map(|(i, v)| [t(i), -f64::from(*v)])
        .collect();
    (up, down)
}

fn transport_ui(
    ui: &mut Ui,
    player: &mut Player,
    clip: Option<&Clip>,
    state: &mut WaveViewState,
    actions: &mut Vec<WaveAction>,
) {
    ui.horizontal(|ui| {
        if let AudioStatus::Unavailable(why) = player.status() {
            ui.colored_label(
                Color32::from_rgb(235, 150, 60),
                format!("audio unavailable: {why}"),
            );
            return;
        }
        let ready = clip.is_some();
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
        let has_ref = clip.is_some_and(|c| c.reference.is_some());
        let mut b = player.source_b() && has_ref;
        ui.separator();
        ui.selectable_value(&mut b, false, "A: recovered");
        ui.add_enabled_ui(has_ref, |ui| {
            ui.selectable_value(&mut b, true, "B: reference")
        });
        player.set_source_b(b);
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
            ui.colored_label(Color32::from_rgb(235, 150, 60), format!("audio: {e}"));
        }
    });
}

fn clip_controls_ui(
    ui: &mut Ui,
    run: Option<&ReconRun>,
    groups: usize,
    clip: Option<&Clip>,
    state: &mut WaveViewState,
    actions: &mut Vec<WaveAction>,
) {
    ui.horizontal(|ui| {
        if let Some(r) = run {
            let eta = r
                .eta()
                .map_or("…".into(), |d| format!("{:.0} s left", d.as_secs_f64()));
            ui.add(
                egui::ProgressBar::new(r.fraction())
                    .desired_width(240.0)
                    .text(format!("group {} / {} · {eta}", r.done, r.total)),
            );
            let label = if r.cancelling() {
                "cancelling…"
            } else {
                "Cancel"
            };
            if ui
                .add_enabled(!r.cancelling(), egui::Button::new(label))
                .clicked()
            {
                actions.push(WaveAction::Cancel);
            }
        } else {
            if ui.button("Reconstruct clip").clicked() {
                let range = state.use_range.then(|| {
                    state.range.0.min(state.range.1)..state.range.1.max(state.range.0) + 1
                });
                actions.push(WaveAction::Reconstruct(range));
            }
            ui.checkbox(&mut state.use_range, "only groups");
            let last = groups.saturating_sub(1);
            let from = ui.label("from");
            ui.add_enabled(
                state.use_range,
                egui::DragValue::new(&mut state.range.0).range(0..=last),
            )
            .labelled_by(from.id);
            let to = ui.label("to");
            ui.add_enabled(
                state.use_range,
                egui::DragValue::new(&mut state.range.1).range(0..=last),
            )
            .labelled_by(to.id);
        }
        ui.separator();
        let wav = ui.label("WAV");
        egui::ComboBox::from_id_salt("wav_bits")
            .selected_text(match state.bits {
                WavBits::Int16 => "16-bit",
                WavBits::Int24 => "24-bit",
                WavBits::Float32 => "32-bit float",
            })
            .show_ui(ui, |ui| {
                ui.selectable_value(&mut state.bits, WavBits::Int16, "16-bit");
                ui.selectable_value(&mut state.bits, WavBits::Int24, "24-bit");
                ui.selectable_value(&mut state.bits, WavBits::Float32, "32-bit float");
            })
            .response
            .labelled_by(wav.id);
        let ready = clip.is_some();
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

/// The waveform view; returns what the operator asked for.
pub fn waveform_ui(
    ui: &mut Ui,
    clip: Option<&Clip>,
    run: Option<&ReconRun>,
    groups: usize,
    player: &mut Player,
    state: &mut WaveViewState,
    height: f32,
) -> Vec<WaveAction> {
    let mut actions = Vec::new();
    clip_controls_ui(ui, run, groups, clip, state, &mut actions);
    transport_ui(ui, player, clip, state, &mut actions);
    if let Some(c) = clip {
        ui.horizontal(|ui| {
            match &c.recon.scores {
                Some(s) => {
                    ui.label(format!(
                        "vs reference: r {:.3}  ·  envelope r {}  ·  SNR {:.1} dB  ·  lag {} samples",
                        s.r,
                        s.envelope_r_text(3),
                        s.snr_db,
                        s.lag_samples
                    ));
                }
                None => {
                    ui.weak(c.reference_problem.as_deref().unwrap_or("no reference.wav: no scores"));
                }
            }
            ui.separator();
            ui.checkbox(&mut state.show_reference, "reference");
            ui.checkbox(&mut state.show_envelopes, "envelopes");
            if let Some((a, b)) = state.selection {
                ui.label(format!("selection {a:.3}–{b:.3} s"));
                if ui.small_button("clear").clicked() {
                    state.selection = None;
                    player.set_loop(None);
                }
            }
        });
        for w in c.recon.warnings.iter().take(3) {
            ui.colored_label(Color32::from_rgb(220, 170, 60), w);
        }
    }
    let partial = run
        .map(|r| partial_points(&r.partial))
        .filter(|p| !p.is_empty());
    if clip.is_none() && partial.is_none() {
        empty_note(
            ui,
            "no clip yet: press \"Reconstruct clip\" to run every group",
        );
        return actions;
    }
    let wave_h = height * 0.58;
    let playhead = player.position_secs();
    let playing = player.is_playing();
    let resp = Plot::new("waveform")
        .y_axis_min_width(AXIS_WIDTH_PT)
        .height(wave_h)
        .legend(Legend::default())
        .allow_drag(false)
        .allow_boxed_zoom(false)
        .x_axis_label("time (s)")
        .y_axis_label("level")
        .show(ui, |plot_ui| {
            let b = plot_ui.plot_bounds();
            let (t0, t1) = (b.min()[0], b.max()[0]);
            let cols = (plot_ui.response().rect.width() as usize).clamp(64, MAX_DRAWN_POINTS / 2);
            if let Some(parts) = &partial {
                for (k, seg) in parts.iter().enumerate() {
                    plot_ui.line(
                        Line::new("recovered (so far)", PlotPoints::from(seg.clone()))
                            .id(format!("partial/{k}"))
                            .color(RECOVERED_COLOUR),
                    );
                }
            } else if let Some(c) = clip {
                let rate = f64::from(c.rate_hz());
                if state.show_reference
                    && let Some(r) = &c.reference
                {
                    plot_ui.line(
                        Line::new(
                            "reference",
                            PlotPoints::from(decimate(r, rate, t0, t1, cols)),
                        )
                        .color(REFERENCE_COLOUR.gamma_multiply(0.7)),
                    );
                }
                plot_ui.line(
                    Line::new(
                        "recovered",
                        PlotPoints::from(decimate(&c.recovered, rate, t0, t1, cols)),
                    )
                    .color(RECOVERED_COLOUR),
                );
                if state.show_envelopes {
                    let (up, down) = envelope_lines(
                        &c.recovered_envelope,
                        c.envelope_block,
                        c.recovered.len(),
                        rate,
                    );
                    for (k, l) in [up, down].into_iter().enumerate() {
                        plot_ui.line(
                            Line::new("recovered envelope", PlotPoints::from(l))
                                .id(format!("renv/{k}"))
                                .color(Color32::WHITE)
                                .width(1.0),
                        );
                    }
                    if let (true, Some(e)) = (state.show_reference, &c.reference_envelope) {
                        let (up, down) =
                            envelope_lines(e, c.envelope_block, c.recovered.len(), rate);
                        for (k, l) in [up, down].into_iter().enumerate() {
                            plot_ui.line(
                                Line::new("reference envelope", PlotPoints::from(l))
                                    .id(format!("fenv/{k}"))
                                    .color(Color32::from_rgb(255, 210, 120))
                                    .style(LineStyle::dashed_dense())
                                    .width(1.0),
                            );
                        }
                    }
                }
                if let Some((a, b)) = state.selection {
                    plot_ui.span(Span::new("selection", a..=b).fill(Color32::from_white_alpha(24)));
                }
                if playing || playhead > 0.0 {
                    plot_ui.vline(
                        VLine::new("playhead", playhead).color(Color32::from_rgb(255, 80, 80)),
                    );
                }
            }
            plot_ui.pointer_coordinate()
        });
    if let (Some(_), Some(p)) = (clip, resp.inner) {
        let r = &resp.response;
        if r.drag_started() {
            state.drag_from = Some(p.x.max(0.0));
        }
        if let (true, Some(from)) = (r.dragged(), state.drag_from) {
            let to = p.x.max(0.0);
            state.selection = Some((from.min(to), from.max(to)));
        }
        if r.drag_stopped() {
            state.drag_from = None;
            if state
                .selection
                .is_some_and(|(a, b)| b - a < MIN_SELECTION_SECS)
            {
                state.selection = None;
            }
            player.set_loop(state.selection.filter(|_| state.loop_selection));
        }
        if r.clicked() {
            player.seek_secs(p.x.max(0.0));
        }
    }
    if playing {
        ui.ctx()
            .request_repaint_after(std::time::Duration::from_millis(40));
    }
    if let Some(c) = clip {
        ui.weak("drag: select (loops while playing)  ·  click: seek  ·  scroll: pan  ·  ctrl+scroll: zoom  ·  double-click: reset");
        Plot::new("spectrum")
            .y_axis_min_width(AXIS_WIDTH_PT)
            .height((height - wave_h - 90.0).max(80.0))
            .legend(Legend::default())
            .x_axis_label("frequency (Hz)")
            .y_axis_label("magnitude (dB)")
            .show(ui, |plot_ui| {
                let pts = |s: &crate::app::recon::Spectrum| -> Vec<[f64; 2]> {
                    s.freqs_hz
                        .iter()
                        .zip(&s.db)
                        .map(|(f, d)| [*f, *d])
                        .collect()
                };
                if let (true, Some(r)) = (state.show_reference, &c.reference_spectrum) {
                    plot_ui.line(
                        Line::new("reference spectrum", PlotPoints::from(pts(r)))
                            .color(REFERENCE_COLOUR),
                    );
                }
                plot_ui.line(
                    Line::new(
                        "recovered spectrum",
                        PlotPoints::from(pts(&c.recovered_spectrum)),
                    )
                    .color(RECOVERED_COLOUR),
                );
            });
    }
    actions
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;

    #[test]
    fn decimation_keeps_extremes_and_short_spans_verbatim() {
        let x: Vec<f32> = (0..10_000)
            .map(|i| if i == 5_000 { 1.0 } else { 0.0 })
            .collect();
        let d = decimate(&x, 1000.0, 0.0, 10.0, 100);
        assert!(d.len() <= 200);
        assert!(d.iter().any(|p| p[1] == 1.0), "the spike survives");
        let d = decimate(&x, 1000.0, 5.0, 5.01, 100);
        assert!(d.len() <= 12 && d.iter().any(|p| p[1] == 1.0 && (p[0] - 5.0).abs() < 1e-9));
        assert!(decimate(&[], 1000.0, 0.0, 1.0, 10).is_empty());
    }
}
