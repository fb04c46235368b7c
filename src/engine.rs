//! Whole-scan reconstruction: streams groups through the stage cache, stitches, resamples, filters and scores.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use serde::Serialize;

use crate::io::wav::{Audio, read_wav};
use crate::io::{LoadError, Scan, load_group_frames};
use crate::pipeline::audio_signal::{GroupSignal, StitchedSignal, resample, stitch};
use crate::pipeline::dsp::apply_dsp;
use crate::pipeline::eval::{Scores, evaluate};
use crate::pipeline::frames_read;
use crate::pipeline::sampling::native_spacing_um;
use crate::pipeline::slope_reference::{SlopeHistory, SlopeReference};
use crate::pipeline::{FlowDetail, GroupInput, PipelineParams, Stage, StageCache, StageError};

/// Longest lag searched when scoring against the reference (seconds).
pub const MAX_EVAL_LAG_SECS: f64 = 0.0003;
/// Gaps up to this many native samples are bridged by linear interpolation; longer ones stay silent.
pub const BRIDGE_GAP_SAMPLES: usize = 4;

/// Why a reconstruction failed as a whole.
#[derive(Debug, thiserror::Error)]
pub enum EngineError {
    /// Reading the scan failed.
    #[error(transparent)]
    Load(#[from] LoadError),
    /// A parameter is invalid, or the stitched signal could not be made.
    #[error(transparent)]
    Stage(#[from] StageError),
    /// The operator cancelled.
    #[error("reconstruction cancelled")]
    Cancelled,
    /// No group produced sound.
    #[error("no group produced any sound (see the per-group warnings): {}", path.display())]
    NoSound {
        /// The scan folder.
        path: PathBuf,
        /// What went wrong per group.
        warnings: Vec<String>,
    },
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
#[derive(Clone, Debug, Serialize)]
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
}

/// Total seconds spent per stage over all groups.
#[derive(Clone, Debug, Default, Serialize)]
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
}

/// Runs one group through every stage for its sound (used by the engine and by benchmarks):
/// on the dual-focus path the flow stage gives only the in-focus map ([`FlowDetail::InFocusMap`]),
/// which is all the stripes read. `reference` is the clip's wall-slope reference for this group
/// (the default: none).
///
/// # Errors
/// The first stage error.
pub fn run_group(
    input: &GroupInput,
    params: &PipelineParams,
    reference: &SlopeReference,
) -> Result<(StageCache, Vec<Duration>), StageError> {
    let mut cache = StageCache::new(FlowDetail::InFocusMap);
    cache.set_slope_reference(reference.clone());
    let mut times = vec![Duration::ZERO; Stage::ALL.len()];
    let mut t0 = Instant::now();
    cache.run_from(Stage::Derivatives, input, params, &mut |stage, _| {
        times[stage.index()] = t0.elapsed();
        t0 = Instant::now();
        true
    })?;
    Ok((cache, times))
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
    let params = &opts.params;
    params.validate()?;
    let range = opts.groups.clone().unwrap_or(0..scan.groups.len());
    let range = range.start.min(scan.groups.len())..range.end.min(scan.groups.len());
    let total = range.len();
    let meta = Arc::new(scan.meta.clone());
    let mut timings = StageTimings::default();
    let mut stage_secs = vec![0.0; Stage::ALL.len()];
    let mut signals: Vec<GroupSignal> = Vec::with_capacity(total);
    // Each group's fits are checked against the median wall slope of the groups before it.
    let mut slopes = SlopeHistory::default();
    let mut reports = Vec::with_capacity(total);
    let mut warnings = Vec::new();

    // A decoded group: its index, the first frame loaded, the frames, the seconds it took.
    type Loaded = (
        usize,
        usize,
        Result<Vec<crate::image::Image>, LoadError>,
        f64,
    );
    let (tx, rx) = mpsc::sync_channel::<Loaded>(1);
    let entries: Vec<_> = scan.groups[range.clone()].to_vec();
    let loader_cancel = AtomicBool::new(false);
    let outcome: Result<(), EngineError> = std::thread::scope(|s| {
        // Own the receiver here so that an early return (or a panic) drops it, which unblocks a
        // loader waiting in `send` instead of deadlocking the scope's join.
        let rx = rx;
        let loader = std::thread::Builder::new()
            .name("groovescope-loader".into())
            .spawn_scoped(s, || {
                for entry in &entries {
                    if cancel.load(Ordering::Relaxed) || loader_cancel.load(Ordering::Relaxed) {
                        break;
                    }
                    let t = Instant::now();
                    let window = frames_read(entry.frames.len(), &scan.meta, params);
                    let first = window.start;
                    let frames = load_group_frames(entry, window);
                    if tx
                        .send((entry.index, first, frames, t.elapsed().as_secs_f64()))
                        .is_err()
                    {
                        break;
                    }
                }
                drop(tx);
            });
        if let Err(e) = loader {
            return Err(EngineError::Load(LoadError::Io {
                problem: format!("cannot start the loader thread: {e}"),
                path: scan.dir.clone(),
            }));
        }
        let mut done = 0;
        for (group, first_frame, frames, load_secs) in rx.iter() {
            if cancel.load(Ordering::Relaxed) {
                loader_cancel.store(true, Ordering::Relaxed);
                return Err(EngineError::Cancelled);
            }
            timings.load_secs += load_secs;
            let frames = match frames {
                Ok(f) => f,
                Err(e) if opts.keep_going => {
                    let w = format!("group {group}: {e} (filled with silence)");
                    warnings.push(w.clone());
                    reports.push(GroupReport {
                        group,
                        outlier_fraction: None,
                        rejected_fits: 0,
                        samples: 0,
                        warning: Some(w),
                    });
                    done += 1;
                    progress(&Progress {
                        done,
                        total,
                        signal: None,
                    });
                    continue;
                }
                Err(e) => {
                    loader_cancel.store(true, Ordering::Relaxed);
                    return Err(e.into());
                }
            };
            let input = GroupInput {
                group,
                frames: Arc::new(frames),
                first_frame,
                meta: meta.clone(),
            };
            let reference = slopes.reference(params.orientation.max_wall_slope_change);
            let signal = match run_group(&input, params, &reference) {
                Ok((cache, times)) => {
                    if let Some(o) = cache.orientation() {
                        slopes.push(&o.own_slopes);
                    }
                    for (acc, t) in stage_secs.iter_mut().zip(&times) {
                        *acc += t.as_secs_f64();
                    }
                    let outlier = cache
                        .orientation()
                        .as_ref()
                        .map(|o| o.orientation.outlier_fraction);
                    let rejected_fits = cache
                        .orientation()
                        .as_ref()
                        .map_or(0, |o| o.orientation.rejected_fits);
                    match cache.signal().cloned() {
                        Some(sig) => {
                            reports.push(GroupReport {
                                group,
                                outlier_fraction: outlier,
                                rejected_fits,
                                samples: sig.positions_um.len(),
                                warning: None,
                            });
                            Some(sig)
                        }
                        None => None,
                    }
                }
                Err(e @ StageError::InvalidParam { .. }) => {
                    loader_cancel.store(true, Ordering::Relaxed);
                    return Err(e.into());
                }
                Err(e) => {
                    let w = format!("group {group}: {e} (filled with silence)");
                    warnings.push(w.clone());
                    reports.push(GroupReport {
                        group,
                        outlier_fraction: None,
                        rejected_fits: 0,
                        samples: 0,
                        warning: Some(w),
                    });
                    None
                }
            };
            done += 1;
            progress(&Progress {
                done,
                total,
                signal: signal.clone(),
            });
            if let Some(sig) = signal {
                signals.push(Arc::unwrap_or_clone(sig));
            }
        }
        Ok(())
    });
    outcome?;
    if cancel.load(Ordering::Relaxed) {
        return Err(EngineError::Cancelled);
    }
    if signals.is_empty() {
        return Err(EngineError::NoSound {
            path: scan.dir.clone(),
            warnings,
        });
    }
    timings.stages_secs = Stage::ALL
        .iter()
        .zip(&stage_secs)
        .map(|(s, t)| (s.name().to_string(), *t))
        .collect();

    let t_finish = Instant::now();
    let spacing = native_spacing_um(&scan.meta, &params.sound);
    let mut stitched = stitch(&signals, spacing)?;
    let rejected: usize = reports.iter().map(|r| r.rejected_fits).sum();
    if rejected > 0 {
        warnings.push(format!(
            "{rejected} orientation fits rejected for an implausible wall slope (left as gaps)"
        ));
    }
    let bridged = bridge_short_gaps(&mut stitched);
    if bridged > 0 {
        warnings.push(format!(
            "{bridged} short gaps (≤ {BRIDGE_GAP_SAMPLES} native samples) bridged by interpolation"
        ));
    }
    for gap in &stitched.gaps {
        warnings.push(format!(
            "gap of {} native samples at sample {} filled with silence",
            gap.len(),
            gap.start
        ));
    }
    let out_rate = params.sound.output_rate_hz;
    let mut channels = Vec::with_capacity(stitched.channels.len());
    for ch in &stitched.channels {
        let mut y = resample(ch, stitched.native_rate_hz, out_rate)?;
        apply_dsp(&mut y, f64::from(out_rate), &params.dsp)?;
        channels.push(y);
    }
    let peak =
        channels.iter().flatten().fold(
            0.0_f32,
            |m, v| if v.is_finite() { m.max(v.abs()) } else { m },
        );
    let gain_per_mm_s = if params.sound.normalize_peak > 0.0 {
        if peak > 0.0 {
            f64::from(params.sound.normalize_peak / peak)
        } else {
            1.0
        }
    } else {
        1.0 / params.sound.full_scale_mm_s
    };
    for ch in &mut channels {
        for v in ch.iter_mut() {
            *v = if v.is_finite() {
                (f64::from(*v) * gain_per_mm_s) as f32
            } else {
                0.0
            };
        }
    }
    let audio = Audio {
        sample_rate_hz: out_rate,
        channels,
    };
    timings.finish_secs = t_finish.elapsed().as_secs_f64();

    let scores = match &scan.reference {
        Some(path) => score_against_reference(
            &audio,
            &stitched,
            scan.meta.groove_speed_mm_s(0),
            path,
            &mut warnings,
        ),
        None => None,
    };
    timings.total_secs = started.elapsed().as_secs_f64();
    Ok(Reconstruction {
        audio,
        stitched,
        groups: reports,
        timings,
        gain_per_mm_s,
        scores,
        warnings,
    })
}

/// Bridges gaps of at most [`BRIDGE_GAP_SAMPLES`] with data on both sides by linear
/// interpolation, removes them from `gaps`, and returns how many were bridged.
pub fn bridge_short_gaps(signal: &mut StitchedSignal) -> usize {
    let mut bridged = 0;
    let mut kept = Vec::new();
    for gap in std::mem::take(&mut signal.gaps) {
        let n = signal.channels.first().map_or(0, Vec::len);
        if gap.len() > BRIDGE_GAP_SAMPLES || gap.start == 0 || gap.end >= n {
            kept.push(gap);
            continue;
        }
        let (a, b) = (gap.start - 1, gap.end);
        for ch in &mut signal.channels {
            let (va, vb) = (ch[a], ch[b]);
            for k in gap.clone() {
                let t = (k - a) as f32 / (b - a) as f32;
                ch[k] = va + (vb - va) * t;
            }
        }
        bridged += 1;
    }
    signal.gaps = kept;
    bridged
}

/// Reference sound aligned to the stretch a reconstruction covers, at the recovered rate.
///
/// # Errors
/// [`LoadError`] when the reference cannot be read or resampled.
pub fn aligned_reference(
    recovered: &Audio,
    stitched: &StitchedSignal,
    groove_speed_mm_s: f64,
    path: &std::path::Path,
) -> Result<Vec<f32>, LoadError> {
    let reference = read_wav(path)?;
    let mono = reference.mono();
    let rate = f64::from(reference.sample_rate_hz);
    let start_secs = stitched.start_um / (groove_speed_mm_s * 1000.0);
    let skip = (start_secs * rate).round().max(0.0) as usize;
    let tail = mono.get(skip..).unwrap_or(&[]);
    let resampled = if reference.sample_rate_hz == recovered.sample_rate_hz {
        tail.to_vec()
    } else {
        resample(tail, rate, recovered.sample_rate_hz).map_err(|e| LoadError::Sound {
            problem: format!("cannot resample the reference: {e}"),
            path: path.to_path_buf(),
        })?
    };
    Ok(resampled)
}

fn score_against_reference(
    audio: &Audio,
    stitched: &StitchedSignal,
    groove_speed_mm_s: f64,
    path: &std::path::Path,
    warnings: &mut Vec<String>,
) -> Option<Scores> {
    match aligned_reference(audio, stitched, groove_speed_mm_s, path) {
        Ok(reference) => {
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
