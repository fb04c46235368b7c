//! The `synth-still` and `still` subcommands: generate a top-view still with its truth, and
//! decode a still image of a record into a WAV file.

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};

use crate::io::Cut;
use crate::pipeline::still::Axis;
use crate::synth::still::{StillConfig, StillScene, write_still};

/// Arguments of `synth-still`.
#[derive(Debug, clap::Args)]
pub struct SynthStillArgs {
    /// Sound to cut into every groove (WAV; the middle groove from `start_secs`, each turn further
    /// in one revolution later); without it, or --melody, each wall gets a built-in tone.
    pub sound: Option<PathBuf>,
    /// Output folder (must not exist or be empty): still.png|tif, grooveN.wav, truth.toml.
    #[arg(long)]
    pub out: PathBuf,
    /// Still settings TOML: a `[still]` table, or its keys at the top level (missing keys
    /// take the preset's values; a key outside `[still]` beside it is refused).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Starting settings: test (1000×4000 px, 7 grooves) or demo (the bundled 80 000 px strip).
    #[arg(long, value_parser = ["test", "demo"], default_value = "test")]
    pub preset: String,
    /// Grooves run down (vertical) or across (horizontal) the image (overrides the config).
    #[arg(long, value_parser = ["vertical", "horizontal"])]
    pub axis: Option<String>,
    /// lateral or stereo (overrides the config).
    #[arg(long, value_parser = ["lateral", "stereo"])]
    pub cut: Option<String>,
    /// The built-in melody (C5 E5 G5 C6) in every groove instead of tones.
    #[arg(long, conflicts_with = "sound")]
    pub melody: bool,
    /// Duration of the melody (s).
    #[arg(long, default_value_t = 1.0)]
    pub duration: f64,
    /// Seed of texture, levels, rims, dust and noise (overrides the config).
    #[arg(long)]
    pub seed: Option<u32>,
    /// No summary line.
    #[arg(long)]
    pub quiet: bool,
}

/// Runs `synth-still`.
///
/// # Errors
/// Invalid settings, an unusable sound, an output folder that is not empty, write failures.
pub fn run_synth_still(args: &SynthStillArgs) -> Result<()> {
    crate::cli::check_parent_exists(&args.out)?;
    let base = if args.preset == "demo" {
        StillConfig::demo()
    } else {
        StillConfig::default()
    };
    let mut cfg = match &args.config {
        Some(p) => {
            crate::cli::overlay_toml(&base, p, "still", "still settings", StillConfig::validate)?
        }
        None => base,
    };
    if let Some(axis) = args.axis.as_deref().and_then(Axis::from_name) {
        cfg.axis = axis;
    }
    match args.cut.as_deref() {
        Some("lateral") => cfg.cut = Cut::Lateral,
        Some("stereo") => cfg.cut = Cut::Stereo,
        _ => {}
    }
    if let Some(seed) = args.seed {
        cfg.seed = seed;
    }
    crate::cli::check_duration(args.duration)?;
    let sound = if args.melody {
        Some(crate::synth::arpeggio(
            args.duration / 4.0,
            crate::synth::BUILTIN_RATE_HZ,
        ))
    } else if let Some(p) = &args.sound {
        Some(crate::io::wav::read_wav(p)?)
    } else {
        None
    };
    let scene = StillScene::new(&cfg, sound.as_ref()).map_err(|e| match (&args.sound, e) {
        (Some(p), crate::synth::SynthError::Sound { problem }) => {
            anyhow::anyhow!("unusable sound: {problem}: {}", p.display())
        }
        (_, e) => e.into(),
    })?;
    for line in crate::synth::earlier_unfinished_runs(&args.out) {
        crate::tell!("{line}");
    }
    let summary = write_still(&scene, &args.out)?;
    if !args.quiet {
        let t = &summary.truth;
        crate::say!(
            "wrote {} ({} × {} px, {} grooves, {:?} axis); decode groove N with: groovescope still {} \
             --um-per-px {} --rpm {:.4} --radius-mm <grooves[N].radius_mm in truth.toml> --axis {} --groove N",
            summary.image.display(),
            t.width_px,
            t.height_px,
            t.grooves.len(),
            t.axis,
            crate::stdout::shell_quoted(&summary.image),
            t.um_per_px,
            t.rpm,
            t.axis.name()
        )?;
    }
    Ok(())
}

/// Arguments of `still`.
#[derive(Debug, clap::Args)]
pub struct StillArgs {
    /// The still: a PNG or TIFF (8/16 bit, grey or colour) of grooves seen from above.
    pub image: PathBuf,
    /// Pixel size on the record, µm.
    #[arg(long, allow_negative_numbers = true)]
    pub um_per_px: f64,
    /// Turntable speed the disc was cut at.
    #[arg(long, allow_negative_numbers = true)]
    pub rpm: f64,
    /// Radius of the groove decoded, mm.
    #[arg(long, allow_negative_numbers = true)]
    pub radius_mm: f64,
    /// Grooves run down the image (vertical: time runs down) or across it (horizontal:
    /// time runs rightward).
    #[arg(long, value_parser = ["vertical", "horizontal"], default_value = "vertical")]
    pub axis: String,
    /// lateral (mono) or stereo (45/45: two channels, the left wall first).
    #[arg(long, value_parser = ["lateral", "stereo"], default_value = "lateral")]
    pub cut: String,
    /// Groove to decode, from 1 at the image's left (vertical) or top (horizontal); default:
    /// the most complete groove nearest the centre.
    #[arg(long)]
    pub groove: Option<usize>,
    /// Time runs up (vertical) or leftward (horizontal) instead.
    #[arg(long)]
    pub reverse: bool,
    /// Output WAV file.
    #[arg(long)]
    pub out: PathBuf,
    /// JSON report (grooves found, borders, gaps, scores, timings).
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// A reference WAV of the groove's sound to score against (r, envelope r, SNR).
    #[arg(long)]
    pub reference: Option<PathBuf>,
    /// Parameters TOML (see `groovescope params`: the `[still]`, `[sound]` and `[dsp]` tables apply).
    #[arg(long)]
    pub params: Option<PathBuf>,
    /// WAV sample format: 16, 24 or 32f.
    #[arg(long, default_value = "24")]
    pub bits: crate::io::wav::WavBits,
    /// Replace existing output files.
    #[arg(long)]
    pub force: bool,
    /// No summary on stdout (warnings still go to stderr).
    #[arg(long)]
    pub quiet: bool,
}

/// One groove in the report.
#[derive(Debug, serde::Serialize)]
struct GrooveLine {
    number: usize,
    coverage: f64,
    position_px: f64,
    width_px: f64,
}

/// One border in the report.
#[derive(Debug, serde::Serialize)]
struct BorderLine {
    border: &'static str,
    lines_fitted: usize,
    screened_out: usize,
    rejected_outliers: usize,
}

/// One bridged gap in the report.
#[derive(Debug, serde::Serialize)]
struct GapLine {
    channel: usize,
    start_line: usize,
    lines: usize,
    start_ms: f64,
    duration_ms: f64,
}

/// The JSON report of `still`.
#[derive(Debug, serde::Serialize)]
struct StillReport<'a> {
    version: &'static str,
    /// "ok" (a failed run's report says "failed": [`StillFailureReport`]).
    status: &'static str,
    image: String,
    output: String,
    params_file: Option<String>,
    /// The filters the sound went through, in order and in words (phase included).
    filters: String,
    image_width_px: usize,
    image_height_px: usize,
    axis: &'static str,
    cut: &'static str,
    reverse: bool,
    um_per_px: f64,
    rpm: f64,
    radius_mm: f64,
    groove_speed_mm_s: f64,
    grooves_found: Vec<GrooveLine>,
    bottoms_visible: bool,
    groove: usize,
    groove_chosen_automatically: bool,
    left_wall: &'static str,
    native_rate_hz: f64,
    sample_rate_hz: u32,
    channels: usize,
    duration_secs: f64,
    gain_per_mm_s: f64,
    borders: Vec<BorderLine>,
    gaps: Vec<GapLine>,
    reference: Option<String>,
    scores: Option<Vec<Option<crate::pipeline::eval::Scores>>>,
    timings: super::StillTimings,
    params: &'a crate::pipeline::PipelineParams,
    warnings: &'a [String],
}

/// The still decode's progress bar: its phase and the share of it done (hidden with `quiet`,
/// and where standard error is not a terminal).
fn still_progress(quiet: bool) -> indicatif::ProgressBar {
    if quiet {
        return indicatif::ProgressBar::hidden();
    }
    let pb = indicatif::ProgressBar::new(1000);
    if let Ok(style) =
        indicatif::ProgressStyle::with_template("{spinner} [{elapsed_precise}] {bar:40} {msg}")
    {
        pb.set_style(style);
    }
    pb
}

/// Runs `still`.
///
/// # Errors
/// Any failure as one line naming the file. With `--report`, a failure after the outputs were
/// checked (bad params, an image without grooves, a groove lost, a WAV that cannot be written)
/// is also recorded there (`"status": "failed"` and the error line), for a batch to read why;
/// a Ctrl-C writes nothing.
pub fn run_still(args: &StillArgs) -> Result<()> {
    let outputs: Vec<&Path> = std::iter::once(args.out.as_path())
        .chain(args.report.as_deref())
        .collect();
    let inputs: Vec<&Path> = std::iter::once(args.image.as_path())
        .chain(args.reference.as_deref())
        .chain(args.params.as_deref())
        .collect();
    crate::cli::check_outputs(&outputs, &inputs, args.force)?;
    // One writer an output, taken before the decode: a folder it cannot write in is said now.
    let _locks = crate::side::cli::lock_outputs(&outputs)?;
    let done = match decode_and_write_wav(args) {
        Ok(done) => done,
        Err(e) => return Err(record_failure(args, e)),
    };
    let Decoded {
        run,
        setup,
        params,
        scores,
    } = done;
    if let Some(path) = &args.report {
        let what = ReportInputs {
            image: &args.image,
            out: &args.out,
            params_file: args.params.as_deref(),
            reference: args.reference.as_deref(),
            scores: scores.clone(),
            chosen_automatically: args.groove.is_none(),
        };
        crate::cli::undo_first_on_error(
            &args.out,
            write_still_report(path, &run, &setup, &params, &what, args.force),
        )?;
    }
    let a = &run.analysis;
    let groove = &a.grooves.grooves[a.chosen];
    crate::cli::print_warnings(&run.warnings);
    if let (Some(path), Some(all)) = (&args.reference, &scores)
        && all.iter().any(Option::is_none)
    {
        crate::tell!(
            "warning: too few samples overlap the sound to score against the reference: {}",
            path.display()
        );
    }
    if !args.quiet {
        let details = format!(
            "{}, groove {} of {} found, {:.1} s",
            run.audio.channels_label(),
            groove.number,
            a.grooves.grooves.len(),
            run.timings.total_secs
        );
        crate::say!(
            "{}",
            crate::cli::wrote_sound(&args.out, &run.audio, &details)
        )?;
        for (c, s) in scores.iter().flatten().enumerate() {
            if let Some(s) = s {
                let channel = if run.audio.channels.len() > 1 {
                    format!(" (channel {c})")
                } else {
                    String::new()
                };
                crate::say!("vs reference{channel}: {}", s.line())?;
            }
        }
    }
    Ok(())
}

/// A still decoded and its WAV written: what the report and the summary need.
struct Decoded {
    run: super::StillRun,
    setup: crate::pipeline::still::StillSetup,
    params: crate::pipeline::PipelineParams,
    scores: Option<Vec<Option<crate::pipeline::eval::Scores>>>,
}

/// `still`'s work once its outputs are checked and locked: the params, the reference and the
/// settings read and checked, the still decoded and scored, its WAV written.
fn decode_and_write_wav(args: &StillArgs) -> Result<Decoded> {
    let params = crate::cli::load_params(args.params.as_deref())?;
    // The reference is read first, so that a bad one is said before the decode, not after.
    let reference = args
        .reference
        .as_deref()
        .map(|r| crate::io::wav::read_reference_wav(r).map(|a| (a, r)))
        .transpose()?;
    // clap allows only the axes' names.
    let axis = Axis::from_name(&args.axis).unwrap_or_default();
    let cut = if args.cut == "stereo" {
        Cut::Stereo
    } else {
        Cut::Lateral
    };
    let setup = crate::pipeline::still::StillSetup {
        axis,
        um_per_px: args.um_per_px,
        rpm: args.rpm,
        radius_mm: args.radius_mm,
        cut,
        reverse: args.reverse,
    };
    setup.validate().map_err(|e| match e {
        // The settings came from flags: name them as typed.
        crate::pipeline::StageError::InvalidParam { name, problem } => {
            let flags = name
                .replace("um_per_px", "--um-per-px")
                .replace("radius_mm", "--radius-mm")
                .replace("rpm", "--rpm");
            anyhow::anyhow!("invalid {flags}: {problem}: {}", args.image.display())
        }
        e => anyhow::anyhow!("{e}: {}", args.image.display()),
    })?;
    if args.groove == Some(0) {
        bail!(
            "--groove counts from 1 (the image's left or top groove): {}",
            args.image.display()
        );
    }
    let pb = still_progress(args.quiet);
    let run = super::decode_still_file_reporting(
        &args.image,
        &setup,
        args.groove,
        &params,
        &mut |phase, done| {
            pb.set_message(phase.describe());
            pb.set_position((done.clamp(0.0, 1.0) * 1000.0) as u64);
        },
    );
    pb.finish_and_clear();
    // A Ctrl-C after the decode's last check (the border fits and the finish run without one)
    // still stops it here, before anything is written, and the locks are let go.
    let run = crate::cli::unless_interrupted("still", run)?;
    let scores = reference
        .as_ref()
        .map(|(refa, path)| super::score_still_against(&run.audio, refa, path))
        .transpose()?;
    let info = still_transfer_info(&args.image, &run, &setup, &params, args.bits);
    crate::io::wav::write_transfer_wav(&args.out, &run.audio, args.bits, args.force, &info)?;
    Ok(Decoded {
        run,
        setup,
        params,
        scores,
    })
}

/// The JSON report of a `still` that failed (`status` "failed"): the one-line error and what
/// the run was asked to do. No WAV was written.
#[derive(Debug, serde::Serialize)]
struct StillFailureReport<'a> {
    /// groovescope version.
    version: &'static str,
    /// Always "failed" (a decoded still's report says "ok").
    status: &'static str,
    /// The line the command printed (without `error: `).
    error: String,
    /// The still.
    image: String,
    /// The WAV asked for, not written.
    output: String,
    /// Always false.
    output_written: bool,
    /// The params file given, if any.
    params_file: Option<String>,
    /// The reference given, if any.
    reference: Option<String>,
    /// The settings given (`--axis`, `--cut`, `--reverse`, `--um-per-px`, `--rpm`,
    /// `--radius-mm`, `--groove`; an unusable number is null).
    axis: &'a str,
    /// `--cut`.
    cut: &'a str,
    /// `--reverse`.
    reverse: bool,
    /// `--um-per-px`.
    um_per_px: f64,
    /// `--rpm`.
    rpm: f64,
    /// `--radius-mm`.
    radius_mm: f64,
    /// `--groove` (None: the decoder was to choose).
    groove: Option<usize>,
}

/// `e`, after recording it in the `--report` file when one was asked for and the run was not
/// stopped by Ctrl-C (which writes nothing); a report that cannot be written is said on the
/// same line.
fn record_failure(args: &StillArgs, e: anyhow::Error) -> anyhow::Error {
    let stopped = crate::job::interrupted().load(std::sync::atomic::Ordering::Relaxed);
    let Some(path) = args.report.as_deref().filter(|_| !stopped) else {
        return e;
    };
    let report = StillFailureReport {
        version: env!("CARGO_PKG_VERSION"),
        status: "failed",
        error: format!("{e:#}"),
        image: args.image.display().to_string(),
        output: args.out.display().to_string(),
        output_written: false,
        params_file: args.params.as_ref().map(|p| p.display().to_string()),
        reference: args.reference.as_ref().map(|p| p.display().to_string()),
        axis: &args.axis,
        cut: &args.cut,
        reverse: args.reverse,
        um_per_px: args.um_per_px,
        rpm: args.rpm,
        radius_mm: args.radius_mm,
        groove: args.groove,
    };
    match crate::io::write_json_atomic(path, &report, args.force) {
        Ok(()) => e,
        Err(w) => anyhow::anyhow!("{e:#}; the report of the failure was not written either: {w}"),
    }
}

/// What a still report says beyond the decode itself.
#[derive(Clone, Debug)]
pub struct ReportInputs<'a> {
    /// The still decoded.
    pub image: &'a Path,
    /// The WAV written.
    pub out: &'a Path,
    /// The params file, if one was given.
    pub params_file: Option<&'a Path>,
    /// The reference scored against, if any.
    pub reference: Option<&'a Path>,
    /// Its scores per channel.
    pub scores: Option<Vec<Option<crate::pipeline::eval::Scores>>>,
    /// The groove was chosen by the decoder, not asked for.
    pub chosen_automatically: bool,
}

/// The `bext` chunk of a still's WAV ([`crate::io::bwf`]): the disc and the groove of the
/// image, the still decoder and its filters in words, and as reference fingerprints of the
/// image (its name and size, and the groove) and of the params.
#[must_use]
pub fn still_transfer_info(
    image: &Path,
    run: &super::StillRun,
    setup: &crate::pipeline::still::StillSetup,
    params: &crate::pipeline::PipelineParams,
    bits: crate::io::wav::WavBits,
) -> crate::io::bwf::BroadcastInfo {
    let name = image.file_name().map_or_else(
        || image.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    );
    let groove = run.analysis.chosen + 1;
    let cut = if setup.cut == Cut::Stereo {
        "45/45 stereo"
    } else {
        "lateral-cut"
    };
    // The image's name last: a long one is what the description's 256 characters cut.
    let source = format!(
        "{cut} disc at {} rpm in groove {groove} of a still image at {} um a pixel: {name}",
        crate::io::bwf::short_number(setup.rpm),
        crate::io::bwf::short_number(setup.um_per_px)
    );
    let process = format!(
        "still decoder; {}",
        crate::pipeline::finish::describe_still_filters(&params.dsp)
    );
    let size = std::fs::metadata(image).map_or(0, |m| m.len());
    let reference = format!(
        "{}{}",
        crate::io::fingerprint::fingerprint(format!("{name} {size} {groove}").as_bytes()),
        crate::side::params_fingerprint(params)
    );
    crate::io::bwf::BroadcastInfo::optical_transfer(&source, &process, &reference, &run.audio, bits)
}

/// Writes the JSON report of a decoded still to `path` (atomically; an existing file only
/// when `overwrite`).
///
/// # Errors
/// One line naming the file when it exists or cannot be written.
pub fn write_still_report(
    path: &Path,
    run: &super::StillRun,
    setup: &crate::pipeline::still::StillSetup,
    params: &crate::pipeline::PipelineParams,
    what: &ReportInputs<'_>,
    overwrite: bool,
) -> Result<()> {
    let a = &run.analysis;
    let groove = &a.grooves.grooves[a.chosen];
    let line_ms = 1000.0 / setup.native_rate_hz();
    let names = ["land|wall", "wall|bottom", "bottom|wall", "wall|land"];
    let report = StillReport {
        version: env!("CARGO_PKG_VERSION"),
        status: "ok",
        image: what.image.display().to_string(),
        output: what.out.display().to_string(),
        params_file: what.params_file.map(|p| p.display().to_string()),
        filters: crate::pipeline::finish::describe_still_filters(&params.dsp),
        image_width_px: run.image_px.0,
        image_height_px: run.image_px.1,
        axis: setup.axis.name(),
        cut: setup.cut.name(),
        reverse: setup.reverse,
        um_per_px: setup.um_per_px,
        rpm: setup.rpm,
        radius_mm: setup.radius_mm,
        groove_speed_mm_s: setup.groove_speed_um_s() / 1000.0,
        grooves_found: a
            .grooves
            .grooves
            .iter()
            .map(|g| GrooveLine {
                number: g.number,
                coverage: g.coverage,
                position_px: g.position_px,
                width_px: g.width_px,
            })
            .collect(),
        bottoms_visible: a.grooves.bottoms_visible,
        groove: groove.number,
        groove_chosen_automatically: what.chosen_automatically,
        left_wall: left_wall_text(setup.axis, setup.reverse),
        native_rate_hz: a.signal.native_rate_hz,
        sample_rate_hz: run.audio.sample_rate_hz,
        channels: run.audio.channels.len(),
        duration_secs: run.audio.duration_secs(),
        gain_per_mm_s: run.gain_per_mm_s,
        borders: names
            .iter()
            .zip(a.signal.border_counts)
            .map(|(n, c)| BorderLine {
                border: n,
                lines_fitted: c[0],
                screened_out: c[1],
                rejected_outliers: c[2],
            })
            .collect(),
        gaps: a
            .signal
            .gaps
            .iter()
            .map(|g| GapLine {
                channel: g.channel,
                start_line: g.start_line,
                lines: g.lines,
                start_ms: g.start_line as f64 * line_ms,
                duration_ms: g.lines as f64 * line_ms,
            })
            .collect(),
        reference: what.reference.map(|p| p.display().to_string()),
        scores: what.scores.clone(),
        timings: run.timings,
        params,
        warnings: &run.warnings,
    };
    crate::io::write_json_atomic(path, &report, overwrite)?;
    Ok(())
}

/// Which wall is the left channel (the report, the workbench).
#[must_use]
pub fn left_wall_text(axis: Axis, reverse: bool) -> &'static str {
    match (axis, reverse) {
        (Axis::Vertical, false) => "the right-hand wall (time runs down)",
        (Axis::Vertical, true) => "the left-hand wall (time runs up)",
        (Axis::Horizontal, false) => "the upper wall (time runs rightward)",
        (Axis::Horizontal, true) => "the lower wall (time runs leftward)",
    }
}
