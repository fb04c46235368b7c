//! The still window: the still's settings, a stretch of the image with every groove outlined and
//! numbered and the decoded groove's fitted borders over it (click a groove to decode it), the
//! decode's progress with Cancel, and the groove's sound: its waveform, Listen, Stop and Export.

use egui::{Color32, Pos2, Rect, Sense, Stroke, Ui, pos2};
use egui_plot::{Line, Plot, PlotPoints, VLine};

use super::waveform_ui::{RECOVERED_COLOUR, decimate};
use super::{AXIS_WIDTH_PT, STILL_WINDOW, cancel_button};
use crate::app::background::Polled;
use crate::app::render::region_colour;
use crate::app::still::{
    SetupSource, StillDoc, StillPicture, StillState, groove_at, pixel_of, stretch_picture,
};
use crate::io::Cut;
use crate::pipeline::still::{Axis, lines_and_cross};

/// Colour of the decoded groove's fitted borders.
pub const BORDER_COLOUR: Color32 = Color32::from_rgb(60, 230, 255);
/// Colour of the decoded groove's outline.
pub const CHOSEN_COLOUR: Color32 = Color32::from_rgb(255, 70, 210);
/// Height of the image stretch, points.
const IMAGE_HEIGHT_PT: f32 = 330.0;
/// Height of the waveform, points.
const WAVE_HEIGHT_PT: f32 = 150.0;
/// Largest picture made of a stretch (samples along the grooves, across them).
const PICTURE_MAX: (usize, usize) = (2048, 1024);
/// Outline points drawn per groove across the stretch.
const OUTLINE_POINTS: usize = 240;

/// What the operator asked for in the window.
#[derive(Clone, Debug, PartialEq)]
pub enum StillAction {
    /// Open another still.
    Open,
    /// Decode groove N (from 1; None: the decoder's pick), finding the grooves again when the
    /// settings changed.
    Decode(Option<usize>),
    /// Cancel the decode.
    Cancel,
    /// Play the decoded groove.
    Listen,
    /// Stop playback.
    Stop,
    /// Export the decoded groove's sound.
    Export,
}

/// Draws the window (when open) and returns what was asked for; `position` is the playback
/// position (s) while the player holds the still's sound.
pub fn still_window(
    ctx: &egui::Context,
    place: super::ToolPlace,
    state: &mut StillState,
    position: Option<f64>,
    playing: bool,
) -> Vec<StillAction> {
    let mut actions = Vec::new();
    state.open = STILL_WINDOW.show(ctx, state.open, place, |ui| {
        body(ui, state, position, playing, &mut actions);
    });
    actions
}

fn body(
    ui: &mut Ui,
    state: &mut StillState,
    position: Option<f64>,
    playing: bool,
    actions: &mut Vec<StillAction>,
) {
    let busy = state.job.is_some();
    ui.horizontal_wrapped(|ui| {
        if ui
            .add_enabled(!busy, egui::Button::new("Open still…"))
            .clicked()
        {
            actions.push(StillAction::Open);
        }
        match &state.doc {
            Some(doc) => {
                ui.label(format!(
                    "{} ({}×{} px)",
                    doc.path.display(),
                    doc.image.width,
                    doc.image.height
                ));
                match &doc.source {
                    SetupSource::Sidecar(p) => {
                        ui.weak(format!("settings from {}", p.display()));
                    }
                    SetupSource::Entered => {
                        ui.weak("settings as entered");
                    }
                    SetupSource::Guessed => {
                        ui.colored_label(
                            Color32::from_rgb(230, 180, 60),
                            "settings guessed: check the pixel size, speed and radius",
                        );
                    }
                }
            }
            None if busy => {
                ui.label("opening…");
            }
            None => {
                ui.label("no still open: File ▸ Open still image…, or drop a PNG or TIFF here");
            }
        }
    });
    if let Some(doc) = state.doc.as_mut() {
        settings_row(ui, doc, busy, actions);
    }
    progress_row(ui, state, actions);
    let Some(doc) = &state.doc else {
        return;
    };
    if let Some(problem) = &doc.problem {
        ui.colored_label(crate::app::panels::ERROR_COLOUR, problem);
    }
    groove_row(ui, doc, busy, actions);
    ui.separator();
    image_view(ui, state, position, busy, actions);
    if let Some(doc) = &state.doc {
        sound_view(ui, doc, position, playing, position.is_some(), actions);
    }
}

/// A label and the number field it names (the field is labelled by it for screen readers).
fn labelled_value(ui: &mut Ui, label: &str, value: egui::DragValue<'_>) {
    let l = ui.label(label);
    ui.add(value).labelled_by(l.id);
}

fn settings_row(ui: &mut Ui, doc: &mut StillDoc, busy: bool, actions: &mut Vec<StillAction>) {
    ui.horizontal_wrapped(|ui| {
        let s = &mut doc.setup;
        let l = ui.label("grooves run");
        egui::ComboBox::from_id_salt("still_axis")
            .selected_text(match s.axis {
                Axis::Vertical => "down (vertical)",
                Axis::Horizontal => "across (horizontal)",
            })
            .show_ui(ui, |ui| {
                ui.selectable_value(&mut s.axis, Axis::Vertical, "down (vertical)");
                ui.selectable_value(&mut s.axis, Axis::Horizontal, "across (horizontal)");
            })
            .response
            .labelled_by(l.id);
        labelled_value(
            ui,
            "µm/px",
            egui::DragValue::new(&mut s.um_per_px)
                .range(1e-3..=1e3)
                .speed(0.01)
                .max_decimals(4),
        );
        for (label, value) in [("rpm", &mut s.rpm), ("radius mm", &mut s.radius_mm)] {
            labelled_value(
                ui,
                label,
                egui::DragValue::new(value).range(1.0..=200.0).speed(0.1),
            );
        }
        let l = ui.label("cut");
        egui::ComboBox::from_id_salt("still_cut")
            .selected_text(if s.cut == Cut::Stereo {
                "stereo (45/45)"
            } else {
                "lateral"
            })
            .show_ui(ui, |ui| {
                ui.selectable_value(&mut s.cut, Cut::Lateral, "lateral");
                ui.selectable_value(&mut s.cut, Cut::Stereo, "stereo (45/45)");
            })
            .response
            .labelled_by(l.id);
        ui.checkbox(&mut s.reverse, "time runs backwards");
        let changed = doc.found_with.as_ref() != Some(&doc.setup);
        let label = if changed {
            "Find grooves with these settings"
        } else {
            "Decode again"
        };
        let current = doc
            .run
            .as_ref()
            .map(|r| r.analysis.grooves.grooves[r.analysis.chosen].number);
        if ui.add_enabled(!busy, egui::Button::new(label)).clicked() {
            actions.push(StillAction::Decode(if changed { None } else { current }));
        }
    });
}

fn progress_row(ui: &mut Ui, state: &StillState, actions: &mut Vec<StillAction>) {
    let Some(job) = &state.job else {
        if let Some(run) = state.doc.as_ref().and_then(|d| d.run.as_ref()) {
            let a = &run.analysis;
            let g = &a.grooves.grooves[a.chosen];
            let gaps: usize = a.signal.gaps.iter().map(|g| g.lines).sum();
            ui.label(format!(
                "groove {} of {}: {:.2} s of sound at {} Hz, {}, {} line{} bridged, \
                 decoded in {:.2} s",
                g.number,
                a.grooves.grooves.len(),
                run.audio.duration_secs(),
                run.audio.sample_rate_hz,
                run.audio.channels_label(),
                gaps,
                if gaps == 1 { "" } else { "s" },
                run.timings.total_secs
            ));
        }
        return;
    };
    ui.horizontal(|ui| {
        let p = job.progress;
        ui.add(
            egui::ProgressBar::new(p.fraction as f32)
                .desired_width(360.0)
                .text(format!("{} ({:.0} %)", p.what, 100.0 * p.fraction)),
        );
        if cancel_button(ui, job.cancelling(), "Cancel") {
            actions.push(StillAction::Cancel);
        }
        ui.weak(format!("{:.1} s", job.started.elapsed().as_secs_f64()));
    });
}

fn groove_row(ui: &mut Ui, doc: &StillDoc, busy: bool, actions: &mut Vec<StillAction>) {
    let Some(found) = &doc.found else {
        return;
    };
    let chosen = doc.run.as_ref().map(|r| r.analysis.chosen);
    ui.horizontal_wrapped(|ui| {
        ui.label(format!(
            "{} grooves found, numbered from the image's {} (click one, here or on the image):",
            found.grooves.grooves.len(),
            match found.grooves.axis {
                Axis::Vertical => "left",
                Axis::Horizontal => "top",
            }
        ));
        for (i, g) in found.grooves.grooves.iter().enumerate() {
            let text = egui::RichText::new(format!("groove {}", g.number))
                .color(region_colour(i))
                .strong();
            let r = ui
                .add_enabled(
                    !busy,
                    egui::Button::selectable(chosen == Some(i), text),
                )
                .on_hover_text(format!(
                    "groove {}: found in {:.0} % of the image, {:.1} px wide at the land, at {:.1} px",
                    g.number,
                    100.0 * g.coverage,
                    g.width_px,
                    g.position_px
                ));
            if r.clicked() && chosen != Some(i) {
                actions.push(StillAction::Decode(Some(g.number)));
            }
        }
    });
}

/// Screen position of image point (`line`, `cross`) in `rect` showing lines
/// `[first, first + count)` and every cross sample (pixel-centre coordinates).
fn to_screen(
    rect: Rect,
    axis: Axis,
    first: f64,
    count: f64,
    cross_n: f64,
    line: f64,
    cross: f64,
) -> Pos2 {
    let along = ((line + 0.5 - first) / count) as f32;
    let across = ((cross + 0.5) / cross_n) as f32;
    match axis {
        Axis::Horizontal => pos2(
            rect.left() + along * rect.width(),
            rect.top() + across * rect.height(),
        ),
        Axis::Vertical => pos2(
            rect.left() + across * rect.width(),
            rect.top() + along * rect.height(),
        ),
    }
}

fn image_view(
    ui: &mut Ui,
    state: &mut StillState,
    position: Option<f64>,
    busy: bool,
    actions: &mut Vec<StillAction>,
) {
    let Some(doc) = &state.doc else {
        return;
    };
    let axis = doc
        .found
        .as_ref()
        .map_or(doc.setup.axis, |f| f.grooves.axis);
    let (lines, cross_n) = lines_and_cross(doc.image.width, doc.image.height, axis);
    if lines == 0 || cross_n == 0 {
        return;
    }
    // The stretch: all of a short still, else a window the slider moves.
    let default_span = (lines as f64).min(4000.0);
    let mut span = if state.lines_shown > 0.0 {
        state.lines_shown
    } else {
        default_span
    };
    let mut first = state.first_line;
    ui.horizontal(|ui| {
        ui.label("lines shown");
        if ui
            .button("−")
            .on_hover_text("show more of the groove")
            .clicked()
        {
            span = (span * 2.0).min(lines as f64);
        }
        if ui
            .button("+")
            .on_hover_text("show less of the groove, larger")
            .clicked()
        {
            span = (span / 2.0).max(32.0_f64.min(lines as f64));
        }
        if ui.button("whole image").clicked() {
            span = lines as f64;
            first = 0.0;
        }
        let max_first = (lines as f64 - span).max(0.0);
        first = first.clamp(0.0, max_first);
        let l = ui.label("from line");
        ui.add_enabled(
            max_first > 0.0,
            egui::Slider::new(&mut first, 0.0..=max_first.max(1.0)).integer(),
        )
        .labelled_by(l.id);
        ui.weak(format!("{span:.0} of {lines} lines"));
    });
    state.lines_shown = span;
    state.first_line = first;
    let (f0, n) = (first.floor() as usize, (span.round() as usize).max(1));
    let key = (
        f0,
        n,
        std::sync::Arc::as_ptr(&doc.image) as usize,
        axis as usize,
    );
    if state.picture.as_ref().is_none_or(|p| p.key != key) {
        let (w, h, grey) = stretch_picture(&doc.image, axis, f0, n, PICTURE_MAX.0, PICTURE_MAX.1);
        let img = egui::ColorImage::from_gray([w, h], &grey);
        let handle = ui
            .ctx()
            .load_texture("still_stretch", img, egui::TextureOptions::LINEAR);
        state.picture = Some(StillPicture { key, handle });
    }
    let Some(doc) = &state.doc else {
        return;
    };
    let width = ui.available_width();
    let (rect, resp) = ui.allocate_exact_size(egui::vec2(width, IMAGE_HEIGHT_PT), Sense::click());
    let painter = ui.painter_at(rect);
    if let Some(p) = &state.picture {
        painter.image(
            p.handle.id(),
            rect,
            Rect::from_min_max(pos2(0.0, 0.0), pos2(1.0, 1.0)),
            Color32::WHITE,
        );
    }
    let (first, count, cn) = (f0 as f64, n as f64, cross_n as f64);
    let at = |line: f64, cross: f64| to_screen(rect, axis, first, count, cn, line, cross);
    let chosen = doc.run.as_ref().map(|r| r.analysis.chosen);
    if let Some(found) = &doc.found {
        let map = &found.grooves;
        for (i, g) in map.grooves.iter().enumerate() {
            let colour = if chosen == Some(i) {
                CHOSEN_COLOUR
            } else {
                region_colour(i)
            };
            let width = if chosen == Some(i) { 2.0 } else { 1.2 };
            let path = g.path(map);
            for edge in [0, 3] {
                let pts: Vec<Pos2> = (0..=OUTLINE_POINTS)
                    .map(|k| first + count * k as f64 / OUTLINE_POINTS as f64 - 0.5)
                    .filter_map(|line| {
                        let b = path.at(line);
                        b[edge].is_finite().then(|| at(line, b[edge]))
                    })
                    .collect();
                painter.add(egui::Shape::line(pts, Stroke::new(width, colour)));
            }
            let b = path.at(first + 0.02 * count);
            if b[0].is_finite() && b[3].is_finite() {
                let p = at(first + 0.02 * count, 0.5 * (b[0] + b[3]));
                painter.text(
                    p,
                    egui::Align2::CENTER_CENTER,
                    format!("{}", g.number),
                    egui::FontId::proportional(15.0),
                    colour,
                );
            }
        }
    }
    if let Some(run) = &doc.run {
        let borders = &run.analysis.borders;
        let stride = ((count / f64::from(rect.width().max(rect.height()))) as usize).max(1);
        for b in 0..4 {
            let pos = borders.positions(b);
            let mut seg: Vec<Pos2> = Vec::new();
            for line in (f0..(f0 + n).min(pos.len())).step_by(stride) {
                let v = pos[line];
                if v.is_finite() {
                    seg.push(at(line as f64, v));
                } else if seg.len() > 1 {
                    painter.add(egui::Shape::line(
                        std::mem::take(&mut seg),
                        Stroke::new(1.0, BORDER_COLOUR),
                    ));
                } else {
                    seg.clear();
                }
            }
            if seg.len() > 1 {
                painter.add(egui::Shape::line(seg, Stroke::new(1.0, BORDER_COLOUR)));
            }
        }
    }
    if let Some(line) = position.and_then(|t| doc.line_at(t))
        && (first..first + count).contains(&line)
    {
        let (a, b) = (at(line, -0.5), at(line, cn - 0.5));
        painter.line_segment([a, b], Stroke::new(1.5, Color32::WHITE));
    }
    if resp.clicked()
        && !busy
        && let (Some(p), Some(found)) = (resp.interact_pointer_pos(), &doc.found)
    {
        let (u, v) = (
            (p.x - rect.left()) / rect.width(),
            (p.y - rect.top()) / rect.height(),
        );
        let (along, across) = match axis {
            Axis::Horizontal => (u, v),
            Axis::Vertical => (v, u),
        };
        let line = first + f64::from(along) * count - 0.5;
        let cross = f64::from(across) * cn - 0.5;
        if let Some(i) = groove_at(&found.grooves, line, cross)
            && chosen != Some(i)
        {
            actions.push(StillAction::Decode(Some(found.grooves.grooves[i].number)));
        }
    }
    let (px, py) = pixel_of(axis, first, 0.0);
    ui.weak(format!(
        "from pixel ({px:.0}, {py:.0}), stretched to fit: each groove's outer borders in its \
         colour, the decoded groove's in magenta with its fitted borders in blue; white: what \
         plays now"
    ));
}

fn sound_view(
    ui: &mut Ui,
    doc: &StillDoc,
    position: Option<f64>,
    playing: bool,
    heard: bool,
    actions: &mut Vec<StillAction>,
) {
    let Some(run) = &doc.run else {
        return;
    };
    ui.separator();
    ui.horizontal(|ui| {
        if playing {
            if ui.button("Stop").clicked() {
                actions.push(StillAction::Stop);
            }
        } else if ui.button("Listen").clicked() {
            actions.push(StillAction::Listen);
        }
        if ui.button("Export WAV…").clicked() {
            actions.push(StillAction::Export);
        }
        if run.audio.channels.len() > 1 {
            ui.weak(format!(
                "left channel: {}",
                crate::still::cli::left_wall_text(doc.setup.axis, doc.setup.reverse)
            ));
        }
        if heard && !playing {
            ui.weak("(the player holds this groove; reconstruct to hear the clip again)");
        }
    });
    let audio = &run.audio;
    let rate = f64::from(audio.sample_rate_hz);
    let mono = audio.mono();
    let duration = audio.duration_secs();
    let points = decimate(&mono, rate, 0.0, duration, 1200);
    Plot::new("still_wave")
        .height(WAVE_HEIGHT_PT)
        .y_axis_min_width(AXIS_WIDTH_PT)
        .x_axis_label("s")
        .allow_scroll(false)
        .show(ui, |plot| {
            plot.line(Line::new("groove", PlotPoints::from(points)).color(RECOVERED_COLOUR));
            if let Some(t) = position {
                plot.vline(VLine::new("playing", t).color(Color32::WHITE));
            }
        });
}
