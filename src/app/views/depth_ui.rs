//! Depth view: the Kalman depth map as a heat map with a colour bar and wall lines, and a cross-section across the groove.

use egui::{Color32, Rect, Sense, Stroke, Ui, vec2};
use egui_plot::{Line, LineStyle, Plot, PlotPoints, VLine};

use super::frame_ui::StageData;
use super::{AXIS_WIDTH_PT, hovered_pixel, image_item, image_plot, wall_lines};
use crate::app::render::heat_colour;
use crate::app::textures::Textures;
use crate::app::worker::ViewImage;
use crate::pipeline::{Stage, StageCache};
use crate::viz::robust_range;

/// Colour bands in the colour bar.
const BAR_BANDS: usize = 64;

/// State of the depth view.
#[derive(Clone, Debug, Default)]
pub struct DepthViewState {
    /// Column of the cross-section (None: the middle).
    pub column: Option<usize>,
    /// Last read-out.
    pub readout: Option<String>,
}

/// A vertical colour bar from `lo` (bottom) to `hi` (top) with its unit.
pub fn colour_bar(ui: &mut Ui, lo: f32, hi: f32, unit: &str, height: f32) {
    ui.vertical(|ui| {
        ui.label(format!("{hi:.1} {unit}"));
        let (rect, _) =
            ui.allocate_exact_size(vec2(22.0, (height - 50.0).max(40.0)), Sense::hover());
        let painter = ui.painter_at(rect);
        let band_h = rect.height() / BAR_BANDS as f32;
        for i in 0..BAR_BANDS {
            let t = 1.0 - (i as f32 + 0.5) / BAR_BANDS as f32;
            let top = rect.top() + i as f32 * band_h;
            painter.rect_filled(
                Rect::from_min_size(
                    egui::pos2(rect.left(), top),
                    vec2(rect.width(), band_h + 0.5),
                ),
                0.0,
                heat_colour(t),
            );
        }
        painter.rect_stroke(
            rect,
            0.0,
            Stroke::new(1.0, Color32::GRAY),
            egui::StrokeKind::Inside,
        );
        ui.label(format!("{lo:.1} {unit}"));
    });
}

impl DepthViewState {
    /// The depth view.
    pub fn ui(&mut self, ui: &mut Ui, data: &StageData<'_>, textures: &Textures) {
        let missing =
            "no depth map: the depth path has not run (dual-focus scans use stripes instead)";
        let Some((status, depth)) = data.stage_output(ui, Stage::Depth, StageCache::depth, missing)
        else {
            return;
        };
        let Some(tex) = textures.get_or_note(ui, ViewImage::Depth, "depth map not rendered yet")
        else {
            return;
        };
        let (lo, hi) = (tex.rendered.lo, tex.rendered.hi);
        let handle = tex.handle.clone();
        let z = &depth.map.z_um;
        let column = self
            .column
            .unwrap_or(z.width / 2)
            .min(z.width.saturating_sub(1));
        let dim = status.dim();
        ui.weak("click the map to choose the cross-section column; lines: wall lines");
        let img_h = data.height * 0.62;
        let resp = ui
            .horizontal(|ui| {
                let resp = image_plot("depth_view", img_h)
                    .width((ui.available_width() - 90.0).max(100.0))
                    .show(ui, |plot_ui| {
                        plot_ui.image(image_item("depth", &handle, dim));
                        wall_lines(plot_ui, &depth.walls, Color32::WHITE);
                        plot_ui.vline(
                            VLine::new("cross-section", column as f64 + 0.5)
                                .color(Color32::from_rgb(255, 0, 200))
                                .style(LineStyle::dashed_loose()),
                        );
                    });
                colour_bar(ui, lo, hi, "µm", img_h);
                resp
            })
            .inner;
        if let Some((x, y)) = hovered_pixel(&resp, handle.size()) {
            let var = depth.map.variance.get(x, y).unwrap_or(f32::NAN);
            self.readout = Some(format!("{}  ·  variance {var:.3} µm²", data.readout(x, y)));
            if resp.response.clicked() {
                self.column = Some(x);
            }
        }
        ui.label(
            self.readout
                .as_deref()
                .unwrap_or("hover the map for a read-out"),
        );
        super::guidance::warnings_ui(ui, &depth.map.warnings, 2);
        let section: Vec<[f64; 2]> = (0..z.height)
            .filter_map(|y| {
                let v = z.get(column, y)?;
                v.is_finite().then_some([y as f64, f64::from(v)])
            })
            .collect();
        let walls: Vec<f64> = depth
            .walls
            .iter()
            .filter_map(|w| w.rows.get(column).copied())
            .filter(|r| r.is_finite())
            .map(f64::from)
            .collect();
        // Y range from the map's robust range (as the colour bar), so a stray border value does
        // not squash the section into a flat line; double-click still fits everything.
        let mut plot = Plot::new("depth_section");
        if let Some((lo, hi)) = robust_range(&z.data).filter(|(lo, hi)| lo < hi) {
            let pad = 0.1 * f64::from(hi - lo);
            plot = plot.default_y_bounds(f64::from(lo) - pad, f64::from(hi) + pad);
        }
        plot.y_axis_min_width(AXIS_WIDTH_PT)
            .height((data.height - img_h - 60.0).max(80.0))
            .x_axis_label(format!("y (px) at column {column}"))
            .y_axis_label("Z (µm)")
            .invert_y(false)
            .show(ui, |plot_ui| {
                plot_ui.line(
                    Line::new("Z across the groove", PlotPoints::from(section))
                        .color(Color32::from_rgb(120, 200, 255)),
                );
                for (i, r) in walls.into_iter().enumerate() {
                    plot_ui.vline(
                        VLine::new(format!("wall {i}"), r)
                            .color(Color32::WHITE)
                            .style(LineStyle::dashed_dense()),
                    );
                }
            });
    }
}
