//! Waveform view: the recovered clip (filling in while it reconstructs), the previous clip (A/B
//! after a change), the reference, envelopes, spectrum and scores, with the transport (play,
//! A/B/reference, loop, volume), reconstruct (all, a range, around the current group) and export
//! controls. Its time axis is tied to the groups: the current group's stretch is marked, and a
//! click goes to the group heard there.

use std::sync::Arc;

use egui::{Color32, Ui};
use egui_plot::{Legend, Line, LineStyle, Plot, PlotPoints, Span, VLine};

use super::transport_ui::{WaveAction, WaveViewState, clip_controls_ui, transport_ui};
use super::{AXIS_WIDTH_PT, empty_note, level_plot};
use crate::app::clip_state::ClipState;
use crate::pipeline::audio_signal::GroupSignal;
use crate::playback::Player;

/// Most points per drawn line (min/max pairs per screen column beyond this).
const MAX_DRAWN_POINTS: usize = 4000;
/// Drags shorter than this (seconds) count as clicks.
const MIN_SELECTION_SECS: f64 = 1e-3;

/// Colour of the recovered sound.
pub const RECOVERED_COLOUR: Color32 = Color32::from_rgb(110, 190, 255);
/// Colour of the reference sound.
pub const REFERENCE_COLOUR: Color32 = Color32::from_rgb(255, 160, 70);
/// Colour of the previous clip.
pub const PREVIOUS_COLOUR: Color32 = Color32::from_rgb(200, 140, 255);
/// Colour of the current group's stretch.
pub const GROUP_SPAN_COLOUR: Color32 = Color32::from_rgba_premultiplied(12, 30, 12, 30);

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

/// The waveform view; returns what the operator asked for.
pub fn waveform_ui(
    ui: &mut Ui,
    clips: &ClipState,
    groups: usize,
    current_group: usize,
    player: &mut Player,
    state: &mut WaveViewState,
    height: f32,
) -> Vec<WaveAction> {
    let mut actions = Vec::new();
    let clip = clips.clip.as_deref();
    let previous = clips
        .previous
        .as_ref()
        .and_then(|(_, laid)| laid.as_deref())
        .filter(|_| state.show_previous);
    clip_controls_ui(ui, clips, groups, current_group, state, &mut actions);
    transport_ui(ui, player, clips, state, &mut actions);
    if let Some(c) = clip {
        ui.horizontal(|ui| {
            match &c.recon.scores {
                Some(s) => {
                    ui.label(format!(
                        "vs reference: r {:.3}  ·  envelope r {}  ·  SNR {:.1} dB  ·  lag {} samples",
                        s.r,
                        s.envelope_r_text(3),
                        s.snr_db,
                        s.lag_text(2)
                    ));
                    if let Some(i) = s.inverted {
                        ui.colored_label(
                            ui.visuals().warn_fg_color,
                            format!(
                                "inverted it reads r {:.3} at lag {}: its polarity is likely reversed",
                                i.r, i.lag_samples
                            ),
                        );
                    }
                }
                None => {
                    ui.weak(c.reference_problem.as_deref().unwrap_or("no reference.wav: no scores"));
                }
            }
            ui.separator();
            ui.checkbox(&mut state.show_reference, "reference");
            ui.checkbox(&mut state.show_envelopes, "envelopes");
            if clips.previous.is_some() {
                ui.checkbox(&mut state.show_previous, "previous clip");
            }
            if let Some((a, b)) = state.selection {
                ui.label(format!("selection {a:.3}–{b:.3} s"));
                if ui.small_button("clear").clicked() {
                    state.selection = None;
                    player.set_loop(None);
                }
            }
        });
        super::guidance::warnings_ui(ui, &c.recon.warnings, 3);
    }
    state.toolbar_bottom = ui.cursor().top();
    let partial = clips
        .run
        .as_ref()
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
    let group_span = clip.and_then(|c| c.group_span_secs(current_group));
    let resp = level_plot("waveform", wave_h)
        .allow_drag(false)
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
                if let Some((a, b)) = group_span {
                    plot_ui.span(
                        Span::new(format!("group {current_group}"), a..=b).fill(GROUP_SPAN_COLOUR),
                    );
                }
                if state.show_reference
                    && let Some(r) = &c.reference
                {
                    plot_ui.line(
                        Line::new(
                            "reference",
                            PlotPoints::from(decimate(&r.samples, rate, t0, t1, cols)),
                        )
                        .color(REFERENCE_COLOUR.gamma_multiply(0.7)),
                    );
                }
                if let Some(p) = previous {
                    plot_ui.line(
                        Line::new(
                            "previous clip",
                            PlotPoints::from(decimate(p, rate, t0, t1, cols)),
                        )
                        .color(PREVIOUS_COLOUR.gamma_multiply(0.8)),
                    );
                }
                plot_ui.line(
                    Line::new(
                        "recovered",
                        PlotPoints::from(decimate(&c.recovered.samples, rate, t0, t1, cols)),
                    )
                    .color(RECOVERED_COLOUR),
                );
                if state.show_envelopes {
                    let (up, down) = envelope_lines(
                        &c.recovered.envelope,
                        c.envelope_block,
                        c.recovered.samples.len(),
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
                    if let (true, Some(e)) = (state.show_reference, &c.reference) {
                        let (up, down) = envelope_lines(
                            &e.envelope,
                            c.envelope_block,
                            c.recovered.samples.len(),
                            rate,
                        );
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
    if let (Some(c), Some(p)) = (clip, resp.inner) {
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
            let t = p.x.max(0.0);
            player.seek_secs(t);
            if let Some(g) = c.group_at_secs(t) {
                actions.push(WaveAction::Group(g));
            }
        }
    }
    if playing {
        ui.ctx()
            .request_repaint_after(std::time::Duration::from_millis(40));
    }
    if let Some(c) = clip {
        ui.weak("drag: select (loops while playing)  ·  click: seek and show that group  ·  scroll: pan  ·  ctrl+scroll: zoom  ·  double-click: reset");
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
                if let (true, Some(r)) = (state.show_reference, &c.reference) {
                    plot_ui.line(
                        Line::new("reference spectrum", PlotPoints::from(pts(&r.spectrum)))
                            .color(REFERENCE_COLOUR),
                    );
                }
                plot_ui.line(
                    Line::new(
                        "recovered spectrum",
                        PlotPoints::from(pts(&c.recovered.spectrum)),
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
