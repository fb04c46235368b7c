//! Second-order IIR sections from analog prototypes by the bilinear transform, pre-warped at each corner: DC blocker, Butterworth low-pass, shelves.

use super::*;

/// One second-order IIR section `H(z) = (b0 + b1 z⁻¹ + b2 z⁻²) / (1 + a1 z⁻¹ + a2 z⁻²)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Biquad {
    /// Numerator coefficients.
    pub b: [f64; 3],
    /// Denominator coefficients a1, a2 (a0 = 1).
    pub a: [f64; 2],
}

impl Biquad {
    /// The identity filter.
    pub(super) const IDENTITY: Self = Self {
        b: [1.0, 0.0, 0.0],
        a: [0.0, 0.0],
    };

    /// Complex response at `freq_hz` for sample rate `sample_rate_hz`, as (re, im).
    #[must_use]
    pub fn response(&self, freq_hz: f64, sample_rate_hz: f64) -> (f64, f64) {
        let w = 2.0 * PI * freq_hz / sample_rate_hz;
        // z⁻¹ = e^{-jw}, z⁻² = e^{-2jw}.
        let (s1, c1) = w.sin_cos();
        let (s2, c2) = (2.0 * w).sin_cos();
        let num = (
            self.b[0] + self.b[1] * c1 + self.b[2] * c2,
            -self.b[1] * s1 - self.b[2] * s2,
        );
        let den = (
            1.0 + self.a[0] * c1 + self.a[1] * c2,
            -self.a[0] * s1 - self.a[1] * s2,
        );
        let d2 = den.0 * den.0 + den.1 * den.1;
        (
            (num.0 * den.0 + num.1 * den.1) / d2,
            (num.1 * den.0 - num.0 * den.1) / d2,
        )
    }

    /// Gain in dB at `freq_hz`.
    #[must_use]
    pub fn gain_db(&self, freq_hz: f64, sample_rate_hz: f64) -> f64 {
        let (re, im) = self.response(freq_hz, sample_rate_hz);
        10.0 * (re * re + im * im).log10()
    }

    /// Scales the numerator so the gain is multiplied by `k`.
    pub(super) fn scaled(mut self, k: f64) -> Self {
        for b in &mut self.b {
            *b *= k;
        }
        self
    }

    /// Filters `samples` in place (direct form II transposed, f64 state). The state starts at
    /// the steady state for a constant input equal to the first sample, so a signal that starts
    /// on a DC offset does not begin with a step transient.
    pub fn run(&self, samples: &mut [f32]) {
        let Some(&first) = samples.first() else {
            return;
        };
        self.run_settled(samples, f64::from(first));
    }

    /// Like [`Biquad::run`], but the filter starts settled on a constant input `x0` instead of
    /// the first sample (a high-pass then has no start transient from a DC offset of `x0`).
    pub fn run_settled(&self, samples: &mut [f32], x0: f64) {
        self.settled(x0).run(samples.iter_mut());
    }

    /// The filter's running state, settled on a constant input `x0`: it can be fed samples in
    /// any order (backward, or across buffers) without copying them into one.
    #[must_use]
    pub fn settled(&self, x0: f64) -> Running<'_> {
        let [b0, b1, b2] = self.b;
        let [a1, a2] = self.a;
        let den = 1.0 + a1 + a2;
        let dc_gain = if den.abs() > f64::EPSILON {
            (b0 + b1 + b2) / den
        } else {
            0.0
        };
        let y0 = dc_gain * x0;
        let s2 = b2 * x0 - a2 * y0;
        let s1 = b1 * x0 - a1 * y0 + s2;
        Running {
            section: self,
            s1,
            s2,
        }
    }
}

/// A [`Biquad`] part way through a signal (see [`Biquad::settled`]).
#[derive(Debug)]
pub struct Running<'a> {
    section: &'a Biquad,
    s1: f64,
    s2: f64,
}

impl Running<'_> {
    /// Filters `samples` in place, in the order given, carrying the state on.
    pub fn run<'s>(&mut self, samples: impl Iterator<Item = &'s mut f32>) {
        let [b0, b1, b2] = self.section.b;
        let [a1, a2] = self.section.a;
        for v in samples {
            let x = f64::from(*v);
            let y = b0 * x + self.s1;
            self.s1 = b1 * x - a1 * y + self.s2;
            self.s2 = b2 * x - a2 * y;
            #[allow(clippy::cast_possible_truncation)] // audio samples are f32
            {
                *v = y as f32;
            }
        }
    }
}

/// Bilinear constant that maps the analog corner `corner_hz` to the same digital frequency.
pub(super) fn prewarp(corner_hz: f64, sample_rate_hz: f64) -> f64 {
    let w = 2.0 * PI * corner_hz;
    w / (w / (2.0 * sample_rate_hz)).tan()
}

/// First-order section `(n0 + n1·s) / (d0 + d1·s)` by the bilinear transform, numerator warped
/// with constant `cn` and denominator with `cd` (`s = c·(1 − z⁻¹)/(1 + z⁻¹)`).
pub(super) fn first_order(n: [f64; 2], cn: f64, d: [f64; 2], cd: f64) -> Biquad {
    let (nb0, nb1) = (n[0] + n[1] * cn, n[0] - n[1] * cn);
    let (da0, da1) = (d[0] + d[1] * cd, d[0] - d[1] * cd);
    Biquad {
        b: [nb0 / da0, nb1 / da0, 0.0],
        a: [da1 / da0, 0.0],
    }
}

/// Pole-zero shelf `(1 + s/ωz) / (1 + s/ωp)` with both corners pre-warped.
pub(super) fn shelf(zero_hz: f64, pole_hz: f64, sample_rate_hz: f64) -> Biquad {
    first_order(
        [1.0, 1.0 / (2.0 * PI * zero_hz)],
        prewarp(zero_hz, sample_rate_hz),
        [1.0, 1.0 / (2.0 * PI * pole_hz)],
        prewarp(pole_hz, sample_rate_hz),
    )
}

/// First-order low-pass `1 / (1 + s/ωp)`, pre-warped at its corner.
pub(super) fn first_order_lowpass(pole_hz: f64, sample_rate_hz: f64) -> Biquad {
    let c = prewarp(pole_hz, sample_rate_hz);
    first_order([1.0, 0.0], c, [1.0, 1.0 / (2.0 * PI * pole_hz)], c)
}

/// First-order high-pass `(s/ωc) / (1 + s/ωc)`, pre-warped at its corner (the DC blocker).
#[must_use]
pub fn dc_blocker(corner_hz: f64, sample_rate_hz: f64) -> Biquad {
    let c = prewarp(corner_hz, sample_rate_hz);
    let tau = 1.0 / (2.0 * PI * corner_hz);
    first_order([0.0, tau], c, [1.0, tau], c)
}

/// 2nd-order Butterworth low-pass (−3 dB at `cutoff_hz`, pre-warped bilinear transform).
#[must_use]
pub fn butterworth_lowpass(cutoff_hz: f64, sample_rate_hz: f64) -> Biquad {
    butterworth_from_k((PI * cutoff_hz / sample_rate_hz).tan())
}

/// The 2nd-order Butterworth low-pass that, run forward and then backward, is −3 dB at
/// `cutoff_hz`. The pair's power response is `1/(1 + (t/k)⁴)²` with `t = tan(π f/fs)`, which is
/// ½ at the cutoff when `k = tan(π·cutoff/fs) / (√2 − 1)^¼` (a corner about 1.25× the cutoff's).
#[must_use]
pub fn zero_phase_lowpass(cutoff_hz: f64, sample_rate_hz: f64) -> Biquad {
    let t = (PI * cutoff_hz / sample_rate_hz).tan();
    butterworth_from_k(t / (SQRT_2 - 1.0).powf(0.25))
}

/// The 2nd-order Butterworth low-pass of bilinear constant `k = tan(π·corner/fs)`.
fn butterworth_from_k(k: f64) -> Biquad {
    let k2 = k * k;
    let norm = 1.0 / (1.0 + SQRT_2 * k + k2);
    let b0 = k2 * norm;
    Biquad {
        b: [b0, 2.0 * b0, b0],
        a: [2.0 * (k2 - 1.0) * norm, (1.0 - SQRT_2 * k + k2) * norm],
    }
}
