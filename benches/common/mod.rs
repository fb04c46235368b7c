//! Set-up shared by the benches: one synthetic group rendered to a temporary folder and loaded.

use std::path::Path;
use std::sync::Arc;

use groovescope::io::{Scan, load_group};
use groovescope::job::Job;
use groovescope::pipeline::GroupInput;
use groovescope::synth::{SynthConfig, render_scan, tone};

/// Renders one group of `cfg` (12 frames of 1280×1024 by default), carrying a `tone_hz` tone,
/// into `dir`, and loads it: the scan and its first group as stage input.
pub fn render_group(dir: &Path, cfg: SynthConfig, tone_hz: f64) -> (Scan, GroupInput) {
    let cfg = SynthConfig {
        max_groups: Some(1),
        ..cfg
    };
    render_scan(&tone(tone_hz, 0.05, 44_100), &cfg, dir, Job::unwatched()).expect("synthetic scan");
    let scan = Scan::open(dir).expect("scan");
    let frames = load_group(&scan.groups[0]).expect("frames");
    let input = GroupInput {
        group: 0,
        frames: Arc::new(frames),
        first_frame: 0,
        meta: Arc::new(scan.meta.clone()),
    };
    (scan, input)
}
