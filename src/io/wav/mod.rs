//! WAV files: reading (any integer PCM or float WAV: [`read`]) and atomic writing (16/24-bit integer or 32-bit float, mono or stereo, via hound).

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::limits::MAX_WAV_SAMPLES;
use super::{LoadError, atomic::write_atomic_with};

pub mod read;

/// Sample encoding of an exported WAV file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum WavBits {
    /// 16-bit integer PCM.
    #[serde(rename = "16")]
    Int16,
    /// 24-bit integer PCM.
    #[default]
    #[serde(rename = "24")]
    Int24,
    /// 32-bit IEEE float.
    #[serde(rename = "32f")]
    Float32,
}

impl std::str::FromStr for WavBits {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "16" => Ok(Self::Int16),
            "24" => Ok(Self::Int24),
            "32f" => Ok(Self::Float32),
            // Integer or float? groovescope writes no 32-bit integer samples, and a transfer
            // that is not what was asked for is worse than a refusal.
            "32" => Err(
                "\"32\" could mean integer or float samples: use 32f for 32-bit float (16 and 24 \
                 are integer)"
                    .into(),
            ),
            _ => Err(format!(
                "unknown WAV sample format {s:?} (use 16, 24 or 32f)"
            )),
        }
    }
}

/// Audio held as one `Vec<f32>` per channel, values nominally in `[-1, 1]`.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Audio {
    /// Sample rate in Hz.
    pub sample_rate_hz: u32,
    /// One buffer per channel, all the same length.
    pub channels: Vec<Vec<f32>>,
}

impl Audio {
    /// Frames (samples per channel).
    #[must_use]
    pub fn len(&self) -> usize {
        self.channels.first().map_or(0, Vec::len)
    }

    /// True when there are no samples.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Duration in seconds.
    #[must_use]
    pub fn duration_secs(&self) -> f64 {
        if self.sample_rate_hz == 0 {
            0.0
        } else {
            self.len() as f64 / f64::from(self.sample_rate_hz)
        }
    }

    /// Length and rate as words, for summaries: `1.234 s at 44100 Hz`.
    #[must_use]
    pub fn length_label(&self) -> String {
        format!(
            "{:.3} s at {} Hz",
            self.duration_secs(),
            self.sample_rate_hz
        )
    }

    /// The channel count as words: `1 channel`, `2 channels`.
    #[must_use]
    pub fn channels_label(&self) -> String {
        match self.channels.len() {
            1 => "1 channel".to_string(),
            n => format!("{n} channels"),
        }
    }

    /// The mean of all channels.
    #[must_use]
    pub fn mono(&self) -> Vec<f32> {
        let n = self.channels.len().max(1) as f32;
        (0..self.len())
            .map(|i| self.channels.iter().map(|c| c[i]).sum::<f32>() / n)
            .collect()
    }
}

/// Reads a WAV file (integer PCM of any depth and container, or 32/64-bit float; see [`read`])
/// into `[-1, 1]` floats.
///
/// # Errors
/// [`LoadError::Sound`] naming the file when it is missing, not WAV, unsupported, empty or
/// longer than [`MAX_WAV_SAMPLES`].
pub fn read_wav(path: &Path) -> Result<Audio, LoadError> {
    let file = std::fs::File::open(path).map_err(|e| LoadError::Sound {
        problem: format!("cannot read WAV: {e}"),
        path: path.to_path_buf(),
    })?;
    read_wav_from(std::io::BufReader::new(file), path)
}

/// Lowest reference rate scored against (Hz): nothing slower records a groove's sound, and
/// resampling from it to the clip's rate costs in proportion to the ratio.
pub const MIN_REFERENCE_RATE_HZ: u32 = 1000;

/// [`read_wav`] for a sound to score: NaN or infinite samples are refused rather than
/// counted as silence.
///
/// # Errors
/// As [`read_wav`], and [`LoadError::Sound`] naming the file when a sample is not finite.
pub fn read_finite_wav(path: &Path) -> Result<Audio, LoadError> {
    let audio = read_wav(path)?;
    if audio.channels.iter().flatten().any(|v| !v.is_finite()) {
        return Err(LoadError::Sound {
            problem: "the sound holds NaN or infinite samples".into(),
            path: path.to_path_buf(),
        });
    }
    Ok(audio)
}

/// [`read_finite_wav`] for a reference to score against: its rate must also be at least
/// [`MIN_REFERENCE_RATE_HZ`].
///
/// # Errors
/// As [`read_finite_wav`], and [`LoadError::Sound`] naming the file for a lower rate.
pub fn read_reference_wav(path: &Path) -> Result<Audio, LoadError> {
    let audio = read_finite_wav(path)?;
    if audio.sample_rate_hz < MIN_REFERENCE_RATE_HZ {
        return Err(LoadError::Sound {
            problem: format!(
                "its rate, {} Hz, is below the {MIN_REFERENCE_RATE_HZ} Hz a recording of the \
                 groove's sound needs",
                audio.sample_rate_hz
            ),
            path: path.to_path_buf(),
        });
    }
    Ok(audio)
}

/// Reads WAV data from `source` (see [`read_wav`]); `path` names it in errors. The sample
/// count in the header is checked against [`MAX_WAV_SAMPLES`] before samples are read.
///
/// # Errors
/// As [`read_wav`].
pub fn read_wav_from(mut source: impl std::io::Read, path: &Path) -> Result<Audio, LoadError> {
    let (sample_rate_hz, channels) =
        read::read_audio(&mut source, MAX_WAV_SAMPLES).map_err(|problem| LoadError::Sound {
            problem,
            path: path.to_path_buf(),
        })?;
    Ok(Audio {
        sample_rate_hz,
        channels,
    })
}

/// Writes audio as WAV atomically; never replaces an existing file unless `overwrite`.
/// Samples outside `[-1, 1]` are clipped for integer formats.
///
/// # Errors
/// [`LoadError::Io`] / [`LoadError::Sound`] naming the file.
pub fn write_wav(
    path: &Path,
    audio: &Audio,
    bits: WavBits,
    overwrite: bool,
) -> Result<(), LoadError> {
    let data = encode_wav(path, audio, bits)?;
    super::write_atomic(path, &data, overwrite)
}

/// Writes a transfer as a Broadcast Wave File: [`write_wav`]'s WAV with a `bext` chunk of
/// `info` before its samples (see [`super::bwf`]).
///
/// # Errors
/// As [`write_wav`].
pub fn write_transfer_wav(
    path: &Path,
    audio: &Audio,
    bits: WavBits,
    overwrite: bool,
    info: &super::bwf::BroadcastInfo,
) -> Result<(), LoadError> {
    let data = encode_wav(path, audio, bits)?;
    // The samples stay where `encode_wav` put them: the header is written in front of them.
    let insert = super::bwf::BextInsert::plan(&data, info).map_err(|problem| LoadError::Sound {
        problem: format!("cannot write the broadcast chunk: {problem}"),
        path: path.to_path_buf(),
    })?;
    write_atomic_with(path, overwrite, |w| insert.write(&data, w))
}

/// `audio` encoded as a WAV file in memory (`path` names it in errors).
fn encode_wav(path: &Path, audio: &Audio, bits: WavBits) -> Result<Vec<u8>, LoadError> {
    let nch = audio.channels.len();
    if nch == 0 || nch > 2 || audio.channels.iter().any(|c| c.len() != audio.len()) {
        return Err(LoadError::Sound {
            problem: format!("cannot write {nch} channels of unequal or unsupported layout"),
            path: path.to_path_buf(),
        });
    }
    let spec = hound::WavSpec {
        channels: nch as u16,
        sample_rate: audio.sample_rate_hz,
        bits_per_sample: match bits {
            WavBits::Int16 => 16,
            WavBits::Int24 => 24,
            WavBits::Float32 => 32,
        },
        sample_format: if bits == WavBits::Float32 {
            hound::SampleFormat::Float
        } else {
            hound::SampleFormat::Int
        },
    };
    let mut bytes = std::io::Cursor::new(Vec::with_capacity(audio.len() * nch * 4 + 64));
    {
        let mut w = hound::WavWriter::new(&mut bytes, spec).map_err(|e| LoadError::Sound {
            problem: format!("cannot encode WAV: {e}"),
            path: path.to_path_buf(),
        })?;
        let full = match bits {
            WavBits::Int16 => 32767.0,
            WavBits::Int24 => 8_388_607.0,
            WavBits::Float32 => 1.0,
        };
        let res: Result<(), hound::Error> = (|| {
            for i in 0..audio.len() {
                for c in &audio.channels {
                    let v = if c[i].is_finite() { c[i] } else { 0.0 };
                    if bits == WavBits::Float32 {
                        w.write_sample(v)?;
                    } else {
                        w.write_sample((f64::from(v.clamp(-1.0, 1.0)) * full).round() as i32)?;
                    }
                }
            }
            w.finalize()
        })();
        res.map_err(|e| LoadError::Sound {
            problem: format!("cannot encode WAV: {e}"),
            path: path.to_path_buf(),
        })?;
    }
    Ok(bytes.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn all_formats_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let audio = Audio {
            sample_rate_hz: 48_000,
            channels: vec![vec![0.0, 0.5, -0.5, 0.25], vec![0.1, -0.1, 0.9, -0.9]],
        };
        for (i, bits) in [WavBits::Int16, WavBits::Int24, WavBits::Float32]
            .into_iter()
            .enumerate()
        {
            let p = dir.path().join(format!("{i}.wav"));
            write_wav(&p, &audio, bits, false).unwrap();
            let back = read_wav(&p).unwrap();
            assert_eq!(back.sample_rate_hz, 48_000);
            assert_eq!(back.channels.len(), 2);
            for (a, b) in audio.channels[1].iter().zip(&back.channels[1]) {
                assert!((a - b).abs() < 1e-4, "{bits:?}: {a} vs {b}");
            }
        }
        assert!(write_wav(&dir.path().join("0.wav"), &audio, WavBits::Int16, false).is_err());
    }

    #[test]
    fn sample_formats_parse_and_an_ambiguous_32_is_refused() {
        assert_eq!("24".parse::<WavBits>(), Ok(WavBits::Int24));
        assert_eq!("32f".parse::<WavBits>(), Ok(WavBits::Float32));
        assert!("32".parse::<WavBits>().unwrap_err().contains("32f"));
    }

    #[test]
    fn non_wav_is_a_clear_error() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("x.wav");
        std::fs::write(&p, b"hello").unwrap();
        assert!(read_wav(&p).unwrap_err().to_string().contains("x.wav"));
    }
}
