//! Broadcast Wave: the `bext` chunk (EBU Tech 3285) that makes a transfer's WAV describe itself — what was transferred, by what, how, and its coding history (EBU R98).
//!
//! Archives keep preservation copies as Broadcast Wave Files: a WAV with a `bext` chunk before
//! its `data`. groovescope's transfers carry one: the description, `groovescope` as
//! originator, a reference made of the scan's and the params' fingerprints, and two coding
//! history lines, the disc and the optical transfer (decoder and filters in words). The
//! origination date and time are left empty (outside the letter of Tech 3285, which most
//! readers accept), so one transfer always gives the same bytes: a merged side matches a
//! one-process run, and a scan's folder its store. Readers that do not know the chunk skip it,
//! as RIFF says.

use super::wav::{Audio, WavBits};
use crate::meta::{Cut, ScanMeta};

/// Bytes of the fixed part of a version 1 `bext` chunk, before the coding history.
const FIXED_BYTES: usize = 602;

/// What a `bext` chunk says.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BroadcastInfo {
    /// What the sound is (at most 256 ASCII characters are kept).
    pub description: String,
    /// The originator's reference (at most 32 ASCII characters are kept).
    pub reference: String,
    /// Coding history lines, oldest first (`A=…,F=…,W=…,M=…,T=…`).
    pub coding_history: Vec<String>,
}

/// `text` as printable ASCII, at most `max` bytes: the signs the filter descriptions use
/// become their ASCII look-alikes, anything else `?`.
fn ascii(text: &str, max: usize) -> Vec<u8> {
    text.chars()
        .map(|c| match c {
            c if c.is_ascii() && !c.is_ascii_control() => c as u8,
            '−' | '–' | '—' => b'-',
            'µ' | 'μ' => b'u',
            '×' => b'x',
            _ => b'?',
        })
        .take(max)
        .collect()
}

/// `v` with at most three decimals and no trailing zeros (16.667, 78).
#[must_use]
pub fn short_number(v: f64) -> String {
    let text = format!("{v:.3}");
    text.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// `text` for a coding history `T=` field: no commas (they separate the fields).
fn free_text(text: &str) -> String {
    text.replace(',', ";")
}

/// "mono" or "stereo", for the `M=` field.
fn mode(channels: usize) -> &'static str {
    if channels == 2 { "stereo" } else { "mono" }
}

/// The disc a scan shows, in words: its cut, speed and radius.
#[must_use]
pub fn disc_words(meta: &ScanMeta) -> String {
    let cut = match meta.record.cut {
        Cut::Lateral => "lateral-cut",
        Cut::Stereo => "45/45 stereo",
        Cut::Vertical => "vertical-cut",
    };
    format!(
        "{cut} disc at {} rpm, groove radius {} mm",
        short_number(meta.record.rpm),
        short_number(meta.record.radius_mm)
    )
}

impl BroadcastInfo {
    /// The record of an optical transfer of `source` (the disc or image, in words) by
    /// `process` (the decoder and filters, in words) to `audio` at `bits`, with `reference`
    /// (at most 32 characters: fingerprints that tie the WAV to its input and settings).
    #[must_use]
    pub fn optical_transfer(
        source: &str,
        process: &str,
        reference: &str,
        audio: &Audio,
        bits: WavBits,
    ) -> Self {
        let (width, float) = match bits {
            WavBits::Int16 => ("16", ""),
            WavBits::Int24 => ("24", ""),
            WavBits::Float32 => ("32", " (IEEE float samples)"),
        };
        let channels = mode(audio.channels.len());
        Self {
            description: format!("Optical transfer by groovescope of a {source}"),
            reference: reference.to_string(),
            coding_history: vec![
                format!("A=ANALOGUE,M={channels},T={}", free_text(source)),
                format!(
                    "A=PCM,F={},W={width},M={channels},T={}",
                    audio.sample_rate_hz,
                    free_text(&format!(
                        "groovescope {} optical transfer{float}: {process}",
                        env!("CARGO_PKG_VERSION")
                    ))
                ),
            ],
        }
    }

    /// The chunk's payload (version 1; no date, time, time reference or UMID), its length even
    /// so no pad byte follows it.
    #[must_use]
    pub fn payload(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(FIXED_BYTES + 256);
        let mut field = |text: &str, len: usize| {
            let mut bytes = ascii(text, len);
            bytes.resize(len, 0);
            out.extend(bytes);
        };
        field(&self.description, 256);
        field("groovescope", 32);
        field(&self.reference, 32);
        field("", 10); // OriginationDate: empty, see the module docs
        field("", 8); // OriginationTime
        out.extend(0u64.to_le_bytes()); // TimeReference
        out.extend(1u16.to_le_bytes()); // Version
        out.extend([0u8; 64]); // UMID
        out.extend([0u8; 190]); // Reserved
        let mut history: Vec<u8> = self
            .coding_history
            .iter()
            .flat_map(|line| {
                let mut l = ascii(line, usize::MAX);
                l.extend(b"\r\n");
                l
            })
            .collect();
        history.push(0);
        if history.len() % 2 == 1 {
            history.push(0);
        }
        out.extend(history);
        out
    }
}

/// The chunks of a RIFF file in memory after its `WAVE` header: where each starts, its id and
/// its length (a chunk cut short by the file's end is the last one yielded).
fn chunks(wav: &[u8]) -> impl Iterator<Item = (usize, [u8; 4], usize)> + '_ {
    let mut at = 12;
    std::iter::from_fn(move || {
        let header = wav.get(at..at + 8)?;
        let id = [header[0], header[1], header[2], header[3]];
        let len = u32::from_le_bytes([header[4], header[5], header[6], header[7]]) as usize;
        let here = at;
        at = at.saturating_add(8 + len + (len & 1));
        Some((here, id, len))
    })
}

/// How to make a WAV in memory a Broadcast Wave File without moving its samples: `wav[..at]`
/// (its RIFF size already grown), then `chunk`, then `wav[at..]`, then `pad` zero bytes.
#[derive(Debug)]
pub struct BextInsert {
    /// Where the `bext` chunk goes: the start of the `data` chunk.
    pub at: usize,
    /// The whole `bext` chunk, header included.
    pub chunk: Vec<u8>,
    /// The pad byte RIFF asks for after an odd-length `data` chunk that ends the file (hound
    /// writes none: 24-bit mono of an odd sample count), 0 or 1.
    pub pad: usize,
}

impl BextInsert {
    /// Plans a `bext` chunk of `info` before the `data` chunk of `wav` (a RIFF WAVE file in
    /// memory), growing its RIFF size for the chunk and the pad byte.
    ///
    /// # Errors
    /// A sentence when `wav` is not a RIFF WAVE file with a `data` chunk.
    pub fn plan(wav: &mut [u8], info: &BroadcastInfo) -> Result<Self, String> {
        if wav.len() < 12 || &wav[0..4] != b"RIFF" || &wav[8..12] != b"WAVE" {
            return Err("not a RIFF WAVE file".into());
        }
        let (at, _, data_len) = chunks(wav)
            .find(|(_, id, _)| id == b"data")
            .ok_or("no data chunk")?;
        let payload = info.payload();
        let mut chunk = b"bext".to_vec();
        let len = u32::try_from(payload.len()).map_err(|_| "bext chunk too long".to_string())?;
        chunk.extend(len.to_le_bytes());
        chunk.extend(payload);
        let pad = usize::from(data_len % 2 == 1 && wav.len() == at + 8 + data_len);
        let riff = u32::from_le_bytes([wav[4], wav[5], wav[6], wav[7]]);
        let grown = u32::try_from(chunk.len() + pad)
            .ok()
            .and_then(|n| riff.checked_add(n))
            .ok_or("the WAV is too long for a bext chunk")?;
        wav[4..8].copy_from_slice(&grown.to_le_bytes());
        Ok(Self { at, chunk, pad })
    }

    /// Writes `wav` (as [`Self::plan`] left it) with the chunk to `out`.
    ///
    /// # Errors
    /// What `out` fails with.
    pub fn write(&self, wav: &[u8], out: &mut impl std::io::Write) -> std::io::Result<()> {
        out.write_all(&wav[..self.at])?;
        out.write_all(&self.chunk)?;
        out.write_all(&wav[self.at..])?;
        out.write_all(&[0u8; 1][..self.pad])
    }
}

/// The `bext` chunk of a WAV in memory, if it has one: its description, originator,
/// reference and coding history lines.
#[must_use]
pub fn read_bext(wav: &[u8]) -> Option<(String, String, String, Vec<String>)> {
    let (at, _, len) = chunks(wav).find(|(_, id, _)| id == b"bext")?;
    let p = wav.get(at + 8..at + 8 + len)?;
    let text = |b: &[u8]| {
        String::from_utf8_lossy(b)
            .trim_end_matches('\0')
            .to_string()
    };
    let history = text(p.get(FIXED_BYTES..)?);
    Some((
        text(p.get(0..256)?),
        text(p.get(256..288)?),
        text(p.get(288..320)?),
        history
            .split("\r\n")
            .filter(|l| !l.is_empty())
            .map(str::to_string)
            .collect(),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `wav` (a RIFF WAVE file in memory) with a `bext` chunk of `info` before its `data` chunk
    /// ([`BextInsert`], made one buffer).
    ///
    /// # Errors
    /// As [`BextInsert::plan`].
    fn with_bext(mut wav: Vec<u8>, info: &BroadcastInfo) -> Result<Vec<u8>, String> {
        let insert = BextInsert::plan(&mut wav, info)?;
        let mut out = Vec::with_capacity(wav.len() + insert.chunk.len() + insert.pad);
        insert.write(&wav, &mut out).map_err(|e| e.to_string())?;
        Ok(out)
    }

    #[test]
    fn a_bext_chunk_goes_before_the_data_and_the_wav_still_reads() {
        let audio = Audio {
            sample_rate_hz: 44_100,
            channels: vec![vec![0.0, 0.5, -0.5, 0.25], vec![0.1, 0.2, 0.3, 0.4]],
        };
        let dir = tempfile::tempdir().unwrap();
        let plain = dir.path().join("plain.wav");
        crate::io::wav::write_wav(&plain, &audio, WavBits::Int24, false).unwrap();
        let info = BroadcastInfo::optical_transfer(
            "45/45 stereo disc at 33.3 rpm, groove radius 100 mm",
            "edges decoder, low-pass 3000 Hz",
            "0123456789abcdef0123456789abcdefTOO LONG",
            &audio,
            WavBits::Int24,
        );
        let bwf = with_bext(std::fs::read(&plain).unwrap(), &info).unwrap();
        let (description, originator, reference, history) = read_bext(&bwf).unwrap();
        assert!(description.starts_with("Optical transfer by groovescope of a 45/45"));
        assert_eq!(originator, "groovescope");
        assert_eq!(reference, "0123456789abcdef0123456789abcdef");
        assert_eq!(
            history[0],
            "A=ANALOGUE,M=stereo,T=45/45 stereo disc at 33.3 rpm; groove radius 100 mm"
        );
        assert!(
            history[1].starts_with("A=PCM,F=44100,W=24,M=stereo,T=groovescope ")
                && history[1].ends_with("optical transfer: edges decoder; low-pass 3000 Hz"),
            "{}",
            history[1]
        );
        // The RIFF size counts the new chunk, and the samples read back as they were written.
        let riff = u32::from_le_bytes([bwf[4], bwf[5], bwf[6], bwf[7]]) as usize;
        assert_eq!(riff + 8, bwf.len());
        let path = dir.path().join("bwf.wav");
        std::fs::write(&path, &bwf).unwrap();
        let (a, b) = (
            crate::io::wav::read_wav(&plain).unwrap(),
            crate::io::wav::read_wav(&path).unwrap(),
        );
        assert_eq!(a.channels, b.channels);
        assert!(with_bext(b"RIFF\0\0\0\0WAVEfmt ".to_vec(), &info).is_err());

        // 24-bit mono of three samples: nine bytes of data, then the pad byte RIFF asks for.
        let odd = Audio {
            sample_rate_hz: 44_100,
            channels: vec![vec![0.5, -0.25, 0.125]],
        };
        let plain = dir.path().join("odd.wav");
        crate::io::wav::write_wav(&plain, &odd, WavBits::Int24, false).unwrap();
        let bwf = with_bext(std::fs::read(&plain).unwrap(), &info).unwrap();
        assert_eq!(bwf.len() % 2, 0);
        let riff = u32::from_le_bytes([bwf[4], bwf[5], bwf[6], bwf[7]]) as usize;
        assert_eq!(riff + 8, bwf.len());
        let path = dir.path().join("odd-bwf.wav");
        std::fs::write(&path, &bwf).unwrap();
        assert_eq!(
            crate::io::wav::read_wav(&path).unwrap().channels,
            crate::io::wav::read_wav(&plain).unwrap().channels
        );
    }
}
