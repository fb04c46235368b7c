//! Flow view: the flow field of one derivative window as a colour image or as arrows over its frame.

use egui::Ui;

use super::frame_ui::{ArrowOptions, StageData, arrow_controls, flow_arrows};
use super::{empty_note, hovered_pixel, image_item, image_plot};
use crate::app::textures::Textures;
use crate::pipeline::optical_flow::{
    FlowField, FlowMethod, FlowParams, WALL_PRESOLVE_MAX_ITERATIONS, WALL_PRESOLVE_TOLERANCE_PX,
};
use crate::pipeline::{Stage, StageCache};

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

/// The iteration read-out of one field and its explanation. Where the groove method finds the
/// wall sides itself it runs a plain pass first (to its own tolerance, within at least
/// [`WALL_PRESOLVE_MAX_ITERATIONS`]) and then the groove pass, which the cap and τ apply to;
/// the field's count holds both, so it can exceed the cap.
#[must_use]
pub fn iterations_text(f: &FlowField, p: &FlowParams) -> (String, String) {
    let state = if f.converged {
        "converged"
    } else {
        "stopped at the cap"
    };
    let cap = p.max_iterations;
    if p.method != FlowMethod::GrooveHornSchunck {
        return (
            format!("{} of at most {cap} iterations, {state}", f.iterations),
            format!(
                "Stops when the mean change per iteration falls below τ = {} px, or at the cap.",
                p.tolerance_px
            ),
        );
    }
    let hover = format!(
        "Where the wall sides are found in this window, a plain pass runs first (to \
         {WALL_PRESOLVE_TOLERANCE_PX:e} px, within at least {} iterations), then the groove \
         pass, which the cap of {cap} and τ = {} px apply to; the count holds both passes.",
        WALL_PRESOLVE_MAX_ITERATIONS.max(cap),
        p.tolerance_px
    );
    let text = if f.iterations > cap {
        format!(
            "{} iterations: wall pass + groove pass (the cap of {cap} is the groove pass's), {state}",
            f.iterations
        )
    } else {
        format!("{} iterations, {state}", f.iterations)
    };
    (text, hover)
}

/// The colour key of the flow image: a swatch for each direction in the very colours the
/// image uses, and the magnitude at full colour.
pub fn flow_legend(ui: &mut Ui, hi_px: f32) {
    let swatch = |u: f32, v: f32| {
        let [r, g, b, _] = crate::viz::flow_color(u, v);
        egui::Color32::from_rgb(r, g, b)
    };
    ui.horizontal(|ui| {
        ui.weak("direction:");
        for (name, u, v) in [
            ("+x", 1.0, 0.0),
            ("−x", -1.0, 0.0),
            ("+y (down)", 0.0, 1.0),
            ("−y", 0.0, -1.0),
        ] {
            super::guidance::swatch(ui, swatch(u, v));
            ui.weak(name);
        }
        ui.weak(format!(
            "· full colour at {hi_px:.3} px/frame, white = moves with the record surface"
        ));
    });
}

impl FlowViewState {
    /// The flow view.
    pub fn ui(&mut self, ui: &mut Ui, data: &StageData<'_>, textures: &mut Textures) {
        let Some((status, flows)) =
            data.stage_output(ui, Stage::Flow, StageCache::flows, "no flow yet")
        else {
            return;
        };
        if flows.is_empty() {
            empty_note(ui, "the flow stage produced no fields");
            return;
        }
        let mut window = self.window.unwrap_or(flows.len() / 2).min(flows.len() - 1);
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
                        ui.selectable_value(
                            &mut window,
                            i,
                            format!("{i} (frame {})", f.frame_index),
                        );
                    }
                })
                .response
                .labelled_by(l.id);
            ui.separator();
            ui.selectable_value(&mut self.arrows_over_frame, false, "colour");
            ui.selectable_value(&mut self.arrows_over_frame, true, "arrows over frame");
            if let Some(f) = flows.get(window) {
                ui.separator();
                let (text, hover) = iterations_text(f, &data.params.flow);
                ui.label(text).on_hover_text(hover);
            }
        });
        self.window = Some(window);
        if self.arrows_over_frame {
            arrow_controls(ui, &mut self.arrows);
        }
        let Some(field) = flows.get(window) else {
            return;
        };
        let dim = status.dim();
        let land = data.land_flow_px();
        let (tex, hi) = if self.arrows_over_frame {
            let Some(t) = data.frame_texture(ui, textures, field.frame_index) else {
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
            flow_legend(ui, hi);
        }
        let resp = image_plot("flow_view", data.height).show(ui, |plot_ui| {
            plot_ui.image(image_item("flow", &tex, dim));
            if self.arrows_over_frame {
                flow_arrows(plot_ui, field, &self.arrows, land);
            }
        });
        if let Some((x, y)) = hovered_pixel(&resp, tex.size()) {
            let (u, v, c) = (
                field.u.get(x, y),
                field.v.get(x, y),
                field.confidence.get(x, y),
            );
            if let (Some(u), Some(v), Some(c)) = (u, v, c) {
                self.readout = Some(format!(
                    "x {x}  y {y}  ·  u {u:+.4}  v {v:+.4} px/frame  ·  confidence {c:.4}"
                ));
            }
        }
        ui.label(
            self.readout
                .as_deref()
                .unwrap_or("hover the image for a read-out"),
        );
    }
}
