//! Stripes view: segmented in-focus stripes and their centroid lines over the frame, filled voids marked.

use egui::{Color32, Ui};
use egui_plot::{HLine, LineStyle};

use super::frame_ui::StageData;
use super::{empty_note, hovered_pixel, image_item, image_plot, wall_lines};
use crate::app::textures::Textures;
use crate::app::worker::ViewImage;
use crate::pipeline::hough::label;
use crate::pipeline::{Stage, StageCache};

/// What the stripes view shows under the lines.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum StripesBase {
    /// Regions coloured over the dimmed frame, centroid lines drawn in (magenta = filled voids).
    #[default]
    Segmentation,
    /// The frame, with the centroid lines drawn over it.
    Frame,
    /// The in-focus map, with the centroid lines drawn over it.
    InFocus,
}

/// Why the dual-focus stages have no output.
pub const NO_DUAL_FOCUS: &str =
    "the dual-focus path has not run (scan without [dual_focus], or path = depth)";

/// State of the stripes view.
#[derive(Clone, Debug, Default)]
pub struct StripesViewState {
    /// The base image.
    pub base: StripesBase,
    /// Last read-out.
    pub readout: Option<String>,
}

impl StripesViewState {
    /// The stripes view.
    pub fn ui(&mut self, ui: &mut Ui, data: &StageData<'_>, textures: &mut Textures) {
        let missing = format!("no stripes: {NO_DUAL_FOCUS}");
        let Some((status, stripes)) =
            data.stage_output(ui, Stage::Stripes, StageCache::stripes, &missing)
        else {
            return;
        };
        ui.horizontal(|ui| {
        ui.selectable_value(&mut self.base, StripesBase::Segmentation, "segmentation");
        ui.selectable_value(&mut self.base, StripesBase::Frame, "frame");
        ui.selectable_value(&mut self.base, StripesBase::InFocus, "in-focus map");
        ui.weak("regions: one colour per stripe (red: in two windows); lines: centroids (magenta = filled voids); dashed: glass edge");
    });
        let frame_index = data
            .cache
            .derivatives()
            .as_ref()
            .and_then(|d| d.get(d.len() / 2))
            .map_or(data.frame, |d| d.frame_index);
        let base = match self.base {
            StripesBase::Segmentation => textures
                .get(ViewImage::Segmentation)
                .map(|t| t.handle.clone()),
            StripesBase::InFocus => textures.get(ViewImage::InFocus).map(|t| t.handle.clone()),
            StripesBase::Frame => data.frames.and_then(|f| {
                textures
                    .frame(ui.ctx(), data.group, frame_index, f)
                    .cloned()
            }),
        };
        let Some(base) = base else {
            empty_note(ui, "not rendered yet");
            return;
        };
        let vector_lines = self.base != StripesBase::Segmentation;
        let dim = status.dim();
        let glass = data
            .meta
            .and_then(|m| m.dual_focus.as_ref())
            .map(|d| d.glass_edge_row);
        let resp = image_plot("stripes_view", data.height).show(ui, |plot_ui| {
            plot_ui.image(image_item("base", &base, dim));
            if vector_lines {
                wall_lines(plot_ui, &stripes.lines, Color32::from_rgb(255, 240, 80));
            }
            if let Some(row) = glass {
                plot_ui.hline(
                    HLine::new("glass edge", row)
                        .color(Color32::LIGHT_BLUE)
                        .style(LineStyle::dashed_loose()),
                );
            }
        });
        if let Some((x, y)) = hovered_pixel(&resp, base.size()) {
            let l = stripes.label_at(x, y);
            let what = match l {
                l if l >= 0 && l as usize == stripes.dropped => format!("stripe {l} (dropped)"),
                l if l >= 0 => format!("stripe {l}"),
                label::DISCARDED => "in two windows (discarded)".into(),
                label::UNASSIGNED => "in focus, in no window".into(),
                _ => "not in focus".into(),
            };
            self.readout = Some(format!("{}  ·  {what}", data.readout(x, y)));
        }
        ui.label(
            self.readout
                .as_deref()
                .unwrap_or("hover the image for a read-out"),
        );
        for (i, l) in stripes.lines.iter().enumerate() {
            let filled = l.filled.iter().filter(|f| **f).count();
            ui.label(format!(
                "line {i} ({:?} wall): depth {}  ·  {filled} filled columns",
                l.side,
                l.depth_um.map_or("?".into(), |d| format!("{d:.1} µm")),
            ));
        }
    }
}
