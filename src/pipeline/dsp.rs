//! Post-processing DSP: DC block, playback EQ curves for 78s and LPs, 2nd-order Butterworth low-pass, and a spectrum.
//!
//! Every filter is an analog prototype mapped by the bilinear transform. Each first-order
//! section is pre-warped at its own corner (the `(1 + z⁻¹)` factors of numerator and denominator
//! cancel, so every corner can carry its own warp constant), which puts every corner frequency
//! exactly where the analog curve has it. The price is the bilinear transform's compression
//! near Nyquist: a first-order roll-off of the digital curve falls below the analog one there
//! (RIAA at 44.1 kHz: 0.004 dB off at 1 kHz, −0.05 dB at 3 kHz, −0.27 dB at 5 kHz, −1.6 dB at
//! 10 kHz; the 500 Hz turnover curve has no treble pole and stays within 0.01 dB everywhere).

use std::f64::consts::{PI, SQRT_2};

use serde::{Deserialize, Serialize};

use super::{StageError, check_range};

/// RIAA time constants (s): bass shelf pole, turnover zero, treble pole.
const RIAA_T1_S: f64 = 3180e-6;
/// RIAA turnover zero (s).
const RIAA_T2_S: f64 = 318e-6;
/// RIAA treble roll-off pole (s).
const RIAA_T3_S: f64 = 75e-6;
/// Bass turnover of the [`EqCurve::Turnover500`] curve (Hz).
const TURNOVER500_HZ: f64 = 500.0;
/// The turnover curve's boost stops a decade below the turnover (50 Hz), like RIAA's 3180 µs
/// shelf: a pure constant-amplitude bass would need infinite gain at DC.
const TURNOVER500_SHELF_HZ: f64 = 50.0;
/// Frequency at which every EQ curve has 0 dB gain.
const EQ_REFERENCE_HZ: f64 = 1000.0;
/// Floor of [`magnitude_spectrum`] levels (dB), so silence is finite.
const SPECTRUM_FLOOR_DB: f64 = -300.0;

/// Playback equalisation curve.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum EqCurve {
    /// No EQ: the output is groove velocity.
    #[default]
    Flat,
    /// RIAA playback de-emphasis (3180/318/75 µs), 0 dB at 1 kHz.
    Riaa,
    /// A common 78 rpm curve: 500 Hz turnover, no treble roll-off, 0 dB at 1 kHz. The bass
    /// boost (+6 dB/octave below 500 Hz) levels off at 50 Hz so DC gain stays finite.
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
    /// Apply a first-order DC-blocking high-pass first (per-group tilt bias becomes DC).
    pub dc_block: bool,
    /// Its −3 dB corner (Hz).
    pub dc_block_hz: f64,
}

impl Default for DspParams {
    fn default() -> Self {
        Self {
            lowpass: true,
            lowpass_hz: 3000.0,
            eq: EqCurve::Flat,
            dc_block: true,
            dc_block_hz: 10.0,
        }
    }
}

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
    const IDENTITY: Self = Self {
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
    fn scaled(mut self, k: f64) -> Self {
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
        let [b0, b1, b2] = self.b;
        let [a1, a2] = self.a;
        let den = 1.0 + a1 + a2;
        let dc_gain = if den.abs() > f64::EPSILON {
            (b0 + b1 + b2) / den
        } else {
            0.0
        };
        let y0 = dc_gain * x0;
        let mut s2 = b2 * x0 - a2 * y0;
        let mut s1 = b1 * x0 - a1 * y0 + s2;
        for v in samples.iter_mut() {
            let x = f64::from(*v);
            let y = b0 * x + s1;
            s1 = b1 * x - a1 * y + s2;
            s2 = b2 * x - a2 * y;
            #[allow(clippy::cast_possible_truncation)] // audio samples are f32
            {
                *v = y as f32;
            }
        }
    }
}

/// Bilinear constant that maps the analog corner `corner_hz` to the same digital frequency.
fn prewarp(corner_hz: f64, sample_rate_hz: f64) -> f64 {
    let w = 2.0 * PI * corner_hz;
    w / (w / (2.0 * sample_rate_hz)).tan()
}

/// First-order section `(n0 + n1·s) / (d0 + d1·s)` by the bilinear transform, numerator warped
/// with constant `cn` and denominator with `cd` (`s = c·(1 − z⁻¹)/(1 + z⁻¹)`).
fn first_order(n: [f64; 2], cn: f64, d: [f64; 2], cd: f64) -> Biquad {
    let (nb0, nb1) = (n[0] + n[1] * cn, n[0] - n[1] * cn);
    let (da0, da1) = (d[0] + d[1] * cd, d[0] - d[1] * cd);
    Biquad {
        b: [nb0 / da0, nb1 / da0, 0.0],
        a: [da1 / da0, 0.0],
    }
}

/// Pole-zero shelf `(1 + s/ωz) / (1 + s/ωp)` with both corners pre-warped.
fn shelf(zero_hz: f64, pole_hz: f64, sample_rate_hz: f64) -> Biquad {
    first_order(
        [1.0, 1.0 / (2.0 * PI * zero_hz)],
        prewarp(zero_hz, sample_rate_hz),
        [1.0, 1.0 / (2.0 * PI * pole_hz)],
        prewarp(pole_hz, sample_rate_hz),
    )
}

/// First-order low-pass `1 / (1 + s/ωp)`, pre-warped at its corner.
fn first_order_lowpass(pole_hz: f64, sample_rate_hz: f64) -> Biquad {
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
    let k = (PI * cutoff_hz / sample_rate_hz).tan();
    let k2 = k * k;
    let norm = 1.0 / (1.0 + SQRT_2 * k + k2);
    let b0 = k2 * norm;
    Biquad {
        b: [b0, 2.0 * b0, b0],
        a: [2.0 * (k2 - 1.0) * norm, (1.0 - SQRT_2 * k + k2) * norm],
    }
}

/// Corner frequency (Hz) of a time constant (s).
fn corner_hz(tau_s: f64) -> f64 {
    1.0 / (2.0 * PI * tau_s)
}

impl EqCurve {
    /// Analog magnitude (linear, not normalised) of the curve at `freq_hz`.
    fn analog_raw(self, freq_hz: f64) -> f64 {
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
    fn highest_corner_hz(self) -> f64 {
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

/// The whole filter chain of [`apply_dsp`] (DC block, EQ, low-pass) as biquad sections.
///
/// # Errors
/// [`StageError::InvalidParam`] for a NaN or non-positive rate or corner, or a corner not
/// below Nyquist.
pub fn dsp_chain(sample_rate_hz: f64, params: &DspParams) -> Result<Vec<Biquad>, StageError> {
    check_range("sample_rate_hz", sample_rate_hz, f64::MIN_POSITIVE, 1e9)?;
    let nyquist_hz = sample_rate_hz / 2.0;
    let below_nyquist = |name: &str, hz: f64| -> Result<(), StageError> {
        if hz.is_finite() && hz > 0.0 && hz < nyquist_hz {
            Ok(())
        } else {
            Err(StageError::InvalidParam {
                name: name.to_string(),
                problem: format!("{hz} Hz is not in (0, Nyquist = {nyquist_hz} Hz)"),
            })
        }
    };
    let mut chain = Vec::new();
    if params.dc_block {
        below_nyquist("dsp.dc_block_hz", params.dc_block_hz)?;
        chain.push(dc_blocker(params.dc_block_hz, sample_rate_hz));
    }
    if params.eq != EqCurve::Flat {
        let corner = params.eq.highest_corner_hz();
        if corner >= nyquist_hz {
            return Err(StageError::InvalidParam {
                name: "dsp.eq".to_string(),
                problem: format!(
                    "{:?} needs a sample rate above {} Hz, got {sample_rate_hz} Hz",
                    params.eq,
                    2.0 * corner
                ),
            });
        }
        chain.extend(params.eq.sections(sample_rate_hz));
    }
    if params.lowpass {
        below_nyquist("dsp.lowpass_hz", params.lowpass_hz)?;
        chain.push(butterworth_lowpass(params.lowpass_hz, sample_rate_hz));
    }
    if chain.is_empty() {
        chain.push(Biquad::IDENTITY);
    }
    Ok(chain)
}

/// Applies the DC block, EQ and the low-pass (in that order) to one channel in place.
/// Non-finite samples are replaced by 0 first (an IIR filter would spread them forever).
///
/// # Errors
/// [`StageError`] when the cutoff is not below Nyquist or not positive, or any rate or corner
/// is NaN.
pub fn apply_dsp(
    samples: &mut [f32],
    sample_rate_hz: f64,
    params: &DspParams,
) -> Result<(), StageError> {
    let chain = dsp_chain(sample_rate_hz, params)?;
    if samples.is_empty() {
        return Ok(());
    }
    for v in samples.iter_mut() {
        if !v.is_finite() {
            *v = 0.0;
        }
    }
    for (i, section) in chain.iter().enumerate() {
        if i == 0 && params.dc_block {
            // Start the DC block settled on the mean level of its first time constant, not
            // on the first sample (which carries signal): otherwise the difference decays
            // through the clip as a slow drift, which dominates the error of a short clip.
            // (dsp_chain puts the DC block first when it is on.)
            let tau = (sample_rate_hz / (2.0 * PI * params.dc_block_hz)).ceil() as usize;
            let head = &samples[..tau.clamp(1, samples.len())];
            let level = head.iter().map(|&v| f64::from(v)).sum::<f64>() / head.len() as f64;
            section.run_settled(samples, level);
        } else {
            section.run(samples);
        }
    }
    Ok(())
}

/// Twiddles e^{−2πik/n} for k < n/2 (the largest FFT stage; smaller stages stride through them).
fn twiddles(n: usize) -> Vec<(f64, f64)> {
    (0..n / 2)
        .map(|k| {
            #[allow(clippy::cast_precision_loss)] // k, n ≤ 2^52
            let angle = -2.0 * PI * k as f64 / n as f64;
            let (s, c) = angle.sin_cos();
            (c, s)
        })
        .collect()
}

/// Forward radix-2 decimation-in-frequency FFT: natural-order input, **bit-reversed** output
/// (no permutation pass: on large arrays the scattered swaps of a bit reversal cost more than
/// all the butterflies). `tw` from [`twiddles`] for this length.
fn fft_dif(re: &mut [f64], im: &mut [f64], tw: &[(f64, f64)]) {
    let n = re.len();
    let mut stage_tw: Vec<(f64, f64)> = Vec::with_capacity(n / 2);
    let mut len = n;
    while len >= 2 {
        let half = len / 2;
        stage_tw.clear();
        stage_tw.extend(tw.iter().step_by(n / len).take(half));
        for (cr, ci) in re.chunks_exact_mut(len).zip(im.chunks_exact_mut(len)) {
            let (ar, br) = cr.split_at_mut(half);
            let (ai, bi) = ci.split_at_mut(half);
            for ((((ar, ai), br), bi), &(wr, wi)) in ar
                .iter_mut()
                .zip(ai.iter_mut())
                .zip(br.iter_mut())
                .zip(bi.iter_mut())
                .zip(&stage_tw)
            {
                let (dr, di) = (*ar - *br, *ai - *bi);
                *ar += *br;
                *ai += *bi;
                *br = dr * wr - di * wi;
                *bi = dr * wi + di * wr;
            }
        }
        len = half;
    }
}

/// Inverse radix-2 decimation-in-time FFT (unnormalised): **bit-reversed** input, natural
/// output; the inverse of [`fft_dif`] up to a factor n.
fn ifft_dit(re: &mut [f64], im: &mut [f64], tw: &[(f64, f64)]) {
    let n = re.len();
    let mut stage_tw: Vec<(f64, f64)> = Vec::with_capacity(n / 2);
    let mut len = 2;
    while len <= n {
        let half = len / 2;
        stage_tw.clear();
        // Conjugate twiddles: e^{+2πik/len}.
        stage_tw.extend(tw.iter().step_by(n / len).take(half).map(|&(c, s)| (c, -s)));
        for (cr, ci) in re.chunks_exact_mut(len).zip(im.chunks_exact_mut(len)) {
            let (ar, br) = cr.split_at_mut(half);
            let (ai, bi) = ci.split_at_mut(half);
            for ((((ar, ai), br), bi), &(wr, wi)) in ar
                .iter_mut()
                .zip(ai.iter_mut())
                .zip(br.iter_mut())
                .zip(bi.iter_mut())
                .zip(&stage_tw)
            {
                let tr = *br * wr - *bi * wi;
                let ti = *br * wi + *bi * wr;
                *br = *ar - tr;
                *bi = *ai - ti;
                *ar += tr;
                *ai += ti;
            }
        }
        len *= 2;
    }
}

/// Index of bin `k` in the bit-reversed output of an FFT of 2^`bits` points.
fn bit_reversed(k: usize, bits: u32) -> usize {
    if bits == 0 {
        0
    } else {
        k.reverse_bits() >> (usize::BITS - bits)
    }
}

/// In-place radix-2 complex FFT (forward, unnormalised, natural order in and out). `re.len()`
/// must be a power of two equal to `im.len()`; other lengths are left untouched.
pub fn fft_in_place(re: &mut [f64], im: &mut [f64]) {
    let n = re.len();
    if n < 2 || !n.is_power_of_two() || im.len() != n {
        return;
    }
    fft_dif(re, im, &twiddles(n));
    let bits = n.trailing_zeros();
    for i in 0..n {
        let j = bit_reversed(i, bits);
        if j > i {
            re.swap(i, j);
            im.swap(i, j);
        }
    }
}

/// Circular cross-correlation c[m] = Σ_i a[i]·b[i + m] (indices mod n) of two real signals
/// zero-padded to n = the next power of two ≥ a.len() + b.len(), so that every lag in
/// (−a.len(), b.len()) appears unaliased at index lag mod n. Returns (c, n).
pub(crate) fn cross_correlation(a: &[f64], b: &[f64]) -> (Vec<f64>, usize) {
    let n = (a.len() + b.len()).next_power_of_two().max(2);
    let tw = twiddles(n);
    let (mut ar, mut ai) = (vec![0.0; n], vec![0.0; n]);
    let (mut br, mut bi) = (vec![0.0; n], vec![0.0; n]);
    ar[..a.len()].copy_from_slice(a);
    br[..b.len()].copy_from_slice(b);
    fft_dif(&mut ar, &mut ai, &tw);
    fft_dif(&mut br, &mut bi, &tw);
    // conj(A)·B, bin by bin (both in the same bit-reversed order).
    for (((xr, xi), &yr), &yi) in ar.iter_mut().zip(ai.iter_mut()).zip(&br).zip(&bi) {
        let (pr, pi) = (*xr * yr + *xi * yi, *xr * yi - *xi * yr);
        *xr = pr;
        *xi = pi;
    }
    ifft_dit(&mut ar, &mut ai, &tw);
    #[allow(clippy::cast_precision_loss)] // n ≤ 2^52
    let scale = 1.0 / n as f64;
    for v in &mut ar {
        *v *= scale;
    }
    (ar, n)
}

/// Magnitude spectrum of `samples` (Hann window, zero-padded to a power of two), as
/// `(frequency Hz, level dB)` for bins 0..=N/2. Levels are amplitude-calibrated: a sine of
/// amplitude A that falls on a bin reads 20·log10(A) dB (floored at −300 dB). Non-finite samples
/// count as 0. Empty input or a non-positive/NaN rate gives an empty spectrum.
#[must_use]
pub fn magnitude_spectrum(samples: &[f32], sample_rate_hz: f64) -> Vec<(f64, f64)> {
    if samples.is_empty() || !(sample_rate_hz.is_finite() && sample_rate_hz > 0.0) {
        return Vec::new();
    }
    let len = samples.len();
    let n = len.next_power_of_two().max(2);
    let mut re = vec![0.0; n];
    let mut im = vec![0.0; n];
    let mut window_sum = 0.0;
    #[allow(clippy::cast_precision_loss)] // lengths ≤ 2^52
    let denom = len as f64;
    for (i, (&x, r)) in samples.iter().zip(re.iter_mut()).enumerate() {
        #[allow(clippy::cast_precision_loss)]
        let w = if len > 1 {
            0.5 - 0.5 * (2.0 * PI * i as f64 / (denom - 1.0)).cos()
        } else {
            1.0
        };
        window_sum += w;
        let v = if x.is_finite() { f64::from(x) } else { 0.0 };
        *r = v * w;
    }
    fft_dif(&mut re, &mut im, &twiddles(n));
    let bits = n.trailing_zeros();
    let scale = if window_sum > 0.0 {
        2.0 / window_sum
    } else {
        0.0
    };
    #[allow(clippy::cast_precision_loss)]
    let bin_hz = sample_rate_hz / n as f64;
    (0..=n / 2)
        .map(|k| {
            let j = bit_reversed(k, bits);
            let mag = (re[j] * re[j] + im[j] * im[j]).sqrt()
                * if k == 0 || k == n / 2 {
                    scale / 2.0
                } else {
                    scale
                };
            let db = if mag > 0.0 {
                (20.0 * mag.log10()).max(SPECTRUM_FLOOR_DB)
            } else {
                SPECTRUM_FLOOR_DB
            };
            #[allow(clippy::cast_precision_loss)]
            (k as f64 * bin_hz, db)
        })
        .collect()
}

/// Gain (dB) at `freq_hz` of a chain of sections.
#[must_use]
pub fn chain_gain_db(chain: &[Biquad], freq_hz: f64, sample_rate_hz: f64) -> f64 {
    chain
        .iter()
        .map(|s| s.gain_db(freq_hz, sample_rate_hz))
        .sum()
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests unwrap known-good results
mod tests {
    use super::*;

    const FS: f64 = 44_100.0;

    /// Amplitude of a unit sine after the section chain, by running it through (used by tests to
    /// check that `run` matches the coefficients' response).
    fn measured_gain_db(params: &DspParams, freq_hz: f64, fs: f64) -> f64 {
        let n = (fs * 2.0) as usize;
        let mut x: Vec<f32> = (0..n)
            .map(|i| (2.0 * PI * freq_hz * i as f64 / fs).sin() as f32)
            .collect();
        apply_dsp(&mut x, fs, params).unwrap();
        // Steady-state amplitude from the second half (RMS·√2).
        let tail = &x[n / 2..];
        let rms =
            (tail.iter().map(|&v| f64::from(v).powi(2)).sum::<f64>() / tail.len() as f64).sqrt();
        20.0 * (rms * SQRT_2).log10()
    }

    const HALF_POWER: f64 = std::f64::consts::FRAC_1_SQRT_2;

    fn only(lowpass: bool, eq: EqCurve, dc_block: bool) -> DspParams {
        DspParams {
            lowpass,
            eq,
            dc_block,
            ..DspParams::default()
        }
    }

    #[test]
    fn butterworth_minus_3db_at_cutoff_and_12db_per_octave() {
        for &(fc, fs) in &[(3000.0, FS), (1000.0, 48_000.0), (8000.0, 22_050.0)] {
            let lp = butterworth_lowpass(fc, fs);
            let at_fc = lp.gain_db(fc, fs);
            assert!(
                (at_fc - 20.0 * HALF_POWER.log10()).abs() < 0.1,
                "{fc}/{fs}: {at_fc}"
            );
            assert!(lp.gain_db(10.0, fs).abs() < 0.01);
            // Analog Butterworth an octave up: −10·log10(1 + 2⁴) = −12.30 dB; the bilinear
            // transform adds attenuation towards Nyquist (zero there), so the digital one is at
            // least that, and close to it when 2·fc is far below Nyquist.
            let oct = lp.gain_db(2.0 * fc, fs);
            if 2.0 * fc < fs / 2.0 {
                assert!(oct < -12.30 + 0.01, "{fc}/{fs}: octave {oct}");
            }
            if 2.0 * fc < fs / 20.0 {
                assert!((oct - -12.30).abs() < 0.1, "{fc}/{fs}: octave {oct}");
            }
        }
        // Digital response at 2·fc matches the analog formula mapped through the pre-warp.
        let (fc, fs) = (3000.0, FS);
        let lp = butterworth_lowpass(fc, fs);
        let warp = |f: f64| (PI * f / fs).tan();
        let ratio = warp(2.0 * fc) / warp(fc);
        let expected = -10.0 * (1.0 + ratio.powi(4)).log10();
        assert!((lp.gain_db(2.0 * fc, fs) - expected).abs() < 1e-9);
    }

    #[test]
    fn running_the_filter_matches_its_response() {
        let p = only(true, EqCurve::Flat, false);
        let got = measured_gain_db(&p, 3000.0, FS);
        assert!((got - -3.0103).abs() < 0.1, "{got}");
        let got = measured_gain_db(&p, 6000.0, FS);
        let expected = butterworth_lowpass(3000.0, FS).gain_db(6000.0, FS);
        assert!((got - expected).abs() < 0.1, "{got} vs {expected}");
        let p = only(false, EqCurve::Riaa, false);
        for f in [100.0, 1000.0, 5000.0] {
            let got = measured_gain_db(&p, f, FS);
            let expected = chain_gain_db(&dsp_chain(FS, &p).unwrap(), f, FS);
            assert!((got - expected).abs() < 0.1, "{f}: {got} vs {expected}");
        }
    }

    #[test]
    fn riaa_follows_the_analog_curve() {
        // Published RIAA playback values (0 dB at 1 kHz).
        for &(f, db) in &[
            (20.0, 19.27),
            (100.0, 13.09),
            (1000.0, 0.0),
            (10_000.0, -13.73),
        ] {
            let a = EqCurve::Riaa.analog_gain_db(f);
            assert!((a - db).abs() < 0.02, "analog {f}: {a} vs {db}");
        }
        let chain = dsp_chain(FS, &only(false, EqCurve::Riaa, false)).unwrap();
        // Tolerances grow with frequency: the bilinear transform compresses towards Nyquist.
        for &(f, tol) in &[
            (20.0, 0.01),
            (100.0, 0.01),
            (500.0, 0.02),
            (1000.0, 0.05),
            (3000.0, 0.25),
            (5000.0, 0.6),
        ] {
            let d = chain_gain_db(&chain, f, FS);
            let a = EqCurve::Riaa.analog_gain_db(f);
            assert!((d - a).abs() < tol, "{f} Hz: digital {d} analog {a}");
        }
        // Corners sit where they should: the treble pole is −3 dB below the shelf's asymptote
        // at 2122 Hz only in the analog sense; check the digital 1 kHz normalisation instead.
        assert!(chain_gain_db(&chain, 1000.0, FS).abs() < 0.05);
    }

    #[test]
    fn turnover500_follows_the_analog_curve() {
        let chain = dsp_chain(FS, &only(false, EqCurve::Turnover500, false)).unwrap();
        // Analog: +3 dB point relative to the HF asymptote at 500 Hz, no treble roll-off.
        let a500 = EqCurve::Turnover500.analog_gain_db(500.0);
        let a_hf = EqCurve::Turnover500.analog_gain_db(20_000.0);
        assert!((a500 - a_hf - 3.0).abs() < 0.1, "{a500} {a_hf}");
        for f in [30.0, 100.0, 250.0, 500.0, 1000.0, 5000.0, 15_000.0] {
            let d = chain_gain_db(&chain, f, FS);
            let a = EqCurve::Turnover500.analog_gain_db(f);
            assert!((d - a).abs() < 0.05, "{f} Hz: digital {d} analog {a}");
        }
        // +6 dB/octave slope between shelf and turnover: 100 → 200 Hz gains ≈ −5 dB or so.
        let slope = chain_gain_db(&chain, 100.0, FS) - chain_gain_db(&chain, 200.0, FS);
        assert!(slope > 4.0 && slope < 6.1, "{slope}");
    }

    #[test]
    fn dc_blocker_kills_dc_and_passes_audio() {
        let hp = dc_blocker(10.0, FS);
        assert!((hp.gain_db(10.0, FS) - -3.0103).abs() < 0.01);
        assert!(hp.gain_db(1000.0, FS).abs() < 0.01);
        // A DC offset plus a tone: the offset is gone after a few time constants.
        let n = 44_100;
        let mut x: Vec<f32> = (0..n)
            .map(|i| 0.5 + 0.1 * (2.0 * PI * 1000.0 * i as f64 / FS).sin() as f32)
            .collect();
        apply_dsp(&mut x, FS, &only(false, EqCurve::Flat, true)).unwrap();
        let tail = &x[n / 2..];
        let mean = tail.iter().map(|&v| f64::from(v)).sum::<f64>() / tail.len() as f64;
        assert!(mean.abs() < 1e-3, "{mean}");
        // Steady-state start: no step transient from the initial offset.
        assert!(x[0].abs() < 5e-3, "{}", x[0]);
    }

    #[test]
    fn dc_block_starts_settled_on_the_mean_level_not_the_first_sample() {
        // An offset tone that starts at its crest: a filter settled on the first sample
        // (0.5 + 0.1) would start 0.1 low and drift back over the first time constant (16 ms).
        let n = 4410;
        let mut x: Vec<f32> = (0..n)
            .map(|i| 0.5 + 0.1 * (2.0 * PI * 1000.0 * i as f64 / FS).cos() as f32)
            .collect();
        apply_dsp(&mut x, FS, &only(false, EqCurve::Flat, true)).unwrap();
        let head = &x[..882];
        let mean = head.iter().map(|&v| f64::from(v)).sum::<f64>() / head.len() as f64;
        assert!(mean.abs() < 0.01, "mean of the first 20 ms: {mean}");
    }

    #[test]
    fn invalid_params_are_rejected() {
        let mut x = vec![0.0f32; 16];
        let bad = |p: DspParams, fs: f64| {
            let mut y = vec![0.0f32; 4];
            apply_dsp(&mut y, fs, &p).is_err()
        };
        assert!(bad(
            DspParams {
                lowpass_hz: 22_050.0,
                ..DspParams::default()
            },
            FS
        ));
        assert!(bad(
            DspParams {
                lowpass_hz: f64::NAN,
                ..DspParams::default()
            },
            FS
        ));
        assert!(bad(
            DspParams {
                lowpass_hz: -1.0,
                ..DspParams::default()
            },
            FS
        ));
        assert!(bad(
            DspParams {
                dc_block_hz: f64::NAN,
                ..DspParams::default()
            },
            FS
        ));
        assert!(bad(DspParams::default(), f64::NAN));
        assert!(bad(DspParams::default(), 0.0));
        assert!(bad(only(false, EqCurve::Riaa, false), 4000.0));
        // A disabled low-pass does not need a valid cutoff.
        let p = DspParams {
            lowpass: false,
            lowpass_hz: f64::NAN,
            ..DspParams::default()
        };
        assert!(apply_dsp(&mut x, FS, &p).is_ok());
    }

    #[test]
    fn filters_stay_finite_on_nan_input() {
        let mut x = vec![1.0f32; 1000];
        x[10] = f32::NAN;
        x[20] = f32::INFINITY;
        apply_dsp(&mut x, FS, &only(true, EqCurve::Riaa, true)).unwrap();
        assert!(x.iter().all(|v| v.is_finite()));
    }

    #[test]
    fn fft_matches_a_direct_dft() {
        let n = 64;
        let sig: Vec<f64> = (0..n).map(|i| ((i * 7 + 3) % 11) as f64 - 5.0).collect();
        let mut re = sig.clone();
        let mut im = vec![0.0; n];
        fft_in_place(&mut re, &mut im);
        for k in 0..n {
            let (mut sr, mut si) = (0.0, 0.0);
            for (i, &x) in sig.iter().enumerate() {
                let a = -2.0 * PI * (k * i) as f64 / n as f64;
                sr += x * a.cos();
                si += x * a.sin();
            }
            assert!(
                (re[k] - sr).abs() < 1e-9 && (im[k] - si).abs() < 1e-9,
                "bin {k}"
            );
        }
    }

    #[test]
    fn cross_correlation_matches_direct_sums() {
        let a: Vec<f64> = (0..37).map(|i| ((i * 5 + 1) % 13) as f64 - 6.0).collect();
        let b: Vec<f64> = (0..50).map(|i| ((i * 3 + 2) % 7) as f64 - 3.0).collect();
        let (c, n) = cross_correlation(&a, &b);
        assert!(n >= a.len() + b.len() && n.is_power_of_two());
        for lag in -(a.len() as i64 - 1)..b.len() as i64 {
            let direct: f64 = (0..a.len() as i64)
                .filter(|&i| i + lag >= 0 && i + lag < b.len() as i64)
                .map(|i| a[i as usize] * b[(i + lag) as usize])
                .sum();
            let idx = lag.rem_euclid(n as i64) as usize;
            assert!(
                (c[idx] - direct).abs() < 1e-9,
                "lag {lag}: {} vs {direct}",
                c[idx]
            );
        }
    }

    #[test]
    fn spectrum_finds_a_tone_at_its_level() {
        let fs = 48_000.0;
        let n = 8192;
        let f0 = 46.0 * fs / n as f64; // on a bin
        let x: Vec<f32> = (0..n)
            .map(|i| (0.25 * (2.0 * PI * f0 * i as f64 / fs).sin()) as f32)
            .collect();
        let spec = magnitude_spectrum(&x, fs);
        assert_eq!(spec.len(), n / 2 + 1);
        let (peak_f, peak_db) = spec
            .iter()
            .copied()
            .fold((0.0, f64::MIN), |a, b| if b.1 > a.1 { b } else { a });
        assert!((peak_f - f0).abs() < 1e-6, "{peak_f} vs {f0}");
        assert!((peak_db - 20.0 * 0.25f64.log10()).abs() < 0.05, "{peak_db}");
        // Far from the tone the Hann leakage is tiny.
        assert!(spec[400].1 < peak_db - 100.0);
        assert!(magnitude_spectrum(&[], fs).is_empty());
        assert!(magnitude_spectrum(&x, f64::NAN).is_empty());
    }
}
