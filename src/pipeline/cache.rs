//! The stage cache shared by the CLI and the workbench: one slot per [`Stage`], rerun from the first stale one.

use rayon::prelude::*;
use std::sync::Arc;

use super::audio_signal::{GroupSignal, SoundParams, group_signal};
use super::depth::{DepthMap, estimate_depth};
use super::derivatives::{
    DerivativeMode, Derivatives, SIMONCELLI_WINDOW_FRAMES, compute_derivatives,
};
use super::hough::{Stripes, segment_stripes};
use super::optical_flow::{
    FlowField, FlowMethod, WallSideMap, compute_flow, compute_flow_from, estimate_wall_sides,
    flow_confidence_only,
};
use super::orientation::{Orientation, orient_from_depth, orient_from_lines};
use super::walls::{WallLine, find_walls};
use super::{PipelineParams, Stage, StageError, median};
use crate::image::{Image, zeros_par};
use crate::io::ScanMeta;

/// Columns kept clear of each frame edge when placing samples (px): pre-warping clamps there.
pub const SAMPLE_MARGIN_PX: f64 = 8.0;

/// What a group's stages run on.
#[derive(Clone, Debug)]
pub struct GroupInput {
    /// Group index in the scan.
    pub group: usize,
    /// Grey frames of the group, in order: all of them, or a run of them that starts at
    /// `first_frame` (reconstruction loads only the window the dual-focus path reads).
    pub frames: Arc<Vec<Image>>,
    /// Index in the whole group of `frames[0]`.
    pub first_frame: usize,
    /// The scan's metadata.
    pub meta: Arc<ScanMeta>,
}

/// Depth-path output: the Kalman depth map and the wall lines found on it.
#[derive(Clone, Debug, PartialEq)]
pub struct DepthOutput {
    /// Depth and variance.
    pub map: DepthMap,
    /// One line per wall.
    pub walls: Vec<WallLine>,
}

/// Where a group's samples fall: the groove position of each column of the reference frame.
#[derive(Clone, Debug, PartialEq)]
pub struct SampleGrid {
    /// Frame of the group whose columns are sampled.
    pub frame_index: usize,
    /// Groove position of column 0 (µm from the scan start).
    pub column0_um: f64,
    /// Groove length per column at the walls' depth (µm).
    pub um_per_px: f64,
    /// Columns of the samples (on the scan's global sample grid).
    pub columns: Vec<f32>,
}

/// Orientation-stage output with the sample grid it used.
#[derive(Clone, Debug, PartialEq)]
pub struct OrientationOutput {
    /// Wall tilts per sample.
    pub orientation: Orientation,
    /// Sample placement.
    pub grid: SampleGrid,
}

/// How much the flow stage computes on the dual-focus path (the depth path always needs the
/// whole field).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum FlowDetail {
    /// The flow field (u, v) as well as its confidence: what the workbench and `inspect` show.
    #[default]
    Field,
    /// Only the confidence map, the pixels that carry flow, which is all the dual-focus stripes
    /// read ([`flow_confidence_only`]): whole-scan reconstruction skips the Horn–Schunck solve.
    /// Stripes, orientation and sound are the same as with [`FlowDetail::Field`].
    InFocusMap,
}

/// One slot per stage. `Arc`s make clones cheap, so a worker can take a copy, run, and send it back.
#[derive(Clone, Debug, Default)]
pub struct StageCache {
    /// How much the flow stage computes on the dual-focus path (set by the cache's owner).
    pub flow_detail: FlowDetail,
    /// [`Stage::Derivatives`].
    pub derivatives: Option<Arc<Vec<Derivatives>>>,
    /// [`Stage::Flow`].
    pub flows: Option<Arc<Vec<FlowField>>>,
    /// [`Stage::Depth`] (depth path only).
    pub depth: Option<Arc<DepthOutput>>,
    /// [`Stage::Stripes`] (dual-focus path only).
    pub stripes: Option<Arc<Stripes>>,
    /// [`Stage::Orientation`].
    pub orientation: Option<Arc<OrientationOutput>>,
    /// [`Stage::Sound`].
    pub signal: Option<Arc<GroupSignal>>,
    /// Params each slot was produced with (None: never run or invalidated).
    pub produced_with: [Option<PipelineParams>; 6],
    /// Group the slots belong to.
    pub group: Option<usize>,
}

/// Sample spacing along the groove (µm): the param, or one output sample at the scan's groove speed.
#[must_use]
pub fn native_spacing_um(meta: &ScanMeta, sound: &SoundParams) -> f64 {
    if sound.native_spacing_um > 0.0 {
        sound.native_spacing_um
    } else {
        meta.groove_speed_mm_s(0) * 1000.0 / f64::from(sound.output_rate_hz)
    }
}

/// Places the scan's global sample grid on the columns of one frame of one group.
#[must_use]
pub fn sample_grid(
    meta: &ScanMeta,
    group: usize,
    frame_index: usize,
    width: usize,
    projection_depth_um: f64,
    sound: &SoundParams,
) -> SampleGrid {
    let geom = meta.geometry();
    let cx = (width as f64 - 1.0) / 2.0;
    let cam_s = group as f64 * meta.motion.group_step_um
        + frame_index as f64 * meta.motion.frame_step_um
        + cx * geom.pixel_pitch_um;
    let um_per_px = geom.pixel_pitch_um * projection_depth_um / geom.working_distance_um;
    let column0_um = cam_s - cx * um_per_px;
    let spacing = native_spacing_um(meta, sound);
    let lo = column0_um + SAMPLE_MARGIN_PX * um_per_px;
    let hi = column0_um + (width as f64 - 1.0 - SAMPLE_MARGIN_PX) * um_per_px;
    let mut columns = Vec::new();
    if spacing > 0.0 && hi > lo {
        let first = (lo / spacing).ceil() as i64;
        let last = (hi / spacing).floor() as i64;
        for j in first..=last {
            columns.push(((j as f64 * spacing - column0_um) / um_per_px) as f32);
        }
    }
    SampleGrid {
        frame_index,
        column0_um,
        um_per_px,
        columns,
    }
}

/// Median depth along the wall lines (µm); the scale of the sample grid for the depth path.
fn wall_depth_um(depth: &DepthMap, walls: &[WallLine]) -> Option<f64> {
    let mut zs = Vec::new();
    for line in walls {
        for (x, &row) in line.rows.iter().enumerate() {
            if row.is_finite()
                && row >= 0.0
                && let Some(z) = depth.z_um.get(x, row.round() as usize)
                && z.is_finite()
            {
                zs.push(f64::from(z));
            }
        }
    }
    median(zs)
}

fn missing(stage: Stage) -> StageError {
    StageError::BadInput {
        stage: stage.name(),
        problem: "an earlier stage has no result".into(),
    }
}

impl StageCache {
    /// Marks `stage` and every later stage as needing a rerun (their results stay for display).
    pub fn invalidate_from(&mut self, stage: Stage) {
        for slot in &mut self.produced_with[stage.index()..] {
            *slot = None;
        }
    }

    /// True when `stage` holds a result produced with params whose relevant part equals `params`.
    #[must_use]
    pub fn is_fresh(&self, stage: Stage, params: &PipelineParams) -> bool {
        self.produced_with[stage.index()]
            .as_ref()
            .is_some_and(|p| p.first_changed_stage(params).is_none_or(|s| s > stage))
    }

    /// The first stage that must run for `params` (None: everything is fresh).
    #[must_use]
    pub fn first_stale(&self, params: &PipelineParams) -> Option<Stage> {
        Stage::ALL.into_iter().find(|s| !self.is_fresh(*s, params))
    }

    fn mark(&mut self, stage: Stage, params: &PipelineParams) {
        self.produced_with[stage.index()] = Some(params.clone());
    }

    /// Runs `from` and every later stage for `input`, storing each result.
    ///
    /// After each stage `after_stage(stage, self)` is called; returning `false` stops the run
    /// with [`StageError::Cancelled`] (a newer job superseded this one).
    ///
    /// # Errors
    /// The first failing stage's error; earlier stages keep their fresh results.
    pub fn run_from(
        &mut self,
        from: Stage,
        input: &GroupInput,
        params: &PipelineParams,
        after_stage: &mut dyn FnMut(Stage, &StageCache) -> bool,
    ) -> Result<(), StageError> {
        params.validate()?;
        if self.group != Some(input.group) {
            self.invalidate_from(Stage::Derivatives);
            self.group = Some(input.group);
        }
        let meta = &input.meta;
        let geom = meta.geometry();
        let dual = params.uses_dual_focus(meta);
        for stage in Stage::ALL.into_iter().filter(|s| *s >= from) {
            self.produced_with[stage.index()] = None;
            match stage {
                Stage::Derivatives => {
                    // The dual-focus path reads only the middle window: derive just its frames.
                    let range = frames_read(input.frames.len(), meta, params);
                    let first = range.start;
                    let frames = input.frames.get(range).unwrap_or(&input.frames[..]);
                    let mut d =
                        compute_derivatives(frames, geom.land_flow_px(), &params.derivatives)?;
                    for set in &mut d {
                        set.frame_index += input.first_frame + first;
                    }
                    self.derivatives = Some(Arc::new(d));
                }
                Stage::Flow => {
                    let derivs = self.derivatives.clone().ok_or_else(|| missing(stage))?;
                    let flows = if dual {
                        // The dual-focus path reads one flow field, the middle window's (its
                        // in-focus map): the other windows would be computed for nothing.
                        let d = derivs.get(derivs.len() / 2).ok_or_else(|| missing(stage))?;
                        vec![match self.flow_detail {
                            FlowDetail::Field => {
                                compute_flow(d, geom.focal_px, None, &params.flow)?
                            }
                            FlowDetail::InFocusMap => flow_confidence_only(d, &params.flow)?,
                        }]
                    } else {
                        depth_path_flows(&derivs, geom.focal_px, geom.land_flow_px(), params)?
                    };
                    self.flows = Some(Arc::new(flows));
                }
                Stage::Depth => {
                    if dual {
                        self.depth = None;
                    } else {
                        let flows = self.flows.clone().ok_or_else(|| missing(stage))?;
                        let map = estimate_depth(&flows, &geom, &params.depth)?;
                        let walls = find_walls(&map, &geom, &params.walls)?;
                        self.depth = Some(Arc::new(DepthOutput { map, walls }));
                    }
                }
                Stage::Stripes => {
                    if let (true, Some(df)) = (dual, meta.dual_focus.as_ref()) {
                        let derivs = self.derivatives.clone().ok_or_else(|| missing(stage))?;
                        let flows = self.flows.clone().ok_or_else(|| missing(stage))?;
                        let Some((d, f)) = middle_window(&derivs, &flows) else {
                            return Err(missing(stage));
                        };
                        self.stripes = Some(Arc::new(segment_stripes(d, f, df, &params.hough)?));
                    } else if dual {
                        return Err(StageError::BadInput {
                            stage: stage.name(),
                            problem: "the dual-focus path needs a [dual_focus] table in scan.toml"
                                .into(),
                        });
                    } else {
                        self.stripes = None;
                    }
                }
                Stage::Orientation => {
                    let out = if dual {
                        let stripes = self.stripes.clone().ok_or_else(|| missing(stage))?;
                        let derivs = self.derivatives.clone().ok_or_else(|| missing(stage))?;
                        let mid = derivs.len() / 2;
                        let Some(d) = derivs.get(mid) else {
                            return Err(missing(stage));
                        };
                        let zp = stripes
                            .lines
                            .iter()
                            .find_map(|l| l.projection_depth_um.or(l.depth_um))
                            .unwrap_or(geom.working_distance_um);
                        let grid = sample_grid(
                            meta,
                            input.group,
                            d.frame_index,
                            d.ix.width,
                            zp,
                            &params.sound,
                        );
                        let orientation = orient_from_lines(
                            &stripes.lines,
                            d.ix.width,
                            d.ix.height,
                            &grid.columns,
                            &geom,
                            &params.orientation,
                        )?;
                        OrientationOutput { orientation, grid }
                    } else {
                        let depth = self.depth.clone().ok_or_else(|| missing(stage))?;
                        let zp = wall_depth_um(&depth.map, &depth.walls).ok_or_else(|| {
                            StageError::NotFound {
                                stage: stage.name(),
                                problem: "no depth on the wall lines".into(),
                            }
                        })?;
                        let grid = sample_grid(
                            meta,
                            input.group,
                            depth.map.frame_index,
                            depth.map.z_um.width,
                            zp,
                            &params.sound,
                        );
                        let orientation = orient_from_depth(
                            &depth.map,
                            &depth.walls,
                            &grid.columns,
                            &geom,
                            &params.orientation,
                        )?;
                        OrientationOutput { orientation, grid }
                    };
                    self.orientation = Some(Arc::new(out));
                }
                Stage::Sound => {
                    let o = self.orientation.clone().ok_or_else(|| missing(stage))?;
                    let signal = group_signal(
                        input.group,
                        &o.orientation,
                        meta.record.cut,
                        o.grid.column0_um,
                        o.grid.um_per_px,
                        meta.groove_speed_mm_s(input.group),
                    )?;
                    self.signal = Some(Arc::new(signal));
                }
            }
            self.mark(stage, params);
            if !after_stage(stage, self) {
                return Err(StageError::Cancelled);
            }
        }
        Ok(())
    }
}

/// Flow of every derivative window for the depth path, using the group's temporal coherence:
/// the first window runs the full solve (for groove Horn–Schunck: plain solve, wall sides
/// estimated from it, groove solve); each later window starts from the previous result moved
/// with the content (the land flow toward −x) and, for groove Horn–Schunck, reuses the first
/// window's wall sides moved the same way, so it skips the plain pre-solve. Each window still
/// iterates to the same tolerance and cap; only the starting point changes.
fn depth_path_flows(
    derivs: &[Derivatives],
    focal_px: f64,
    land_flow_px: f64,
    params: &PipelineParams,
) -> Result<Vec<FlowField>, StageError> {
    let Some((first, rest)) = derivs.split_first() else {
        return Ok(Vec::new());
    };
    let flow0 = compute_flow(first, focal_px, None, &params.flow)?;
    let walls0 = match params.flow.method {
        FlowMethod::GrooveHornSchunck => Some(estimate_wall_sides(&flow0, focal_px)?),
        _ => None,
    };
    let mut flows = Vec::with_capacity(derivs.len());
    flows.push(flow0);
    for d in rest {
        let Some(prev) = flows.last() else {
            break;
        };
        let step = d.frame_index.saturating_sub(prev.frame_index) as f64 * land_flow_px.abs();
        let init = shift_flow(prev, step);
        let from_first = d.frame_index.saturating_sub(first.frame_index) as f64;
        let walls = walls0
            .as_ref()
            .map(|w| shift_walls(w, from_first * land_flow_px.abs()));
        flows.push(compute_flow_from(
            d,
            focal_px,
            walls.as_ref(),
            Some(&init),
            &params.flow,
        )?);
    }
    Ok(flows)
}

/// A flow field whose content moved by `shift_px` toward −x: column x takes the (linearly
/// interpolated) value at x + shift; beyond the right edge the last column repeats.
fn shift_flow(flow: &FlowField, shift_px: f64) -> FlowField {
    let s = if shift_px.is_finite() { shift_px } else { 0.0 };
    // Column x reads x + s = x + whole + t: the same fraction t for every column.
    let whole = s.floor();
    let t = (s - whole) as f32;
    let shift = |im: &Image| {
        let w = im.width.max(1);
        let mut out = zeros_par(im.data.len());
        out.par_chunks_mut(w)
            .zip(im.data.par_chunks(w))
            .for_each(|(dst, row)| {
                let last = row.len().saturating_sub(1);
                let (Some(&first), Some(&end)) = (row.first(), row.last()) else {
                    return;
                };
                // Column x reads i = x + whole: before the row, the first value; from the last
                // column on, the last; in between, a + (b − a)·t of columns i and i + 1.
                let n = dst.len().min(row.len());
                let (lo, hi) = if whole >= 0.0 {
                    let k = (whole as usize).min(n);
                    (0, last.saturating_sub(k).min(n))
                } else {
                    let k = ((-whole) as usize).min(n);
                    (k, n)
                };
                let k0 = (lo as f64 + whole) as usize;
                let (head, rest) = dst.split_at_mut(lo);
                let (mid, tail) = rest.split_at_mut(hi.max(lo) - lo);
                head.fill(first);
                tail.fill(end);
                if let (Some(a), Some(b)) = (
                    row.get(k0..k0 + mid.len()),
                    row.get(k0 + 1..k0 + 1 + mid.len()),
                ) {
                    for ((d, &a), &b) in mid.iter_mut().zip(a).zip(b) {
                        *d = a + (b - a) * t;
                    }
                }
            });
        Image {
            width: im.width,
            height: im.height,
            data: out,
        }
    };
    FlowField {
        u: shift(&flow.u),
        v: shift(&flow.v),
        confidence: Image::zeros(0, 0),
        iterations: 0,
        converged: false,
        frame_index: flow.frame_index,
    }
}

/// The wall-side map of content that moved by `shift_px` toward −x: column x takes the side
/// found at x + shift (rounded; beyond the right edge the last column repeats).
fn shift_walls(walls: &WallSideMap, shift_px: f64) -> WallSideMap {
    let w = walls.width;
    let s = if shift_px.is_finite() {
        shift_px.round().max(0.0) as usize
    } else {
        0
    };
    let mut sign = Vec::with_capacity(walls.sign.len());
    for row in walls.sign.chunks(w.max(1)) {
        sign.extend((0..w).map(|x| {
            row.get((x + s).min(w.saturating_sub(1)))
                .copied()
                .unwrap_or(0)
        }));
    }
    WallSideMap {
        width: w,
        height: walls.height,
        sign,
    }
}

/// The frames of a group of `n` that its stages read: the middle derivative window on the
/// dual-focus path (its stripes come from that window alone), all of them on the depth path.
/// Reconstruction decodes only these.
#[must_use]
pub fn frames_read(n: usize, meta: &ScanMeta, params: &PipelineParams) -> std::ops::Range<usize> {
    if params.uses_dual_focus(meta) {
        middle_window_range(n, params.derivatives.mode)
    } else {
        0..n
    }
}

/// The frames of a group of `n` the dual-focus path reads: its middle derivative window (all
/// `n` when there are too few for one, so the derivative stage reports the shortage).
#[must_use]
pub fn middle_window_range(n: usize, mode: DerivativeMode) -> std::ops::Range<usize> {
    let span = match mode {
        DerivativeMode::Simoncelli => SIMONCELLI_WINDOW_FRAMES,
        DerivativeMode::TwoFrame => 2,
    };
    match (n + 1).checked_sub(span).filter(|&windows| windows > 0) {
        Some(windows) => windows / 2..windows / 2 + span,
        None => 0..n,
    }
}

/// The middle derivative window and its flow field (the pair the dual-focus path reads).
fn middle_window<'a>(
    derivs: &'a [Derivatives],
    flows: &'a [FlowField],
) -> Option<(&'a Derivatives, &'a FlowField)> {
    let d = derivs.get(derivs.len() / 2)?;
    let f = flows.iter().find(|f| f.frame_index == d.frame_index)?;
    Some((d, f))
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests fail loudly on purpose
mod tests {
    use super::*;
    use crate::pipeline::derivatives::DerivativeParams;

    fn frames(n: usize) -> Vec<Image> {
        (0..n)
            .map(|k| {
                Image::from_fn(40, 24, |x, y| {
                    let t = x as f32 + 1.7 * k as f32;
                    (0.3 * t).sin() * (0.2 * y as f32).cos() + 0.01 * (k * k) as f32
                })
            })
            .collect()
    }

    /// One group of `frames` frames of the small dual-focus camera, rendered by the generator.
    fn dual_focus_group(frames: usize) -> GroupInput {
        use std::sync::atomic::AtomicBool;
        let dir = tempfile::tempdir().unwrap();
        let cfg = crate::synth::SynthConfig {
            frames_per_group: frames,
            ..crate::accuracy::small_dual_focus(1)
        };
        let tone = crate::synth::tone(1000.0, 0.01, crate::synth::BUILTIN_RATE_HZ);
        crate::synth::render_scan(&tone, &cfg, dir.path(), &|_, _| {}, &AtomicBool::new(false))
            .unwrap();
        let scan = crate::io::Scan::open(dir.path()).unwrap();
        let frames = crate::io::load_group(&scan.groups[0]).unwrap();
        GroupInput {
            group: 0,
            frames: Arc::new(frames),
            first_frame: 0,
            meta: Arc::new(scan.meta.clone()),
        }
    }

    #[test]
    fn the_in_focus_map_alone_gives_the_same_dual_focus_sound() {
        let input = dual_focus_group(7);
        let params = PipelineParams::default();
        assert!(params.uses_dual_focus(&input.meta));
        let run = |flow_detail| {
            let mut c = StageCache {
                flow_detail,
                ..StageCache::default()
            };
            c.run_from(Stage::Derivatives, &input, &params, &mut |_, _| true)
                .unwrap();
            c
        };
        let (full, lean) = (run(FlowDetail::Field), run(FlowDetail::InFocusMap));
        let (ff, lf) = (
            &full.flows.as_ref().unwrap()[0],
            &lean.flows.as_ref().unwrap()[0],
        );
        assert!(ff.iterations > 0 && !ff.u.data.is_empty());
        assert_eq!((lf.iterations, lf.u.data.len()), (0, 0));
        assert_eq!(ff.confidence, lf.confidence);
        assert_eq!(full.stripes, lean.stripes);
        // Debug text, so NaN gaps (and NaN weights) compare equal to themselves.
        let same =
            |a: &dyn std::fmt::Debug, b: &dyn std::fmt::Debug| format!("{a:?}") == format!("{b:?}");
        assert!(
            same(&full.orientation, &lean.orientation),
            "orientation differs"
        );
        assert!(same(&full.signal, &lean.signal), "sound differs");
        assert!(lean.signal.as_ref().unwrap().positions_um.len() > 10);
    }

    #[test]
    fn loading_only_the_middle_window_gives_the_same_dual_focus_sound() {
        let full = dual_focus_group(12);
        let window = middle_window_range(12, DerivativeMode::Simoncelli);
        assert_eq!(window, 3..10);
        let part = GroupInput {
            frames: Arc::new(full.frames[window.clone()].to_vec()),
            first_frame: window.start,
            ..full.clone()
        };
        let params = PipelineParams::default();
        let run = |input: &GroupInput| {
            let mut c = StageCache::default();
            c.run_from(Stage::Derivatives, input, &params, &mut |_, _| true)
                .unwrap();
            c
        };
        let (a, b) = (run(&full), run(&part));
        assert_eq!(a.derivatives.as_ref().unwrap()[0].frame_index, 6);
        assert_eq!(a.derivatives, b.derivatives);
        assert_eq!(a.stripes, b.stripes);
        assert_eq!(
            format!("{:?}", a.signal),
            format!("{:?}", b.signal),
            "sound differs"
        );
        // Without the offset the samples would land three frames early along the groove.
        let shifted = GroupInput {
            first_frame: 0,
            ..part
        };
        let c = run(&shifted);
        assert_ne!(
            a.signal.as_ref().unwrap().positions_um,
            c.signal.as_ref().unwrap().positions_um
        );
    }

    /// The frames of the middle derivative window of a group (the window the full group's
    /// `derivs[len / 2]` would be) and the index of its first frame. Too few frames: all of them,
    /// so the derivative stage reports the shortage.
    fn middle_window_frames(frames: &[Image], mode: DerivativeMode) -> (usize, &[Image]) {
        let range = middle_window_range(frames.len(), mode);
        (range.start, frames.get(range).unwrap_or(frames))
    }

    #[test]
    fn middle_window_frames_give_the_full_groups_middle_derivatives() {
        for (n, mode) in [
            (12, DerivativeMode::Simoncelli),
            (7, DerivativeMode::Simoncelli),
            (9, DerivativeMode::TwoFrame),
        ] {
            let fr = frames(n);
            let params = DerivativeParams {
                mode,
                ..DerivativeParams::default()
            };
            let full = compute_derivatives(&fr, -2.0, &params).unwrap();
            let (start, sub) = middle_window_frames(&fr, mode);
            let mut one = compute_derivatives(sub, -2.0, &params).unwrap();
            assert_eq!(one.len(), 1, "{n} frames {mode:?}");
            one[0].frame_index += start;
            assert_eq!(one[0], full[full.len() / 2], "{n} frames {mode:?}");
        }
        // Too few frames: all of them go through, so the stage reports the shortage.
        let fr = frames(5);
        assert_eq!(
            middle_window_frames(&fr, DerivativeMode::Simoncelli),
            (0, &fr[..])
        );
    }

    #[test]
    fn shifted_flow_and_walls_follow_the_content() {
        let u = Image::from_fn(6, 2, |x, y| x as f32 + 10.0 * y as f32);
        let f = FlowField {
            u: u.clone(),
            v: u,
            confidence: Image::zeros(6, 2),
            iterations: 0,
            converged: true,
            frame_index: 3,
        };
        let s = shift_flow(&f, 1.5);
        assert_eq!(s.u.data[..6], [1.5, 2.5, 3.5, 4.5, 5.0, 5.0]);
        assert_eq!(s.v.data[6..], [11.5, 12.5, 13.5, 14.5, 15.0, 15.0]);
        let walls = WallSideMap {
            width: 4,
            height: 1,
            sign: vec![0, 1, -1, 0],
        };
        assert_eq!(shift_walls(&walls, 1.2).sign, [1, -1, 0, 0]);
    }

    #[test]
    fn warm_started_windows_match_cold_ones() {
        // A textured pattern translating by 1.3 px/frame, 12 frames: every window's flow from
        // the depth-path loop (warm starts, shared walls) against each window solved from zero.
        let fr: Vec<Image> = (0..12)
            .map(|k| {
                Image::from_fn(64, 48, |x, y| {
                    let t = x as f32 + 1.3 * k as f32;
                    (0.37 * t).sin() * (0.23 * y as f32 + 0.1 * t).cos() + 0.3 * (0.11 * t).cos()
                })
            })
            .collect();
        let mut params = PipelineParams::default();
        params.flow.method = FlowMethod::HornSchunck;
        params.flow.max_iterations = 400;
        // Converged solves: the same fixed point from either start.
        params.flow.tolerance_px = 1e-5;
        let d = compute_derivatives(&fr, -1.0, &params.derivatives).unwrap();
        let warm = depth_path_flows(&d, 10_000.0, -1.0, &params).unwrap();
        assert_eq!(warm.len(), d.len());
        let diffs: Vec<f64> = warm
            .iter()
            .zip(&d)
            .map(|(w, di)| {
                assert_eq!(w.frame_index, di.frame_index);
                let cold = compute_flow(di, 10_000.0, None, &params.flow).unwrap();
                w.u.data
                    .iter()
                    .zip(&cold.u.data)
                    .map(|(a, b)| f64::from((a - b).abs()))
                    .sum::<f64>()
                    / cold.u.data.len() as f64
            })
            .collect();
        assert!(
            diffs.iter().all(|&x| x < 1e-4),
            "mean |Δu| per window {diffs:?}"
        );
    }
}
