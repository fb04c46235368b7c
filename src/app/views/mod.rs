//! The workbench's views: each draws one stage of the current group from cached results, never computing it.

pub mod compare_ui;
pub mod depth_ui;
pub mod edges_ui;
pub mod flow_ui;
pub mod frame_ui;
pub mod guidance;
pub mod health_ui;
pub mod hough_ui;
pub mod meta_ui;
pub mod nav_ui;
pub mod orientation_ui;
pub mod overview_ui;
pub mod params_ui;
pub mod states;
pub mod still_ui;
pub mod stripes_ui;
pub mod transport_ui;
pub mod waveform_ui;

use egui::{Color32, TextureHandle, Ui};
use egui_plot::{Line, Plot, PlotImage, PlotPoint, PlotPoints, PlotResponse, PlotUi};

use crate::pipeline::Stage;
use crate::pipeline::walls::WallLine;

/// The views the central area can show.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum View {
    /// All stages at a glance.
    Overview,
    /// The frames, with pixel read-out and flow arrows.
    Frame,
    /// Flow field: colours or arrows.
    Flow,
    /// Hough accumulator with peaks and windows.
    Hough,
    /// Segmented stripes and centroid lines.
    Stripes,
    /// Depth map, colour bar and cross-section.
    Depth,
    /// Wall orientation and robust-fit outliers.
    Orientation,
    /// The edge decoder's borders on their frame, and the walls' displacement.
    Edges,
    /// The whole clip: waveform, reference, envelopes, spectrum, playback.
    Waveform,
    /// The scan's metadata form.
    Metadata,
}

impl View {
    /// Every view, in tab order.
    pub const ALL: [View; 10] = [
        View::Overview,
        View::Frame,
        View::Flow,
        View::Hough,
        View::Stripes,
        View::Depth,
        View::Orientation,
        View::Edges,
        View::Waveform,
        View::Metadata,
    ];

    /// Tab label (also the name used by `GROOVESCOPE_VIEW`).
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            View::Overview => "overview",
            View::Frame => "frame",
            View::Flow => "flow",
            View::Hough => "hough",
            View::Stripes => "stripes",
            View::Depth => "depth",
            View::Orientation => "orientation",
            View::Edges => "edges",
            View::Waveform => "waveform",
            View::Metadata => "metadata",
        }
    }

    /// The view named `name` (case-insensitive).
    #[must_use]
    pub fn from_name(name: &str) -> Option<View> {
        View::ALL
            .into_iter()
            .find(|v| v.name().eq_ignore_ascii_case(name.trim()))
    }

    /// The stage whose result the view shows (None for views of the whole scan).
    #[must_use]
    pub fn stage(self) -> Option<Stage> {
        match self {
            View::Frame => Some(Stage::Derivatives),
            View::Flow => Some(Stage::Flow),
            View::Hough | View::Stripes => Some(Stage::Stripes),
            View::Depth => Some(Stage::Depth),
            View::Orientation => Some(Stage::Orientation),
            View::Edges => Some(Stage::Edges),
            View::Overview | View::Waveform | View::Metadata => None,
        }
    }
}

/// State of one stage of the current group, as the UI shows it.
#[derive(Clone, Debug, PartialEq)]
pub enum StageStatus {
    /// The result matches the current params and group.
    Fresh,
    /// The result (if any) is out of date; it waits for the worker.
    Stale,
    /// The worker is running it now.
    Running,
    /// It failed with this message.
    Failed(String),
    /// The current path does not use it.
    Unused,
    /// No scan is open: there is nothing to run it on.
    NoScan,
}

impl StageStatus {
    /// One word for labels.
    #[must_use]
    pub fn word(&self) -> &'static str {
        match self {
            StageStatus::Fresh => "fresh",
            StageStatus::Stale => "stale",
            StageStatus::Running => "running",
            StageStatus::Failed(_) => "failed",
            StageStatus::Unused => "not used",
            StageStatus::NoScan => "no scan",
        }
    }

    /// Colour for the status word.
    #[must_use]
    pub fn colour(&self) -> Color32 {
        match self {
            StageStatus::Fresh => Color32::from_rgb(90, 200, 110),
            StageStatus::Stale => Color32::from_rgb(200, 170, 60),
            StageStatus::Running => Color32::from_rgb(90, 160, 240),
            StageStatus::Failed(_) => Color32::from_rgb(235, 80, 70),
            StageStatus::Unused | StageStatus::NoScan => Color32::GRAY,
        }
    }

    /// True when views of this stage should be dimmed.
    #[must_use]
    pub fn dim(&self) -> bool {
        !matches!(self, StageStatus::Fresh | StageStatus::Unused)
    }
}

/// Room for the value labels of plot y axes (points): enough for "4030.5" or "-120".
pub const AXIS_WIDTH_PT: f32 = 48.0;

/// A sound plot (time in seconds against level) `height_pt` tall, with a legend and no boxed
/// zoom, as the waveform and A/B views draw it.
#[must_use]
pub fn level_plot(id: &str, height_pt: f32) -> Plot<'static> {
    Plot::new(id)
        .y_axis_min_width(AXIS_WIDTH_PT)
        .height(height_pt)
        .legend(egui_plot::Legend::default())
        .allow_boxed_zoom(false)
        .x_axis_label("time (s)")
        .y_axis_label("level")
}

/// Tint of stale images.
pub const STALE_TINT: Color32 = Color32::from_gray(110);

/// Tint for an image: white when fresh, grey when stale.
#[must_use]
pub fn tint(dim: bool) -> Color32 {
    if dim { STALE_TINT } else { Color32::WHITE }
}

/// A plot showing an image in pixel coordinates (row 0 at the top), with pan and zoom.
#[must_use]
pub fn image_plot<'a>(id: &str, height: f32) -> Plot<'a> {
    Plot::new(id)
        .data_aspect(1.0)
        .invert_y(true)
        .height(height)
        .allow_boxed_zoom(false)
        .show_grid(false)
        .x_axis_label("x (px)")
        .y_axis_label("y (px)")
}

/// The image item covering pixels `[0, w] × [0, h]`.
#[must_use]
pub fn image_item(name: &str, tex: &TextureHandle, dim: bool) -> PlotImage {
    let [w, h] = tex.size();
    PlotImage::new(
        name.to_string(),
        tex.id(),
        PlotPoint::new(w as f64 / 2.0, h as f64 / 2.0),
        [w as f32, h as f32],
    )
    .tint(tint(dim))
}

/// A plot of one curve a wall, each split into runs where it has a value, coloured by wall;
/// `axes` are the x and y labels.
pub fn wall_curves(
    ui: &mut Ui,
    id: &str,
    height: f32,
    axes: [&str; 2],
    curves: Vec<(String, Vec<Vec<[f64; 2]>>)>,
) {
    Plot::new(id)
        .y_axis_min_width(AXIS_WIDTH_PT)
        .height(height)
        .legend(egui_plot::Legend::default())
        .x_axis_label(axes[0])
        .y_axis_label(axes[1])
        .show(ui, |plot_ui| {
            for (i, (name, runs)) in curves.into_iter().enumerate() {
                for (k, run) in runs.into_iter().enumerate() {
                    plot_ui.line(
                        Line::new(name.clone(), PlotPoints::from(run))
                            .id(format!("{name}/{k}"))
                            .color(crate::app::render::region_colour(i)),
                    );
                }
            }
        });
}

/// Splits `(x, y)` points into plot lines, breaking where `y` is not finite.
#[must_use]
pub fn finite_runs(points: impl IntoIterator<Item = [f64; 2]>) -> Vec<Vec<[f64; 2]>> {
    let mut out = Vec::new();
    let mut cur = Vec::new();
    for p in points {
        if p[1].is_finite() {
            cur.push(p);
        } else if !cur.is_empty() {
            out.push(std::mem::take(&mut cur));
        }
    }
    if !cur.is_empty() {
        out.push(cur);
    }
    out
}

/// Splits a per-column row list into plot lines (pixel centres), breaking at NaN.
#[must_use]
pub fn row_segments(rows: &[f32]) -> Vec<Vec<[f64; 2]>> {
    finite_runs(
        rows.iter()
            .enumerate()
            .map(|(x, &r)| [x as f64 + 0.5, f64::from(r) + 0.5]),
    )
}

/// Draws wall or centroid lines (and their filled voids) over an image plot.
pub fn wall_lines(plot_ui: &mut PlotUi<'_>, lines: &[WallLine], colour: Color32) {
    for (i, line) in lines.iter().enumerate() {
        let name = format!("{:?} wall {i}", line.side);
        for (k, seg) in row_segments(&line.rows).into_iter().enumerate() {
            plot_ui.line(
                Line::new(name.clone(), PlotPoints::from(seg))
                    .id(format!("{name}/{k}"))
                    .color(colour)
                    .width(1.5),
            );
        }
        let voids: Vec<[f64; 2]> = line
            .filled
            .iter()
            .enumerate()
            .filter(|(_, f)| **f)
            .filter_map(|(x, _)| {
                let r = *line.rows.get(x)?;
                r.is_finite()
                    .then_some([x as f64 + 0.5, f64::from(r) + 0.5])
            })
            .collect();
        if !voids.is_empty() {
            plot_ui.add(
                egui_plot::Points::new(format!("{name} filled"), PlotPoints::from(voids))
                    .color(Color32::from_rgb(255, 0, 200))
                    .radius(1.5),
            );
        }
    }
}

/// Pixel under the pointer of an image plot, when inside `[0, w) × [0, h)`.
#[must_use]
pub fn hovered_pixel<R>(resp: &PlotResponse<R>, size: [usize; 2]) -> Option<(usize, usize)> {
    if !resp.response.hovered() {
        return None;
    }
    let p = resp.response.hover_pos()?;
    let v = resp.transform.value_from_position(p);
    (v.x >= 0.0 && v.y >= 0.0 && v.x < size[0] as f64 && v.y < size[1] as f64)
        .then_some((v.x as usize, v.y as usize))
}

/// A status line above a stage view: the stage's state, dimmed note and error text.
pub fn stage_banner(ui: &mut Ui, stage: Stage, status: &StageStatus) {
    ui.horizontal(|ui| {
        ui.label(format!("{}:", stage.name()));
        ui.colored_label(status.colour(), status.word());
        match status {
            StageStatus::Failed(msg) => {
                ui.colored_label(StageStatus::Failed(String::new()).colour(), msg);
            }
            StageStatus::Stale | StageStatus::Running => {
                ui.weak("(showing the previous result, dimmed)");
            }
            _ => {}
        }
    });
}

/// The colour at `t` on a ramp through three colours: `stops[0]` at 0 (and below), `stops[1]`
/// at 0.5, `stops[2]` at 1 (and above), each channel mixed linearly in the caller's float
/// type; a `t` that is not finite is read as `if_not_finite`.
pub fn three_stop_colour<T>(t: T, if_not_finite: T, stops: [[T; 3]; 3]) -> Color32
where
    T: Copy
        + PartialOrd
        + From<u8>
        + Into<f64>
        + std::ops::Add<Output = T>
        + std::ops::Sub<Output = T>
        + std::ops::Mul<Output = T>
        + std::ops::Div<Output = T>,
{
    let (zero, one, two) = (T::from(0), T::from(1), T::from(2));
    let t = if !Into::<f64>::into(t).is_finite() {
        if_not_finite
    } else if t < zero {
        zero
    } else if t > one {
        one
    } else {
        t
    };
    let half = one / two;
    let [lo, mid, hi] = stops;
    let (from, to, u) = if t < half {
        (lo, mid, t * two)
    } else {
        (mid, hi, (t - half) * two)
    };
    // Rounded in f64: the value converts exactly, so it rounds as in `T`.
    let c = |k: usize| Into::<f64>::into(from[k] + (to[k] - from[k]) * u).round() as u8;
    Color32::from_rgb(c(0), c(1), c(2))
}

/// A closable tool window: its title and its size when first shown (points).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ToolWindow {
    /// The title (also the window's id).
    pub title: &'static str,
    /// Default size (less where the room is smaller).
    pub size: [f32; 2],
}

/// The "Compare methods" window.
pub const COMPARE_WINDOW: ToolWindow = ToolWindow {
    title: "Compare methods",
    size: [1100.0, 620.0],
};

/// The still window.
pub const STILL_WINDOW: ToolWindow = ToolWindow {
    title: "Still image",
    size: [1240.0, 700.0],
};

/// Height a tool window opens with at least (points): where less room is left below the
/// toolbars (a small screen), it opens higher, still below the menu bar.
pub const TOOL_MIN_OPEN_HEIGHT: f32 = 280.0;
/// Width a tool window opens with at least (points), likewise.
pub const TOOL_MIN_OPEN_WIDTH: f32 = 360.0;

/// Where tool windows go, measured as each frame is drawn: the room between the menu bar and
/// the status bar, which they never leave (so they cover neither, and fit a small window), and
/// the corner they open at, below the central view's tabs and toolbar (the waveform's transport
/// and export rows in the waveform view), so they cover neither when first shown.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ToolPlace {
    /// The room windows stay in.
    pub area: egui::Rect,
    /// Where a window's top left corner goes when it first opens.
    pub corner: egui::Pos2,
}

impl Default for ToolPlace {
    /// Before the first frame measured it: the whole window, from its top left.
    fn default() -> Self {
        Self {
            area: egui::Rect::EVERYTHING,
            corner: egui::Pos2::ZERO,
        }
    }
}

impl ToolPlace {
    /// The rect a window of `size` opens in: at the corner, no larger than the room left
    /// there; moved up or left (never out of the area) where that leaves less than
    /// [`TOOL_MIN_OPEN_HEIGHT`] × [`TOOL_MIN_OPEN_WIDTH`].
    #[must_use]
    pub fn open_rect(&self, size: [f32; 2]) -> egui::Rect {
        let a = self.area;
        let x = self
            .corner
            .x
            .min(a.right() - TOOL_MIN_OPEN_WIDTH)
            .max(a.left());
        let y = self
            .corner
            .y
            .min(a.bottom() - TOOL_MIN_OPEN_HEIGHT)
            .max(a.top());
        let min = egui::pos2(x, y);
        let room = (a.max - min).max(egui::Vec2::ZERO);
        egui::Rect::from_min_size(min, egui::vec2(size[0], size[1]).min(room))
    }
}

impl ToolWindow {
    /// Draws the window, `body` inside, while `open`; returns whether it is still open. It
    /// opens where `place` says and stays in its room; its content scrolls when the window is
    /// smaller than it (a small screen), so all of it can be reached.
    pub fn show(
        &self,
        ctx: &egui::Context,
        open: bool,
        place: ToolPlace,
        body: impl FnOnce(&mut Ui),
    ) -> bool {
        let mut open = open;
        let area = if place.area.is_finite() {
            place.area
        } else {
            ctx.content_rect()
        };
        let place = ToolPlace { area, ..place };
        egui::Window::new(self.title)
            .open(&mut open)
            .default_rect(place.open_rect(self.size))
            .constrain_to(area)
            .scroll(true)
            .show(ctx, body);
        open
    }
}

/// The cancel button of running work: `label` while it runs, a greyed "cancelling…" once
/// cancel was asked for; true when clicked.
pub fn cancel_button(ui: &mut Ui, cancelling: bool, label: &str) -> bool {
    let text = if cancelling { "cancelling…" } else { label };
    ui.add_enabled(!cancelling, egui::Button::new(text))
        .clicked()
}

/// A centred notice inside a view that has nothing to draw yet.
pub fn empty_note(ui: &mut Ui, text: &str) {
    ui.add_space(20.0);
    ui.vertical_centered(|ui| ui.weak(text));
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;

    #[test]
    fn segments_break_at_nan_and_names_round_trip() {
        let s = row_segments(&[1.0, 2.0, f32::NAN, f32::NAN, 5.0]);
        assert_eq!(s.len(), 2);
        assert_eq!(s[0], vec![[0.5, 1.5], [1.5, 2.5]]);
        assert_eq!(s[1], vec![[4.5, 5.5]]);
        for v in View::ALL {
            assert_eq!(View::from_name(v.name()), Some(v));
        }
        assert_eq!(View::from_name("Hough"), Some(View::Hough));
        assert!(View::from_name("nope").is_none());
    }
}
