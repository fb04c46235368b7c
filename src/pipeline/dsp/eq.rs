//! Playback equalisation curves (RIAA, 500 Hz turnover, and a 78's curve set by its turnover, treble roll-off and bass shelf) as analog curves and as biquad sections.

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
/// Where a treble roll-off is stated: a 78 chart's "roll-off" is the cut at 10 kHz (Hz).
pub(super) const ROLLOFF_REFERENCE_HZ: f64 = 10_000.0;

/// Corner frequency (Hz) of a time constant (s).
pub(super) fn corner_hz(tau_s: f64) -> f64 {
    1.0 / (2.0 * PI * tau_s)
}

/// The corner (Hz) of the first-order treble roll-off that cuts `rolloff_db` at 10 kHz
/// (`10·log10(1 + (10 kHz/f)²) = rolloff_db`); None for no roll-off (0 dB or less). 13.7 dB
/// gives 2.11 kHz, about RIAA's 75 µs (2.12 kHz, 13.66 dB).
#[must_use]
pub fn rolloff_corner_hz(rolloff_db: f64) -> Option<f64> {
    (rolloff_db > 0.0).then(|| ROLLOFF_REFERENCE_HZ / (10f64.powf(rolloff_db / 10.0) - 1.0).sqrt())
}

/// A playback curve by its corners (Hz): the bass boost rises 6 dB an octave from
/// `turnover_hz` down to `shelf_hz`, where it levels off, and a first-order treble roll-off
/// has its corner at `rolloff_hz`. What [`DspParams::playback_eq`] makes of `dsp.eq`: RIAA and
/// the 500 Hz turnover curve are such curves with fixed corners, `custom` takes them from its
/// knobs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlaybackEq {
    /// Where the bass boost levels off (Hz).
    pub shelf_hz: f64,
    /// The bass turnover, the boost's +3 dB point (Hz).
    pub turnover_hz: f64,
    /// The treble roll-off's corner (Hz; None: no roll-off).
    pub rolloff_hz: Option<f64>,
}

impl PlaybackEq {
    /// RIAA: 3180 µs shelf, 318 µs turnover, 75 µs roll-off.
    #[must_use]
    pub fn riaa() -> Self {
        Self {
            shelf_hz: corner_hz(RIAA_T1_S),
            turnover_hz: corner_hz(RIAA_T2_S),
            rolloff_hz: Some(corner_hz(RIAA_T3_S)),
        }
    }

    /// The common 78 curve: 500 Hz turnover, 50 Hz shelf, no roll-off.
    #[must_use]
    pub fn turnover500() -> Self {
        Self {
            shelf_hz: TURNOVER500_SHELF_HZ,
            turnover_hz: TURNOVER500_HZ,
            rolloff_hz: None,
        }
    }

    /// Analog magnitude (linear, not normalised) of the curve at `freq_hz`:
    /// `|1 + jf/f_turnover| / (|1 + jf/f_shelf|·|1 + jf/f_rolloff|)`.
    pub(super) fn analog_raw(self, freq_hz: f64) -> f64 {
        let pole = |hz: f64| (1.0 + (freq_hz / hz).powi(2)).sqrt();
        pole(self.turnover_hz) / (pole(self.shelf_hz) * self.rolloff_hz.map_or(1.0, pole))
    }

    /// The analog curve's gain (dB, 0 dB at 1 kHz) at `freq_hz`: the reference the digital
    /// filters are tested against.
    #[must_use]
    pub fn analog_gain_db(self, freq_hz: f64) -> f64 {
        20.0 * (self.analog_raw(freq_hz) / self.analog_raw(EQ_REFERENCE_HZ)).log10()
    }

    /// Highest corner of the curve (Hz); the sample rate must exceed twice it.
    pub(super) fn highest_corner_hz(self) -> f64 {
        self.rolloff_hz
            .map_or(self.turnover_hz, |r| r.max(self.turnover_hz))
    }

    /// The digital sections of the curve at `sample_rate_hz` (the shelf, then the roll-off),
    /// scaled to 0 dB at 1 kHz (1 kHz must be below Nyquist for the scaling; otherwise the
    /// analog scale is used).
    #[must_use]
    pub fn sections(self, sample_rate_hz: f64) -> Vec<Biquad> {
        let mut sections: Vec<Biquad> =
            std::iter::once(shelf(self.turnover_hz, self.shelf_hz, sample_rate_hz))
                .chain(
                    self.rolloff_hz
                        .map(|r| first_order_lowpass(r, sample_rate_hz)),
                )
                .collect();
        // Normalise with the analog gain at the reference so that the digital curve follows
        // the analog one (equal at low frequencies where warping vanishes).
        let scale = 1.0 / self.analog_raw(EQ_REFERENCE_HZ);
        if let Some(first) = sections.first_mut() {
            *first = first.scaled(scale);
        }
        sections
    }
}
