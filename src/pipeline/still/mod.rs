//! The still decoder: grooves found in a top-view image, both borders of each wall tracked along
//! the chosen groove, and the borders' displacement turned into sound.

use serde::{Deserialize, Serialize};

/// Which way the grooves run in a still.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Axis {
    /// Grooves run down the image; time runs down.
    #[default]
    Vertical,
    /// Grooves run across the image; time runs rightward.
    Horizontal,
}
