//! Whole sides: plans that cut a scan into shards, journals that let a run resume, parts, and their merge.
//!
//! A *plan* (`plan.json`) cuts the groups into contiguous ranges. Each shard runs its range to
//! a *part* (the group signals with exact float bits, their report rows and an identity), and
//! *merge* finishes the parts' signals, in group order, with the same
//! [`crate::pipeline::finish::finish_clip`] a one-process run ends with, so the WAV is the
//! same byte for byte. What a group gives depends on its own frames and on the clip's slope
//! reference ([`crate::pipeline::slope_reference::SlopeReference`]), the medians of the groups before it: a shard
//! first runs enough groups before its range to rebuild that history exactly
//! ([`run::seed_before`]). Every run journals its finished groups (`journal`), so a killed run
//! continues where it stopped.

pub mod cli;
pub mod journal;
pub mod merge;
pub mod part;
pub mod plan;
pub mod record;
pub mod run;

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use crate::engine::EngineError;
use crate::io::{LoadError, Scan};
use crate::pipeline::PipelineParams;

/// Why a plan, shard, journal or merge was refused or failed.
#[derive(Debug, thiserror::Error)]
pub enum SideError {
    /// The file belongs to another run, is damaged, or is missing; the message says which.
    #[error("{problem}: {}", path.display())]
    Refused {
        /// What is wrong.
        problem: String,
        /// The plan, journal or part.
        path: PathBuf,
    },
    /// The reconstruction failed.
    #[error(transparent)]
    Engine(#[from] EngineError),
    /// Reading or writing a file failed.
    #[error(transparent)]
    Load(#[from] LoadError),
}

impl SideError {
    fn refused(problem: impl Into<String>, path: impl Into<PathBuf>) -> Self {
        Self::Refused {
            problem: problem.into(),
            path: path.into(),
        }
    }

    fn io(problem: &str, e: &std::io::Error, path: impl Into<PathBuf>) -> Self {
        Self::Load(LoadError::Io {
            problem: format!("{problem}: {e}"),
            path: path.into(),
        })
    }
}

pub use crate::io::fingerprint::{fingerprint, scan_fingerprint};

/// The params' fingerprint (over their canonical TOML).
#[must_use]
pub fn params_fingerprint(params: &PipelineParams) -> String {
    fingerprint(params.to_toml_string().unwrap_or_default().as_bytes())
}

/// Which shard of which plan a run is.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ShardId {
    /// Shard index, from 0.
    pub index: usize,
    /// Shards in the plan.
    pub count: usize,
    /// The plan's fingerprint.
    pub plan_fingerprint: String,
}

/// What a journal or part belongs to: written as its header, compared before anything is
/// mixed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunIdentity {
    /// groovescope version that wrote it (not compared).
    pub groovescope: String,
    /// The scan as given on the command line (not compared).
    pub scan: String,
    /// [`scan_fingerprint`].
    pub scan_fingerprint: String,
    /// Groups in the whole scan.
    pub scan_groups: usize,
    /// [`params_fingerprint`].
    pub params_fingerprint: String,
    /// Unreadable groups become gaps instead of failing the run.
    pub keep_going: bool,
    /// First group and end group (exclusive) of the run.
    pub groups: (usize, usize),
    /// The shard, for a run of a plan.
    pub shard: Option<ShardId>,
    /// The params (a merge finishes the clip with them).
    pub params: PipelineParams,
    /// The scan's metadata as TOML (a merge needs the groove speed).
    pub meta_toml: String,
}

impl RunIdentity {
    /// The identity of a run of `range` of `scan` with `params`.
    #[must_use]
    pub fn new(
        scan: &Scan,
        params: &PipelineParams,
        keep_going: bool,
        range: std::ops::Range<usize>,
        shard: Option<ShardId>,
    ) -> Self {
        Self {
            groovescope: env!("CARGO_PKG_VERSION").to_string(),
            scan: scan.dir.display().to_string(),
            scan_fingerprint: scan_fingerprint(scan),
            scan_groups: scan.groups.len(),
            params_fingerprint: params_fingerprint(params),
            keep_going,
            groups: (range.start, range.end),
            shard,
            params: params.clone(),
            meta_toml: scan.meta.to_toml_string().unwrap_or_default(),
        }
    }

    /// True when `other` is this run but for the params' `[dsp]` table, written by this
    /// version: only the finish reads `[dsp]`, so `other`'s groups are this run's groups.
    #[must_use]
    pub fn same_groups_as(&self, other: &RunIdentity) -> bool {
        // `other` with these params: any difference left is beyond the params.
        let rest = RunIdentity {
            params: self.params.clone(),
            params_fingerprint: self.params_fingerprint.clone(),
            ..other.clone()
        };
        other.groovescope == self.groovescope
            && self.params.same_groups_as(&other.params)
            && self.difference(&rest).is_none()
    }

    /// How `other` differs from this identity, in words (None when it is the same run).
    #[must_use]
    pub fn difference(&self, other: &RunIdentity) -> Option<String> {
        if other.scan_fingerprint != self.scan_fingerprint {
            return Some(format!(
                "made from another scan (fingerprint {}, expected {})",
                other.scan_fingerprint, self.scan_fingerprint
            ));
        }
        if other.params_fingerprint != self.params_fingerprint {
            return Some(format!(
                "made with other params (fingerprint {}, expected {})",
                other.params_fingerprint, self.params_fingerprint
            ));
        }
        if other.keep_going != self.keep_going {
            return Some(
                if other.keep_going {
                    "made with --keep-going (unreadable groups became gaps), which this run lacks"
                } else {
                    "made without --keep-going, which this run has"
                }
                .to_string(),
            );
        }
        let plan = |s: &Option<ShardId>| s.as_ref().map(|s| s.plan_fingerprint.clone());
        if plan(&other.shard) != plan(&self.shard) {
            return Some(match (&other.shard, &self.shard) {
                (Some(o), Some(s)) => format!(
                    "made for another plan (fingerprint {}, expected {})",
                    o.plan_fingerprint, s.plan_fingerprint
                ),
                (Some(_), None) => "made for a shard of a plan, not a whole run".to_string(),
                _ => "made by a whole run, not a shard of a plan".to_string(),
            });
        }
        if other.shard != self.shard {
            return Some("made for another shard of the plan".to_string());
        }
        if other.groups != self.groups {
            return Some(format!(
                "made for groups {}..{}, expected {}..{}",
                other.groups.0, other.groups.1, self.groups.0, self.groups.1
            ));
        }
        None
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;

    #[test]
    fn fingerprints_are_stable_and_tell_inputs_apart() {
        // FNV-1a 64 of "a" is a published test vector.
        assert_eq!(fingerprint(b"a"), "af63dc4c8601ec8c");
        assert_ne!(fingerprint(b"ab"), fingerprint(b"ba"));
        let mut p = PipelineParams::default();
        let before = params_fingerprint(&p);
        p.flow.lambda *= 2.0;
        assert_ne!(params_fingerprint(&p), before);
    }
}
