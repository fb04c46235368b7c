//! The "Compare methods" window: pick methods A and B, run both over the clip (progress and
//! cancel), then A and B drawn over each other with their difference, a per-group agreement
//! strip (r, coloured; SNR on hover) with a legend, and buttons to listen to A or B.

use egui::{Color32, Ui};
use egui_plot::{Bar, BarChart, Legend, Line, Plot, PlotPoints};

use super::waveform_ui::{PREVIOUS_COLOUR, RECOVERED_COLOUR, decimate};
use super::{AXIS_WIDTH_PT, COMPARE_WINDOW, cancel_button, level_plot, three_stop_colour};
use crate::app::background::Polled;
use crate::app::compare::{Agreement, CompareState, METHODS, default_partner};
use crate::pipeline::Method;
use crate::playback::{AudioStatus, Player};

/// Colour of the difference A − B.
pub const DIFFERENCE_COLOUR: Color32 = Color32::from_rgb(255, 90, 90);

/// What the operator asked for in the window.
#[derive(Clone, Debug, PartialEq)]
pub enum CompareAction {
    /// Reconstruct the clip with these two methods.
    Run([Method; 2]),
    /// Cancel the running comparison.
    Cancel,
    /// Listen to A (0) or B (1).
    Listen(usize),
    /// Stop playback.
    Stop,
}

/// Red, yellow, green: the colours of an agreement r of 0, 0.5 and 1.
const AGREEMENT_RAMP: [[f64; 3]; 3] = [
    [220.0, 60.0, 50.0],
    [230.0, 200.0, 60.0],
    [80.0, 200.0, 100.0],
];

/// Colour of an agreement r: green at 1, through yellow at 0.5, to red at 0 and below.
#[must_use]
pub fn agreement_colour(r: f64) -> Color32 {
    // An unknown r is no agreement.
    three_stop_colour(r, 0.0, AGREEMENT_RAMP)
}

/// One line for an agreement: `r 0.998 · 27.3 dB`.
#[must_use]
pub fn agreement_line(a: &Agreement) -> String {
    format!("r {:.3} · {:.1} dB", a.r, a.snr_db)
}

fn method_picker(ui: &mut Ui, id: &str, label: &str, m: &mut Method) {
    let l = ui.label(label);
    egui::ComboBox::from_id_salt(id)
        .selected_text(m.name())
        .show_ui(ui, |ui| {
            for x in METHODS {
                ui.selectable_value(m, x, x.name());
            }
        })
        .response
        .labelled_by(l.id);
}

/// Draws the window (when open) and returns what was asked for; `heard` is true while the
/// player holds the comparison's sound.
pub fn compare_window(
    ctx: &egui::Context,
    place: super::ToolPlace,
    state: &mut CompareState,
    current: Method,
    player: &Player,
    heard: bool,
) -> Vec<CompareAction> {
    let mut actions = Vec::new();
    state.open = COMPARE_WINDOW.show(ctx, state.open, place, |ui| {
        body(ui, state, current, player, heard, &mut actions);
    });
    actions
}

/// What the comparison did to B's timing: `B aligned: it was 1.83 samples (0.04 ms) early`.
#[must_use]
pub fn delay_text(delay_samples: f64, rate_hz: u32) -> String {
    if delay_samples == 0.0 {
        return "B already aligned with A".to_string();
    }
    let ms = delay_samples.abs() / f64::from(rate_hz.max(1)) * 1000.0;
    format!(
        "B aligned: it was {:.2} samples ({ms:.2} ms) {}",
        delay_samples.abs(),
        if delay_samples > 0.0 { "late" } else { "early" }
    )
}

fn body(
    ui: &mut Ui,
    state: &mut CompareState,
    current: Method,
    player: &Player,
    heard: bool,
    actions: &mut Vec<CompareAction>,
) {
    let mut pair = state.methods.unwrap_or([current, default_partner(current)]);
    ui.horizontal_wrapped(|ui| {
        method_picker(ui, "compare_a", "A", &mut pair[0]);
        method_picker(ui, "compare_b", "B", &mut pair[1]);
        ui.separator();
        if let Some(run) = &state.run {
            let label = format!(
                "{} ({}): group {} / {}",
                if run.pass() == 0 { "A" } else { "B" },
                run.methods.get(run.pass()).map_or("", |m| m.name()),
                run.done(),
                run.total
            );
            ui.add(
                egui::ProgressBar::new(run.fraction())
                    .desired_width(260.0)
                    .text(label),
            );
            if cancel_button(ui, run.cancelling(), "Cancel comparison") {
                actions.push(CompareAction::Cancel);
            }
        } else if ui
            .button("Run comparison")
            .on_hover_text("reconstruct the clip with A, then with B")
            .clicked()
        {
            actions.push(CompareAction::Run(pair));
        }
    });
    state.methods = Some(pair);
    let Some(cmp) = state.result.clone() else {
        ui.weak("no comparison yet: pick two methods and press \"Run comparison\"");
        return;
    };
    let [ma, mb] = cmp.methods.map(Method::name);
    ui.horizontal_wrapped(|ui| {
        if let AudioStatus::Unavailable(why) = player.status() {
            ui.colored_label(
                Color32::from_rgb(235, 150, 60),
                format!("audio unavailable: {why}"),
            );
        }
        let heard = heard.then(|| player.source());
        for (i, name) in [(0, ma), (1, mb)] {
            let text = format!("Listen {}: {name}", if i == 0 { "A" } else { "B" });
            if ui.selectable_label(heard == Some(i), text).clicked() {
                actions.push(CompareAction::Listen(i));
            }
        }
        if ui
            .add_enabled(player.is_playing(), egui::Button::new("Stop"))
            .clicked()
        {
            actions.push(CompareAction::Stop);
        }
        ui.separator();
        ui.label(format!(
            "whole clip: {} (B against A, {} groups)",
            agreement_line(&cmp.overall),
            cmp.groups.len()
        ));
        ui.label(delay_text(cmp.b_delay_samples, cmp.a.rate_hz()))
            .on_hover_text(
                "each decoder delays the sound a little of its own: B is moved by its delay \
                 against A before the figures, the difference and listening",
            );
        if let Some(w) = cmp.worst_group() {
            ui.label(format!("worst group {}: {}", w.group, agreement_line(w)));
        }
        ui.checkbox(&mut state.hide_difference, "hide difference");
    });
    let rate = f64::from(cmp.a.rate_hz());
    let height = (ui.available_height() - 150.0).max(180.0);
    level_plot("compare_waveforms", height).show(ui, |plot_ui| {
        let b = plot_ui.plot_bounds();
        let (t0, t1) = (b.min()[0], b.max()[0]);
        let cols = (plot_ui.response().rect.width() as usize).clamp(64, 2000);
        plot_ui.line(
            Line::new(
                format!("A: {ma}"),
                PlotPoints::from(decimate(&cmp.a.recovered.samples, rate, t0, t1, cols)),
            )
            .color(RECOVERED_COLOUR),
        );
        plot_ui.line(
            Line::new(
                format!("B: {mb}"),
                PlotPoints::from(decimate(&cmp.b_on_a, rate, t0, t1, cols)),
            )
            .color(PREVIOUS_COLOUR.gamma_multiply(0.85)),
        );
        if !state.hide_difference {
            plot_ui.line(
                Line::new(
                    "A − B",
                    PlotPoints::from(decimate(&cmp.difference, rate, t0, t1, cols)),
                )
                .color(DIFFERENCE_COLOUR)
                .width(1.0),
            );
        }
    });
    ui.label("agreement per group (bar height and colour: r of B against A; SNR on hover)");
    let bars: Vec<Bar> = cmp
        .groups
        .iter()
        .map(|g| {
            Bar::new(g.group as f64, g.r)
                .width(0.9)
                .fill(agreement_colour(g.r))
                .name(format!("group {}: {}", g.group, agreement_line(g)))
        })
        .collect();
    Plot::new("compare_agreement")
        .y_axis_min_width(AXIS_WIDTH_PT)
        .height(110.0)
        .legend(Legend::default())
        .allow_drag(false)
        .allow_zoom(false)
        .allow_scroll(false)
        .include_y(0.0)
        .include_y(1.0)
        .x_axis_label("group")
        .y_axis_label("r")
        .show(ui, |plot_ui| {
            plot_ui.bar_chart(
                BarChart::new("agreement r (green 1 · yellow 0.5 · red ≤ 0)", bars)
                    .color(agreement_colour(1.0))
                    .element_formatter(Box::new(|bar, _| bar.name.clone())),
            );
        });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn agreement_colours_run_from_red_to_green() {
        assert_eq!(agreement_colour(1.0), Color32::from_rgb(80, 200, 100));
        assert_eq!(agreement_colour(0.5), Color32::from_rgb(230, 200, 60));
        assert_eq!(agreement_colour(-0.3), Color32::from_rgb(220, 60, 50));
        assert_eq!(agreement_colour(f64::NAN), agreement_colour(0.0));
    }
}
