//! The radix-2 FFT, circular cross-correlation and the calibrated magnitude spectrum.

use super::*;

/// Floor of [`magnitude_spectrum`] levels (dB), so silence is finite.
pub(super) const SPECTRUM_FLOOR_DB: f64 = -300.0;
/// Twiddles e^{−2πik/n} for k < n/2 (the largest FFT stage; smaller stages stride through them).
pub(super) fn twiddles(n: usize) -> Vec<(f64, f64)> {
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
pub(super) fn fft_dif(re: &mut [f64], im: &mut [f64], tw: &[(f64, f64)]) {
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
pub(super) fn ifft_dit(re: &mut [f64], im: &mut [f64], tw: &[(f64, f64)]) {
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
pub(super) fn bit_reversed(k: usize, bits: u32) -> usize {
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
