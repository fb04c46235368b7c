//! Flow view: the flow field of one derivative window as a colour image or as arrows over its frame.

use egui::Ui;

use super::frame_ui::{ArrowOptions, StageData, arrow_controls, flow_arrows};
use super::{empty_note, hovered_pixel, image_item, image_plot, stage_banner};
use crate::app::textures::Textures;
use crate::pipeline::Stage;

/// State of the flow view.
#[derive(Clone, Debug, Default)]
pub struct FlowViewState {
    /// Index of the flow field shown (None: the middle one).
    pub window: Option<usize>,
    /// Show arrows over the frame instead of the colour image.
    pub arrows_over_frame: bool,
    /// Arrow options.
    pub arrows: ArrowOptions,
    /// Last read-out.
    pub readout: Option<String>,
}

/// The flow view.
pub fn flow_ui(
    ui: &mut Ui,
    data: &StageData<'_>,
    textures: &mut Textures,
    state: &mut FlowViewState,
    height: f32,
) {
    let status = data.status(Stage::Flow).clone();
    stage_banner(ui, Stage::Flow, &status);
    let Some(flows) = data.cache.flows().cloned() else {
        empty_note(ui, "no flow yet");
        return;
    };
    if flows.is_empty() {
        empty_note(ui, "the flow stage produced no fields");
        return;
    }
    let mut window = state.window.unwrap_or(flows.len() / 2).min(flows.len() - 1);
    ui.horizontal(|ui| {
        let l = ui.label("window");
        egui::ComboBox::from_id_salt("flow_window")
            .selected_text(format!(
                "{} (frame {})",
                window,
                flows.get(window).map_or(0, |f| f.frame_index)
            ))
            .show_ui(ui, |ui| {
                for (i, f) in flows.iter().enumerate() {
                    ui.selectable_value(&mut window, i, format!("{i} (frame {})", f.frame_index));
                }
            })
            .response
            .labelled_by(l.id);
        ui.separator();
        ui.selectable_value(&mut state.arrows_over_frame, false, "colour");
        ui.selectable_value(&mut state.arrows_over_frame, true, "arrows over frame");
        if let Some(f) = flows.get(window) {
            ui.separator();
            ui.label(format!(
                "{} iterations{}",
                f.iterations,
                if f.converged {
                    ", converged"
                } else {
                    ", not converged"
                }
            ));
        }
    });
    state.window = Some(window);
    if state.arrows_over_frame {
        arrow_controls(ui, &mut state.arrows);
    }
    let Some(field) = flows.get(window) else {
        return;
    };
    let dim = status.dim();
    let land = data.land_flow_px();
    let (tex, hi) = if state.arrows_over_frame {
        let Some(frames) = data.frames else {
            empty_note(ui, "frames not loaded");
            return;
        };
        let Some(t) = textures
            .frame(ui.ctx(), data.group, field.frame_index, frames)
            .cloned()
        else {
            return;
        };
        (t, None)
    } else {
        let Some(t) = textures.flow(
            ui.ctx(),
            &flows,
            data.cache.output_id(Stage::Flow),
            window,
            land as f32,
        ) else {
            return;
        };
        (t.handle.clone(), Some(t.rendered.hi))
    };
    if let Some(hi) = hi {
        ui.weak(format!(
            "hue = direction (red: +x, cyan: −x), saturation = magnitude up to {hi:.3} px/frame; black = no confidence"
        ));
    }
    let resp = image_plot("flow_view", height).show(ui, |plot_ui| {
        plot_ui.image(image_item("flow", &tex, dim));
        if state.arrows_over_frame {
            flow_arrows(plot_ui, field, &state.arrows, land);
        }
    });
    if let Some((x, y)) = hovered_pixel(&resp, tex.size()) {
        let (u, v, c) = (
            field.u.get(x, y),
            field.v.get(x, y),
            field.confidence.get(x, y),
        );
        if let (Some(u), Some(v), Some(c)) = (u, v, c) {
            state.readout = Some(format!(
                "x {x}  y {y}  ·  u {u:+.4}  v {v:+.4} px/frame  ·  confidence {c:.4}"
            ));
        }
    }
    ui.label(
        state
            .readout
            .as_deref()
            .unwrap_or("hover the image for a read-out"),
    );
}
