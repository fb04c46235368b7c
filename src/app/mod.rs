//! The workbench (feature `gui`): an eframe app that shows every stage of the current group from
//! the shared stage cache, reruns stale stages on a worker thread while the operator tunes,
//! reconstructs the whole clip in the background, plays it through cpal and exports it.
//!
//! Threads: the UI thread only reads results and draws; `groovescope-stages` runs
//! [`worker::Job`]s; `groovescope-reconstruct` runs the engine over all groups;
//! `groovescope-dialog` shows file dialogs; `groovescope-import` imports a video clip (feature
//! `video`); the cpal callback reads a prepared buffer.

pub mod dialogs;
pub mod export;
pub mod history;
#[cfg(feature = "video")]
pub mod import_video;
pub mod recent;
pub mod recon;
pub mod render;
pub mod shell;
pub mod textures;
pub mod views;
pub mod workbench;
pub mod worker;

use std::path::{Path, PathBuf};

use anyhow::Context as _;

pub use views::View;
pub use workbench::{Workbench, WorkbenchOptions};

/// Env var: save a screenshot of the window to this path once the work settled, then quit.
pub const SCREENSHOT_ENV: &str = "GROOVESCOPE_SCREENSHOT";
/// Env var: the view shown first (`overview`, `flow`, `hough`, `stripes`, `depth`, `waveform`, …).
pub const VIEW_ENV: &str = "GROOVESCOPE_VIEW";
/// Env var: set to `1` to reconstruct the clip as soon as the scan opens.
pub const RECONSTRUCT_ENV: &str = "GROOVESCOPE_RECONSTRUCT";
/// Window size (points): also the size of screenshots.
pub const WINDOW_SIZE: [f32; 2] = [1600.0, 1000.0];

/// The demo scan bundled with the sources, when it exists (the working directory first).
#[must_use]
pub fn demo_scan() -> Option<PathBuf> {
    [
        PathBuf::from("assets/demo"),
        Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/demo"),
    ]
    .into_iter()
    .find(|p| p.join("scan.toml").is_file())
}

/// The scan to open when none is given: the last one used, else the demo scan.
#[must_use]
pub fn default_scan(config_dir: Option<&Path>) -> Option<PathBuf> {
    let recent = recent::RecentScans::load(config_dir);
    recent
        .scans
        .into_iter()
        .find(|p| p.join("scan.toml").is_file())
        .or_else(demo_scan)
}

/// Opens the workbench window on `scan` (None: the last scan used, else the demo scan) and
/// returns when it closes.
///
/// `GROOVESCOPE_SCREENSHOT=PATH` (with `GROOVESCOPE_VIEW=NAME`, and `GROOVESCOPE_RECONSTRUCT=1`
/// for the waveform) saves a screenshot once the work is done and closes the window.
///
/// # Errors
/// When no window can be opened (no display), or a requested screenshot was not written.
pub fn run(scan: Option<PathBuf>) -> anyhow::Result<()> {
    let config_dir = recent::config_dir();
    let screenshot = std::env::var_os(SCREENSHOT_ENV).map(PathBuf::from);
    let view = match std::env::var(VIEW_ENV) {
        Ok(name) => Some(View::from_name(&name).with_context(|| {
            format!(
                "unknown view {name:?} in {VIEW_ENV} (one of: {})",
                View::ALL.map(View::name).join(", ")
            )
        })?),
        Err(_) => None,
    };
    let reconstruct_on_open = std::env::var(RECONSTRUCT_ENV).is_ok_and(|v| v == "1")
        || (screenshot.is_some() && view == Some(View::Waveform));
    let opts = WorkbenchOptions {
        scan: scan.or_else(|| default_scan(config_dir.as_deref())),
        config_dir,
        audio: crate::playback::DeviceChoice::from_env(),
        view,
        screenshot: screenshot.clone(),
        reconstruct_on_open,
        hide_timings: false,
    };
    if let Some(p) = &screenshot
        && p.exists()
    {
        std::fs::remove_file(p)
            .with_context(|| format!("cannot replace the old screenshot {}", p.display()))?;
    }
    let native = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default()
            .with_title("groovescope")
            .with_inner_size(WINDOW_SIZE)
            .with_drag_and_drop(true),
        ..Default::default()
    };
    eframe::run_native(
        "groovescope",
        native,
        Box::new(move |cc| Ok(Box::new(Workbench::new(&cc.egui_ctx, opts)?))),
    )
    .map_err(|e| anyhow::anyhow!("cannot open the workbench window: {e}"))?;
    if let Some(p) = screenshot {
        anyhow::ensure!(p.is_file(), "no screenshot was written to {}", p.display());
    }
    Ok(())
}
