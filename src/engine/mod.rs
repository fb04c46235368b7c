//! Whole-scan reconstruction: streams groups through the stage cache, then finishes and scores the clip.

pub mod stream;

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};

use crate::io::wav::{Audio, read_reference_wav};
use crate::io::{LoadError, Scan, ScanMeta};
use crate::pipeline::audio_signal::{GroupSignal, SignalPack, StitchedSignal, read_from, resample};
use crate::pipeline::eval::{Scores, evaluate};
pub use crate::pipeline::finish::{BRIDGE_GAP_SAMPLES, bridge_short_gaps};
use crate::pipeline::finish::{ClipSignals, FusionReport, finish_method_clip};
use crate::pipeline::slope_reference::{SlopeHistory, SlopeReference};
use crate::pipeline::walls::WallSide;
use crate::pipeline::{
    FlowDetail, GroupInput, Method, PipelineParams, Stage, StageCache, StageError,
};
pub use stream::{GroupOutcome, GroupStream, SlopeMode, check_sample_density, run_groups};

/// What one group adds to the clip's slope history: per wall, its own median |b| from its fits
/// before the clip check. It depends on that group's frames alone.
pub type SlopeEntry = (WallSide, f64);

/// Longest lag searched when scoring against the reference (seconds).
pub const MAX_EVAL_LAG_SECS: f64 = 0.0003;

/// Why a reconstruction failed as a whole.
#[derive(Debug, thiserror::Error)]
pub enum EngineError {
    /// Reading the scan failed.
    #[error(transparent)]
    Load(#[from] LoadError),
    /// A parameter is invalid, or the stitched signal could not be made.
    #[error(transparent)]
    Stage(#[from] StageError),
    /// Writing what the run keeps as it goes (a journal) failed: a full or read-only disk, not
    /// the scan.
    #[error(transparent)]
    Output(LoadError),
    /// The operator cancelled.
    #[error("reconstruction cancelled")]
    Cancelled,
    /// No group produced sound.
    #[error(
        "no group produced any sound by {decoder} ({}): {}",
        first_problem(warnings),
        path.display()
    )]
    NoSound {
        /// The scan folder.
        path: PathBuf,
        /// The decoder that had nothing: "the flow method" or "the edge method".
        decoder: &'static str,
        /// What went wrong per group.
        warnings: Vec<String>,
    },
}

/// The first of a run's per-group problems, for the one line of [`EngineError::NoSound`].
fn first_problem(warnings: &[String]) -> String {
    match warnings {
        [] => "no group reported a problem".into(),
        [only] => only.clone(),
        [first, rest @ ..] => format!("{first}; and {} more", rest.len()),
    }
}

/// Which groups to run and how to treat unreadable ones.
#[derive(Clone, Debug, Default)]
pub struct ReconstructOptions {
    /// Pipeline knobs.
    pub params: PipelineParams,
    /// First group (inclusive) and end group (exclusive); `None` = all.
    pub groups: Option<std::ops::Range<usize>>,
    /// Treat unreadable frames as gaps (a warning) instead of failing.
    pub keep_going: bool,
}

/// Progress of a running reconstruction.
#[derive(Clone, Debug)]
pub struct Progress {
    /// Groups finished so far.
    pub done: usize,
    /// Groups to run.
    pub total: usize,
    /// The group just finished and its signal (None when it failed).
    pub signal: Option<Arc<GroupSignal>>,
}

/// Per-group facts for the report.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GroupReport {
    /// Group index.
    pub group: usize,
    /// Mean outlier fraction of the robust fits (None when the group failed).
    pub outlier_fraction: Option<f64>,
    /// Fits rejected for an implausible wall slope (they became gaps).
    pub rejected_fits: usize,
    /// Samples produced.
    pub samples: usize,
    /// Failure or warning text.
    pub warning: Option<String>,
    /// Pixel noise (σ, grey levels of 255) of the frame the edge stage read the group's coarse
    /// borders on; None where the method reads no edges, the group failed or the frame is too
    /// small to say.
    #[serde(default)]
    pub pixel_noise_grey_levels: Option<f64>,
}

/// Total seconds spent per stage over all groups.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct StageTimings {
    /// Frame loading and grey conversion.
    pub load_secs: f64,
    /// Seconds per [`Stage`], by name.
    pub stages_secs: Vec<(String, f64)>,
    /// Stitching, resampling and DSP.
    pub finish_secs: f64,
    /// Wall-clock total.
    pub total_secs: f64,
}

/// The result of a whole-scan reconstruction.
#[derive(Clone, Debug)]
pub struct Reconstruction {
    /// Final audio at the output rate, after DSP and normalisation.
    pub audio: Audio,
    /// The stitched native-rate signal (velocity, mm/s).
    pub stitched: StitchedSignal,
    /// Per-group report rows.
    pub groups: Vec<GroupReport>,
    /// Stage timings.
    pub timings: StageTimings,
    /// Gain applied to velocity (mm/s) to reach the output level.
    pub gain_per_mm_s: f64,
    /// Scores against `reference.wav`, when the scan has one.
    pub scores: Option<Scores>,
    /// Warnings worth showing (gaps, failed groups).
    pub warnings: Vec<String>,
    /// The method that made the sound.
    pub method: Method,
    /// How the `fused` method weighed the decoders, per group and block (None otherwise).
    pub fusion: Option<FusionReport>,
}

/// Runs one group through the stages its method's sound needs (used by the engine and by
/// benchmarks; [`StageCache::sound_only`]): on the dual-focus path the flow stage gives only the in-focus map ([`FlowDetail::InFocusMap`]),
/// which is all the stripes read. `reference` is the clip's wall-slope reference for this group
/// (the default: none). Returns the cache with every stage that finished, the time each took,
/// and the first stage error (the stages after it have not run).
pub fn run_group(
    input: &GroupInput,
    params: &PipelineParams,
    reference: &SlopeReference,
) -> (StageCache, Vec<Duration>, Result<(), StageError>) {
    let mut cache = StageCache::new(FlowDetail::InFocusMap).sound_only();
    cache.set_slope_reference(reference.clone());
    let mut times = vec![Duration::ZERO; Stage::ALL.len()];
    let mut t0 = Instant::now();
    let ran = cache.run_from(Stage::Derivatives, input, params, &mut |stage, _| {
        times[stage.index()] = t0.elapsed();
        t0 = Instant::now();
        true
    });
    (cache, times, ran)
}

/// Reconstructs the sound of a scan.
///
/// Groups are decoded on a loader thread one group ahead and processed in order (each stage
/// parallel inside), so memory stays at about two groups whatever the scan length.
/// `progress` is called after every group; setting `cancel` stops at the next group.
///
/// # Errors
/// [`EngineError`] on invalid params, an unreadable frame (unless `keep_going`), cancellation,
/// or when no group produced sound.
pub fn reconstruct(
    scan: &Scan,
    opts: &ReconstructOptions,
    progress: &mut dyn FnMut(&Progress),
    cancel: &AtomicBool,
) -> Result<Reconstruction, EngineError> {
    let started = Instant::now();
    let clip = run_clip_groups(scan, opts, progress, cancel)?;
    let mut rec = finish_scan_clip(scan, clip, &opts.params)?;
    rec.timings.total_secs = started.elapsed().as_secs_f64();
    Ok(rec)
}

/// [`finish_reconstruction`] of `scan`'s gathered groups: its metadata, its reference and its
/// folder for the errors.
///
/// # Errors
/// As [`finish_reconstruction`].
pub fn finish_scan_clip(
    scan: &Scan,
    clip: ClipGroups,
    params: &PipelineParams,
) -> Result<Reconstruction, EngineError> {
    finish_reconstruction(
        clip,
        &scan.meta,
        scan.reference.as_deref(),
        params,
        &scan.dir,
    )
}

/// Runs the groups of [`reconstruct`] and gathers them, without the finish: what
/// [`finish_reconstruction`] makes the clip of, with these params or with another `[dsp]`
/// table (only the finish reads it).
///
/// # Errors
/// As [`reconstruct`], but for [`EngineError::NoSound`], which only the finish says.
pub fn run_clip_groups(
    scan: &Scan,
    opts: &ReconstructOptions,
    progress: &mut dyn FnMut(&Progress),
    cancel: &AtomicBool,
) -> Result<ClipGroups, EngineError> {
    let params = &opts.params;
    params.validate_for_clip()?;
    let range = opts.groups.clone().unwrap_or(0..scan.groups.len());
    let range = range.start.min(scan.groups.len())..range.end.min(scan.groups.len());
    let total = range.len();
    let mut clip = ClipGroups::with_capacity(total);
    // Each group's fits are checked against the median wall slope of the groups before it.
    let mut slopes = SlopeHistory::default();
    run_groups(
        &GroupStream {
            scan,
            params,
            keep_going: opts.keep_going,
            mode: SlopeMode::Check,
        },
        range,
        &mut slopes,
        cancel,
        &mut |outcome| {
            let signal = outcome.signal.clone();
            clip.add(outcome);
            progress(&Progress {
                done: clip.groups_seen,
                total,
                signal,
            });
            Ok(())
        },
    )?;
    Ok(clip)
}

/// The groups of a clip gathered in order: signals, report rows, warnings and timings.
#[derive(Clone, Debug, Default)]
pub struct ClipGroups {
    /// The signals of the groups that produced sound, in group order, packed (a long run
    /// holds them all until it is finished).
    pub signals: SignalPack,
    /// The edge stage's border tracks of those groups, in group order (methods that read the
    /// edges), packed.
    pub borders: SignalPack,
    /// Report rows in group order.
    pub reports: Vec<GroupReport>,
    /// Per-group warnings (failed groups), in group order.
    pub warnings: Vec<String>,
    /// Decode seconds, summed.
    pub load_secs: f64,
    /// Seconds per [`Stage`], summed.
    pub stage_secs: Vec<f64>,
    /// Groups added so far.
    pub groups_seen: usize,
}

impl ClipGroups {
    /// Room for `groups` groups.
    #[must_use]
    pub fn with_capacity(groups: usize) -> Self {
        Self {
            signals: SignalPack::with_capacity(groups),
            borders: SignalPack::with_capacity(groups),
            reports: Vec::with_capacity(groups),
            stage_secs: vec![0.0; Stage::ALL.len()],
            ..Self::default()
        }
    }

    /// Bytes its signals and border tracks hold on the heap.
    #[must_use]
    pub fn signal_bytes(&self) -> usize {
        self.signals.heap_bytes() + self.borders.heap_bytes()
    }

    /// Adds the next group's outcome.
    pub fn add(&mut self, outcome: GroupOutcome) {
        self.groups_seen += 1;
        self.load_secs += outcome.load_secs;
        for (acc, t) in self.stage_secs.iter_mut().zip(&outcome.stage_secs) {
            *acc += t;
        }
        if let Some(report) = outcome.report {
            if let Some(w) = &report.warning {
                self.warnings.push(w.clone());
            }
            self.reports.push(report);
        }
        if let Some(sig) = outcome.signal {
            self.signals.push(&sig);
        }
        if let Some(b) = outcome.borders {
            self.borders.push(&b);
        }
    }
}

/// Groove length (µm) of the groups that gave no sound before the first group that did and
/// after the last, from the report rows (one a group, in group order): consecutive groups lie
/// `group_step_um` apart, so the clip extended by these keeps its place and length.
fn silent_ends_um(reports: &[GroupReport], meta: &ScanMeta) -> [f64; 2] {
    let sounded = |r: &&GroupReport| r.samples > 0;
    let (Some(first), Some(last)) = (reports.first(), reports.last()) else {
        return [0.0; 2];
    };
    match (
        reports.iter().find(sounded),
        reports.iter().rev().find(sounded),
    ) {
        (Some(a), Some(b)) => {
            #[allow(clippy::cast_precision_loss)] // group counts
            let um = |groups: usize| groups as f64 * meta.motion.group_step_um;
            [
                um(a.group.saturating_sub(first.group)),
                um(last.group.saturating_sub(b.group)),
            ]
        }
        _ => [0.0; 2],
    }
}

/// Finishes gathered groups into a reconstruction (`pipeline::finish`) and scores it against
/// `reference` when given. `scan_dir` names the scan in errors. `total_secs` is left for the
/// caller to set.
///
/// # Errors
/// [`EngineError::NoSound`] when no group produced sound; [`EngineError::Stage`] when
/// finishing fails.
pub fn finish_reconstruction(
    clip: ClipGroups,
    meta: &ScanMeta,
    reference: Option<&std::path::Path>,
    params: &PipelineParams,
    scan_dir: &std::path::Path,
) -> Result<Reconstruction, EngineError> {
    let ClipGroups {
        signals,
        borders,
        reports,
        mut warnings,
        load_secs,
        stage_secs,
        ..
    } = clip;
    // The decoder the method needs that has nothing (fused needs the edges; without any group
    // of the flow method's it is the edge method, below).
    let (flow, edges) = ("the flow method", "the edge method");
    let silent = match params.method {
        Method::Flow => signals.is_empty().then_some(flow),
        Method::Edges | Method::Fused => borders.is_empty().then_some(edges),
    };
    if let Some(decoder) = silent {
        return Err(EngineError::NoSound {
            path: scan_dir.to_path_buf(),
            decoder,
            warnings,
        });
    }
    let mut timings = StageTimings {
        load_secs,
        stages_secs: Stage::ALL
            .iter()
            .zip(&stage_secs)
            .map(|(s, t)| (s.name().to_string(), *t))
            .collect(),
        ..StageTimings::default()
    };
    let t_finish = Instant::now();
    // A fused clip whose every group the flow method lost (each read by the edges alone) has
    // nothing to fuse: it is the edge method's clip, and says so.
    let edges_alone;
    let params = if params.method == Method::Fused && signals.is_empty() {
        warnings.push(
            "the flow method gave no group any sound: the edges alone made the clip \
             (method edges)"
                .into(),
        );
        edges_alone = PipelineParams {
            method: Method::Edges,
            ..params.clone()
        };
        &edges_alone
    } else {
        params
    };
    let rejected: usize = reports.iter().map(|r| r.rejected_fits).sum();
    if rejected > 0 {
        warnings.push(format!(
            "{rejected} orientation fits rejected for an implausible wall slope (left as gaps)"
        ));
    }
    let finished = finish_method_clip(
        ClipSignals {
            flow: signals,
            borders,
            silent_ends_um: silent_ends_um(&reports, meta),
        },
        meta,
        params,
    )?;
    warnings.extend(finished.warnings);
    let audio = Audio {
        sample_rate_hz: finished.sample_rate_hz,
        channels: finished.channels,
    };
    let stitched = finished.stitched;
    timings.finish_secs = t_finish.elapsed().as_secs_f64();
    let scores = match reference {
        Some(path) => score_against_reference(
            &audio,
            &stitched,
            meta.groove_speed_mm_s(0),
            path,
            &mut warnings,
        ),
        None => None,
    };
    // Samples past the last group's step lie in its frames' overlap, not in a group of their
    // own: the fusion report lists the clip's groups only.
    let clip_groups =
        reports.first().map_or(0, |r| r.group)..=reports.last().map_or(0, |r| r.group);
    let fusion = finished.fusion.map(|mut f| {
        f.groups.retain(|g| clip_groups.contains(&g.group));
        f
    });
    Ok(Reconstruction {
        audio,
        stitched,
        groups: reports,
        timings,
        gain_per_mm_s: finished.gain_per_mm_s,
        scores,
        warnings,
        method: params.method,
        fusion,
    })
}

/// Seconds of the reference kept past the clip's end before it is resampled (far more than
/// the resampler's filter and the scores' lag search reach, so the clip's stretch comes out the
/// same as from the whole reference).
const REFERENCE_TAIL_SECS: f64 = 10.0;
/// Most samples a reference is resampled to for scoring (23 min at 48 kHz): a reference that
/// needs more, because the clip starts that far into it, is not scored.
const MAX_RESAMPLED_REFERENCE: f64 = (1u64 << 26) as f64;

/// Reference sound aligned to the stretch a reconstruction covers, at the recovered rate, and
/// how many channels the file has (more than one are mixed to mono to give it).
///
/// Only the reference up to 10 s (`REFERENCE_TAIL_SECS`) past the clip's end is resampled: a long
/// reference at a low rate (a hostile or mislabelled `reference.wav`: a few thousand samples
/// "at 1 Hz") would otherwise be resampled whole, to hours of sound.
///
/// # Errors
/// [`LoadError`] when the reference cannot be read or resampled, or the clip starts too far
/// into it.
pub fn aligned_reference(
    recovered: &Audio,
    stitched: &StitchedSignal,
    groove_speed_mm_s: f64,
    path: &std::path::Path,
) -> Result<(Vec<f32>, usize), LoadError> {
    let reference = read_reference_wav(path)?;
    let mono = reference.mono();
    let rate = f64::from(reference.sample_rate_hz);
    let start_secs = stitched.start_um / (groove_speed_mm_s * 1000.0);
    // The whole reference at the recovered rate, read from the clip's start, which may fall
    // between samples (rounding it to a reference sample misaligned the scores by up to half a
    // sample: up to 10 µs at 48 kHz, −18 dB of error at 2 kHz).
    let out_rate = f64::from(recovered.sample_rate_hz);
    let end_secs = start_secs + recovered.duration_secs() + REFERENCE_TAIL_SECS;
    let keep = if end_secs.is_finite() {
        ((end_secs * rate).ceil().max(0.0) as usize).min(mono.len())
    } else {
        mono.len()
    };
    let needed = keep as f64 * out_rate / rate;
    if needed.is_nan() || needed > MAX_RESAMPLED_REFERENCE {
        return Err(LoadError::Sound {
            problem: format!(
                "the clip starts {start_secs:.0} s into the reference, which would take \
                 {needed:.3e} samples at {out_rate} Hz to score (at most \
                 {MAX_RESAMPLED_REFERENCE:.3e})"
            ),
            path: path.to_path_buf(),
        });
    }
    let resampled = resample(
        mono.get(..keep).unwrap_or(&[]),
        rate,
        recovered.sample_rate_hz,
    )
    .map_err(|e| LoadError::Sound {
        problem: format!("cannot resample the reference: {e}"),
        path: path.to_path_buf(),
    })?;
    Ok((
        read_from(
            &resampled,
            (start_secs * f64::from(recovered.sample_rate_hz)).max(0.0),
        ),
        reference.channels.len(),
    ))
}

fn score_against_reference(
    audio: &Audio,
    stitched: &StitchedSignal,
    groove_speed_mm_s: f64,
    path: &std::path::Path,
    warnings: &mut Vec<String>,
) -> Option<Scores> {
    match aligned_reference(audio, stitched, groove_speed_mm_s, path) {
        Ok((reference, channels)) => {
            if channels > 1 {
                warnings.push(format!(
                    "{} has {channels} channels: scored as their mono mix against the clip's \
                     (groovescope eval scores a stereo transfer channel by channel)",
                    path.display()
                ));
            }
            let max_lag = (MAX_EVAL_LAG_SECS * f64::from(audio.sample_rate_hz)) as usize;
            let scores = evaluate(&audio.mono(), &reference, max_lag, audio.sample_rate_hz);
            if scores.is_none() {
                warnings.push("too little overlap with reference.wav to score".into());
            }
            scores
        }
        Err(e) => {
            warnings.push(format!("reference not scored: {e}"));
            None
        }
    }
}
