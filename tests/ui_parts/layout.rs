//! Workbench layout tests (review items 3 and 4): the tool windows open below the menu bar and
//! the view's toolbar and stay inside the window, and at 640×480 every panel's content can
//! still be reached (scrolled to), the central view keeps room beside the side panel.

use egui_kittest::kittest::Queryable;
use groovescope::app::View;
use groovescope::image::Image;

use super::gui_common::*;

/// The window sizes checked (points): the harness's own and a small laptop screen.
const SIZES: [[f32; 2]; 2] = [SIZE, [640.0, 480.0]];

/// The rect the window titled `title` takes (egui names a window's area by its title text,
/// an `Option<Cow<str>>`, which hashes as `Some(&str)` does).
fn window_rect(h: &H, title: &str) -> egui::Rect {
    h.ctx
        .memory(|m| m.area_rect(egui::Id::unique(Some(title))))
        .unwrap_or_else(|| panic!("no window {title:?}"))
}

#[test]
fn tool_windows_open_below_the_menu_bar_and_the_toolbar_inside_the_window() {
    for size in SIZES {
        let (tmp, mut h) = settled_on(&demo_scan());
        h.set_size(egui::vec2(size[0], size[1]));
        wb_mut(&mut h).set_view(View::Waveform);
        h.run_ok();
        let menu_bottom = h.get_by_label("File").rect().bottom();
        let toolbar_bottom = h.get_by_label("Export WAV…").rect().bottom();
        // The status bar's audio line (the waveform's transport says it too, higher up).
        let status_top = h
            .query_all_by_label_contains("audio unavailable")
            .map(|n| n.rect().top())
            .fold(0.0, f32::max);
        wb_mut(&mut h).open_compare();
        h.run_ok();
        // Below the menu bar, and at the full size below `bar` too; above the status bar,
        // inside the window.
        let check = |h: &H, title: &str, bar: (&str, f32)| {
            let r = window_rect(h, title);
            let (bar_name, bar_bottom) = bar;
            assert!(
                r.top() >= menu_bottom,
                "{size:?}: {title} {r:?} covers the menu bar"
            );
            assert!(
                size != SIZE || r.top() >= bar_bottom,
                "{size:?}: {title} {r:?} covers the {bar_name} (to {bar_bottom})"
            );
            assert!(
                r.bottom() <= status_top + 1.0,
                "{size:?}: {title} {r:?} covers the status bar"
            );
            assert!(
                r.right() <= size[0] + 0.5,
                "{size:?}: {title} {r:?} leaves the window"
            );
        };
        check(&h, "Compare methods", ("waveform toolbar", toolbar_bottom));
        // The still window: below the menu bar and the view tabs, inside the window.
        let tabs_bottom = h.get_by_label("export PNG…").rect().bottom();
        let still = tmp.path().join("blank.png");
        groovescope::io::save_grey_png(&Image::from_fn(400, 60, |_, _| 0.5), &still, false, true)
            .unwrap();
        wb_mut(&mut h).open_still(&still);
        settle(&mut h);
        check(&h, "Still image", ("view tabs", tabs_bottom));
    }
}

/// The node whose label contains `label`, scrolled to, shows in `region` (a panel): all of its
/// height, and some of its width (a long line may run on past the panel's edge).
fn reachable(h: &mut H, label: &str, region: egui::Rect) {
    for _ in 0..3 {
        h.get_by_label_contains(label).scroll_to_me();
        h.run_ok();
    }
    let r = h.get_by_label_contains(label).rect();
    assert!(
        r.top() >= region.top() && r.bottom() <= region.bottom() && r.intersects(region),
        "{label:?} at {r:?} cannot be brought into {region:?}"
    );
}

#[test]
fn at_640_by_480_every_panel_can_be_reached() {
    let size = [640.0, 480.0];
    let (_tmp, mut h) = settled_on(&demo_scan());
    h.set_size(egui::vec2(size[0], size[1]));
    h.run_ok();
    // The central view keeps a usable width beside the side panel.
    let tabs = h.get_by_label("overview").rect();
    assert!(
        size[0] - tabs.left() >= 320.0,
        "the central view is {} points wide",
        size[0] - tabs.left()
    );
    // Between the menu bar and the status bar (about 30 points each).
    let side = egui::Rect::from_x_y_ranges(0.0..=tabs.left(), 30.0..=size[1] - 30.0);
    let central = egui::Rect::from_x_y_ranges(tabs.left()..=size[0], 30.0..=size[1] - 30.0);
    // The metadata form's buttons lie below the fold: the central view scrolls to them.
    wb_mut(&mut h).set_view(View::Metadata);
    h.run_ok();
    reachable(&mut h, "Save scan.toml", central);
    // The waveform's spectrum below its plot, and the side panel's last section.
    wb_mut(&mut h).reconstruct(None);
    settle(&mut h);
    wb_mut(&mut h).set_view(View::Waveform);
    h.run_ok();
    reachable(&mut h, "drag: select", central);
    reachable(&mut h, "filter / EQ (clip)", side);
}
