//! The `import-video` subcommand: its arguments and handler (progress bar, one summary line).
//!
//! The subcommand is always listed; a binary built without the `video` feature answers it with one
//! line saying so and exits with failure.

use std::path::PathBuf;

use anyhow::Result;

/// Arguments of `import-video`.
#[derive(Debug, clap::Args)]
pub struct ImportVideoArgs {
    /// The clip (AVI, MP4, MKV, … anything this FFmpeg decodes).
    pub clip: PathBuf,
    /// Output scan folder (must not exist or be empty).
    #[arg(long)]
    pub out: PathBuf,
    /// Frames in each group (at least 7).
    #[arg(long, default_value_t = 12)]
    pub frames_per_group: usize,
    /// Frames between the first frames of consecutive groups (default: --frames-per-group, no
    /// shared frames; smaller repeats frames, larger skips them).
    #[arg(long)]
    pub group_stride: Option<usize>,
    /// Clip frames to skip before the first group.
    #[arg(long, default_value_t = 0)]
    pub first_frame: usize,
    /// Write at most this many groups.
    #[arg(long)]
    pub max_groups: Option<usize>,
    /// Turntable speed the disc was cut at.
    #[arg(long, allow_hyphen_values = true)]
    pub rpm: f64,
    /// Groove radius at the first group, mm.
    #[arg(long, allow_hyphen_values = true)]
    pub radius_mm: f64,
    /// Cut type.
    #[arg(long, value_parser = ["lateral", "stereo", "vertical"], default_value = "lateral")]
    pub cut: String,
    /// Size of one pixel on the land plane, µm.
    #[arg(long, allow_hyphen_values = true)]
    pub pixel_pitch_um: f64,
    /// Optical centre to the land plane, mm.
    #[arg(long, allow_hyphen_values = true)]
    pub working_distance_mm: f64,
    /// Record travel between consecutive frames, µm.
    #[arg(long, allow_hyphen_values = true)]
    pub frame_step_um: f64,
    /// Travel between the first frames of consecutive groups, µm (default: stride × frame step).
    #[arg(long, allow_hyphen_values = true)]
    pub group_step_um: Option<f64>,
    /// Write a Zarr store (one zstd chunk per group, see `groovescope pack`) instead of a scan
    /// folder, group by group as the clip is decoded; also chosen by an --out name ending in
    /// `.zarr`.
    #[arg(long)]
    pub zarr: bool,
    /// What to do with an interrupted import into this store.
    #[command(flatten)]
    pub interrupted: crate::pack_cli::ResumeArgs,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// Runs `import-video`.
///
/// # Errors
/// One line naming the clip or folder and the problem; without the `video` feature, always.
#[cfg(feature = "video")]
pub fn run_import_video(args: &ImportVideoArgs) -> Result<()> {
    use indicatif::{ProgressBar, ProgressStyle};

    use crate::io::Cut;
    use crate::io::video::{ClipMeta, GroupLayout, import_video, import_video_to_store};
    use crate::io::zarr::DEFAULT_ZSTD_LEVEL;
    use crate::job::Job;

    crate::cli::check_parent_exists(&args.out)?;
    let cut = match args.cut.as_str() {
        "stereo" => Cut::Stereo,
        "vertical" => Cut::Vertical,
        _ => Cut::Lateral,
    };
    let layout = GroupLayout {
        frames_per_group: args.frames_per_group,
        group_stride_frames: args.group_stride,
        first_frame: args.first_frame,
        max_groups: args.max_groups,
    };
    let meta = ClipMeta {
        rpm: args.rpm,
        radius_mm: args.radius_mm,
        cut,
        pixel_pitch_um: args.pixel_pitch_um,
        working_distance_mm: args.working_distance_mm,
        frame_step_um: args.frame_step_um,
        group_step_um: args.group_step_um,
    };
    let pb = if args.quiet {
        ProgressBar::hidden()
    } else {
        let pb = ProgressBar::new(0);
        if let Ok(style) = ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {bar:40} {pos}/{len} frames ({per_sec}, ETA {eta})",
        ) {
            pb.set_style(style);
        }
        pb
    };
    let progress = |done: usize, total: usize| {
        pb.set_length(total as u64);
        pb.set_position(done as u64);
    };
    let zarr = args.zarr || args.out.extension().is_some_and(|e| e == "zarr");
    if !zarr && (args.interrupted.resume || args.interrupted.force) {
        anyhow::bail!(
            "--resume and --force are for an import into a Zarr store (--zarr, or --out NAME.zarr); \
             an import into a folder starts afresh: {}",
            args.out.display()
        );
    }
    let summary = if zarr {
        // Straight into the store, group by group, resumable.
        let options = args.interrupted.options(DEFAULT_ZSTD_LEVEL);
        let job = Job::reporting(&progress);
        import_video_to_store(&args.clip, &args.out, &layout, &meta, options, job).map_err(|e| {
            let kept = matches!(e, crate::io::video::VideoError::Kept { .. });
            crate::pack_cli::stopped(e, kept)
        })?
    } else {
        import_video(
            &args.clip,
            &args.out,
            &layout,
            &meta,
            Job::reporting(&progress),
        )?
    };
    pb.finish_and_clear();
    if summary.resumed_groups > 0 && !args.quiet {
        crate::say!(
            "resumed: {} of {} groups were written and checked before",
            summary.resumed_groups,
            summary.groups
        )?;
    }
    if !args.quiet {
        let details = format!(
            "stride {}, {}x{} {}-bit grey, {} frames decoded, {}",
            summary.group_stride_frames,
            summary.width,
            summary.height,
            summary.bit_depth,
            summary.frames_decoded,
            summary.codec
        );
        crate::say!(
            "{}",
            crate::cli::wrote_scan(
                &summary.out_dir,
                summary.groups,
                summary.frames_per_group,
                &details
            )
        )?;
    }
    for path in &summary.removed_stale {
        crate::tell!(
            "removed an unfinished import left by an earlier, killed run: {}",
            path.display()
        );
    }
    Ok(())
}

/// Runs `import-video`: this build has no video support, so it says so.
///
/// # Errors
/// Always.
#[cfg(not(feature = "video"))]
pub fn run_import_video(args: &ImportVideoArgs) -> Result<()> {
    let _ = args;
    anyhow::bail!(
        "this groovescope was built without video support; rebuild with `cargo build --features video` (needs the FFmpeg dev packages)"
    )
}
