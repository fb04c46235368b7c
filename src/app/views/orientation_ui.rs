//! Orientation view: wall tilt tan θ along x per wall, and the robust fit's weight (outlier) map.

use egui::{Color32, Ui};

use super::frame_ui::StageData;
use super::{hovered_pixel, image_item, image_plot, wall_curves, wall_lines};
use crate::app::render::NO_FIT_COLOUR;
use crate::app::textures::Textures;
use crate::app::worker::ViewImage;
use crate::pipeline::orientation::WallOrientation;
use crate::pipeline::{Stage, StageCache};

/// State of the orientation view.
#[derive(Clone, Debug, Default)]
pub struct OrientationViewState {
    /// Last read-out.
    pub readout: Option<String>,
}

/// Splits a wall's samples into lines of (x, tan θ), breaking where a fit is missing.
#[must_use]
pub fn tan_segments(wall: &WallOrientation) -> Vec<Vec<[f64; 2]>> {
    super::finite_runs(wall.samples.iter().map(|s| {
        let tan = if s.fit.is_some() {
            s.tan_theta
        } else {
            f64::NAN
        };
        [f64::from(s.x_px), tan]
    }))
}

/// What the outlier share means, for the hover of its read-out.
#[must_use]
pub fn outlier_note(p: &crate::pipeline::PipelineParams) -> String {
    let o = &p.orientation;
    format!(
        "Points further than {:.1} σ from their fitted wall plane, with σ the fit's final scale \
         (it shrinks each round, but not below σ min = {} µm). On a clean scan the residuals \
         are often larger than that floor, so most points count and a share near 90 % can go \
         with a very good sound. What marks damage is a group whose share stands well above \
         the others: the health strip colours those.",
        o.outlier_sigmas, o.sigma_min_um
    )
}

impl OrientationViewState {
    /// The orientation view.
    pub fn ui(&mut self, ui: &mut Ui, data: &StageData<'_>, textures: &Textures) {
        let missing = "no orientation yet";
        let Some((status, out)) =
            data.stage_output(ui, Stage::Orientation, StageCache::orientation, missing)
        else {
            return;
        };
        let o = &out.orientation;
        let walls = o.walls.len();
        ui.horizontal(|ui| {
            ui.label(format!(
                "{walls} wall{}  ·  {} sample columns  ·  {:.4} µm per column  ·  ",
                if walls == 1 { "" } else { "s" },
                out.grid.columns.len(),
                out.grid.um_per_px
            ));
            ui.label(format!(
                "outliers {:.1} % of fit points (what?)",
                100.0 * o.outlier_fraction
            ))
            .on_hover_text(outlier_note(data.params));
        });
        let plot_h = data.height * 0.4;
        let curves = o
            .walls
            .iter()
            .map(|w| (format!("{:?} wall", w.side), tan_segments(w)))
            .collect();
        let axes = ["x (px)", "tan θ (= V / Vt)"];
        wall_curves(ui, "orientation_plot", plot_h, axes, curves);
        let Some(tex) = textures.get_or_note(ui, ViewImage::Weights, "weight map not rendered yet")
        else {
            return;
        };
        ui.horizontal(|ui| {
            ui.weak("robust-fit weight per pixel: bright = trusted, dark = outlier,");
            super::guidance::swatch(ui, NO_FIT_COLOUR);
            ui.weak("not in any fit; lines: walls");
        });
        let handle = tex.handle.clone();
        let dim = status.dim();
        let lines = data
            .cache
            .depth()
            .as_ref()
            .map(|d| d.walls.clone())
            .or_else(|| data.cache.stripes().map(|s| s.lines.clone()))
            .unwrap_or_default();
        let resp = image_plot(
            "orientation_weights",
            (data.height - plot_h - 70.0).max(100.0),
        )
        .show(ui, |plot_ui| {
            plot_ui.image(image_item("weights", &handle, dim));
            wall_lines(plot_ui, &lines, Color32::WHITE);
        });
        if let Some((x, y)) = hovered_pixel(&resp, handle.size()) {
            let weight = match o.weight_map.get(x, y) {
                Some(w) if w.is_finite() => format!("weight {w:.3}"),
                _ => "not in any fit".into(),
            };
            let near = o.walls.iter().filter_map(|wall| {
                wall.samples
                    .iter()
                    .min_by(|a, b| {
                        (a.x_px - x as f32)
                            .abs()
                            .total_cmp(&(b.x_px - x as f32).abs())
                    })
                    .map(|s| (wall.side, s))
            });
            let mut text = format!("x {x}  y {y}  ·  {weight}");
            for (side, s) in near {
                text += &format!("  ·  {side:?}: tan θ {:+.5}", s.tan_theta);
                if let Some(f) = s.fit {
                    text += &format!(
                        " ({:?}, {} rounds, {:.0} % outliers)",
                        f.stop,
                        f.iterations,
                        100.0 * f.outlier_fraction
                    );
                }
            }
            self.readout = Some(text);
        }
        ui.label(
            self.readout
                .as_deref()
                .unwrap_or("hover the map for a read-out"),
        );
    }
}
