//! Hough view: the accumulator as a heat map over θ/ρ, the peaks and their windows (drag an edge to resize).

use egui::{Color32, Stroke, Ui};
use egui_plot::{LineStyle, Plot, PlotImage, PlotPoint, PlotPoints, Points, Polygon, VLine};

use super::frame_ui::StageData;
use super::stripes_ui::NO_DUAL_FOCUS;
use super::{empty_note, tint};
use crate::app::render::region_colour;
use crate::app::textures::Textures;
use crate::app::worker::ViewImage;
use crate::pipeline::hough::{HoughParams, MAX_WINDOW_THETA_DEG};
use crate::pipeline::{Stage, StageCache};

/// Pointer distance (screen points) that grabs a window edge.
pub const GRAB_PT: f32 = 6.0;

/// Which window size an edge drag changes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Edge {
    /// A left/right edge: the θ half-width.
    Theta(usize),
    /// A top/bottom edge: the ρ half-width.
    Rho(usize),
}

/// State of the Hough view.
#[derive(Clone, Debug, Default)]
pub struct HoughViewState {
    /// Edge under the pointer last frame.
    pub hover: Option<Edge>,
    /// Edge being dragged.
    pub dragging: Option<Edge>,
    /// Last read-out.
    pub readout: Option<String>,
    /// Where each peak's window was drawn last frame (screen points).
    pub windows_on_screen: Vec<egui::Rect>,
}

/// The window edge of one of `peaks` (θ°, ρ px) with half-sizes `(±θ°, ±ρ px)` within
/// [`GRAB_PT`] of the screen point `p`; `to_screen` maps plot values to the screen.
pub fn edge_near(
    peaks: &[(f64, f64)],
    (wt, wr): (f64, f64),
    p: egui::Pos2,
    to_screen: impl Fn(PlotPoint) -> egui::Pos2,
) -> Option<Edge> {
    peaks.iter().enumerate().find_map(|(i, &(t, r))| {
        let a = to_screen(PlotPoint::new(t - wt, r - wr));
        let b = to_screen(PlotPoint::new(t + wt, r + wr));
        let rect = egui::Rect::from_two_pos(a, b).expand(GRAB_PT);
        if !rect.contains(p) {
            return None;
        }
        if (p.x - a.x).abs() < GRAB_PT || (p.x - b.x).abs() < GRAB_PT {
            Some(Edge::Theta(i))
        } else if (p.y - a.y).abs() < GRAB_PT || (p.y - b.y).abs() < GRAB_PT {
            Some(Edge::Rho(i))
        } else {
            None
        }
    })
}

/// A label and a drag value labelled by it.
fn labelled_drag(
    ui: &mut Ui,
    text: &str,
    value: &mut f32,
    speed: f64,
    range: std::ops::RangeInclusive<f64>,
) {
    let l = ui.label(text);
    ui.add(egui::DragValue::new(value).speed(speed).range(range))
        .labelled_by(l.id);
}

/// Height of the controls and notes above the accumulator plot (points).
const CONTROLS_HEIGHT: f32 = 130.0;

/// Number controls of the windows and ranges; edits `draft`.
pub fn hough_controls(ui: &mut Ui, draft: &mut HoughParams) {
    ui.horizontal(|ui| {
        labelled_drag(
            ui,
            "window ±θ°",
            &mut draft.window_theta_deg,
            0.1,
            0.1..=f64::from(MAX_WINDOW_THETA_DEG),
        );
        labelled_drag(ui, "±ρ px", &mut draft.window_rho_px, 0.5, 0.5..=2000.0);
        ui.separator();
        labelled_drag(ui, "θ from°", &mut draft.theta_min_deg, 0.5, -90.0..=90.0);
        labelled_drag(ui, "to°", &mut draft.theta_max_deg, 0.5, -90.0..=90.0);
    });
}

impl HoughViewState {
    /// The Hough view. Edits `draft` when a window edge is dragged or a control changes.
    pub fn ui(
        &mut self,
        ui: &mut Ui,
        data: &StageData<'_>,
        textures: &Textures,
        draft: &mut HoughParams,
    ) {
        let status = data.banner(ui, Stage::Stripes);
        hough_controls(ui, draft);
        let missing = format!("no Hough accumulator: {NO_DUAL_FOCUS}");
        let Some(stripes) = data.output_or_note(ui, StageCache::stripes, &missing) else {
            return;
        };
        let Some(tex) =
            textures.get_or_note(ui, ViewImage::Accumulator, "accumulator not rendered yet")
        else {
            return;
        };
        let acc = &stripes.accumulator;
        let thetas: Vec<f64> = acc
            .thetas_rad
            .iter()
            .map(|t| f64::from(t.to_degrees()))
            .collect();
        let (Some(&t0), Some(&t1)) = (thetas.first(), thetas.last()) else {
            empty_note(ui, "empty accumulator");
            return;
        };
        let dt = if thetas.len() > 1 {
            (t1 - t0) / (thetas.len() - 1) as f64
        } else {
            1.0
        };
        // ρ bin r is centred on rho_min + r·step.
        let rho_step = f64::from(acc.rho_step_px);
        let rho0 = f64::from(acc.rho_min_px) - rho_step / 2.0;
        let rho_span = rho_step * acc.rho_bins as f64;
        let (lo_t, hi_t) = (t0 - dt / 2.0, t1 + dt / 2.0);
        let peaks: Vec<(f64, f64)> = stripes
            .peaks
            .iter()
            .map(|p| (f64::from(p.theta_rad.to_degrees()), f64::from(p.rho_px)))
            .collect();
        let (wt, wr) = (
            f64::from(draft.window_theta_deg),
            f64::from(draft.window_rho_px),
        );
        let dim = status.dim();
        let handle = tex.handle.clone();
        let max_votes = tex.rendered.hi;
        ui.weak(format!(
        "log-scaled votes (max {max_votes:.0}); boxes: peak windows (drag an edge to resize); dashed: the dropped top stripe"
    ));
        let drag_locked = self.hover.is_some() || self.dragging.is_some();
        let resp = Plot::new("hough_view")
            .height(data.height - CONTROLS_HEIGHT)
            .invert_y(true)
            .allow_drag(!drag_locked)
            .allow_boxed_zoom(false)
            .x_axis_label("θ (degrees)")
            .y_axis_label("ρ (px)")
            .show(ui, |plot_ui| {
                plot_ui.image(
                    PlotImage::new(
                        "accumulator",
                        handle.id(),
                        PlotPoint::new((lo_t + hi_t) / 2.0, rho0 + rho_span / 2.0),
                        [(hi_t - lo_t) as f32, rho_span as f32],
                    )
                    .tint(tint(dim)),
                );
                for (name, t) in [
                    ("θ min", draft.theta_min_deg),
                    ("θ max", draft.theta_max_deg),
                ] {
                    plot_ui.vline(
                        VLine::new(name, f64::from(t))
                            .color(Color32::GRAY)
                            .style(LineStyle::dashed_loose()),
                    );
                }
                for (i, &(t, r)) in peaks.iter().enumerate() {
                    let c = region_colour(i);
                    let style = if i == stripes.dropped {
                        LineStyle::dashed_dense()
                    } else {
                        LineStyle::Solid
                    };
                    plot_ui.polygon(
                        Polygon::new(
                            format!("window {i}"),
                            PlotPoints::from(vec![
                                [t - wt, r - wr],
                                [t + wt, r - wr],
                                [t + wt, r + wr],
                                [t - wt, r + wr],
                            ]),
                        )
                        .stroke(Stroke::new(1.5, c))
                        .fill_color(Color32::TRANSPARENT)
                        .style(style)
                        .allow_hover(false),
                    );
                    plot_ui.points(
                        Points::new(format!("peak {i}"), PlotPoints::from(vec![[t, r]]))
                            .color(c)
                            .radius(4.0)
                            .filled(true),
                    );
                }
            });
        // Edge hover and drag, in screen space. The edge a drag moves is the one under the point
        // where the button went down: egui reports the drag only once the pointer has moved past
        // its click distance, by when it may have left the edge.
        let tr = resp.transform;
        let pointer = resp
            .response
            .hover_pos()
            .or(resp.response.interact_pointer_pos());
        self.windows_on_screen = peaks
            .iter()
            .map(|&(t, r)| {
                egui::Rect::from_two_pos(
                    tr.position_from_point(&PlotPoint::new(t - wt, r - wr)),
                    tr.position_from_point(&PlotPoint::new(t + wt, r + wr)),
                )
            })
            .collect();
        let edge_at =
            |p: egui::Pos2| edge_near(&peaks, (wt, wr), p, |pt| tr.position_from_point(&pt));
        let near = pointer.and_then(edge_at);
        if resp.response.drag_started() {
            let origin = ui.input(|i| i.pointer.press_origin());
            self.dragging = origin.and_then(edge_at);
        }
        if let (Some(edge), Some(p)) = (self.dragging, pointer) {
            let v = tr.value_from_position(p);
            match edge {
                Edge::Theta(i) => {
                    if let Some(&(t, _)) = peaks.get(i) {
                        draft.window_theta_deg =
                            ((v.x - t).abs() as f32).clamp(0.1, MAX_WINDOW_THETA_DEG);
                    }
                }
                Edge::Rho(i) => {
                    if let Some(&(_, r)) = peaks.get(i) {
                        draft.window_rho_px = ((v.y - r).abs() as f32).max(0.5);
                    }
                }
            }
        }
        if resp.response.drag_stopped() || !resp.response.is_pointer_button_down_on() {
            self.dragging = None;
        }
        self.hover = near;
        if near.is_some() || self.dragging.is_some() {
            let icon = match self.dragging.or(near) {
                Some(Edge::Theta(_)) => egui::CursorIcon::ResizeHorizontal,
                _ => egui::CursorIcon::ResizeVertical,
            };
            ui.ctx().set_cursor_icon(icon);
        }
        if let Some(p) = resp.response.hover_pos() {
            let v = tr.value_from_position(p);
            let ti = ((v.x - t0) / dt).round();
            let ri = ((v.y - rho0) / rho_step).floor();
            if ti >= 0.0
                && ri >= 0.0
                && (ti as usize) < thetas.len()
                && (ri as usize) < acc.rho_bins
            {
                let votes = acc.get(ti as usize, ri as usize);
                self.readout = Some(format!("θ {:.2}°  ρ {:.1} px  ·  {votes} votes", v.x, v.y));
            }
        }
        ui.label(
            self.readout
                .as_deref()
                .unwrap_or("hover the accumulator for a read-out"),
        );
        for (i, p) in stripes.peaks.iter().enumerate() {
            ui.label(format!(
                "peak {i}: θ {:.2}°  ρ {:.1} px  {} votes{}",
                p.theta_rad.to_degrees(),
                p.rho_px,
                p.votes,
                if i == stripes.dropped {
                    "  (dropped)"
                } else {
                    ""
                }
            ));
        }
    }
}
