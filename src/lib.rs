//! groovescope: plays gramophone records from microscope image sequences by optical flow (Tian & Barron).
//!
//! The [`pipeline`] holds the pure stages; [`io`] reads scans and writes sound; [`synth`] renders
//! ground-truth scans.

pub mod accuracy;
pub mod alloc;
#[cfg(feature = "gui")]
pub mod app;
pub mod assets;
pub mod cli;
pub mod engine;
pub mod eval_cli;
pub mod image;
pub mod inspect;
pub mod io;
pub mod job;
pub mod meta;
pub(crate) mod output_checks;
pub mod pack_cli;
pub mod pipeline;
#[cfg(feature = "gui")]
pub mod playback;
pub mod side;
pub mod stdout;
pub mod still;
pub mod synth;
#[cfg(test)]
pub(crate) mod test_support;
pub mod toml_error;
pub mod video_cli;
pub mod viz;
