//! Per-channel tone and crosstalk of a 2-channel WAV (docs/ACCURACY.md, stereo rows), with the measure the still tests use.
//!
//! `cargo run --release --no-default-features --example stereo_crosstalk -- clip.wav [LEFT_HZ RIGHT_HZ]`
//! (defaults 3000 and 800 Hz). Drops 1 ms at each end, finds each channel's dominant frequency
//! (`pipeline::still::measure::dominant_frequency_hz`: trend removed, Hann spectrum, refined
//! within a bin) and gives the level at the other channel's frequency relative to its own
//! (`relative_level_db`).

use std::path::PathBuf;
use std::process::ExitCode;

use groovescope::io::wav::read_wav;
use groovescope::pipeline::still::measure::{dominant_frequency_hz, relative_level_db};

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(path) = args.first().map(PathBuf::from) else {
        eprintln!("usage: stereo_crosstalk clip.wav [LEFT_HZ RIGHT_HZ]");
        return ExitCode::FAILURE;
    };
    let want: Vec<f64> = args.iter().skip(1).filter_map(|a| a.parse().ok()).collect();
    let (want_l, want_r) = match want[..] {
        [l, r] => (l, r),
        _ => (3000.0, 800.0),
    };
    let audio = match read_wav(&path) {
        Ok(a) => a,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::FAILURE;
        }
    };
    let [left, right] = audio.channels.as_slice() else {
        eprintln!(
            "{}: {} channels, not 2",
            path.display(),
            audio.channels.len()
        );
        return ExitCode::FAILURE;
    };
    let rate = f64::from(audio.sample_rate_hz);
    let cut = (rate * 0.001).round() as usize;
    let trim = |x: &[f32]| {
        x.get(cut..x.len().saturating_sub(cut))
            .unwrap_or(&[])
            .to_vec()
    };
    let (l, r) = (trim(left), trim(right));
    let (Some(fl), Some(fr)) = (
        dominant_frequency_hz(&l, rate),
        dominant_frequency_hz(&r, rate),
    ) else {
        eprintln!("{}: too short to measure", path.display());
        return ExitCode::FAILURE;
    };
    println!(
        "left peak {fl:.1} Hz ({:+.2} %), right peak {fr:.1} Hz ({:+.2} %), into left {:.1} dB, into right {:.1} dB",
        (fl / want_l - 1.0) * 100.0,
        (fr / want_r - 1.0) * 100.0,
        relative_level_db(&l, rate, fl, fr),
        relative_level_db(&r, rate, fr, fl),
    );
    ExitCode::SUCCESS
}
