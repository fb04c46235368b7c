//! How a clip's frames become groups ([`GroupLayout`]) and the metadata the caller supplies ([`ClipMeta`]).

use super::{DEFAULT_FRAMES_PER_GROUP, VideoError};
use crate::io::scan::{
    CameraMeta, Cut, FORMAT_VERSION, MIN_FRAMES_PER_GROUP, MotionMeta, NumberedNames, RecordMeta,
    ScanMeta,
};

/// How a clip's frames are cut into groups.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct GroupLayout {
    /// Frames in each group (at least [`MIN_FRAMES_PER_GROUP`]).
    pub frames_per_group: usize,
    /// Frames between the first frames of consecutive groups; `None` = `frames_per_group`
    /// (no shared frames). Smaller values repeat frames; larger values skip frames.
    pub group_stride_frames: Option<usize>,
    /// Clip frames skipped before the first group.
    pub first_frame: usize,
    /// Write at most this many groups (decoding stops once they are full).
    pub max_groups: Option<usize>,
}

impl Default for GroupLayout {
    fn default() -> Self {
        Self {
            frames_per_group: DEFAULT_FRAMES_PER_GROUP,
            group_stride_frames: None,
            first_frame: 0,
            max_groups: None,
        }
    }
}

impl GroupLayout {
    /// Frames between the first frames of consecutive groups.
    #[must_use]
    pub fn stride(&self) -> usize {
        self.group_stride_frames.unwrap_or(self.frames_per_group)
    }

    /// Checks the grouping; returns the first problem.
    ///
    /// # Errors
    /// A sentence naming the setting.
    pub fn validate(&self) -> Result<(), String> {
        if self.frames_per_group < MIN_FRAMES_PER_GROUP {
            return Err(format!(
                "frames_per_group must be at least {MIN_FRAMES_PER_GROUP} (the derivative filters need {MIN_FRAMES_PER_GROUP}), got {}",
                self.frames_per_group
            ));
        }
        if self.stride() == 0 {
            return Err("group_stride_frames must be at least 1, got 0".into());
        }
        if self.max_groups == Some(0) {
            return Err("max_groups must be at least 1, got 0".into());
        }
        Ok(())
    }

    /// Full groups in `frames` frames counted from the first frame used (before `max_groups`).
    #[must_use]
    pub fn full_groups(&self, frames: usize) -> usize {
        if frames < self.frames_per_group {
            0
        } else {
            (frames - self.frames_per_group) / self.stride() + 1
        }
    }

    /// Groups written from `frames` frames (from the first frame used), `max_groups` applied.
    #[must_use]
    pub fn groups_written(&self, frames: usize) -> usize {
        let n = self.full_groups(frames);
        self.max_groups.map_or(n, |m| n.min(m))
    }

    /// Frames (from the first frame used) needed to fill `max_groups`, if set.
    pub(super) fn frames_needed(&self) -> Option<usize> {
        self.max_groups
            .map(|m| (m - 1) * self.stride() + self.frames_per_group)
    }

    /// The groups frame `j` (from the first frame used) belongs to, with its index in each.
    pub(super) fn placements(&self, j: usize) -> impl Iterator<Item = (usize, usize)> + '_ {
        let stride = self.stride();
        let lo = (j + 1)
            .saturating_sub(self.frames_per_group)
            .div_ceil(stride);
        let hi = j / stride;
        let cap = self.max_groups.unwrap_or(usize::MAX);
        (lo..=hi)
            .filter(move |&g| g < cap && j - g * stride < self.frames_per_group)
            .map(move |g| (g, j - g * stride))
    }
}

/// The metadata a clip does not carry: the caller supplies it and it becomes `scan.toml`.
#[derive(Clone, Debug, PartialEq)]
pub struct ClipMeta {
    /// Turntable speed the disc was cut at.
    pub rpm: f64,
    /// Groove radius at the first group.
    pub radius_mm: f64,
    /// Cut type.
    pub cut: Cut,
    /// Size of one pixel on the land plane.
    pub pixel_pitch_um: f64,
    /// Optical centre to the land plane.
    pub working_distance_mm: f64,
    /// Record travel between consecutive frames.
    pub frame_step_um: f64,
    /// Travel between the first frames of consecutive groups; `None` = stride × `frame_step_um`.
    pub group_step_um: Option<f64>,
}

impl Default for ClipMeta {
    /// The example values of docs/FORMAT.md (a 78 rpm disc under the paper's microscope).
    fn default() -> Self {
        Self {
            rpm: 78.0,
            radius_mm: 115.0,
            cut: Cut::Lateral,
            pixel_pitch_um: 0.39,
            working_distance_mm: 4.0,
            frame_step_um: 0.78,
            group_step_um: None,
        }
    }
}

impl ClipMeta {
    /// The scan metadata for `layout` (no extra tables), validated as [`crate::io::Scan::open`] does.
    ///
    /// # Errors
    /// [`VideoError::Settings`] naming the first invalid key.
    pub fn scan_meta(&self, layout: &GroupLayout) -> Result<ScanMeta, VideoError> {
        let group_step_um = self
            .group_step_um
            .unwrap_or(layout.stride() as f64 * self.frame_step_um);
        let meta = ScanMeta {
            format: FORMAT_VERSION,
            record: RecordMeta {
                rpm: self.rpm,
                radius_mm: self.radius_mm,
                cut: self.cut,
                group_radius_mm: None,
            },
            camera: CameraMeta {
                pixel_pitch_um: self.pixel_pitch_um,
                working_distance_mm: self.working_distance_mm,
            },
            motion: MotionMeta {
                frame_step_um: self.frame_step_um,
                group_step_um,
                numbered_names: NumberedNames::Positions,
            },
            dual_focus: None,
            extra: toml::Table::new(),
        };
        meta.validate()
            .map_err(|problem| VideoError::Settings { problem })?;
        Ok(meta)
    }
}
