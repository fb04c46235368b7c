//! Overview: every stage of the current group at a glance, plus the clip's waveform.

use egui::{Color32, Ui};
use egui_plot::{Line, Plot, PlotImage, PlotPoint, PlotPoints};

use super::frame_ui::{ArrowOptions, StageData, flow_arrows};
use super::orientation_ui::tan_segments;
use super::waveform_ui::{RECOVERED_COLOUR, REFERENCE_COLOUR, decimate};
use super::{View, image_item, wall_lines};
use crate::app::recon::Clip;
use crate::app::render::region_colour;
use crate::app::textures::Textures;
use crate::app::worker::ViewImage;
use crate::pipeline::Stage;

/// Columns of the waveform thumbnail.
const THUMB_COLUMNS: usize = 600;

fn thumb<'a>(id: &str, h: f32, w: f32) -> Plot<'a> {
    Plot::new(id)
        .height(h)
        .width(w)
        .show_axes(false)
        .show_grid(false)
        .allow_drag(false)
        .allow_zoom(false)
        .allow_scroll(false)
        .allow_boxed_zoom(false)
        .show_x(false)
        .show_y(false)
}

/// A [`thumb`] of an image: square pixels, rows downward.
fn image_thumb<'a>(id: &str, h: f32, w: f32) -> Plot<'a> {
    thumb(id, h, w).data_aspect(1.0).invert_y(true)
}

/// The cell titles of the overview: each a link to its view, most with the status of the
/// view's stage beside it; remembers which was clicked.
struct Titles<'a, 'd> {
    data: &'a StageData<'d>,
    /// The view whose title was clicked.
    open: Option<View>,
}

impl Titles<'_, '_> {
    /// The title `text` of `view`'s cell, with the status of [`View::stage`].
    fn show(&mut self, ui: &mut Ui, text: &str, view: View) {
        self.draw(ui, text, view, view.stage());
    }

    /// The title `text` of `view`'s cell, without a status.
    fn plain(&mut self, ui: &mut Ui, text: &str, view: View) {
        self.draw(ui, text, view, None);
    }

    fn draw(&mut self, ui: &mut Ui, text: &str, view: View, stage: Option<Stage>) {
        ui.horizontal(|ui| {
            if ui.link(text).clicked() {
                self.open = Some(view);
            }
            if let Some(s) = stage {
                let st = self.data.status(s);
                ui.colored_label(st.colour(), st.word());
            }
        });
    }
}

/// The overview grid; returns a view to switch to when a title is clicked.
pub fn overview_ui(
    ui: &mut Ui,
    data: &StageData<'_>,
    textures: &mut Textures,
    clip: Option<&Clip>,
) -> Option<View> {
    let mut titles = Titles { data, open: None };
    let cell_h = (data.height / 2.0 - 40.0).max(80.0);
    let cell_w = (ui.available_width() / 3.0 - 12.0).max(80.0);
    let dual = data.cache.stripes().is_some();
    let frame_tex = data
        .frames
        .and_then(|f| textures.frame(ui.ctx(), data.group, data.frame, f).cloned());
    let flow_tex = data.cache.flows().cloned().and_then(|f| {
        let mid = f.len() / 2;
        textures
            .flow(
                ui.ctx(),
                &f,
                data.cache.output_id(Stage::Flow),
                mid,
                data.land_flow_px() as f32,
            )
            .map(|t| t.handle.clone())
    });
    let third = if dual {
        textures
            .get(ViewImage::Segmentation)
            .map(|t| t.handle.clone())
    } else {
        textures.get(ViewImage::Depth).map(|t| t.handle.clone())
    };
    let acc = textures
        .get(ViewImage::Accumulator)
        .map(|t| t.handle.clone());
    egui::Grid::new("overview_grid")
        .num_columns(3)
        .spacing([12.0, 8.0])
        .show(ui, |ui| {
            ui.vertical(|ui| {
                titles.plain(
                    ui,
                    &format!("frame {} (group {})", data.frame, data.group),
                    View::Frame,
                );
                image_thumb("ov_frame", cell_h, cell_w).show(ui, |p| {
                    if let Some(t) = &frame_tex {
                        p.image(image_item("frame", t, false));
                    }
                    if let Some((_, f)) = data.flow_for_frame(data.frame) {
                        let opts = ArrowOptions {
                            spacing_px: 48,
                            ..ArrowOptions::default()
                        };
                        flow_arrows(p, f, &opts, data.land_flow_px());
                    }
                });
            });
            ui.vertical(|ui| {
                titles.show(ui, "flow", View::Flow);
                let dim = data.status(Stage::Flow).dim();
                image_thumb("ov_flow", cell_h, cell_w).show(ui, |p| {
                    if let Some(t) = &flow_tex {
                        p.image(image_item("flow", t, dim));
                    }
                });
            });
            ui.vertical(|ui| {
                let (name, stage, view) = if dual {
                    ("stripes", Stage::Stripes, View::Stripes)
                } else {
                    ("depth", Stage::Depth, View::Depth)
                };
                titles.show(ui, name, view);
                let dim = data.status(stage).dim();
                image_thumb("ov_third", cell_h, cell_w).show(ui, |p| {
                    if let Some(t) = &third {
                        p.image(image_item(name, t, dim));
                    }
                    if let (false, Some(d)) = (dual, data.cache.depth()) {
                        wall_lines(p, &d.walls, Color32::WHITE);
                    }
                });
            });
            ui.end_row();
            ui.vertical(|ui| {
                titles.show(ui, "Hough accumulator", View::Hough);
                match (&acc, data.cache.stripes()) {
                    (Some(t), Some(_)) => {
                        let [w, h] = t.size();
                        let dim = data.status(Stage::Stripes).dim();
                        thumb("ov_hough", cell_h, cell_w)
                            .invert_y(true)
                            .show(ui, |p| {
                                p.image(
                                    PlotImage::new(
                                        "acc",
                                        t.id(),
                                        PlotPoint::new(w as f64 / 2.0, h as f64 / 2.0),
                                        [w as f32, h as f32],
                                    )
                                    .tint(super::tint(dim)),
                                );
                            });
                    }
                    _ => {
                        ui.add_sized(
                            [cell_w, cell_h],
                            egui::Label::new(
                                egui::RichText::new("depth path: no Hough accumulator").weak(),
                            ),
                        );
                    }
                }
            });
            ui.vertical(|ui| {
                titles.show(ui, "orientation (tan θ along x)", View::Orientation);
                thumb("ov_orientation", cell_h, cell_w)
                    .show_axes(true)
                    .show(ui, |p| {
                        if let Some(o) = data.cache.orientation() {
                            for (i, w) in o.orientation.walls.iter().enumerate() {
                                for (k, seg) in tan_segments(w).into_iter().enumerate() {
                                    p.line(
                                        Line::new(format!("{:?}", w.side), PlotPoints::from(seg))
                                            .id(format!("ov{i}/{k}"))
                                            .color(region_colour(i)),
                                    );
                                }
                            }
                        }
                    });
            });
            ui.vertical(|ui| {
                titles.plain(ui, "clip waveform", View::Waveform);
                thumb("ov_wave", cell_h, cell_w)
                    .show_axes([true, false])
                    .show(ui, |p| {
                        if let Some(c) = clip {
                            let rate = f64::from(c.rate_hz());
                            let dur = c.recon.audio.duration_secs();
                            if let Some(r) = &c.reference {
                                p.line(
                                    Line::new(
                                        "reference",
                                        PlotPoints::from(decimate(
                                            &r.samples,
                                            rate,
                                            0.0,
                                            dur,
                                            THUMB_COLUMNS,
                                        )),
                                    )
                                    .color(REFERENCE_COLOUR.gamma_multiply(0.6)),
                                );
                            }
                            p.line(
                                Line::new(
                                    "recovered",
                                    PlotPoints::from(decimate(
                                        &c.recovered.samples,
                                        rate,
                                        0.0,
                                        dur,
                                        THUMB_COLUMNS,
                                    )),
                                )
                                .color(RECOVERED_COLOUR),
                            );
                        }
                    });
                if let Some(s) = clip.and_then(|c| c.recon.scores) {
                    ui.label(format!("r {:.3}  ·  SNR {:.1} dB", s.r, s.snr_db));
                }
            });
            ui.end_row();
        });
    titles.open
}
