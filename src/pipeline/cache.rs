//! The stage cache shared by the CLI and the workbench: a private store of each stage's output with the key it was made with, rerun from the first stale stage.
//!
//! What makes a stage stale follows from [`GRAPH`](super::graph::GRAPH) alone: a slot is fresh
//! when its stage's knobs and clip inputs are unchanged and every stage it reads still holds
//! the very output (the same version) it was made from, itself fresh. Every output gets a
//! process-wide version number, so outputs copied between caches (the workbench adopts its
//! worker's) keep their identity.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use super::audio_signal::GroupSignal;
use super::derivatives::Derivatives;
use super::edges::Edges;
use super::graph::{DepthOutput, FlowDetail, OrientationOutput, Stage, StageOutput, StageRun};
use super::hough::Stripes;
use super::optical_flow::FlowField;
use super::slope_reference::SlopeReference;
use super::{PipelineParams, StageError};
use crate::image::Image;
use crate::meta::ScanMeta;

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

/// The next output version (process-wide, never 0).
static NEXT_VERSION: AtomicU64 = AtomicU64::new(1);

/// One stage's output and what it was made from.
#[derive(Clone, Debug)]
struct Slot {
    output: StageOutput,
    /// Unique identity of this output.
    version: u64,
    /// The knobs it was made with.
    params: PipelineParams,
    /// Versions of the outputs of the stages it read, in `reads` order.
    reads: Vec<u64>,
    /// The clip's slope reference it read, if its stage reads one.
    reference: Option<SlopeReference>,
    /// Marked for a rerun (the output stays for display).
    stale: bool,
}

/// A group's stage outputs. Clones are cheap (`Arc`s), so a worker can take a copy, run, and
/// send it back.
#[derive(Clone, Debug, Default)]
pub struct StageCache {
    flow_detail: FlowDetail,
    /// Run only the stages the method's sound needs ([`StageSpec::needed`](super::graph::StageSpec::needed)).
    sound_only: bool,
    /// The clip's slope reference, an input of the orientation stage.
    slope_reference: SlopeReference,
    /// The group and metadata the slots belong to.
    owner: Option<(usize, Arc<ScanMeta>)>,
    slots: [Option<Slot>; Stage::COUNT],
}

/// One accessor per stage output, `name: Variant => Type;` each: the output of
/// `Stage::Variant`, when its slot holds one (and, for a stage that only one path runs, when
/// that path ran it).
macro_rules! output_accessors {
    ($($(#[doc = $doc:literal])* $name:ident: $variant:ident => $ty:ty;)*) => {
        $(
            $(#[doc = $doc])*
            #[must_use]
            pub fn $name(&self) -> Option<&Arc<$ty>> {
                match self.output(Stage::$variant)? {
                    StageOutput::$variant(o) => o.into(),
                    _ => None,
                }
            }
        )*
    };
}

impl StageCache {
    /// An empty cache whose flow stage computes `flow_detail` on the dual-focus path.
    #[must_use]
    pub fn new(flow_detail: FlowDetail) -> Self {
        Self {
            flow_detail,
            ..Self::default()
        }
    }

    /// This cache, running only the stages the method's sound needs (whole-scan
    /// reconstruction): the others are skipped and hold no output. The workbench runs them all.
    #[must_use]
    pub fn sound_only(mut self) -> Self {
        self.sound_only = true;
        self
    }

    /// True when a stage runs for `params`: every stage, or in a [`StageCache::sound_only`]
    /// cache those the method's sound needs.
    #[must_use]
    pub fn runs(&self, stage: Stage, params: &PipelineParams) -> bool {
        !self.sound_only || (stage.spec().needed)(params)
    }

    /// How much the flow stage computes on the dual-focus path.
    #[must_use]
    pub fn flow_detail(&self) -> FlowDetail {
        self.flow_detail
    }

    /// The clip's slope reference the orientation stage reads.
    #[must_use]
    pub fn slope_reference(&self) -> &SlopeReference {
        &self.slope_reference
    }

    /// Sets the clip's slope reference (a changed one makes orientation onward stale).
    pub fn set_slope_reference(&mut self, reference: SlopeReference) {
        self.slope_reference = reference;
    }

    /// The group the outputs belong to.
    #[must_use]
    pub fn group(&self) -> Option<usize> {
        self.owner.as_ref().map(|(g, _)| *g)
    }

    fn output(&self, stage: Stage) -> Option<&StageOutput> {
        self.slots[stage.index()].as_ref().map(|s| &s.output)
    }

    output_accessors! {
        /// [`Stage::Derivatives`]: one set per derivative window.
        derivatives: Derivatives => Vec<Derivatives>;
        /// [`Stage::Flow`]: one field per derivative window (dual-focus path: the middle one).
        flows: Flow => Vec<FlowField>;
        /// [`Stage::Depth`] (depth path only).
        depth: Depth => DepthOutput;
        /// [`Stage::Stripes`] (dual-focus path only).
        stripes: Stripes => Stripes;
        /// [`Stage::Orientation`].
        orientation: Orientation => OrientationOutput;
        /// [`Stage::Sound`].
        signal: Sound => GroupSignal;
        /// [`Stage::Edges`] (methods that read the edges only).
        edges: Edges => Edges;
    }

    /// A unique identity of the output `stage` holds (0 when none): equal identities mean the
    /// same output, in this cache or a copy of it.
    #[must_use]
    pub fn output_id(&self, stage: Stage) -> u64 {
        self.slots[stage.index()].as_ref().map_or(0, |s| s.version)
    }

    /// Marks `stage` for a rerun; every stage that reads it goes stale with it. The outputs
    /// stay for display.
    pub fn invalidate(&mut self, stage: Stage) {
        if let Some(slot) = &mut self.slots[stage.index()] {
            slot.stale = true;
        }
    }

    /// Forgets every output (another group or scan).
    pub fn clear(&mut self) {
        self.slots = Default::default();
        self.owner = None;
    }

    /// True when `stage` holds an output made with `params` (the knobs it reads) and the
    /// current clip inputs from the current, fresh outputs of every stage it reads.
    #[must_use]
    pub fn is_fresh(&self, stage: Stage, params: &PipelineParams) -> bool {
        let spec = stage.spec();
        if !self.runs(stage, params) {
            // A skipped stage holds nothing, and nothing that runs reads it.
            return true;
        }
        let Some(slot) = &self.slots[stage.index()] else {
            return false;
        };
        !slot.stale
            && !(spec.knobs_changed)(&slot.params, params)
            && (!spec.reads_slope_reference
                || slot.reference.as_ref() == Some(&self.slope_reference))
            && spec
                .reads
                .iter()
                .zip(&slot.reads)
                .all(|(r, &v)| self.output_id(*r) == v && self.is_fresh(*r, params))
    }

    /// The first stage that must run for `params` (None: everything is fresh).
    #[must_use]
    pub fn first_stale(&self, params: &PipelineParams) -> Option<Stage> {
        Stage::ALL.into_iter().find(|s| !self.is_fresh(*s, params))
    }

    /// Takes `stage`'s output, with what it was made from, from `other` (a copy of this cache
    /// that a worker ran on). Does nothing when `other` belongs to another group or scan.
    pub fn adopt(&mut self, stage: Stage, other: &StageCache) {
        if other.owner.is_none() {
            return;
        }
        if !same_owner(&self.owner, &other.owner) {
            self.clear();
            self.owner.clone_from(&other.owner);
        }
        self.slots[stage.index()].clone_from(&other.slots[stage.index()]);
    }

    /// Runs `from` and every later stage that is not fresh for `input`, storing each result.
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
        super::sampling::check_sample_density(&input.meta, &params.sound).map_err(|too_fine| {
            StageError::BadInput {
                stage: "sampling",
                problem: too_fine.problem,
            }
        })?;
        let owner = Some((input.group, input.meta.clone()));
        if !same_owner(&self.owner, &owner) {
            self.clear();
            self.owner = owner;
        }
        for stage in Stage::ALL.into_iter().filter(|s| *s >= from) {
            if !self.runs(stage, params) {
                self.slots[stage.index()] = None;
                continue;
            }
            if stage > from && self.is_fresh(stage, params) {
                continue;
            }
            self.invalidate(stage);
            let spec = stage.spec();
            let run = StageRun {
                input,
                params,
                cache: self,
            };
            let output = (spec.run)(&run)?;
            let reads = spec.reads.iter().map(|r| self.output_id(*r)).collect();
            self.slots[stage.index()] = Some(Slot {
                output,
                version: NEXT_VERSION.fetch_add(1, Ordering::Relaxed),
                params: params.clone(),
                reads,
                reference: spec
                    .reads_slope_reference
                    .then(|| self.slope_reference.clone()),
                stale: false,
            });
            if !after_stage(stage, self) {
                return Err(StageError::Cancelled);
            }
        }
        Ok(())
    }
}

/// True when both name the same group of the same scan metadata.
fn same_owner(a: &Option<(usize, Arc<ScanMeta>)>, b: &Option<(usize, Arc<ScanMeta>)>) -> bool {
    match (a, b) {
        (Some((ga, ma)), Some((gb, mb))) => ga == gb && (Arc::ptr_eq(ma, mb) || ma == mb),
        _ => false,
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests fail loudly on purpose
mod tests {
    use super::*;
    use crate::pipeline::derivatives::{DerivativeMode, DerivativeParams, compute_derivatives};
    use crate::pipeline::graph::middle_window_range;

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
        use crate::job::Job;
        let dir = tempfile::tempdir().unwrap();
        let cfg = crate::synth::SynthConfig {
            frames_per_group: frames,
            ..crate::accuracy::small_dual_focus(1)
        };
        let tone = crate::synth::tone(1000.0, 0.01, crate::synth::BUILTIN_RATE_HZ);
        crate::synth::render_scan(&tone, &cfg, dir.path(), Job::unwatched()).unwrap();
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
            let mut c = StageCache::new(flow_detail);
            c.run_from(Stage::Derivatives, &input, &params, &mut |_, _| true)
                .unwrap();
            c
        };
        let (full, lean) = (run(FlowDetail::Field), run(FlowDetail::InFocusMap));
        let (ff, lf) = (&full.flows().unwrap()[0], &lean.flows().unwrap()[0]);
        assert!(ff.iterations > 0 && !ff.u.data.is_empty());
        assert_eq!((lf.iterations, lf.u.data.len()), (0, 0));
        assert_eq!(ff.confidence, lf.confidence);
        assert_eq!(full.stripes(), lean.stripes());
        // Debug text, so NaN gaps (and NaN weights) compare equal to themselves.
        let same =
            |a: &dyn std::fmt::Debug, b: &dyn std::fmt::Debug| format!("{a:?}") == format!("{b:?}");
        assert!(
            same(&full.orientation(), &lean.orientation()),
            "orientation differs"
        );
        assert!(same(&full.signal(), &lean.signal()), "sound differs");
        assert!(lean.signal().unwrap().positions_um.len() > 10);
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
        assert_eq!(a.derivatives().unwrap()[0].frame_index, 6);
        assert_eq!(a.derivatives(), b.derivatives());
        assert_eq!(a.stripes(), b.stripes());
        assert_eq!(
            format!("{:?}", a.signal()),
            format!("{:?}", b.signal()),
            "sound differs"
        );
        // Without the offset the samples would land three frames early along the groove.
        let shifted = GroupInput {
            first_frame: 0,
            ..part
        };
        let c = run(&shifted);
        assert_ne!(
            a.signal().unwrap().positions_um,
            c.signal().unwrap().positions_um
        );
    }

    #[test]
    fn edges_on_the_flow_window_fit_the_same_frames_whether_or_not_the_rest_are_held() {
        let full = dual_focus_group(12);
        let window = middle_window_range(12, DerivativeMode::Simoncelli);
        let part = GroupInput {
            frames: Arc::new(full.frames[window.clone()].to_vec()),
            first_frame: window.start,
            ..full.clone()
        };
        let run = |input: &GroupInput, all_frames: bool| {
            let mut params = PipelineParams::default();
            params.edges.all_frames = all_frames;
            assert_eq!(
                crate::pipeline::frames_read(12, &input.meta, &params),
                if all_frames { 0..12 } else { window.clone() }
            );
            let mut c = StageCache::default();
            c.run_from(Stage::Edges, input, &params, &mut |_, _| true)
                .unwrap();
            format!("{:?}", c.edges().unwrap())
        };
        // The workbench holds the whole group, reconstruction only the window it reads.
        let (held_all, held_window) = (run(&full, false), run(&part, false));
        assert_eq!(held_all, held_window);
        // Every frame is read by default, and gives other fits.
        assert_ne!(run(&full, true), held_all);
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

    /// A cache that has run every stage on `input` with `p`.
    fn run_all(input: &GroupInput, p: &PipelineParams) -> StageCache {
        let mut cache = StageCache::default();
        cache
            .run_from(Stage::Derivatives, input, p, &mut |_, _| true)
            .unwrap();
        cache
    }

    /// Staleness follows the graph: a Hough range makes stripes, orientation and sound stale
    /// (not derivatives, flow or depth); λ makes flow onward stale; an output-rate change the
    /// orientation stage's sample grid; a rerun of flow everything that reads it, transitively;
    /// a new clip slope reference orientation onward.
    #[test]
    fn staleness_follows_the_stage_graph() {
        let (input, p) = (dual_focus_group(7), PipelineParams::default());
        let mut cache = run_all(&input, &p);
        assert_eq!(cache.first_stale(&p), None);
        let fresh = |c: &StageCache, q: &PipelineParams| Stage::ALL.map(|s| c.is_fresh(s, q));
        let mut hough = p.clone();
        hough.hough.theta_max_deg -= 5.0;
        assert_eq!(cache.first_stale(&hough), Some(Stage::Stripes));
        assert_eq!(
            fresh(&cache, &hough),
            [true, true, true, false, false, false, true]
        );
        let mut lambda = p.clone();
        lambda.flow.lambda *= 2.0;
        assert_eq!(
            fresh(&cache, &lambda),
            [true, false, false, false, false, false, true]
        );
        let mut rate = p.clone();
        rate.sound.output_rate_hz = 48_000;
        assert_eq!(cache.first_stale(&rate), Some(Stage::Orientation));
        let mut reference = cache.clone();
        reference.set_slope_reference(SlopeReference {
            sides: vec![(crate::pipeline::walls::WallSide::Left, 0.4)],
        });
        assert_eq!(reference.first_stale(&p), Some(Stage::Orientation));
        // A rerun of flow: its readers go stale with it; running from there brings all back.
        let runs = std::cell::RefCell::new(Vec::new());
        cache.invalidate(Stage::Flow);
        assert_eq!(
            fresh(&cache, &p),
            [true, false, false, false, false, false, true]
        );
        let before = cache.output_id(Stage::Derivatives);
        cache
            .run_from(Stage::Flow, &input, &p, &mut |s, _| {
                runs.borrow_mut().push(s);
                true
            })
            .unwrap();
        assert_eq!(runs.into_inner(), &Stage::ALL[1..6], "edges read no flow");
        assert_eq!(
            cache.output_id(Stage::Derivatives),
            before,
            "derivatives kept"
        );
        assert_eq!(cache.first_stale(&p), None);
        // Only what is stale after the first stage runs: from stripes, depth is skipped.
        let runs = std::cell::RefCell::new(Vec::new());
        cache
            .run_from(Stage::Stripes, &input, &hough, &mut |s, _| {
                runs.borrow_mut().push(s);
                true
            })
            .unwrap();
        assert_eq!(
            runs.into_inner(),
            [Stage::Stripes, Stage::Orientation, Stage::Sound]
        );
    }

    /// A cache adopts another's outputs stage by stage, keeping their identity, and a copy
    /// from another group replaces everything.
    #[test]
    fn adopted_outputs_keep_their_identity() {
        let (input, p) = (dual_focus_group(7), PipelineParams::default());
        let worker = run_all(&input, &p);
        let mut ui = StageCache::default();
        for s in Stage::ALL {
            ui.adopt(s, &worker);
            assert_eq!(ui.output_id(s), worker.output_id(s));
            assert!(ui.is_fresh(s, &p), "{s:?}");
        }
        let other = GroupInput {
            group: 1,
            ..input.clone()
        };
        let mut elsewhere = StageCache::default();
        elsewhere
            .run_from(Stage::Derivatives, &other, &p, &mut |_, _| true)
            .unwrap();
        ui.adopt(Stage::Derivatives, &elsewhere);
        assert_eq!(ui.group(), Some(1));
        assert!(ui.flows().is_none(), "the other group's outputs are gone");
    }
}
