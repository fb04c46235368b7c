//! Measuring a decoded tone: its dominant frequency (to a small fraction of a DFT bin, for
//! clips of a few cycles) and the level of a given frequency, for tests and accuracy reports.

use crate::pipeline::dsp::magnitude_spectrum;

/// Golden-section steps refining the peak.
const REFINE_STEPS: usize = 60;

/// `x` with its least-squares line removed and a Hann window applied.
fn prepared(x: &[f32]) -> Vec<f64> {
    let n = x.len() as f64;
    let val = |v: f32| if v.is_finite() { f64::from(v) } else { 0.0 };
    let (mi, mv) = x.iter().enumerate().fold((0.0, 0.0), |(a, b), (i, &v)| {
        (a + i as f64 / n, b + val(v) / n)
    });
    let (sxy, sxx) = x.iter().enumerate().fold((0.0, 0.0), |(a, b), (i, &v)| {
        (
            a + (i as f64 - mi) * (val(v) - mv),
            b + (i as f64 - mi).powi(2),
        )
    });
    let slope = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    x.iter()
        .enumerate()
        .map(|(i, &v)| {
            let w = 0.5 - 0.5 * (std::f64::consts::TAU * i as f64 / n).cos();
            (val(v) - mv - slope * (i as f64 - mi)) * w
        })
        .collect()
}

/// Power of the prepared signal `y` at `f_hz` (a direct DFT).
fn power(y: &[f64], rate_hz: f64, f_hz: f64) -> f64 {
    let (mut re, mut im) = (0.0, 0.0);
    let w = std::f64::consts::TAU * f_hz / rate_hz;
    for (i, v) in y.iter().enumerate() {
        let (s, c) = (w * i as f64).sin_cos();
        re += v * c;
        im += v * s;
    }
    re * re + im * im
}

/// The dominant frequency of `x` sampled at `rate_hz`, linear trend removed: the largest bin of
/// its Hann spectrum, refined by a golden-section search of the DFT power within a bin of it.
/// `None` for fewer than 8 samples or a non-positive rate.
#[must_use]
pub fn dominant_frequency_hz(x: &[f32], rate_hz: f64) -> Option<f64> {
    if x.len() < 8 || !(rate_hz.is_finite() && rate_hz > 0.0) {
        return None;
    }
    let y = prepared(x);
    let spectrum = magnitude_spectrum(&y.iter().map(|&v| v as f32).collect::<Vec<_>>(), rate_hz);
    let bin = spectrum.get(1).map_or(rate_hz, |b| b.0);
    let (peak, _) = spectrum
        .iter()
        .skip(1)
        .copied()
        .max_by(|a, b| a.1.total_cmp(&b.1))?;
    let (mut a, mut b) = ((peak - bin).max(0.0), peak + bin);
    for _ in 0..REFINE_STEPS {
        let m1 = a + 0.382 * (b - a);
        let m2 = a + 0.618 * (b - a);
        if power(&y, rate_hz, m1) > power(&y, rate_hz, m2) {
            b = m2;
        } else {
            a = m1;
        }
    }
    Some(0.5 * (a + b))
}

/// Level (dB) of the component at `other_hz` relative to the one at `own_hz` in `x`.
#[must_use]
pub fn relative_level_db(x: &[f32], rate_hz: f64, own_hz: f64, other_hz: f64) -> f64 {
    let y = prepared(x);
    10.0 * (power(&y, rate_hz, other_hz) / power(&y, rate_hz, own_hz).max(f64::MIN_POSITIVE))
        .log10()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_few_cycles_give_their_frequency() {
        let rate = 44_100.0;
        // 4.3 cycles of 1234 Hz on a ramp, plus a tone 30 dB down.
        let x: Vec<f32> = (0..154)
            .map(|i| {
                let t = i as f64 / rate;
                ((std::f64::consts::TAU * 1234.0 * t).sin()
                    + 0.0316 * (std::f64::consts::TAU * 3100.0 * t).sin()
                    + 20.0 * t) as f32
            })
            .collect();
        let f = dominant_frequency_hz(&x, rate).unwrap();
        assert!((f / 1234.0 - 1.0).abs() < 0.01, "{f}");
        let long: Vec<f32> = (0..8192)
            .map(|i| (std::f64::consts::TAU * 1234.0 * i as f64 / rate).sin() as f32)
            .collect();
        let f = dominant_frequency_hz(&long, rate).unwrap();
        assert!((f / 1234.0 - 1.0).abs() < 1e-4, "{f}");
        let db = relative_level_db(&x, rate, 1234.0, 3100.0);
        assert!((db + 30.0).abs() < 3.0, "{db}");
        assert!(dominant_frequency_hz(&x[..4], rate).is_none());
    }
}
