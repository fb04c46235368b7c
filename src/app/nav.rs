//! Where the operator is: the open scan, the current group and frame, the group's frames once
//! loaded (or why they could not be), and a scan being opened (it replaces the open one only
//! once its first group has loaded).

use std::path::Path;
use std::sync::Arc;

use super::tuning::Tuning;
use crate::image::Image;
use crate::io::{Scan, ScanMeta};
use crate::pipeline::PipelineParams;

/// A scan waiting for its first group to load before it replaces the open one.
#[derive(Debug)]
pub struct Opening {
    /// The scan.
    pub scan: Scan,
    /// Its params (its `preset.toml` or the defaults) and the line saying which.
    pub tuning: (Tuning, Result<String, String>),
    /// The worker job loading its first group.
    pub generation: u64,
}

/// The open scan and the place in it.
#[derive(Debug, Default)]
pub struct Navigation {
    /// The open scan.
    pub scan: Option<Scan>,
    /// Its metadata (shared with jobs).
    pub meta: Option<Arc<ScanMeta>>,
    /// A scan being opened.
    pub opening: Option<Opening>,
    /// Current group.
    pub group: usize,
    /// Current frame within the group.
    pub frame: usize,
    /// Frames of a group (the group index they belong to), once loaded.
    pub frames: Option<(usize, Arc<Vec<Image>>)>,
    /// Why the current group's frames could not be loaded.
    pub load_error: Option<String>,
}

impl Navigation {
    /// The place in a newly opened scan: group 0, its middle frame.
    #[must_use]
    pub fn opened(scan: Scan, frames: Arc<Vec<Image>>) -> Self {
        Self {
            meta: Some(Arc::new(scan.meta.clone())),
            scan: Some(scan),
            opening: None,
            group: 0,
            frame: frames.len() / 2,
            frames: Some((0, frames)),
            load_error: None,
        }
    }

    /// Groups in the open scan (0 when none is open).
    #[must_use]
    pub fn groups(&self) -> usize {
        self.scan.as_ref().map_or(0, |s| s.groups.len())
    }

    /// The open scan's folder.
    #[must_use]
    pub fn dir(&self) -> Option<&Path> {
        self.scan.as_ref().map(|s| s.dir.as_path())
    }

    /// The current group's frames, once loaded.
    #[must_use]
    pub fn frames(&self) -> Option<&Arc<Vec<Image>>> {
        self.frames
            .as_ref()
            .filter(|(g, _)| *g == self.group)
            .map(|(_, f)| f)
    }

    /// Frames in the current group (0 until they are loaded).
    #[must_use]
    pub fn frame_count(&self) -> usize {
        self.frames().map_or(0, |f| f.len())
    }

    /// Moves to group `g` (clamped); true when that is another group, or the current one's
    /// frames are not loaded (so it must be loaded and run).
    pub fn go_to_group(&mut self, g: usize) -> bool {
        if self.scan.is_none() {
            return false;
        }
        let g = g.min(self.groups().saturating_sub(1));
        if g == self.group && self.frames().is_some() {
            return false;
        }
        self.group = g;
        self.load_error = None;
        true
    }

    /// Shows frame `f` of the current group (clamped).
    pub fn set_frame(&mut self, f: usize) {
        let n = self.frames.as_ref().map_or(1, |(_, fr)| fr.len());
        self.frame = f.min(n.saturating_sub(1));
    }

    /// The frames of the current group arrived: keeps them (unless some are already there).
    pub fn frames_loaded(&mut self, group: usize, frames: Arc<Vec<Image>>) -> bool {
        if group != self.group || self.frames().is_some() {
            return false;
        }
        self.frame = self.frame.min(frames.len().saturating_sub(1));
        self.frames = Some((group, frames));
        self.load_error = None;
        true
    }

    /// Forgets the current group's frames, so the next job loads them again.
    pub fn forget_frames(&mut self) {
        self.frames = None;
        self.load_error = None;
    }

    /// True when `params` put the open scan on the dual-focus path.
    #[must_use]
    pub fn uses_dual(&self, params: &PipelineParams) -> bool {
        self.meta
            .as_ref()
            .is_some_and(|m| params.uses_dual_focus(m))
    }
}
