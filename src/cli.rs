//! The command-line front end: clap subcommands over the engine (reconstruct, plan, merge, eval, flow, params, synth, inspect, gui).

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};
use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};

use crate::io::wav::{Audio, WavBits};
use crate::job::Job;
pub(crate) use crate::output_checks::{
    check_folder_outside_scan, check_outputs, check_outside_scan, check_parent_exists,
    undo_first_on_error,
};
use crate::pipeline::PipelineParams;
use crate::pipeline::{Method, PathChoice};
pub use crate::side::cli::{Report, make_report, run_reconstruct};

/// Plays gramophone records from microscope image sequences (Tian & Barron's optical-flow method).
#[derive(Debug, Parser)]
#[command(name = "groovescope", version, about, long_about = None)]
pub struct Cli {
    /// What to do; with none, the workbench opens on the demo scan when a display exists,
    /// otherwise the demo scan is reconstructed to a WAV file with a report.
    #[command(subcommand)]
    pub command: Option<Command>,
}

/// Subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Reconstruct a scan's sound to a WAV file.
    Reconstruct(ReconstructArgs),
    /// Score a recovered WAV against a reference WAV (r, envelope r, SNR).
    Eval {
        /// The recovered sound (a WAV file).
        recovered: PathBuf,
        /// The reference sound (a WAV file).
        reference: PathBuf,
        /// Print JSON instead of text: one object, `channels` holding each channel pair's
        /// scores (a single pair's also at the top level) and `mixed_to_mono`.
        #[arg(long)]
        json: bool,
        /// Longest lag searched, in milliseconds.
        #[arg(long, default_value_t = 5.0)]
        max_lag_ms: f64,
    },
    /// Run the derivative and flow stages on a frame sequence and write a Middlebury .flo file.
    Flow(FlowArgs),
    /// Print the default parameters as TOML (every knob, units in names).
    Params,
    /// Render a ground-truth scan from a sound (ray-traced groove under a microscope camera).
    Synth(SynthArgs),
    /// Render a depth-validation scene (cube, cylinder or sphere) with its true depth maps.
    SynthScene {
        /// cube, cylinder or sphere.
        #[arg(value_parser = ["cube", "cylinder", "sphere"])]
        kind: String,
        /// Output folder (must not exist or be empty).
        #[arg(long)]
        out: PathBuf,
        /// Scene settings TOML: a `[scene]` table, or its keys at the top level (missing keys
        /// take defaults; a key outside `[scene]` beside it is refused).
        #[arg(long)]
        config: Option<PathBuf>,
    },
    /// Run one group through every stage and dump each intermediate output (PNG) and the
    /// per-sample wall tilts (samples.csv) into a folder.
    Inspect {
        /// The scan: a folder holding scan.toml, or a Zarr store (`pack`, `import-video --zarr`).
        scan: PathBuf,
        /// Group index.
        #[arg(long, default_value_t = 0)]
        group: usize,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// Parameters TOML.
        #[arg(long)]
        params: Option<PathBuf>,
        /// Force a path instead of choosing by the `[dual_focus]` table.
        #[arg(long, value_parser = ["auto", "depth", "dual-focus"], default_value = "auto")]
        path: String,
        /// Replace existing files.
        #[arg(long)]
        force: bool,
    },
    /// Run the accuracy suite against ground truth (tones, speech, melody, Fig. 20, Table 2
    /// depth scenes) and write a markdown report.
    Accuracy {
        /// The report file (markdown).
        #[arg(long)]
        out: PathBuf,
        /// Fewer, shorter cases (about a minute).
        #[arg(long)]
        quick: bool,
        /// Keep the rendered scans in this folder (must not exist or be empty).
        #[arg(long)]
        keep: Option<PathBuf>,
        /// Replace an existing report.
        #[arg(long)]
        force: bool,
        /// No per-case lines on stderr.
        #[arg(long)]
        quiet: bool,
    },
    /// Decode a still image of grooves seen from above (micrograph, stitched strip, scan) to a WAV file.
    Still(crate::still::cli::StillArgs),
    /// Render a top-view still of neighbouring grooves with known wall tones and its truth.
    SynthStill(crate::still::cli::SynthStillArgs),
    /// Cut a scan into shards for several machines (Slurm job arrays and the like).
    Plan(crate::side::cli::PlanArgs),
    /// Merge the parts of every shard of a plan into the side's WAV.
    Merge(crate::side::cli::MergeArgs),
    /// Convert a scan folder to a Zarr store (one zstd chunk per group) and check it.
    Pack(crate::pack_cli::PackArgs),
    /// Import a microscope video clip (AVI/MP4) as a scan folder or Zarr store (needs the `video` feature).
    ImportVideo(crate::video_cli::ImportVideoArgs),
    /// Open the workbench (optionally on a scan).
    Gui {
        /// A scan to open (a folder holding scan.toml, or a Zarr store), or a still image (PNG or
        /// TIFF) to open in the still window.
        scan: Option<PathBuf>,
    },
}

/// Arguments of `reconstruct`.
#[derive(Debug, clap::Args)]
pub struct ReconstructArgs {
    /// The scan: a folder holding scan.toml, or a Zarr store (`pack`, `import-video --zarr`).
    pub scan: PathBuf,
    /// Output WAV file.
    #[arg(long)]
    pub out: PathBuf,
    /// Parameters TOML (see `groovescope params`).
    #[arg(long)]
    pub params: Option<PathBuf>,
    /// JSON report (timings, per-group outliers and pixel noise, scores against reference.wav).
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Force a path instead of choosing by the `[dual_focus]` table.
    #[arg(long, value_parser = ["auto", "depth", "dual-focus"], default_value = "auto")]
    pub path: String,
    /// Decoder, overriding the params' `method`: flow, edges or fused.
    #[arg(long, value_parser = ["flow", "edges", "fused"])]
    pub method: Option<String>,
    /// WAV sample format: 16, 24 or 32f (default 24).
    #[arg(long)]
    pub bits: Option<WavBits>,
    /// First group to run.
    #[arg(long)]
    pub first_group: Option<usize>,
    /// Number of groups to run.
    #[arg(long)]
    pub groups: Option<usize>,
    /// Treat unreadable frames as silent gaps instead of failing.
    #[arg(long)]
    pub keep_going: bool,
    /// Replace existing output files.
    #[arg(long)]
    pub force: bool,
    /// No progress bar and no summary line (warnings still go to stderr).
    #[arg(long)]
    pub quiet: bool,
    /// Shards, resume, progress lines.
    #[command(flatten)]
    pub side: crate::side::cli::SideRunArgs,
}

/// Arguments of `flow`.
#[derive(Debug, clap::Args)]
pub struct FlowArgs {
    /// Frames in order (7 or more for the Simoncelli filters, 2 or more with --two-frame).
    #[arg(required = true)]
    pub frames: Vec<PathBuf>,
    /// Output .flo file (the flow of the middle window).
    #[arg(long)]
    pub out: PathBuf,
    /// Known land motion per frame in px (content moving toward −x is negative); 0 = none.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub land_flow_px: f64,
    /// Focal length in px (for the groove constraint).
    #[arg(long, default_value_t = 10_256.0)]
    pub focal_px: f64,
    /// Parameters TOML.
    #[arg(long)]
    pub params: Option<PathBuf>,
    /// Use two-frame differences.
    #[arg(long)]
    pub two_frame: bool,
    /// Replace an existing output file.
    #[arg(long)]
    pub force: bool,
}

/// Arguments of `synth`.
#[derive(Debug, clap::Args)]
pub struct SynthArgs {
    /// Sound to cut into the groove (WAV); or use --tone / --sweep / --melody.
    pub sound: Option<PathBuf>,
    /// Output scan folder (must not exist or be empty).
    #[arg(long)]
    pub out: PathBuf,
    /// Generator settings TOML: a `[synth]` table, or its keys at the top level (missing keys
    /// take the preset's values; a key outside `[synth]` beside it is refused).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Starting settings: paper (1280×1024, the paper's optics), quick (small frames), demo, dual-focus.
    #[arg(long, value_parser = ["paper", "quick", "demo", "dual-focus"], default_value = "paper")]
    pub preset: String,
    /// A built-in test tone at this frequency (Hz).
    #[arg(long, conflicts_with_all = ["sound", "sweep", "melody"])]
    pub tone: Option<f64>,
    /// A built-in exponential sweep F0:F1 (Hz).
    #[arg(long, conflicts_with_all = ["sound", "melody"])]
    pub sweep: Option<String>,
    /// A built-in short melody.
    #[arg(long, conflicts_with = "sound")]
    pub melody: bool,
    /// Duration of a built-in sound (s).
    #[arg(long, default_value_t = 0.05)]
    pub duration: f64,
    /// Render at most this many groups.
    #[arg(long)]
    pub max_groups: Option<usize>,
    /// Seed of texture, noise and damage (overrides the config).
    #[arg(long)]
    pub seed: Option<u32>,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

fn run_synth(args: &SynthArgs) -> Result<()> {
    use crate::synth::{
        BUILTIN_RATE_HZ, Groove, SynthConfig, arpeggio, render_scan, sweep, tone, write_scan,
    };
    check_parent_exists(&args.out)?;
    let base = match args.preset.as_str() {
        "quick" => SynthConfig::quick_test(),
        "demo" => SynthConfig::demo(),
        "dual-focus" => SynthConfig::dual_focus_demo(),
        _ => SynthConfig::default(),
    };
    let mut cfg = match &args.config {
        Some(p) => overlay_toml(&base, p, "synth", "synth settings", SynthConfig::validate)?,
        None => base,
    };
    if let Some(n) = args.max_groups {
        cfg.max_groups = Some(n);
    }
    if let Some(seed) = args.seed {
        cfg.seed = seed;
        cfg.damage.seed = seed;
    }
    check_duration(args.duration)?;
    let pb = progress_bar(0, args.quiet);
    let progress = |done: usize, total: usize| {
        pb.set_length(total as u64);
        pb.set_position(done as u64);
    };
    let job = Job::reporting(&progress);
    // The built-in sounds are made at 48 kHz: a frequency at or past its Nyquist would alias.
    let nyquist_hz = f64::from(BUILTIN_RATE_HZ) / 2.0;
    let audible = |f: f64| f.is_finite() && f > 0.0 && f < nyquist_hz;
    let builtin = if let Some(f) = args.tone {
        if !audible(f) {
            bail!("--tone must be a frequency above 0 and below {nyquist_hz} Hz, got {f}");
        }
        Some(tone(f, args.duration, BUILTIN_RATE_HZ))
    } else if let Some(spec) = &args.sweep {
        let Some((a, b)) = spec.split_once(':') else {
            bail!("--sweep takes F0:F1 in Hz, got {spec}");
        };
        let (Ok(f0), Ok(f1)) = (a.parse::<f64>(), b.parse::<f64>()) else {
            bail!("--sweep takes F0:F1 in Hz, got {spec}");
        };
        if !(audible(f0) && audible(f1)) {
            bail!("--sweep frequencies must be above 0 and below {nyquist_hz} Hz, got {spec}");
        }
        Some(sweep(f0, f1, args.duration, BUILTIN_RATE_HZ))
    } else if args.melody {
        Some(arpeggio(args.duration / 4.0, BUILTIN_RATE_HZ))
    } else {
        None
    };
    // Hidden folders of earlier runs killed outright (kill -9): removed or named, not silent.
    for line in crate::synth::earlier_unfinished_runs(&args.out) {
        crate::tell!("{line}");
    }
    let summary = match (builtin, &args.sound) {
        (Some(sound), _) => render_scan(&sound, &cfg, &args.out, job)?,
        (None, Some(path)) => write_scan(&Groove::from_wav(path, &cfg)?, &args.out, job)?,
        (None, None) => bail!("give a sound file, --tone HZ, --sweep F0:F1 or --melody"),
    };
    pb.finish_and_clear();
    // The generator's own (a stereo sound mixed for a one-channel cut, focus stripes over the
    // glass edge): to standard error, as every warning, --quiet or not.
    for w in &summary.warnings {
        crate::tell!("warning: {w}");
    }
    // A limit on the groups cuts the sound short: said even with --quiet, naming the limit.
    if let Some(n) = cfg.max_groups.filter(|&n| n == summary.groups) {
        let limit = if args.max_groups.is_some() {
            "--max-groups".to_string()
        } else if args.config.is_some() {
            "the config's max_groups".to_string()
        } else {
            format!("the {} preset's max_groups", args.preset)
        };
        crate::tell!(
            "warning: stopped at {limit} = {n} groups: the scan holds {:.4} s of the sound \
             (a larger --max-groups renders more of it)",
            summary.reference_secs
        );
    }
    if !args.quiet {
        let details = format!("{:.4} s of sound", summary.reference_secs);
        let line = wrote_scan(
            &summary.out_dir,
            summary.groups,
            summary.frames_per_group,
            &details,
        );
        crate::say!("{line}")?;
    }
    Ok(())
}

fn run_synth_scene(kind: &str, out: &Path, config: Option<&Path>) -> Result<()> {
    use crate::synth::{SceneConfig, SceneKind, render_scene};
    check_parent_exists(out)?;
    let kind = match kind {
        "cube" => SceneKind::Cube,
        "cylinder" => SceneKind::Cylinder,
        _ => SceneKind::Sphere,
    };
    let cfg = match config {
        Some(p) => overlay_toml(
            &SceneConfig::default(),
            p,
            "scene",
            "scene settings",
            SceneConfig::validate,
        )?,
        None => SceneConfig::default(),
    };
    for line in crate::synth::earlier_unfinished_runs(out) {
        crate::tell!("{line}");
    }
    let meta = render_scene(kind, &cfg, out, Job::reporting(&|_, _| {}))?;
    crate::say!(
        "wrote {} ({} frames with true depth)",
        out.display(),
        meta.frames
    )?;
    Ok(())
}

/// The method `--method` names, or `default` without one.
pub(crate) fn method_choice(arg: Option<&str>, default: Method) -> Method {
    arg.and_then(Method::from_name).unwrap_or(default)
}

pub(crate) fn path_choice(arg: &str, default: PathChoice) -> PathChoice {
    match arg {
        "depth" => PathChoice::Depth,
        "dual-focus" => PathChoice::DualFocus,
        _ => default,
    }
}

/// Loads params from TOML, or the defaults.
///
/// # Errors
/// When the file cannot be read or holds an invalid key or value (NaN, negative).
pub fn load_params(path: Option<&Path>) -> Result<PipelineParams> {
    let params = match path {
        Some(p) => {
            let text = crate::io::limits::read_toml_text(p, "parameters")?;
            PipelineParams::from_toml_str(&text)
                .map_err(|e| anyhow::anyhow!("invalid parameters: {e}: {}", p.display()))?
        }
        None => PipelineParams::default(),
    };
    if let Err(e) = params.validate_for_clip() {
        match path {
            Some(p) => bail!("{e}: {}", p.display()),
            None => bail!("{e}"),
        }
    }
    Ok(params)
}

/// `base` with the keys of the TOML file `path` (optionally under a `[table]`) laid over it
/// ([`crate::toml_error::overlay`]: a key it cannot use is refused, never dropped), then
/// checked by `validate`.
///
/// # Errors
/// When the file cannot be read, a key or value is invalid, or `validate` refuses the result:
/// one line naming the key (and its line, where the file's syntax is at fault) and the file.
pub(crate) fn overlay_toml<T, E: std::fmt::Display>(
    base: &T,
    path: &Path,
    table: &str,
    what: &str,
    validate: impl FnOnce(&T) -> std::result::Result<(), E>,
) -> Result<T>
where
    T: serde::Serialize + serde::de::DeserializeOwned,
{
    let text = crate::io::limits::read_toml_text(path, what)?;
    let merged = crate::toml_error::overlay(base, &text, table)
        .map_err(|problem| anyhow::anyhow!("invalid {what}: {problem}: {}", path.display()))?;
    // A value out of range names the file it came from, as a type error does.
    validate(&merged).map_err(|e| anyhow::anyhow!("{e}: {}", path.display()))?;
    Ok(merged)
}

/// Checks a built-in sound's `--duration`: positive, and no longer than the longest
/// reference WAV groovescope reads back ([`crate::io::limits::MAX_WAV_SAMPLES`] at the
/// built-in rate), which also bounds the memory the sound takes.
///
/// # Errors
/// One line with the limit.
pub(crate) fn check_duration(secs: f64) -> Result<()> {
    let max_secs =
        crate::io::limits::MAX_WAV_SAMPLES as f64 / f64::from(crate::synth::BUILTIN_RATE_HZ);
    if !(secs.is_finite() && secs > 0.0 && secs <= max_secs) {
        bail!("--duration must be above 0 and at most {max_secs:.0} s, got {secs}");
    }
    Ok(())
}

/// Prints each of a run's warnings to stderr, one `warning: …` line each.
pub(crate) fn print_warnings(warnings: &[String]) {
    for w in warnings {
        crate::tell!("warning: {w}");
    }
}

/// The line a command that wrote a scan says it with: `wrote OUT (N groups of M frames, DETAILS)`.
pub(crate) fn wrote_scan(
    out: &Path,
    groups: usize,
    frames_per_group: usize,
    details: &str,
) -> String {
    let out = out.display();
    format!("wrote {out} ({groups} groups of {frames_per_group} frames, {details})")
}

/// The line a command that wrote a WAV says it with: `wrote OUT (LENGTH, DETAILS)`.
pub(crate) fn wrote_sound(out: &Path, audio: &Audio, details: &str) -> String {
    format!(
        "wrote {} ({}, {details})",
        out.display(),
        audio.length_label()
    )
}

pub(crate) fn progress_bar(total: usize, quiet: bool) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let pb = ProgressBar::new(total as u64);
    // The message says what is counted: "groups", unless a run sets another (a shard's
    // groups before its range).
    if let Ok(style) = ProgressStyle::with_template(
        "{spinner} [{elapsed_precise}] {bar:40} {pos}/{len} {msg} ({per_sec}, ETA {eta})",
    ) {
        pb.set_style(style);
    }
    pb.set_message("groups");
    pb
}

fn run_flow(args: &FlowArgs) -> Result<()> {
    use crate::pipeline::derivatives::{DerivativeMode, compute_derivatives};
    use crate::pipeline::optical_flow::compute_flow;
    let inputs: Vec<&Path> = args
        .frames
        .iter()
        .map(PathBuf::as_path)
        .chain(args.params.as_deref())
        .collect();
    check_outputs(&[args.out.as_path()], &inputs, args.force)?;
    if !(args.land_flow_px.is_finite() && args.focal_px.is_finite() && args.focal_px > 0.0) {
        bail!("--land-flow-px and --focal-px must be finite (focal length positive)");
    }
    let mut params = load_params(args.params.as_deref())?;
    if args.two_frame {
        params.derivatives.mode = DerivativeMode::TwoFrame;
    }
    let frames = args
        .frames
        .iter()
        .map(|p| crate::io::load_frame(p))
        .collect::<Result<Vec<_>, _>>()?;
    if let Some(first) = frames.first() {
        for (f, p) in frames.iter().zip(&args.frames) {
            if !f.same_size(first) {
                bail!(
                    "frame is {}x{} but the first frame is {}x{}: {}",
                    f.width,
                    f.height,
                    first.width,
                    first.height,
                    p.display()
                );
            }
        }
    }
    let derivs = compute_derivatives(&frames, args.land_flow_px, &params.derivatives)?;
    let Some(mid) = derivs.get(derivs.len() / 2) else {
        bail!("too few frames for the derivative filters");
    };
    let flow = compute_flow(mid, args.focal_px, None, &params.flow)?;
    crate::io::flo::write_flo(&args.out, &flow.u, &flow.v, args.force)?;
    crate::say!(
        "wrote {} ({}x{}, frame {}, {} iterations{})",
        args.out.display(),
        flow.u.width,
        flow.u.height,
        flow.frame_index,
        flow.iterations,
        if flow.converged { ", converged" } else { "" }
    )?;
    Ok(())
}

/// Ends a command that Ctrl-C stopped (see [`crate::job::catch_interrupts`]) with one line,
/// "`command`: cancelled; nothing written", to be called before it writes anything.
///
/// # Errors
/// That line, once Ctrl-C was pressed.
pub(crate) fn stop_if_interrupted(command: &str) -> Result<()> {
    if crate::job::interrupted().load(std::sync::atomic::Ordering::Relaxed) {
        bail!("{command}: cancelled; nothing written");
    }
    Ok(())
}

/// `result` of work that Ctrl-C may have stopped: [`stop_if_interrupted`]'s line when it did
/// (whatever the work returned, a cancellation error included), else `result`.
///
/// # Errors
/// As above, or the work's own error.
pub(crate) fn unless_interrupted<T, E: Into<anyhow::Error>>(
    command: &str,
    result: std::result::Result<T, E>,
) -> Result<T> {
    stop_if_interrupted(command)?;
    result.map_err(Into::into)
}

/// Runs a parsed command line (`None` means the default action was handled by the caller).
///
/// # Errors
/// Any failure, with the file named.
pub fn run(command: Command) -> Result<()> {
    // The commands whose jobs stop cleanly on Ctrl-C; the others are ended by it as before.
    let stoppable = matches!(
        command,
        Command::Reconstruct(_)
            | Command::Pack(_)
            | Command::Synth(_)
            | Command::SynthScene { .. }
            | Command::ImportVideo(_)
            | Command::Still(_)
            | Command::Accuracy { .. }
            | Command::Plan(_)
            | Command::Merge(_)
            | Command::Inspect { .. }
    );
    if stoppable {
        crate::job::catch_interrupts().map_err(|e| anyhow::anyhow!("cannot catch Ctrl-C: {e}"))?;
    }
    match command {
        Command::Reconstruct(args) => crate::side::cli::run_reconstruct_command(&args),
        Command::Plan(args) => crate::side::cli::run_plan(&args),
        Command::Merge(args) => crate::side::cli::run_merge(&args),
        Command::Pack(args) => crate::pack_cli::run_pack(&args),
        Command::Eval {
            recovered,
            reference,
            json,
            max_lag_ms,
        } => crate::eval_cli::run_eval(&recovered, &reference, json, max_lag_ms),
        Command::Flow(args) => run_flow(&args),
        Command::Params => {
            crate::stdout::write_text(&params_toml_documented()?)?;
            Ok(())
        }
        Command::Synth(args) => run_synth(&args),
        Command::SynthScene { kind, out, config } => {
            run_synth_scene(&kind, &out, config.as_deref())
        }
        Command::Inspect {
            scan,
            group,
            out,
            params,
            path,
            force,
        } => {
            check_parent_exists(&out)?;
            check_folder_outside_scan(&out, &scan)?;
            let mut p = load_params(params.as_deref())?;
            p.path = path_choice(&path, p.path);
            crate::inspect::run_inspect(&scan, group, &out, &p, force)
        }
        Command::Accuracy {
            out,
            quick,
            keep,
            force,
            quiet,
        } => {
            if let Some(keep) = &keep {
                check_parent_exists(keep)?;
            }
            // The shared checks first: a folder named as the report is refused before the
            // suite's minutes, not when the report is written.
            check_outputs(&[out.as_path()], &[], force)?;
            let opts = crate::accuracy::AccuracyOptions { quick, keep };
            crate::accuracy::write_report(&out, force, &opts, &mut |line| {
                if !quiet {
                    crate::tell!("{line}");
                }
            })?;
            if !quiet {
                crate::say!("wrote {}", out.display())?;
            }
            Ok(())
        }
        Command::Still(args) => crate::still::cli::run_still(&args),
        Command::SynthStill(args) => crate::still::cli::run_synth_still(&args),
        Command::ImportVideo(args) => crate::video_cli::run_import_video(&args),
        Command::Gui { scan } => run_gui(scan),
    }
}

/// Opens the workbench.
///
/// # Errors
/// When no display is available or the GUI was not built.
pub fn run_gui(scan: Option<PathBuf>) -> Result<()> {
    #[cfg(feature = "gui")]
    {
        crate::app::run(scan)
    }
    #[cfg(not(feature = "gui"))]
    {
        let _ = scan;
        bail!("this groovescope was built without the `gui` feature")
    }
}

/// The default params as TOML, preceded by a header comment.
///
/// # Errors
/// When serialisation fails.
pub fn params_toml_documented() -> Result<String> {
    let body = crate::pipeline::knobs::documented_toml(&PipelineParams::default())?;
    Ok(format!(
        "# groovescope pipeline parameters (defaults). Units are in the key names.\n\
         # Pass to `groovescope reconstruct --params FILE`; missing keys take these defaults.\n\
         \n{body}"
    ))
}
