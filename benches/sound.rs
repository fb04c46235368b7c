//! Benchmarks of the sound stages: stitching one second of groups, resampling, DSP, evaluation and the spectrum.

use std::f64::consts::PI;
use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use groovescope::pipeline::audio_signal::{GroupSignal, resample, stitch};
use groovescope::pipeline::dsp::{DspParams, EqCurve, apply_dsp, magnitude_spectrum};
use groovescope::pipeline::edges::despike::despike;
use groovescope::pipeline::eval::evaluate;

/// Groove speed at 78 rpm, R = 115 mm (mm/s).
const VT_MM_S: f64 = 939.0;
/// Output rate (Hz).
const RATE_HZ: u32 = 44_100;

/// One second of groups: 2000 groups of 24 samples 21.3 µm apart, 460 µm group step.
fn one_second_of_groups() -> Vec<GroupSignal> {
    let wavelength_um = VT_MM_S * 1000.0 / 1000.0;
    (0..2000)
        .map(|k| {
            let start = k as f64 * 460.0 + (k as f64 * 0.618_034).fract() * 21.3;
            let positions_um: Vec<f64> = (0..24).map(|j| start + j as f64 * 21.3).collect();
            GroupSignal::mono_from_fn(k, positions_um, VT_MM_S, |p| {
                (50.0 * (2.0 * PI * p / wavelength_um).sin()) as f32
            })
        })
        .collect()
}

fn tone(n: usize, rate: f64) -> Vec<f32> {
    (0..n)
        .map(|i| (0.5 * (2.0 * PI * 1000.0 * i as f64 / rate).sin()) as f32)
        .collect()
}

fn benches(c: &mut Criterion) {
    let groups = one_second_of_groups();
    let spacing = VT_MM_S * 1000.0 / f64::from(RATE_HZ);
    c.bench_function("stitch 1 s (2000 groups)", |b| {
        b.iter(|| stitch(black_box(&groups), spacing));
    });
    let native = tone(44_714, 44_714.285);
    c.bench_function("resample 1 s 44714->44100", |b| {
        b.iter(|| resample(black_box(&native), 44_714.285, RATE_HZ));
    });
    // A wall's displacement over 1 s (µm: a 1 kHz tone at 50 mm/s), with an outlier in every
    // 500 samples.
    let displacement: Vec<f64> = tone(44_100, f64::from(RATE_HZ))
        .iter()
        .enumerate()
        .map(|(j, &v)| 16.0 * f64::from(v) + if j % 500 == 250 { 0.5 } else { 0.0 })
        .collect();
    c.bench_function("despike 1 s of a wall's displacement", |b| {
        b.iter(|| {
            let mut x = displacement.clone();
            despike(black_box(&mut x), 5.0)
        });
    });
    let audio = tone(44_100, f64::from(RATE_HZ));
    let params = DspParams {
        eq: EqCurve::Riaa,
        ..DspParams::default()
    };
    c.bench_function("apply_dsp 1 s (dc+riaa+lowpass)", |b| {
        b.iter(|| {
            let mut x = audio.clone();
            apply_dsp(black_box(&mut x), f64::from(RATE_HZ), &params)
        });
    });
    let reference = tone(441_000, f64::from(RATE_HZ));
    let recovered: Vec<f32> = reference.iter().map(|v| 0.8 * v).collect();
    c.bench_function("evaluate 10 s, ±4410 lags", |b| {
        b.iter(|| evaluate(black_box(&recovered), &reference, 4410, RATE_HZ));
    });
    c.bench_function("magnitude_spectrum 65536", |b| {
        b.iter(|| magnitude_spectrum(black_box(&reference[..65_536]), f64::from(RATE_HZ)));
    });
}

criterion_group! {
    name = sound;
    config = Criterion::default().sample_size(10);
    targets = benches
}
criterion_main!(sound);
