//! Frame viewer: pan/zoom over the group's frames with a pixel read-out (grey, flow, depth) and optional flow arrows.

use std::sync::Arc;

use egui::Ui;
use egui_plot::{Arrows, PlotPoints, PlotUi};

use super::{StageStatus, empty_note, hovered_pixel, image_item, image_plot, stage_banner};
use crate::app::render::heat_colour;
use crate::app::textures::Textures;
use crate::image::Image;
use crate::io::ScanMeta;
use crate::pipeline::optical_flow::FlowField;
use crate::pipeline::{PipelineParams, Stage, StageCache};

/// Colour bins of flow arrows.
const ARROW_BINS: usize = 8;

/// Arrow origins and tips of one colour bin.
type ArrowBin = (Vec<[f64; 2]>, Vec<[f64; 2]>);

/// Read-only data of the current group that every stage view draws from.
pub struct StageData<'a> {
    /// Latest stage results (possibly stale).
    pub cache: &'a StageCache,
    /// The group's frames, once loaded.
    pub frames: Option<&'a Arc<Vec<Image>>>,
    /// Why the frames could not be loaded.
    pub load_error: Option<&'a str>,
    /// Group index.
    pub group: usize,
    /// Frame index within the group.
    pub frame: usize,
    /// Status per stage (index = `Stage::index`).
    pub status: &'a [StageStatus; Stage::ALL.len()],
    /// Current params.
    pub params: &'a PipelineParams,
    /// The scan's metadata.
    pub meta: Option<&'a ScanMeta>,
    /// Height the view may fill (points).
    pub height: f32,
}

impl StageData<'_> {
    /// The texture of frame `index` of the group, or None after a note saying why (the frames
    /// are loading or failed to load, or the group has no such frame).
    pub fn frame_texture(
        &self,
        ui: &mut Ui,
        textures: &mut Textures,
        index: usize,
    ) -> Option<egui::TextureHandle> {
        let Some(frames) = self.frames else {
            match self.load_error {
                Some(e) => {
                    ui.colored_label(StageStatus::Failed(String::new()).colour(), e);
                }
                None => empty_note(ui, "loading frames…"),
            }
            return None;
        };
        let tex = textures.frame(ui.ctx(), self.group, index, frames).cloned();
        if tex.is_none() {
            empty_note(ui, "no such frame");
        }
        tex
    }

    /// Status of `stage`.
    #[must_use]
    pub fn status(&self, stage: Stage) -> &StageStatus {
        &self.status[stage.index()]
    }

    /// Draws `stage`'s status banner and returns the status (a view dims a stale result).
    pub fn banner(&self, ui: &mut Ui, stage: Stage) -> StageStatus {
        let status = self.status(stage).clone();
        stage_banner(ui, stage, &status);
        status
    }

    /// A stage output of the cache, cloned; when there is none, `missing` is drawn as the
    /// view's note instead.
    pub fn output_or_note<T: Clone>(
        &self,
        ui: &mut Ui,
        output: impl FnOnce(&StageCache) -> Option<&T>,
        missing: &str,
    ) -> Option<T> {
        let out = output(self.cache).cloned();
        if out.is_none() {
            empty_note(ui, missing);
        }
        out
    }

    /// What a stage view starts with: `stage`'s [`Self::banner`], then its output
    /// ([`Self::output_or_note`]) with the status.
    pub fn stage_output<T: Clone>(
        &self,
        ui: &mut Ui,
        stage: Stage,
        output: impl FnOnce(&StageCache) -> Option<&T>,
        missing: &str,
    ) -> Option<(StageStatus, T)> {
        let status = self.banner(ui, stage);
        Some((status, self.output_or_note(ui, output, missing)?))
    }

    /// The flow field computed on `frame` (or the middle one when none matches).
    #[must_use]
    pub fn flow_for_frame(&self, frame: usize) -> Option<(usize, &FlowField)> {
        let flows = self.cache.flows()?;
        flows
            .iter()
            .enumerate()
            .find(|(_, f)| f.frame_index == frame)
            .or_else(|| flows.get(flows.len() / 2).map(|f| (flows.len() / 2, f)))
    }

    /// Land (record surface) flow in px/frame, from the metadata.
    #[must_use]
    pub fn land_flow_px(&self) -> f64 {
        self.meta.map_or(0.0, |m| m.geometry().land_flow_px())
    }

    /// Read-out text for pixel `(x, y)`: grey value, flow and depth where known.
    #[must_use]
    pub fn readout(&self, x: usize, y: usize) -> String {
        let mut s = format!("x {x}  y {y}");
        if let Some(g) = self
            .frames
            .and_then(|f| f.get(self.frame))
            .and_then(|f| f.get(x, y))
        {
            s += &format!("  ·  grey {g:.4}");
        }
        if let Some((_, f)) = self.flow_for_frame(self.frame)
            && let (Some(u), Some(v)) = (f.u.get(x, y), f.v.get(x, y))
        {
            s += &format!("  ·  flow ({u:+.4}, {v:+.4}) px/frame");
        }
        if let Some(z) = self.cache.depth().and_then(|d| d.map.z_um.get(x, y)) {
            s += &format!("  ·  depth {z:.2} µm");
        }
        s
    }
}

/// Options of flow arrows.
#[derive(Clone, Debug, PartialEq)]
pub struct ArrowOptions {
    /// Draw arrows at all.
    pub show: bool,
    /// Grid spacing (px).
    pub spacing_px: usize,
    /// Arrow length per px/frame of flow.
    pub scale: f32,
    /// Subtract the land flow, so arrows show what depth changes.
    pub relative_to_land: bool,
}

impl Default for ArrowOptions {
    fn default() -> Self {
        Self {
            show: true,
            spacing_px: 32,
            scale: 8.0,
            relative_to_land: false,
        }
    }
}

/// Slider row for arrow options.
pub fn arrow_controls(ui: &mut Ui, opts: &mut ArrowOptions) {
    ui.horizontal(|ui| {
        ui.checkbox(&mut opts.show, "arrows");
        ui.add(egui::Slider::new(&mut opts.spacing_px, 4..=96).text("spacing px"));
        ui.add(
            egui::Slider::new(&mut opts.scale, 0.5..=200.0)
                .logarithmic(true)
                .text("scale"),
        );
        ui.checkbox(&mut opts.relative_to_land, "relative to land flow");
    });
}

/// Draws subsampled flow arrows coloured by magnitude (bins from low to high).
pub fn flow_arrows(plot_ui: &mut PlotUi<'_>, flow: &FlowField, opts: &ArrowOptions, land_px: f64) {
    if !opts.show {
        return;
    }
    let step = opts.spacing_px.max(2);
    let base = if opts.relative_to_land {
        land_px as f32
    } else {
        0.0
    };
    let mut pts = Vec::new();
    for y in (step / 2..flow.u.height).step_by(step) {
        for x in (step / 2..flow.u.width).step_by(step) {
            let (Some(u), Some(v), Some(c)) = (
                flow.u.get(x, y),
                flow.v.get(x, y),
                flow.confidence.get(x, y),
            ) else {
                continue;
            };
            if c > 0.0 && u.is_finite() && v.is_finite() {
                pts.push((x, y, u - base, v));
            }
        }
    }
    let mags: Vec<f32> = pts.iter().map(|p| p.2.hypot(p.3)).collect();
    let (lo, hi) = crate::app::render::finite_range(&mags).unwrap_or((0.0, 1.0));
    let span = if hi > lo { hi - lo } else { 1.0 };
    let mut bins: Vec<ArrowBin> = vec![(Vec::new(), Vec::new()); ARROW_BINS];
    for ((x, y, u, v), m) in pts.into_iter().zip(mags) {
        let b = (((m - lo) / span) * (ARROW_BINS - 1) as f32).round() as usize;
        let (o, t) = &mut bins[b.min(ARROW_BINS - 1)];
        let (ox, oy) = (x as f64 + 0.5, y as f64 + 0.5);
        o.push([ox, oy]);
        t.push([
            ox + f64::from(u * opts.scale),
            oy + f64::from(v * opts.scale),
        ]);
    }
    for (i, (o, t)) in bins.into_iter().enumerate() {
        if o.is_empty() {
            continue;
        }
        plot_ui.add(
            Arrows::new(
                format!("flow {i}"),
                PlotPoints::from(o),
                PlotPoints::from(t),
            )
            .color(heat_colour(
                0.15 + 0.85 * i as f32 / (ARROW_BINS - 1) as f32,
            ))
            .tip_length(4.0)
            .allow_hover(false),
        );
    }
}

/// State of the frame view.
#[derive(Clone, Debug, Default)]
pub struct FrameViewState {
    /// Arrow overlay options.
    pub arrows: ArrowOptions,
    /// Read-out of the last hovered pixel.
    pub readout: Option<String>,
}

impl FrameViewState {
    /// The frame viewer.
    pub fn ui(&mut self, ui: &mut Ui, data: &StageData<'_>, textures: &mut Textures) {
        let Some(tex) = data.frame_texture(ui, textures, data.frame) else {
            return;
        };
        arrow_controls(ui, &mut self.arrows);
        let flow = data.flow_for_frame(data.frame).map(|(_, f)| f);
        let dim_flow = data.status(Stage::Flow).dim();
        let land = data.land_flow_px();
        let resp = image_plot("frame_view", data.height).show(ui, |plot_ui| {
            plot_ui.image(image_item("frame", &tex, false));
            if let Some(f) = flow.filter(|_| !dim_flow || self.arrows.show) {
                flow_arrows(plot_ui, f, &self.arrows, land);
            }
        });
        if let Some((x, y)) = hovered_pixel(&resp, tex.size()) {
            self.readout = Some(data.readout(x, y));
        }
        ui.label(
            self.readout
                .as_deref()
                .unwrap_or("hover the image for a read-out"),
        );
    }
}
