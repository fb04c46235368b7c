//! Merge: the parts of every shard of one plan, checked, then finished exactly as a one-process run.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};

use super::part::{read_part, read_part_header};
use super::{RunIdentity, SideError};
use crate::engine::{ClipGroups, EngineError, Reconstruction, finish_reconstruction};
use crate::io::ScanMeta;
use crate::pipeline::PipelineParams;
use crate::pipeline::dsp::DspParams;

/// A merged side.
#[derive(Debug)]
pub struct Merged {
    /// The reconstruction, as one process would have made it.
    pub reconstruction: Reconstruction,
    /// The identity of shard 0 (scan, params) with the whole scan's range.
    pub identity: RunIdentity,
    /// The parts, in shard order.
    pub parts: Vec<PathBuf>,
}

/// A part whose header passed [`read_parts`]' checks: where it is and what it belongs to
/// (its groups are read and checked, one part at a time, when merged).
#[derive(Clone, Debug)]
pub struct CheckedPart {
    /// The part as given.
    pub path: PathBuf,
    /// Its header.
    pub identity: RunIdentity,
}

/// Reads every part and checks that together they are all the shards of one plan: one scan,
/// one plan, one set of params, each shard once. Only the headers are read here;
/// [`merge_parts`] reads each part whole (checksum, every group record) as it adds it, so a
/// side's parts are read once and never all in memory at once. Returns them in shard order.
///
/// # Errors
/// [`SideError::Refused`] naming the part: not a part, a damaged header, from another scan,
/// another plan, other params, a duplicated shard; or naming the shard that is missing.
pub fn read_parts(paths: &[PathBuf]) -> Result<Vec<CheckedPart>, SideError> {
    if paths.is_empty() {
        return Err(SideError::refused("no parts given", "."));
    }
    let mut parts: Vec<CheckedPart> = Vec::with_capacity(paths.len());
    for path in paths {
        let part = CheckedPart {
            path: path.clone(),
            identity: read_part_header(path)?,
        };
        let Some(shard) = part.identity.shard.clone() else {
            return Err(SideError::refused(
                "not a shard's part (no plan in its header)",
                path,
            ));
        };
        if let Some(first) = parts.first() {
            let mut expected = first.identity.clone();
            expected.shard = Some(super::ShardId {
                index: shard.index,
                ..first.identity.shard.clone().unwrap_or(shard.clone())
            });
            expected.groups = part.identity.groups;
            // A shard may have gone on past an unreadable group (--keep-going) where the plan
            // did not: its part holds the gap, the others hold none.
            expected.keep_going = part.identity.keep_going;
            if let Some(diff) = expected.difference(&part.identity) {
                return Err(SideError::refused(
                    format!("part {diff} (against {})", first.path.display()),
                    path,
                ));
            }
            if let Some(twin) = parts
                .iter()
                .find(|p| p.identity.shard.as_ref().map(|s| s.index) == Some(shard.index))
            {
                return Err(SideError::refused(
                    format!(
                        "duplicates shard {} of {} (also given as {})",
                        shard.index,
                        shard.count,
                        twin.path.display()
                    ),
                    path,
                ));
            }
        }
        if shard.index >= shard.count {
            return Err(SideError::refused(
                "its shard index is past its count",
                path,
            ));
        }
        parts.push(part);
    }
    parts.sort_by_key(|p| p.identity.groups.0);
    let count = parts
        .first()
        .and_then(|p| p.identity.shard.as_ref())
        .map_or(0, |s| s.count);
    let index = |p: &CheckedPart| p.identity.shard.as_ref().map(|s| s.index);
    let held: Vec<usize> = parts.iter().filter_map(index).collect();
    // Each run of missing shards, with the groups it leaves uncovered: the plan tiles the scan
    // in shard order, so they lie between the parts on either side of the run.
    let mut gaps: Vec<String> = Vec::new();
    let mut k = 0;
    while k < count {
        if held.contains(&k) {
            k += 1;
            continue;
        }
        let first = k;
        while k < count && !held.contains(&k) {
            k += 1;
        }
        let start = parts
            .iter()
            .filter(|p| index(p).is_some_and(|i| i < first))
            .map(|p| p.identity.groups.1)
            .max()
            .unwrap_or(0);
        let end = parts
            .iter()
            .filter(|p| index(p).is_some_and(|i| i >= k))
            .map(|p| p.identity.groups.0)
            .min()
            .unwrap_or_else(|| parts.last().map_or(0, |p| p.identity.scan_groups));
        let (shards, verb) = if k - first == 1 {
            (format!("shard {first}"), "is")
        } else {
            (format!("shards {first}–{}", k - 1), "are")
        };
        gaps.push(format!("{shards} (groups {start}..{end}) {verb}"));
    }
    if !gaps.is_empty() {
        let given: Vec<String> = parts.iter().map(|p| p.path.display().to_string()).collect();
        let held: Vec<String> = held.iter().map(ToString::to_string).collect();
        return Err(SideError::refused(
            format!(
                "the plan has {count} shards and {} missing: merge needs every shard's part, \
                 and the parts given hold shard{} {}",
                gaps.join(" and "),
                if held.len() == 1 { "" } else { "s" },
                held.join(", ")
            ),
            given.join(", "),
        ));
    }
    // The plan tiles the scan, so shards of one plan cover every group once, in order.
    let mut next = 0;
    for p in &parts {
        if p.identity.groups.0 != next {
            return Err(SideError::refused(
                format!(
                    "covers groups {}..{} but the parts before end at {next}",
                    p.identity.groups.0, p.identity.groups.1
                ),
                &p.path,
            ));
        }
        next = p.identity.groups.1;
    }
    if let Some(p) = parts.last()
        && next != p.identity.scan_groups
    {
        return Err(SideError::refused(
            format!(
                "the parts end at group {next} of {}",
                p.identity.scan_groups
            ),
            &p.path,
        ));
    }
    Ok(parts)
}

/// Merges parts whose headers agree ([`read_parts`]) into the side's reconstruction: each
/// part read and checked whole in shard order, its groups through [`finish_reconstruction`],
/// scored against the scan's `reference.wav` when the scan named in the parts is still there.
///
/// Stops between parts once `cancel` is raised.
///
/// # Errors
/// [`SideError`] from the checks (a truncated part, one whose header changed since it was
/// read), when no group produced sound, or [`EngineError::Cancelled`].
pub fn merge_parts(paths: &[PathBuf], cancel: &AtomicBool) -> Result<Merged, SideError> {
    merge_checked(read_parts(paths)?, None, cancel)
}

/// [`merge_parts`] of parts [`read_parts`] has checked, finished with `dsp` in place of the
/// parts' `[dsp]` table when given (only the finish reads it; the merged identity then
/// carries it and its fingerprint).
///
/// # Errors
/// As [`merge_parts`].
pub fn merge_checked(
    parts: Vec<CheckedPart>,
    dsp: Option<DspParams>,
    cancel: &AtomicBool,
) -> Result<Merged, SideError> {
    let Some(first) = parts.first() else {
        return Err(SideError::refused("no parts given", "."));
    };
    let mut identity = first.identity.clone();
    identity.groups = (0, identity.scan_groups);
    identity.keep_going = parts.iter().any(|p| p.identity.keep_going);
    if let Some(dsp) = dsp {
        identity.params.dsp = dsp;
        identity.params_fingerprint = super::params_fingerprint(&identity.params);
    }
    let meta = ScanMeta::from_toml_str(&identity.meta_toml, &first.path)?;
    let params: PipelineParams = identity.params.clone();
    let scan_dir = PathBuf::from(&identity.scan);
    let reference = crate::io::scan::reference_in(&scan_dir);
    let mut clip = ClipGroups::with_capacity(identity.scan_groups);
    let part_paths: Vec<PathBuf> = parts.iter().map(|p| p.path.clone()).collect();
    for checked in parts {
        if cancel.load(Ordering::Relaxed) {
            return Err(EngineError::Cancelled.into());
        }
        let part = read_part(&checked.path)?;
        if part.identity.difference(&checked.identity).is_some() {
            return Err(SideError::refused(
                "changed while the parts were merged",
                &checked.path,
            ));
        }
        for g in part.groups {
            clip.add(g);
        }
    }
    let reconstruction =
        finish_reconstruction(clip, &meta, reference.as_deref(), &params, &scan_dir)?;
    Ok(Merged {
        reconstruction,
        identity,
        parts: part_paths,
    })
}
