//! The stage results on screen for the current group: the stage cache the worker fills, each
//! stage's error, time and run count, the textures rendered from its outputs, and which inputs
//! a failed stage failed with (so it is not retried until one of them changes).

use std::sync::Arc;
use std::time::Duration;

use super::textures::Textures;
use super::views::StageStatus;
use super::worker::StageResult;
use crate::pipeline::{PipelineParams, Stage, StageCache};

/// Number of stages.
pub const STAGES: usize = Stage::ALL.len();

/// Results of the current group's stages.
#[derive(Debug, Default)]
pub struct StageState {
    /// Latest outputs (possibly stale).
    pub cache: StageCache,
    /// Textures of the views, rendered from `cache`.
    pub textures: Textures,
    errors: [Option<String>; STAGES],
    /// Params and group each failed stage failed with.
    failed_with: [Option<(PipelineParams, usize)>; STAGES],
    times: [Option<Duration>; STAGES],
    runs: [u64; STAGES],
}

impl StageState {
    /// Status of `stage` of `group`: failed, running (`running` is the stage the worker is
    /// on), fresh for `params`, not used on this path (`dual`), or stale.
    #[must_use]
    pub fn status(
        &self,
        stage: Stage,
        group: usize,
        params: &PipelineParams,
        dual: bool,
        running: Option<Stage>,
    ) -> StageStatus {
        if let Some(e) = &self.errors[stage.index()] {
            return StageStatus::Failed(e.clone());
        }
        if running == Some(stage) {
            return StageStatus::Running;
        }
        if self.cache.group() == Some(group) && self.cache.is_fresh(stage, params) {
            let unused = if dual {
                stage == Stage::Depth
            } else {
                stage == Stage::Stripes
            };
            return if unused {
                StageStatus::Unused
            } else {
                StageStatus::Fresh
            };
        }
        StageStatus::Stale
    }

    /// How often `stage` finished for this scan (counts reruns).
    #[must_use]
    pub fn runs(&self, stage: Stage) -> u64 {
        self.runs[stage.index()]
    }

    /// Time of each stage's last run.
    #[must_use]
    pub fn times(&self) -> &[Option<Duration>; STAGES] {
        &self.times
    }

    /// Another group is shown: its results are not these.
    pub fn clear_for_group(&mut self) {
        self.cache.clear();
        self.errors = Default::default();
        self.failed_with = Default::default();
    }

    /// `stage` and every later one must run again (an explicit rerun).
    pub fn invalidate_from(&mut self, stage: Stage) {
        self.cache.invalidate(stage);
        for f in &mut self.failed_with[stage.index()..] {
            *f = None;
        }
    }

    /// True when `from` failed for `group` with inputs `params` leaves unchanged (a rerun
    /// would fail the same way).
    #[must_use]
    pub fn failed_with_these(&self, from: Stage, group: usize, params: &PipelineParams) -> bool {
        self.failed_with[from.index()]
            .as_ref()
            .is_some_and(|(p, g)| {
                *g == group && p.first_changed_stage(params).is_none_or(|s| s > from)
            })
    }

    /// A job from `from` starts: forget the errors it may clear.
    pub fn clear_errors_from(&mut self, from: Stage) {
        for e in &mut self.errors[from.index()..] {
            *e = None;
        }
    }

    /// Takes a finished stage's outputs when they belong to `group` and `params`; uploads its
    /// renderings. False when they are out of date (a newer job or another group).
    pub fn adopt(
        &mut self,
        ctx: &egui::Context,
        stage: Stage,
        result: StageResult,
        elapsed: Duration,
        group: usize,
        params: &PipelineParams,
    ) -> bool {
        let usable = result.cache.group() == Some(group) && result.cache.is_fresh(stage, params);
        if !usable {
            return false;
        }
        self.cache.adopt(stage, &result.cache);
        let i = stage.index();
        self.errors[i] = None;
        self.times[i] = Some(elapsed);
        self.runs[i] += 1;
        let source = self.cache.output_id(stage);
        for (key, r) in result.renders {
            self.textures.set(ctx, key, Arc::clone(&r), source);
        }
        true
    }

    /// `stage` failed with `msg` for `group` with `params`.
    pub fn fail(&mut self, stage: Stage, msg: String, params: &PipelineParams, group: usize) {
        self.errors[stage.index()] = Some(msg);
        self.failed_with[stage.index()] = Some((params.clone(), group));
    }

    /// The group's frames cannot be read (`msg` says why): every stage, each of which reads
    /// them, has failed, instead of waiting as stale for a run that cannot come.
    pub fn frames_unreadable(&mut self, msg: &str) {
        for e in &mut self.errors {
            *e = Some(format!("the group's frames cannot be read: {msg}"));
        }
    }

    /// Marks `stage` failed when its job ended in failure without saying why.
    pub fn fail_unexplained(&mut self, stage: Stage) {
        if let Some(e) = self.errors.get_mut(stage.index())
            && e.is_none()
        {
            *e = Some("failed".into());
        }
    }
}
