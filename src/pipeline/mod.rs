//! The reconstruction pipeline: pure per-group stages (no I/O, no GUI) and the stage cache both front ends share.

pub mod audio_signal;
pub mod depth;
pub mod derivatives;
pub mod dsp;
pub mod eval;
pub mod hough;
pub mod optical_flow;
pub mod orientation;
pub mod walls;

/// Why a stage could not produce its output.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StageError {
    /// A parameter is NaN, out of range or inconsistent.
    #[error("invalid parameter {name}: {problem}")]
    InvalidParam {
        /// The parameter (TOML path such as `flow.lambda`).
        name: String,
        /// What is wrong with it.
        problem: String,
    },
    /// The input does not suit the stage (too few frames, mismatched sizes, ...).
    #[error("{stage}: {problem}")]
    BadInput {
        /// The stage.
        stage: &'static str,
        /// What is wrong.
        problem: String,
    },
    /// The stage ran but found nothing usable (no walls, fewer than three stripes, ...).
    #[error("{stage}: {problem}")]
    NotFound {
        /// The stage.
        stage: &'static str,
        /// What was not found.
        problem: String,
    },
    /// A newer job superseded this one.
    #[error("cancelled")]
    Cancelled,
}

/// Checks that a float parameter is finite and inside `[lo, hi]`.
///
/// # Errors
/// [`StageError::InvalidParam`] naming `name`.
pub fn check_range(name: &str, value: f64, lo: f64, hi: f64) -> Result<(), StageError> {
    if value.is_finite() && value >= lo && value <= hi {
        Ok(())
    } else {
        Err(StageError::InvalidParam {
            name: name.to_string(),
            problem: format!("{value} is not in [{lo}, {hi}]"),
        })
    }
}
