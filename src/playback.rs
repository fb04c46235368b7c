//! Audio output through cpal: plays a prepared buffer from a callback that never blocks, with
//! several sources of the same length and rate to switch between while playing (the clip, the
//! previous clip, the reference: A/B listening); play/pause/stop/seek, loop a selection and
//! volume. Audio is optional: without a usable device the player says why and everything else
//! keeps working.

use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use cpal::traits::{DeviceTrait, HostTrait, StreamTrait};
use cpal::{FromSample, SampleFormat, SizedSample};

/// Env var choosing the output device: unset = the default device, `off` = no audio, else a device name.
pub const AUDIO_DEVICE_ENV: &str = "GROOVESCOPE_AUDIO_DEVICE";

/// "No value" marker in the atomics below.
const NONE: u64 = u64::MAX;

/// Which output device to open.
#[derive(Clone, Debug, PartialEq, Eq, Default)]
pub enum DeviceChoice {
    /// The host's default output device.
    #[default]
    Default,
    /// The output device with this name.
    Named(String),
    /// No audio at all.
    Off,
}

impl DeviceChoice {
    /// The choice named by [`AUDIO_DEVICE_ENV`].
    #[must_use]
    pub fn from_env() -> Self {
        match std::env::var(AUDIO_DEVICE_ENV) {
            Err(_) => Self::Default,
            Ok(v) if v.is_empty() || v == "default" => Self::Default,
            Ok(v) if v == "off" || v == "none" => Self::Off,
            Ok(v) => Self::Named(v),
        }
    }
}

/// Sound prepared for playback: sources at one rate, one buffer per channel each; source 0 is
/// the clip itself (its length is the player's), the others are laid on its time axis.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PlayBuffers {
    /// Sample rate of every source (Hz).
    pub rate_hz: u32,
    /// The sources, each one buffer per channel (an empty source plays as silence).
    pub sources: Vec<Vec<Vec<f32>>>,
}

impl PlayBuffers {
    /// Source `i` (source 0 when there is no such source).
    fn source(&self, i: usize) -> &[Vec<f32>] {
        self.sources
            .get(i)
            .or_else(|| self.sources.first())
            .map_or(&[], Vec::as_slice)
    }

    /// Frames of source 0.
    #[must_use]
    pub fn len(&self) -> usize {
        self.sources
            .first()
            .and_then(|s| s.first())
            .map_or(0, Vec::len)
    }

    /// True when source 0 is empty.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Whether sound can be played.
#[derive(Clone, Debug, PartialEq)]
pub enum AudioStatus {
    /// A stream is open.
    Ready {
        /// Device name.
        device: String,
        /// Device sample rate (Hz).
        rate_hz: u32,
        /// Device channels.
        channels: u16,
    },
    /// No stream: why.
    Unavailable(String),
}

/// State shared between the UI and the audio callback (atomics, plus a slot the callback only `try_lock`s).
#[derive(Debug)]
struct Shared {
    slot: Mutex<Option<Arc<PlayBuffers>>>,
    version: AtomicU64,
    playing: AtomicBool,
    source: AtomicUsize,
    volume_bits: AtomicU32,
    position: AtomicU64,
    seek_to: AtomicU64,
    loop_start: AtomicU64,
    loop_end: AtomicU64,
    last_error: Mutex<Option<String>>,
    /// Set by the error callback when the device went away mid-stream.
    device_lost: AtomicBool,
}

impl Default for Shared {
    fn default() -> Self {
        Self {
            slot: Mutex::new(None),
            version: AtomicU64::new(0),
            playing: AtomicBool::new(false),
            source: AtomicUsize::new(0),
            volume_bits: AtomicU32::new(1.0_f32.to_bits()),
            position: AtomicU64::new(0),
            seek_to: AtomicU64::new(NONE),
            loop_start: AtomicU64::new(NONE),
            loop_end: AtomicU64::new(NONE),
            last_error: Mutex::new(None),
            device_lost: AtomicBool::new(false),
        }
    }
}

/// The callback's own state: the buffer it holds and its fractional read position.
struct Cursor {
    shared: Arc<Shared>,
    buffers: Option<Arc<PlayBuffers>>,
    seen_version: u64,
    pos: f64,
    device_rate_hz: u32,
    device_channels: usize,
}

impl Cursor {
    /// Fills one interleaved device buffer. Never blocks: the slot is only `try_lock`ed.
    fn fill<T: SizedSample + FromSample<f32>>(&mut self, out: &mut [T]) {
        let sh = &self.shared;
        let version = sh.version.load(Ordering::Acquire);
        if version != self.seen_version
            && let Ok(slot) = sh.slot.try_lock()
        {
            self.buffers.clone_from(&slot);
            self.seen_version = version;
        }
        let seek = sh.seek_to.swap(NONE, Ordering::AcqRel);
        if seek != NONE {
            self.pos = seek as f64;
        }
        let silence = T::from_sample(0.0_f32);
        let nch = self.device_channels.max(1);
        let playing = sh.playing.load(Ordering::Acquire);
        let Some(buf) = self.buffers.as_ref().filter(|_| playing) else {
            out.fill(silence);
            return;
        };
        let src = buf.source(sh.source.load(Ordering::Relaxed));
        // Source 0 sets the length; the others are read where they have samples (silence
        // elsewhere), so a switch never ends playback or reads out of bounds.
        let len = buf.len();
        let step = f64::from(buf.rate_hz) / f64::from(self.device_rate_hz.max(1));
        let vol = f32::from_bits(sh.volume_bits.load(Ordering::Relaxed));
        let (ls, le) = (
            sh.loop_start.load(Ordering::Relaxed),
            sh.loop_end.load(Ordering::Relaxed),
        );
        let looping = ls != NONE && le != NONE && le > ls;
        let mut ended = false;
        for frame in out.chunks_mut(nch) {
            if looping && (self.pos >= le as f64 || self.pos < ls as f64) {
                self.pos = ls as f64;
            }
            if ended || self.pos >= (len.saturating_sub(1)) as f64 {
                ended = true;
                frame.fill(silence);
                continue;
            }
            let i = self.pos as usize;
            let f = (self.pos - i as f64) as f32;
            for (c, o) in frame.iter_mut().enumerate() {
                let ch = src.get(c.min(src.len().saturating_sub(1)));
                let at = |k: usize| ch.and_then(|ch| ch.get(k)).copied().unwrap_or(0.0);
                let (a, b) = (at(i), at(i + 1));
                let v = (a + (b - a) * f) * vol;
                *o = T::from_sample(if v.is_finite() {
                    v.clamp(-1.0, 1.0)
                } else {
                    0.0
                });
            }
            self.pos += step;
        }
        if ended {
            sh.playing.store(false, Ordering::Release);
            self.pos = 0.0;
        }
        sh.position.store(self.pos as u64, Ordering::Release);
    }
}

/// The audio output.
pub struct Player {
    shared: Arc<Shared>,
    stream: Option<cpal::Stream>,
    status: AudioStatus,
    current: Option<Arc<PlayBuffers>>,
    previous: Option<Arc<PlayBuffers>>,
}

impl std::fmt::Debug for Player {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Player")
            .field("status", &self.status)
            .finish_non_exhaustive()
    }
}

fn build<T: SizedSample + FromSample<f32>>(
    device: &cpal::Device,
    config: cpal::StreamConfig,
    shared: &Arc<Shared>,
) -> Result<cpal::Stream, cpal::Error> {
    let mut cursor = Cursor {
        shared: shared.clone(),
        buffers: None,
        seen_version: u64::MAX,
        pos: 0.0,
        device_rate_hz: config.sample_rate,
        device_channels: usize::from(config.channels),
    };
    let err_shared = shared.clone();
    device.build_output_stream::<T, _, _>(
        config,
        move |out: &mut [T], _| cursor.fill(out),
        move |e| {
            // Glitches and reroutes leave the stream playing; anything else means it is gone.
            let lost = !matches!(
                e.kind(),
                cpal::ErrorKind::Xrun
                    | cpal::ErrorKind::DeviceChanged
                    | cpal::ErrorKind::RealtimeDenied
            );
            stream_failed(&err_shared, e.to_string(), lost);
        },
        None,
    )
}

/// What the stream's error callback does: keeps the message and, when the device is gone
/// (`lost`), stops playback and flags the loss for [`Player::poll_device`]. Never blocks.
fn stream_failed(shared: &Shared, message: String, lost: bool) {
    if lost {
        shared.playing.store(false, Ordering::Release);
        shared.device_lost.store(true, Ordering::Release);
    }
    if let Ok(mut slot) = shared.last_error.try_lock() {
        *slot = Some(message);
    }
}

fn open_stream(
    choice: &DeviceChoice,
    shared: &Arc<Shared>,
) -> Result<(cpal::Stream, AudioStatus), String> {
    let host = cpal::default_host();
    let device = match choice {
        DeviceChoice::Off => return Err("audio switched off".into()),
        DeviceChoice::Default => host
            .default_output_device()
            .ok_or_else(|| "no output device".to_string())?,
        DeviceChoice::Named(name) => host
            .output_devices()
            .map_err(|e| e.to_string())?
            .find(|d| d.description().is_ok_and(|desc| desc.name() == name))
            .ok_or_else(|| format!("no output device named {name:?}"))?,
    };
    let name = device
        .description()
        .map_or_else(|_| "output".to_string(), |d| d.name().to_string());
    let supported = device.default_output_config().map_err(|e| e.to_string())?;
    let config = supported.config();
    let stream = match supported.sample_format() {
        SampleFormat::I16 => build::<i16>(&device, config, shared),
        SampleFormat::U16 => build::<u16>(&device, config, shared),
        SampleFormat::I32 => build::<i32>(&device, config, shared),
        _ => build::<f32>(&device, config, shared),
    }
    .map_err(|e| e.to_string())?;
    stream.play().map_err(|e| e.to_string())?;
    Ok((
        stream,
        AudioStatus::Ready {
            device: name,
            rate_hz: config.sample_rate,
            channels: config.channels,
        },
    ))
}

impl Player {
    /// Opens the chosen device; on failure the player is [`AudioStatus::Unavailable`] (never panics).
    #[must_use]
    pub fn open(choice: &DeviceChoice) -> Self {
        let shared = Arc::new(Shared::default());
        let (stream, status) = match open_stream(choice, &shared) {
            Ok((s, st)) => (Some(s), st),
            Err(e) => (None, AudioStatus::Unavailable(e)),
        };
        Self {
            shared,
            stream,
            status,
            current: None,
            previous: None,
        }
    }

    /// Device state.
    #[must_use]
    pub fn status(&self) -> &AudioStatus {
        &self.status
    }

    /// True when a stream is open.
    #[must_use]
    pub fn available(&self) -> bool {
        self.stream.is_some()
    }

    /// The last error the stream reported, if any.
    #[must_use]
    pub fn stream_error(&self) -> Option<String> {
        self.shared.last_error.lock().ok().and_then(|e| e.clone())
    }

    /// Hands new sound to the callback (stops playback and rewinds).
    pub fn load(&mut self, buffers: PlayBuffers) {
        self.stop();
        let buffers = Arc::new(buffers);
        if let Ok(mut slot) = self.shared.slot.lock() {
            *slot = Some(buffers.clone());
        }
        self.shared.version.fetch_add(1, Ordering::AcqRel);
        // Keep the older buffer alive a while so the callback never frees memory.
        self.previous = self.current.replace(buffers);
    }

    /// The loaded sound.
    #[must_use]
    pub fn buffers(&self) -> Option<&PlayBuffers> {
        self.current.as_deref()
    }

    /// Checks whether the device went away while the stream ran (unplugged, sound server
    /// stopped). The first call after that closes the stream, makes the player
    /// [`AudioStatus::Unavailable`] and returns the message to show; the loaded clip stays.
    pub fn poll_device(&mut self) -> Option<String> {
        if !self.shared.device_lost.swap(false, Ordering::AcqRel) {
            return None;
        }
        let why = self
            .stream_error()
            .unwrap_or_else(|| "the stream stopped".into());
        self.stream = None;
        self.shared.playing.store(false, Ordering::Release);
        self.status = AudioStatus::Unavailable(format!("the audio device stopped: {why}"));
        Some(format!(
            "audio unavailable: the audio device stopped: {why}"
        ))
    }

    /// Starts or resumes playback.
    ///
    /// # Errors
    /// Why it cannot play (no device, nothing loaded).
    pub fn play(&self) -> Result<(), String> {
        if let AudioStatus::Unavailable(why) = &self.status {
            return Err(format!("audio unavailable: {why}"));
        }
        if self.current.as_ref().is_none_or(|b| b.is_empty()) {
            return Err("nothing to play yet: reconstruct the clip first".into());
        }
        self.shared.playing.store(true, Ordering::Release);
        Ok(())
    }

    /// Pauses, keeping the position.
    pub fn pause(&self) {
        self.shared.playing.store(false, Ordering::Release);
    }

    /// Stops and rewinds to the loop start (or the beginning).
    pub fn stop(&self) {
        self.pause();
        let start = self.shared.loop_start.load(Ordering::Relaxed);
        let to = if start == NONE { 0 } else { start };
        self.shared.seek_to.store(to, Ordering::Release);
        self.shared.position.store(to, Ordering::Release);
    }

    /// True while playing.
    #[must_use]
    pub fn is_playing(&self) -> bool {
        self.shared.playing.load(Ordering::Acquire)
    }

    fn rate(&self) -> f64 {
        self.current.as_ref().map_or(0.0, |b| f64::from(b.rate_hz))
    }

    /// Moves the playhead to `secs`.
    pub fn seek_secs(&self, secs: f64) {
        let frame = (secs.max(0.0) * self.rate()).round() as u64;
        self.shared.seek_to.store(frame, Ordering::Release);
        self.shared.position.store(frame, Ordering::Release);
    }

    /// Playhead position (seconds).
    #[must_use]
    pub fn position_secs(&self) -> f64 {
        let r = self.rate();
        if r > 0.0 {
            self.shared.position.load(Ordering::Acquire) as f64 / r
        } else {
            0.0
        }
    }

    /// Sets the gain (0..=2).
    pub fn set_volume(&self, volume: f32) {
        let v = if volume.is_finite() {
            volume.clamp(0.0, 2.0)
        } else {
            1.0
        };
        self.shared
            .volume_bits
            .store(v.to_bits(), Ordering::Relaxed);
    }

    /// The gain.
    #[must_use]
    pub fn volume(&self) -> f32 {
        f32::from_bits(self.shared.volume_bits.load(Ordering::Relaxed))
    }

    /// Plays source `i` of the loaded buffers (source 0 when there is no such source); the
    /// position stays, so the switch is heard at once.
    pub fn set_source(&self, i: usize) {
        self.shared.source.store(i, Ordering::Relaxed);
    }

    /// The source selected.
    #[must_use]
    pub fn source(&self) -> usize {
        self.shared.source.load(Ordering::Relaxed)
    }

    /// Loops `[start, end)` seconds, or clears the loop.
    pub fn set_loop(&self, range: Option<(f64, f64)>) {
        let r = self.rate();
        let (s, e) = match range {
            Some((a, b)) if b > a && r > 0.0 => {
                ((a.max(0.0) * r) as u64, (b.max(0.0) * r).ceil() as u64)
            }
            _ => (NONE, NONE),
        };
        self.shared.loop_start.store(s, Ordering::Relaxed);
        self.shared.loop_end.store(e, Ordering::Relaxed);
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;

    fn cursor(device_rate_hz: u32, channels: usize) -> Cursor {
        Cursor {
            shared: Arc::new(Shared::default()),
            buffers: None,
            seen_version: u64::MAX,
            pos: 0.0,
            device_rate_hz,
            device_channels: channels,
        }
    }

    fn load(c: &Cursor, b: PlayBuffers) {
        *c.shared.slot.lock().unwrap() = Some(Arc::new(b));
        c.shared.version.fetch_add(1, Ordering::AcqRel);
    }

    #[test]
    fn callback_plays_resamples_loops_and_stops_at_the_end() {
        let mut c = cursor(2, 2);
        load(
            &c,
            PlayBuffers {
                rate_hz: 1,
                sources: vec![vec![vec![0.0, 1.0, 0.0, -1.0, 0.0]], vec![vec![0.5; 5]]],
            },
        );
        let mut out = vec![9.0_f32; 4];
        c.fill(&mut out);
        assert_eq!(out, vec![0.0; 4], "paused: silence");
        c.shared.playing.store(true, Ordering::Release);
        let mut out = vec![0.0_f32; 8];
        c.fill(&mut out);
        // Device at twice the source rate: linear interpolation, mono copied to both channels.
        assert_eq!(out, vec![0.0, 0.0, 0.5, 0.5, 1.0, 1.0, 0.5, 0.5]);
        c.shared.source.store(1, Ordering::Relaxed);
        c.shared
            .volume_bits
            .store(0.5_f32.to_bits(), Ordering::Relaxed);
        let mut out = vec![0.0_f32; 2];
        c.fill(&mut out);
        assert_eq!(out, vec![0.25, 0.25]);
        c.shared.source.store(0, Ordering::Relaxed);
        c.shared
            .volume_bits
            .store(1.0_f32.to_bits(), Ordering::Relaxed);
        c.shared.loop_start.store(1, Ordering::Relaxed);
        c.shared.loop_end.store(2, Ordering::Relaxed);
        let mut out = vec![0.0_f32; 8];
        c.fill(&mut out);
        assert_eq!(out, vec![1.0, 1.0, 0.5, 0.5, 1.0, 1.0, 0.5, 0.5]);
        c.shared.loop_start.store(NONE, Ordering::Relaxed);
        c.shared.loop_end.store(NONE, Ordering::Relaxed);
        let mut out = vec![0.0_f32; 40];
        c.fill(&mut out);
        assert!(
            !c.shared.playing.load(Ordering::Acquire),
            "stops at the end"
        );
        assert_eq!(&out[30..], &[0.0; 10]);
    }

    #[test]
    fn switching_to_a_shorter_or_missing_source_plays_silence_there() {
        let mut c = cursor(1, 1);
        load(
            &c,
            PlayBuffers {
                rate_hz: 1,
                sources: vec![vec![vec![0.5; 6]], vec![vec![0.25; 2]], vec![]],
            },
        );
        c.shared.playing.store(true, Ordering::Release);
        c.shared.source.store(1, Ordering::Relaxed);
        let mut out = vec![9.0_f32; 4];
        c.fill(&mut out);
        assert_eq!(
            out,
            vec![0.25, 0.25, 0.0, 0.0],
            "B ends; A's length goes on"
        );
        assert!(c.shared.playing.load(Ordering::Acquire));
        c.shared.source.store(2, Ordering::Relaxed);
        c.fill(&mut out);
        assert_eq!(out[0], 0.0, "an empty source is silence");
        c.shared.source.store(7, Ordering::Relaxed);
        c.shared.playing.store(true, Ordering::Release);
        let mut out = vec![9.0_f32; 1];
        c.fill(&mut out);
        assert_eq!(out, vec![0.5], "no such source: A");
    }

    #[test]
    fn a_device_that_vanishes_mid_playback_stops_it_with_a_message_and_keeps_the_clip() {
        let mut p = Player {
            shared: Arc::new(Shared::default()),
            stream: None,
            status: AudioStatus::Ready {
                device: "test".into(),
                rate_hz: 48_000,
                channels: 2,
            },
            current: None,
            previous: None,
        };
        p.load(PlayBuffers {
            rate_hz: 48_000,
            sources: vec![vec![vec![0.1; 4800]]],
        });
        p.play().unwrap();
        // A glitch keeps playing.
        stream_failed(&p.shared, "buffer underrun".into(), false);
        assert!(p.is_playing() && p.poll_device().is_none());
        // What cpal's error callback reports when the device goes away.
        stream_failed(
            &p.shared,
            "The requested device is no longer available".into(),
            true,
        );
        assert!(!p.is_playing());
        let msg = p.poll_device().unwrap();
        assert!(msg.contains("no longer available"), "{msg}");
        assert!(p.poll_device().is_none(), "reported once");
        assert!(matches!(p.status(), AudioStatus::Unavailable(why) if why.contains("stopped")));
        assert!(p.play().unwrap_err().starts_with("audio unavailable:"));
        assert_eq!(p.buffers().map(PlayBuffers::len), Some(4800));
    }

    #[test]
    fn missing_device_is_a_message_not_a_panic() {
        let p = Player::open(&DeviceChoice::Named("groovescope-no-such-device".into()));
        match p.status() {
            AudioStatus::Unavailable(why) => assert!(!why.is_empty()),
            AudioStatus::Ready { .. } => panic!("a device with that name exists?"),
        }
        let err = p.play().unwrap_err();
        assert!(err.starts_with("audio unavailable:"), "{err}");
        let off = Player::open(&DeviceChoice::Off);
        assert!(!off.available());
    }
}
