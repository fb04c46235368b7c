//! groovescope's fuzz targets as a library, for the libFuzzer binary and the seed writer.

#[path = "targets.rs"]
pub mod targets;

pub use targets::{TARGETS, Target, target};
