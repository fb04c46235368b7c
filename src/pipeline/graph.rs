//! The stage graph: which per-group stages exist, what each one reads (earlier outputs, knobs, clip inputs) and how it runs — the one table that staleness and the cache follow.
//!
//! [`GRAPH`] has one row per [`Stage`]: the stages whose outputs it reads, a test of whether
//! the knobs it reads changed, whether it reads the clip's [`SlopeReference`](super::slope_reference::SlopeReference), and the function
//! that runs it on a [`StageCache`]'s earlier outputs. A stage is fresh when it was produced
//! with the same knobs and clip inputs from the very outputs now held by every stage it reads,
//! and those are fresh ([`StageCache::is_fresh`]). Adding a stage means a variant here, its
//! output variant, and one row.

use std::sync::Arc;

use serde::{Deserialize, Serialize};

use super::audio_signal::{GroupSignal, group_signal};
use super::cache::{GroupInput, StageCache};
use super::depth::{DepthMap, estimate_depth};
use super::derivatives::{
    DerivativeMode, Derivatives, SIMONCELLI_WINDOW_FRAMES, compute_derivatives,
};
use super::edges::{Edges, detect_edges};
use super::hough::{Stripes, segment_stripes};
use super::optical_flow::{FlowField, compute_flow, flow_confidence_only, flows_of_group};
use super::orientation::{Orientation, median_wall_slope, orient_from_depth, orient_from_lines};
use super::sampling::{SampleGrid, sample_grid};
use super::slope_reference::check_against;
use super::walls::{WallLine, WallSide, find_walls};
use super::{PipelineParams, StageError, median};
use crate::meta::ScanMeta;

/// The per-group stages, in the order they run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Stage {
    /// Ix, Iy, It of every 7-frame window (dual-focus path: the middle window only, the one
    /// its stripes are read from).
    Derivatives,
    /// Optical flow of every derivative set.
    Flow,
    /// Kalman depth map and wall lines (depth path).
    Depth,
    /// In-focus map, Hough accumulator, stripes and centroid lines (dual-focus path).
    Stripes,
    /// Robust wall orientation per sample column.
    Orientation,
    /// Velocity samples of the group.
    Sound,
    /// Sub-pixel wall borders of every frame, as displacement and velocity (the `edges` and
    /// `fused` methods; it reads the frames alone).
    Edges,
}

impl Stage {
    /// Every stage in run order (each reads only stages before it).
    pub const ALL: [Stage; 7] = [
        Stage::Derivatives,
        Stage::Flow,
        Stage::Depth,
        Stage::Stripes,
        Stage::Orientation,
        Stage::Sound,
        Stage::Edges,
    ];

    /// Number of stages.
    pub const COUNT: usize = Self::ALL.len();

    /// Position in [`Stage::ALL`].
    #[must_use]
    pub fn index(self) -> usize {
        self as usize
    }

    /// Human-readable name.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Stage::Derivatives => "derivatives",
            Stage::Flow => "flow",
            Stage::Depth => "depth",
            Stage::Stripes => "stripes",
            Stage::Orientation => "orientation",
            Stage::Sound => "sound",
            Stage::Edges => "edges",
        }
    }

    /// This stage's row of [`GRAPH`].
    #[must_use]
    pub fn spec(self) -> &'static StageSpec {
        &GRAPH[self.index()]
    }
}

/// Depth-path output: the Kalman depth map and the wall lines found on it.
#[derive(Clone, Debug, PartialEq)]
pub struct DepthOutput {
    /// Depth and variance.
    pub map: DepthMap,
    /// One line per wall.
    pub walls: Vec<WallLine>,
}

/// Orientation-stage output with the sample grid it used.
#[derive(Clone, Debug, PartialEq)]
pub struct OrientationOutput {
    /// Wall tilts per sample (fits that strayed from the clip's reference are gaps).
    pub orientation: Orientation,
    /// Sample placement.
    pub grid: SampleGrid,
    /// Each wall's own median cross-groove slope |b|, from its fits before the clip check
    /// (what the clip's [`super::slope_reference::SlopeHistory`] records).
    pub own_slopes: Vec<(WallSide, f64)>,
}

/// One stage's output. Stages that the chosen path does not use hold `None`.
#[derive(Clone, Debug)]
pub enum StageOutput {
    /// [`Stage::Derivatives`].
    Derivatives(Arc<Vec<Derivatives>>),
    /// [`Stage::Flow`].
    Flow(Arc<Vec<FlowField>>),
    /// [`Stage::Depth`] (None on the dual-focus path).
    Depth(Option<Arc<DepthOutput>>),
    /// [`Stage::Stripes`] (None on the depth path).
    Stripes(Option<Arc<Stripes>>),
    /// [`Stage::Orientation`].
    Orientation(Arc<OrientationOutput>),
    /// [`Stage::Sound`].
    Sound(Arc<GroupSignal>),
    /// [`Stage::Edges`] (None when the method does not read the edges).
    Edges(Option<Arc<Edges>>),
}

/// How much the flow stage computes on the dual-focus path (the depth path always needs the
/// whole field). Fixed for a cache's lifetime.
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

/// What a stage function is given: the group, the knobs, and the cache holding the outputs of
/// the stages it reads.
pub struct StageRun<'a> {
    /// The group's frames and metadata.
    pub input: &'a GroupInput,
    /// The knobs.
    pub params: &'a PipelineParams,
    /// Earlier outputs, the flow detail and the clip inputs.
    pub cache: &'a StageCache,
}

/// One row of [`GRAPH`].
pub struct StageSpec {
    /// The stage.
    pub stage: Stage,
    /// Stages whose outputs it reads (all earlier in [`Stage::ALL`]).
    pub reads: &'static [Stage],
    /// True when a knob the stage reads differs between the two params.
    pub knobs_changed: fn(&PipelineParams, &PipelineParams) -> bool,
    /// True when the stage reads the clip's [`SlopeReference`](super::slope_reference::SlopeReference).
    pub reads_slope_reference: bool,
    /// True when the method's sound needs the stage: a cache made
    /// [`StageCache::sound_only`] runs only these (reconstruction skips the flow stages for
    /// the `edges` method).
    pub needed: fn(&PipelineParams) -> bool,
    /// Runs the stage.
    pub run: fn(&StageRun<'_>) -> Result<StageOutput, StageError>,
}

/// The stage graph, one row per stage in [`Stage::ALL`] order.
pub static GRAPH: [StageSpec; Stage::COUNT] = [
    StageSpec {
        stage: Stage::Derivatives,
        reads: &[],
        // The path decides which frames are derived.
        knobs_changed: |a, b| a.path != b.path || differ(&a.derivatives, &b.derivatives),
        reads_slope_reference: false,
        needed: reads_flow,
        run: run_derivatives,
    },
    StageSpec {
        stage: Stage::Flow,
        reads: &[Stage::Derivatives],
        knobs_changed: |a, b| a.path != b.path || differ(&a.flow, &b.flow),
        reads_slope_reference: false,
        needed: reads_flow,
        run: run_flow,
    },
    StageSpec {
        stage: Stage::Depth,
        reads: &[Stage::Flow],
        knobs_changed: |a, b| {
            a.path != b.path || differ(&a.depth, &b.depth) || differ(&a.walls, &b.walls)
        },
        reads_slope_reference: false,
        needed: reads_flow,
        run: run_depth,
    },
    StageSpec {
        stage: Stage::Stripes,
        reads: &[Stage::Derivatives, Stage::Flow],
        knobs_changed: |a, b| a.path != b.path || differ(&a.hough, &b.hough),
        reads_slope_reference: false,
        needed: reads_flow,
        run: run_stripes,
    },
    StageSpec {
        stage: Stage::Orientation,
        reads: &[Stage::Derivatives, Stage::Depth, Stage::Stripes],
        // The sample grid follows the sound table (output rate, native spacing).
        knobs_changed: |a, b| {
            a.path != b.path || differ(&a.orientation, &b.orientation) || differ(&a.sound, &b.sound)
        },
        reads_slope_reference: true,
        needed: reads_flow,
        run: run_orientation,
    },
    StageSpec {
        stage: Stage::Sound,
        reads: &[Stage::Orientation],
        knobs_changed: |_, _| false,
        reads_slope_reference: false,
        needed: reads_flow,
        run: run_sound,
    },
    StageSpec {
        stage: Stage::Edges,
        reads: &[],
        // The sample grid follows the sound table (output rate, native spacing).
        // Without `all_frames` its frames are the flow stages' window, which the path and the
        // derivative mode choose.
        knobs_changed: |a, b| {
            a.method.reads_edges() != b.method.reads_edges()
                || differ(&a.edges, &b.edges)
                || differ(&a.sound, &b.sound)
                || (!a.edges.all_frames
                    && (a.path != b.path || a.derivatives.mode != b.derivatives.mode))
        },
        reads_slope_reference: false,
        needed: |p| p.method.reads_edges(),
        run: run_edges,
    },
];

/// Whether two knob tables differ, a NaN knob equal to a NaN knob. An operator can leave a
/// knob at NaN (the stage refuses it when it runs); were NaN unequal to itself, that stage
/// would look changed on every frame and the workbench would rerun it, failing, forever.
fn differ<T: PartialEq + serde::Serialize>(a: &T, b: &T) -> bool {
    if a == b {
        return false;
    }
    // Only tables holding a NaN reach here unchanged; TOML writes NaN as `nan`.
    match (toml::to_string(a), toml::to_string(b)) {
        (Ok(x), Ok(y)) => x != y,
        _ => true,
    }
}

fn reads_flow(p: &PipelineParams) -> bool {
    p.method.reads_flow()
}

fn missing(stage: Stage) -> StageError {
    StageError::BadInput {
        stage: stage.name(),
        problem: "an earlier stage has no result".into(),
    }
}

/// The frames `range` picks out of those `input` holds, and the group index of the first. A
/// stage's range is taken of the frames held, so the engine, which holds only the frames the
/// stages read ([`frames_read`]), and the workbench, which holds the whole group, pick the same.
fn held(input: &GroupInput, range: std::ops::Range<usize>) -> (&[crate::image::Image], usize) {
    match input.frames.get(range.clone()) {
        Some(frames) => (frames, input.first_frame + range.start),
        None => (&input.frames[..], input.first_frame),
    }
}

fn run_derivatives(r: &StageRun<'_>) -> Result<StageOutput, StageError> {
    let (input, params) = (r.input, r.params);
    let meta = &input.meta;
    // The dual-focus path reads only the middle window: derive just its frames.
    let (frames, first) = held(input, flow_frames(input.frames.len(), meta, params));
    let mut d = compute_derivatives(frames, meta.geometry().land_flow_px(), &params.derivatives)?;
    for set in &mut d {
        set.frame_index += first;
    }
    Ok(StageOutput::Derivatives(Arc::new(d)))
}

fn run_flow(r: &StageRun<'_>) -> Result<StageOutput, StageError> {
    let stage = Stage::Flow;
    let geom = r.input.meta.geometry();
    let derivs = r.cache.derivatives().ok_or_else(|| missing(stage))?;
    let flows = if r.params.uses_dual_focus(&r.input.meta) {
        // The dual-focus path reads one flow field, the middle window's (its in-focus map):
        // the other windows would be computed for nothing.
        let d = derivs.get(derivs.len() / 2).ok_or_else(|| missing(stage))?;
        vec![match r.cache.flow_detail() {
            FlowDetail::Field => compute_flow(d, geom.focal_px, None, &r.params.flow)?,
            FlowDetail::InFocusMap => flow_confidence_only(d, &r.params.flow)?,
        }]
    } else {
        flows_of_group(derivs, geom.focal_px, geom.land_flow_px(), &r.params.flow)?
    };
    Ok(StageOutput::Flow(Arc::new(flows)))
}

fn run_depth(r: &StageRun<'_>) -> Result<StageOutput, StageError> {
    if r.params.uses_dual_focus(&r.input.meta) {
        return Ok(StageOutput::Depth(None));
    }
    let geom = r.input.meta.geometry();
    let flows = r.cache.flows().ok_or_else(|| missing(Stage::Depth))?;
    let map = estimate_depth(flows, &geom, &r.params.depth)?;
    let walls = find_walls(&map, &geom, &r.params.walls)?;
    Ok(StageOutput::Depth(Some(Arc::new(DepthOutput {
        map,
        walls,
    }))))
}

fn run_stripes(r: &StageRun<'_>) -> Result<StageOutput, StageError> {
    let stage = Stage::Stripes;
    if !r.params.uses_dual_focus(&r.input.meta) {
        return Ok(StageOutput::Stripes(None));
    }
    let Some(df) = r.input.meta.dual_focus.as_ref() else {
        return Err(StageError::BadInput {
            stage: stage.name(),
            problem: "the dual-focus path needs a [dual_focus] table in scan.toml".into(),
        });
    };
    let derivs = r.cache.derivatives().ok_or_else(|| missing(stage))?;
    let flows = r.cache.flows().ok_or_else(|| missing(stage))?;
    let Some((d, f)) = middle_window(derivs, flows) else {
        return Err(missing(stage));
    };
    let stripes = segment_stripes(d, f, df, &r.params.hough)?;
    Ok(StageOutput::Stripes(Some(Arc::new(stripes))))
}

fn run_orientation(r: &StageRun<'_>) -> Result<StageOutput, StageError> {
    let stage = Stage::Orientation;
    let (input, params) = (r.input, r.params);
    let meta = &input.meta;
    let geom = meta.geometry();
    let (mut orientation, grid) = if params.uses_dual_focus(meta) {
        let stripes = r.cache.stripes().ok_or_else(|| missing(stage))?;
        let derivs = r.cache.derivatives().ok_or_else(|| missing(stage))?;
        let d = derivs.get(derivs.len() / 2).ok_or_else(|| missing(stage))?;
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
            stage.name(),
        )?;
        let o = orient_from_lines(
            &stripes.lines,
            d.ix.width,
            d.ix.height,
            &grid.columns,
            &geom,
            &params.orientation,
        )?;
        (o, grid)
    } else {
        let depth = r.cache.depth().ok_or_else(|| missing(stage))?;
        let zp = wall_depth_um(&depth.map, &depth.walls).ok_or_else(|| StageError::NotFound {
            stage: stage.name(),
            problem: "no depth on the wall lines".into(),
        })?;
        let grid = sample_grid(
            meta,
            input.group,
            depth.map.frame_index,
            depth.map.z_um.width,
            zp,
            &params.sound,
            stage.name(),
        )?;
        let o = orient_from_depth(
            &depth.map,
            &depth.walls,
            &grid.columns,
            &geom,
            &params.orientation,
        )?;
        (o, grid)
    };
    let own_slopes = orientation
        .walls
        .iter()
        .filter_map(|w| median_wall_slope(&w.samples).map(|m| (w.side, m)))
        .collect();
    check_against(
        &mut orientation,
        r.cache.slope_reference(),
        params.orientation.max_wall_slope_change,
    );
    Ok(StageOutput::Orientation(Arc::new(OrientationOutput {
        orientation,
        grid,
        own_slopes,
    })))
}

fn run_sound(r: &StageRun<'_>) -> Result<StageOutput, StageError> {
    let input = r.input;
    let o = r.cache.orientation().ok_or_else(|| missing(Stage::Sound))?;
    let signal = group_signal(
        input.group,
        &o.orientation,
        input.meta.record.cut,
        o.grid.column0_um,
        o.grid.um_per_px,
        input.meta.groove_speed_mm_s(input.group),
    )?;
    Ok(StageOutput::Sound(Arc::new(signal)))
}

fn run_edges(r: &StageRun<'_>) -> Result<StageOutput, StageError> {
    if !r.params.method.reads_edges() {
        return Ok(StageOutput::Edges(None));
    }
    let input = r.input;
    let (frames, first) = held(
        input,
        edge_frames(input.frames.len(), &input.meta, r.params),
    );
    let edges = detect_edges(
        frames,
        first,
        input.group,
        &input.meta,
        &r.params.sound,
        &r.params.edges,
    )?;
    Ok(StageOutput::Edges(Some(Arc::new(edges))))
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

/// The frames of a group of `n` that its stages read: the edge stage's ([`edge_frames`]) for a
/// method that reads the edges, else the flow stages' ([`flow_frames`]); the edge stage's hold
/// the flow stages'. Reconstruction decodes only these.
#[must_use]
pub fn frames_read(n: usize, meta: &ScanMeta, params: &PipelineParams) -> std::ops::Range<usize> {
    if params.method.reads_edges() {
        edge_frames(n, meta, params)
    } else {
        flow_frames(n, meta, params)
    }
}

/// The frames of a group of `n` the edge stage fits: all of them, or with `edges.all_frames`
/// off the flow stages' ([`flow_frames`]).
#[must_use]
pub fn edge_frames(n: usize, meta: &ScanMeta, params: &PipelineParams) -> std::ops::Range<usize> {
    if params.edges.all_frames {
        0..n
    } else {
        flow_frames(n, meta, params)
    }
}

/// The frames of a group of `n` the flow stages read: the middle derivative window on the
/// dual-focus path (its stripes come from that window alone), all of them on the depth path.
#[must_use]
pub fn flow_frames(n: usize, meta: &ScanMeta, params: &PipelineParams) -> std::ops::Range<usize> {
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
mod tests {
    use super::*;

    #[test]
    fn the_table_lists_every_stage_once_in_order_reading_only_earlier_ones() {
        for (i, spec) in GRAPH.iter().enumerate() {
            assert_eq!(spec.stage.index(), i, "{:?}", spec.stage);
            assert!(
                spec.reads.iter().all(|r| *r < spec.stage),
                "{:?}",
                spec.stage
            );
        }
    }

    #[test]
    fn a_nan_knob_equals_itself_so_its_stage_does_not_look_changed_forever() {
        let mut p = PipelineParams::default();
        p.flow.lambda = f32::NAN;
        p.orientation.sigma_start_um = f64::NAN;
        assert_eq!(p.first_changed_stage(&p.clone()), None);
        let mut q = p.clone();
        q.flow.lambda = 0.5;
        assert_eq!(p.first_changed_stage(&q), Some(Stage::Flow));
        let mut r = p.clone();
        r.orientation.sigma_start_um = f64::INFINITY;
        assert_eq!(p.first_changed_stage(&r), Some(Stage::Orientation));
    }
}
