//! One shard of a plan: its range run (after the groups before it, for the slope history) to a part folder with its report.

use std::path::Path;

use anyhow::{Result, bail};
use serde::Serialize;

use super::{
    RunProgress, after_failure, check_missing_groups, check_params_fit_scan, json_line,
    lock_outputs, run_with_progress,
};
use crate::cli::{ReconstructArgs, load_params, method_choice, path_choice};
use crate::io::{Scan, write_json_atomic};
use crate::side::part::{PART_FILE, read_part, write_part};
use crate::side::plan::Plan;
use crate::side::run::RangeRun;
use crate::side::{RunIdentity, params_fingerprint};

/// The shard's report beside its part.
#[derive(Debug, Serialize)]
struct ShardReport<'a> {
    version: &'static str,
    scan: &'a str,
    plan: String,
    shard: usize,
    shards: usize,
    groups: (usize, usize),
    progress: RunProgress,
    load_secs: f64,
    warnings: Vec<String>,
}

/// Runs shard `index` of the plan at `plan_path` into the part folder `args.out`.
pub(super) fn run_shard(args: &ReconstructArgs, plan_path: &Path, index: usize) -> Result<()> {
    // --out is the part folder the shard makes and fills: anywhere in the scan (the scan
    // itself, a group's folder, a new folder beside the groups, which would read as a group,
    // or in a store) it would alter the scan, --force or not.
    crate::cli::check_folder_outside_scan(&args.out, &args.scan)?;
    crate::cli::check_parent_exists(&args.out)?;
    let plan = Plan::load(plan_path)?;
    let params = if args.params.is_none() && args.path == "auto" && args.method.is_none() {
        plan.params.clone()
    } else {
        let mut p = load_params(args.params.as_deref())?;
        p.path = path_choice(&args.path, plan.params.path);
        p.method = method_choice(args.method.as_deref(), plan.params.method);
        if params_fingerprint(&p) != plan.params_fingerprint {
            bail!(
                "--params/--path/--method give other params than the plan's (leave them out to run the plan's): {}",
                plan_path.display()
            );
        }
        p
    };
    // A shard stopped by an unreadable group goes on past it with --keep-going, as a whole run
    // does: the merge takes parts with and without it (those without hold no such gap).
    let keep_going = plan.keep_going || args.keep_going;
    if args.first_group.is_some() || args.groups.is_some() {
        bail!("--first-group/--groups do not go with --plan: the plan gives the shard's groups");
    }
    if args.report.is_some() || args.bits.is_some() {
        bail!(
            "--report/--bits do not go with --plan: a shard writes its part, and merge writes the side's WAV and report (give them to merge)"
        );
    }
    let scan = Scan::open(&args.scan)?;
    check_params_fit_scan(&params, &scan, Some(plan_path))?;
    let (shard, id) = plan.shard(index, &scan, plan_path)?;
    let range = shard.first_group..shard.end_group;
    check_missing_groups(&scan, range.clone(), keep_going)?;
    let identity = RunIdentity::new(&scan, &params, keep_going, range.clone(), Some(id));
    let made_folder = !args.out.exists();
    std::fs::create_dir_all(&args.out).map_err(|e| {
        anyhow::anyhow!("cannot create the part folder: {e}: {}", args.out.display())
    })?;
    let part_path = args.out.join(PART_FILE);
    let lock = lock_outputs(&[part_path.as_path()])?;
    let journal = args.out.join("journal");
    if part_path.exists() && !args.force {
        if args.side.resume
            && read_part(&args.out).is_ok_and(|p| identity.difference(&p.identity).is_none())
        {
            // A journal left beside a complete part (its removal failed) is spent.
            let _ = std::fs::remove_file(&journal);
            if !args.quiet {
                crate::tell!("shard {index} is already complete: {}", part_path.display());
            }
            return Ok(());
        }
        bail!(
            "refusing to overwrite an existing part (use --force): {}",
            part_path.display()
        );
    }
    let run = RangeRun {
        scan: &scan,
        params: &params,
        keep_going,
        range: range.clone(),
        shard: true,
        journal: &journal,
        identity: identity.clone(),
        resume: args.side.resume,
        force: args.force,
    };
    let had_journal = journal.exists();
    let mut groups = Vec::with_capacity(range.len());
    let (result, mut run_progress) = match run_with_progress(&run, args, &mut |g| groups.push(g)) {
        Ok(done) => done,
        Err(e) => {
            let e = after_failure(e, &journal, had_journal, args, groups.len(), keep_going);
            // A part folder this run made and left empty (no journal kept) goes too, with its
            // lock, so the failed shard leaves nothing.
            drop(lock);
            if made_folder {
                let _ = std::fs::remove_dir(&args.out);
            }
            return Err(e);
        }
    };
    run_progress.context_groups = result.context_groups;
    let report = ShardReport {
        version: env!("CARGO_PKG_VERSION"),
        scan: &identity.scan,
        plan: plan_path.display().to_string(),
        shard: index,
        shards: plan.shards.len(),
        groups: identity.groups,
        progress: run_progress.clone(),
        load_secs: groups.iter().map(|g| g.load_secs).sum(),
        warnings: groups
            .iter()
            .filter_map(|g| g.report.as_ref().and_then(|r| r.warning.clone()))
            .collect(),
    };
    // The report before the part: the part marks the shard complete, so a report that cannot
    // be written (a full disk) leaves the shard to --resume from its journal, not a part that
    // --resume called complete without a report. A failure here, after the groups ran, says
    // what is kept and how to go on, as a failure among the groups does.
    let finish = || -> Result<std::path::PathBuf> {
        write_json_atomic(&args.out.join("report.json"), &report, true)?;
        let written = write_part(&args.out, &identity, &groups, args.force)?;
        result.journal.remove()?;
        Ok(written)
    };
    let written = finish()
        .map_err(|e| after_failure(e, &journal, had_journal, args, groups.len(), keep_going))?;
    // The groups' warnings as a whole run prints them, even with --quiet: a gap filled with
    // silence must not pass unseen until the merge.
    crate::cli::print_warnings(&report.warnings);
    let text = format!(
        "wrote {} (shard {index} of {}: groups {}..{}, {} run before them for the slope history, {:.1} s, {:.1} groups/s)",
        written.display(),
        plan.shards.len(),
        range.start,
        range.end,
        run_progress.context_groups,
        run_progress.elapsed_secs,
        run_progress.groups_per_sec
    );
    if args.side.progress_json {
        json_line(&serde_json::json!({"event": "done", "output": written.display().to_string()}));
        crate::tell!("{text}");
    } else if !args.quiet {
        crate::say!("{text}")?;
    }
    Ok(())
}
