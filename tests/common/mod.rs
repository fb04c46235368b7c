//! Shared helpers for integration tests: tiny scans on disk and the binary's path.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use groovescope::image::Image;
use groovescope::io::save_grey_png;

/// Minimal valid scan.toml text.
pub const SCAN_TOML: &str = r#"format = 1
[record]
rpm = 78.0
radius_mm = 115.0
cut = "lateral"
[camera]
pixel_pitch_um = 0.39
working_distance_mm = 4.0
[motion]
frame_step_um = 0.78
group_step_um = 4.0
"#;

/// Writes a scan of `groups` groups of `frames` textured frames (`w`×`h`) under `dir`.
pub fn write_scan(dir: &Path, groups: usize, frames: usize, w: usize, h: usize) -> PathBuf {
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(dir.join("scan.toml"), SCAN_TOML).unwrap();
    for g in 0..groups {
        let gd = dir.join(format!("g{g:05}"));
        std::fs::create_dir_all(&gd).unwrap();
        for k in 0..frames {
            let img = Image::from_fn(w, h, |x, y| {
                let xs = x as f32 + 2.0 * k as f32;
                0.5 + 0.2 * (xs * 0.31).sin() * (y as f32 * 0.23).cos()
            });
            save_grey_png(&img, &gd.join(format!("f{k:03}.png")), false, false).unwrap();
        }
    }
    dir.to_path_buf()
}

/// Runs the groovescope binary.
pub fn groovescope(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_groovescope"))
        .args(args)
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .output()
        .unwrap()
}

/// Stderr as text.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}
