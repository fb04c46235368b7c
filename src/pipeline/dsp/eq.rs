//! Playback equalisation curves (RIAA, 500 Hz turnover) as analog curves and as biquad sections.

use super::*;

/// RIAA time constants (s): bass shelf pole, turnover zero, treble pole.
pub(super) const RIAA_T1_S: f64 = 3180e-6;
/// RIAA turnover zero (s).
pub(super) const RIAA_T2_S: f64 = 318e-6;
/// RIAA treble roll-off pole (s).
pub(super) const RIAA_T3_S: f64 = 75e-6;
/// Bass turnover of the [`EqCurve::Turnover500`] curve (Hz).
pub(super) const TURNOVER500_HZ: f64 = 500.0;
/// The turnover curve's boost stops a decade below the turnover (50 Hz), like RIAA's 3180 µs
/// shelf: a pure constant-amplitude bass would need infinite gain at DC.
pub(super) const TURNOVER500_SHELF_HZ: f64 = 50.0;
/// Frequency at which every EQ curve has 0 dB gain.
pub(super) const EQ_REFERENCE_HZ: f64 = 1000.0;
/// Corner frequency (Hz) of a time constant (s).
pub(super) fn corner_hz(tau_s: f64) -> f64 {
    1.0 / (2.0 * PI * tau_s)
}

impl EqCurve {
    /// Analog magnitude (linear, not normalised) of the curve at `freq_hz`.
    pub(super) fn analog_raw(self, freq_hz: f64) -> f64 {
        let w = 2.0 * PI * freq_hz;
        let mag = |tau: f64| (1.0 + (w * tau).powi(2)).sqrt();
        match self {
            Self::Flat => 1.0,
            Self::Riaa => mag(RIAA_T2_S) / (mag(RIAA_T1_S) * mag(RIAA_T3_S)),
            Self::Turnover500 => {
                mag(1.0 / (2.0 * PI * TURNOVER500_HZ))
                    / mag(1.0 / (2.0 * PI * TURNOVER500_SHELF_HZ))
            }
        }
    }

    /// The analog curve's gain (dB, 0 dB at 1 kHz) at `freq_hz`: the reference the digital
    /// filters are tested against.
    #[must_use]
    pub fn analog_gain_db(self, freq_hz: f64) -> f64 {
        20.0 * (self.analog_raw(freq_hz) / self.analog_raw(EQ_REFERENCE_HZ)).log10()
    }

    /// Highest corner of the curve (Hz); the sample rate must exceed twice it.
    pub(super) fn highest_corner_hz(self) -> f64 {
        match self {
            Self::Flat => 0.0,
            Self::Riaa => corner_hz(RIAA_T3_S),
            Self::Turnover500 => TURNOVER500_HZ,
        }
    }

    /// The digital sections of the curve at `sample_rate_hz`, scaled to 0 dB at 1 kHz
    /// (1 kHz must be below Nyquist for the scaling; otherwise the analog scale is used).
    #[must_use]
    pub fn sections(self, sample_rate_hz: f64) -> Vec<Biquad> {
        let raw = match self {
            Self::Flat => return Vec::new(),
            Self::Riaa => vec![
                shelf(corner_hz(RIAA_T2_S), corner_hz(RIAA_T1_S), sample_rate_hz),
                first_order_lowpass(corner_hz(RIAA_T3_S), sample_rate_hz),
            ],
            Self::Turnover500 => vec![shelf(TURNOVER500_HZ, TURNOVER500_SHELF_HZ, sample_rate_hz)],
        };
        // Normalise with the analog gain at the reference so that the digital curve follows
        // the analog one (equal at low frequencies where warping vanishes).
        let scale = 1.0 / self.analog_raw(EQ_REFERENCE_HZ);
        let mut sections = raw;
        if let Some(first) = sections.first_mut() {
            *first = first.scaled(scale);
        }
        sections
    }
}
