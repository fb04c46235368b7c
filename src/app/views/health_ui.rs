//! The clip health strip: one cell per group, coloured from sound (green) through doubtful
//! (amber) to lost (red), grey where not reconstructed; hover says why, a click goes there.
//! With more groups than the strip has room for, each column of [`MIN_CELL_PT`] stands for a
//! run of groups and shows the worst of them.

use std::ops::Range;

use egui::{Color32, Rect, Sense, Stroke, Ui, pos2, vec2};

use super::three_stop_colour;
use crate::app::health::ClipHealth;

/// Height of the strip (points).
pub const STRIP_HEIGHT_PT: f32 = 16.0;
/// Narrowest cell (points): below this, cells merge into columns of several groups.
pub const MIN_CELL_PT: f32 = 2.0;
/// Colour of groups not reconstructed yet.
pub const NOT_RUN_COLOUR: Color32 = Color32::from_gray(70);

/// Green, amber, red: the colours of a severity of 0, 0.5 and 1.
const SEVERITY_RAMP: [[f32; 3]; 3] = [
    [70.0, 170.0, 90.0],
    [230.0, 180.0, 50.0],
    [220.0, 50.0, 45.0],
];

/// Colour of a severity in `[0, 1]`: green, amber at 0.5, red at 1.
#[must_use]
pub fn severity_colour(severity: f32) -> Color32 {
    // An unknown severity is the worst.
    three_stop_colour(severity, 1.0, SEVERITY_RAMP)
}

/// The strip's columns: the groups each stands for and its rectangle inside `rect`.
#[must_use]
pub fn strip_columns(groups: usize, rect: Rect) -> Vec<(Range<usize>, Rect)> {
    if groups == 0 || rect.width() <= 0.0 {
        return Vec::new();
    }
    let fit = (rect.width() / MIN_CELL_PT).floor().max(1.0) as usize;
    let columns = groups.min(fit);
    let w = rect.width() / columns as f32;
    (0..columns)
        .map(|c| {
            let a = c * groups / columns;
            let b = (c + 1) * groups / columns;
            let x0 = rect.left() + c as f32 * w;
            (
                a..b,
                Rect::from_min_max(pos2(x0, rect.top()), pos2(x0 + w, rect.bottom())),
            )
        })
        .collect()
}

/// Draws the strip for `health` with the `current` group outlined; returns the group clicked.
pub fn health_strip_ui(ui: &mut Ui, health: &ClipHealth, current: usize) -> Option<usize> {
    let n = health.len();
    if n == 0 {
        return None;
    }
    let (rect, _) =
        ui.allocate_exact_size(vec2(ui.available_width(), STRIP_HEIGHT_PT), Sense::hover());
    let painter = ui.painter_at(rect);
    let id = ui.scope_id().with("health_strip");
    let mut clicked = None;
    let mut current_rect = None;
    for (k, (groups, r)) in strip_columns(n, rect).into_iter().enumerate() {
        let worst = health.worst_in(groups.clone()).unwrap_or(groups.start);
        let colour = match health.cell(worst) {
            Some(c) if c.ran => severity_colour(c.severity),
            _ => NOT_RUN_COLOUR,
        };
        let inner = if r.width() >= 4.0 {
            r.shrink2(vec2(0.5, 0.0))
        } else {
            r
        };
        painter.rect_filled(inner, 0.0, colour);
        if groups.contains(&current) {
            current_rect = Some(r);
        }
        let resp = ui.interact(r, id.with(k), Sense::click());
        let label = || {
            if groups.len() == 1 {
                format!("health of group {}", groups.start)
            } else {
                format!("health of groups {}–{}", groups.start, groups.end - 1)
            }
        };
        resp.widget_info(|| egui::WidgetInfo::labeled(egui::Role::Button, true, label()));
        if resp.hovered() {
            let text = if groups.len() == 1 {
                health.describe(groups.start)
            } else {
                format!("{}\nworst: {}", label(), health.describe(worst))
            };
            resp.clone().on_hover_text(text);
        }
        if resp.clicked() {
            clicked = Some(if groups.len() == 1 {
                groups.start
            } else {
                worst
            });
        }
    }
    if let Some(r) = current_rect {
        // Drawn inside the cell (at least 4 points wide), so the strip's clip keeps all of it.
        let mark = Rect::from_center_size(r.center(), vec2(r.width().max(4.0), r.height()));
        painter.rect_stroke(
            mark,
            1.0,
            Stroke::new(2.0, Color32::WHITE),
            egui::StrokeKind::Inside,
        );
    }
    clicked
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_column_per_group_until_they_get_too_narrow() {
        let rect = Rect::from_min_size(pos2(10.0, 0.0), vec2(300.0, 16.0));
        let cols = strip_columns(13, rect);
        assert_eq!(cols.len(), 13);
        assert!(cols.iter().enumerate().all(|(g, (r, _))| *r == (g..g + 1)));
        assert!((cols[12].1.right() - 310.0).abs() < 1e-3);
        let cols = strip_columns(10_000, rect);
        assert_eq!(cols.len(), 150);
        assert_eq!(cols[0].0.start, 0);
        assert_eq!(cols[149].0.end, 10_000);
        assert!(cols.windows(2).all(|w| w[0].0.end == w[1].0.start));
        assert!(strip_columns(0, rect).is_empty());
        assert_eq!(severity_colour(0.0), Color32::from_rgb(70, 170, 90));
        assert_eq!(severity_colour(1.0), Color32::from_rgb(220, 50, 45));
    }
}
