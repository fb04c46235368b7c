//! Edges view: the four fitted borders on the frame they were read on, and each wall's displacement along the groove.

use egui::{Color32, Ui};
use egui_plot::{Legend, PlotPoints, Points};

use super::frame_ui::StageData;
use super::{finite_runs, hovered_pixel, image_item, image_plot, wall_curves};
use crate::app::textures::Textures;
use crate::io::Cut;
use crate::pipeline::edges::Edges;
use crate::pipeline::{Stage, StageCache};
use crate::viz::border_fit_points;

/// The borders' colours ([`crate::viz::BORDER_RGBA`], as the inspect command's PNG draws them).
const BORDER_COLOURS: [Color32; 4] = {
    let c = crate::viz::BORDER_RGBA;
    [
        Color32::from_rgb(c[0][0], c[0][1], c[0][2]),
        Color32::from_rgb(c[1][0], c[1][1], c[1][2]),
        Color32::from_rgb(c[2][0], c[2][1], c[2][2]),
        Color32::from_rgb(c[3][0], c[3][1], c[3][2]),
    ]
};

/// State of the edges view.
#[derive(Clone, Debug, Default)]
pub struct EdgesViewState {
    /// Last read-out.
    pub readout: Option<String>,
}

/// One line on the group: what was read where, and how much of each border was seen.
#[must_use]
pub fn summary(e: &Edges) -> String {
    let n = e.positions_um.len();
    let seen: Vec<String> = e
        .borders
        .iter()
        .map(|b| {
            let found = b.y_um.iter().filter(|y| y.is_finite()).count();
            format!("{} {found}/{n}", b.id.name())
        })
        .collect();
    let bottom = if e.bottom_depth_um.is_finite() {
        format!("{:.1} µm", e.bottom_depth_um)
    } else {
        "not measured".into()
    };
    let one_track = if e.cut == Cut::Lateral {
        "  ·  a lateral cut: both walls move as one"
    } else {
        ""
    };
    let noise = e.coarse.pixel_noise_grey_levels.map_or_else(
        || "pixel noise not measured".into(),
        |l| format!("pixel noise {l:.2} grey levels of 255"),
    );
    format!(
        "read on frame {} ({noise}: blurred borders read at most ±{:.0} px)  ·  {n} samples \
         {:.2} µm apart  ·  bottom {bottom} below the land  ·  seen: {}{one_track}",
        e.coarse.frame,
        e.coarse.band_cap_px,
        e.spacing_um,
        seen.join(", ")
    )
}

impl EdgesViewState {
    /// The edges view.
    pub fn ui(&mut self, ui: &mut Ui, data: &StageData<'_>, textures: &mut Textures) {
        let missing = "no edges yet (the flow method alone reads none: choose edges or fused)";
        let Some((status, e)) = data.stage_output(ui, Stage::Edges, StageCache::edges, missing)
        else {
            return;
        };
        ui.label(summary(&e));
        super::guidance::warnings_ui(ui, &e.warnings, 3);
        let plot_h = data.height * 0.35;
        let start = e.positions_um.first().copied().unwrap_or(0.0);
        let curves = e
            .walls
            .iter()
            .map(|w| {
                let points = e
                    .positions_um
                    .iter()
                    .zip(&w.displacement_um)
                    .map(|(&s, &d)| [s - start, d]);
                (format!("{:?} wall", w.side), finite_runs(points))
            })
            .collect();
        let axes = [
            "along the groove in this group (µm)",
            "wall displacement (µm)",
        ];
        wall_curves(ui, "edges_displacement", plot_h, axes, curves);
        let Some(tex) = data.frame_texture(ui, textures, e.coarse.frame) else {
            return;
        };
        ui.weak("the frame the borders were read on; dots: each sample's fitted border row");
        let points: Vec<Vec<Option<[f64; 2]>>> = e.borders.iter().map(border_fit_points).collect();
        let dim = status.dim();
        let resp = image_plot("edges_frame", (data.height - plot_h - 90.0).max(100.0))
            .legend(Legend::default())
            .show(ui, |plot_ui| {
                plot_ui.image(image_item("frame", &tex, dim));
                for (b, pts) in e.borders.iter().zip(&points) {
                    let seen: Vec<[f64; 2]> = pts.iter().flatten().copied().collect();
                    plot_ui.add(
                        Points::new(b.id.name(), PlotPoints::from(seen))
                            .color(BORDER_COLOURS[b.id as usize])
                            .radius(1.5),
                    );
                }
            });
        if let Some((x, _)) = hovered_pixel(&resp, tex.size()) {
            self.readout = Some(readout(&e, &points, x as f64 + 0.5));
        }
        ui.label(
            self.readout
                .as_deref()
                .unwrap_or("hover the frame for a read-out"),
        );
    }
}

/// The read-out of the sample nearest column `x`: each border's record `y`, standard error and
/// weight in the combination.
fn readout(e: &Edges, points: &[Vec<Option<[f64; 2]>>], x: f64) -> String {
    let nearest = points
        .iter()
        .flat_map(|pts| pts.iter().enumerate())
        .filter_map(|(i, p)| p.map(|p| (i, (p[0] - x).abs())))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(i, _)| i);
    let Some(i) = nearest else {
        return "no border was fitted in this group".into();
    };
    let mut text = format!(
        "sample {} at {:.1} µm",
        e.first_sample + i as i64,
        e.positions_um.get(i).copied().unwrap_or(f64::NAN)
    );
    for b in &e.borders {
        let y = b.y_um.get(i).copied().unwrap_or(f64::NAN);
        if y.is_finite() {
            text += &format!(
                "  ·  {}: {y:.3} ± {:.3} µm, weight {:.2}",
                b.id.name(),
                b.std_error_um.get(i).copied().unwrap_or(f64::NAN),
                b.weight.get(i).copied().unwrap_or(f64::NAN)
            );
        } else {
            text += &format!("  ·  {}: not found", b.id.name());
        }
    }
    text
}
