//! The sound of the groups a running reconstruction has finished so far, to listen to while a
//! long one goes on: their signals stitched, short gaps bridged, resampled, filtered and
//! normalised by `pipeline::finish::finish_clip`, as the engine finishes a whole clip.

use std::sync::Arc;

use crate::io::ScanMeta;
use crate::io::wav::Audio;
use crate::pipeline::PipelineParams;
use crate::pipeline::audio_signal::GroupSignal;
use crate::pipeline::finish::finish_clip;
use crate::pipeline::sampling::native_spacing_um;

/// The sound of `signals` (in group order) at the output rate, after the DSP chain, scaled as
/// the engine scales a clip (to `normalize_peak`, or `full_scale_mm_s` to 1).
///
/// # Errors
/// When no group produced a signal yet, or stitching, resampling or the DSP chain fails.
pub fn partial_sound(
    signals: &[Arc<GroupSignal>],
    meta: &ScanMeta,
    params: &PipelineParams,
) -> Result<Audio, String> {
    if signals.is_empty() {
        return Err("no group has sound yet".into());
    }
    let owned: Vec<GroupSignal> = signals.iter().map(|s| (**s).clone()).collect();
    let spacing = native_spacing_um(meta, &params.sound);
    let clip = finish_clip(&owned, spacing, params).map_err(|e| e.to_string())?;
    Ok(Audio {
        sample_rate_hz: clip.sample_rate_hz,
        channels: clip.channels,
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;
    use crate::engine::{ReconstructOptions, reconstruct};
    use crate::job::Job;
    use std::sync::atomic::AtomicBool;

    #[test]
    fn all_groups_so_far_sound_like_the_finished_clip() {
        let dir = tempfile::tempdir().unwrap();
        let cfg = crate::synth::SynthConfig {
            frames_per_group: 7,
            max_groups: Some(3),
            ..crate::synth::SynthConfig::quick_test()
        };
        let sound = crate::synth::tone(440.0, 0.2, 44_100);
        crate::synth::render_scan(&sound, &cfg, dir.path(), Job::unwatched()).unwrap();
        let scan = crate::io::Scan::open(dir.path()).unwrap();
        // The flow method: its group signals are the clip's (the edge methods finish from the
        // border tracks, which partial_sound does not read yet).
        let opts = ReconstructOptions {
            params: crate::pipeline::PipelineParams {
                method: crate::pipeline::Method::Flow,
                ..Default::default()
            },
            ..ReconstructOptions::default()
        };
        let mut signals = Vec::new();
        let rec = reconstruct(
            &scan,
            &opts,
            &mut |p| signals.extend(p.signal.clone()),
            &AtomicBool::new(false),
        )
        .unwrap();
        assert!(signals.len() >= 2);
        let all = partial_sound(&signals, &scan.meta, &opts.params).unwrap();
        assert_eq!(all.sample_rate_hz, rec.audio.sample_rate_hz);
        assert!(
            all.channels == rec.audio.channels,
            "bit for bit the engine's sound"
        );
        let first = partial_sound(&signals[..1], &scan.meta, &opts.params).unwrap();
        assert!(first.len() < all.len() && !first.is_empty());
        assert!(partial_sound(&[], &scan.meta, &opts.params).is_err());
    }
}
