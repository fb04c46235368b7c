//! The accuracy suite: renders ground-truth scans and depth scenes, reconstructs them with the engine and reports the scores as markdown.
//!
//! Every figure in the report is measured here against what the generator knows: the
//! reference sound of a scan (r, envelope r, SNR from [`crate::pipeline::eval`]) or the true
//! depth map of a scene (the paper's Table 2 error bands). Nothing is typed in by hand.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use crate::engine::{ReconstructOptions, reconstruct};
use crate::image::Image;
use crate::io::wav::{Audio, read_wav};
use crate::io::{Scan, write_atomic};
use crate::pipeline::audio_signal::SoundParams;
use crate::pipeline::depth::estimate_depth;
use crate::pipeline::derivatives::compute_derivatives;
use crate::pipeline::eval::Scores;
use crate::pipeline::optical_flow::{FlowMethod, compute_flow};
use crate::pipeline::walls::WallMethod;
use crate::pipeline::{PathChoice, PipelineParams};
use crate::synth::{
    BUILTIN_RATE_HZ, DamageConfig, SceneConfig, SceneKind, SynthConfig, arpeggio, render_scan, tone,
};

/// Sound rendered beyond the last group's span (s): the generator never runs short.
const SOUND_MARGIN_SECS: f64 = 0.01;

/// Output rate the report's sound cases are scored at (the engine's default), Hz.
fn output_rate_hz() -> f64 {
    f64::from(SoundParams::default().output_rate_hz)
}
/// The paper's Table 2 frames (1-based there; here the frame index from 0 of a 40-frame scene).
pub const TABLE2_FRAMES: [usize; 4] = [7, 19, 27, 36];
/// The phrase spoken by `espeak-ng` for the speech cases.
pub const PHRASE: &str = "groove scope";

/// Why the suite could not run.
#[derive(Debug, thiserror::Error)]
pub enum AccuracyError {
    /// The report file exists and overwriting was not asked for.
    #[error("the report already exists (use --force to replace it): {}", .0.display())]
    ReportExists(PathBuf),
    /// A case failed; the message names the case.
    #[error("{case}: {problem}")]
    Case {
        /// Which case.
        case: String,
        /// What went wrong.
        problem: String,
    },
    /// Writing the report or a work folder failed.
    #[error(transparent)]
    Io(#[from] crate::io::LoadError),
}

fn case_err(case: &str, e: impl std::fmt::Display) -> AccuracyError {
    AccuracyError::Case {
        case: case.to_string(),
        problem: e.to_string(),
    }
}

/// The "small camera" of the sound cases: 0.78 µm pixels (about 200×), 320×384 px frames, 7
/// frames a group, a 16⅔ rpm transcription disc at 60 mm (Vt ≈ 105 mm/s, so one group spans
/// about 2.2 ms of sound), with the dual-focus cover glass of paper §9.
#[must_use]
pub fn small_dual_focus(groups: usize) -> SynthConfig {
    SynthConfig {
        width_px: 320,
        height_px: 384,
        pixel_pitch_um: 0.78,
        frame_step_um: 1.56,
        frames_per_group: 7,
        group_overlap_px: 24,
        rpm: 16.667,
        radius_mm: 60.0,
        bit_depth: 8,
        noise_sigma_8bit: 0.5,
        max_groups: Some(groups),
        ..SynthConfig::dual_focus_demo()
    }
}

/// The same camera and disc without the cover glass and depth-of-field blur, with 12 frames a
/// group: the depth path's case (flow → Kalman depth → orientation).
#[must_use]
pub fn small_lateral(groups: usize) -> SynthConfig {
    SynthConfig {
        working_distance_mm: 4.0,
        numerical_aperture: 0.0,
        dual_focus: None,
        frames_per_group: 12,
        groove_top_width_um: 180.0,
        groove_depth_um: 70.0,
        ..small_dual_focus(groups)
    }
}

/// Scratches, dust and missing wall chunks for the damaged-groove cases.
#[must_use]
pub fn heavy_damage() -> DamageConfig {
    DamageConfig {
        scratches_per_mm: 6.0,
        dust_per_mm2: 60.0,
        missing_wall_chunks_per_mm: 2.0,
        chunk_length_um: 150.0,
        chunk_wall_fraction: 0.45,
        ..DamageConfig::default()
    }
}

/// The orientation neighbourhood that spans about two output samples along the groove
/// (odd, at least 5 px): the smallest window that does not low-pass the sound below Nyquist.
#[must_use]
pub fn two_sample_window_px(cfg: &SynthConfig) -> usize {
    let spacing_px = cfg.groove_speed_um_s() / output_rate_hz() / cfg.pixel_pitch_um;
    let n = (2.0 * spacing_px).round().max(5.0) as usize;
    n | 1
}

/// Params of the sound cases: the defaults with the low-pass off (so tones above 3 kHz are
/// measured, not filtered away), the given orientation window and robust switch.
#[must_use]
pub fn sound_params(window_px: usize, robust: bool) -> PipelineParams {
    let mut p = PipelineParams::default();
    p.dsp.lowpass = false;
    p.orientation.neighbourhood_px = window_px;
    p.orientation.robust = robust;
    p
}

/// SNR (dB) that a signal with correlation `r` to its reference would have if the difference
/// were independent noise: 10·log10(r² / (1 − r²)).
#[must_use]
pub fn snr_from_r_db(r: f64) -> f64 {
    let r2 = (r * r).min(1.0 - 1e-12);
    10.0 * (r2 / (1.0 - r2)).log10()
}

/// Renders a scan of `sound` with `cfg` into `dir` (which must not exist or be empty).
///
/// # Errors
/// The generator's error, named by `case`.
pub fn render(
    case: &str,
    sound: &Audio,
    cfg: &SynthConfig,
    dir: &Path,
) -> Result<(), AccuracyError> {
    render_scan(sound, cfg, dir, &|_, _| {}, &AtomicBool::new(false))
        .map(|_| ())
        .map_err(|e| case_err(case, e))
}

/// Seconds of sound that `cfg.max_groups` groups cover (with a margin).
#[must_use]
pub fn scan_secs(cfg: &SynthConfig) -> f64 {
    let groups = cfg.max_groups.unwrap_or(1) as f64;
    groups * cfg.group_span_um() / cfg.groove_speed_um_s() + SOUND_MARGIN_SECS
}

/// Renders a scan of a `freq_hz` tone long enough for `cfg.max_groups` groups into `dir`.
///
/// # Errors
/// As [`render`].
pub fn render_tone(
    case: &str,
    freq_hz: f64,
    cfg: &SynthConfig,
    dir: &Path,
) -> Result<(), AccuracyError> {
    render(
        case,
        &tone(freq_hz, scan_secs(cfg), BUILTIN_RATE_HZ),
        cfg,
        dir,
    )
}

/// Reconstructs the scan in `dir` with `params` and scores it against its `reference.wav`;
/// also returns the wall-clock seconds.
///
/// # Errors
/// The engine's error, named by `case`; a scan without a reference is an error.
pub fn score_scan(
    case: &str,
    dir: &Path,
    params: &PipelineParams,
) -> Result<(Scores, f64), AccuracyError> {
    let scan = Scan::open(dir).map_err(|e| case_err(case, e))?;
    let opts = ReconstructOptions {
        params: params.clone(),
        groups: None,
        keep_going: true,
    };
    let t = Instant::now();
    let rec = reconstruct(&scan, &opts, &mut |_| {}, &AtomicBool::new(false))
        .map_err(|e| case_err(case, e))?;
    let secs = t.elapsed().as_secs_f64();
    let scores = rec
        .scores
        .ok_or_else(|| case_err(case, "the scan has no reference.wav to score against"))?;
    Ok((scores, secs))
}

/// One row of the paper's Table 2: relative depth errors at one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DepthErrors {
    /// Frame index.
    pub frame: usize,
    /// Share (%) of pixels with relative error below 5%.
    pub below_5: f64,
    /// Share (%) with error from 5% to 15%.
    pub from_5_to_15: f64,
    /// Share (%) above 15%.
    pub above_15: f64,
    /// Mean relative error (%).
    pub mean: f64,
    /// Its standard deviation (%).
    pub sigma: f64,
    /// Pixels measured.
    pub pixels: usize,
}

/// Relative errors of `estimate` against `truth` over the pixels where `mask` holds, leaving
/// out a `border` px frame (where the filters read clamped samples) and unmeasured pixels.
#[must_use]
pub fn depth_errors(
    frame: usize,
    estimate: &Image,
    truth: &Image,
    border: usize,
    mask: impl Fn(f32) -> bool,
) -> DepthErrors {
    let (w, h) = (truth.width, truth.height);
    let mut errs = Vec::new();
    for y in border..h.saturating_sub(border) {
        for x in border..w.saturating_sub(border) {
            let (Some(z), Some(t)) = (estimate.get(x, y), truth.get(x, y)) else {
                continue;
            };
            if !(z.is_finite() && t.is_finite() && t > 0.0 && mask(t)) {
                continue;
            }
            errs.push(f64::from((z - t).abs() / t) * 100.0);
        }
    }
    let n = errs.len().max(1) as f64;
    let share = |f: &dyn Fn(f64) -> bool| errs.iter().filter(|&&e| f(e)).count() as f64 / n * 100.0;
    let mean = errs.iter().sum::<f64>() / n;
    let var = errs.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / n;
    DepthErrors {
        frame,
        below_5: share(&|e| e < 5.0),
        from_5_to_15: share(&|e| (5.0..=15.0).contains(&e)),
        above_15: share(&|e| e > 15.0),
        mean,
        sigma: var.sqrt(),
        pixels: errs.len(),
    }
}

/// One frame's Table 2 errors on a scene: on the object's pixels and on every pixel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneDepthRow {
    /// Errors on the object (pixels nearer than the background plane).
    pub object: DepthErrors,
    /// Errors on every pixel, background included.
    pub all: DepthErrors,
}

/// Table 2 on one scene: renders the frames (in memory), runs derivatives, plain Horn–Schunck
/// flow and the Kalman depth stage over the flows up to each frame of `at`, and measures the
/// relative depth error at that frame, on the object and on every pixel.
///
/// # Errors
/// A rendering or stage error, named by the scene.
pub fn scene_depth_table(
    kind: SceneKind,
    cfg: &SceneConfig,
    at: &[usize],
    params: &PipelineParams,
) -> Result<Vec<SceneDepthRow>, AccuracyError> {
    use rayon::prelude::*;
    let case = format!("{kind:?} scene");
    let last = at.iter().copied().max().unwrap_or(0);
    let cfg = SceneConfig {
        frames: (last + 4).max(cfg.frames),
        ..cfg.clone()
    };
    let geom = cfg.geometry();
    let (frames, truths): (Vec<Image>, Vec<Image>) = (0..cfg.frames)
        .into_par_iter()
        .map(|k| crate::synth::scene::render_scene_frame(kind, &cfg, k))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| case_err(&case, e))?
        .into_iter()
        .unzip();
    let derivs = compute_derivatives(&frames, geom.land_flow_px(), &params.derivatives)
        .map_err(|e| case_err(&case, e))?;
    let mut flow_params = params.flow.clone();
    if flow_params.method == FlowMethod::GrooveHornSchunck {
        // The groove constraint describes groove walls; a scene has none.
        flow_params.method = FlowMethod::HornSchunck;
    }
    // In frame order (one flow per derivative window).
    let flows = derivs
        .par_iter()
        .map(|d| compute_flow(d, geom.focal_px, None, &flow_params))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| case_err(&case, e))?;
    let plane = cfg.plane_distance_um as f32;
    let border = 8;
    let mut rows = Vec::with_capacity(at.len());
    for &k in at {
        let upto = flows.iter().take_while(|f| f.frame_index <= k).count();
        if upto == 0 || flows[upto - 1].frame_index != k {
            return Err(case_err(&case, format!("no flow field at frame {k}")));
        }
        let depth =
            estimate_depth(&flows[..upto], &geom, &params.depth).map_err(|e| case_err(&case, e))?;
        let truth = &truths[k];
        rows.push(SceneDepthRow {
            object: depth_errors(k, &depth.z_um, truth, border, |t| t < plane - 0.5),
            all: depth_errors(k, &depth.z_um, truth, border, |_| true),
        });
    }
    Ok(rows)
}

/// Speaks `phrase` with `espeak-ng` into a WAV file in `dir`; `None` when espeak-ng is missing
/// or fails (the report then says the speech cases were skipped).
#[must_use]
pub fn speak(phrase: &str, dir: &Path) -> Option<PathBuf> {
    let path = dir.join("speech.wav");
    let ok = Command::new("espeak-ng")
        .args(["-s", "160", "-w"])
        .arg(&path)
        .arg(phrase)
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    (ok && path.is_file()).then_some(path)
}

/// First time (s) the sound rises above 2% of its peak (skips leading silence).
fn onset_secs(audio: &Audio) -> f64 {
    let Some(ch) = audio.channels.first() else {
        return 0.0;
    };
    let peak = ch.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    let first = ch.iter().position(|v| v.abs() > 0.02 * peak).unwrap_or(0);
    first as f64 / f64::from(audio.sample_rate_hz)
}

/// Settings of a suite run.
#[derive(Clone, Debug, Default)]
pub struct AccuracyOptions {
    /// Fewer, shorter cases (about a minute): tones 500 Hz–5 kHz, 0.1 s of speech, no melody.
    pub quick: bool,
    /// Keep the rendered scans in this folder (must not exist or be empty) instead of a
    /// temporary one.
    pub keep: Option<PathBuf>,
}

struct Report {
    md: String,
}

impl Report {
    fn line(&mut self, s: &str) {
        self.md.push_str(s);
        self.md.push('\n');
    }
}

/// r, SNR and SNR(r), for steady tones (whose envelope is flat, so envelope r says nothing).
fn tone_cells(s: &Scores) -> String {
    format!("{:.3} | {:.1} | {:.1}", s.r, s.snr_db, snr_from_r_db(s.r))
}

fn score_cells(s: &Scores) -> String {
    format!(
        "{:.3} | {} | {:.1} | {:.1}",
        s.r,
        s.envelope_r_text(3),
        s.snr_db,
        snr_from_r_db(s.r)
    )
}

/// Runs the whole suite and returns the markdown report. `log` receives one line per finished
/// case.
///
/// # Errors
/// [`AccuracyError`] naming the case that failed.
pub fn run_suite(
    opts: &AccuracyOptions,
    log: &mut dyn FnMut(&str),
) -> Result<String, AccuracyError> {
    let started = Instant::now();
    let tmp;
    let work: PathBuf = match &opts.keep {
        Some(dir) => {
            let empty = crate::io::atomic::dir_is_missing_or_empty(dir)?;
            if !empty {
                return Err(case_err(
                    "--keep",
                    format!("the folder is not empty: {}", dir.display()),
                ));
            }
            std::fs::create_dir_all(dir)
                .map_err(|e| case_err("--keep", format!("{e}: {}", dir.display())))?;
            dir.clone()
        }
        None => {
            tmp = tempfile::tempdir().map_err(|e| case_err("work folder", e))?;
            tmp.path().to_path_buf()
        }
    };
    let mut rep = Report { md: String::new() };
    let threads = rayon::current_num_threads();
    rep.line("# groovescope accuracy report");
    rep.line("");
    rep.line(&format!(
        "Made by `groovescope accuracy{}` (groovescope {}, {} threads). Every figure is measured \
         against the generator's ground truth: the reference sound of a rendered scan or the \
         true depth map of a rendered scene. r: Pearson r of the waveforms at the best lag \
         (±0.3 ms); env r: r of the peak envelopes; SNR: 10·log10(Σref²/Σ(ref − g·rec)²) after \
         the best gain (a DC offset counts as noise); SNR(r): the SNR that r alone implies, \
         10·log10(r²/(1 − r²)). Steady tones have flat envelopes, so their tables leave \
         envelope r out.",
        if opts.quick { " --quick" } else { "" },
        env!("CARGO_PKG_VERSION"),
        threads
    ));
    rep.line("");

    // --- Tones, dual-focus path.
    let small = small_dual_focus(1);
    let w2 = two_sample_window_px(&small);
    let tone_groups = if opts.quick { 8 } else { 16 };
    let freqs: &[f64] = if opts.quick {
        &[500.0, 1000.0, 2000.0, 5000.0]
    } else {
        &[200.0, 500.0, 1000.0, 2000.0, 5000.0, 10_000.0, 20_000.0]
    };
    rep.line("## Sinusoids, dual-focus path");
    rep.line("");
    rep.line(&format!(
        "The small camera (`accuracy::small_dual_focus`): 320×384 px frames of 0.78 µm, 7 frames \
         a group, a 16⅔ rpm disc at 60 mm (Vt ≈ {:.0} mm/s, one 44.1 kHz output sample every \
         {:.1} px), cover glass 0.11 mm n = 1.515, NA 0.45, 20 mm/s peak velocity, {} groups \
         (≈ {:.0} ms of sound) per tone. Low-pass off, except in the last three columns, which \
         add the default 2nd-order Butterworth low-pass at 3 kHz (it attenuates the 5 kHz and \
         higher tones themselves; r ignores gain). Orientation window: the default 100 px, and \
         {} px (about two output samples).",
        small.groove_speed_um_s() / 1000.0,
        small.groove_speed_um_s() / output_rate_hz() / small.pixel_pitch_um,
        tone_groups,
        tone_groups as f64 * small.group_step_um() / small.groove_speed_um_s() * 1000.0,
        w2
    ));
    rep.line("");
    rep.line(&format!(
        "| tone | r (100 px) | SNR dB | SNR(r) dB | r ({w2} px) | SNR dB | SNR(r) dB | r ({w2} px, 3 kHz LP) | SNR dB | SNR(r) dB |"
    ));
    rep.line("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for &f in freqs {
        let case = format!("{f} Hz tone (dual focus)");
        let dir = work.join(format!("tone_df_{f}"));
        render_tone(&case, f, &small_dual_focus(tone_groups), &dir)?;
        let (a, _) = score_scan(&case, &dir, &sound_params(100, true))?;
        let (b, _) = score_scan(&case, &dir, &sound_params(w2, true))?;
        let mut lp = sound_params(w2, true);
        lp.dsp.lowpass = true;
        let (c, _) = score_scan(&case, &dir, &lp)?;
        rep.line(&format!(
            "| {f} Hz | {} | {} | {} |",
            tone_cells(&a),
            tone_cells(&b),
            tone_cells(&c)
        ));
        log(&format!(
            "{case}: r {:.3} / {:.3} / {:.3}, SNR {:.1} / {:.1} / {:.1} dB",
            a.r, b.r, c.r, a.snr_db, b.snr_db, c.snr_db
        ));
    }
    rep.line("");

    // --- Tones, depth path.
    let lat = small_lateral(1);
    let wl = two_sample_window_px(&lat);
    let depth_groups = if opts.quick { 4 } else { 12 };
    let depth_freqs: &[f64] = if opts.quick {
        &[1000.0]
    } else {
        &[200.0, 500.0, 1000.0, 2000.0, 5000.0]
    };
    rep.line("## Sinusoids, depth path (no cover glass: flow → Kalman depth → orientation)");
    rep.line("");
    rep.line(&format!(
        "The same camera and disc (`accuracy::small_lateral`), everything in focus, 12 frames a \
         group, a 180 µm wide 70 µm deep groove, {depth_groups} groups per tone. Walls found by \
         depth levels (the default), with the orientation window at the default 100 px, at \
         {wl} px, and at {wl} px with the 3 kHz low-pass; the last columns find the walls by \
         slope runs (the method before 29 Nov 2026) at {wl} px, low-pass off."
    ));
    rep.line("");
    rep.line(&format!(
        "| tone | r (100 px) | SNR dB | SNR(r) dB | r ({wl} px) | SNR dB | SNR(r) dB | r ({wl} px, 3 kHz LP) | SNR dB | SNR(r) dB | r (slope runs, {wl} px) | SNR dB | SNR(r) dB |"
    ));
    rep.line("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for &f in depth_freqs {
        let case = format!("{f} Hz tone (depth path)");
        let dir = work.join(format!("tone_depth_{f}"));
        render_tone(&case, f, &small_lateral(depth_groups), &dir)?;
        let depth_params = |window: usize, lowpass: bool, walls: WallMethod| {
            let mut p = sound_params(window, true);
            p.path = PathChoice::Depth;
            p.dsp.lowpass = lowpass;
            p.walls.method = walls;
            p
        };
        let mut cells = Vec::new();
        for (window, lowpass, walls) in [
            (100, false, WallMethod::DepthLevels),
            (wl, false, WallMethod::DepthLevels),
            (wl, true, WallMethod::DepthLevels),
            (wl, false, WallMethod::SlopeRuns),
        ] {
            let (s, _) = score_scan(&case, &dir, &depth_params(window, lowpass, walls))?;
            cells.push(s);
        }
        rep.line(&format!(
            "| {f} Hz | {} |",
            cells.iter().map(tone_cells).collect::<Vec<_>>().join(" | ")
        ));
        log(&format!(
            "{case}: r {}",
            cells
                .iter()
                .map(|s| format!("{:.3}", s.r))
                .collect::<Vec<_>>()
                .join(" / ")
        ));
    }
    rep.line("");

    // --- Speech, clean and damaged.
    let speech_groups = if opts.quick { 45 } else { 228 };
    rep.line("## Speech (espeak-ng), clean and damaged");
    rep.line("");
    match speak(PHRASE, &work).and_then(|wav| read_wav(&wav).ok()) {
        None => {
            rep.line("Skipped: `espeak-ng` is not installed or failed.");
            log("speech: skipped (espeak-ng missing)");
        }
        Some(speech) => {
            let onset = onset_secs(&speech);
            let clean = SynthConfig {
                start_secs: onset,
                ..small_dual_focus(speech_groups)
            };
            let damaged = SynthConfig {
                damage: heavy_damage(),
                ..clean.clone()
            };
            let dur = speech_groups as f64 * clean.group_step_um() / clean.groove_speed_um_s();
            rep.line(&format!(
                "`espeak-ng -s 160 \"{PHRASE}\"`, from its onset ({onset:.3} s), {speech_groups} \
                 groups (≈ {dur:.2} s) on the small dual-focus camera. The damaged groove adds \
                 {} scratches/mm, {} dust particles/mm² and {} missing wall chunks/mm (150 µm \
                 long, 45% of the wall). Robust: the Lorentzian M-estimator; LS: plain least \
                 squares.",
                heavy_damage().scratches_per_mm,
                heavy_damage().dust_per_mm2,
                heavy_damage().missing_wall_chunks_per_mm
            ));
            rep.line("");
            rep.line("| groove | fit | window | r | env r | SNR dB | SNR(r) dB |");
            rep.line("|---|---|---:|---:|---:|---:|---:|");
            for (name, cfg) in [("clean", &clean), ("damaged", &damaged)] {
                let case = format!("speech ({name})");
                let dir = work.join(format!("speech_{name}"));
                render(&case, &speech, cfg, &dir)?;
                let fits: &[bool] = if name == "clean" {
                    &[true]
                } else {
                    &[true, false]
                };
                for &robust in fits {
                    for window in [100, w2] {
                        let (s, _) = score_scan(&case, &dir, &sound_params(window, robust))?;
                        let fit = if robust { "robust" } else { "LS" };
                        rep.line(&format!(
                            "| {name} | {fit} | {window} px | {} |",
                            score_cells(&s)
                        ));
                        log(&format!(
                            "{case}, {fit}, {window} px: r {:.3}, env r {}, SNR {:.1} dB",
                            s.r,
                            s.envelope_r_text(3),
                            s.snr_db
                        ));
                    }
                }
            }
        }
    }
    rep.line("");

    // --- Melody.
    if !opts.quick {
        let case = "melody";
        let note = 0.03;
        let sound = arpeggio(note, BUILTIN_RATE_HZ);
        let groups = (4.0 * note * small.groove_speed_um_s() / small.group_step_um()) as usize;
        let dir = work.join("melody");
        render(case, &sound, &small_dual_focus(groups.max(1)), &dir)?;
        let (s, _) = score_scan(case, &dir, &sound_params(w2, true))?;
        rep.line("## Melody");
        rep.line("");
        rep.line(&format!(
            "C5 E5 G5 C6, {:.0} ms each, {} groups on the small dual-focus camera, window {w2} px.",
            note * 1000.0,
            groups
        ));
        rep.line("");
        rep.line("| sound | r | env r | SNR dB | SNR(r) dB |");
        rep.line("|---|---:|---:|---:|---:|");
        rep.line(&format!("| melody | {} |", score_cells(&s)));
        rep.line("");
        log(&format!("melody: r {:.3}, SNR {:.1} dB", s.r, s.snr_db));
    }

    // --- Paper Fig. 20: half a wall missing.
    {
        let case = "Fig. 20 scan";
        let groups = if opts.quick { 4 } else { 6 };
        let cfg = SynthConfig {
            max_groups: Some(groups),
            ..SynthConfig::dual_focus_fig20()
        };
        let dir = work.join("fig20");
        render_tone(case, 1000.0, &cfg, &dir)?;
        let robust = score_scan(case, &dir, &sound_params(100, true))?.0;
        let ls = score_scan(case, &dir, &sound_params(100, false))?.0;
        rep.line("## Paper Fig. 20: nearly half of a wall missing");
        rep.line("");
        rep.line(&format!(
            "`SynthConfig::dual_focus_fig20()`: the paper's optics (1280×1024 px of 0.39 µm, 12 \
             frames of 0.78 µm, 78 rpm at 115 mm), the upper 45% of the right wall missing from \
             300 to 1300 µm, a 1 kHz tone, {groups} groups, window 100 px."
        ));
        rep.line("");
        rep.line("| fit | r | SNR dB | SNR(r) dB |");
        rep.line("|---|---:|---:|---:|");
        rep.line(&format!("| robust | {} |", tone_cells(&robust)));
        rep.line(&format!("| least squares | {} |", tone_cells(&ls)));
        rep.line("");
        rep.line(&format!(
            "The robust fit gains Δr = {:+.3} over plain least squares.",
            robust.r - ls.r
        ));
        rep.line("");
        log(&format!(
            "Fig. 20: robust r {:.3}, LS r {:.3}",
            robust.r, ls.r
        ));
    }

    // --- Table 2 depth scenes.
    rep.line("## Depth scenes (paper §5.2, Table 2)");
    rep.line("");
    let scene = SceneConfig::default();
    rep.line(&format!(
        "`groovescope synth-scene` scenes: {}×{} px, focal length {} px, the background plane at \
         {} µm, the object's centre at {} µm, {} µm objects, the camera moving {} µm per frame; \
         derivatives, plain Horn–Schunck and the Kalman depth stage with default params. \
         Relative depth error |Z − Z_true|/Z_true on the object's pixels (an 8 px border left \
         out); the last column is the mean over every pixel, background included. The paper's \
         Kalman filter reached a mean error of about 7–9% at frame 27.",
        scene.width_px,
        scene.height_px,
        scene.focal_px,
        scene.plane_distance_um,
        scene.object_distance_um,
        scene.object_size_um,
        scene.frame_step_um
    ));
    rep.line("");
    rep.line("| scene | frame | < 5% | 5–15% | > 15% | mean ± σ (%) | all pixels mean (%) |");
    rep.line("|---|---:|---:|---:|---:|---:|---:|");
    let params = PipelineParams::default();
    let kinds: &[SceneKind] = if opts.quick {
        &[SceneKind::Sphere]
    } else {
        &[SceneKind::Cube, SceneKind::Cylinder, SceneKind::Sphere]
    };
    for &kind in kinds {
        let rows = scene_depth_table(kind, &scene, &TABLE2_FRAMES, &params)?;
        for SceneDepthRow { object: o, all: a } in &rows {
            rep.line(&format!(
                "| {kind:?} | {} | {:.1} | {:.1} | {:.1} | {:.2} ± {:.2} | {:.2} |",
                o.frame, o.below_5, o.from_5_to_15, o.above_15, o.mean, o.sigma, a.mean
            ));
        }
        if let Some(row) = rows.iter().find(|r| r.object.frame == 27) {
            log(&format!(
                "{kind:?}: frame 27 mean error {:.2}%",
                row.object.mean
            ));
        }
    }
    rep.line("");
    let _ = writeln!(
        rep.md,
        "Suite time: {:.0} s.",
        started.elapsed().as_secs_f64()
    );
    Ok(rep.md)
}

/// Runs the suite and writes the report to `out` atomically; refuses an existing file unless
/// `force`. The check comes first, so nothing runs for a refused report.
///
/// # Errors
/// [`AccuracyError::ReportExists`], or the suite's or the write's error.
pub fn write_report(
    out: &Path,
    force: bool,
    opts: &AccuracyOptions,
    log: &mut dyn FnMut(&str),
) -> Result<(), AccuracyError> {
    if out.exists() && !force {
        return Err(AccuracyError::ReportExists(out.to_path_buf()));
    }
    let md = run_suite(opts, log)?;
    write_atomic(out, md.as_bytes(), force)?;
    Ok(())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;

    #[test]
    fn depth_errors_bands_and_mean() {
        let truth = Image::filled(20, 20, 100.0);
        let mut est = Image::filled(20, 20, 100.0);
        // 3 of the 16 interior (border 2) pixels at 10% error, 1 at 20%, 1 NaN (skipped).
        est.data[2 * 20 + 2] = 110.0;
        est.data[2 * 20 + 3] = 90.0;
        est.data[2 * 20 + 4] = 110.0;
        est.data[3 * 20 + 2] = 120.0;
        est.data[3 * 20 + 3] = f32::NAN;
        let e = depth_errors(0, &est, &truth, 2, |_| true);
        assert_eq!(e.pixels, 16 * 16 - 1);
        let n = e.pixels as f64;
        assert!((e.from_5_to_15 - 300.0 / n).abs() < 1e-9);
        assert!((e.above_15 - 100.0 / n).abs() < 1e-9);
        assert!((e.mean - 50.0 / n).abs() < 1e-6, "{}", e.mean);
        // A mask that keeps nothing measures nothing.
        assert_eq!(depth_errors(0, &est, &truth, 2, |_| false).pixels, 0);
    }

    #[test]
    fn snr_from_r_and_window() {
        assert!(snr_from_r_db(0.0) < -100.0);
        assert!((snr_from_r_db((0.5f64).sqrt())).abs() < 1e-9);
        assert!((snr_from_r_db(0.995) - 19.98).abs() < 0.05);
        let w = two_sample_window_px(&small_dual_focus(1));
        assert_eq!(w % 2, 1);
        assert!((5..=9).contains(&w), "{w}");
        // The paper's optics: ≈ 21 µm per output sample at 0.39 µm/px → ≈ 109 px.
        let paper = two_sample_window_px(&SynthConfig::default());
        assert!((101..=121).contains(&paper), "{paper}");
    }
}
