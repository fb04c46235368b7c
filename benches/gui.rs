//! Workbench responsiveness: rerunning flow onward and Hough/orientation onward for one 12-frame
//! 1280×1024 group through the shared stage cache, and UI frame times while the worker runs.
//!
//! `cargo bench --bench gui` (add `-- --quick` for a short run). Targets (issue 5): flow onward
//! ≤ 0.5 s, Hough or orientation onward ≤ 100 ms, no UI frame over 50 ms while the worker runs;
//! (issue 20) the clip health strip redraws in ≤ 2 ms for 10,000 groups.
//! The groups are rendered by the synth generator (the paper's camera) into a temporary folder.

mod common;

use std::path::PathBuf;
use std::time::{Duration, Instant};

use common::render_group;
use criterion::Criterion;
use groovescope::pipeline::{GroupInput, PipelineParams, Stage, StageCache};
use groovescope::synth::SynthConfig;

/// Runs every stage once (printing each stage's time, and the error that stopped it, if any);
/// returns the filled cache.
fn full_cache(name: &str, input: &GroupInput, params: &PipelineParams) -> StageCache {
    let mut cache = StageCache::default();
    let mut t0 = Instant::now();
    let mut times = Vec::new();
    let err = cache
        .run_from(Stage::Derivatives, input, params, &mut |stage, _| {
            times.push(format!(
                "{} {:.0} ms",
                stage.name(),
                t0.elapsed().as_secs_f64() * 1e3
            ));
            t0 = Instant::now();
            true
        })
        .err()
        .map(|e| e.to_string());
    println!("{name}: one full run: {}", times.join(", "));
    if let Some(e) = &err {
        println!("note: the {name} group stops at: {e}");
    }
    cache
}

fn rerun_from(c: &mut Criterion, name: &str, from: Stage, input: &GroupInput, base: &StageCache) {
    let params = PipelineParams::default();
    c.bench_function(name, |b| {
        b.iter(|| {
            let mut cache = base.clone();
            cache.invalidate(from);
            let _ = cache.run_from(from, input, &params, &mut |_, _| true);
            cache
        });
    });
}

/// UI frame times while the worker reruns flow onward (the harness does not render, so this is
/// the app's own work per frame: polling, texture uploads, layout, plots).
fn ui_frame_times(scan: PathBuf) {
    use egui_kittest::Harness;
    use groovescope::app::{View, Workbench, WorkbenchOptions};
    use groovescope::playback::DeviceChoice;

    let opts = WorkbenchOptions {
        scan: Some(scan),
        audio: DeviceChoice::Off,
        ..WorkbenchOptions::default()
    };
    let mut h = Harness::builder()
        .with_size(egui::vec2(1600.0, 1000.0))
        .with_accessibility_check(false)
        .build_ui_state(
            |ui, app: &mut (Option<Workbench>, eframe::Frame)| {
                if let Some(wb) = &mut app.0 {
                    eframe::App::ui(wb, ui, &mut app.1);
                }
            },
            (None, eframe::Frame::_new_kittest()),
        );
    let ctx = h.ctx.clone();
    h.state_mut().0 = Some(Workbench::new(&ctx, opts).expect("workbench"));
    let busy = |h: &Harness<'_, (Option<Workbench>, eframe::Frame)>| {
        h.state().0.as_ref().is_some_and(|w| !w.is_idle())
    };
    let t0 = Instant::now();
    while busy(&h) && t0.elapsed() < Duration::from_secs(600) {
        h.step();
        std::thread::sleep(Duration::from_millis(2));
    }
    let mut worst = Duration::ZERO;
    let mut frames = 0;
    for view in [View::Flow, View::Overview, View::Depth] {
        let Some(wb) = h.state_mut().0.as_mut() else {
            return;
        };
        wb.set_view(view);
        let mut p = wb.params().clone();
        p.flow.lambda *= 1.5;
        wb.set_params(p);
        let t0 = Instant::now();
        while busy(&h) && t0.elapsed() < Duration::from_secs(600) {
            let s = Instant::now();
            h.step();
            worst = worst.max(s.elapsed());
            frames += 1;
            std::thread::sleep(Duration::from_millis(5));
        }
    }
    // Scrubbing through the frames (the worker rendered them with the group).
    let mut worst_scrub = Duration::ZERO;
    for i in 0..12 {
        let Some(wb) = h.state_mut().0.as_mut() else {
            return;
        };
        wb.set_view(View::Frame);
        wb.set_frame(i);
        let s = Instant::now();
        h.step();
        worst_scrub = worst_scrub.max(s.elapsed());
    }
    println!(
        "UI frames while scrubbing 12 frames: worst step {:.1} ms",
        worst_scrub.as_secs_f64() * 1e3
    );
    let in_app = h
        .state()
        .0
        .as_ref()
        .map_or(0.0, |w| w.max_busy_frame().as_secs_f64() * 1e3);
    println!(
        "UI frames while the worker reran flow onward: {frames} frames, worst step {:.1} ms (in-app worst {in_app:.1} ms)",
        worst.as_secs_f64() * 1e3
    );
}

/// One frame of a side panel holding only the health strip of a 10,000-group clip: layout,
/// painting and tessellation (what a redraw of the strip costs the UI thread).
fn health_strip(c: &mut Criterion) {
    use groovescope::app::health::{ClipHealth, GroupTrack};
    use groovescope::app::views::health_ui::health_strip_ui;
    use groovescope::engine::GroupReport;

    const GROUPS: usize = 10_000;
    // A clip with scattered damage: some gaps, rejected fits, outlier outliers, failed groups.
    let tracks: Vec<GroupTrack> = (0..GROUPS)
        .map(|g| GroupTrack {
            group: g,
            span_um: (g as f64 * 460.0, g as f64 * 460.0 + 450.0),
            samples: 22,
            gap_samples: if g % 37 == 0 { g % 23 } else { 0 },
            failed: g % 997 == 0,
        })
        .collect();
    let reports: Vec<GroupReport> = (0..GROUPS)
        .map(|g| GroupReport {
            group: g,
            outlier_fraction: (g % 997 != 0).then_some(0.9 + 0.1 * ((g % 13) as f64 / 13.0)),
            rejected_fits: usize::from(g % 101 == 0),
            samples: 22,
            warning: None,
            pixel_noise_grey_levels: None,
        })
        .collect();
    let health = ClipHealth::new(GROUPS, &tracks, &reports);
    let ctx = egui::Context::default();
    let input = egui::RawInput {
        screen_rect: Some(egui::Rect::from_min_size(
            egui::Pos2::ZERO,
            egui::vec2(1600.0, 1000.0),
        )),
        ..Default::default()
    };
    c.bench_function(
        "health strip: 10,000 groups, one frame (layout, paint, tessellate)",
        |b| {
            b.iter(|| {
                let mut out = ctx.run_ui(input.clone(), |ui| {
                    egui::Panel::left("side")
                        .default_size(330.0)
                        .show(ui, |ui| health_strip_ui(ui, &health, GROUPS / 2));
                });
                // No GPU here: the font atlas upload is not the strip's work.
                out.textures_delta.clear();
                ctx.tessellate(out.shapes, out.pixels_per_point)
            });
        },
    );
}

fn main() {
    // As the `groovescope` binary does at start-up (the workbench included).
    groovescope::alloc::keep_freed_buffers();
    let mut c = Criterion::default().sample_size(10).configure_from_args();
    health_strip(&mut c);
    if std::env::args().any(|a| a == "health") {
        c.final_summary();
        return;
    }
    let tmp = tempfile::tempdir().expect("tempdir");
    let params = PipelineParams::default();

    let depth_dir = tmp.path().join("depth");
    let (_, depth_input) = render_group(&depth_dir, SynthConfig::default(), 440.0);
    let cache = full_cache("depth path", &depth_input, &params);
    for (name, from) in [
        ("depth path: flow onward (12x1280x1024)", Stage::Flow),
        ("depth path: orientation onward", Stage::Orientation),
    ] {
        rerun_from(&mut c, name, from, &depth_input, &cache);
    }

    let (_, dual_input) = render_group(
        &tmp.path().join("dual"),
        SynthConfig::dual_focus_demo(),
        440.0,
    );
    let dual_cache = full_cache("dual focus", &dual_input, &params);
    for (name, from) in [
        ("dual focus: flow onward (12x1280x1024)", Stage::Flow),
        ("dual focus: Hough (stripes) onward", Stage::Stripes),
        ("dual focus: orientation onward", Stage::Orientation),
    ] {
        rerun_from(&mut c, name, from, &dual_input, &dual_cache);
    }

    ui_frame_times(depth_dir);
    c.final_summary();
}
