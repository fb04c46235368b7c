//! Plans: a scan's groups cut into contiguous shard ranges, with the params every shard runs and the expected time.

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::{ShardId, SideError, fingerprint, params_fingerprint, scan_fingerprint};
use crate::io::Scan;
use crate::pipeline::PipelineParams;
use crate::pipeline::slope_reference::SLOPE_HISTORY;

/// The plan format this build reads and writes.
pub const PLAN_FORMAT: u32 = 1;
/// The plan's `kind` field.
pub const PLAN_KIND: &str = "groovescope-plan";

/// One shard of a plan.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlanShard {
    /// Shard index, from 0.
    pub index: usize,
    /// First group of its range.
    pub first_group: usize,
    /// End of its range (exclusive).
    pub end_group: usize,
    /// First group it runs for the slope history before its range (more when groups there
    /// fail or miss a wall).
    pub context_first_group: usize,
    /// Expected seconds on one machine like the one the plan was made on (None: not measured).
    pub expected_secs: Option<f64>,
}

/// A plan (`plan.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Plan {
    /// [`PLAN_FORMAT`].
    pub format: u32,
    /// [`PLAN_KIND`].
    pub kind: String,
    /// The scan as given.
    pub scan: String,
    /// [`scan_fingerprint`].
    pub scan_fingerprint: String,
    /// Groups in the scan.
    pub groups: usize,
    /// Groups each shard runs before its range for the slope history.
    pub context_groups: usize,
    /// Unreadable groups become gaps.
    pub keep_going: bool,
    /// Measured seconds per group, decode included (None: not measured).
    pub secs_per_group: Option<f64>,
    /// How `secs_per_group` was measured.
    pub secs_per_group_basis: String,
    /// The shards.
    pub shards: Vec<PlanShard>,
    /// [`params_fingerprint`] of `params`.
    pub params_fingerprint: String,
    /// The params every shard runs.
    pub params: PipelineParams,
    /// Fingerprint of the scan, params, option and ranges (not of the time estimates).
    pub fingerprint: String,
}

impl Plan {
    /// Cuts `scan`'s groups into `shards` contiguous ranges of near-equal length.
    ///
    /// # Errors
    /// [`SideError::Refused`] for 0 shards or more shards than groups.
    pub fn new(
        scan: &Scan,
        params: &PipelineParams,
        keep_going: bool,
        shards: usize,
        secs_per_group: Option<(f64, String)>,
    ) -> Result<Self, SideError> {
        let n = scan.groups.len();
        if shards == 0 || shards > n {
            return Err(SideError::refused(
                format!("--shards {shards} must be between 1 and the scan's {n} groups"),
                &scan.dir,
            ));
        }
        let (secs, basis) = match secs_per_group {
            Some((s, b)) => (Some(s), b),
            None => (None, "not measured".to_string()),
        };
        let shards = (0..shards)
            .map(|k| {
                let (first, end) = (k * n / shards, (k + 1) * n / shards);
                let context_first_group = first.saturating_sub(SLOPE_HISTORY);
                PlanShard {
                    index: k,
                    first_group: first,
                    end_group: end,
                    context_first_group,
                    expected_secs: secs.map(|s| s * (end - context_first_group) as f64),
                }
            })
            .collect();
        let mut plan = Self {
            format: PLAN_FORMAT,
            kind: PLAN_KIND.to_string(),
            scan: scan.dir.display().to_string(),
            scan_fingerprint: scan_fingerprint(scan),
            groups: n,
            context_groups: SLOPE_HISTORY,
            keep_going,
            secs_per_group: secs,
            secs_per_group_basis: basis,
            shards,
            params_fingerprint: params_fingerprint(params),
            params: params.clone(),
            fingerprint: String::new(),
        };
        plan.fingerprint = plan.computed_fingerprint();
        Ok(plan)
    }

    fn computed_fingerprint(&self) -> String {
        let mut text = format!(
            "plan {} scan {} groups {} params {} keep_going {} context {}\n",
            self.format,
            self.scan_fingerprint,
            self.groups,
            params_fingerprint(&self.params),
            self.keep_going,
            self.context_groups
        );
        for s in &self.shards {
            text.push_str(&format!("{} {} {}\n", s.index, s.first_group, s.end_group));
        }
        fingerprint(text.as_bytes())
    }

    /// Reads and checks a plan file.
    ///
    /// # Errors
    /// [`SideError::Refused`] naming the file when it cannot be read, is not a plan, or was
    /// edited (its fingerprint, ranges or params do not add up).
    pub fn load(path: &Path) -> Result<Self, SideError> {
        let bytes =
            std::fs::read(path).map_err(|e| SideError::io("cannot read the plan", &e, path))?;
        let plan: Plan = serde_json::from_slice(&bytes)
            .map_err(|e| SideError::refused(format!("not a groovescope plan ({e})"), path))?;
        if plan.kind != PLAN_KIND || plan.format != PLAN_FORMAT {
            return Err(SideError::refused(
                format!("not a groovescope plan of format {PLAN_FORMAT}"),
                path,
            ));
        }
        let tiles = plan.shards.iter().enumerate().all(|(k, s)| {
            s.index == k
                && s.first_group < s.end_group
                && (k == 0
                    || plan
                        .shards
                        .get(k - 1)
                        .is_some_and(|p| p.end_group == s.first_group))
        }) && plan.shards.first().is_some_and(|s| s.first_group == 0)
            && plan
                .shards
                .last()
                .is_some_and(|s| s.end_group == plan.groups);
        if !tiles
            || plan.computed_fingerprint() != plan.fingerprint
            || params_fingerprint(&plan.params) != plan.params_fingerprint
        {
            return Err(SideError::refused(
                "the plan was edited or is damaged (its shards or fingerprint do not add up)",
                path,
            ));
        }
        plan.params
            .validate()
            .map_err(|e| SideError::refused(e.to_string(), path))?;
        Ok(plan)
    }

    /// Shard `index`, checked against this plan and `scan`.
    ///
    /// # Errors
    /// [`SideError::Refused`] naming the plan when the index is out of range or the scan is
    /// not the one the plan was made for.
    pub fn shard(
        &self,
        index: usize,
        scan: &Scan,
        path: &Path,
    ) -> Result<(&PlanShard, ShardId), SideError> {
        let found = scan_fingerprint(scan);
        if found != self.scan_fingerprint || scan.groups.len() != self.groups {
            return Err(SideError::refused(
                format!(
                    "the plan was made for another scan ({} groups, fingerprint {}; {} has {} groups, fingerprint {found})",
                    self.groups,
                    self.scan_fingerprint,
                    scan.dir.display(),
                    scan.groups.len()
                ),
                path,
            ));
        }
        let Some(shard) = self.shards.get(index) else {
            return Err(SideError::refused(
                format!(
                    "--shard {index} is out of range: the plan has {} shards (0 to {})",
                    self.shards.len(),
                    self.shards.len().saturating_sub(1)
                ),
                path,
            ));
        };
        Ok((
            shard,
            ShardId {
                index,
                count: self.shards.len(),
                plan_fingerprint: self.fingerprint.clone(),
            },
        ))
    }
}
