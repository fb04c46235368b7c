//! The `pack` subcommand: a scan folder converted to a Zarr store and checked.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Result, bail};

use crate::cli::progress_bar;
use crate::io::Scan;
use crate::io::zarr::{DEFAULT_ZSTD_LEVEL, PackOptions, pack_scan};
use crate::job::Job;
use crate::side::scan_fingerprint;

/// Arguments of `pack`.
#[derive(Debug, clap::Args)]
pub struct PackArgs {
    /// Scan folder to convert.
    pub scan: PathBuf,
    /// The Zarr store to write (a new or empty folder, e.g. scan.zarr).
    #[arg(long)]
    pub out: PathBuf,
    /// zstd compression level (1 fastest … 22 smallest).
    #[arg(long, default_value_t = DEFAULT_ZSTD_LEVEL)]
    pub zstd_level: i32,
    /// What to do with an interrupted pack of this output.
    #[command(flatten)]
    pub interrupted: ResumeArgs,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// What a store's writer (`pack`, `import-video` into a store) does with the partial store an
/// interrupted run of the same output left (docs/FORMAT.md, "A store in progress").
#[derive(Clone, Copy, Debug, clap::Args)]
pub struct ResumeArgs {
    /// Go on from an interrupted run writing this store (its partial store beside `--out`)
    /// after the last group it wrote and checked; without one, start.
    #[arg(long, conflicts_with = "force")]
    pub resume: bool,
    /// Remove an interrupted run's partial store of this output and start over.
    #[arg(long)]
    pub force: bool,
}

impl ResumeArgs {
    /// The store options: these flags at zstd `level`, keeping what a stopped run wrote.
    #[must_use]
    pub fn options(self, zstd_level: i32) -> PackOptions {
        PackOptions {
            zstd_level,
            resume: self.resume,
            force: self.force,
        }
    }
}

/// The line of a store writer that stopped: with groups kept, the command line's way on.
pub(crate) fn stopped(e: impl std::fmt::Display, kept: bool) -> anyhow::Error {
    let advice = if kept {
        ": run the same command with --resume to go on"
    } else {
        ""
    };
    anyhow::anyhow!("{e}{advice}")
}

/// Runs `pack`: converts, reads every chunk back, then opens the store as a scan and checks
/// that it is the same scan (metadata, group names, frame counts).
///
/// # Errors
/// An unreadable or irregular scan, an output folder that is not empty, a failed check.
pub fn run_pack(args: &PackArgs) -> Result<()> {
    crate::cli::check_parent_exists(&args.out)?;
    crate::cli::check_folder_outside_scan(&args.out, &args.scan)?;
    if !(1..=22).contains(&args.zstd_level) {
        bail!("--zstd-level must be 1 to 22, got {}", args.zstd_level);
    }
    let scan = Scan::open(&args.scan)?;
    let started = Instant::now();
    let pb = progress_bar(scan.groups.len(), args.quiet);
    let options = args.interrupted.options(args.zstd_level);
    let summary = pack_scan(
        &scan,
        &args.out,
        options,
        Job::reporting(&|done, _| pb.set_position(done as u64)),
    );
    pb.finish_and_clear();
    let summary = summary.map_err(|e| {
        let kept = e.kept.is_some();
        stopped(e, kept)
    })?;
    if summary.resumed > 0 && !args.quiet {
        crate::say!(
            "resumed: {} of {} groups were packed and checked before",
            summary.resumed,
            summary.groups
        )?;
    }
    let packed = Scan::open(&summary.out)?;
    if scan_fingerprint(&packed) != scan_fingerprint(&scan) {
        bail!(
            "the store does not read back as the same scan: {}",
            summary.out.display()
        );
    }
    if !args.quiet {
        let (bytes_in, bytes_stored) = (summary.folder_bytes as f64, summary.store_bytes as f64);
        let details = format!(
            "{:?} samples, {:.1} MB of frames in, {:.1} MB stored, {:.0}%, {:.1} s",
            summary.sample_type,
            bytes_in / 1e6,
            bytes_stored / 1e6,
            100.0 * bytes_stored / bytes_in.max(1.0),
            started.elapsed().as_secs_f64()
        );
        let line = crate::cli::wrote_scan(
            &summary.out,
            summary.groups,
            summary.frames_per_group,
            &details,
        );
        crate::say!("{line}; every chunk read back and checked")?;
    }
    Ok(())
}
