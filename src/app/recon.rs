//! Whole-clip reconstruction on a named background thread, with progress, ETA and cancel, plus
//! the display data of the finished clip (aligned reference, envelopes, spectra).

use std::ops::Range;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use super::health::GroupTrack;
use super::partial::partial_sound;
use super::tuning::ParamState;
use crate::engine::{
    ClipGroups, EngineError, Progress, ReconstructOptions, Reconstruction, aligned_reference,
    finish_scan_clip, run_clip_groups,
};
use crate::io::Scan;
use crate::pipeline::PipelineParams;
use crate::pipeline::audio_signal::GroupSignal;
use crate::pipeline::dsp::magnitude_spectrum;
use crate::pipeline::eval::block_peaks;

/// Longest envelope block (seconds).
pub const ENVELOPE_BLOCK_SECS: f64 = 0.005;
/// Fewest envelope blocks over a clip (short clips get shorter blocks).
pub const ENVELOPE_MIN_BLOCKS: usize = 100;
/// Most points of a displayed spectrum.
pub const SPECTRUM_POINTS: usize = 4096;
/// Most bytes of group signals a clip keeps for a refinish ([`ReconRun::refinish`]). The
/// fused method's hold about 3 MB a second of sound (the accuracy suite's small dual-focus
/// camera: 1.49 MB for its 0.50 s of speech), so a preview clip of up to about 85 s keeps
/// them, and a whole side run in the workbench does not hold its signals twice.
pub const KEEP_GROUPS_MAX_BYTES: usize = 256 << 20;

/// An averaged magnitude spectrum.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Spectrum {
    /// Bin frequencies (Hz).
    pub freqs_hz: Vec<f64>,
    /// Level per bin (dB; a full-scale sine reads 0 dB).
    pub db: Vec<f64>,
}

/// One sound the waveform view draws: its samples, their block peaks and their spectrum.
#[derive(Clone, Debug)]
pub struct Trace {
    /// Mono samples at the clip's rate.
    pub samples: Arc<Vec<f32>>,
    /// Peak |x| per block of [`Clip::envelope_block`] samples.
    pub envelope: Vec<f32>,
    /// Its spectrum.
    pub spectrum: Spectrum,
}

impl Trace {
    /// The trace of `samples` at `rate_hz`, with peaks per `block` samples.
    #[must_use]
    pub fn new(samples: Vec<f32>, block: usize, rate_hz: u32) -> Self {
        Self {
            envelope: block_peaks(&samples, block),
            spectrum: clip_spectrum(&samples, rate_hz),
            samples: Arc::new(samples),
        }
    }
}

/// A finished reconstruction with everything the waveform view draws.
#[derive(Clone, Debug)]
pub struct Clip {
    /// The engine's result.
    pub recon: Reconstruction,
    /// The recovered audio's mono mix.
    pub recovered: Trace,
    /// The reference aligned to the recovered audio (same rate and length at most), when the
    /// scan has one.
    pub reference: Option<Trace>,
    /// Samples per envelope block of both traces.
    pub envelope_block: usize,
    /// Params the clip was made with (recorded in exports).
    pub params: PipelineParams,
    /// Where those params came from when the reconstruction started (recorded in exports).
    pub param_state: ParamState,
    /// Groups it covers.
    pub groups: Range<usize>,
    /// Where each of them lies on the groove and how much of it is gaps, in group order.
    pub tracks: Vec<GroupTrack>,
    /// Scan folder.
    pub scan_dir: PathBuf,
    /// The scan's metadata as the clip was made (the exported WAV's `bext` chunk names it).
    pub scan_meta: Arc<crate::io::ScanMeta>,
    /// The scan's fingerprint (the exported WAV's `bext` reference starts with it).
    pub scan_fingerprint: String,
    /// Why the reference is missing, when `scan.reference` exists but could not be read.
    pub reference_problem: Option<String>,
    /// The clip's groups before the finish, kept so that another `[dsp]` table (which only
    /// the finish reads) refinishes the clip without running them again; None where they
    /// passed [`KEEP_GROUPS_MAX_BYTES`], and for a method comparison's clips.
    pub groups_before_finish: Option<Arc<ClipGroups>>,
    /// True when the clip is an earlier clip's groups finished again with another `[dsp]`
    /// table ([`ReconRun::refinish`]).
    pub refinished: bool,
}

impl Clip {
    /// True when `params` (for a scan of metadata `meta`) would finish this clip's kept groups
    /// again instead of running them: the metadata is the clip's and the params differ from its
    /// own at most in `[dsp]`. A clip belongs to the scan open, so only its metadata, which the
    /// form saves in place, can have changed under it.
    #[must_use]
    pub fn refinishes_with(&self, meta: &crate::io::ScanMeta, params: &PipelineParams) -> bool {
        self.groups_before_finish.is_some()
            && *self.scan_meta == *meta
            && self.params.same_groups_as(params)
    }

    /// Sample rate of the recovered audio (Hz).
    #[must_use]
    pub fn rate_hz(&self) -> u32 {
        self.recon.audio.sample_rate_hz
    }

    /// Seconds into the clip of the groove position `pos_um` (sample 0 of the stitched signal
    /// is the clip's start; its native rate is Vt over its spacing).
    #[must_use]
    pub fn secs_at_um(&self, pos_um: f64) -> f64 {
        let s = &self.recon.stitched;
        let um_per_sec = s.spacing_um * s.native_rate_hz;
        if um_per_sec > 0.0 {
            (pos_um - s.start_um) / um_per_sec
        } else {
            f64::NAN
        }
    }

    /// Where group `g` lies in the clip (seconds), when it produced sound.
    #[must_use]
    pub fn group_span_secs(&self, g: usize) -> Option<(f64, f64)> {
        let t = self.tracks.iter().find(|t| t.group == g)?;
        let (a, b) = (self.secs_at_um(t.span_um.0), self.secs_at_um(t.span_um.1));
        (a.is_finite() && b.is_finite()).then_some((a, b))
    }

    /// The group heard at `secs` into the clip: the one whose span holds it, else the nearest.
    #[must_use]
    pub fn group_at_secs(&self, secs: f64) -> Option<usize> {
        self.tracks
            .iter()
            .filter_map(|t| Some((t.group, self.group_span_secs(t.group)?)))
            .min_by(|(_, a), (_, b)| {
                let d = |(s, e): (f64, f64)| {
                    if secs < s {
                        s - secs
                    } else if secs > e {
                        secs - e
                    } else {
                        0.0
                    }
                };
                d(*a).total_cmp(&d(*b))
            })
            .map(|(g, _)| g)
    }

    /// `other`'s recovered sound (mono) laid on this clip's time axis by groove position, as
    /// long as this clip: silence where `other` has none. None when the rates differ.
    #[must_use]
    pub fn lay_on(&self, other: &Clip) -> Option<Vec<f32>> {
        if other.rate_hz() != self.rate_hz() {
            return None;
        }
        let offset_secs = self.secs_at_um(other.recon.stitched.start_um);
        if !offset_secs.is_finite() {
            return None;
        }
        let offset = (offset_secs * f64::from(self.rate_hz())).round() as i64;
        Some(
            (0..self.recovered.samples.len())
                .map(|i| {
                    usize::try_from(i as i64 - offset)
                        .ok()
                        .and_then(|k| other.recovered.samples.get(k))
                        .copied()
                        .unwrap_or(0.0)
                })
                .collect(),
        )
    }
}

/// Magnitude spectrum of `samples` (`crate::pipeline::dsp::magnitude_spectrum`, amplitude
/// calibrated: a full-scale sine reads 0 dB), reduced to at most [`SPECTRUM_POINTS`] bands by
/// keeping each band's loudest bin, so peaks survive.
#[must_use]
pub fn clip_spectrum(samples: &[f32], rate_hz: u32) -> Spectrum {
    let full = magnitude_spectrum(samples, f64::from(rate_hz));
    let per = full.len().div_ceil(SPECTRUM_POINTS).max(1);
    let (freqs_hz, db) = full
        .chunks(per)
        .filter_map(|c| c.iter().copied().max_by(|a, b| a.1.total_cmp(&b.1)))
        .unzip();
    Spectrum { freqs_hz, db }
}

/// Builds the display data of a finished reconstruction.
#[must_use]
pub fn make_clip(
    scan: &Scan,
    recon: Reconstruction,
    params: PipelineParams,
    param_state: ParamState,
    groups: Range<usize>,
    tracks: Vec<GroupTrack>,
) -> Clip {
    let rate = recon.audio.sample_rate_hz;
    let recovered = recon.audio.mono();
    let block = ((ENVELOPE_BLOCK_SECS * f64::from(rate)).round() as usize)
        .min(recovered.len() / ENVELOPE_MIN_BLOCKS)
        .max(1);
    let (reference, reference_problem) = match &scan.reference {
        Some(path) => match aligned_reference(
            &recon.audio,
            &recon.stitched,
            scan.meta.groove_speed_mm_s(groups.start),
            path,
        ) {
            Ok((mut r, _)) => {
                r.truncate(recovered.len());
                (Some(r), None)
            }
            Err(e) => (None, Some(e.to_string())),
        },
        None => (None, None),
    };
    Clip {
        recovered: Trace::new(recovered, block, rate),
        reference: reference.map(|r| Trace::new(r, block, rate)),
        envelope_block: block,
        recon,
        params,
        param_state,
        groups,
        tracks,
        scan_dir: scan.dir.clone(),
        scan_meta: Arc::new(scan.meta.clone()),
        scan_fingerprint: crate::io::fingerprint::scan_fingerprint(scan),
        reference_problem,
        groups_before_finish: None,
        refinished: false,
    }
}

/// A reconstruction thread's outcome in the words the workbench shows.
fn result_text<T>(result: std::thread::Result<Result<T, EngineError>>) -> Result<T, String> {
    match result {
        Ok(Ok(done)) => Ok(done),
        Ok(Err(e)) => Err(e.to_string()),
        Err(_) => Err("the reconstruction panicked (see the log)".into()),
    }
}

/// Messages from the reconstruction thread.
#[derive(Debug)]
enum ReconEvent {
    Progress(Progress),
    /// The sound of the groups finished so far (asked for with [`ReconRun::request_partial`]).
    Partial(Result<PartialClip, String>),
    Finished(Result<Box<Clip>, String>),
}

/// The sound of the groups a running reconstruction finished so far.
#[derive(Clone, Debug)]
pub struct PartialClip {
    /// Groups it holds.
    pub groups: usize,
    /// The sound.
    pub audio: crate::io::wav::Audio,
}

/// A reconstruction running in the background.
#[derive(Debug)]
pub struct ReconRun {
    cancel: Arc<AtomicBool>,
    partial_wanted: Arc<AtomicBool>,
    rx: Receiver<ReconEvent>,
    thread: Option<JoinHandle<()>>,
    /// When it started.
    pub started: Instant,
    /// Groups finished.
    pub done: usize,
    /// Groups to run.
    pub total: usize,
    /// Signals of the groups finished so far (for the live waveform).
    pub partial: Vec<Arc<GroupSignal>>,
    /// Tracks of the groups finished so far (for the live health strip).
    pub tracks: Vec<GroupTrack>,
    /// First group of the run.
    pub first_group: usize,
    /// True when it refinishes a clip's kept groups ([`ReconRun::refinish`]): no group runs.
    pub refinishing: bool,
    /// The latest partial sound that arrived (taken by [`ReconRun::take_partial`]).
    partial_sound: Option<Result<PartialClip, String>>,
}

/// The group a progress report is about: groups run in order from `first`.
fn reported_group(first: usize, p: &Progress) -> usize {
    first + p.done.saturating_sub(1)
}

impl ReconRun {
    /// Starts reconstructing `scan` with `opts` (whose params are in `param_state`) on a named
    /// thread; `repaint` wakes the UI.
    ///
    /// # Errors
    /// When the thread cannot be started.
    pub fn start(
        scan: Scan,
        opts: ReconstructOptions,
        param_state: ParamState,
        repaint: Box<dyn Fn() + Send + Sync>,
    ) -> std::io::Result<Self> {
        let groups = opts.groups.clone().unwrap_or(0..scan.groups.len());
        let total = groups
            .end
            .min(scan.groups.len())
            .saturating_sub(groups.start);
        let first_group = groups.start;
        Self::launch(total, first_group, false, move |tx, flag, wanted| {
            let started = Instant::now();
            let ptx = tx.clone();
            let mut tracks = Vec::new();
            let mut signals = Vec::new();
            let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                let gathered = run_clip_groups(
                    &scan,
                    &opts,
                    &mut |p| {
                        let g = reported_group(first_group, p);
                        tracks.push(GroupTrack::new(g, p.signal.as_deref()));
                        signals.extend(p.signal.clone());
                        let _ = ptx.send(ReconEvent::Progress(p.clone()));
                        if wanted.swap(false, Ordering::AcqRel) {
                            let sound =
                                partial_sound(&signals, &scan.meta, &opts.params).map(|audio| {
                                    PartialClip {
                                        groups: signals.len(),
                                        audio,
                                    }
                                });
                            let _ = ptx.send(ReconEvent::Partial(sound));
                        }
                        repaint();
                    },
                    &flag,
                )?;
                let kept = (gathered.signal_bytes() <= KEEP_GROUPS_MAX_BYTES)
                    .then(|| Arc::new(gathered.clone()));
                let mut recon = finish_scan_clip(&scan, gathered, &opts.params)?;
                recon.timings.total_secs = started.elapsed().as_secs_f64();
                Ok::<_, EngineError>((recon, kept))
            }));
            let outcome = result_text(result).map(|(recon, kept)| {
                let mut clip = make_clip(
                    &scan,
                    recon,
                    opts.params.clone(),
                    param_state,
                    groups,
                    tracks,
                );
                clip.groups_before_finish = kept;
                Box::new(clip)
            });
            let _ = tx.send(ReconEvent::Finished(outcome));
            repaint();
        })
    }

    /// Finishes `source`'s kept groups again with `params`, whose groups are `source`'s (the
    /// params differ only in `[dsp]`: the caller checks), on a named thread: the clip with
    /// other filters in the time the finish takes, no group run again. None when `source`
    /// kept no groups.
    ///
    /// # Errors
    /// When the thread cannot be started.
    pub fn refinish(
        scan: Scan,
        source: &Clip,
        params: PipelineParams,
        param_state: ParamState,
        repaint: Box<dyn Fn() + Send + Sync>,
    ) -> std::io::Result<Option<Self>> {
        let Some(kept) = source.groups_before_finish.clone() else {
            return Ok(None);
        };
        let groups = source.groups.clone();
        let tracks = source.tracks.clone();
        // The groups' own seconds are the earlier run's; only the finish is new.
        let before = &source.recon.timings;
        let groups_secs = before.total_secs - before.finish_secs;
        let run = Self::launch(groups.len(), groups.start, true, move |tx, flag, _| {
            let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                params.validate_for_clip()?;
                let mut recon = finish_scan_clip(&scan, (*kept).clone(), &params)?;
                if flag.load(Ordering::Relaxed) {
                    return Err(EngineError::Cancelled);
                }
                recon.timings.total_secs = groups_secs + recon.timings.finish_secs;
                Ok(recon)
            }));
            let outcome = result_text(result).map(|recon| {
                let mut clip = make_clip(&scan, recon, params, param_state, groups, tracks);
                clip.groups_before_finish = Some(kept);
                clip.refinished = true;
                Box::new(clip)
            });
            let _ = tx.send(ReconEvent::Finished(outcome));
            repaint();
        })?;
        Ok(Some(run))
    }

    /// Starts `body` on the reconstruction thread with the run's channel, cancel flag and
    /// partial-sound request flag.
    fn launch(
        total: usize,
        first_group: usize,
        refinishing: bool,
        body: impl FnOnce(mpsc::Sender<ReconEvent>, Arc<AtomicBool>, Arc<AtomicBool>) + Send + 'static,
    ) -> std::io::Result<Self> {
        let cancel = Arc::new(AtomicBool::new(false));
        let partial_wanted = Arc::new(AtomicBool::new(false));
        let (tx, rx) = mpsc::channel();
        let (flag, wanted) = (cancel.clone(), partial_wanted.clone());
        let thread = std::thread::Builder::new()
            .name("groovescope-reconstruct".into())
            .spawn(move || body(tx, flag, wanted))?;
        Ok(Self {
            cancel,
            partial_wanted,
            rx,
            thread: Some(thread),
            started: Instant::now(),
            done: 0,
            total,
            partial: Vec::new(),
            tracks: Vec::new(),
            first_group,
            refinishing,
            partial_sound: None,
        })
    }

    /// Asks the run to stop after the current group.
    pub fn cancel(&self) {
        self.cancel.store(true, Ordering::Relaxed);
    }

    /// Asks for the sound of the groups finished so far; it arrives after the group running
    /// now ([`ReconRun::take_partial`]).
    pub fn request_partial(&self) {
        self.partial_wanted.store(true, Ordering::Release);
    }

    /// True while a requested partial sound has not arrived yet.
    #[must_use]
    pub fn partial_pending(&self) -> bool {
        self.partial_wanted.load(Ordering::Acquire)
    }

    /// The partial sound that arrived, if any.
    pub fn take_partial(&mut self) -> Option<Result<PartialClip, String>> {
        self.partial_sound.take()
    }

    /// True once cancel was asked for.
    #[must_use]
    pub fn cancelling(&self) -> bool {
        self.cancel.load(Ordering::Relaxed)
    }

    /// Takes the waiting progress reports; returns the outcome once the run ended.
    pub fn poll(&mut self) -> Option<Result<Box<Clip>, String>> {
        while let Ok(ev) = self.rx.try_recv() {
            match ev {
                ReconEvent::Progress(p) => {
                    self.done = p.done;
                    self.total = p.total;
                    let g = reported_group(self.first_group, &p);
                    self.tracks.push(GroupTrack::new(g, p.signal.as_deref()));
                    if let Some(s) = p.signal {
                        self.partial.push(s);
                    }
                }
                ReconEvent::Partial(sound) => self.partial_sound = Some(sound),
                ReconEvent::Finished(outcome) => {
                    if let Some(t) = self.thread.take() {
                        let _ = t.join();
                    }
                    return Some(outcome);
                }
            }
        }
        None
    }

    /// Share done, in `[0, 1]`.
    #[must_use]
    pub fn fraction(&self) -> f32 {
        if self.total == 0 {
            0.0
        } else {
            self.done as f32 / self.total as f32
        }
    }

    /// Estimated time left, from the mean time per finished group.
    #[must_use]
    pub fn eta(&self) -> Option<Duration> {
        if self.done == 0 || self.done >= self.total {
            return None;
        }
        let per = self.started.elapsed().as_secs_f64() / self.done as f64;
        Some(Duration::from_secs_f64(
            per * (self.total - self.done) as f64,
        ))
    }
}

impl Drop for ReconRun {
    /// Asks the run to stop and lets the thread finish on its own (never blocks the UI).
    fn drop(&mut self) {
        self.cancel();
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;

    #[test]
    fn envelope_takes_block_peaks() {
        let e = block_peaks(&[0.1, -0.5, 0.2, 0.3, f32::NAN, -0.1], 2);
        assert_eq!(e, vec![0.5, 0.3, 0.1]);
    }

    #[test]
    fn spectrum_peaks_at_the_tone() {
        let rate = 8000;
        let f = 1000.0;
        let x: Vec<f32> = (0..8000)
            .map(|i| (std::f64::consts::TAU * f * f64::from(i) / f64::from(rate)).sin() as f32)
            .collect();
        let s = clip_spectrum(&x, rate);
        let (k, _) =
            s.db.iter()
                .enumerate()
                .max_by(|a, b| a.1.total_cmp(b.1))
                .unwrap();
        assert!((s.freqs_hz[k] - f).abs() < 2.0, "{}", s.freqs_hz[k]);
        // Amplitude calibrated: a full-scale sine reads about 0 dB (less the Hann scalloping).
        assert!(s.db[k] > -2.0 && s.db[k] < 0.5, "{}", s.db[k]);
        assert!(s.db.len() <= SPECTRUM_POINTS);
        assert!(clip_spectrum(&[], rate).db.is_empty());
    }
}
