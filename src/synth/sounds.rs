//! Built-in test sounds: tones, sweeps, chords and melodies (mono), and a stereo pairing helper.

use crate::io::wav::Audio;

/// Sample rate of the built-in sounds (`synth --tone/--sweep/--melody`, the accuracy suite).
pub const BUILTIN_RATE_HZ: u32 = 48_000;
/// Peak level of the built-in sounds (leaves headroom in the WAV range).
const LEVEL: f64 = 0.5;
/// Fade-in/out of each melody note, seconds (avoids clicks).
const NOTE_FADE_SECS: f64 = 0.005;

fn samples(duration_secs: f64, rate_hz: u32) -> usize {
    if duration_secs.is_finite() && duration_secs > 0.0 {
        (duration_secs * f64::from(rate_hz)).round() as usize
    } else {
        0
    }
}

fn mono(rate_hz: u32, data: Vec<f64>) -> Audio {
    Audio {
        sample_rate_hz: rate_hz,
        channels: vec![data.into_iter().map(|v| v as f32).collect()],
    }
}

/// A sine of `freq_hz` lasting `duration_secs` at `rate_hz`, peak 0.5, starting at phase 0.
/// A non-positive or NaN duration gives an empty sound.
#[must_use]
pub fn tone(freq_hz: f64, duration_secs: f64, rate_hz: u32) -> Audio {
    chord(&[freq_hz], duration_secs, rate_hz)
}

/// An exponential sine sweep from `f0_hz` to `f1_hz` (linear when either is not positive).
#[must_use]
pub fn sweep(f0_hz: f64, f1_hz: f64, duration_secs: f64, rate_hz: u32) -> Audio {
    let n = samples(duration_secs, rate_hz);
    let rate = f64::from(rate_hz);
    let tau = std::f64::consts::TAU;
    let data = (0..n)
        .map(|i| {
            let t = i as f64 / rate;
            let phase = if f0_hz > 0.0 && f1_hz > 0.0 && (f1_hz - f0_hz).abs() > 1e-9 {
                let k = (f1_hz / f0_hz).ln() / duration_secs;
                tau * f0_hz * ((k * t).exp() - 1.0) / k
            } else {
                tau * (f0_hz * t + 0.5 * (f1_hz - f0_hz) / duration_secs * t * t)
            };
            LEVEL * phase.sin()
        })
        .collect();
    mono(rate_hz, data)
}

/// Equal-level sines of `freqs_hz` summed, peak at most 0.5.
#[must_use]
pub fn chord(freqs_hz: &[f64], duration_secs: f64, rate_hz: u32) -> Audio {
    let n = samples(duration_secs, rate_hz);
    let rate = f64::from(rate_hz);
    let gain = LEVEL / freqs_hz.len().max(1) as f64;
    let data = (0..n)
        .map(|i| {
            let t = i as f64 / rate;
            freqs_hz
                .iter()
                .map(|f| (std::f64::consts::TAU * f * t).sin())
                .sum::<f64>()
                * gain
        })
        .collect();
    mono(rate_hz, data)
}

/// Notes `(freq_hz, duration_secs)` one after another, each faded in and out over 5 ms.
/// A frequency of 0 is a rest.
#[must_use]
pub fn melody(notes: &[(f64, f64)], rate_hz: u32) -> Audio {
    let rate = f64::from(rate_hz);
    let mut data = Vec::new();
    for &(f, d) in notes {
        let n = samples(d, rate_hz);
        let fade = (NOTE_FADE_SECS * rate).max(1.0);
        for i in 0..n {
            let t = i as f64 / rate;
            let edge = (i as f64).min((n - 1 - i) as f64);
            let env = if edge < fade {
                0.5 - 0.5 * (std::f64::consts::PI * edge / fade).cos()
            } else {
                1.0
            };
            data.push(LEVEL * env * (std::f64::consts::TAU * f * t).sin());
        }
    }
    mono(rate_hz, data)
}

/// The built-in melody: C5 E5 G5 C6, `note_secs` each.
#[must_use]
pub fn arpeggio(note_secs: f64, rate_hz: u32) -> Audio {
    melody(
        &[
            (523.25, note_secs),
            (659.25, note_secs),
            (783.99, note_secs),
            (1046.5, note_secs),
        ],
        rate_hz,
    )
}

/// A stereo sound from two mono ones (first channel of each; the shorter is padded with silence).
#[must_use]
pub fn stereo(left: &Audio, right: &Audio) -> Audio {
    let l = left.channels.first().cloned().unwrap_or_default();
    let r = right.channels.first().cloned().unwrap_or_default();
    let n = l.len().max(r.len());
    let pad = |mut c: Vec<f32>| {
        c.resize(n, 0.0);
        c
    };
    Audio {
        sample_rate_hz: left.sample_rate_hz,
        channels: vec![pad(l), pad(r)],
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;

    fn zero_crossings(a: &Audio) -> usize {
        a.channels[0]
            .windows(2)
            .filter(|w| (w[0] < 0.0) != (w[1] < 0.0))
            .count()
    }

    #[test]
    fn tone_has_its_frequency_and_level() {
        let a = tone(1000.0, 0.1, 48_000);
        assert_eq!(a.len(), 4800);
        let zc = zero_crossings(&a);
        assert!((199..=201).contains(&zc), "{zc}");
        let peak = a.channels[0].iter().fold(0.0f32, |m, v| m.max(v.abs()));
        assert!((peak - 0.5).abs() < 1e-3);
        assert!(tone(1000.0, -1.0, 48_000).is_empty());
    }

    #[test]
    fn sweep_rises_and_melody_concatenates() {
        let s = sweep(100.0, 2000.0, 1.0, 48_000);
        let first = Audio {
            sample_rate_hz: 48_000,
            channels: vec![s.channels[0][..24_000].to_vec()],
        };
        let second = Audio {
            sample_rate_hz: 48_000,
            channels: vec![s.channels[0][24_000..].to_vec()],
        };
        assert!(zero_crossings(&second) > 3 * zero_crossings(&first));
        let m = melody(&[(440.0, 0.1), (0.0, 0.05), (660.0, 0.1)], 8000);
        assert_eq!(m.len(), 2000);
        assert!(m.channels[0][0].abs() < 1e-6, "faded in");
        let st = stereo(&tone(100.0, 0.1, 8000), &tone(200.0, 0.05, 8000));
        assert_eq!(st.channels.len(), 2);
        assert_eq!(st.channels[1].len(), 800);
        assert!((chord(&[100.0, 150.0], 0.1, 8000).channels[0][3]).abs() <= 0.5);
    }
}
