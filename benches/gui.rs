//! Workbench responsiveness: rerunning flow onward and Hough/orientation onward for one 12-frame
//! 1280×1024 group through the shared stage cache, and UI frame times while the worker runs.
//!
//! `cargo bench --bench gui` (add `-- --quick` for a short run). Targets (issue 5): flow onward
//! ≤ 0.5 s, Hough or orientation onward ≤ 100 ms, no UI frame over 50 ms while the worker runs.

use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};

use criterion::Criterion;
use groovescope::image::Image;
use groovescope::io::ScanMeta;
use groovescope::pipeline::{GroupInput, PipelineParams, Stage, StageCache};

/// Frame size and count of the benchmark group (the paper's camera).
const WIDTH: usize = 1280;
const HEIGHT: usize = 1024;
const FRAMES: usize = 12;

const SCAN_TOML: &str = "format = 1
[record]
rpm = 78.0
radius_mm = 115.0
[camera]
pixel_pitch_um = 0.39
working_distance_mm = 4.0
[motion]
frame_step_um = 0.78
group_step_um = 460.2
";

fn texture(x: f64, y: f64) -> f64 {
    0.5 + 0.2 * (0.37 * x + 0.11 * y).sin()
        + 0.15 * (0.23 * x - 0.31 * y + 1.0).sin()
        + 0.1 * (0.71 * x + 0.05 * y + 2.0).sin()
}

/// A V-groove across the middle of the frame: 45° walls 160 rows each, content moving by
/// f·U/Z px per frame (2 px on the land).
fn groove_frames() -> Vec<Image> {
    let (pitch, wd) = (0.39, 4000.0);
    let (top, mid, bottom) = (352.0, 512.0, 672.0);
    let depth = |y: f64| {
        let d = if (top..mid).contains(&y) {
            y - top
        } else if (mid..bottom).contains(&y) {
            bottom - y
        } else {
            0.0
        };
        wd + d * pitch
    };
    (0..FRAMES)
        .map(|t| {
            Image::from_fn(WIDTH, HEIGHT, |x, y| {
                let z = depth(y as f64);
                let gain = if z > wd + 0.2 { 0.95 } else { 0.35 };
                let shift = t as f64 * 2.0 * wd / z;
                (gain * texture(x as f64 + shift, y as f64)).clamp(0.0, 1.0) as f32
            })
        })
        .collect()
}

fn input(meta_text: &str) -> GroupInput {
    let meta = ScanMeta::from_toml_str(meta_text, Path::new("bench.toml")).expect("bench metadata");
    GroupInput {
        group: 0,
        frames: Arc::new(groove_frames()),
        meta: Arc::new(meta),
    }
}

/// Runs every stage once; returns the filled cache and the stage that failed, if any.
fn full_cache(input: &GroupInput, params: &PipelineParams) -> (StageCache, Option<String>) {
    let mut cache = StageCache::default();
    let err = cache
        .run_from(Stage::Derivatives, input, params, &mut |_, _| true)
        .err()
        .map(|e| e.to_string());
    (cache, err)
}

fn rerun_from(c: &mut Criterion, name: &str, from: Stage, input: &GroupInput, base: &StageCache) {
    let params = PipelineParams::default();
    c.bench_function(name, |b| {
        b.iter(|| {
            let mut cache = base.clone();
            cache.invalidate_from(from);
            let _ = cache.run_from(from, input, &params, &mut |_, _| true);
            cache
        });
    });
}

/// UI frame times while the worker reruns flow onward (the harness does not render).
fn ui_frame_times() {
    use egui_kittest::Harness;
    use groovescope::app::{Workbench, WorkbenchOptions};
    use groovescope::playback::DeviceChoice;

    let tmp = tempfile::tempdir().expect("tempdir");
    let dir = tmp.path().join("scan");
    let gdir = dir.join("group_000");
    std::fs::create_dir_all(&gdir).expect("scan folder");
    std::fs::write(dir.join("scan.toml"), SCAN_TOML).expect("scan.toml");
    for (i, f) in groove_frames().iter().enumerate() {
        groovescope::io::save_grey_png(f, &gdir.join(format!("f{i:02}.png")), true, true)
            .expect("frame");
    }
    let opts = WorkbenchOptions {
        scan: Some(dir),
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
    let t0 = Instant::now();
    while h.state().0.as_ref().is_some_and(|w| !w.is_idle())
        && t0.elapsed() < Duration::from_secs(600)
    {
        h.step();
        std::thread::sleep(Duration::from_millis(2));
    }
    let mut worst = Duration::ZERO;
    let mut frames = 0;
    for view in [
        groovescope::app::View::Flow,
        groovescope::app::View::Overview,
    ] {
        let Some(wb) = h.state_mut().0.as_mut() else {
            return;
        };
        wb.set_view(view);
        let mut p = wb.params().clone();
        p.flow.lambda *= 1.5;
        wb.set_params(p);
        let t0 = Instant::now();
        while h.state().0.as_ref().is_some_and(|w| !w.is_idle())
            && t0.elapsed() < Duration::from_secs(600)
        {
            let s = Instant::now();
            h.step();
            worst = worst.max(s.elapsed());
            frames += 1;
            std::thread::sleep(Duration::from_millis(5));
        }
    }
    println!(
        "ui frames while the worker reran flow onward: {frames} frames, worst {:.1} ms (in-app max {:.1} ms)",
        worst.as_secs_f64() * 1e3,
        h.state()
            .0
            .as_ref()
            .map_or(0.0, |w| w.max_busy_frame().as_secs_f64() * 1e3)
    );
}

fn main() {
    let mut c = Criterion::default().sample_size(10).configure_from_args();
    let params = PipelineParams::default();
    let depth_input = input(SCAN_TOML);
    let (cache, err) = full_cache(&depth_input, &params);
    if let Some(e) = &err {
        println!("note: the synthetic group stops at: {e}");
    }
    rerun_from(
        &mut c,
        "depth path: flow onward (12×1280×1024)",
        Stage::Flow,
        &depth_input,
        &cache,
    );
    rerun_from(
        &mut c,
        "depth path: orientation onward",
        Stage::Orientation,
        &depth_input,
        &cache,
    );
    let dual_text = format!(
        "{SCAN_TOML}\n[dual_focus]\nfocus_distance_mm = 4.0\nglass_thickness_mm = 0.11\nglass_index = 1.515\nglass_edge_row = 300\n"
    );
    let dual_input = input(&dual_text);
    let (dual_cache, err) = full_cache(&dual_input, &params);
    if let Some(e) = &err {
        println!("note: the synthetic dual-focus group stops at: {e}");
    }
    rerun_from(
        &mut c,
        "dual focus: Hough (stripes) onward",
        Stage::Stripes,
        &dual_input,
        &dual_cache,
    );
    ui_frame_times();
    c.final_summary();
}
