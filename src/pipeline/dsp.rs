//! Post-processing DSP: 2nd-order Butterworth low-pass and playback EQ curves for 78s and LPs.

use serde::{Deserialize, Serialize};

use super::StageError;

/// Playback equalisation curve.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum EqCurve {
    /// No EQ: the output is groove velocity.
    #[default]
    Flat,
    /// RIAA playback de-emphasis (3180/318/75 µs).
    Riaa,
    /// A common 78 rpm curve: 500 Hz turnover, no treble roll-off.
    Turnover500,
}

/// Knobs of [`apply_dsp`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DspParams {
    /// Apply the Butterworth low-pass.
    pub lowpass: bool,
    /// Its −3 dB cutoff (Hz).
    pub lowpass_hz: f64,
    /// EQ curve.
    pub eq: EqCurve,
}

impl Default for DspParams {
    fn default() -> Self {
        Self {
            lowpass: true,
            lowpass_hz: 3000.0,
            eq: EqCurve::Flat,
        }
    }
}

/// Applies EQ and the low-pass to one channel in place.
///
/// # Errors
/// [`StageError`] when the cutoff is not below Nyquist or not positive.
pub fn apply_dsp(
    samples: &mut [f32],
    sample_rate_hz: f64,
    params: &DspParams,
) -> Result<(), StageError> {
    todo!("dsp helper: {} {sample_rate_hz} {params:?}", samples.len())
}
