//! "Compare methods" (A/B of decoders): the clip reconstructed with two methods one after the
//! other on the named thread `groovescope-compare`, with progress and cancel, and what the
//! comparison shows: B laid on A's time axis, their difference, and the agreement (correlation
//! r and SNR of B against A) per group and over the whole clip.
//!
//! B is laid on A by groove position and then by its own delay: a decoder can delay the sound
//! by a few samples of its own, and a delay read as disagreement would hide how alike the two
//! sounds are (on the demo scan, fused against flow: r 0.892 and 6.7 dB with flow 3.0 samples
//! late, r 0.944 and 9.6 dB once aligned). The delay is the lag within [`ALIGN_MAX_LAG_S`] at
//! which B correlates best with A, to a fraction of a sample (`pipeline::eval::evaluate`); B
//! is read there by band-limited interpolation (`read_from`), both for the figures and for
//! listening, and the window says how far it moved.

use std::sync::Arc;

use super::background::{Background, Polled};
use super::health::GroupTrack;
use super::recon::{Clip, make_clip};
use super::tuning::ParamState;
use crate::engine::{ReconstructOptions, reconstruct};
use crate::io::Scan;
use crate::pipeline::audio_signal::read_from;
use crate::pipeline::eval::evaluate;
use crate::pipeline::{Method, PipelineParams};
use crate::playback::PlayBuffers;

/// Every method, in the order the pickers list them.
pub const METHODS: [Method; 3] = [Method::Fused, Method::Flow, Method::Edges];

/// SNR shown for two identical signals (dB): the agreement stays a finite number.
pub const MAX_AGREEMENT_DB: f64 = 120.0;

/// Largest delay of B against A that the comparison takes out (seconds): 1 ms, a few times the
/// decoders' own delays, and shorter than the period of most of a record's sound, so a steady
/// tone is not aligned a whole period off.
pub const ALIGN_MAX_LAG_S: f64 = 0.001;

/// The method to set against `a` by default: the other of the two best (fused and flow).
#[must_use]
pub fn default_partner(a: Method) -> Method {
    match a {
        Method::Fused => Method::Flow,
        Method::Flow | Method::Edges => Method::Fused,
    }
}

/// The pair named by `text` (`"fused,flow"`), as `GROOVESCOPE_COMPARE_METHODS` takes it.
///
/// # Errors
/// A line naming the word that is not a method.
pub fn parse_pair(text: &str) -> Result<[Method; 2], String> {
    let words: Vec<&str> = text.split(',').map(str::trim).collect();
    let [a, b] = words.as_slice() else {
        return Err(format!(
            "give two methods separated by a comma (e.g. fused,flow), not {text:?}"
        ));
    };
    let one = |w: &str| {
        Method::from_name(w).ok_or_else(|| {
            format!(
                "unknown method {w:?} (one of: {})",
                METHODS.map(Method::name).join(", ")
            )
        })
    };
    Ok([one(a)?, one(b)?])
}

/// How well B agrees with A over a stretch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Agreement {
    /// Group index (for the whole clip: its first group).
    pub group: usize,
    /// Pearson correlation of the two waveforms, in `[-1, 1]` (1 for identical signals).
    pub r: f64,
    /// A's energy over the energy of A − B (dB), at most [`MAX_AGREEMENT_DB`].
    pub snr_db: f64,
    /// Samples compared.
    pub samples: usize,
}

/// Agreement of `b` with `a` over their common length (`group` is recorded as given).
#[must_use]
pub fn agreement(group: usize, a: &[f32], b: &[f32]) -> Agreement {
    let n = a.len().min(b.len());
    let (a, b) = (a.get(..n).unwrap_or(&[]), b.get(..n).unwrap_or(&[]));
    if n == 0 {
        return Agreement {
            group,
            r: 0.0,
            snr_db: 0.0,
            samples: 0,
        };
    }
    let (mut energy, mut err) = (0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        let (x, y) = (f64::from(*x), f64::from(*y));
        energy += x * x;
        err += (x - y) * (x - y);
    }
    // Identical signals agree perfectly even where r is undefined (constant or one sample).
    let r = if err == 0.0 {
        1.0
    } else {
        crate::pipeline::eval::pearson(a, b)
    };
    let snr_db = if err == 0.0 {
        MAX_AGREEMENT_DB
    } else if energy == 0.0 {
        -MAX_AGREEMENT_DB
    } else {
        (10.0 * (energy / err).log10()).clamp(-MAX_AGREEMENT_DB, MAX_AGREEMENT_DB)
    };
    Agreement {
        group,
        r,
        snr_db,
        samples: n,
    }
}

/// A finished comparison of two methods on the same groups.
#[derive(Clone, Debug)]
pub struct MethodComparison {
    /// The methods A and B.
    pub methods: [Method; 2],
    /// The clip made with A.
    pub a: Arc<Clip>,
    /// The clip made with B.
    pub b: Arc<Clip>,
    /// B's sound (mono) laid on A's time axis, as long as A's: by groove position, then moved
    /// by [`MethodComparison::b_delay_samples`].
    pub b_on_a: Arc<Vec<f32>>,
    /// How late B's sound was against A's once laid by groove position (samples at A's rate;
    /// negative: early), the delay taken out of `b_on_a`; 0 where the clips are too short to
    /// measure it.
    pub b_delay_samples: f64,
    /// A − B, sample by sample, on A's time axis.
    pub difference: Vec<f32>,
    /// The agreement of each group that made sound in A, in group order.
    pub groups: Vec<Agreement>,
    /// The agreement over the whole clip.
    pub overall: Agreement,
}

impl MethodComparison {
    /// Compares two clips of the same groups (`b` is laid on `a` by groove position, then
    /// moved by its delay against `a`; see the module docs).
    ///
    /// # Errors
    /// When the clips cannot be laid on one axis (different sample rates).
    pub fn new(methods: [Method; 2], a: Clip, b: Clip) -> Result<Self, String> {
        let by_position = a.lay_on(&b).ok_or_else(|| {
            format!(
                "the two clips have different sample rates ({} and {} Hz)",
                a.rate_hz(),
                b.rate_hz()
            )
        })?;
        let (b_on_a, b_delay_samples) = align(&a.recovered.samples, &by_position, a.rate_hz());
        let difference = a
            .recovered
            .samples
            .iter()
            .zip(&b_on_a)
            .map(|(x, y)| x - y)
            .collect();
        let rate = f64::from(a.rate_hz());
        let n = a.recovered.samples.len();
        let groups = a
            .tracks
            .iter()
            .filter_map(|t| {
                let (s, e) = a.group_span_secs(t.group)?;
                let i0 = ((s * rate).round().max(0.0) as usize).min(n);
                let i1 = ((e * rate).round().max(0.0) as usize).clamp(i0, n);
                let (x, y) = (a.recovered.samples.get(i0..i1)?, b_on_a.get(i0..i1)?);
                (i1 > i0).then(|| agreement(t.group, x, y))
            })
            .collect();
        let overall = agreement(a.groups.start, &a.recovered.samples, &b_on_a);
        Ok(Self {
            methods,
            a: Arc::new(a),
            b: Arc::new(b),
            b_on_a: Arc::new(b_on_a),
            b_delay_samples,
            difference,
            groups,
            overall,
        })
    }

    /// Sound for the player: source 0 is A, source 1 is B (both mono, on A's time axis).
    #[must_use]
    pub fn play_buffers(&self) -> PlayBuffers {
        PlayBuffers {
            rate_hz: self.a.rate_hz(),
            sources: vec![
                vec![self.a.recovered.samples.to_vec()],
                vec![self.b_on_a.to_vec()],
            ],
        }
    }

    /// The lowest group agreement (r), when any group was compared.
    #[must_use]
    pub fn worst_group(&self) -> Option<&Agreement> {
        self.groups.iter().min_by(|x, y| x.r.total_cmp(&y.r))
    }
}

/// `b` moved by its delay against `a` (see the module docs): the moved samples, as long as
/// `b`, and the delay in samples (positive: `b` was late). Where no delay is found (too few
/// samples, or `b` already aligned to the sample) `b` is returned as it is, with 0.
#[must_use]
pub fn align(a: &[f32], b: &[f32], rate_hz: u32) -> (Vec<f32>, f64) {
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // ≥ 0, tens of samples
    let max_lag = (ALIGN_MAX_LAG_S * f64::from(rate_hz)).round().max(1.0) as usize;
    let Some(delay) = evaluate(b, a, max_lag, rate_hz)
        .map(|s| s.lag_refined_samples)
        .filter(|d| d.is_finite() && *d != 0.0)
    else {
        return (b.to_vec(), 0.0);
    };
    (shifted(b, delay), delay)
}

/// `x` read `delay` samples later (`out[i] = x(i + delay)`, between samples by `read_from`'s
/// band-limited interpolation), as long as `x`; silence where that falls outside `x`.
fn shifted(x: &[f32], delay: f64) -> Vec<f32> {
    let whole = delay.floor();
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // |delay| ≤ tens
    let lead = (-whole).max(0.0) as usize;
    // A negative delay reads before x: that much silence in front, read from the fraction.
    let padded: Vec<f32> = std::iter::repeat_n(0.0, lead)
        .chain(x.iter().copied())
        .collect();
    let mut out = read_from(&padded, delay + lead as f64);
    out.resize(x.len(), 0.0);
    out
}

/// A comparison running in the background.
#[derive(Debug)]
pub struct CompareRun {
    /// The job; its progress is (pass running: 0 for A, 1 for B; groups finished in it).
    job: Background<(usize, usize), Box<MethodComparison>>,
    /// The methods A and B.
    pub methods: [Method; 2],
    /// Groups per pass.
    pub total: usize,
}

impl CompareRun {
    /// Starts reconstructing `groups` of `scan` (None: all) with `params` (whose origin is
    /// `param_state`) under method A, then under method B, on a named thread; `repaint` wakes the UI.
    ///
    /// # Errors
    /// When the thread cannot be started.
    pub fn start(
        scan: Scan,
        params: &PipelineParams,
        methods: [Method; 2],
        groups: Option<std::ops::Range<usize>>,
        param_state: ParamState,
        repaint: Box<dyn Fn() + Send + Sync>,
    ) -> std::io::Result<Self> {
        let range = groups.clone().unwrap_or(0..scan.groups.len());
        let total = range.end.min(scan.groups.len()).saturating_sub(range.start);
        let base = params.clone();
        let job = Background::start("groovescope-compare", (0, 0), repaint, move |r| {
            let mut clips = Vec::with_capacity(2);
            for (pass, method) in methods.into_iter().enumerate() {
                let params = PipelineParams {
                    method,
                    ..base.clone()
                };
                let opts = ReconstructOptions {
                    params: params.clone(),
                    groups: Some(range.clone()),
                    keep_going: true,
                };
                let mut tracks = Vec::new();
                let recon = reconstruct(
                    &scan,
                    &opts,
                    &mut |p| {
                        tracks.push(GroupTrack::new(
                            range.start + p.done.saturating_sub(1),
                            p.signal.as_deref(),
                        ));
                        r.report((pass, p.done));
                    },
                    r.flag(),
                )
                .map_err(|e| format!("method {}: {e}", method.name()))?;
                if r.cancelled() {
                    return Err("cancelled".to_string());
                }
                clips.push(make_clip(
                    &scan,
                    recon,
                    params,
                    param_state.clone(),
                    range.clone(),
                    tracks,
                ));
            }
            let b = clips.pop().ok_or("no clip B")?;
            let a = clips.pop().ok_or("no clip A")?;
            MethodComparison::new(methods, a, b).map(Box::new)
        })?;
        Ok(Self {
            job,
            methods,
            total,
        })
    }

    /// Asks the run to stop after the current group.
    pub fn cancel(&self) {
        self.job.cancel();
    }

    /// The pass running (0: A, 1: B).
    #[must_use]
    pub fn pass(&self) -> usize {
        self.job.progress.0
    }

    /// Groups finished in that pass.
    #[must_use]
    pub fn done(&self) -> usize {
        self.job.progress.1
    }

    /// Share of both passes done, in `[0, 1]`.
    #[must_use]
    pub fn fraction(&self) -> f32 {
        if self.total == 0 {
            0.0
        } else {
            (self.pass() * self.total + self.done()) as f32 / (2 * self.total) as f32
        }
    }
}

/// The run's outcome is the comparison of its two passes.
impl Polled for CompareRun {
    type Outcome = Result<Box<MethodComparison>, String>;

    fn poll(&mut self) -> Option<Self::Outcome> {
        self.job.poll()
    }

    fn cancelling(&self) -> bool {
        self.job.cancelling()
    }
}

/// The "Compare methods" window's state for the open scan.
#[derive(Debug, Default)]
pub struct CompareState {
    /// The window is shown.
    pub open: bool,
    /// The methods picked (None: not chosen yet; the window fills in the default pair).
    pub methods: Option<[Method; 2]>,
    /// The comparison running now.
    pub run: Option<CompareRun>,
    /// The last finished comparison.
    pub result: Option<Arc<MethodComparison>>,
    /// Draw the difference A − B.
    pub hide_difference: bool,
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;
    use crate::test_support::delayed_chord;

    fn tone(n: usize, f: f64, phase: f64) -> Vec<f32> {
        (0..n)
            .map(|i| (std::f64::consts::TAU * f * i as f64 / 8000.0 + phase).sin() as f32)
            .collect()
    }

    #[test]
    fn identical_signals_agree_perfectly() {
        let x = tone(800, 440.0, 0.0);
        let a = agreement(3, &x, &x);
        assert_eq!(a.group, 3);
        assert_eq!(a.samples, 800);
        assert!((a.r - 1.0).abs() < 1e-12, "{}", a.r);
        assert_eq!(a.snr_db, MAX_AGREEMENT_DB);
    }

    #[test]
    fn agreement_measures_noise_and_inversion() {
        let x = tone(8000, 440.0, 0.0);
        // B = A + an error 1/10 of A's RMS: 20 dB.
        let e = tone(8000, 1234.0, 0.3);
        let y: Vec<f32> = x.iter().zip(&e).map(|(a, b)| a + 0.1 * b).collect();
        let a = agreement(0, &x, &y);
        assert!((a.snr_db - 20.0).abs() < 0.2, "{}", a.snr_db);
        assert!(a.r > 0.99 && a.r < 1.0, "{}", a.r);
        let inv: Vec<f32> = x.iter().map(|v| -v).collect();
        let a = agreement(0, &x, &inv);
        assert!((a.r + 1.0).abs() < 1e-9, "{}", a.r);
        assert!(
            (a.snr_db - 10.0 * 0.25f64.log10()).abs() < 0.01,
            "{}",
            a.snr_db
        );
        assert_eq!(agreement(0, &[], &[]).samples, 0);
    }

    #[test]
    fn a_delayed_b_is_aligned_and_agrees_closely() {
        let a = delayed_chord(4000, 0.0);
        for delay in [2.4, -1.83, 7.0, -0.5] {
            let b = delayed_chord(4000, delay);
            let before = agreement(0, &a, &b);
            let (moved, found) = align(&a, &b, 44_100);
            assert!((found - delay).abs() < 0.01, "{delay}: found {found}");
            assert_eq!(moved.len(), b.len());
            // The ends, where B had to be read past its samples, are left out.
            let after = agreement(0, &a[40..3960], &moved[40..3960]);
            // Half a sample of this chord reads 20 dB, more samples less.
            assert!(before.snr_db < 21.0, "{delay}: before {before:?}");
            assert!(after.snr_db > 50.0, "{delay}: after {after:?}");
        }
        // Already aligned: unchanged, and said so.
        let (same, none) = align(&a, &a, 44_100);
        assert_eq!(none, 0.0);
        assert_eq!(same, a);
        // A delay beyond ALIGN_MAX_LAG_S (1 ms = 44 samples) is not taken out.
        let far = delayed_chord(4000, 300.0);
        assert!(align(&a, &far, 44_100).1.abs() <= 45.0);
    }

    #[test]
    fn pairs_parse_and_bad_words_say_which() {
        assert_eq!(parse_pair("fused, flow"), Ok([Method::Fused, Method::Flow]));
        assert_eq!(
            parse_pair("edges,edges"),
            Ok([Method::Edges, Method::Edges])
        );
        assert!(parse_pair("fused").unwrap_err().contains("two methods"));
        assert!(
            parse_pair("fused,wavelet")
                .unwrap_err()
                .contains("\"wavelet\"")
        );
        assert_eq!(default_partner(Method::Fused), Method::Flow);
        assert_eq!(default_partner(Method::Flow), Method::Fused);
    }
}
