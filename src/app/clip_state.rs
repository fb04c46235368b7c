//! The clip of the open scan: the reconstruction running in the background, the finished clip
//! on screen and in the player.

use std::sync::Arc;

use super::recon::{Clip, ReconRun};

/// The open scan's clip and its reconstruction.
#[derive(Debug, Default)]
pub struct ClipState {
    /// The reconstruction running now.
    pub run: Option<ReconRun>,
    /// The finished clip.
    pub clip: Option<Arc<Clip>>,
}

impl ClipState {
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
        let outcome = self.run.as_mut()?.poll()?;
        self.run = None;
        Some(outcome)
    }
}
