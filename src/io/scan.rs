//! The scan directory contract: `scan.toml` metadata, group folders and their frames (see docs/FORMAT.md).

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use super::LoadError;
use super::frames::frame_dimensions;
use super::limits::{MAX_FRAMES_PER_GROUP, MAX_GROUPS, read_toml_text};
use super::numbering::{in_numbered_order, strays};

/// Fewest frames a group may hold: the derivative stage needs 7.
pub const MIN_FRAMES_PER_GROUP: usize = 7;

pub use crate::meta::{
    CameraMeta, Cut, DualFocusMeta, FORMAT_VERSION, Geometry, GlassSide, MotionMeta, NumberedNames,
    RecordMeta, ScanMeta,
};

/// Reading and writing `scan.toml`.
impl ScanMeta {
    /// Parses and validates `scan.toml` text; `path` is used in errors only.
    ///
    /// # Errors
    /// A [`LoadError::Metadata`] naming the file and the missing or invalid key.
    pub fn from_toml_str(text: &str, path: &Path) -> Result<Self, LoadError> {
        let meta: ScanMeta = toml::from_str(text).map_err(|e| LoadError::Metadata {
            problem: crate::toml_error::located(text, &e),
            path: path.to_path_buf(),
        })?;
        meta.validate().map_err(|problem| LoadError::Metadata {
            problem,
            path: path.to_path_buf(),
        })?;
        Ok(meta)
    }

    /// Reads `scan.toml` from a file.
    ///
    /// # Errors
    /// [`LoadError`] when the file cannot be read or is invalid.
    pub fn load(path: &Path) -> Result<Self, LoadError> {
        let text = read_toml_text(path, "scan metadata")?;
        Self::from_toml_str(&text, path)
    }

    /// The TOML text of this metadata.
    ///
    /// # Errors
    /// When serialisation fails (it does not for validated metadata).
    pub fn to_toml_string(&self) -> Result<String, toml::ser::Error> {
        toml::to_string_pretty(self)
    }
}

/// One group: its index, folder and sorted frame files, or its chunk in a Zarr store.
#[derive(Clone, Debug, PartialEq)]
pub struct GroupEntry {
    /// Position in the scan, from 0.
    pub index: usize,
    /// The group folder (in a Zarr store: the store joined with the group's name, which
    /// names the group in messages).
    pub dir: PathBuf,
    /// The names of its frame files inside `dir`, in order: by name, or by number (a skipped
    /// one kept as the name it would have; see docs/FORMAT.md). Empty in a Zarr store. Groups
    /// whose frames are named alike share one list, so a side's 367,000 groups hold one list
    /// rather than a path a frame (0.7 kB a group with 12 frames).
    pub frame_names: Arc<[OsString]>,
    /// Where the frames are in a Zarr store (None for a scan folder).
    pub zarr: Option<super::zarr::ZarrGroup>,
    /// For a place the scan's numbering skips (it keeps its place; see docs/FORMAT.md): what
    /// is missing there, in words ("group folder", or a store's "group (the store was packed
    /// without it)"). Set when the scan is opened.
    pub missing: Option<&'static str>,
}

impl GroupEntry {
    /// Frames in the group.
    #[must_use]
    pub fn frame_count(&self) -> usize {
        self.zarr
            .as_ref()
            .map_or(self.frame_names.len(), |z| z.layout.frames)
    }

    /// The file of frame `k` of a scan folder's group (None past its frames, and in a Zarr
    /// store).
    #[must_use]
    pub fn frame_path(&self, k: usize) -> Option<PathBuf> {
        self.frame_names.get(k).map(|name| self.dir.join(name))
    }

    /// The files of a scan folder's group, in order (none in a Zarr store).
    pub fn frame_paths(&self) -> impl ExactSizeIterator<Item = PathBuf> + '_ {
        self.frame_names.iter().map(|name| self.dir.join(name))
    }

    /// True for a place the scan's numbering skips (see [`GroupEntry::missing`]).
    #[must_use]
    pub fn is_missing(&self) -> bool {
        self.missing.is_some()
    }

    /// [`LoadError::Missing`] naming the place, for a place the scan's numbering skips.
    #[must_use]
    pub fn missing_error(&self) -> Option<LoadError> {
        self.missing.map(|what| LoadError::Missing {
            what,
            path: self.dir.clone(),
        })
    }

    /// The group's name: its folder's name.
    #[must_use]
    pub fn name(&self) -> String {
        self.dir.file_name().map_or_else(
            || self.index.to_string(),
            |n| n.to_string_lossy().into_owned(),
        )
    }
}

/// An opened scan: metadata plus the list of groups. Frames are read on demand.
#[derive(Clone, Debug)]
pub struct Scan {
    /// The scan folder.
    pub dir: PathBuf,
    /// Parsed `scan.toml`.
    pub meta: ScanMeta,
    /// Groups in groove order: by folder name, or by number with a skipped one in its place
    /// (see docs/FORMAT.md).
    pub groups: Vec<GroupEntry>,
    /// `reference.wav`, when present.
    pub reference: Option<PathBuf>,
    /// Width and height of every frame (px): the first frame's, which all the others must
    /// match.
    pub frame_size: (usize, usize),
}

fn is_frame_file(p: &Path) -> bool {
    p.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| matches!(e.to_ascii_lowercase().as_str(), "png" | "tif" | "tiff"))
}

/// The scan's frame size: `first`'s (the first group with enough frames), unless the middle
/// and last such groups agree on another. One odd group 0 (cropped, or from another camera)
/// would otherwise set the size every other group is then refused for.
fn majority_frame_size(groups: &[GroupEntry], first: (usize, usize)) -> (usize, usize) {
    let usable: Vec<&GroupEntry> = groups
        .iter()
        .filter(|g| g.frame_names.len() >= MIN_FRAMES_PER_GROUP)
        .collect();
    let size_of = |g: Option<&&GroupEntry>| {
        g.and_then(|g| g.frame_path(0))
            .and_then(|f| frame_dimensions(&f).ok())
    };
    if usable.len() < 3 {
        return first;
    }
    match (
        size_of(usable.get(usable.len() / 2)),
        size_of(usable.last()),
    ) {
        (Some(mid), Some(last)) if mid == last && mid != first => mid,
        _ => first,
    }
}

/// The scan's `reference.wav` in `dir` when anything of that name is there: a folder or a
/// dangling link too, so that scoring names what is wrong with it instead of skipping it.
pub(crate) fn reference_in(dir: &Path) -> Option<PathBuf> {
    Some(dir.join("reference.wav")).filter(|p| p.symlink_metadata().is_ok())
}

/// A name starting with a dot: another program's file (macOS's `._f000.png` resource forks,
/// `.Trashes`, thumbnail caches), never a group or a frame.
fn hidden(p: &Path) -> bool {
    p.file_name()
        .is_some_and(|n| n.to_string_lossy().starts_with('.'))
}

/// Checks `meta` against a scan of the places `groups` and frames of `frame_size`. The
/// radius list counts places on the groove, a skipped number's included, and the message says
/// so when the scan skips one (a list that counted folders is one short).
///
/// # Errors
/// [`LoadError::Metadata`] naming `meta_path`.
pub(super) fn check_meta_against(
    meta: &ScanMeta,
    groups: &[GroupEntry],
    frame_size: (usize, usize),
    meta_path: &Path,
) -> Result<(), LoadError> {
    let skipped = groups.iter().filter(|g| g.is_missing()).count();
    meta.check_against_scan(groups.len(), frame_size)
        .map_err(|problem| LoadError::Metadata {
            problem: if skipped > 0 && meta.record.group_radius_mm.is_some() {
                format!(
                    "{problem}, {skipped} of them a number the group folders skip (it keeps its place)"
                )
            } else {
                problem
            },
            path: meta_path.to_path_buf(),
        })
}

/// Refuses a group folder holding one frame twice, in two formats (`f000.png` and `f000.tif`,
/// a conversion that left its source): taken in name order the two sets would interleave.
fn refuse_twin_frames(dir: &Path, files: &[PathBuf]) -> Result<(), LoadError> {
    let mut stems: Vec<(&std::ffi::OsStr, &Path)> = files
        .iter()
        .filter_map(|p| Some((p.file_stem()?, p.as_path())))
        .collect();
    stems.sort_unstable();
    match stems.windows(2).find(|w| w[0].0 == w[1].0) {
        Some(w) => Err(LoadError::NotAScan {
            problem: format!(
                "the group holds frames {} and {}, one frame in two formats: keep one set",
                w[0].1.file_name().unwrap_or_default().to_string_lossy(),
                w[1].1.file_name().unwrap_or_default().to_string_lossy()
            ),
            path: dir.to_path_buf(),
        }),
        None => Ok(()),
    }
}

/// What a folder entry is, as `Path::is_dir` and `Path::is_file` say (a link followed).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum EntryKind {
    Folder,
    File,
    Other,
}

impl EntryKind {
    /// The kind of `entry`: from the listing itself where it says (no call to the file
    /// system: a side's scan folder holds 367,000 group folders of about 12 frames), else
    /// from the file's metadata, a link followed.
    fn of(entry: &std::fs::DirEntry) -> Self {
        let kind = |t: std::fs::FileType| {
            if t.is_dir() {
                Self::Folder
            } else if t.is_file() {
                Self::File
            } else {
                Self::Other
            }
        };
        match entry.file_type() {
            Ok(t) if !t.is_symlink() => kind(t),
            _ => std::fs::metadata(entry.path()).map_or(Self::Other, |m| kind(m.file_type())),
        }
    }
}

/// The entries of `dir` of `kind` whose paths pass `keep`, sorted by name; more than `limit`
/// of them is refused.
fn sorted_entries(
    dir: &Path,
    kind: EntryKind,
    keep: impl Fn(&Path) -> bool,
    limit: usize,
    what: &str,
) -> Result<Vec<PathBuf>, LoadError> {
    let list_err = |e: std::io::Error| LoadError::Io {
        problem: format!("cannot list folder: {e}"),
        path: dir.to_path_buf(),
    };
    let rd = std::fs::read_dir(dir).map_err(list_err)?;
    let mut out = Vec::new();
    for entry in rd {
        let entry = entry.map_err(list_err)?;
        let path = entry.path();
        if !keep(&path) || EntryKind::of(&entry) != kind {
            continue;
        }
        if out.len() == limit {
            return Err(LoadError::NotAScan {
                problem: format!("the folder holds more than {limit} {what}, past the limit"),
                path: dir.to_path_buf(),
            });
        }
        out.push(path);
    }
    out.sort();
    Ok(out)
}

/// Frame-name lists shared between groups: the frames of each group folder as names inside it,
/// one list kept for each run of groups that name their frames alike (every group of a
/// regular scan).
#[derive(Default)]
struct FrameNames {
    last: Option<Arc<[OsString]>>,
}

impl FrameNames {
    /// The names of `files` (paths inside one folder), shared with the last group's list
    /// when they are the same.
    fn shared(&mut self, files: &[PathBuf]) -> Arc<[OsString]> {
        let same = |last: &[OsString]| {
            last.len() == files.len()
                && last
                    .iter()
                    .zip(files)
                    .all(|(name, file)| file.file_name() == Some(name.as_os_str()))
        };
        match &self.last {
            Some(last) if same(last) => Arc::clone(last),
            _ => {
                let names: Arc<[OsString]> = files
                    .iter()
                    .map(|file| file.file_name().unwrap_or_default().to_owned())
                    .collect();
                self.last = Some(Arc::clone(&names));
                names
            }
        }
    }
}

impl Scan {
    /// Whether `dir` looks like a scan [`Scan::open`] reads: a folder holding `scan.toml`, or a
    /// Zarr store (`zarr.json`).
    #[must_use]
    pub fn is_scan_dir(dir: &Path) -> bool {
        dir.join("scan.toml").is_file() || dir.join("zarr.json").is_file()
    }

    /// Opens a scan: a folder (reads `scan.toml` and lists the groups and their frames) or a
    /// Zarr store made by `groovescope pack` (a folder holding `zarr.json`).
    ///
    /// # Errors
    /// [`LoadError`] when the folder is not a scan, the metadata is invalid, there are no
    /// groups, or no group holds [`MIN_FRAMES_PER_GROUP`] frames. A group with fewer (a
    /// transfer cut short) keeps its place, so the groups after it stay where they lie on the
    /// groove; loading it fails (see [`super::load_group_frames`]), a gap under `--keep-going`.
    pub fn open(dir: &Path) -> Result<Self, LoadError> {
        if dir.join("zarr.json").is_file() {
            return super::zarr::open_scan(dir);
        }
        if !dir.is_dir() {
            let problem = if dir.exists() {
                "not a scan: a scan is a folder (of group folders, or a Zarr store), not a file"
            } else {
                "no such folder"
            };
            return Err(LoadError::NotAScan {
                problem: problem.into(),
                path: dir.to_path_buf(),
            });
        }
        let meta_path = dir.join("scan.toml");
        if !meta_path.is_file() {
            return Err(LoadError::NotAScan {
                problem: "not a scan folder: scan.toml is missing".into(),
                path: dir.to_path_buf(),
            });
        }
        let meta = ScanMeta::load(&meta_path)?;
        let folders = sorted_entries(
            dir,
            EntryKind::Folder,
            |p| !hidden(p),
            MAX_GROUPS,
            "group folders",
        )?;
        let mut frames_of = std::collections::HashMap::new();
        let mut names = FrameNames::default();
        for path in &folders {
            let files = sorted_entries(
                path,
                EntryKind::File,
                |p| !hidden(p) && is_frame_file(p),
                MAX_FRAMES_PER_GROUP,
                "frames",
            )?;
            refuse_twin_frames(path, &files)?;
            let files = in_numbered_order(
                path,
                files,
                MAX_FRAMES_PER_GROUP,
                "frames",
                meta.motion.numbered_names,
            )?;
            frames_of.insert(path.clone(), names.shared(&files));
        }
        let holds_frames = |i: usize| frames_of.get(&folders[i]).is_some_and(|f| !f.is_empty());
        let stray = strays(&folders, holds_frames);
        let folders: Vec<PathBuf> = folders
            .into_iter()
            .enumerate()
            .filter(|(i, _)| stray.binary_search(i).is_err())
            .map(|(_, path)| path)
            .collect();
        let mut groups = Vec::new();
        let names_say = meta.motion.numbered_names;
        for path in in_numbered_order(dir, folders, MAX_GROUPS, "group folders", names_say)? {
            // A number the scan skips has no folder and no frames: loading it fails naming it.
            let frames = frames_of.remove(&path);
            groups.push(GroupEntry {
                index: groups.len(),
                dir: path,
                missing: frames.is_none().then_some("group folder"),
                frame_names: frames.unwrap_or_else(|| Arc::new([])),
                zarr: None,
            });
        }
        let Some(first) = groups
            .iter()
            .find(|g| g.frame_names.len() >= MIN_FRAMES_PER_GROUP)
            .and_then(|g| g.frame_path(0))
        else {
            return Err(match groups.iter().find(|g| !g.frame_names.is_empty()) {
                Some(short) => LoadError::TooFewFrames {
                    found: short.frame_names.len(),
                    needed: MIN_FRAMES_PER_GROUP,
                    path: short.dir.clone(),
                },
                None => LoadError::NotAScan {
                    problem: "the scan holds no group folders with frames".into(),
                    path: dir.to_path_buf(),
                },
            });
        };
        let frame_size = majority_frame_size(&groups, frame_dimensions(&first)?);
        check_meta_against(&meta, &groups, frame_size, &meta_path)?;
        let reference = reference_in(dir);
        Ok(Self {
            dir: dir.to_path_buf(),
            meta,
            groups,
            reference,
            frame_size,
        })
    }

    /// The groups in `range` whose folders the scan's numbering skips (see docs/FORMAT.md):
    /// they keep their places, and loading one fails with [`LoadError::Missing`].
    #[must_use]
    pub fn missing_groups(&self, range: std::ops::Range<usize>) -> Vec<&GroupEntry> {
        self.groups
            .get(range.start.min(self.groups.len())..range.end.min(self.groups.len()))
            .unwrap_or_default()
            .iter()
            .filter(|g| g.is_missing())
            .collect()
    }

    /// What [`Self::missing_groups`] finds in `range`, in words (None when nothing is
    /// missing): "the scan's numbering skips 2 group folders among groups 0..13 (g00003,
    /// g00007; the first would be /scan/g00003)".
    #[must_use]
    pub fn missing_note(&self, range: std::ops::Range<usize>) -> Option<String> {
        /// Names given before "and N more".
        const NAMED: usize = 3;
        let missing = self.missing_groups(range.clone());
        let first = missing.first()?;
        let mut names: Vec<String> = missing.iter().take(NAMED).map(|g| g.name()).collect();
        if missing.len() > NAMED {
            names.push(format!("and {} more", missing.len() - NAMED));
        }
        let (count, s) = (missing.len(), if missing.len() == 1 { "" } else { "s" });
        let (a, b, names) = (range.start, range.end, names.join(", "));
        Some(if self.is_store() {
            format!(
                "the store's group names skip {count} group{s} among groups {a}..{b} ({names}; \
                 it was packed from folders that lacked them): {}",
                self.dir.display()
            )
        } else {
            format!(
                "the scan's numbering skips {count} group folder{s} among groups {a}..{b} \
                 ({names}; the first would be {})",
                first.dir.display()
            )
        })
    }

    /// True for a Zarr store (`pack`), false for a scan folder.
    #[must_use]
    pub fn is_store(&self) -> bool {
        self.groups.iter().any(|g| g.zarr.is_some())
    }

    /// Start of group `group` along the groove, in µm from the first group.
    #[must_use]
    pub fn group_start_um(&self, group: usize) -> f64 {
        group as f64 * self.meta.motion.group_step_um
    }
}

/// Scan metadata shared by the unit tests of several modules.
#[cfg(test)]
pub(crate) mod test_support {
    use std::path::Path;

    use super::ScanMeta;

    /// scan.toml of a 78 rpm lateral record at 115 mm under the paper's camera (0.39 µm px at
    /// 4 mm), frames 0.78 µm apart and groups `group_step_um` apart.
    pub(crate) fn scan_toml(group_step_um: f64) -> String {
        format!(
            "format = 1\n[record]\nrpm = 78.0\nradius_mm = 115.0\ncut = \"lateral\"\n\
             [camera]\npixel_pitch_um = 0.39\nworking_distance_mm = 4.0\n\
             [motion]\nframe_step_um = 0.78\ngroup_step_um = {group_step_um:?}\n"
        )
    }

    /// [`scan_toml`] read.
    #[allow(clippy::unwrap_used)] // test support: the text is valid
    pub(crate) fn scan_meta(group_step_um: f64) -> ScanMeta {
        ScanMeta::from_toml_str(&scan_toml(group_step_um), Path::new("scan.toml")).unwrap()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use test_support::scan_toml;

    /// The minimal scan.toml, its groups 460.2 µm apart (one 1280 px frame's land motion).
    fn minimal() -> String {
        scan_toml(460.2)
    }

    #[test]
    fn minimal_file_loads_and_derives_geometry() {
        let m = ScanMeta::from_toml_str(&minimal(), Path::new("scan.toml")).unwrap();
        let g = m.geometry();
        assert!((g.focal_px - 10_256.41).abs() < 0.01);
        assert!((g.land_flow_px() + 2.0).abs() < 1e-9);
        assert!((m.groove_speed_mm_s(0) - 939.336).abs() < 0.01);
        assert!(m.dual_focus.is_none());
    }

    #[test]
    fn missing_key_names_it_and_the_file() {
        let text = minimal().replace("rpm = 78.0\n", "");
        let err = ScanMeta::from_toml_str(&text, Path::new("/x/scan.toml")).unwrap_err();
        let msg = err.to_string();
        assert!(msg.contains("rpm"), "{msg}");
        assert!(msg.contains("/x/scan.toml"), "{msg}");
    }

    #[test]
    fn nan_and_negative_values_are_rejected() {
        let text = minimal().replace("radius_mm = 115.0", "radius_mm = nan");
        assert!(ScanMeta::from_toml_str(&text, Path::new("s")).is_err());
        let text = minimal().replace("frame_step_um = 0.78", "frame_step_um = -0.78");
        let msg = ScanMeta::from_toml_str(&text, Path::new("s"))
            .unwrap_err()
            .to_string();
        assert!(msg.contains("motion.frame_step_um"), "{msg}");
    }

    #[test]
    fn dual_focus_shift_matches_thin_lens_geometry() {
        let text = format!(
            "{}\n[dual_focus]\nfocus_distance_mm = 4.0\nglass_thickness_mm = 0.11\nglass_index = 1.515\nglass_edge_row = 300\n",
            minimal()
        );
        let m = ScanMeta::from_toml_str(&text, Path::new("s")).unwrap();
        let (a, b) = m.dual_focus.unwrap().focal_distances_mm();
        assert!((a - 4.000).abs() < 1e-12);
        assert!((b - 4.037).abs() < 0.0005, "{b}");
        let bad = text.replace("glass_index = 1.515", "glass_index = 0.9");
        assert!(ScanMeta::from_toml_str(&bad, Path::new("s")).is_err());
    }

    #[test]
    fn extra_tables_round_trip() {
        let text = format!("{}\n[synth]\nseed = 7\n", minimal());
        let m = ScanMeta::from_toml_str(&text, Path::new("s")).unwrap();
        let back = ScanMeta::from_toml_str(&m.to_toml_string().unwrap(), Path::new("s")).unwrap();
        assert_eq!(m, back);
        assert!(back.extra.contains_key("synth"));
    }

    #[test]
    fn numbered_names_are_written_only_when_they_are_an_order() {
        // The default is left out, so the canonical text (and every scan's fingerprint) of a
        // scan.toml without the key is what it was before the key existed.
        let m = ScanMeta::from_toml_str(&minimal(), Path::new("s")).unwrap();
        assert_eq!(m.motion.numbered_names, NumberedNames::Positions);
        assert!(!m.to_toml_string().unwrap().contains("numbered_names"));
        let text = minimal().replace("[motion]\n", "[motion]\nnumbered_names = \"order\"\n");
        let m = ScanMeta::from_toml_str(&text, Path::new("s")).unwrap();
        assert_eq!(m.motion.numbered_names, NumberedNames::Order);
        let back = ScanMeta::from_toml_str(&m.to_toml_string().unwrap(), Path::new("s")).unwrap();
        assert_eq!(m, back);
        let bad = text.replace("\"order\"", "\"time\"");
        let msg = ScanMeta::from_toml_str(&bad, Path::new("/x/scan.toml"))
            .unwrap_err()
            .to_string();
        assert!(
            msg.contains("numbered_names") && msg.contains("`order`"),
            "{msg}"
        );
    }

    #[test]
    fn groups_that_name_their_frames_alike_share_one_list() {
        let files = |dir: &str, names: &[&str]| -> Vec<PathBuf> {
            names.iter().map(|n| Path::new(dir).join(n)).collect()
        };
        let mut names = FrameNames::default();
        let a = names.shared(&files("s/g0", &["f0.png", "f1.png"]));
        let b = names.shared(&files("s/g1", &["f0.png", "f1.png"]));
        let c = names.shared(&files("s/g2", &["f0.png", "f2.png"]));
        let d = names.shared(&files("s/g3", &["f0.png"]));
        assert!(Arc::ptr_eq(&a, &b));
        assert!(!Arc::ptr_eq(&b, &c));
        assert_eq!(&*d, &[OsString::from("f0.png")]);
        let entry = GroupEntry {
            index: 2,
            dir: PathBuf::from("s/g2"),
            frame_names: c,
            zarr: None,
            missing: None,
        };
        assert_eq!(entry.frame_count(), 2);
        assert_eq!(entry.frame_path(1), Some(PathBuf::from("s/g2/f2.png")));
        assert_eq!(entry.frame_path(2), None);
        let paths: Vec<PathBuf> = entry.frame_paths().collect();
        assert_eq!(paths, files("s/g2", &["f0.png", "f2.png"]));
    }

    /// The kind read from a folder listing is what `Path::is_dir` / `Path::is_file` say, links
    /// followed (a linked group folder or frame counts; a dangling link is neither).
    #[test]
    fn a_listings_kinds_are_what_the_paths_are_links_followed() {
        let tmp = tempfile::tempdir().unwrap();
        let d = tmp.path();
        for folder in ["g0", "f9.png"] {
            std::fs::create_dir(d.join(folder)).unwrap();
        }
        for file in ["f0.png", "g2"] {
            std::fs::write(d.join(file), b"x").unwrap();
        }
        for (link, to) in [("g1", "g0"), ("f1.png", "f0.png"), ("f2.png", "gone")] {
            std::os::unix::fs::symlink(d.join(to), d.join(link)).unwrap();
        }
        for entry in std::fs::read_dir(d).unwrap() {
            let entry = entry.unwrap();
            let p = entry.path();
            let want = if p.is_dir() {
                EntryKind::Folder
            } else if p.is_file() {
                EntryKind::File
            } else {
                EntryKind::Other
            };
            assert_eq!(EntryKind::of(&entry), want, "{}", p.display());
        }
        let names = |kind, keep: fn(&Path) -> bool| -> Vec<String> {
            sorted_entries(d, kind, keep, 10, "entries")
                .unwrap()
                .iter()
                .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
                .collect()
        };
        assert_eq!(names(EntryKind::Folder, |_| true), ["f9.png", "g0", "g1"]);
        assert_eq!(names(EntryKind::File, is_frame_file), ["f0.png", "f1.png"]);
    }
}
