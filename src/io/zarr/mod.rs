//! The Zarr v3 scan store: one zstd-compressed chunk per group, for side-scale scans (see docs/FORMAT.md).
//!
//! `scan.zarr/` holds a root group whose `groovescope` attribute carries the scan's
//! `scan.toml` text, the group names and the sample type, and one array `frames` of shape
//! `[groups, frames, height, width]` chunked `[1, frames, height, width]`: the samples as
//! stored in the frames (uint8 or uint16 grey; float32 grey for colour frames), `bytes` then
//! `zstd` with its checksum. `reference.wav` (when the scan has one) sits in the store folder
//! beside `zarr.json`. A missing chunk is an error naming it (a gap with `--keep-going`), never
//! a silent run of fill values.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use zarrs::array::codec::ZstdCodec;
use zarrs::array::{Array, ArrayBuilder, CodecOptions, data_type};
use zarrs::filesystem::FilesystemStore;
use zarrs::group::{Group, GroupBuilder};

use super::LoadError;
use super::frames::{RawFrame, RawSamples, grey_from_raw};
use super::limits::MAX_GROUPS;
use super::numbering::in_numbered_order;
use super::scan::{GroupEntry, MIN_FRAMES_PER_GROUP, Scan, ScanMeta, check_meta_against};
use crate::image::Image;

mod pack;
pub mod partial;
pub use pack::{PackError, PackSummary, pack_scan};
pub use partial::{Kept, PROGRESS_FILE, PackOptions, PartialStore, kept_groups, partial_path};

/// Path of the frames array inside the store.
pub const FRAMES_ARRAY: &str = "/frames";
/// Root attribute holding the scan's metadata.
pub const SCAN_ATTRIBUTE: &str = "groovescope";
/// Store layout version this build reads and writes.
pub const STORE_FORMAT: u32 = 1;
/// Default zstd level of `pack`.
pub const DEFAULT_ZSTD_LEVEL: i32 = 3;

/// How frame samples are stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SampleType {
    /// 8-bit grey.
    U8,
    /// 16-bit grey.
    U16,
    /// Grey `f32` from colour frames.
    F32,
}

impl SampleType {
    /// The type of a raw frame's samples.
    #[must_use]
    pub fn of(samples: &RawSamples) -> Self {
        match samples {
            RawSamples::U8(_) => Self::U8,
            RawSamples::U16(_) => Self::U16,
            RawSamples::F32(_) => Self::F32,
        }
    }

    fn data_type(self) -> zarrs::array::DataType {
        match self {
            Self::U8 => data_type::uint8(),
            Self::U16 => data_type::uint16(),
            Self::F32 => data_type::float32(),
        }
    }
}

/// The frames of every group of a store: how many, their size and how their samples are stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ChunkLayout {
    /// Frames per group.
    pub frames: usize,
    /// Frame width (px).
    pub width: usize,
    /// Frame height (px).
    pub height: usize,
    /// How samples are stored.
    pub sample_type: SampleType,
}

/// The root group's `groovescope` attribute.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StoreAttributes {
    /// [`STORE_FORMAT`].
    pub store_format: u32,
    /// The scan's `scan.toml`.
    pub scan_toml: String,
    /// Group names, in order (the folder names of the scan it was packed from).
    pub groups: Vec<String>,
    /// How samples are stored.
    pub sample_type: SampleType,
}

/// Where one group's frames are in a store.
#[derive(Clone, Debug, PartialEq)]
pub struct ZarrGroup {
    /// The store folder, one allocation shared by every group of the store.
    pub store: Arc<Path>,
    /// The group's chunk index.
    pub group: usize,
    /// The store's frames.
    pub layout: ChunkLayout,
}

impl ZarrGroup {
    /// The file of the group's chunk (it names the group in errors).
    #[must_use]
    pub fn chunk_path(&self) -> PathBuf {
        chunk_file(&self.store, self.group)
    }
}

/// The file of chunk `group` of the store folder `store`.
#[must_use]
pub fn chunk_file(store: &Path, group: usize) -> PathBuf {
    store
        .join("frames")
        .join("c")
        .join(group.to_string())
        .join("0")
        .join("0")
        .join("0")
}

fn not_a_store(problem: String, path: &Path) -> LoadError {
    LoadError::NotAScan {
        problem: format!("not a groovescope Zarr store: {problem}"),
        path: path.to_path_buf(),
    }
}

fn open_store(dir: &Path) -> Result<Arc<FilesystemStore>, LoadError> {
    FilesystemStore::new(dir)
        .map(Arc::new)
        .map_err(|e| LoadError::io(format!("cannot open the Zarr store: {e}"), dir))
}

/// Opens a store written by [`pack_scan`] or the video import as a [`Scan`].
///
/// # Errors
/// [`LoadError`] naming the store when its metadata is missing or does not fit a scan.
pub fn open_scan(dir: &Path) -> Result<Scan, LoadError> {
    let store = open_store(dir)?;
    let group = Group::open(store.clone(), "/").map_err(|e| not_a_store(e.to_string(), dir))?;
    let attrs: StoreAttributes = group
        .attributes()
        .get(SCAN_ATTRIBUTE)
        .cloned()
        .ok_or_else(|| not_a_store(format!("no `{SCAN_ATTRIBUTE}` attribute"), dir))
        .and_then(|v| serde_json::from_value(v).map_err(|e| not_a_store(e.to_string(), dir)))?;
    if attrs.store_format != STORE_FORMAT {
        return Err(not_a_store(
            format!(
                "store format {} (this build reads {STORE_FORMAT})",
                attrs.store_format
            ),
            dir,
        ));
    }
    let meta = ScanMeta::from_toml_str(&attrs.scan_toml, &dir.join("zarr.json"))?;
    let array = Array::open(store, FRAMES_ARRAY).map_err(|e| not_a_store(e.to_string(), dir))?;
    let shape = array.shape().to_vec();
    let dims: Vec<usize> = shape.iter().map(|&d| d as usize).collect();
    let [groups, frames, height, width] = dims[..] else {
        return Err(not_a_store(format!("frames array of shape {shape:?}"), dir));
    };
    if groups != attrs.groups.len()
        || *array.data_type() != attrs.sample_type.data_type()
        || array
            .chunk_shape(&[0, 0, 0, 0])
            .map(|c| c.iter().map(|d| d.get()).collect::<Vec<_>>())
            .ok()
            != Some(vec![1, shape[1], shape[2], shape[3]])
    {
        return Err(not_a_store(
            "the frames array does not match the group list, sample type or one chunk a group"
                .into(),
            dir,
        ));
    }
    if groups == 0 {
        return Err(LoadError::NotAScan {
            problem: "the scan holds no groups".into(),
            path: dir.to_path_buf(),
        });
    }
    if frames < MIN_FRAMES_PER_GROUP {
        return Err(LoadError::TooFewFrames {
            found: frames,
            needed: MIN_FRAMES_PER_GROUP,
            path: dir.join("frames"),
        });
    }
    // The names are read as a scan folder's are (docs/FORMAT.md): a store packed before
    // numbered names were positions holds its groups in name order (g10 before g2), and one
    // packed from folders that had lost a group holds the groups after it one place early.
    let stored: Vec<PathBuf> = attrs.groups.iter().map(|name| dir.join(name)).collect();
    let chunk_of: std::collections::HashMap<&PathBuf, usize> =
        stored.iter().enumerate().map(|(k, p)| (p, k)).collect();
    if chunk_of.len() != stored.len() {
        return Err(not_a_store(
            "two of its groups carry the same name, so which chunk is which is unknown".into(),
            dir,
        ));
    }
    let names_say = meta.motion.numbered_names;
    let places = in_numbered_order(dir, stored.clone(), MAX_GROUPS, "groups", names_say)?;
    let store: Arc<Path> = Arc::from(dir);
    let entries: Vec<GroupEntry> = places
        .into_iter()
        .enumerate()
        .map(|(index, path)| GroupEntry {
            index,
            // A skipped number has no chunk: loading it fails naming it.
            missing: (!chunk_of.contains_key(&path))
                .then_some("group (the store was packed without it)"),
            zarr: chunk_of.get(&path).map(|&group| ZarrGroup {
                store: Arc::clone(&store),
                group,
                layout: ChunkLayout {
                    frames,
                    width,
                    height,
                    sample_type: attrs.sample_type,
                },
            }),
            dir: path,
            frame_names: std::sync::Arc::new([]),
        })
        .collect();
    check_meta_against(&meta, &entries, (width, height), &dir.join("zarr.json"))?;
    Ok(Scan {
        dir: dir.to_path_buf(),
        meta,
        groups: entries,
        reference: super::scan::reference_in(dir),
        frame_size: (width, height),
    })
}

/// Reads one group's chunk as raw frames.
///
/// # Errors
/// [`LoadError::BadFrame`] naming the chunk when it is missing or does not decode (its zstd
/// checksum catches damage).
pub fn load_group_raw(z: &ZarrGroup) -> Result<Vec<RawFrame>, LoadError> {
    let store = open_store(&z.store)?;
    let array = Array::open(store, FRAMES_ARRAY).map_err(|e| LoadError::BadFrame {
        problem: e.to_string(),
        path: z.chunk_path(),
    })?;
    group_frames(&array, z)
}

/// Group `z.group`'s chunk of `array` as raw frames (see [`load_group_raw`]).
fn group_frames(array: &Array<FilesystemStore>, z: &ZarrGroup) -> Result<Vec<RawFrame>, LoadError> {
    let chunk = z.chunk_path();
    let bad = |problem: String| LoadError::BadFrame {
        problem,
        path: chunk.clone(),
    };
    let idx = [z.group as u64, 0, 0, 0];
    let px = z.layout.width * z.layout.height;
    let missing = || {
        bad(format!(
            "the chunk of group {} is missing from the store",
            z.group
        ))
    };
    let frames: Vec<RawSamples> = match z.layout.sample_type {
        SampleType::U8 => chunk_frames(array, &idx, px, RawSamples::U8),
        SampleType::U16 => chunk_frames(array, &idx, px, RawSamples::U16),
        SampleType::F32 => chunk_frames(array, &idx, px, RawSamples::F32),
    }
    .map_err(|e| bad(e.to_string()))?
    .ok_or_else(missing)?;
    if frames.len() != z.layout.frames {
        return Err(bad(format!(
            "the chunk holds {} frames, the array says {}",
            frames.len(),
            z.layout.frames
        )));
    }
    Ok(frames
        .into_iter()
        .map(|samples| RawFrame {
            width: z.layout.width,
            height: z.layout.height,
            samples,
        })
        .collect())
}

/// A chunk's frames of `px` samples each (None when the chunk is missing).
fn chunk_frames<T: zarrs::array::ElementOwned + Clone>(
    array: &Array<FilesystemStore>,
    idx: &[u64],
    px: usize,
    wrap: fn(Vec<T>) -> RawSamples,
) -> Result<Option<Vec<RawSamples>>, zarrs::array::ArrayError> {
    Ok(array
        .retrieve_chunk_if_exists::<Vec<T>>(idx)?
        .map(|v| v.chunks(px.max(1)).map(|f| wrap(f.to_vec())).collect()))
}

/// The frames `range` (clamped) of a group as grey `f32`, exactly as the frames of the scan
/// folder it was packed from load. The whole chunk is decoded, so damage anywhere in it is
/// reported.
///
/// # Errors
/// As [`load_group_raw`].
pub fn load_group_frames(
    z: &ZarrGroup,
    range: std::ops::Range<usize>,
) -> Result<Vec<Image>, LoadError> {
    let raw = load_group_raw(z)?;
    let n = raw.len();
    Ok(raw
        .into_iter()
        .skip(range.start.min(n))
        .take(range.end.min(n).saturating_sub(range.start.min(n)))
        .collect::<Vec<_>>()
        .into_par_iter()
        .map(grey_from_raw)
        .collect())
}

/// Writes a store group by group (used by `pack` and by the video import).
pub struct ZarrWriter {
    dir: PathBuf,
    store: Arc<FilesystemStore>,
    array: Array<FilesystemStore>,
    layout: ChunkLayout,
    names: Vec<String>,
}

impl std::fmt::Debug for ZarrWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ZarrWriter")
            .field("dir", &self.dir)
            .field("groups", &self.names.len())
            .finish_non_exhaustive()
    }
}

impl ZarrWriter {
    /// Starts a store in the empty folder `dir` for groups of `layout`, compressed at zstd
    /// `level`.
    ///
    /// # Errors
    /// [`LoadError::Io`] naming `dir` when the store cannot be created.
    pub fn create(dir: &Path, layout: ChunkLayout, level: i32) -> Result<Self, LoadError> {
        Self::reopen(dir, layout, level, Vec::new())
    }

    /// Goes on with a store in `dir` whose first `names.len()` chunks were written (and
    /// checked) by a writer of the same layout and `level`: the array's metadata is written
    /// again from that layout (the copy on disk may be one group ahead of the chunks, or torn
    /// by a kill), and the next group written becomes chunk `names.len()`. With no names it
    /// starts a new store.
    ///
    /// # Errors
    /// [`LoadError::Io`] naming `dir` when the store cannot be created or its metadata written.
    pub fn reopen(
        dir: &Path,
        layout: ChunkLayout,
        level: i32,
        names: Vec<String>,
    ) -> Result<Self, LoadError> {
        let err = |e: &dyn std::fmt::Display| {
            LoadError::io(format!("cannot create the Zarr store: {e}"), dir)
        };
        std::fs::create_dir_all(dir).map_err(|e| err(&e))?;
        let store = open_store(dir)?;
        let (f, h, w) = (
            layout.frames as u64,
            layout.height as u64,
            layout.width as u64,
        );
        let fill: zarrs::array::FillValue = match layout.sample_type {
            SampleType::U8 => 0u8.into(),
            SampleType::U16 => 0u16.into(),
            SampleType::F32 => 0f32.into(),
        };
        let array = ArrayBuilder::new(
            vec![names.len() as u64, f, h, w],
            vec![1, f, h, w],
            layout.sample_type.data_type(),
            fill,
        )
        .bytes_to_bytes_codecs(vec![Arc::new(ZstdCodec::new(level, true))])
        .dimension_names(["group", "frame", "y", "x"].into())
        .build(store.clone(), FRAMES_ARRAY)
        .map_err(|e| err(&e))?;
        if !names.is_empty() {
            array.store_metadata().map_err(|e| err(&e))?;
        }
        Ok(Self {
            dir: dir.to_path_buf(),
            store,
            array,
            layout,
            names,
        })
    }

    /// Appends the next group's frames as one chunk.
    ///
    /// # Errors
    /// [`LoadError`] naming the group when its frames do not fit the store, or the write fails.
    pub fn write_group(
        &mut self,
        name: &str,
        frames: &[RawFrame],
        source: &Path,
    ) -> Result<(), LoadError> {
        let g = self.names.len() as u64;
        if frames.len() != self.layout.frames {
            return Err(LoadError::Io {
                problem: format!(
                    "a Zarr store needs the same number of frames in every group: this one has {}, the first {}",
                    frames.len(),
                    self.layout.frames
                ),
                path: source.to_path_buf(),
            });
        }
        let mut u8s = Vec::new();
        let mut u16s = Vec::new();
        let mut f32s = Vec::new();
        for f in frames {
            if f.width != self.layout.width || f.height != self.layout.height {
                return Err(LoadError::MixedSizes {
                    found_w: f.width,
                    found_h: f.height,
                    want_w: self.layout.width,
                    want_h: self.layout.height,
                    path: source.to_path_buf(),
                });
            }
            match (&f.samples, self.layout.sample_type) {
                (RawSamples::U8(v), SampleType::U8) => u8s.extend_from_slice(v),
                (RawSamples::U16(v), SampleType::U16) => u16s.extend_from_slice(v),
                (RawSamples::F32(v), SampleType::F32) => f32s.extend_from_slice(v),
                (other, want) => {
                    return Err(LoadError::Io {
                        problem: format!(
                            "a Zarr store needs one sample type: this group has {:?} frames, the first group {want:?}",
                            SampleType::of(other)
                        ),
                        path: source.to_path_buf(),
                    });
                }
            }
        }
        let mut shape = self.array.shape().to_vec();
        shape[0] = g + 1;
        // The write is the store's: named by the chunk's file, not the group it came from.
        let chunk = chunk_file(&self.dir, usize::try_from(g).unwrap_or(usize::MAX));
        let err = |e: &dyn std::fmt::Display| {
            LoadError::io(format!("cannot write the group's chunk: {e}"), &chunk)
        };
        // In memory only: the metadata on disk is written by `store_metadata` (and by
        // `reopen`), and [`Self::read_back`] reads through this array.
        self.array.set_shape(shape).map_err(|e| err(&e))?;
        // A chunk of zeros is still written: a missing chunk means a lost group, not black frames.
        let opts = CodecOptions::default().with_store_empty_chunks(true);
        let idx = [g, 0, 0, 0];
        match self.layout.sample_type {
            SampleType::U8 => self.array.store_chunk_opt(&idx, u8s, &opts),
            SampleType::U16 => self.array.store_chunk_opt(&idx, u16s, &opts),
            SampleType::F32 => self.array.store_chunk_opt(&idx, f32s, &opts),
        }
        .map_err(|e| err(&e))?;
        self.names.push(name.to_string());
        Ok(())
    }

    /// Writes the metadata (array shape, root attributes with `scan_toml`) and ends the store.
    ///
    /// # Errors
    /// [`LoadError::Io`] naming the store when a write fails.
    pub fn finish(self, scan_toml: &str) -> Result<PathBuf, LoadError> {
        self.store_metadata(scan_toml)?;
        Ok(self.dir)
    }

    /// Writes the metadata (array shape, root attributes with `scan_toml`) as [`Self::finish`]
    /// does, keeping the writer (a store finished again after a failure writes it again).
    ///
    /// # Errors
    /// [`LoadError::Io`] naming the store when a write fails.
    pub fn store_metadata(&self, scan_toml: &str) -> Result<(), LoadError> {
        let err = |e: &dyn std::fmt::Display| {
            LoadError::io(format!("cannot write the Zarr metadata: {e}"), &self.dir)
        };
        self.array.store_metadata().map_err(|e| err(&e))?;
        let attrs = StoreAttributes {
            store_format: STORE_FORMAT,
            scan_toml: scan_toml.to_string(),
            groups: self.names.clone(),
            sample_type: self.layout.sample_type,
        };
        let mut map = serde_json::Map::new();
        map.insert(
            SCAN_ATTRIBUTE.into(),
            serde_json::to_value(&attrs).map_err(|e| err(&e))?,
        );
        GroupBuilder::new()
            .attributes(map)
            .build(self.store.clone(), "/")
            .map_err(|e| err(&e))?
            .store_metadata()
            .map_err(|e| err(&e))
    }

    /// Group `g`'s chunk as written, decoded through the writer's own array (no metadata is
    /// read from disk).
    ///
    /// # Errors
    /// As [`load_group_raw`].
    pub fn read_back(&self, g: usize) -> Result<Vec<RawFrame>, LoadError> {
        let z = ZarrGroup {
            store: Arc::from(self.dir.as_path()),
            group: g,
            layout: self.layout,
        };
        group_frames(&self.array, &z)
    }
}
