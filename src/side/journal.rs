//! The run journal: an append-only file of checksummed records of finished groups, fsynced every few seconds.
//!
//! It lies beside the output (`OUT.wav.journal`, or `journal` inside a shard's part folder)
//! and is removed once the output is in place. A killed run leaves it; the same command with
//! `--resume` checks its header against the run's identity (another scan, other params,
//! another plan or shard: refused, never mixed), drops a torn last record, and continues after
//! the last group it holds. Records reach the file as each group finishes, so a `kill -9`
//! loses none; `fsync` every [`SYNC_INTERVAL_SECS`] bounds what a power cut can take.

use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use super::record::{Record, decode, encode, read_frames, write_frame};
use super::{RunIdentity, SideError};

/// First bytes of a journal.
pub const JOURNAL_MAGIC: &[u8] = b"GROOVESCOPE JOURNAL 1\n";
/// Seconds between fsyncs of a journal.
pub const SYNC_INTERVAL_SECS: f64 = 2.0;

/// An open journal, appending.
#[derive(Debug)]
pub struct Journal {
    file: File,
    path: PathBuf,
    last_sync: Instant,
}

/// A record file read back: its identity, each record with the offset just past it, and the
/// length of the valid part.
pub type RecordFile = (RunIdentity, Vec<(Record, usize)>, usize);

/// Reads a file that starts with `magic` and an identity header: the identity, the records
/// after it (up to a torn or damaged tail), and the byte length of what was valid.
///
/// # Errors
/// [`SideError::Refused`] when the file is not of that kind or its header is damaged.
pub fn read_record_file(
    bytes: &[u8],
    magic: &[u8],
    what: &str,
    path: &Path,
) -> Result<RecordFile, SideError> {
    if !bytes.starts_with(magic) {
        return Err(SideError::refused(
            format!("not a groovescope {what}"),
            path,
        ));
    }
    let frames = read_frames(bytes, magic.len());
    let Some(((header, header_end), rest)) = frames.split_first() else {
        return Err(SideError::refused(
            format!("the {what}'s header is damaged or missing"),
            path,
        ));
    };
    let identity: RunIdentity = serde_json::from_slice(header)
        .map_err(|e| SideError::refused(format!("the {what}'s header does not read: {e}"), path))?;
    let mut records = Vec::with_capacity(rest.len());
    let mut valid = *header_end;
    for (payload, end) in rest {
        match decode(payload) {
            Ok(r) => {
                records.push((r, *end));
                valid = *end;
            }
            // A checksummed record that does not decode comes from another build: stop there.
            Err(_) => break,
        }
    }
    Ok((identity, records, valid))
}

impl Journal {
    /// Starts a new journal for `identity` at `path` (an existing file is replaced).
    ///
    /// # Errors
    /// [`SideError::Load`] when the file cannot be written.
    pub fn create(path: &Path, identity: &RunIdentity) -> Result<Self, SideError> {
        let header = serde_json::to_vec(identity)
            .map_err(|e| SideError::refused(format!("cannot encode the header: {e}"), path))?;
        let mut file =
            File::create(path).map_err(|e| SideError::io("cannot create the journal", &e, path))?;
        let mut head = JOURNAL_MAGIC.to_vec();
        write_frame(&mut head, &header).map_err(|e| SideError::io("journal", &e, path))?;
        file.write_all(&head)
            .and_then(|()| file.sync_data())
            .map_err(|e| SideError::io("cannot write the journal", &e, path))?;
        Ok(Self {
            file,
            path: path.to_path_buf(),
            last_sync: Instant::now(),
        })
    }

    /// Opens the journal at `path` to continue `identity`'s run: its records (a torn last one
    /// is cut off the file), positioned to append after them, and whether the journal's run
    /// had another `[dsp]` table (which only the finish reads: its groups are this run's).
    ///
    /// # Errors
    /// [`SideError::Refused`] naming the journal when it belongs to another run (another scan,
    /// other params beyond `[dsp]` or another version, another plan, shard or range, or
    /// `--keep-going` where `identity` lacks it) or is not a journal.
    pub fn resume(
        path: &Path,
        identity: &RunIdentity,
    ) -> Result<(Self, Vec<Record>, bool), SideError> {
        let bytes =
            std::fs::read(path).map_err(|e| SideError::io("cannot read the journal", &e, path))?;
        let (mut found, records, valid) = read_record_file(&bytes, JOURNAL_MAGIC, "journal", path)?;
        // A run without --keep-going stops at the first unreadable group, so its journal holds
        // only groups that read, each as a run with --keep-going makes it: such a run goes on
        // from them (past a damaged frame that stopped it), never the other way round.
        if identity.keep_going {
            found.keep_going = true;
        }
        let difference = identity.difference(&found);
        if let Some(diff) = &difference
            && !identity.same_groups_as(&found)
        {
            return Err(SideError::refused(
                format!(
                    "the journal of the interrupted run was {diff}; \
                     run it with what it was made with, or start over with --force"
                ),
                path,
            ));
        }
        let file = OpenOptions::new()
            .write(true)
            .open(path)
            .map_err(|e| SideError::io("cannot open the journal", &e, path))?;
        file.set_len(valid as u64)
            .and_then(|()| file.sync_data())
            .map_err(|e| SideError::io("cannot cut the journal's torn tail", &e, path))?;
        let mut journal = Self {
            file,
            path: path.to_path_buf(),
            last_sync: Instant::now(),
        };
        journal.seek_end()?;
        let records = records.into_iter().map(|(r, _)| r).collect();
        Ok((journal, records, difference.is_some()))
    }

    fn seek_end(&mut self) -> Result<(), SideError> {
        use std::io::Seek;
        self.file
            .seek(std::io::SeekFrom::End(0))
            .map(|_| ())
            .map_err(|e| SideError::io("cannot open the journal", &e, &self.path))
    }

    /// Appends a record; fsyncs when [`SYNC_INTERVAL_SECS`] have passed since the last one.
    ///
    /// # Errors
    /// [`SideError::Load`] when the write fails (a full disk).
    pub fn append(&mut self, record: &Record) -> Result<(), SideError> {
        let mut frame = Vec::new();
        write_frame(&mut frame, &encode(record))
            .map_err(|e| SideError::io("journal", &e, &self.path))?;
        self.file
            .write_all(&frame)
            .map_err(|e| SideError::io("cannot write the journal", &e, &self.path))?;
        if self.last_sync.elapsed().as_secs_f64() >= SYNC_INTERVAL_SECS {
            self.sync()?;
        }
        Ok(())
    }

    /// Fsyncs now.
    ///
    /// # Errors
    /// [`SideError::Load`] when the sync fails.
    pub fn sync(&mut self) -> Result<(), SideError> {
        self.last_sync = Instant::now();
        self.file
            .sync_data()
            .map_err(|e| SideError::io("cannot sync the journal", &e, &self.path))
    }

    /// The journal's path.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Removes the journal once the output it led to is in place.
    ///
    /// # Errors
    /// [`SideError::Load`] when it cannot be removed.
    pub fn remove(self) -> Result<(), SideError> {
        drop(self.file);
        std::fs::remove_file(&self.path)
            .map_err(|e| SideError::io("cannot remove the finished journal", &e, &self.path))
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;
    use crate::pipeline::PipelineParams;

    fn identity(keep_going: bool) -> RunIdentity {
        RunIdentity {
            groovescope: env!("CARGO_PKG_VERSION").into(),
            scan: "scan".into(),
            scan_fingerprint: "0123456789abcdef".into(),
            scan_groups: 10,
            params_fingerprint: "fedcba9876543210".into(),
            keep_going,
            groups: (0, 10),
            shard: None,
            params: PipelineParams::default(),
            meta_toml: String::new(),
        }
    }

    /// A journal made without --keep-going holds only groups that read: a run with it goes on
    /// from them. One made with --keep-going may hold gaps, which a run without it would not
    /// have made: refused, in words (the params' fingerprints are the same).
    #[test]
    fn keep_going_may_be_added_on_resume_never_dropped() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("o.wav.journal");
        Journal::create(&path, &identity(false)).unwrap();
        let (_, records, other_finish) = Journal::resume(&path, &identity(true)).unwrap();
        assert!(records.is_empty() && !other_finish);
        Journal::create(&path, &identity(true)).unwrap();
        let e = Journal::resume(&path, &identity(false))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(
                "made with --keep-going (unreadable groups became gaps), which this run lacks"
            ) && e.contains("o.wav.journal"),
            "{e}"
        );
    }
}
