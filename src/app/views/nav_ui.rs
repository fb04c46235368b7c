//! Navigation panel: group slider/next/previous/jump, frame scrubber and movie, and the stage status list.

use std::time::Duration;

use egui::Ui;

use super::StageStatus;
use crate::pipeline::Stage;

/// State of the navigation panel.
#[derive(Clone, Debug, Default)]
pub struct NavState {
    /// The group number typed into "jump".
    pub jump: usize,
    /// Playing the frames as a movie (the frame loop steps it before drawing, so every panel
    /// shows the same frame).
    pub movie: bool,
    /// Time (egui clock) of the last movie step.
    pub last_step: f64,
}

/// What the operator asked for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NavAction {
    /// Show this group.
    Group(usize),
    /// Show this frame.
    Frame(usize),
    /// Rerun this stage (and everything after it).
    Rerun(Stage),
}

/// Group and frame navigation.
pub fn nav_ui(
    ui: &mut Ui,
    groups: usize,
    group: usize,
    frames: usize,
    frame: usize,
    state: &mut NavState,
) -> Vec<NavAction> {
    let mut out = Vec::new();
    if groups == 0 {
        ui.weak("no scan open");
        return out;
    }
    let last = groups - 1;
    ui.horizontal(|ui| {
        if ui
            .add_enabled(group > 0, egui::Button::new("< previous"))
            .clicked()
        {
            out.push(NavAction::Group(group - 1));
        }
        ui.label(format!("group {group} / {last}"));
        if ui
            .add_enabled(group < last, egui::Button::new("next >"))
            .clicked()
        {
            out.push(NavAction::Group(group + 1));
        }
    });
    let mut g = group;
    let l = ui.label("group");
    if ui
        .add(egui::Slider::new(&mut g, 0..=last).clamping(egui::SliderClamping::Always))
        .labelled_by(l.id)
        .changed()
    {
        out.push(NavAction::Group(g));
    }
    ui.horizontal(|ui| {
        let l = ui.label("jump to");
        ui.add(egui::DragValue::new(&mut state.jump).range(0..=last))
            .labelled_by(l.id);
        if ui.button("go").clicked() {
            out.push(NavAction::Group(state.jump.min(last)));
        }
    });
    if frames > 0 {
        let mut f = frame.min(frames - 1);
        ui.horizontal(|ui| {
            let l = ui.label("frame");
            if ui
                .add(egui::Slider::new(&mut f, 0..=frames - 1))
                .labelled_by(l.id)
                .changed()
            {
                out.push(NavAction::Frame(f));
            }
            let label = if state.movie {
                "pause movie"
            } else {
                "play movie"
            };
            if ui.button(label).clicked() {
                state.movie = !state.movie;
                state.last_step = ui.input(|i| i.time);
            }
        });
    }
    out
}

/// Why the stages cannot be rerun with no scan open.
pub const NO_SCAN_TO_RERUN: &str =
    "no scan open: nothing to rerun (File > Open scan…, or drop a scan folder here)";

/// The stage list: one `name: status` line per stage, timing, error text and a rerun button.
pub fn stages_ui(
    ui: &mut Ui,
    status: &[StageStatus; Stage::ALL.len()],
    times: &[Option<Duration>; Stage::ALL.len()],
    hide_times: bool,
) -> Vec<NavAction> {
    let mut out = Vec::new();
    for s in Stage::ALL {
        let st = &status[s.index()];
        ui.horizontal(|ui| {
            ui.colored_label(st.colour(), format!("{}: {}", s.name(), st.word()));
            if let (StageStatus::Fresh, Some(t)) = (st, times[s.index()]) {
                if hide_times {
                    ui.weak("– ms");
                } else {
                    ui.weak(format!("{:.0} ms", t.as_secs_f64() * 1000.0));
                }
            }
            // With no scan there is nothing to run: the button says why instead.
            let open = *st != StageStatus::NoScan;
            if ui
                .add_enabled(open, egui::Button::new("rerun").small())
                .on_hover_text(format!("rerun {} and later stages", s.name()))
                .on_disabled_hover_text(NO_SCAN_TO_RERUN)
                .clicked()
            {
                out.push(NavAction::Rerun(s));
            }
        });
        if let StageStatus::Failed(msg) = st {
            ui.label(egui::RichText::new(msg).small().color(st.colour()));
        }
    }
    out
}
