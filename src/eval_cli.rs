//! The `eval` subcommand: a recovered WAV scored against a reference (r, envelope r, SNR), stereo pairs channel by channel.

use std::borrow::Cow;
use std::path::Path;

use anyhow::{Result, bail};

use crate::io::wav::read_finite_wav;

/// A recovered channel and the reference channel it is scored against.
type ChannelPair<'a> = (Cow<'a, [f32]>, Cow<'a, [f32]>);

/// Below this |r| the scores say the sounds are hardly alike (see [`run_eval`]'s warning).
const LOW_R: f64 = 0.3;

/// What `eval --json` prints: one object whatever the channels.
#[derive(serde::Serialize)]
struct EvalJson<'a> {
    /// A single comparison's scores (mono, or channels mixed to mono) at the top level too,
    /// as `eval --json` printed them before `channels` came.
    #[serde(flatten)]
    only: Option<&'a crate::pipeline::eval::Scores>,
    /// Channels that did not pair up (stereo against mono) were mixed to mono.
    mixed_to_mono: bool,
    /// Each channel pair's scores in order: one for mono, two for a stereo pair.
    channels: &'a [crate::pipeline::eval::Scores],
}

/// Runs `eval`: prints the scores as text or JSON (one object, `EvalJson`; it was an object
/// for a mono comparison and an array for a stereo one).
///
/// # Errors
/// An unreadable or non-finite sound, channels that do not pair up, too few overlapping
/// samples, or a bad `--max-lag-ms`; each names its file.
pub fn run_eval(recovered: &Path, reference: &Path, json: bool, max_lag_ms: f64) -> Result<()> {
    if !(max_lag_ms.is_finite() && max_lag_ms >= 0.0) {
        bail!("--max-lag-ms must be a non-negative number, got {max_lag_ms}");
    }
    let (rec, refa) = (read_finite_wav(recovered)?, read_finite_wav(reference)?);
    // Channel by channel: a stereo pair mixed to mono can cancel (left = −right scores 0).
    let (n_rec, n_ref) = (rec.channels.len(), refa.channels.len());
    // Borrowed where they pair up as they are: a side's channels are not copied.
    let mixed = n_rec != n_ref;
    let channels: Vec<ChannelPair> = if n_rec == n_ref {
        rec.channels
            .iter()
            .zip(&refa.channels)
            .map(|(a, b)| (Cow::Borrowed(a.as_slice()), Cow::Borrowed(b.as_slice())))
            .collect()
    } else if n_rec == 1 || n_ref == 1 {
        crate::tell!(
            "warning: the recovered sound has {n_rec} channels and the reference {n_ref}: scored as their mono mixes"
        );
        vec![(Cow::Owned(rec.mono()), Cow::Owned(refa.mono()))]
    } else {
        bail!(
            "the recovered sound has {n_rec} channels and the reference {n_ref}: {}",
            reference.display()
        );
    };
    let max_lag = (max_lag_ms / 1000.0 * f64::from(rec.sample_rate_hz)) as usize;
    let mut all = Vec::with_capacity(channels.len());
    for (rec_ch, ref_ch) in &channels {
        let ref_ch = if refa.sample_rate_hz == rec.sample_rate_hz {
            Cow::Borrowed(ref_ch.as_ref())
        } else {
            Cow::Owned(crate::pipeline::audio_signal::resample(
                ref_ch,
                f64::from(refa.sample_rate_hz),
                rec.sample_rate_hz,
            )?)
        };
        let Some(scores) =
            crate::pipeline::eval::evaluate(rec_ch, &ref_ch, max_lag, rec.sample_rate_hz)
        else {
            bail!(
                "too few overlapping samples to compare ({} in {}, {} in the reference {})",
                rec_ch.len(),
                recovered.display(),
                ref_ch.len(),
                reference.display()
            );
        };
        // Two sounds further apart than the search reaches score as noise: a best lag at the
        // search's edge, or hardly any likeness, is said with the way to look further.
        let at_edge = max_lag > 0 && scores.lag_samples.unsigned_abs() as usize >= max_lag;
        // A silent sound (or a mix whose channels cancel) scores 0 at any lag: said as such.
        let silent = [
            (rec_ch.as_ref(), recovered, n_rec),
            (ref_ch.as_ref(), reference, n_ref),
        ]
        .into_iter()
        .find(|(x, _, _)| x.iter().all(|v| *v == x[0]));
        if let Some((_, path, n)) = silent {
            let what = if mixed && n > 1 {
                "the mono mix of its channels is silent (they cancel)"
            } else {
                "it is silent"
            };
            crate::tell!("warning: nothing to score: {what}: {}", path.display());
        } else if at_edge || scores.r.abs() < LOW_R {
            crate::tell!(
                "warning: r {:.3} at lag {} samples: if the sounds are further apart than the \
                 ±{max_lag_ms} ms searched, --max-lag-ms looks further: {}",
                scores.r,
                scores.lag_samples,
                recovered.display()
            );
        }
        all.push(scores);
    }
    let mut text = String::new();
    if json {
        text = serde_json::to_string_pretty(&EvalJson {
            only: match all.as_slice() {
                [one] => Some(one),
                _ => None,
            },
            mixed_to_mono: mixed,
            channels: &all,
        })?;
        text.push('\n');
    } else {
        for (k, scores) in all.iter().enumerate() {
            if all.len() > 1 {
                text += &format!("channel {}\n", k + 1);
            }
            text += &format!("r            {:.4}\n", scores.r);
            text += &format!("envelope r   {}\n", scores.envelope_r_text(4));
            text += &format!("SNR          {:.2} dB\n", scores.snr_db);
            text += &format!("lag          {} samples\n", scores.lag_text(3));
            text += &format!("samples      {}\n", scores.samples);
            if let Some(i) = scores.inverted {
                text += &format!(
                    "inverted     r {:.4} at lag {} samples: the polarity is likely reversed\n",
                    i.r, i.lag_samples
                );
            }
        }
    }
    crate::stdout::write_text(&text)
}
