//! The clip of the open scan: the reconstruction running in the background, the finished clip
//! on screen and in the player, the clip before it (kept for A/B listening after a change,
//! laid on the new clip's time axis), and the health of every group.

use std::sync::Arc;

use super::health::ClipHealth;
use super::recon::{Clip, PartialClip, ReconRun};
use crate::playback::PlayBuffers;

/// The player's sources, in [`ClipState::play_buffers`] order.
pub const SOURCE_CLIP: usize = 0;
/// The previous clip.
pub const SOURCE_PREVIOUS: usize = 1;
/// The scan's reference recording.
pub const SOURCE_REFERENCE: usize = 2;

/// A clip kept for comparison, and its sound laid on the current clip's time axis (None when
/// the two have different rates).
pub type PreviousClip = (Arc<Clip>, Option<Arc<Vec<f32>>>);

/// The open scan's clip and its reconstruction.
#[derive(Debug, Default)]
pub struct ClipState {
    /// The reconstruction running now.
    pub run: Option<ReconRun>,
    /// The finished clip.
    pub clip: Option<Arc<Clip>>,
    /// The clip before it, for A/B.
    pub previous: Option<PreviousClip>,
    /// Health of each of the scan's groups.
    pub health: ClipHealth,
    /// The sound of the groups finished so far, arrived from the running reconstruction and
    /// not yet handed to the player.
    pub partial_arrived: Option<Result<PartialClip, String>>,
    /// The methods A and B when the player holds a method comparison's sound instead of the
    /// clip's (source 0: A, 1: B).
    pub comparison_heard: Option<[crate::pipeline::Method; 2]>,
    /// The player holds the still window's groove instead of the clip.
    pub still_heard: bool,
    groups: usize,
}

impl ClipState {
    /// No clip yet for a scan of `groups` groups.
    #[must_use]
    pub fn for_scan(groups: usize) -> Self {
        let mut s = Self {
            groups,
            ..Self::default()
        };
        s.refresh_health();
        s
    }

    /// True while a reconstruction runs.
    #[must_use]
    pub fn is_running(&self) -> bool {
        self.run.is_some()
    }

    /// Asks the running reconstruction to stop after its current group.
    pub fn cancel(&self) {
        if let Some(r) = &self.run {
            r.cancel();
        }
    }

    /// Takes the running reconstruction's reports; its outcome once it ended.
    pub fn poll(&mut self) -> Option<Result<Box<Clip>, String>> {
        let run = self.run.as_mut()?;
        let before = run.tracks.len();
        let outcome = run.poll();
        // A partial sound that comes with the end is dropped: the whole clip is there.
        if let Some(p) = run.take_partial().filter(|_| outcome.is_none()) {
            self.partial_arrived = Some(p);
        }
        let grew = run.tracks.len() != before;
        if outcome.is_some() {
            self.run = None;
        }
        if grew {
            self.refresh_health();
        }
        outcome
    }

    /// Asks the running reconstruction for the sound of the groups finished so far.
    pub fn request_partial(&self) {
        if let Some(r) = &self.run {
            r.request_partial();
        }
    }

    /// Makes `clip` the clip; the one before becomes the previous clip.
    pub fn finish(&mut self, clip: Clip) {
        let clip = Arc::new(clip);
        self.previous = self.clip.take().map(|old| {
            let laid = clip.lay_on(&old).map(Arc::new);
            (old, laid)
        });
        self.clip = Some(clip);
        self.comparison_heard = None;
        self.still_heard = false;
        self.refresh_health();
    }

    /// Health from the finished clip (its tracks and report rows), or the running
    /// reconstruction's tracks so far.
    pub fn refresh_health(&mut self) {
        self.health = match (&self.run, &self.clip) {
            // A refinish runs no group: the clip's health stands until it is done.
            (Some(run), _) if !run.refinishing => ClipHealth::new(self.groups, &run.tracks, &[]),
            (_, Some(c)) => ClipHealth::new(self.groups, &c.tracks, &c.recon.groups),
            (_, None) => ClipHealth::new(self.groups, &[], &[]),
        };
    }

    /// Sound for the player: the clip, the previous clip laid on it, the reference (empty
    /// where missing).
    #[must_use]
    pub fn play_buffers(&self) -> PlayBuffers {
        let Some(clip) = &self.clip else {
            return PlayBuffers::default();
        };
        let previous = self
            .previous
            .as_ref()
            .and_then(|(_, laid)| laid.as_ref())
            .map_or_else(Vec::new, |p| vec![p.to_vec()]);
        let reference = clip
            .reference
            .as_ref()
            .map_or_else(Vec::new, |r| vec![r.samples.to_vec()]);
        PlayBuffers {
            rate_hz: clip.rate_hz(),
            sources: vec![clip.recon.audio.channels.clone(), previous, reference],
        }
    }
}
