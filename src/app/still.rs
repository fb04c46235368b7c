//! The workbench's still mode: a still image of a record opened whole, its grooves found and one
//! of them decoded on the named thread `groovescope-still` (progress and cancel), with what the
//! still window draws: the grooves outlined and numbered, the fitted borders, and the sound.
//!
//! The decode is the `still` command's ([`crate::still::find_grooves`] and
//! [`crate::still::decode_groove`]) on the image held in memory, so picking another groove reads
//! no file again and does not find the grooves again.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use super::background::{Background, Reporter};
use crate::image::Image;
use crate::io::Cut;
use crate::io::still::StillReader;
use crate::pipeline::PipelineParams;
use crate::pipeline::still::{Axis, GrooveMap, StillSetup, choose_groove, lines_and_cross};
use crate::playback::PlayBuffers;
use crate::still::{
    FoundGrooves, StillPhase, StillRun, StillRunError, decode_groove, find_grooves,
};

/// Largest still the workbench opens whole (pixels; 2²⁶ ≈ 67 Mpx, 268 MB as grey `f32`).
/// Larger stills stream through `groovescope still` instead.
pub const MAX_WORKBENCH_STILL_PIXELS: usize = 1 << 26;
/// Rows read per progress report while the image loads.
const LOAD_BAND_ROWS: usize = 256;

/// True for a file the still window opens (by its name: PNG or TIFF).
#[must_use]
pub fn is_still_image(path: &Path) -> bool {
    path.is_file()
        && path.extension().is_some_and(|e| {
            let e = e.to_string_lossy().to_ascii_lowercase();
            matches!(e.as_str(), "png" | "tif" | "tiff")
        })
}

/// Where the settings of a still came from.
#[derive(Clone, Debug, PartialEq)]
pub enum SetupSource {
    /// The generator's `truth.toml` beside the image.
    Sidecar(PathBuf),
    /// Guessed (the axis from the image's long side); the pixel size must be checked.
    Guessed,
    /// Typed in the window over a guess.
    Entered,
}

/// The settings for `image` (at `path`): from a `truth.toml` written by `synth-still` beside it
/// (with the groove it names), else a guess: grooves along the image's long side, the
/// paper's 0.39 µm pixels at 78 rpm and 100 mm.
#[must_use]
pub fn setup_for(
    path: &Path,
    width: usize,
    height: usize,
) -> (StillSetup, Option<usize>, SetupSource) {
    if let Some(dir) = path.parent()
        && let Ok(demo) = crate::still::demo::read_generated_still(dir)
        && demo.image.file_name() == path.file_name()
    {
        return (
            demo.setup,
            Some(demo.groove),
            SetupSource::Sidecar(dir.join("truth.toml")),
        );
    }
    let axis = if width > height {
        Axis::Horizontal
    } else {
        Axis::Vertical
    };
    (
        StillSetup {
            axis,
            um_per_px: 0.39,
            rpm: 78.0,
            radius_mm: 100.0,
            cut: Cut::Lateral,
            reverse: false,
        },
        None,
        SetupSource::Guessed,
    )
}

/// How far a still decode has got.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StillProgressNow {
    /// What it is doing.
    pub what: &'static str,
    /// Share of the whole decode done, in `[0, 1]`.
    pub fraction: f64,
}

/// What a finished still job hands back: the image, its grooves and the decoded groove; an
/// error after the grooves were found keeps them, so the operator can pick another.
#[derive(Clone, Debug)]
pub struct StillOutcome {
    /// The image (None when it could not be read).
    pub image: Option<Arc<Image>>,
    /// The grooves found.
    pub found: Option<Arc<FoundGrooves>>,
    /// The groove decoded.
    pub run: Option<Arc<StillRun>>,
    /// Why it stopped short, if it did.
    pub error: Option<String>,
}

/// The open still.
#[derive(Clone, Debug)]
pub struct StillDoc {
    /// The image file.
    pub path: PathBuf,
    /// The image, grey.
    pub image: Arc<Image>,
    /// The settings in force (the window edits them; "Find grooves" applies them).
    pub setup: StillSetup,
    /// Where they came from.
    pub source: SetupSource,
    /// The grooves found with `found_with`.
    pub found: Option<Arc<FoundGrooves>>,
    /// The settings the grooves were found with.
    pub found_with: Option<StillSetup>,
    /// The decoded groove.
    pub run: Option<Arc<StillRun>>,
    /// Why the last decode gave no sound (cleared by the next that does).
    pub problem: Option<String>,
}

impl StillDoc {
    /// The player's buffers for the decoded groove.
    #[must_use]
    pub fn play_buffers(&self) -> Option<PlayBuffers> {
        let run = self.run.as_ref()?;
        Some(PlayBuffers {
            rate_hz: run.audio.sample_rate_hz,
            sources: vec![run.audio.channels.clone()],
        })
    }

    /// The image line (row of a vertical still, column of a horizontal one) heard at `secs`
    /// into the decoded groove's sound.
    #[must_use]
    pub fn line_at(&self, secs: f64) -> Option<f64> {
        let run = self.run.as_ref()?;
        let lines = run.analysis.borders.lines as f64;
        let rate = run.analysis.signal.native_rate_hz;
        let n = (secs * rate).clamp(0.0, (lines - 1.0).max(0.0));
        Some(if self.setup.reverse {
            lines - 1.0 - n
        } else {
            n
        })
    }
}

/// The picture of the image stretch shown, kept while the stretch stays.
pub struct StillPicture {
    /// First line, lines, image identity and axis it was made for.
    pub key: (usize, usize, usize, usize),
    /// The texture.
    pub handle: egui::TextureHandle,
}

impl std::fmt::Debug for StillPicture {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("StillPicture")
            .field("key", &self.key)
            .finish_non_exhaustive()
    }
}

/// The still window's state.
#[derive(Debug, Default)]
pub struct StillState {
    /// The window is shown.
    pub open: bool,
    /// The open still.
    pub doc: Option<StillDoc>,
    /// The decode running now.
    pub job: Option<Background<StillProgressNow, StillOutcome>>,
    /// A still being opened: its file, settings and their origin (the doc once it loads).
    pub pending: Option<(PathBuf, StillSetup, SetupSource)>,
    /// The picture of the stretch shown.
    pub picture: Option<StillPicture>,
    /// First image line shown.
    pub first_line: f64,
    /// Image lines shown across the view (0: fit the image).
    pub lines_shown: f64,
}

/// What a still job must do.
#[derive(Clone, Debug)]
pub struct StillTask {
    /// The image file.
    pub path: PathBuf,
    /// The image when already loaded.
    pub image: Option<Arc<Image>>,
    /// The grooves when already found with `setup`.
    pub found: Option<Arc<FoundGrooves>>,
    /// The settings.
    pub setup: StillSetup,
    /// The groove to decode (from 1; None: the decoder's pick).
    pub groove: Option<usize>,
    /// The knobs (the `[still]`, `[sound]` and `[dsp]` tables apply).
    pub params: PipelineParams,
}

/// Reads the whole still at `path` as grey, reporting each band of rows.
///
/// # Errors
/// One line naming the file: unreadable, or too large for the workbench.
pub fn load_still(path: &Path, report: &mut dyn FnMut(f64) -> bool) -> Result<Image, String> {
    let mut reader = StillReader::open(path).map_err(|e| e.to_string())?;
    let (w, h) = (reader.width(), reader.height());
    if w.saturating_mul(h) > MAX_WORKBENCH_STILL_PIXELS {
        return Err(format!(
            "{w}×{h} px is more than the workbench opens whole ({} Mpx): decode it with \
             `groovescope still`, which streams it: {}",
            MAX_WORKBENCH_STILL_PIXELS >> 20,
            path.display()
        ));
    }
    let mut data = Vec::with_capacity(w * h);
    let mut band = Vec::new();
    loop {
        if !report(reader.next_row() as f64 / h.max(1) as f64) {
            return Err("cancelled".into());
        }
        if reader
            .read_rows(&mut band, LOAD_BAND_ROWS)
            .map_err(|e| e.to_string())?
            == 0
        {
            break;
        }
        data.extend_from_slice(&band);
    }
    Ok(Image {
        width: w,
        height: h,
        data,
    })
}

/// Runs `task`: loads the image, finds the grooves and decodes one, as far as each is needed.
fn run_task(task: StillTask, r: &Reporter<StillProgressNow, StillOutcome>) -> StillOutcome {
    let started = Instant::now();
    // Shares of the whole decode: loading, finding the grooves, the chosen groove's pass, fits.
    let load_share = if task.image.is_none() { 0.3 } else { 0.0 };
    let find_share = if task.found.is_none() { 0.3 } else { 0.0 };
    let rest = 1.0 - load_share - find_share;
    let image = match task.image.clone() {
        Some(i) => i,
        None => {
            let loaded = load_still(&task.path, &mut |f| {
                r.report(StillProgressNow {
                    what: "reading the image",
                    fraction: load_share * f,
                })
            });
            match loaded {
                Ok(i) => Arc::new(i),
                Err(e) => {
                    return StillOutcome {
                        image: None,
                        found: None,
                        run: None,
                        error: Some(e),
                    };
                }
            }
        }
    };
    let fail = |found: Option<Arc<FoundGrooves>>, e: StillRunError| StillOutcome {
        image: Some(image.clone()),
        found,
        run: None,
        error: Some(e.to_string()),
    };
    let mut open = || Ok(StillReader::from_image(image.as_ref().clone(), &task.path));
    let found = match task.found.clone() {
        Some(f) => f,
        None => {
            let mut progress = |_: StillPhase, f: f64| {
                r.report(StillProgressNow {
                    what: StillPhase::Profiles.describe(),
                    fraction: load_share + find_share * f,
                })
            };
            match find_grooves(&mut open, &task.setup, &task.params.still, &mut progress) {
                Ok(f) => Arc::new(f),
                Err(e) => return fail(None, e),
            }
        }
    };
    let chosen = match choose_groove(&found.grooves, task.groove) {
        Ok(c) => c,
        Err(problem) => {
            return fail(
                Some(found.clone()),
                StillRunError::Still {
                    problem,
                    path: task.path.clone(),
                },
            );
        }
    };
    let base = load_share + find_share;
    let mut progress = |phase: StillPhase, f: f64| {
        let (from, share) = match phase {
            StillPhase::Profiles | StillPhase::Ribbon => (0.0, 0.4),
            StillPhase::Decode => (0.4, 0.6),
        };
        r.report(StillProgressNow {
            what: phase.describe(),
            fraction: base + rest * (from + share * f),
        })
    };
    match decode_groove(
        &mut open,
        &found,
        chosen,
        &task.setup,
        &task.params,
        &mut progress,
        started,
    ) {
        Ok(run) => StillOutcome {
            image: Some(image.clone()),
            found: Some(found),
            run: Some(Arc::new(run)),
            error: None,
        },
        Err(e) => fail(Some(found), e),
    }
}

/// Starts `task` on the thread `groovescope-still`; `repaint` wakes the UI.
///
/// # Errors
/// When the thread cannot be started.
pub fn start_still(
    task: StillTask,
    repaint: Box<dyn Fn() + Send + Sync>,
) -> std::io::Result<Background<StillProgressNow, StillOutcome>> {
    Background::start(
        "groovescope-still",
        StillProgressNow {
            what: "starting",
            fraction: 0.0,
        },
        repaint,
        move |r| Ok(run_task(task, r)),
    )
}

/// The groove (index into `map.grooves`) under image point (`line`, `cross`): the one whose
/// outer borders there enclose it, else the nearest one's centre within a groove width.
#[must_use]
pub fn groove_at(map: &GrooveMap, line: f64, cross: f64) -> Option<usize> {
    let mut best: Option<(usize, f64)> = None;
    for (i, g) in map.grooves.iter().enumerate() {
        let b = g.predict(map, line);
        if !(b[0].is_finite() && b[3].is_finite()) {
            continue;
        }
        let (lo, hi) = (b[0].min(b[3]), b[0].max(b[3]));
        if (lo..=hi).contains(&cross) {
            return Some(i);
        }
        let d = (cross - 0.5 * (lo + hi)).abs();
        if d <= g.width_px.max(hi - lo) && best.is_none_or(|(_, bd)| d < bd) {
            best = Some((i, d));
        }
    }
    best.map(|(i, _)| i)
}

/// Image pixel (x, y) of (`line`, `cross`) for `axis`.
#[must_use]
pub fn pixel_of(axis: Axis, line: f64, cross: f64) -> (f64, f64) {
    match axis {
        Axis::Vertical => (cross, line),
        Axis::Horizontal => (line, cross),
    }
}

/// A grey picture of image lines `[first, first + count)` of `image` (all of the cross), at
/// most `max_along` samples along the lines and `max_cross` across (box averages): returned
/// as (width, height, grey bytes) in the image's own orientation.
#[must_use]
pub fn stretch_picture(
    image: &Image,
    axis: Axis,
    first: usize,
    count: usize,
    max_along: usize,
    max_cross: usize,
) -> (usize, usize, Vec<u8>) {
    let (lines, cross) = lines_and_cross(image.width, image.height, axis);
    let first = first.min(lines.saturating_sub(1));
    let count = count.clamp(1, lines - first);
    let along_out = count.min(max_along.max(1));
    let cross_out = cross.min(max_cross.max(1));
    let (w, h) = match axis {
        Axis::Vertical => (cross_out, along_out),
        Axis::Horizontal => (along_out, cross_out),
    };
    let mut out = vec![0u8; w * h];
    let value = |line: usize, c: usize| -> f32 {
        let (x, y) = match axis {
            Axis::Vertical => (c, line),
            Axis::Horizontal => (line, c),
        };
        image.data.get(y * image.width + x).copied().unwrap_or(0.0)
    };
    for a in 0..along_out {
        let l0 = first + a * count / along_out;
        let l1 = (first + (a + 1) * count / along_out).max(l0 + 1);
        for c in 0..cross_out {
            let c0 = c * cross / cross_out;
            let c1 = ((c + 1) * cross / cross_out).max(c0 + 1);
            let mut sum = 0.0f64;
            for l in l0..l1 {
                for k in c0..c1 {
                    sum += f64::from(value(l, k));
                }
            }
            let mean = sum / ((l1 - l0) * (c1 - c0)) as f64;
            let (x, y) = match axis {
                Axis::Vertical => (c, a),
                Axis::Horizontal => (a, c),
            };
            out[y * w + x] = (mean.clamp(0.0, 1.0) * 255.0).round() as u8;
        }
    }
    (w, h, out)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;
    use crate::pipeline::still::GrooveTrack;

    fn map() -> GrooveMap {
        let track = |number: usize, at: f64| GrooveTrack {
            number,
            blocks: vec![Some([at, at + 4.0, at + 6.0, at + 10.0]); 3],
            coverage: 1.0,
            position_px: at + 5.0,
            width_px: 10.0,
        };
        GrooveMap {
            axis: Axis::Vertical,
            lines: 96,
            cross: 100,
            block_lines: 32,
            block_centres: vec![16.0, 48.0, 80.0],
            grooves: vec![track(1, 10.0), track(2, 40.0), track(3, 70.0)],
            drift_px_per_block: 0.0,
            brightness_gain: 1.0,
            bottoms_visible: true,
            energy_ratio: 0.1,
        }
    }

    #[test]
    fn a_click_picks_the_groove_under_it_or_the_nearest_one() {
        let m = map();
        assert_eq!(groove_at(&m, 50.0, 45.0), Some(1));
        assert_eq!(groove_at(&m, 0.0, 10.0), Some(0));
        // Between grooves 2 and 3, within a groove width of 3's centre (75).
        assert_eq!(groove_at(&m, 50.0, 66.0), Some(2));
        assert_eq!(groove_at(&m, 50.0, 60.0), None);
        // Far from every groove.
        assert_eq!(groove_at(&m, 50.0, -40.0), None);
    }

    #[test]
    fn the_stretch_picture_keeps_the_orientation_and_averages() {
        // 6 wide, 4 high, value = x / 10.
        let image = Image {
            width: 6,
            height: 4,
            data: (0..24).map(|i| (i % 6) as f32 / 10.0).collect(),
        };
        let (w, h, px) = stretch_picture(&image, Axis::Horizontal, 2, 4, 2, 8);
        assert_eq!((w, h), (2, 4));
        // Columns 2–3 average 0.25, columns 4–5 average 0.45.
        assert_eq!(px[0], (0.25f64 * 255.0).round() as u8);
        assert_eq!(px[1], (0.45f64 * 255.0).round() as u8);
        let (w, h, _) = stretch_picture(&image, Axis::Vertical, 1, 2, 10, 3);
        assert_eq!((w, h), (3, 2));
        assert_eq!(pixel_of(Axis::Vertical, 5.0, 2.0), (2.0, 5.0));
        assert_eq!(pixel_of(Axis::Horizontal, 5.0, 2.0), (5.0, 2.0));
    }

    #[test]
    fn the_generated_demo_still_brings_its_settings() {
        let dir = crate::still::demo::demo_still_dir();
        let (setup, groove, source) = setup_for(&dir.join("still.png"), 86_000, 72);
        assert_eq!(setup.axis, Axis::Horizontal);
        assert!((setup.um_per_px - 6.0).abs() < 1e-9);
        assert!(groove.is_some());
        assert!(matches!(source, SetupSource::Sidecar(_)));
        let (setup, groove, source) = setup_for(Path::new("/nowhere/x.png"), 1000, 4000);
        assert_eq!(setup.axis, Axis::Vertical);
        assert_eq!((groove, source), (None, SetupSource::Guessed));
    }
}
