//! Tests of the DSP: Butterworth and EQ responses against their analog curves, the DC blocker, bad params, the FFT, cross-correlation and spectrum against direct sums.

use super::eq::{RIAA_T1_S, RIAA_T2_S, RIAA_T3_S, corner_hz};
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
    let rms = (tail.iter().map(|&v| f64::from(v).powi(2)).sum::<f64>() / tail.len() as f64).sqrt();
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
        let a = PlaybackEq::riaa().analog_gain_db(f);
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
        let a = PlaybackEq::riaa().analog_gain_db(f);
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
    let a500 = PlaybackEq::turnover500().analog_gain_db(500.0);
    let a_hf = PlaybackEq::turnover500().analog_gain_db(20_000.0);
    assert!((a500 - a_hf - 3.0).abs() < 0.1, "{a500} {a_hf}");
    for f in [30.0, 100.0, 250.0, 500.0, 1000.0, 5000.0, 15_000.0] {
        let d = chain_gain_db(&chain, f, FS);
        let a = PlaybackEq::turnover500().analog_gain_db(f);
        assert!((d - a).abs() < 0.05, "{f} Hz: digital {d} analog {a}");
    }
    // +6 dB/octave slope between shelf and turnover: 100 → 200 Hz gains ≈ −5 dB or so.
    let slope = chain_gain_db(&chain, 100.0, FS) - chain_gain_db(&chain, 200.0, FS);
    assert!(slope > 4.0 && slope < 6.1, "{slope}");
}

/// The custom 78 curve with a chart's numbers.
fn custom(turnover_hz: f64, rolloff_db: f64, shelf_hz: f64) -> DspParams {
    DspParams {
        eq_turnover_hz: turnover_hz,
        eq_rolloff_db: rolloff_db,
        eq_shelf_hz: shelf_hz,
        ..only(false, EqCurve::Custom, false)
    }
}

#[test]
fn custom_curve_with_riaas_numbers_is_riaa() {
    // RIAA as a chart states it: 318 µs turnover, 3180 µs shelf, 75 µs roll-off (13.66 dB).
    let t3 = 2.0 * PI * 10_000.0 * RIAA_T3_S;
    let rolloff_db = 10.0 * (1.0 + t3 * t3).log10();
    assert!((rolloff_db - 13.66).abs() < 0.01, "{rolloff_db}");
    let p = custom(corner_hz(RIAA_T2_S), rolloff_db, corner_hz(RIAA_T1_S));
    p.validate().unwrap();
    let curve = p.playback_eq().unwrap();
    let chain = dsp_chain(FS, &p).unwrap();
    let riaa = dsp_chain(FS, &only(false, EqCurve::Riaa, false)).unwrap();
    for f in [
        20.0, 100.0, 500.0, 1000.0, 2122.0, 5000.0, 10_000.0, 20_000.0,
    ] {
        let (a, b) = (
            curve.analog_gain_db(f),
            PlaybackEq::riaa().analog_gain_db(f),
        );
        assert!((a - b).abs() < 1e-9, "analog {f} Hz: {a} vs {b}");
        let (a, b) = (chain_gain_db(&chain, f, FS), chain_gain_db(&riaa, f, FS));
        assert!((a - b).abs() < 1e-6, "digital {f} Hz: {a} vs {b}");
    }
}

#[test]
fn custom_curve_meets_its_chart_numbers() {
    // 300 Hz turnover, −16 dB at 10 kHz, the boost levelling off at 30 Hz.
    let p = custom(300.0, 16.0, 30.0);
    let curve = p.playback_eq().unwrap();
    let flat_top = custom(300.0, 0.0, 30.0).playback_eq().unwrap();
    // The roll-off alone cuts exactly its figure at 10 kHz.
    let cut = 20.0 * (curve.analog_raw(10_000.0) / flat_top.analog_raw(10_000.0)).log10();
    assert!((cut - -16.0).abs() < 1e-9, "{cut}");
    // The bass boost is 3 dB over the curve's middle at the turnover (0.1 dB of that is the
    // shelf a decade below), and 6 dB an octave between shelf and turnover where they lie far
    // apart.
    let middle = flat_top.analog_gain_db(3000.0);
    let boost = flat_top.analog_gain_db(300.0) - middle;
    assert!((boost - 3.0).abs() < 0.1, "{boost}");
    let wide = custom(800.0, 0.0, 10.0).playback_eq().unwrap();
    let octave = wide.analog_gain_db(50.0) - wide.analog_gain_db(100.0);
    assert!((octave - 6.0).abs() < 0.2, "{octave}");
    // The digital chain follows the analog curve (the bilinear transform compresses towards
    // Nyquist, as for RIAA), is 0 dB at 1 kHz, and running it matches its response.
    let chain = dsp_chain(FS, &p).unwrap();
    assert_eq!(chain.len(), 2, "shelf and roll-off");
    for &(f, tol) in &[(20.0, 0.01), (300.0, 0.01), (1000.0, 0.05), (5000.0, 0.6)] {
        let (d, a) = (chain_gain_db(&chain, f, FS), curve.analog_gain_db(f));
        assert!((d - a).abs() < tol, "{f} Hz: digital {d} analog {a}");
        let m = measured_gain_db(&p, f.max(100.0), FS);
        let want = chain_gain_db(&chain, f.max(100.0), FS);
        assert!((m - want).abs() < 0.1, "{f} Hz: ran {m}, response {want}");
    }
    assert!(chain_gain_db(&chain, 1000.0, FS).abs() < 0.05);
    // No roll-off: one section.
    assert_eq!(dsp_chain(FS, &custom(500.0, 0.0, 50.0)).unwrap().len(), 1);
    assert_eq!(
        describe_chain(&p, FilterPhase::Causal),
        "playback EQ 300 Hz turnover, bass shelf 30 Hz, −16 dB at 10 kHz (causal)"
    );
}

#[test]
fn custom_curve_numbers_that_cannot_work_are_named() {
    let key = |r: Result<(), StageError>| match r {
        Err(StageError::InvalidParam { name, problem }) => format!("{name}: {problem}"),
        other => panic!("{other:?}"),
    };
    // The shelf must lie below the turnover.
    let e = key(custom(300.0, 0.0, 300.0).validate());
    assert!(
        e.starts_with("dsp.eq_shelf_hz: 300 Hz must be below"),
        "{e}"
    );
    // Numbers the curve does not read do not matter while another curve is chosen.
    DspParams {
        eq: EqCurve::Riaa,
        ..custom(300.0, 0.0, 300.0)
    }
    .validate()
    .unwrap();
    for (p, name) in [
        (custom(f64::NAN, 0.0, 50.0), "dsp.eq_turnover_hz"),
        (custom(500.0, -1.0, 50.0), "dsp.eq_rolloff_db"),
        (custom(500.0, f64::INFINITY, 50.0), "dsp.eq_rolloff_db"),
        (custom(500.0, 0.0, 0.0), "dsp.eq_shelf_hz"),
    ] {
        let e = key(p.validate());
        assert!(e.starts_with(name), "{e}");
    }
    // Half a dB at 10 kHz puts the roll-off's corner at 28.6 kHz, past 22.05 kHz.
    let e = key(check_chain(FS, &custom(500.0, 0.5, 50.0)));
    assert!(
        e.starts_with(
            "dsp.eq_rolloff_db: 0.5 dB at 10 kHz puts the treble roll-off's corner at 28"
        ),
        "{e}"
    );
    check_chain(96_000.0, &custom(500.0, 0.5, 50.0)).unwrap();
    let e = key(check_chain(800.0, &custom(500.0, 0.0, 50.0)));
    assert!(e.starts_with("dsp.eq_turnover_hz: "), "{e}");
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
fn the_zero_phase_dc_block_kills_dc_without_shifting_the_tone() {
    // A DC offset plus a 500 Hz tone over 1 s: the causal DC block leads the tone by
    // atan(10/500) = 0.02 rad; forward and backward, the phase stays (< 1e-3 rad) and the
    // offset still goes.
    let n = 44_100;
    let w = 2.0 * PI * 500.0 / FS;
    let x: Vec<f32> = (0..n)
        .map(|i| (0.3 + (w * i as f64).sin()) as f32)
        .collect();
    let phase_of = |y: &[f32]| {
        let (mut s, mut c) = (0.0, 0.0);
        for (i, &v) in y.iter().enumerate().take(3 * n / 4).skip(n / 4) {
            s += f64::from(v) * (w * i as f64).sin();
            c += f64::from(v) * (w * i as f64).cos();
        }
        c.atan2(s)
    };
    let params = only(false, EqCurve::Flat, true);
    let mut causal = x.clone();
    apply_dsp(&mut causal, FS, &params).unwrap();
    let mut zero = x.clone();
    apply_dsp_with(&mut zero, FS, &params, FilterPhase::ZeroPhase).unwrap();
    assert!(
        (phase_of(&causal) - 0.02).abs() < 2e-3,
        "{}",
        phase_of(&causal)
    );
    assert!(phase_of(&zero).abs() < 1e-3, "{}", phase_of(&zero));
    let mid = &zero[n / 4..3 * n / 4];
    let mean = mid.iter().map(|&v| f64::from(v)).sum::<f64>() / mid.len() as f64;
    assert!(mean.abs() < 1e-3, "{mean}");
}

/// SNR (dB) of `y` against `reference` after the best gain.
fn snr_db(reference: &[f32], y: &[f32]) -> f64 {
    let dot = |a: &[f32], b: &[f32]| {
        a.iter()
            .zip(b)
            .map(|(&p, &q)| f64::from(p) * f64::from(q))
            .sum::<f64>()
    };
    let gain = dot(reference, y) / dot(y, y);
    let error: f64 = reference
        .iter()
        .zip(y)
        .map(|(&r, &v)| (f64::from(r) - gain * f64::from(v)).powi(2))
        .sum();
    10.0 * (dot(reference, reference) / error).log10()
}

#[test]
fn the_dc_block_starts_in_steady_state_on_a_short_clip_at_any_phase() {
    // Settled on the level alone, the block started off by up to 1/(ωτ) = 0.02 of a 500 Hz
    // tone and kept it as an offset through an 8 ms clip (33.7 dB at the worst of these
    // phases); settled on its steady state, sum term included, 58.7 dB.
    let params = only(false, EqCurve::Flat, true);
    let w = 2.0 * PI * 500.0 / FS;
    for step in 0..8 {
        let phase = f64::from(step) * PI / 4.0;
        let tone: Vec<f32> = (0..347)
            .map(|i| (w * i as f64 + phase).sin() as f32)
            .collect();
        let mut y: Vec<f32> = tone.iter().map(|&v| v + 0.3).collect();
        apply_dsp_with(&mut y, FS, &params, FilterPhase::ZeroPhase).unwrap();
        let snr = snr_db(&tone, &y);
        assert!(snr > 55.0, "phase {phase:.2}: {snr:.1} dB");
    }
    // Causal: 0.1 s of a 500 Hz tone, or a 30 Hz one over 1 s, against the block's response
    // to the same samples after 20 time constants of the tone before them (at the worst
    // phase 76.8 and 41.7 dB; 41.6 and 18.5 settled on the plain mean of one time constant).
    for (f, n, min_db) in [(500.0, 4410, 60.0), (30.0, 44_100, 30.0)] {
        let lead = 20 * 702;
        let w = 2.0 * PI * f / FS;
        for step in 0..8 {
            let phase = f64::from(step) * PI / 4.0;
            let mut long: Vec<f32> = (0..lead + n)
                .map(|i| (0.3 + (w * i as f64 + phase).sin()) as f32)
                .collect();
            let mut clip = long[lead..].to_vec();
            apply_dsp(&mut long, FS, &params).unwrap();
            apply_dsp(&mut clip, FS, &params).unwrap();
            let snr = snr_db(&long[lead..], &clip);
            assert!(snr > min_db, "{f} Hz, phase {phase:.2}: {snr:.1} dB");
        }
    }
}

/// Amplitude gain at `f` of the zero-phase low-pass pair with cutoff `fc`, from its design.
fn zero_phase_gain(f: f64, fc: f64) -> f64 {
    let k = (PI * fc / FS).tan() / (SQRT_2 - 1.0).powf(0.25);
    1.0 / (1.0 + ((PI * f / FS).tan() / k).powi(4))
}

#[test]
fn the_zero_phase_low_pass_is_minus_3db_at_its_cutoff_and_shifts_no_tone() {
    // Tones at 1 kHz, the cutoff and twice it, through the low-pass alone (DC block off).
    // Causal, the 2nd-order Butterworth delays them (its phase at 1 kHz is −0.48 rad, 76 µs,
    // for a 3 kHz corner); forward and backward, none moves, the cutoff is still
    // at −3 dB, and the octave above it falls to 1/(1 + ((t/k)⁴))² in power, t = tan(π f/fs).
    let (fc, n) = (3000.0, 44_100);
    let params = only(true, EqCurve::Flat, false);
    let tone = |f: f64, phase: FilterPhase| {
        let w = 2.0 * PI * f / FS;
        let mut y: Vec<f32> = (0..n).map(|i| (w * i as f64).sin() as f32).collect();
        apply_dsp_with(&mut y, FS, &params, phase).unwrap();
        let (mut s, mut c) = (0.0, 0.0);
        for (i, &v) in y.iter().enumerate().take(3 * n / 4).skip(n / 4) {
            s += f64::from(v) * (w * i as f64).sin();
            c += f64::from(v) * (w * i as f64).cos();
        }
        let m = (n / 2) as f64 / 2.0;
        ((s / m).hypot(c / m), c.atan2(s))
    };
    let (_, causal_phase) = tone(1000.0, FilterPhase::Causal);
    assert!((causal_phase + 0.48).abs() < 0.005, "{causal_phase}");
    for f in [1000.0, fc, 2.0 * fc] {
        let (gain, phase) = tone(f, FilterPhase::ZeroPhase);
        let expected = zero_phase_gain(f, fc);
        assert!(phase.abs() < 1e-3, "{f} Hz: phase {phase}");
        assert!(
            (gain - expected).abs() < 2e-3,
            "{f} Hz: {gain} vs {expected}"
        );
    }
    let (at_fc, _) = tone(fc, FilterPhase::ZeroPhase);
    assert!((at_fc - HALF_POWER).abs() < 2e-3, "{at_fc}");
}

#[test]
fn a_short_clip_keeps_its_ends_through_the_zero_phase_low_pass() {
    // 11 ms of a 2289 Hz tone (a still's clip), whole, ends included, against the tone at the
    // pair's gain: with each pass settled on its first sample alone the ends ring (30 dB);
    // with the odd-reflected padding, 38 dB.
    let (f, n) = (2289.0, 507);
    let params = only(true, EqCurve::Flat, false);
    let x: Vec<f64> = (0..n)
        .map(|i| (2.0 * PI * f * i as f64 / FS + 0.7).sin())
        .collect();
    let mut y: Vec<f32> = x.iter().map(|&v| v as f32).collect();
    apply_dsp_with(&mut y, FS, &params, FilterPhase::ZeroPhase).unwrap();
    let gain = zero_phase_gain(f, 3000.0);
    let (mut signal, mut error) = (0.0, 0.0);
    for (&a, &b) in x.iter().zip(&y) {
        signal += (gain * a).powi(2);
        error += (f64::from(b) - gain * a).powi(2);
    }
    let snr_db = 10.0 * (signal / error).log10();
    assert!(snr_db > 35.0, "{snr_db:.1} dB");
}

#[test]
fn zero_phase_filters_take_clips_of_one_two_and_three_samples() {
    // The padding is cut to what the clip can reflect; a DC level passes unchanged.
    for (n, eq) in (1..=3).flat_map(|n| [(n, EqCurve::Riaa), (n, EqCurve::Flat)]) {
        let mut y = vec![0.25f32; n];
        apply_dsp_with(&mut y, FS, &only(true, eq, false), FilterPhase::ZeroPhase).unwrap();
        assert!(y.iter().all(|v| v.is_finite()), "{n} {eq:?}: {y:?}");
        if eq == EqCurve::Flat {
            assert!(y.iter().all(|v| (v - 0.25).abs() < 1e-6), "{n}: {y:?}");
        }
    }
}

#[test]
fn the_chain_is_described_as_it_runs() {
    let riaa_causal = describe_chain(&only(true, EqCurve::Riaa, false), FilterPhase::Causal);
    assert_eq!(
        riaa_causal,
        "playback EQ RIAA (causal); low-pass 3000 Hz (2nd-order Butterworth, causal: −3 dB at \
         3000 Hz, 12 dB an octave above)"
    );
    let dc_only = describe_chain(&only(false, EqCurve::Flat, true), FilterPhase::ZeroPhase);
    assert_eq!(
        dc_only,
        "DC block 10 Hz (first-order high-pass, forward and backward)"
    );
    let nothing = describe_chain(&only(false, EqCurve::Flat, false), FilterPhase::Causal);
    assert_eq!(nothing, "none");
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
fn lag_cross_correlation_matches_direct_sums() {
    // Signals longer than one block (2^15 points), of unequal lengths, with a lag window that
    // reaches past both ends, read through offsets as evaluate reads them.
    let a: Vec<f32> = (0..70_001)
        .map(|i| ((i * 5 + 1) % 13) as f32 - 6.0)
        .collect();
    let b: Vec<f32> = (0..50_123)
        .map(|i| ((i * 3 + 2) % 7) as f32 - 3.0)
        .collect();
    // Then a window wider than both signals (one block).
    for (a, b, max_lag) in [(&a[..], &b[..], 300usize), (&a[..500], &b[..300], 800)] {
        let c = lag_cross_correlation(a, b, max_lag, |v| f64::from(v) + 0.5, f64::from);
        assert_eq!(c.len(), 2 * max_lag + 1);
        for (j, &got) in c.iter().enumerate() {
            let lag = j as i64 - max_lag as i64;
            let direct: f64 = (0..a.len() as i64)
                .filter(|&i| i + lag >= 0 && i + lag < b.len() as i64)
                .map(|i| (f64::from(a[i as usize]) + 0.5) * f64::from(b[(i + lag) as usize]))
                .sum();
            assert!(
                (got - direct).abs() < 1e-6 * direct.abs().max(1.0),
                "lag {lag}: {got} vs {direct}"
            );
        }
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

#[test]
fn a_corner_past_nyquist_is_refused_for_the_clip_but_never_stops_the_stages() {
    let mut p = crate::pipeline::PipelineParams::default();
    p.dsp.lowpass_hz = 25_000.0;
    assert!(p.validate().is_ok(), "the workbench's stages still run");
    let e = p.validate_for_clip().unwrap_err().to_string();
    assert!(e.contains("dsp.lowpass_hz") && e.contains("22050"), "{e}");
    p.dsp.lowpass_hz = 3000.0;
    p.dsp.dc_block_hz = 30_000.0;
    let e = p.validate_for_clip().unwrap_err().to_string();
    assert!(e.contains("dsp.dc_block_hz"), "{e}");
}
