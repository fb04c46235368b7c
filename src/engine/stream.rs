//! The group stream: a named loader thread decodes the next group while the current one runs through the stages.

use std::ops::Range;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::Instant;

use super::{EngineError, GroupReport, SlopeEntry, run_group};
use crate::image::Image;
use crate::io::{GroupEntry, LoadError, Scan, load_group_frames};
use crate::pipeline::audio_signal::GroupSignal;
use crate::pipeline::slope_reference::{SlopeHistory, SlopeReference};
use crate::pipeline::{GroupInput, Method, PipelineParams, Stage, StageError, frames_read};

/// How a group meets the clip's slope history.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SlopeMode {
    /// Checked against its reference, then added to it (every group of a reconstruction).
    Check,
    /// Only added to it (a group before a shard's range, run for its slope entries alone,
    /// which do not depend on the reference).
    RecordOnly,
}

/// What one group gave.
#[derive(Clone, Debug)]
pub struct GroupOutcome {
    /// Group index in the scan.
    pub group: usize,
    /// Its report row (None only if the stages ran but left no signal, which they do not).
    pub report: Option<GroupReport>,
    /// Its sound (None when it failed and became a gap): the flow method's velocity, or for
    /// the `edges` method the edge stage's own per-group velocity (for display; the clip's
    /// sound comes from `borders`).
    pub signal: Option<Arc<GroupSignal>>,
    /// The edge stage's border tracks ([`crate::pipeline::edges::Edges::border_signal`]) for
    /// the methods that read the edges (None otherwise, or when it failed).
    pub borders: Option<Arc<GroupSignal>>,
    /// What it added to the slope reference.
    pub slopes: Vec<SlopeEntry>,
    /// Seconds decoding its frames.
    pub load_secs: f64,
    /// Seconds per [`Stage`] (zero for a group that failed).
    pub stage_secs: Vec<f64>,
}

impl GroupOutcome {
    fn failed(group: usize, warning: String, load_secs: f64) -> Self {
        Self {
            group,
            report: Some(GroupReport {
                group,
                outlier_fraction: None,
                rejected_fits: 0,
                samples: 0,
                warning: Some(warning),
                pixel_noise_grey_levels: None,
            }),
            signal: None,
            borders: None,
            slopes: Vec::new(),
            load_secs,
            stage_secs: vec![0.0; Stage::ALL.len()],
        }
    }
}

/// What a stream of groups runs on.
#[derive(Clone, Copy, Debug)]
pub struct GroupStream<'a> {
    /// The scan.
    pub scan: &'a Scan,
    /// The params.
    pub params: &'a PipelineParams,
    /// Unreadable groups become gaps with a warning instead of failing the run.
    pub keep_going: bool,
    /// How groups meet the slope history.
    pub mode: SlopeMode,
}

/// `frames` of group `entry` (its first frame the group's `first`), refused when they are not
/// the scan's `size`: a group of another camera's frames would run and make wrong sound.
fn sized_as_scan(
    frames: Vec<Image>,
    entry: &GroupEntry,
    first: usize,
    size: (usize, usize),
) -> Result<Vec<Image>, LoadError> {
    match frames.first() {
        Some(f) if (f.width, f.height) != size => Err(LoadError::GroupSize {
            found_w: f.width,
            found_h: f.height,
            want_w: size.0,
            want_h: size.1,
            path: entry.frame_path(first).unwrap_or_else(|| entry.dir.clone()),
        }),
        _ => Ok(frames),
    }
}

/// [`crate::pipeline::sampling::check_sample_density`] for `scan` and `params`, naming the
/// scan's metadata file (`scan.toml`, or a store's `zarr.json`) or the params key.
///
/// # Errors
/// [`EngineError::Load`] or [`EngineError::Stage`] with the sentence.
pub fn check_sample_density(scan: &Scan, params: &PipelineParams) -> Result<(), EngineError> {
    crate::pipeline::sampling::check_sample_density(&scan.meta, &params.sound).map_err(
        |too_fine| -> EngineError {
            if too_fine.from_scan {
                let file = if scan.is_store() {
                    "zarr.json"
                } else {
                    "scan.toml"
                };
                LoadError::Metadata {
                    problem: too_fine.problem,
                    path: scan.dir.join(file),
                }
                .into()
            } else {
                StageError::invalid("sound.native_spacing_um", too_fine.problem).into()
            }
        },
    )
}

/// Runs the groups `range` of `stream.scan` in order, one group decoded ahead on a named
/// loader thread, and hands each outcome to `on_group`. Memory stays at about two groups.
///
/// A group that cannot be read fails the run, or with `keep_going` becomes a gap with a
/// warning; a group whose stages fail becomes a gap with a warning; an invalid parameter
/// fails the run.
///
/// # Errors
/// [`EngineError`] as above, [`EngineError::Cancelled`] when `cancel` is set, or whatever
/// `on_group` returns.
pub fn run_groups(
    stream: &GroupStream<'_>,
    range: Range<usize>,
    slopes: &mut SlopeHistory,
    cancel: &AtomicBool,
    on_group: &mut dyn FnMut(GroupOutcome) -> Result<(), EngineError>,
) -> Result<(), EngineError> {
    let GroupStream {
        scan,
        params,
        keep_going,
        mode,
    } = *stream;
    let range = range.start.min(scan.groups.len())..range.end.min(scan.groups.len());
    // Refused before the first group: every group would fail alike, after work.
    check_sample_density(scan, params)?;
    if params.path == crate::pipeline::PathChoice::DualFocus && scan.meta.dual_focus.is_none() {
        return Err(StageError::invalid(
            "path",
            format!(
                "dual-focus needs a [dual_focus] table in the scan's metadata, and {} has none",
                scan.dir.display()
            ),
        )
        .into());
    }
    let meta = Arc::new(scan.meta.clone());
    // A decoded group: its index, the first frame loaded, the frames, the seconds it took.
    type Loaded = (usize, usize, Result<Vec<Image>, LoadError>, f64);
    let (tx, rx) = mpsc::sync_channel::<Loaded>(1);
    let entries = scan.groups.get(range).unwrap_or_default();
    let loader_cancel = AtomicBool::new(false);
    std::thread::scope(|s| {
        // Own the receiver here so that an early return (or a panic) drops it, which unblocks a
        // loader waiting in `send` instead of deadlocking the scope's join.
        let rx = rx;
        let loader = std::thread::Builder::new()
            .name("groovescope-loader".into())
            .spawn_scoped(s, || {
                for entry in entries {
                    if cancel.load(Ordering::Relaxed) || loader_cancel.load(Ordering::Relaxed) {
                        break;
                    }
                    let t = Instant::now();
                    let window = frames_read(entry.frame_count(), &scan.meta, params);
                    let first = window.start;
                    let frames = load_group_frames(entry, window)
                        .and_then(|f| sized_as_scan(f, entry, first, scan.frame_size));
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
        let stop = |e: EngineError| {
            loader_cancel.store(true, Ordering::Relaxed);
            Err(e)
        };
        for (group, first_frame, frames, load_secs) in rx.iter() {
            if cancel.load(Ordering::Relaxed) {
                return stop(EngineError::Cancelled);
            }
            let frames = match frames {
                Ok(f) => f,
                Err(e) if keep_going => {
                    let w = format!("group {group}: {e} (filled with silence)");
                    if let Err(e) = on_group(GroupOutcome::failed(group, w, load_secs)) {
                        return stop(e);
                    }
                    continue;
                }
                Err(e) => return stop(e.into()),
            };
            let input = GroupInput {
                group,
                frames: Arc::new(frames),
                first_frame,
                meta: meta.clone(),
            };
            let outcome = match process_group(&input, params, slopes, mode) {
                Ok(o) => GroupOutcome { load_secs, ..o },
                Err(e @ StageError::InvalidParam { .. }) => return stop(e.into()),
                Err(e) => {
                    let w = format!("group {group}: {e} (filled with silence)");
                    GroupOutcome::failed(group, w, load_secs)
                }
            };
            if let Err(e) = on_group(outcome) {
                return stop(e);
            }
        }
        Ok(())
    })?;
    if cancel.load(Ordering::Relaxed) {
        return Err(EngineError::Cancelled);
    }
    Ok(())
}

/// One decoded group through the stages with the clip's slope reference; its own slope
/// medians go into the history (a failed group adds none). With the fused method, a group the
/// flow method's stages fail on is read by the edges alone: the edge stage reads none of their
/// outputs, but runs after them, so it is run on its own; the report row says why the flow
/// method is missing.
fn process_group(
    input: &GroupInput,
    params: &PipelineParams,
    slopes: &mut SlopeHistory,
    mode: SlopeMode,
) -> Result<GroupOutcome, StageError> {
    let reference = match mode {
        SlopeMode::Check => slopes.reference(params.orientation.max_wall_slope_change),
        SlopeMode::RecordOnly => SlopeReference::default(),
    };
    let (mut cache, mut times, ran) = run_group(input, params, &reference);
    let flow_lost = match ran {
        Ok(()) => None,
        Err(e @ StageError::InvalidParam { .. }) => return Err(e),
        Err(e) if params.method == Method::Fused && cache.signal().is_none() => {
            let t0 = Instant::now();
            if cache
                .run_from(Stage::Edges, input, params, &mut |_, _| true)
                .is_err()
            {
                return Err(e);
            }
            times[Stage::Edges.index()] = t0.elapsed();
            Some(format!(
                "group {}: {e} (read by the edges alone)",
                input.group
            ))
        }
        Err(e) => return Err(e),
    };
    let entries: Vec<SlopeEntry> = match flow_lost {
        Some(_) => Vec::new(),
        None => cache
            .orientation()
            .map(|o| o.own_slopes.clone())
            .unwrap_or_default(),
    };
    slopes.push(&entries);
    let orientation = cache.orientation().map(|o| &o.orientation);
    let edges = cache.edges();
    let signal = if params.method.reads_flow() {
        cache.signal().cloned()
    } else {
        edges.map(|e| Arc::new(e.to_group_signal()))
    };
    // A border lost over the group is a gap marked in the report, not a failure.
    let mut notes: Vec<&str> = edges
        .map(|e| e.warnings.iter().map(String::as_str).collect())
        .unwrap_or_default();
    notes.extend(flow_lost.as_deref());
    // No signal only where the flow method was lost and the edges read the group.
    let samples = signal
        .as_ref()
        .map(|sig| sig.positions_um.len())
        .or_else(|| edges.map(|e| e.positions_um.len()));
    let report = samples.map(|samples| GroupReport {
        group: input.group,
        outlier_fraction: orientation.map(|o| o.outlier_fraction),
        rejected_fits: orientation.map_or(0, |o| o.rejected_fits),
        samples,
        warning: (!notes.is_empty()).then(|| notes.join("; ")),
        pixel_noise_grey_levels: edges.and_then(|e| e.coarse.pixel_noise_grey_levels),
    });
    Ok(GroupOutcome {
        group: input.group,
        report,
        signal,
        borders: edges.map(|e| Arc::new(e.border_signal())),
        slopes: entries,
        load_secs: 0.0,
        stage_secs: times.iter().map(std::time::Duration::as_secs_f64).collect(),
    })
}
