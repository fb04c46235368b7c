//! Circular cross-correlation and the calibrated magnitude spectrum, by real FFTs (`realfft`).

use realfft::RealFftPlanner;
use realfft::num_complex::Complex;

use super::*;

/// Floor of [`magnitude_spectrum`] levels (dB), so silence is finite.
pub(super) const SPECTRUM_FLOOR_DB: f64 = -300.0;

/// The spectrum of the real signal `x` (bins 0..=n/2, n = `x.len()`, even).
fn real_spectrum(planner: &mut RealFftPlanner<f64>, x: &mut [f64]) -> Vec<Complex<f64>> {
    let fft = planner.plan_fft_forward(x.len());
    let mut spectrum = fft.make_output_vec();
    // The lengths come from the plan, so this cannot fail.
    let _ = fft.process(x, &mut spectrum);
    spectrum
}

/// A forward complex FFT of one length, planned once (`rustfft`) and run on many blocks.
pub struct ComplexFft {
    fft: std::sync::Arc<dyn rustfft::Fft<f64>>,
}

impl ComplexFft {
    /// Plans the transform of `len` samples.
    #[must_use]
    pub fn new(len: usize) -> Self {
        Self {
            fft: rustfft::FftPlanner::<f64>::new().plan_fft_forward(len),
        }
    }

    /// Forward transform of (`re`, `im`) in place (unnormalised, natural order in and out).
    /// Slices of another length than the plan's are left untouched.
    pub fn forward(&self, re: &mut [f64], im: &mut [f64]) {
        let n = self.fft.len();
        if re.len() != n || im.len() != n || n < 2 {
            return;
        }
        let mut buffer: Vec<Complex<f64>> = re
            .iter()
            .zip(im.iter())
            .map(|(&r, &i)| Complex::new(r, i))
            .collect();
        self.fft.process(&mut buffer);
        for ((r, i), c) in re.iter_mut().zip(im.iter_mut()).zip(&buffer) {
            *r = c.re;
            *i = c.im;
        }
    }
}

/// Forward complex FFT in place (unnormalised, natural order in and out), planned for this one
/// call. `re` and `im` must have the same length; otherwise they are left untouched.
pub fn fft_in_place(re: &mut [f64], im: &mut [f64]) {
    ComplexFft::new(re.len()).forward(re, im);
}

/// Smallest FFT of [`lag_cross_correlation`]'s blocks (2^15 points: 256 KiB a buffer).
const MIN_BLOCK_FFT: usize = 1 << 15;

/// Real FFTs of one length `n` and their buffers: `c[m] = Σ_k a[k]·b[(k + m) mod n]`.
struct Correlator {
    forward: std::sync::Arc<dyn realfft::RealToComplex<f64>>,
    inverse: std::sync::Arc<dyn realfft::ComplexToReal<f64>>,
    a: Vec<f64>,
    b: Vec<f64>,
    sa: Vec<Complex<f64>>,
    sb: Vec<Complex<f64>>,
    c: Vec<f64>,
}

impl Correlator {
    fn new(n: usize) -> Self {
        let mut planner = RealFftPlanner::<f64>::new();
        let (forward, inverse) = (planner.plan_fft_forward(n), planner.plan_fft_inverse(n));
        let (sa, sb) = (forward.make_output_vec(), forward.make_output_vec());
        let c = inverse.make_output_vec();
        Self {
            forward,
            inverse,
            a: vec![0.0; n],
            b: vec![0.0; n],
            sa,
            sb,
            c,
        }
    }

    /// The circular cross-correlation of the buffers `a` and `b` as filled, scaled by 1/n.
    fn correlate(&mut self) -> &[f64] {
        let n = self.a.len();
        // The lengths come from the plans, so these cannot fail.
        let _ = self.forward.process(&mut self.a, &mut self.sa);
        let _ = self.forward.process(&mut self.b, &mut self.sb);
        // conj(A)·B, bin by bin; the DC and Nyquist bins of real signals are real.
        for (x, y) in self.sa.iter_mut().zip(&self.sb) {
            *x = x.conj() * y;
        }
        for end in [0, n / 2] {
            if let Some(p) = self.sa.get_mut(end) {
                p.im = 0.0;
            }
        }
        let _ = self.inverse.process(&mut self.sa, &mut self.c);
        #[allow(clippy::cast_precision_loss)] // n ≤ 2^52
        let scale = 1.0 / n as f64;
        for v in &mut self.c {
            *v *= scale;
        }
        &self.c
    }
}

/// `c[j] = Σ_i a(i)·b(i + j − max_lag)` for `j` in `0..=2·max_lag`: the cross-correlation of
/// two real signals over the lags `−max_lag..=max_lag`, where `a(i)` is `value_a(a[i])`,
/// `b(k)` is `value_b(b[k])`, and a sample outside either signal counts as 0.
///
/// Computed block by block of `a` (overlap-save): a block and the stretch of `b` it reaches,
/// `max_lag` either side, go through FFTs of one length of about four times the lag window,
/// so memory stays O(`max_lag`) however long the signals are. A window about as wide as the
/// signals takes one FFT of both whole instead, as this was done for every window before
/// (which held six buffers of the next power of two above both lengths: 1.7 GB to score
/// three minutes of sound with a window of a few samples).
pub(crate) fn lag_cross_correlation(
    a: &[f32],
    b: &[f32],
    max_lag: usize,
    value_a: impl Fn(f32) -> f64,
    value_b: impl Fn(f32) -> f64,
) -> Vec<f64> {
    let lags = 2 * max_lag + 1;
    let mut c = vec![0.0; lags];
    let n = (4 * lags).max(MIN_BLOCK_FFT).next_power_of_two();
    let whole = (a.len() + b.len()).next_power_of_two().max(2);
    if whole <= n {
        // Every lag in (−a.len(), b.len()) lies unaliased at index lag mod `whole`.
        let mut fft = Correlator::new(whole);
        for (dst, &v) in fft.a.iter_mut().zip(a) {
            *dst = value_a(v);
        }
        for (dst, &v) in fft.b.iter_mut().zip(b) {
            *dst = value_b(v);
        }
        let circular = fft.correlate();
        for (lag, out) in (-(max_lag as i128)..).zip(&mut c) {
            if -(a.len() as i128) < lag && lag < b.len() as i128 {
                *out = circular[lag.rem_euclid(whole as i128) as usize];
            }
        }
        return c;
    }
    let block = n - 2 * max_lag;
    let mut fft = Correlator::new(n);
    for start in (0..a.len()).step_by(block) {
        let len = block.min(a.len() - start);
        // b's stretch: b[start − max_lag .. start + len + max_lag], 0 outside b.
        let (b_lo, b_hi) = (
            start.saturating_sub(max_lag),
            (start + len + max_lag).min(b.len()),
        );
        if b_lo >= b_hi {
            continue;
        }
        for (dst, &v) in fft.a.iter_mut().zip(&a[start..start + len]) {
            *dst = value_a(v);
        }
        fft.a[len..].fill(0.0);
        fft.b.fill(0.0);
        // b[k] holds the signal's b[start − max_lag + k].
        let first = b_lo + max_lag - start;
        for (dst, &v) in fft.b[first..].iter_mut().zip(&b[b_lo..b_hi]) {
            *dst = value_b(v);
        }
        // m ≤ 2·max_lag never wraps (len + 2·max_lag ≤ n): lag m − max_lag.
        for (acc, v) in c.iter_mut().zip(fft.correlate()) {
            *acc += v;
        }
    }
    c
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
    let spectrum = real_spectrum(&mut RealFftPlanner::<f64>::new(), &mut re);
    let scale = if window_sum > 0.0 {
        2.0 / window_sum
    } else {
        0.0
    };
    #[allow(clippy::cast_precision_loss)]
    let bin_hz = sample_rate_hz / n as f64;
    spectrum
        .iter()
        .enumerate()
        .map(|(k, bin)| {
            let mag = bin.norm()
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
