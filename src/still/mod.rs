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
use crate::io::wav::{Audio, read_reference_wav};
use crate::pipeline::audio_signal::resample;
use crate::pipeline::eval::{Scores, evaluate};
use crate::pipeline::finish::channels_to_output;
use crate::pipeline::still::{
    GrooveMap, ProfileBuilder, RibbonBuilder, StillAnalysis, StillError, StillParams, StillSetup,
    StillSignal, choose_groove, decode_borders, detect_grooves, outside_image, track_borders,
};
use crate::pipeline::{PipelineParams, StageError};

/// Most grey values read per band of rows.
const BAND_VALUES: usize = 1 << 22;
/// Longest lag searched against a reference, s.
const MAX_EVAL_LAG_SECS: f64 = 0.002;
/// Share of a channel's lines in gaps above which a warning is given.
const GAP_WARNING_SHARE: f64 = 0.05;
/// A groove speed above this (m/s) is said: no disc turns that fast (a 16-inch transcription
/// disc at 78 rpm, 200 mm out, passes at 1.6 m/s), so the rpm or radius was typed wrong.
const MAX_GROOVE_SPEED_M_S: f64 = 3.0;

/// Why a still could not be decoded (every message ends with the file).
#[derive(Debug, thiserror::Error)]
pub enum StillRunError {
    /// The image (or the reference) cannot be read.
    #[error(transparent)]
    Load(#[from] LoadError),
    /// The caller cancelled it.
    #[error("cancelled")]
    Cancelled,
    /// The decoder refused it.
    #[error("{problem}: {}", path.display())]
    Still {
        /// What went wrong (not an error source: the line holds it once).
        problem: StillError,
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

/// What the caller of the still decoder hears back while it runs: the phase and the share of it
/// done; answering `false` cancels the decode ([`StillRunError::Cancelled`]).
pub type StillProgress<'a> = &'a mut dyn FnMut(StillPhase, f64) -> bool;

/// The phases of a still decode, in order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StillPhase {
    /// First pass over the image: the block profiles.
    Profiles,
    /// Second pass: the band around the chosen groove.
    Ribbon,
    /// Border fits, outlier rejection and the sound.
    Decode,
}

impl StillPhase {
    /// What it does, for a progress line.
    #[must_use]
    pub fn describe(self) -> &'static str {
        match self {
            StillPhase::Profiles => "finding the grooves",
            StillPhase::Ribbon => "reading the chosen groove",
            StillPhase::Decode => "fitting the borders",
        }
    }
}

/// Opens the image anew for each pass (a file, or an in-memory image).
pub type OpenStill<'a> = &'a mut dyn FnMut() -> Result<StillReader, LoadError>;

fn feed(
    open: OpenStill<'_>,
    phase: StillPhase,
    progress: StillProgress<'_>,
    read_secs: &mut f64,
    mut push: impl FnMut(&[f32]) -> Result<(), StillError>,
) -> Result<(), StillRunError> {
    let mut reader = open()?;
    let path = reader.path().to_path_buf();
    let rows_per_band = (BAND_VALUES / reader.width().max(1)).max(1);
    let height = reader.height().max(1);
    let mut band = Vec::new();
    loop {
        if !progress(phase, reader.next_row() as f64 / height as f64) {
            return Err(StillRunError::Cancelled);
        }
        let t = Instant::now();
        let got = reader.read_rows(&mut band, rows_per_band)?;
        *read_secs += t.elapsed().as_secs_f64();
        if got == 0 {
            return Ok(());
        }
        push(&band).map_err(|problem| StillRunError::Still {
            problem,
            path: path.clone(),
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
/// Stops at the next band of rows once [`crate::job::interrupted`] is raised (Ctrl-C, when the
/// command line catches it).
///
/// # Errors
/// [`StillRunError`] naming the file: unreadable or oversized images, bad settings, no groove,
/// a groove out of range, an axis that contradicts the image; [`StillRunError::Cancelled`]
/// when interrupted.
pub fn decode_still_file(
    path: &Path,
    setup: &StillSetup,
    groove: Option<usize>,
    params: &PipelineParams,
) -> Result<StillRun, StillRunError> {
    decode_still_file_reporting(path, setup, groove, params, &mut |_, _| {})
}

/// [`decode_still_file`], telling `report` each phase and the share of it done.
///
/// # Errors
/// As [`decode_still_file`].
pub fn decode_still_file_reporting(
    path: &Path,
    setup: &StillSetup,
    groove: Option<usize>,
    params: &PipelineParams,
    report: &mut dyn FnMut(StillPhase, f64),
) -> Result<StillRun, StillRunError> {
    let started = Instant::now();
    let mut open = || StillReader::open(path);
    let interrupted = crate::job::interrupted();
    let mut go_on = |phase: StillPhase, done: f64| {
        report(phase, done);
        !interrupted.load(std::sync::atomic::Ordering::Relaxed)
    };
    let found = find_grooves(&mut open, setup, &params.still, &mut go_on)?;
    let chosen = choose_groove(&found.grooves, groove).map_err(|problem| StillRunError::Still {
        problem,
        path: path.to_path_buf(),
    })?;
    decode_groove(
        &mut open, &found, chosen, setup, params, &mut go_on, started,
    )
}

/// The grooves of a still (the first pass) and what the second pass needs to know of it.
#[derive(Clone, Debug)]
pub struct FoundGrooves {
    /// The grooves, numbered.
    pub grooves: GrooveMap,
    /// Image size (width, height).
    pub image_px: (usize, usize),
    /// The image's name, for messages.
    pub path: PathBuf,
    /// Seconds spent reading the image in the first pass.
    pub read_secs: f64,
}

/// Finds the grooves of the still `open` gives (the first pass over it).
///
/// # Errors
/// [`StillRunError`] naming the image: unreadable, bad settings, no groove, a contradicting axis;
/// [`StillRunError::Cancelled`] when `progress` said stop.
pub fn find_grooves(
    open: OpenStill<'_>,
    setup: &StillSetup,
    params: &StillParams,
    progress: StillProgress<'_>,
) -> Result<FoundGrooves, StillRunError> {
    let (width, height, path) = {
        let r = open()?;
        (r.width(), r.height(), r.path().to_path_buf())
    };
    let wrap = |problem: StillError| StillRunError::Still {
        problem,
        path: path.clone(),
    };
    setup.validate().map_err(|e| wrap(StillError::Param(e)))?;
    let mut read_secs = 0.0;
    let mut profiles = ProfileBuilder::new(width, height, setup.axis, params).map_err(wrap)?;
    feed(
        open,
        StillPhase::Profiles,
        progress,
        &mut read_secs,
        |rows| profiles.push_rows(rows),
    )?;
    let profiles = profiles.finish().map_err(wrap)?;
    let grooves = detect_grooves(&profiles, setup, params).map_err(wrap)?;
    Ok(FoundGrooves {
        grooves,
        image_px: (width, height),
        path,
        read_secs,
    })
}

/// Decodes groove index `chosen` of `found` (the second pass over the still `open` gives),
/// finishing the sound as the engine does; `started` is when the whole decode began.
///
/// # Errors
/// [`StillRunError`] naming the image; [`StillRunError::Cancelled`] when `progress` said stop.
pub fn decode_groove(
    open: OpenStill<'_>,
    found: &FoundGrooves,
    chosen: usize,
    setup: &StillSetup,
    params: &PipelineParams,
    progress: StillProgress<'_>,
    started: Instant,
) -> Result<StillRun, StillRunError> {
    let wrap = |problem: StillError| StillRunError::Still {
        problem,
        path: found.path.clone(),
    };
    let sp = &params.still;
    let track = found.grooves.grooves.get(chosen);
    let number = track.map_or(chosen + 1, |t| t.number);
    // A groove found in under half the image is refused before its ribbon is read (pure
    // noise gives grooves found in 37-48 % of the blocks, a scanned groove 97-100 %).
    if let Some(track) = track
        && 1.0 - track.coverage > sp.max_lost_share
    {
        return Err(wrap(StillError::NotFollowed {
            number,
            lost: format!(
                "it was found in only {:.0} % of the image's {} blocks",
                100.0 * track.coverage,
                track.blocks.len()
            ),
            share: sp.max_lost_share,
        }));
    }
    let (width, height) = found.image_px;
    let mut read_secs = found.read_secs;
    let mut ribbon = RibbonBuilder::new(&found.grooves, chosen, width, height, sp).map_err(wrap)?;
    feed(open, StillPhase::Ribbon, progress, &mut read_secs, |rows| {
        ribbon.push_rows(rows)
    })?;
    let ribbon = ribbon.finish().map_err(wrap)?;
    if !progress(StillPhase::Decode, 0.0) {
        return Err(StillRunError::Cancelled);
    }
    let borders = track_borders(&ribbon, sp);
    if !progress(StillPhase::Decode, 0.8) {
        return Err(StillRunError::Cancelled);
    }
    let signal = decode_borders(&borders, setup, sp).map_err(wrap)?;
    let (audio, gain_per_mm_s) =
        finish_sound(&signal, params).map_err(|e| wrap(StillError::Param(e)))?;
    let mut warnings = Vec::new();
    let vt_m_s = setup.groove_speed_um_s() / 1e6;
    if vt_m_s > MAX_GROOVE_SPEED_M_S {
        warnings.push(format!(
            "the rpm and radius give a groove speed of {vt_m_s:.2} m/s, faster than any disc \
             turns (a 16-inch transcription at 78 rpm: 1.6 m/s), so the {:.2} ms of sound \
             ({} samples) are likely far too short; check them and the pixel size",
            audio.duration_secs() * 1000.0,
            audio.len(),
        ));
    }
    let gain = found.grooves.brightness_gain;
    if gain > 1.0 {
        warnings.push(format!(
            "the still is dim (its bright level is {:.3} of full scale, such as 12 bits stored \
             in 16, or under-exposed): its grey levels were scaled ×{gain:.1} for the border fits",
            crate::pipeline::still::detect::BRIGHT_LEVEL / gain
        ));
    }
    warnings.extend(outside_image_warning(
        &outside_image(&borders.predicted, found.grooves.cross),
        number,
        borders.lines,
        setup,
    ));
    for c in 0..signal.channels.len() {
        let lost: usize = signal
            .gaps
            .iter()
            .filter(|g| g.channel == c)
            .map(|g| g.lines)
            .sum();
        if lost as f64 > sp.max_lost_share * borders.lines as f64 {
            return Err(wrap(StillError::NotFollowed {
                number,
                lost: format!(
                    "{lost} of {} lines of channel {c} had no usable border",
                    borders.lines
                ),
                share: sp.max_lost_share,
            }));
        }
        if lost as f64 > GAP_WARNING_SHARE * borders.lines as f64 {
            warnings.push(format!(
                "{} of {} lines of channel {c} had no usable border and were bridged",
                lost, borders.lines
            ));
        }
    }
    Ok(StillRun {
        analysis: StillAnalysis {
            grooves: found.grooves.clone(),
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

/// The warning for a groove that lies outside the image on the line runs `outside` (of
/// `lines`): where, how much of it, and that it is silent there.
fn outside_image_warning(
    outside: &[std::ops::Range<usize>],
    number: usize,
    lines: usize,
    setup: &StillSetup,
) -> Option<String> {
    let total: usize = outside.iter().map(ExactSizeIterator::len).sum();
    if total == 0 {
        return None;
    }
    let (lines_name, _) = setup.axis.names();
    let runs: Vec<String> = outside
        .iter()
        .map(|r| format!("{}–{}", r.start, r.end - 1))
        .collect();
    Some(format!(
        "groove {number} runs off the image on {lines_name} {} ({total} of {lines}, {:.3} s): \
         its sound there is not in this still and is left silent",
        runs.join(", "),
        total as f64 / setup.native_rate_hz(),
    ))
}

/// Scores each channel of `audio` against `reference` (per channel when both have as many,
/// else mono against mono), the reference resampled to the output rate.
///
/// # Errors
/// [`LoadError`] when the reference cannot be read or resampled.
pub fn score_still(audio: &Audio, reference: &Path) -> Result<Vec<Option<Scores>>, LoadError> {
    score_still_against(audio, &read_reference_wav(reference)?, reference)
}

/// [`score_still`] against a reference already read from `reference`.
///
/// # Errors
/// [`LoadError`] when the reference cannot be resampled.
pub fn score_still_against(
    audio: &Audio,
    refa: &Audio,
    reference: &Path,
) -> Result<Vec<Option<Scores>>, LoadError> {
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
