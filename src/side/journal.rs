//! The run journal: an append-only file of checksummed records of finished groups, fsynced every few seconds.
//!
//! It lies beside the output (`OUT.wav.journal`, or `journal` inside a shard's part folder)
//! and is removed once the output is in place. A killed run leaves it; the same command with
//! `--resume` checks its header against the run's identity (another scan, other params,
//! another plan or shard: refused, never mixed), drops a torn last record (and says so), and
//! continues after the last group it holds. A journal damaged before its end (a record that
//! does not read with records after it that do) is refused, never cut short: that would drop
//! finished groups without a word. Records reach the file as each group finishes, so a `kill -9`
//! loses none; `fsync` every [`SYNC_INTERVAL_SECS`] bounds what a power cut can take.

use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use super::record::{Record, decode, encode, next_record, read_frames, write_frame};
use super::run::SlopeSeed;
use super::{RunIdentity, SideError};
use crate::engine::GroupOutcome;

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

/// A record file read back up to its first frame that does not read.
#[derive(Debug)]
pub struct RecordFile {
    /// Its identity header.
    pub identity: RunIdentity,
    /// Each record with the offset just past it.
    pub records: Vec<(Record, usize)>,
    /// The offset just past the header.
    pub header_end: usize,
    /// The byte length of the valid part (the offset of the first frame that does not read).
    pub valid: usize,
    /// Why the frame at `valid` did not decode when it is whole and passes its checksum (a
    /// record of another build); None when it is short or damaged, or there is none.
    pub undecodable: Option<String>,
}

/// The end of a journal that a run stopped while writing its last record left: dropped on
/// `--resume`, which says so.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TornTail {
    /// Where it starts.
    pub offset: usize,
    /// Its length.
    pub bytes: usize,
}

/// A journal opened to continue its run (see [`Journal::resume`]).
#[derive(Debug)]
pub struct Resumed {
    /// The journal, positioned to append.
    pub journal: Journal,
    /// The shard's slope history, when the journal holds it.
    pub seed: Option<SlopeSeed>,
    /// Its finished groups, in order from the range's first.
    pub groups: Vec<GroupOutcome>,
    /// The journal's run had another `[dsp]` table (which only the finish reads).
    pub other_finish: bool,
    /// A torn last record, cut off the file.
    pub torn_tail: Option<TornTail>,
}

/// Reads a file that starts with `magic` and an identity header: the identity, the records
/// after it (up to the first frame that does not read), and where that is.
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
    let mut undecodable = None;
    for (payload, end) in rest {
        match decode(payload) {
            Ok(r) => {
                records.push((r, *end));
                valid = *end;
            }
            // A checksummed record that does not decode comes from another build: stop there.
            Err(e) => {
                undecodable = Some(e);
                break;
            }
        }
    }
    Ok(RecordFile {
        identity,
        records,
        header_end: *header_end,
        valid,
        undecodable,
    })
}

/// What to do about a damaged journal, in words: the groups before `at` are sound (cut the
/// file there and resume to keep them), or delete it to run again from the start.
fn damaged(problem: &str, at: usize, groups_before: usize, shard: bool, path: &Path) -> SideError {
    let whole = if shard { "the shard" } else { "the run" };
    SideError::refused(
        format!(
            "damaged journal: {problem}; nothing was dropped. To keep the {groups_before} \
             finished groups before it, cut it there (truncate -s {at} {}) and --resume, or \
             delete it to run {whole} from its start",
            crate::stdout::shell_quoted(path)
        ),
        path,
    )
}

/// The group whose record ends at or before `at`, in words ("after group G's").
fn after_group(records: &[(Record, usize)], at: usize) -> String {
    records
        .iter()
        .rev()
        .find_map(|(r, end)| match r {
            Record::Group(g) if *end <= at => Some(format!("after group {}'s", g.group)),
            _ => None,
        })
        .unwrap_or_else(|| "before any group's".to_string())
}

/// Checks what follows a journal's last record that reads. Nothing: None. A frame that is cut
/// short or damaged with no record that reads after it: the torn tail a run stopped while
/// writing leaves, returned to be dropped. Anything else is damage inside the file (a record
/// that does not read followed by ones that do, or one this build cannot read), refused: a
/// resume past it would drop finished groups without a word.
///
/// # Errors
/// [`SideError::Refused`] naming the journal, the record's byte offset and what to do.
fn check_tail(bytes: &[u8], file: &RecordFile, path: &Path) -> Result<Option<TornTail>, SideError> {
    let at = file.valid;
    if at >= bytes.len() {
        return Ok(None);
    }
    let shard = file.identity.shard.is_some();
    let groups = file
        .records
        .iter()
        .filter(|(r, _)| matches!(r, Record::Group(_)))
        .count();
    let number = file.records.len() + 1;
    let which = format!(
        "record {number} (at byte {at}, {})",
        after_group(&file.records, at)
    );
    if let Some(e) = &file.undecodable {
        return Err(damaged(
            &format!(
                "{which} passes its checksum but does not read ({e}; the journal was written \
                 by groovescope {}, this is {})",
                file.identity.groovescope,
                env!("CARGO_PKG_VERSION")
            ),
            at,
            groups,
            shard,
            path,
        ));
    }
    if let Some(next) = next_record(bytes, at + 1) {
        return Err(damaged(
            &format!(
                "{which} is damaged, yet a record that reads follows at byte {next}, so this is \
                 not the torn end of a stopped run"
            ),
            at,
            groups,
            shard,
            path,
        ));
    }
    Ok(Some(TornTail {
        offset: at,
        bytes: bytes.len() - at,
    }))
}

/// The journal's records as its run wrote them: for a shard, its slope history first, then
/// the range's groups in order from its first, none past its end. Any other order is damage
/// (records do not go missing or change places in a file only ever appended to), refused.
///
/// # Errors
/// [`SideError::Refused`] naming the journal and the record's byte offset.
fn in_order(
    file: RecordFile,
    path: &Path,
) -> Result<(Option<SlopeSeed>, Vec<GroupOutcome>), SideError> {
    let (lo, hi) = file.identity.groups;
    let shard = file.identity.shard.is_some();
    let mut seed = None;
    let mut groups: Vec<GroupOutcome> = Vec::new();
    let mut start = file.header_end;
    for (number, (record, end)) in file.records.into_iter().enumerate() {
        let expected = lo + groups.len();
        let found = match record {
            Record::Seed(h) if shard && seed.is_none() && groups.is_empty() => {
                seed = Some(h);
                None
            }
            Record::Group(g) if g.group == expected && expected < hi => {
                groups.push(g);
                None
            }
            Record::Group(g) => Some(format!("group {}'s", g.group)),
            Record::Seed(_) => Some("a slope history".to_string()),
            Record::End { .. } => Some("a part's end record".to_string()),
        };
        if let Some(found) = found {
            let wanted = if expected < hi {
                format!("group {expected}'s")
            } else {
                format!("none (the range {lo}..{hi} is complete)")
            };
            return Err(damaged(
                &format!(
                    "record {} (at byte {start}) is {found}, where {wanted} should be",
                    number + 1
                ),
                start,
                groups.len(),
                shard,
                path,
            ));
        }
        start = end;
    }
    Ok((seed, groups))
}

impl Journal {
    /// Starts a new journal for `identity` at `path` (an existing file is replaced). The header
    /// is written atomically ([`crate::io::write_atomic`]), so a run stopped as it starts
    /// (`kill -9`, a power cut) leaves a whole journal or none, never one without a header that
    /// `--resume` must refuse; records are appended to it after.
    ///
    /// # Errors
    /// [`SideError::Load`] when the file cannot be written.
    pub fn create(path: &Path, identity: &RunIdentity) -> Result<Self, SideError> {
        let header = serde_json::to_vec(identity)
            .map_err(|e| SideError::refused(format!("cannot encode the header: {e}"), path))?;
        let mut head = JOURNAL_MAGIC.to_vec();
        write_frame(&mut head, &header).map_err(|e| SideError::io("journal", &e, path))?;
        crate::io::write_atomic(path, &head, true)?;
        let file = OpenOptions::new()
            .append(true)
            .open(path)
            .map_err(|e| SideError::io("cannot open the journal", &e, path))?;
        Ok(Self {
            file,
            path: path.to_path_buf(),
            last_sync: Instant::now(),
        })
    }

    /// Opens the journal at `path` to continue `identity`'s run: its slope history and groups,
    /// positioned to append after them, whether the journal's run had another `[dsp]` table
    /// (which only the finish reads: its groups are this run's), and the torn last record cut
    /// off the file, if there was one.
    ///
    /// # Errors
    /// [`SideError::Refused`] naming the journal when it belongs to another run (another scan,
    /// other params beyond `[dsp]` or another version, another plan, shard or range, or
    /// `--keep-going` where `identity` lacks it), is not a journal, or is damaged before its
    /// end (a record that does not read with records after it that do, one this build cannot
    /// read, records out of order): it is left as it was.
    pub fn resume(path: &Path, identity: &RunIdentity) -> Result<Resumed, SideError> {
        let bytes =
            std::fs::read(path).map_err(|e| SideError::io("cannot read the journal", &e, path))?;
        let mut file =
            read_record_file(&bytes, JOURNAL_MAGIC, "journal", path).map_err(|e| match e {
                // No header: no finished group can be read from it (a journal of an older
                // build stopped as it started, or another file in its place).
                SideError::Refused { problem, path } => SideError::Refused {
                    problem: format!(
                        "{problem}, so no finished group can be read from it; delete it to run from the start"
                    ),
                    path,
                },
                other => other,
            })?;
        // A run without --keep-going stops at the first unreadable group, so its journal holds
        // only groups that read, each as a run with --keep-going makes it: such a run goes on
        // from them (past a damaged frame that stopped it), never the other way round.
        if identity.keep_going {
            file.identity.keep_going = true;
        }
        let difference = identity.difference(&file.identity);
        if let Some(diff) = &difference
            && !identity.same_groups_as(&file.identity)
        {
            return Err(SideError::refused(
                format!(
                    "the journal of the interrupted run was {diff}; \
                     run it with what it was made with, or start over with --force"
                ),
                path,
            ));
        }
        let torn_tail = check_tail(&bytes, &file, path)?;
        let valid = file.valid;
        let (seed, groups) = in_order(file, path)?;
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
        Ok(Resumed {
            journal,
            seed,
            groups,
            other_finish: difference.is_some(),
            torn_tail,
        })
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
        let r = Journal::resume(&path, &identity(true)).unwrap();
        assert!(r.groups.is_empty() && r.seed.is_none() && !r.other_finish);
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

    /// A new journal appears whole, its header renamed into place with nothing left beside it;
    /// one without a header (an older build's, stopped as it started) is refused saying that no
    /// group can be read from it and to delete it.
    #[test]
    fn a_journal_appears_with_its_header_and_one_without_is_refused_with_advice() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("o.wav.journal");
        Journal::create(&path, &identity(false)).unwrap();
        let names: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("o.wav.journal")]);
        for torn in [&[][..], &JOURNAL_MAGIC[..3]] {
            std::fs::write(&path, torn).unwrap();
            let e = Journal::resume(&path, &identity(false))
                .unwrap_err()
                .to_string();
            assert!(
                e.contains(
                    "no finished group can be read from it; delete it to run from the start"
                ) && e.ends_with("o.wav.journal"),
                "{e}"
            );
            assert_eq!(std::fs::read(&path).unwrap(), torn);
        }
    }
}
