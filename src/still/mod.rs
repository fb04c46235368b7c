//! Still images of records on the command line: the `synth-still` generator front end and the
//! `still` decoder — the image file streamed twice through the pure decoder in
//! [`crate::pipeline::still`], then resampled, filtered and normalised as the engine does.

pub mod cli;
pub mod demo;

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::Serialize;

use crate::io::LoadError;
use crate::io::still::StillReader;
use crate::io::wav::{Audio, read_wav};
use crate::pipeline::audio_signal::resample;
use crate::pipeline::eval::{Scores, evaluate};
use crate::pipeline::finish::channels_to_output;
use crate::pipeline::still::{
    ProfileBuilder, RibbonBuilder, StillAnalysis, StillError, StillSetup, StillSignal,
    choose_groove, decode_borders, detect_grooves, track_borders,
};
use crate::pipeline::{PipelineParams, StageError};

/// Most grey values read per band of rows.
const BAND_VALUES: usize = 1 << 22;
/// Longest lag searched against a reference, s.
const MAX_EVAL_LAG_SECS: f64 = 0.002;
/// Share of a channel's lines in gaps above which a warning is given.
const GAP_WARNING_SHARE: f64 = 0.05;

/// Why a still could not be decoded (every message ends with the file).
#[derive(Debug, thiserror::Error)]
pub enum StillRunError {
    /// The image (or the reference) cannot be read.
    #[error(transparent)]
    Load(#[from] LoadError),
    /// The decoder refused it.
    #[error("{source}: {}", path.display())]
    Still {
        /// What went wrong.
        source: StillError,
        /// The image.
        path: PathBuf,
    },
}

/// A decoded still.
#[derive(Clone, Debug)]
pub struct StillRun {
    /// What the decoder found.
    pub analysis: StillAnalysis,
    /// The finished sound (resampled, filtered, normalised).
    pub audio: Audio,
    /// Output units per mm/s of velocity.
    pub gain_per_mm_s: f64,
    /// Image size (width, height).
    pub image_px: (usize, usize),
    /// Seconds spent reading the image (both passes) and in all.
    pub timings: StillTimings,
    /// Non-fatal problems.
    pub warnings: Vec<String>,
}

/// Where the time went.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct StillTimings {
    /// Reading and converting the image's rows (both passes).
    pub read_secs: f64,
    /// Everything.
    pub total_secs: f64,
}

fn feed(
    path: &Path,
    read_secs: &mut f64,
    mut push: impl FnMut(&[f32]) -> Result<(), StillError>,
) -> Result<(), StillRunError> {
    let mut reader = StillReader::open(path)?;
    let rows_per_band = (BAND_VALUES / reader.width()).max(1);
    let mut band = Vec::new();
    loop {
        let t = Instant::now();
        let got = reader.read_rows(&mut band, rows_per_band)?;
        *read_secs += t.elapsed().as_secs_f64();
        if got == 0 {
            return Ok(());
        }
        push(&band).map_err(|source| StillRunError::Still {
            source,
            path: path.to_path_buf(),
        })?;
    }
}

/// Resamples, filters (DC block, EQ, low-pass) and normalises a still's signal as the engine
/// finishes a scan's; returns the sound and the gain per mm/s.
///
/// # Errors
/// [`StageError`] for an unusable rate or filter setting.
pub fn finish_sound(
    signal: &StillSignal,
    params: &PipelineParams,
) -> Result<(Audio, f64), StageError> {
    let (channels, gain) = channels_to_output(&signal.channels, signal.native_rate_hz, params)?;
    Ok((
        Audio {
            sample_rate_hz: params.sound.output_rate_hz,
            channels,
        },
        gain,
    ))
}

/// Decodes groove `groove` (1-based; `None`: the most complete near the centre) of the still
/// at `path`, reading the file twice in bands of rows.
///
/// # Errors
/// [`StillRunError`] naming the file: unreadable or oversized images, bad settings, no groove,
/// a groove out of range, an axis that contradicts the image.
pub fn decode_still_file(
    path: &Path,
    setup: &StillSetup,
    groove: Option<usize>,
    params: &PipelineParams,
) -> Result<StillRun, StillRunError> {
    let started = Instant::now();
    let wrap = |source: StillError| StillRunError::Still {
        source,
        path: path.to_path_buf(),
    };
    let sp = &params.still;
    let (width, height) = {
        let r = StillReader::open(path)?;
        (r.width(), r.height())
    };
    let mut read_secs = 0.0;
    let mut profiles = ProfileBuilder::new(width, height, setup.axis, sp).map_err(wrap)?;
    feed(path, &mut read_secs, |rows| profiles.push_rows(rows))?;
    let profiles = profiles.finish().map_err(wrap)?;
    let grooves = detect_grooves(&profiles, setup, sp).map_err(wrap)?;
    let chosen = choose_groove(&grooves, groove).map_err(wrap)?;
    let mut ribbon = RibbonBuilder::new(&grooves, chosen, width, height, sp).map_err(wrap)?;
    feed(path, &mut read_secs, |rows| ribbon.push_rows(rows))?;
    let ribbon = ribbon.finish().map_err(wrap)?;
    let borders = track_borders(&ribbon, sp);
    let signal = decode_borders(&borders, setup, sp).map_err(wrap)?;
    let (audio, gain_per_mm_s) =
        finish_sound(&signal, params).map_err(|e| wrap(StillError::Param(e)))?;
    let mut warnings = Vec::new();
    for c in 0..signal.channels.len() {
        let lost: usize = signal
            .gaps
            .iter()
            .filter(|g| g.channel == c)
            .map(|g| g.lines)
            .sum();
        if lost as f64 > GAP_WARNING_SHARE * borders.lines as f64 {
            warnings.push(format!(
                "{} of {} lines of channel {c} had no usable border and were bridged",
                lost, borders.lines
            ));
        }
    }
    Ok(StillRun {
        analysis: StillAnalysis {
            grooves,
            chosen,
            borders,
            signal,
        },
        audio,
        gain_per_mm_s,
        image_px: (width, height),
        timings: StillTimings {
            read_secs,
            total_secs: started.elapsed().as_secs_f64(),
        },
        warnings,
    })
}

/// Scores each channel of `audio` against `reference` (per channel when both have as many,
/// else mono against mono), the reference resampled to the output rate.
///
/// # Errors
/// [`LoadError`] when the reference cannot be read or resampled.
pub fn score_still(audio: &Audio, reference: &Path) -> Result<Vec<Option<Scores>>, LoadError> {
    let refa = read_wav(reference)?;
    let rate = audio.sample_rate_hz;
    let to_rate = |c: &[f32]| -> Result<Vec<f32>, LoadError> {
        if refa.sample_rate_hz == rate {
            Ok(c.to_vec())
        } else {
            resample(c, f64::from(refa.sample_rate_hz), rate).map_err(|e| LoadError::Sound {
                problem: format!("cannot resample the reference: {e}"),
                path: reference.to_path_buf(),
            })
        }
    };
    let max_lag = (MAX_EVAL_LAG_SECS * f64::from(rate)) as usize;
    if audio.channels.len() > 1 && refa.channels.len() == audio.channels.len() {
        audio
            .channels
            .iter()
            .zip(&refa.channels)
            .map(|(a, r)| Ok(evaluate(a, &to_rate(r)?, max_lag, rate)))
            .collect()
    } else {
        Ok(vec![evaluate(
            &audio.mono(),
            &to_rate(&refa.mono())?,
            max_lag,
            rate,
        )])
    }
}
