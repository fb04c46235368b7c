//! Disk input and output: scans (folders or Zarr stores) and frames, WAV files, `.flo` flow fields, atomic writes, video import (feature `video`).

pub mod atomic;
pub mod bwf;
pub mod fingerprint;
pub mod flo;
pub mod frames;
pub mod limits;
pub mod lock;
mod numbering;
pub mod scan;
pub mod staged;
pub mod still;
#[cfg(feature = "video")]
pub mod video;
pub mod wav;
pub mod zarr;

use std::path::PathBuf;

pub use atomic::{write_atomic, write_atomic_with, write_json_atomic};
pub use frames::{load_frame, load_group, load_group_frames, save_grey_png};
pub use scan::{Cut, Geometry, GroupEntry, Scan, ScanMeta};

impl LoadError {
    /// [`LoadError::Io`]: `problem` with the file or folder `path`.
    #[must_use]
    pub fn io(problem: impl Into<String>, path: &std::path::Path) -> Self {
        Self::Io {
            problem: problem.into(),
            path: path.to_path_buf(),
        }
    }
}

/// Why a scan, frame or sound file could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum LoadError {
    /// The folder is not a scan.
    #[error("{problem}: {}", path.display())]
    NotAScan {
        /// What is wrong.
        problem: String,
        /// The folder.
        path: PathBuf,
    },
    /// `scan.toml` is missing a key or holds an invalid value.
    #[error("invalid scan metadata: {problem}: {}", path.display())]
    Metadata {
        /// What is wrong.
        problem: String,
        /// The metadata file.
        path: PathBuf,
    },
    /// A group folder or a frame that is not on disk: one whose number the scan's numbering
    /// skips (it keeps its place, so what follows stays where it lies; see docs/FORMAT.md),
    /// or one removed after the scan was opened.
    #[error("{what} is missing: {}", path.display())]
    Missing {
        /// "frame", or [`GroupEntry::missing`]'s words for a group.
        what: &'static str,
        /// Where it would be.
        path: PathBuf,
    },
    /// A group holds too few frames.
    #[error("group has {found} frames, at least {needed} are needed: {}", path.display())]
    TooFewFrames {
        /// Frames found.
        found: usize,
        /// Frames needed.
        needed: usize,
        /// The group folder.
        path: PathBuf,
    },
    /// A frame cannot be decoded.
    #[error("cannot decode frame ({problem}): {}", path.display())]
    BadFrame {
        /// Decoder message.
        problem: String,
        /// The frame file.
        path: PathBuf,
    },
    /// A group's frames differ in size from the scan's (its first group's).
    #[error("this group's frames are {found_w}x{found_h} but the scan's are {want_w}x{want_h}: {}", path.display())]
    GroupSize {
        /// Width found.
        found_w: usize,
        /// Height found.
        found_h: usize,
        /// The scan's width.
        want_w: usize,
        /// The scan's height.
        want_h: usize,
        /// The group's first frame read.
        path: PathBuf,
    },
    /// A frame differs in size from the first frame of its group.
    #[error("frame is {found_w}x{found_h} but the group's first frame is {want_w}x{want_h}: {}", path.display())]
    MixedSizes {
        /// Width found.
        found_w: usize,
        /// Height found.
        found_h: usize,
        /// Width expected.
        want_w: usize,
        /// Height expected.
        want_h: usize,
        /// The frame file.
        path: PathBuf,
    },
    /// A sound file is unusable.
    #[error("{problem}: {}", path.display())]
    Sound {
        /// What is wrong.
        problem: String,
        /// The sound file.
        path: PathBuf,
    },
    /// Any other file-system failure (including a full disk).
    #[error("{problem}: {}", path.display())]
    Io {
        /// What failed.
        problem: String,
        /// The file or folder.
        path: PathBuf,
    },
}
