//! Shard parts: one shard's group records, sealed with an end record whose checksum covers the whole file.
//!
//! A part folder (`reconstruct --plan P --shard K --out part-K/`) holds `part.gsp` (the
//! records, see [`super::record`]) and `report.json` (the shard's timings and warnings, for
//! people). `part.gsp` is written atomically; a part without its end record, with records
//! missing, or whose checksum fails is truncated and refused by merge.

use std::io::Read;
use std::path::{Path, PathBuf};

use super::journal::read_record_file;
use super::record::{Record, encode, write_frame};
use super::{RunIdentity, SideError};
use crate::engine::GroupOutcome;
use crate::io::write_atomic;

/// First bytes of a part file.
pub const PART_MAGIC: &[u8] = b"GROOVESCOPE PART 1\n";
/// The part file's name inside a part folder.
pub const PART_FILE: &str = "part.gsp";

/// A part read back and checked.
#[derive(Clone, Debug)]
pub struct Part {
    /// The part file.
    pub path: PathBuf,
    /// What it belongs to.
    pub identity: RunIdentity,
    /// Its groups, in order, covering `identity.groups` exactly.
    pub groups: Vec<GroupOutcome>,
}

/// The part file of `path`: `path` itself, or `path/part.gsp` for a folder.
#[must_use]
pub fn part_file(path: &Path) -> PathBuf {
    if path.is_dir() {
        path.join(PART_FILE)
    } else {
        path.to_path_buf()
    }
}

/// The bytes of a part: header, the groups' records, and the end record.
///
/// # Errors
/// [`SideError::Refused`] when the header cannot be encoded.
pub fn part_bytes(identity: &RunIdentity, groups: &[GroupOutcome]) -> Result<Vec<u8>, SideError> {
    let header = serde_json::to_vec(identity).map_err(|e| {
        SideError::refused(
            format!("cannot encode the part header: {e}"),
            &identity.scan,
        )
    })?;
    let mut bytes = PART_MAGIC.to_vec();
    let frame_err = |e: std::io::Error| SideError::io("part", &e, &identity.scan);
    write_frame(&mut bytes, &header).map_err(frame_err)?;
    for g in groups {
        write_frame(&mut bytes, &encode(&Record::Group(g.clone()))).map_err(frame_err)?;
    }
    let end = Record::End {
        groups: groups.len() as u64,
        file_crc: crc32fast::hash(&bytes),
    };
    write_frame(&mut bytes, &encode(&end)).map_err(frame_err)?;
    Ok(bytes)
}

/// Writes a part atomically to `dir/part.gsp`.
///
/// # Errors
/// [`SideError`] when it exists (without `force`) or cannot be written.
pub fn write_part(
    dir: &Path,
    identity: &RunIdentity,
    groups: &[GroupOutcome],
    force: bool,
) -> Result<PathBuf, SideError> {
    let path = dir.join(PART_FILE);
    write_atomic(&path, &part_bytes(identity, groups)?, force)?;
    Ok(path)
}

/// The part file of `path` (see [`part_file`]), refused when there is none.
fn existing_part_file(path: &Path) -> Result<PathBuf, SideError> {
    let file = part_file(path);
    if file.is_file() {
        Ok(file)
    } else {
        Err(SideError::refused(
            format!("not a part: no {PART_FILE} there"),
            path,
        ))
    }
}

/// Reads only a part's header (what it belongs to): its magic and first frame, not its
/// groups, which [`read_part`] reads and checks.
///
/// # Errors
/// [`SideError::Refused`] naming the part when it is missing, not a part, or its header is
/// damaged.
pub fn read_part_header(path: &Path) -> Result<RunIdentity, SideError> {
    let file = existing_part_file(path)?;
    let io_err = |e: std::io::Error| SideError::io("cannot read the part", &e, &file);
    let mut f = std::fs::File::open(&file).map_err(io_err)?;
    // The magic and the header frame's length, then its payload and checksum.
    let mut head = Vec::new();
    (&mut f)
        .take(PART_MAGIC.len() as u64 + 4)
        .read_to_end(&mut head)
        .map_err(io_err)?;
    if let Some(len) = head
        .get(PART_MAGIC.len()..)
        .and_then(|b| <[u8; 4]>::try_from(b).ok())
    {
        f.take(u64::from(u32::from_le_bytes(len)) + 4)
            .read_to_end(&mut head)
            .map_err(io_err)?;
    }
    Ok(read_record_file(&head, PART_MAGIC, "part", &file)?.identity)
}

/// Reads and checks a part (a folder or its `part.gsp`).
///
/// # Errors
/// [`SideError::Refused`] naming the part when it is missing, not a part, or truncated
/// (no end record, a group record missing, a checksum that fails).
pub fn read_part(path: &Path) -> Result<Part, SideError> {
    let file = existing_part_file(path)?;
    let bytes =
        std::fs::read(&file).map_err(|e| SideError::io("cannot read the part", &e, &file))?;
    let super::journal::RecordFile {
        identity,
        records,
        valid,
        ..
    } = read_record_file(&bytes, PART_MAGIC, "part", &file)?;
    let (lo, hi) = identity.groups;
    let mut groups = Vec::with_capacity(hi.saturating_sub(lo));
    let mut end = None;
    let mut start_of_end = 0;
    let mut prev_end = bytes.len().min(valid);
    let mut record_end = 0;
    for (record, end_at) in records {
        match record {
            Record::Group(g) if end.is_none() => groups.push(g),
            Record::End { groups, file_crc } if end.is_none() => {
                end = Some((groups, file_crc));
                start_of_end = record_end;
                prev_end = end_at;
            }
            _ => {
                return Err(SideError::refused(
                    "damaged part: records after its end",
                    &file,
                ));
            }
        }
        record_end = end_at;
    }
    let truncated = |what: String| {
        SideError::refused(
            format!("truncated part ({what}; it should hold groups {lo}..{hi})"),
            &file,
        )
    };
    let last = groups
        .last()
        .map_or_else(|| "no group".to_string(), |g| format!("group {}", g.group));
    let Some((count, file_crc)) = end else {
        // Bytes that do not read as records: a damaged byte, or a copy cut inside a record.
        let unread = bytes.len().saturating_sub(valid);
        if unread > 0 {
            return Err(SideError::refused(
                format!(
                    "damaged or cut part: its records read up to {last}, and the {unread} bytes after \
                     that do not (it should hold groups {lo}..{hi}; run its shard again)"
                ),
                &file,
            ));
        }
        return Err(truncated(format!("no end record after {last}")));
    };
    // With no group records, the end follows the header directly.
    if start_of_end == 0 {
        start_of_end = header_end(&bytes);
    }
    if prev_end != bytes.len() {
        return Err(truncated("bytes after the end record".into()));
    }
    if bytes.get(..start_of_end).map(crc32fast::hash) != Some(file_crc) {
        return Err(truncated("its checksum does not match".into()));
    }
    let expected: Vec<usize> = (lo..hi).collect();
    let found: Vec<usize> = groups.iter().map(|g| g.group).collect();
    if count != groups.len() as u64 || found != expected {
        return Err(truncated(format!(
            "{} group records of {}, ending at {last}",
            groups.len(),
            hi.saturating_sub(lo)
        )));
    }
    Ok(Part {
        path: path.to_path_buf(),
        identity,
        groups,
    })
}

/// Offset just past the header frame.
fn header_end(bytes: &[u8]) -> usize {
    super::record::read_frames(bytes, PART_MAGIC.len())
        .first()
        .map_or(0, |f| f.1)
}
