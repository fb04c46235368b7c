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

use super::wav::read::{SUBFORMAT_TAIL, TAG_EXTENSIBLE, TAG_FLOAT, TAG_PCM, le_u16, le_u32};
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
        let len = le_u32(header, 4) as usize;
        let here = at;
        at = at.saturating_add(8 + len + (len & 1));
        Some((here, id, len))
    })
}

/// The plain format chunk body for a `WAVE_FORMAT_EXTENSIBLE` body `fmt` of integer PCM or
/// IEEE float, at most two channels, every bit of each sample valid; `None` for any other.
///
/// - Integer PCM becomes `WAVE_FORMAT_PCM` (16 bytes: tag 1, then channels, rate, byte rate,
///   block align and bits). hound writes the extensible form for 24-bit samples; Tech 3285
///   describes PCM as tag 1, and readers that know only that tag (Python's `wave` before 3.12,
///   for one) refuse the extensible form.
/// - IEEE float becomes `WAVE_FORMAT_IEEE_FLOAT` (18 bytes: tag 3, the same fields, a zero
///   extension size); SoX warns that the extensible form's header is "missing extended part of
///   fmt chunk".
///
/// A transfer carries the plain form where it means the same.
fn plain_format(fmt: &[u8]) -> Option<Vec<u8>> {
    let extensible = fmt.len() >= 40 && le_u16(fmt, 0) == TAG_EXTENSIBLE;
    if !extensible
        || le_u16(fmt, 2) > 2
        || le_u16(fmt, 18) != le_u16(fmt, 14)
        || fmt[26..40] != SUBFORMAT_TAIL
    {
        return None;
    }
    let tag = le_u16(fmt, 24);
    let mut plain = tag.to_le_bytes().to_vec();
    plain.extend_from_slice(&fmt[2..16]);
    match tag {
        TAG_PCM => Some(plain),
        // WAVEFORMATEX: an extension size, zero.
        TAG_FLOAT => Some([plain, vec![0, 0]].concat()),
        _ => None,
    }
}

/// A RIFF chunk: `id`, the length of `body`, `body`, and the pad byte of an odd length.
fn chunk(id: &[u8; 4], body: &[u8]) -> Result<Vec<u8>, String> {
    let len = u32::try_from(body.len()).map_err(|_| format!("{} chunk too long", ascii_id(id)))?;
    let mut out = Vec::with_capacity(body.len() + 9);
    out.extend_from_slice(id);
    out.extend(len.to_le_bytes());
    out.extend_from_slice(body);
    if body.len() % 2 == 1 {
        out.push(0);
    }
    Ok(out)
}

/// A chunk id as text, for messages.
fn ascii_id(id: &[u8; 4]) -> String {
    String::from_utf8_lossy(id).trim_end().to_string()
}

/// How to make a WAV in memory a Broadcast Wave File without moving its samples: `head` (the
/// RIFF header, the chunks before `data` with the format chunk in its plain form where it
/// holds integer PCM or float of at most two channels, and a `fact` chunk after it where the
/// format is not plain PCM and the WAV has none, then the `bext` chunk), then
/// `wav[data_at..]` (the `data` chunk), then `pad` zero bytes.
#[derive(Debug)]
pub struct BextInsert {
    /// Everything before the `data` chunk, its RIFF size counting the whole file.
    pub head: Vec<u8>,
    /// Where the `data` chunk starts in the WAV.
    pub data_at: usize,
    /// The pad byte RIFF asks for after an odd-length `data` chunk that ends the file (hound
    /// writes none: 24-bit mono of an odd sample count), 0 or 1.
    pub pad: usize,
}

impl BextInsert {
    /// Plans a `bext` chunk of `info` before the `data` chunk of `wav` (a RIFF WAVE file in
    /// memory).
    ///
    /// # Errors
    /// A sentence when `wav` is not a RIFF WAVE file with a format and a `data` chunk.
    pub fn plan(wav: &[u8], info: &BroadcastInfo) -> Result<Self, String> {
        if wav.len() < 12 || &wav[0..4] != b"RIFF" || &wav[8..12] != b"WAVE" {
            return Err("not a RIFF WAVE file".into());
        }
        let mut head = b"RIFF\0\0\0\0WAVE".to_vec();
        let mut data = None;
        // The format's tag and block align, once read.
        let mut format = None;
        let mut has_fact = false;
        for (at, id, len) in chunks(wav) {
            if &id == b"data" {
                data = Some((at, len));
                break;
            }
            let body = wav
                .get(at + 8..at + 8 + len)
                .ok_or_else(|| format!("the {} chunk is cut short", ascii_id(&id)))?;
            if &id == b"fmt " {
                let body = plain_format(body).unwrap_or_else(|| body.to_vec());
                if body.len() < 16 {
                    return Err("the fmt chunk is cut short".into());
                }
                format = Some((le_u16(&body, 0), le_u16(&body, 12)));
                head.extend(chunk(&id, &body)?);
            } else {
                has_fact |= &id == b"fact";
                head.extend(chunk(&id, body)?);
            }
        }
        let (data_at, data_len) = data.ok_or("no data chunk")?;
        let (tag, align) = format.ok_or("no format chunk")?;
        if tag != TAG_PCM && !has_fact {
            // The sample frames per channel, which RIFF asks of every format but PCM.
            let frames = u32::try_from(data_len / usize::from(align.max(1)))
                .map_err(|_| "the WAV is too long for a fact chunk".to_string())?;
            head.extend(chunk(b"fact", &frames.to_le_bytes())?);
        }
        head.extend(chunk(b"bext", &info.payload())?);
        let pad = usize::from(data_len % 2 == 1 && wav.len() == data_at + 8 + data_len);
        let riff = u32::try_from(head.len() - 8 + (wav.len() - data_at) + pad)
            .map_err(|_| "the WAV is too long for a bext chunk".to_string())?;
        head[4..8].copy_from_slice(&riff.to_le_bytes());
        Ok(Self { head, data_at, pad })
    }

    /// Writes the Broadcast Wave File of `wav` (the one planned for) to `out`.
    ///
    /// # Errors
    /// What `out` fails with.
    pub fn write(&self, wav: &[u8], out: &mut impl std::io::Write) -> std::io::Result<()> {
        out.write_all(&self.head)?;
        out.write_all(&wav[self.data_at..])?;
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
    fn with_bext(wav: &[u8], info: &BroadcastInfo) -> Result<Vec<u8>, String> {
        let insert = BextInsert::plan(wav, info)?;
        let mut out = Vec::with_capacity(wav.len() + insert.head.len() + insert.pad);
        insert.write(wav, &mut out).map_err(|e| e.to_string())?;
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
        let bwf = with_bext(&std::fs::read(&plain).unwrap(), &info).unwrap();
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
        // hound's extensible format chunk for 24 bits became the plain PCM one: tag 1, two
        // channels, 44.1 kHz, 6 bytes a frame, 24 bits.
        assert_eq!(&bwf[12..20], b"fmt \x10\0\0\0");
        assert_eq!(&bwf[20..24], [1, 0, 2, 0]);
        assert_eq!(&bwf[32..36], [6, 0, 24, 0]);
        let path = dir.path().join("bwf.wav");
        std::fs::write(&path, &bwf).unwrap();
        let (a, b) = (
            crate::io::wav::read_wav(&plain).unwrap(),
            crate::io::wav::read_wav(&path).unwrap(),
        );
        assert_eq!(a.channels, b.channels);
        assert!(with_bext(b"RIFF\0\0\0\0WAVEfmt ", &info).is_err());

        // 32-bit float becomes the plain IEEE float chunk (tag 3, 18 bytes) with the `fact`
        // chunk RIFF asks for beside it (the frame count), and reads back.
        let float = dir.path().join("float.wav");
        crate::io::wav::write_wav(&float, &audio, WavBits::Float32, false).unwrap();
        let bwf = with_bext(&std::fs::read(&float).unwrap(), &info).unwrap();
        assert_eq!(&bwf[12..22], b"fmt \x12\0\0\0\x03\0");
        assert_eq!(&bwf[32..38], [8, 0, 32, 0, 0, 0]);
        let frames = u32::try_from(audio.channels[0].len()).unwrap();
        assert_eq!(&bwf[38..42], b"fact");
        assert_eq!(
            &bwf[42..50],
            [&4u32.to_le_bytes()[..], &frames.to_le_bytes()].concat()
        );
        let path = dir.path().join("float-bwf.wav");
        std::fs::write(&path, &bwf).unwrap();
        assert_eq!(
            crate::io::wav::read_wav(&path).unwrap().channels,
            crate::io::wav::read_wav(&float).unwrap().channels
        );

        // 24-bit mono of three samples: nine bytes of data, then the pad byte RIFF asks for.
        let odd = Audio {
            sample_rate_hz: 44_100,
            channels: vec![vec![0.5, -0.25, 0.125]],
        };
        let plain = dir.path().join("odd.wav");
        crate::io::wav::write_wav(&plain, &odd, WavBits::Int24, false).unwrap();
        let bwf = with_bext(&std::fs::read(&plain).unwrap(), &info).unwrap();
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
