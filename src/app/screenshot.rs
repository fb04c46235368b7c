//! Pictures of the window: a view saved as PNG (a capture of its area), and the screenshot mode
//! that waits until the work settled, saves the whole window and closes it.

use std::path::PathBuf;
use std::sync::mpsc::{Receiver, Sender};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Frames to wait after everything settled before a screenshot (textures and layout settle).
pub const SCREENSHOT_SETTLE_FRAMES: u32 = 6;
/// Longest wait for the app to settle before the screenshot is taken anyway.
pub const SCREENSHOT_TIMEOUT: Duration = Duration::from_secs(600);

/// Screenshot mode: wait until the work is done, capture the window, save it, close.
#[derive(Debug)]
pub struct ScreenshotPlan {
    /// Where the PNG goes.
    pub path: PathBuf,
    /// When the app started.
    pub started: Instant,
    /// Frames in a row the app was settled.
    pub settled: u32,
    /// True once the capture was asked for.
    pub requested: bool,
    /// The outcome of saving, once known.
    pub result: Arc<Mutex<Option<Result<(), String>>>>,
}

impl ScreenshotPlan {
    /// A plan to save the window to `path`.
    #[must_use]
    pub fn new(path: PathBuf) -> Self {
        Self {
            path,
            started: Instant::now(),
            settled: 0,
            requested: false,
            result: Arc::new(Mutex::new(None)),
        }
    }

    /// The outcome of saving, once known.
    #[must_use]
    pub fn outcome(&self) -> Option<Result<(), String>> {
        self.result.lock().ok().and_then(|r| r.clone())
    }
}

/// A view capture on its way: the file, and whether it may replace one.
#[derive(Clone, Debug)]
pub struct PendingCapture {
    /// Target PNG.
    pub path: PathBuf,
    /// Replace an existing file.
    pub overwrite: bool,
}

/// Captures of the window.
#[derive(Debug)]
pub struct Capture {
    /// Screenshot mode, when on.
    pub plan: Option<ScreenshotPlan>,
    /// Frames captured for a view export arrive here.
    pub channel: (
        Sender<Arc<egui::ColorImage>>,
        Receiver<Arc<egui::ColorImage>>,
    ),
    /// The view export waiting for its capture.
    pub pending: Option<PendingCapture>,
    /// Where the central view was drawn last frame (the area a view export keeps).
    pub view_rect: egui::Rect,
}

impl Capture {
    /// Captures, with screenshot mode on when `screenshot` is given.
    #[must_use]
    pub fn new(screenshot: Option<PathBuf>) -> Self {
        Self {
            plan: screenshot.map(ScreenshotPlan::new),
            channel: std::sync::mpsc::channel(),
            pending: None,
            view_rect: egui::Rect::NOTHING,
        }
    }
}
