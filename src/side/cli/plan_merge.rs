//! The `plan` and `merge` subcommands.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Result;

use super::{lock_outputs, make_report};
use crate::cli::check_outputs;
use crate::cli::{load_params, path_choice, unless_interrupted};
use crate::engine::{GroupOutcome, GroupStream, SlopeMode, run_groups};
use crate::io::wav::{WavBits, write_transfer_wav};
use crate::io::{Scan, ScanMeta, write_json_atomic};
use crate::job::interrupted;
use crate::pipeline::PipelineParams;
use crate::pipeline::dsp::DspParams;
use crate::pipeline::slope_reference::SlopeHistory;
use crate::side::merge::{merge_checked, read_parts};
use crate::side::plan::Plan;

/// Arguments of `plan`.
#[derive(Debug, clap::Args)]
pub struct PlanArgs {
    /// Scan folder or Zarr store.
    pub scan: PathBuf,
    /// Number of shards.
    #[arg(long)]
    pub shards: usize,
    /// The plan file to write.
    #[arg(long, default_value = "plan.json")]
    pub out: PathBuf,
    /// Parameters TOML every shard runs with.
    #[arg(long)]
    pub params: Option<PathBuf>,
    /// Force a path instead of choosing by the `[dual_focus]` table.
    #[arg(long, value_parser = ["auto", "depth", "dual-focus"], default_value = "auto")]
    pub path: String,
    /// Treat unreadable frames as silent gaps instead of failing.
    #[arg(long)]
    pub keep_going: bool,
    /// Groups run here to measure the time per group, the first as a warm-up (0: no estimate).
    #[arg(long, default_value_t = 3)]
    pub probe_groups: usize,
    /// Print the Slurm commands that submit the shards and the merge.
    #[arg(long)]
    pub slurm: bool,
    /// Folder of the parts, for the printed Slurm commands.
    #[arg(long, default_value = "parts")]
    pub parts: PathBuf,
    /// Replace an existing plan file.
    #[arg(long)]
    pub force: bool,
}

/// Arguments of `merge`.
#[derive(Debug, clap::Args)]
pub struct MergeArgs {
    /// Part folders (or their part.gsp files), one per shard, in any order.
    #[arg(required = true)]
    pub parts: Vec<PathBuf>,
    /// Output WAV file.
    #[arg(long)]
    pub out: PathBuf,
    /// JSON report.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// WAV sample format: 16, 24 or 32f.
    #[arg(long, default_value = "24")]
    pub bits: WavBits,
    /// Finish with the keys of this TOML's `[dsp]` table (EQ, low-pass, DC block) in place of
    /// the parts': an access copy with a playback curve from the same parts, no group run
    /// again. Only `[dsp]`: the other tables set how the groups were made.
    #[arg(long)]
    pub dsp: Option<PathBuf>,
    /// Replace existing output files.
    #[arg(long)]
    pub force: bool,
    /// No summary line (warnings still go to stderr).
    #[arg(long)]
    pub quiet: bool,
}

/// The parts' `[dsp]` table with the keys of `file`'s in place of theirs (see
/// [`MergeArgs::dsp`]), checked against the parts' output rate.
///
/// # Errors
/// One line naming `file`: unreadable, a table other than `[dsp]`, a bad key or value.
fn finish_dsp(parts: &PipelineParams, file: &Path) -> Result<DspParams> {
    let what = "DSP settings";
    let text = crate::io::limits::read_toml_text(file, what)?;
    // Another params table ([flow], [edges], …), with or without a [dsp] beside it; or, beside
    // a [dsp] table, a top-level key (`method`, …), which the overlay would otherwise drop
    // unread (without the table, top-level keys are read as [dsp]'s and an unknown one named).
    if let Ok(table) = toml::from_str::<toml::Table>(&text) {
        let has_dsp = table.get("dsp").is_some_and(toml::Value::is_table);
        let other = table
            .iter()
            .find(|(k, v)| *k != "dsp" && (v.is_table() || has_dsp))
            .map(|(k, v)| (k, v.is_table()));
        if let Some((other, is_table)) = other {
            let what_it_is = if is_table {
                format!(
                    "`{other}`, which sets how the groups were made (run the plan again to change it)"
                )
            } else {
                // `key_at` gives `KEY (line N)`: the key quoted, its line after.
                let at = crate::toml_error::key_at(&text, None, other);
                let line = at.strip_prefix(other.as_str()).unwrap_or("");
                format!(
                    "`{other}`{line} outside it, which merge cannot use (the finish takes only \
                     the [dsp] table's keys; the others set how the groups were made)"
                )
            };
            anyhow::bail!(
                "invalid {what}: merge --dsp takes only a [dsp] table (the finish's filters), \
                 not {what_it_is}: {}",
                file.display()
            );
        }
    }
    let dsp = crate::cli::overlay_toml(&parts.dsp, file, "dsp", what, |d| d.validate())?;
    crate::pipeline::dsp::check_chain(f64::from(parts.sound.output_rate_hz), &dsp)
        .map_err(|e| anyhow::anyhow!("{e}: {}", file.display()))?;
    Ok(dsp)
}

/// Runs `merge`.
///
/// # Errors
/// A refused part (named), or a write failure.
pub fn run_merge(args: &MergeArgs) -> Result<()> {
    let outputs: Vec<&Path> = std::iter::once(args.out.as_path())
        .chain(args.report.as_deref())
        .collect();
    let part_files: Vec<PathBuf> = args
        .parts
        .iter()
        .map(|p| crate::side::part::part_file(p))
        .collect();
    let inputs: Vec<&Path> = part_files.iter().map(PathBuf::as_path).collect();
    check_outputs(&outputs, &inputs, args.force)?;
    let _locks = lock_outputs(&outputs)?;
    let started = Instant::now();
    let parts = read_parts(&args.parts)?;
    let dsp = match (&args.dsp, parts.first()) {
        (Some(file), Some(first)) => Some(finish_dsp(&first.identity.params, file)?),
        _ => None,
    };
    let merged = unless_interrupted("merge", merge_checked(parts, dsp, interrupted()))?;
    let mut rec = merged.reconstruction;
    rec.timings.total_secs = started.elapsed().as_secs_f64();
    let identity = &merged.identity;
    let first_part = merged
        .parts
        .first()
        .map_or(Path::new("."), PathBuf::as_path);
    let meta = ScanMeta::from_toml_str(&identity.meta_toml, first_part)?;
    let info = super::transfer_info(
        &meta,
        &identity.params,
        &rec,
        (&identity.scan_fingerprint, &identity.params_fingerprint),
        (&rec.audio, args.bits),
    );
    write_transfer_wav(&args.out, &rec.audio, args.bits, args.force, &info)?;
    if let Some(report_path) = &args.report {
        let report = make_report(
            Path::new(&merged.identity.scan),
            &meta,
            &args.out,
            None,
            &merged.identity.params,
            &rec,
        );
        crate::cli::undo_first_on_error(
            &args.out,
            write_json_atomic(report_path, &report, args.force).map_err(Into::into),
        )?;
    }
    crate::cli::print_warnings(&rec.warnings);
    if !args.quiet {
        let details = format!(
            "from {} parts, {} groups",
            merged.parts.len(),
            rec.groups.len()
        );
        crate::say!(
            "{}",
            crate::cli::wrote_sound(&args.out, &rec.audio, &details)
        )?;
        if let Some(s) = &rec.scores {
            crate::say!("vs reference: {}", s.line())?;
        }
    }
    Ok(())
}

/// Seconds per group measured on the first `groups` groups of `scan`, decode included, over
/// the groups that gave sound, the first left out as a warm-up ([`steady_secs_per_group`]);
/// None when none did.
fn probe_secs_per_group(
    scan: &Scan,
    params: &PipelineParams,
    keep_going: bool,
    groups: usize,
) -> Result<Option<(f64, String)>> {
    let n = groups.min(scan.groups.len());
    if n == 0 {
        return Ok(None);
    }
    let started = Instant::now();
    let mut slopes = SlopeHistory::default();
    // Per group, in order: seconds from the start to when it finished, and whether it gave
    // sound.
    let mut done: Vec<(f64, bool)> = Vec::with_capacity(n);
    run_groups(
        &GroupStream {
            scan,
            params,
            keep_going,
            mode: SlopeMode::Check,
        },
        0..n,
        &mut slopes,
        interrupted(),
        &mut |o: GroupOutcome| {
            done.push((started.elapsed().as_secs_f64(), o.signal.is_some()));
            Ok(())
        },
    )?;
    let threads = rayon::current_num_threads();
    Ok(steady_secs_per_group(&done).map(|(secs, basis)| {
        (
            secs,
            format!("{basis}, run here with {threads} threads, decode included"),
        )
    }))
}

/// Seconds per group from when each probe group finished (seconds from the start, in order)
/// and whether it gave sound, with the groups timed in words; None when none gave sound.
///
/// With two or more groups the clock starts when the first is done: it pays the start-up
/// (threads, buffers, the first reads), which a shard pays once. A group that failed (a gap
/// under --keep-going) is not counted: most fail when read, at next to no cost, and counted
/// they would make the side look faster; one that fails late spreads its time over the others,
/// which errs slow.
fn steady_secs_per_group(done: &[(f64, bool)]) -> Option<(f64, String)> {
    let sound = |d: &[(f64, bool)]| d.iter().filter(|(_, s)| *s).count();
    let n = done.len();
    let end = done.last()?.0;
    let (secs, timed, basis) = match done.split_first() {
        Some((&(first_done, _), rest)) if sound(rest) > 0 => (
            end - first_done,
            rest,
            format!("groups 1..{n} timed after group 0 (a warm-up)"),
        ),
        _ => (end, done, format!("groups 0..{n}")),
    };
    let ran = sound(timed);
    if ran == 0 {
        return None;
    }
    let failed = timed.len() - ran;
    let basis = if failed == 0 {
        basis
    } else {
        format!("{basis}, over the {ran} that gave sound ({failed} failed)")
    };
    Some((secs / ran as f64, basis))
}

/// Runs `plan`.
///
/// # Errors
/// An unreadable scan or params, a shard count out of range, an existing plan file.
pub fn run_plan(args: &PlanArgs) -> Result<()> {
    let inputs: Vec<&Path> = args.params.as_deref().into_iter().collect();
    crate::cli::check_outside_scan(&[args.out.as_path()], &args.scan)?;
    check_outputs(&[args.out.as_path()], &inputs, args.force)?;
    // The output's lock, as reconstruct and merge take theirs: a second plan writing the same
    // file is refused, and a folder that cannot be written is named now, before the scan is
    // opened and the probe runs its groups (minutes on a side), not when the plan is written.
    let _lock = lock_outputs(&[args.out.as_path()])?;
    let mut params = load_params(args.params.as_deref())?;
    params.path = path_choice(&args.path, params.path);
    let scan = Scan::open(&args.scan)?;
    super::check_missing_groups(&scan, 0..scan.groups.len(), args.keep_going)?;
    // Checked here too: with --probe-groups 0 no group runs before the shards would fail.
    super::check_params_fit_scan(&params, &scan, args.params.as_deref())?;
    // Also what stops a plan that Ctrl-C reached while its scan was opened (or with no probe).
    let probe = unless_interrupted(
        "plan",
        probe_secs_per_group(&scan, &params, args.keep_going, args.probe_groups),
    )?;
    let plan = Plan::new(&scan, &params, args.keep_going, args.shards, probe)?;
    write_json_atomic(&args.out, &plan, args.force)?;
    crate::say!(
        "wrote {} ({} groups in {} shards; each also runs up to {} groups before its range)",
        args.out.display(),
        plan.groups,
        plan.shards.len(),
        plan.context_groups
    )?;
    if let Some(s) = plan.secs_per_group {
        crate::say!("{s:.4} s a group ({})", plan.secs_per_group_basis)?;
    }
    for s in &plan.shards {
        let eta = s.expected_secs.map_or_else(
            || "not estimated".to_string(),
            |t| format!("about {}", human_secs(t)),
        );
        crate::say!(
            "  shard {:>3}: groups {}..{} (from {} with context), {eta}",
            s.index,
            s.first_group,
            s.end_group,
            s.context_first_group
        )?;
    }
    if args.slurm {
        let last = plan.shards.len() - 1;
        let parts = crate::stdout::shell_quoted(&args.parts);
        crate::say!(
            "# submit the shards as a job array, then the merge once every shard has finished:\n\
             jid=$(sbatch --parsable --array=0-{last} scripts/slurm/reconstruct-side.sbatch {} {} {parts})\n\
             sbatch --dependency=afterok:$jid scripts/slurm/merge-side.sbatch {parts} side.wav",
            crate::stdout::shell_quoted(&scan.dir),
            crate::stdout::shell_quoted(&args.out),
        )?;
    }
    Ok(())
}

/// `s` as "1 h 05 min", "3 min 20 s" or "4.2 s".
fn human_secs(s: f64) -> String {
    if s >= 3600.0 {
        format!(
            "{} h {:02} min",
            (s / 3600.0) as u64,
            ((s % 3600.0) / 60.0) as u64
        )
    } else if s >= 60.0 {
        format!("{} min {:02} s", (s / 60.0) as u64, (s % 60.0) as u64)
    } else {
        format!("{s:.1} s")
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;

    #[test]
    fn the_probe_times_the_groups_after_the_first() {
        // Group 0 pays the start-up (0.5 s); the others take 0.1 s each.
        let (secs, basis) =
            steady_secs_per_group(&[(0.5, true), (0.6, true), (0.7, true)]).unwrap();
        assert!((secs - 0.1).abs() < 1e-12, "{secs}");
        assert_eq!(basis, "groups 1..3 timed after group 0 (a warm-up)");
        // A failed group after the first is not counted, its time is.
        let (secs, basis) =
            steady_secs_per_group(&[(0.5, true), (0.51, false), (0.7, true)]).unwrap();
        assert!((secs - 0.2).abs() < 1e-12, "{secs}");
        assert!(
            basis.ends_with("over the 1 that gave sound (1 failed)"),
            "{basis}"
        );
        // One group, or none after the first with sound: the whole time.
        let (secs, basis) = steady_secs_per_group(&[(0.5, true)]).unwrap();
        assert!(
            (secs - 0.5).abs() < 1e-12 && basis == "groups 0..1",
            "{secs} {basis}"
        );
        let (secs, _) = steady_secs_per_group(&[(0.5, true), (0.51, false)]).unwrap();
        assert!((secs - 0.51).abs() < 1e-12, "{secs}");
        assert!(steady_secs_per_group(&[(0.5, false), (0.6, false)]).is_none());
        assert!(steady_secs_per_group(&[]).is_none());
    }
}
