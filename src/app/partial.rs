//! The sound of the groups a running reconstruction has finished so far, to listen to while a
//! long one goes on: their signals stitched, short gaps bridged, resampled, filtered and
//! normalised as the engine finishes a whole clip.
//!
//! The steps are the engine's; once the clip finishing is one pipeline function (issue 16,
//! item 6: `pipeline::finish::finish_clip`), this calls it instead.

use std::sync::Arc;

use crate::engine::bridge_short_gaps;
use crate::io::ScanMeta;
use crate::io::wav::Audio;
use crate::pipeline::PipelineParams;
use crate::pipeline::audio_signal::{GroupSignal, resample, stitch};
use crate::pipeline::dsp::apply_dsp;
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
    let mut stitched = stitch(&owned, spacing).map_err(|e| e.to_string())?;
    bridge_short_gaps(&mut stitched);
    let rate = params.sound.output_rate_hz;
    let mut channels = Vec::with_capacity(stitched.channels.len());
    for ch in &stitched.channels {
        let mut y = resample(ch, stitched.native_rate_hz, rate).map_err(|e| e.to_string())?;
        apply_dsp(&mut y, f64::from(rate), &params.dsp).map_err(|e| e.to_string())?;
        channels.push(y);
    }
    let peak =
        channels.iter().flatten().fold(
            0.0_f32,
            |m, v| {
                if v.is_finite() { m.max(v.abs()) } else { m }
            },
        );
    let gain = if params.sound.normalize_peak > 0.0 {
        if peak > 0.0 {
            f64::from(params.sound.normalize_peak / peak)
        } else {
            1.0
        }
    } else {
        1.0 / params.sound.full_scale_mm_s
    };
    for v in channels.iter_mut().flatten() {
        *v = if v.is_finite() {
            (f64::from(*v) * gain) as f32
        } else {
            0.0
        };
    }
    Ok(Audio {
        sample_rate_hz: rate,
        channels,
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;
    use crate::engine::{ReconstructOptions, reconstruct};
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
        crate::synth::render_scan(
            &sound,
            &cfg,
            dir.path(),
            &|_, _| {},
            &AtomicBool::new(false),
        )
        .unwrap();
        let scan = crate::io::Scan::open(dir.path()).unwrap();
        let opts = ReconstructOptions::default();
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
