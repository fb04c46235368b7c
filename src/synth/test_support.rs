//! Synthetic grooves shared by the unit tests of several modules.

use super::config::SynthConfig;
use super::groove::Groove;
use super::sounds::tone;
use super::still::{StillConfig, StillScene, render_still};
use crate::image::Image;

/// The dual-focus demo camera (cover glass on top) on a narrow 64 × 700 px frame, carrying 10 ms
/// of a 1 kHz tone.
pub(crate) fn narrow_dual_focus_groove() -> Groove {
    let cfg = SynthConfig {
        width_px: 64,
        height_px: 700,
        group_overlap_px: 10,
        ..SynthConfig::dual_focus_demo()
    };
    #[allow(clippy::unwrap_used)] // test support: the demo config is valid
    Groove::new(&tone(1000.0, 0.01, 48_000), &cfg).unwrap()
}

/// The still scene of `cfg` (its own default tones) and its rendered image.
pub(crate) fn still_scene_and_image(cfg: &StillConfig) -> (StillScene, Image) {
    #[allow(clippy::unwrap_used)] // test support: the tests' configs are valid
    let scene = StillScene::new(cfg, None).unwrap();
    let image = render_still(&scene).image;
    (scene, image)
}
