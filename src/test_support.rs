//! Fixtures shared by the unit tests of several modules of the crate.

use std::path::PathBuf;

/// A path named `name` in a fresh temporary folder, which lives as long as the returned guard.
#[allow(clippy::unwrap_used)] // test support: a temporary folder can be made
pub(crate) fn path_in_temp_dir(name: &str) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(name);
    (dir, path)
}

/// A chord of 97 Hz to 5 kHz at 44.1 kHz, `n` samples of it `delay` samples late (a fraction
/// of a sample included): sub-sample alignment tests read their delay back from it.
#[must_use]
pub(crate) fn delayed_chord(n: usize, delay: f64) -> Vec<f32> {
    (0..n)
        .map(|i| {
            let t = (i as f64 - delay) / 44_100.0;
            [
                (97.0, 0.3),
                (440.0, 0.4),
                (1234.5, 0.3),
                (2900.0, 0.2),
                (5000.0, 0.1),
            ]
            .iter()
            .map(|&(f, a)| a * (std::f64::consts::TAU * f * t + f / 1000.0).sin())
            .sum::<f64>() as f32
        })
        .collect()
}
