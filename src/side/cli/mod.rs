//! The `reconstruct` subcommand (a whole run or one shard, journaled and resumable), with `plan` and `merge` beside it.

use std::io::Write;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Result, bail};
use serde::Serialize;

use crate::cli::{ReconstructArgs, load_params, method_choice, path_choice};
use crate::engine::{ClipGroups, GroupOutcome, Reconstruction, StageTimings, finish_scan_clip};
use crate::io::bwf::{BroadcastInfo, disc_words};
use crate::io::wav::write_transfer_wav;
use crate::io::{Scan, ScanMeta, write_json_atomic};
use crate::pipeline::PipelineParams;
use crate::side::RunIdentity;
use crate::side::run::{RangeRun, run_range};
use progress::ProgressOut;

mod plan_merge;
mod progress;
mod shard;
pub use plan_merge::{MergeArgs, PlanArgs, run_merge, run_plan};

/// `reconstruct`'s options for long runs.
#[derive(Clone, Debug, Default, clap::Args)]
pub struct SideRunArgs {
    /// Run one shard of this plan (see `groovescope plan`); --out is then the part folder.
    #[arg(long, requires = "shard")]
    pub plan: Option<PathBuf>,
    /// The shard of --plan to run, from 0.
    #[arg(long, requires = "plan")]
    pub shard: Option<usize>,
    /// Continue from the journal an interrupted run left beside its output (a fresh start
    /// when there is none).
    #[arg(long)]
    pub resume: bool,
    /// Print one JSON line per finished group on stdout (done, total, groups/s, ETA);
    /// messages go to stderr.
    #[arg(long)]
    pub progress_json: bool,
}

/// Progress of a run in the JSON report: the rate it ran at.
#[derive(Clone, Debug, Default, Serialize)]
pub struct RunProgress {
    /// Groups run in this process (after those resumed).
    pub groups_run: usize,
    /// Groups read back from the journal.
    pub resumed_groups: usize,
    /// Groups before the range run for the slope history (shards).
    pub context_groups: usize,
    /// Wall-clock seconds of this process's run.
    pub elapsed_secs: f64,
    /// Groups (context included) per second.
    pub groups_per_sec: f64,
}

/// The JSON report written beside a reconstruction.
#[derive(Debug, Serialize)]
pub struct Report<'a> {
    /// groovescope version.
    pub version: &'static str,
    /// Scan folder.
    pub scan: String,
    /// Output WAV.
    pub output: String,
    /// Params file used (None: defaults).
    pub params_file: Option<String>,
    /// Params used.
    pub params: &'a PipelineParams,
    /// Reconstruction path that ran.
    pub path: &'static str,
    /// The decoder that made the sound: flow, edges or fused.
    pub method: &'static str,
    /// For `fused`: the crossover and edge weights per group and analysis block.
    pub fusion: Option<&'a crate::pipeline::finish::FusionReport>,
    /// The filters the sound went through, in order and in words (phase included).
    pub filters: String,
    /// Output duration.
    pub duration_secs: f64,
    /// Output sample rate.
    pub sample_rate_hz: u32,
    /// Native sample rate before resampling.
    pub native_rate_hz: f64,
    /// Gain from velocity (mm/s) to output units.
    pub gain_per_mm_s: f64,
    /// Timings.
    pub timings: &'a StageTimings,
    /// Rate of the run (None for the library's reports).
    pub progress: Option<RunProgress>,
    /// Per group.
    pub groups: &'a [crate::engine::GroupReport],
    /// Scores against reference.wav.
    pub scores: Option<crate::pipeline::eval::Scores>,
    /// Warnings.
    pub warnings: &'a [String],
}

/// The `bext` chunk of a transfer's WAV ([`crate::io::bwf`]): the disc, the decoder, path and
/// filters in words, and `(scan, params)` fingerprints as its reference (the same for a
/// scan's folder and store, and for a merged side and a one-process run; a run's
/// [`RunIdentity`] holds both).
#[must_use]
pub fn transfer_info(
    meta: &ScanMeta,
    params: &PipelineParams,
    rec: &Reconstruction,
    (scan_fingerprint, params_fingerprint): (&str, &str),
    (audio, bits): (&crate::io::wav::Audio, crate::io::wav::WavBits),
) -> BroadcastInfo {
    let process = format!(
        "{} decoder on the {} path; {}",
        rec.method.name(),
        params.path_name(meta),
        crate::pipeline::finish::describe_filters(&params.dsp, rec.method)
    );
    let reference = format!("{scan_fingerprint}{params_fingerprint}");
    BroadcastInfo::optical_transfer(&disc_words(meta), &process, &reference, audio, bits)
}

/// Builds the report for a finished reconstruction of the scan at `scan_dir`.
#[must_use]
pub fn make_report<'a>(
    scan_dir: &Path,
    meta: &ScanMeta,
    out: &Path,
    params_file: Option<&Path>,
    params: &'a PipelineParams,
    rec: &'a Reconstruction,
) -> Report<'a> {
    Report {
        version: env!("CARGO_PKG_VERSION"),
        scan: scan_dir.display().to_string(),
        output: out.display().to_string(),
        params_file: params_file.map(|p| p.display().to_string()),
        params,
        path: params.path_name(meta),
        method: rec.method.name(),
        fusion: rec.fusion.as_ref(),
        filters: crate::pipeline::finish::describe_filters(&params.dsp, rec.method),
        duration_secs: rec.audio.duration_secs(),
        sample_rate_hz: rec.audio.sample_rate_hz,
        native_rate_hz: rec.stitched.native_rate_hz,
        gain_per_mm_s: rec.gain_per_mm_s,
        timings: &rec.timings,
        progress: None,
        groups: &rec.groups,
        scores: rec.scores,
        warnings: &rec.warnings,
    }
}

/// Prints one JSON line on stdout and flushes it; a closed stdout (the reader went away) is
/// not an error of the run.
fn json_line(value: &serde_json::Value) {
    let mut out = std::io::stdout().lock();
    let _ = writeln!(out, "{value}");
    let _ = out.flush();
}

/// The journal of a whole run writing `out`: `OUT.journal` beside it.
#[must_use]
pub fn journal_path(out: &Path) -> PathBuf {
    crate::io::atomic::beside(out, "out", |name| format!("{name}.journal"))
}

/// Takes the output lock of every path (one writer at a time per output: a second run writing
/// the same files is refused before any work, instead of mixing its files with the first's).
pub(crate) fn lock_outputs(paths: &[&Path]) -> Result<Vec<crate::io::lock::OutputLock>> {
    Ok(paths
        .iter()
        .map(|p| crate::io::lock::OutputLock::acquire(p))
        .collect::<Result<Vec<_>, _>>()?)
}

/// Refuses params that `scan`'s frames cannot carry, naming the params file (`file`; `None`:
/// the defaults): a Hough accumulator too large for them, or a native sample grid finer than
/// they resolve (the grid `scan.toml` fixes is named there instead).
pub(super) fn check_params_fit_scan(
    params: &PipelineParams,
    scan: &Scan,
    file: Option<&Path>,
) -> Result<()> {
    let file = || file.map_or("the default params".into(), |p| p.display().to_string());
    if let Err(e) = crate::io::limits::check_hough_accumulator(params, scan) {
        bail!("{e}: {}", file());
    }
    match crate::engine::check_sample_density(scan, params) {
        Err(crate::engine::EngineError::Stage(e)) => bail!("{e}: {}", file()),
        other => Ok(other?),
    }
}

/// Runs `run` with the terminal progress `args` ask for, each finished group to `sink`;
/// returns its result and rate.
fn run_with_progress(
    run: &RangeRun<'_>,
    args: &ReconstructArgs,
    sink: &mut dyn FnMut(GroupOutcome),
) -> Result<(crate::side::run::RangeResult, RunProgress)> {
    let mut progress = ProgressOut::new(run.range.len(), args);
    let result = run_range(
        run,
        &mut |e| progress.event(e),
        sink,
        crate::job::interrupted(),
    );
    match result {
        Ok(r) => {
            let p = progress.summary(r.groups - r.resumed);
            Ok((r, p))
        }
        Err(e) => {
            progress.bar.finish_and_clear();
            match progress.cancelled_early(&e) {
                Some(line) => Err(anyhow::anyhow!(line)),
                None => Err(e.into()),
            }
        }
    }
}

/// Runs `reconstruct`: one shard of a plan with `--plan`/`--shard`, else the whole range.
///
/// # Errors
/// Any failure, with the file named.
pub fn run_reconstruct_command(args: &ReconstructArgs) -> Result<()> {
    match (&args.side.plan, args.side.shard) {
        (Some(plan), Some(shard)) => shard::run_shard(args, plan, shard),
        _ => run_reconstruct(args).map(|_| ()),
    }
}

/// Refuses a run over groups whose folders the scan's numbering skips, before any work (a
/// run of hours would stop there), unless `keep_going`: then it warns once that they become
/// gaps. `quiet` does not hide the warning: silence in the sound must not pass unseen.
///
/// # Errors
/// Missing groups in `range` without `keep_going`, named with the scan.
pub fn check_missing_groups(scan: &Scan, range: Range<usize>, keep_going: bool) -> Result<()> {
    let Some(what) = scan.missing_note(range) else {
        return Ok(());
    };
    if !keep_going {
        // Folders can be renamed; a store's names are what it was packed with.
        let rename = if scan.is_store() {
            ""
        } else {
            " (or, if the numbers are not places on the groove, such as timestamps, say \
             numbered_names = \"order\" in the [motion] table of scan.toml)"
        };
        bail!(
            "{what}: run with --keep-going to read each as a gap of silence, in its place{rename}"
        );
    }
    crate::tell!("warning: {what}: each becomes a gap of silence, in its place");
    Ok(())
}

/// Runs `reconstruct` over a range of groups (all by default), journaled beside the output.
///
/// # Errors
/// Any failure, with the file named.
pub fn run_reconstruct(args: &ReconstructArgs) -> Result<Reconstruction> {
    let outputs: Vec<&Path> = std::iter::once(args.out.as_path())
        .chain(args.report.as_deref())
        .collect();
    let (reference, meta) = (args.scan.join("reference.wav"), args.scan.join("scan.toml"));
    let inputs: Vec<&Path> = [reference.as_path(), meta.as_path()]
        .into_iter()
        .chain(args.params.as_deref())
        .collect();
    // Among the scan's frames is refused whatever --force says, so that is said first.
    crate::cli::check_outside_scan(&outputs, &args.scan)?;
    crate::cli::check_outputs(&outputs, &inputs, args.force)?;
    if args.groups == Some(0) {
        bail!("--groups must be at least 1: {}", args.scan.display());
    }
    let _locks = lock_outputs(&outputs)?;
    let mut params = load_params(args.params.as_deref())?;
    params.path = path_choice(&args.path, params.path);
    params.method = method_choice(args.method.as_deref(), params.method);
    let scan = Scan::open(&args.scan)?;
    check_params_fit_scan(&params, &scan, args.params.as_deref())?;
    let first = args.first_group.unwrap_or(0);
    let end = args
        .groups
        .map_or(scan.groups.len(), |n| first.saturating_add(n))
        .min(scan.groups.len());
    if first >= scan.groups.len() {
        bail!(
            "--first-group {first} is past the last group ({} groups): {}",
            scan.groups.len(),
            scan.dir.display()
        );
    }
    if let Some(n) = args.groups.filter(|&n| first.saturating_add(n) > end) {
        crate::tell!(
            "warning: --groups {n} from group {first} runs past the scan's last group ({} \
             groups): running the {} there are",
            scan.groups.len(),
            end - first
        );
    }
    check_missing_groups(&scan, first..end, args.keep_going)?;
    let journal = journal_path(&args.out);
    let run = RangeRun {
        scan: &scan,
        params: &params,
        keep_going: args.keep_going,
        range: first..end,
        shard: false,
        journal: &journal,
        identity: RunIdentity::new(&scan, &params, args.keep_going, first..end, None),
        resume: args.side.resume,
        force: args.force,
    };
    let had_journal = journal.exists();
    let mut finished = 0usize;
    let outcome = (|| -> Result<Reconstruction> {
        let started = Instant::now();
        // Each group goes into the clip as it finishes: the clip keeps its signals packed and
        // drops the rest (timings summed, slope entries already in the history).
        let mut clip = ClipGroups::with_capacity(run.range.len());
        let (result, run_progress) = run_with_progress(&run, args, &mut |g| {
            finished += 1;
            clip.add(g);
        })?;
        let mut rec = finish_scan_clip(&scan, clip, &params)?;
        rec.timings.total_secs = started.elapsed().as_secs_f64();
        let id = &run.identity;
        let bits = args.bits.unwrap_or_default();
        let fingerprints = (id.scan_fingerprint.as_str(), id.params_fingerprint.as_str());
        let info = transfer_info(&scan.meta, &params, &rec, fingerprints, (&rec.audio, bits));
        write_transfer_wav(&args.out, &rec.audio, bits, args.force, &info)?;
        if let Some(report_path) = &args.report {
            let mut report = make_report(
                &scan.dir,
                &scan.meta,
                &args.out,
                args.params.as_deref(),
                &params,
                &rec,
            );
            report.progress = Some(run_progress.clone());
            crate::cli::undo_first_on_error(
                &args.out,
                write_json_atomic(report_path, &report, args.force).map_err(Into::into),
            )?;
        }
        result.journal.remove()?;
        finish_message(args, &rec, &run_progress)?;
        Ok(rec)
    })();
    outcome.map_err(|e| after_failure(e, &journal, had_journal, args, finished, args.keep_going))
}

/// A failed run's error, and what becomes of its journal: one this run created (`had_journal`
/// false, or started over by `--force`) is removed when it holds no finished group, or only
/// groups that made no sound (nothing to go on from); a journal holding finished groups is kept
/// and the line says how to go on; one the run was given (--resume) is never removed. A run
/// stopped by a group whose frames do not load says --keep-going would make it a gap, whether
/// or not groups finished before it (a shard can stop at its first group).
fn after_failure(
    e: anyhow::Error,
    journal: &Path,
    had_journal: bool,
    args: &ReconstructArgs,
    finished: usize,
    keep_going: bool,
) -> anyhow::Error {
    // A group whose frames do not load stops the run (the engine's `EngineError::Load`), and
    // stops it again at the same group unless --keep-going makes it a gap, as it makes any such
    // group.
    let load = {
        use crate::engine::EngineError;
        use crate::side::SideError;
        match (
            e.downcast_ref::<EngineError>(),
            e.downcast_ref::<SideError>(),
        ) {
            (Some(EngineError::Load(l)), _)
            | (_, Some(SideError::Engine(EngineError::Load(l)))) => Some(l),
            _ => None,
        }
    };
    let unreadable = !keep_going && load.is_some();
    // A group's last frame gone since the run began changes the scan's frame counts, which
    // --resume checks: then only the file put back lets it go on.
    let gone = matches!(load, Some(crate::io::LoadError::Missing { .. }));
    let alone = |e: anyhow::Error| {
        if unreadable {
            anyhow::anyhow!(
                "{e:#} (run with --keep-going to make the unreadable group a gap of silence, or \
                 mend its frames first)"
            )
        } else {
            e
        }
    };
    if !journal.exists() {
        return alone(e);
    }
    // The journal is this run's own when it was not there, or when --force (without
    // --resume) started it over; a refused or failed --resume never loses the one it was given.
    let created = !had_journal || (args.force && !args.side.resume);
    let no_sound = matches!(
        e.downcast_ref::<crate::engine::EngineError>(),
        Some(crate::engine::EngineError::NoSound { .. })
    );
    if created && (finished == 0 || no_sound) {
        let _ = std::fs::remove_file(journal);
        return alone(e);
    }
    if finished == 0 {
        return alone(e);
    }
    let how = if unreadable && gone {
        "the same command with --resume goes on from them; add --keep-going to make the group a \
         gap, or put the file back first (where it was a group's last frame, the scan's frame \
         count changed and --resume goes on only once it is back)"
    } else if unreadable {
        "the same command with --resume goes on from them; add --keep-going to make the \
         unreadable group a gap, or mend its frames first"
    } else {
        "the same command with --resume goes on from them"
    };
    anyhow::anyhow!(
        "{e:#} ({finished} finished groups are kept in {}: {how})",
        journal.display()
    )
}

fn finish_message(args: &ReconstructArgs, rec: &Reconstruction, p: &RunProgress) -> Result<()> {
    if args.side.progress_json {
        let line = serde_json::json!({
            "event": "done", "output": args.out.display().to_string(),
            "groups": rec.groups.len(), "elapsed_secs": p.elapsed_secs,
            "groups_per_sec": p.groups_per_sec,
        });
        json_line(&line);
    }
    // Warnings are printed even with --quiet: a gap filled with silence must not pass unseen.
    crate::cli::print_warnings(&rec.warnings);
    if args.quiet {
        return Ok(());
    }
    // After a resume the time and the rate are this run's, so its groups are counted apart.
    let mut groups = format!("{} groups", rec.groups.len());
    if p.resumed_groups > 0 {
        groups += &format!(
            ": {} read back from the journal, {} run",
            p.resumed_groups, p.groups_run
        );
    }
    // The time and the rate from one clock (this run's), so that the one follows from the other.
    let details = format!(
        "{groups} in {:.1} s, {:.1} groups/s",
        p.elapsed_secs, p.groups_per_sec
    );
    let text = crate::cli::wrote_sound(&args.out, &rec.audio, &details);
    let scores = rec.scores.map(|s| format!("vs reference: {}", s.line()));
    for line in std::iter::once(text).chain(scores) {
        if args.side.progress_json {
            crate::tell!("{line}");
        } else {
            crate::say!("{line}")?;
        }
    }
    Ok(())
}
