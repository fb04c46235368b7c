//! WAV reading as RIFF and Microsoft's WAVE format describe it: chunks walked with their pad bytes, integer PCM of 1 to 32 valid bits in a 1- to 4-byte container, and 32- or 64-bit IEEE float, in the plain or the `WAVE_FORMAT_EXTENSIBLE` format chunk.
//!
//! - **Chunks.** A chunk of odd length is followed by one pad byte that its length does not
//!   count. Chunks other than `fmt ` and `data` (`LIST`, `bext`, `JUNK`, …) are skipped; the
//!   format must come before the samples.
//! - **Integers.** An integer sample fills its container (`block_align / channels` bytes,
//!   little-endian, two's complement; 8-bit samples are unsigned around 128). When fewer bits
//!   are valid than the container holds, WAVEFORMATEXTENSIBLE puts them at the top and zeroes
//!   the rest, so the container's value over its full scale is the sample. Some writers put
//!   them at the bottom instead, sign-extended (hound does for 24 bits in 4 bytes): a file whose
//!   unused low bits are not all zero is read that way when every sample fits the valid bits,
//!   and refused when one does not. A sample `v` of a `b`-bit container reads as `v / 2^(b−1)`.
//! - **Floats** are read as they are; 64-bit ones are rounded to `f32`.
//! - **A data length of 0xFFFFFFFF** (a recorder streaming its file never filled it in) reads
//!   the samples up to the end of the file.

use std::io::Read;

/// `WAVE_FORMAT_PCM`: integer samples.
pub(crate) const TAG_PCM: u16 = 1;
/// `WAVE_FORMAT_IEEE_FLOAT`.
pub(crate) const TAG_FLOAT: u16 = 3;
/// `WAVE_FORMAT_EXTENSIBLE`: the real format is the sub-format GUID's.
pub(crate) const TAG_EXTENSIBLE: u16 = 0xfffe;
/// The tail of a `WAVE_FORMAT_EXTENSIBLE` sub-format GUID that stands for a plain format: its
/// first two bytes are then that format's tag (KSDATAFORMAT_SUBTYPE_PCM is tag 1,
/// KSDATAFORMAT_SUBTYPE_IEEE_FLOAT tag 3).
pub(crate) const SUBFORMAT_TAIL: [u8; 14] = [
    0x00, 0x00, 0x00, 0x00, 0x10, 0x00, 0x80, 0x00, 0x00, 0xaa, 0x00, 0x38, 0x9b, 0x71,
];
/// Longest format chunk read (the extensible one is 40 bytes; vendors add a little).
const MAX_FORMAT_BYTES: u32 = 1024;
/// Samples (all channels) decoded at a time: whole frames of them, at least one.
const BLOCK_SAMPLES: usize = 32_768;

/// A little-endian `u16` of `bytes` at `at`.
pub(crate) fn le_u16(bytes: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([bytes[at], bytes[at + 1]])
}

/// A little-endian `u32` of `bytes` at `at`.
pub(crate) fn le_u32(bytes: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]])
}

/// What the format chunk says of the samples.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Format {
    /// Channels, interleaved.
    pub channels: u16,
    /// Frames per second.
    pub rate_hz: u32,
    /// Bytes that hold one sample.
    pub container_bytes: u16,
    /// Bits of each sample that carry sound (integers; at most the container's).
    pub valid_bits: u16,
    /// IEEE float samples rather than integers.
    pub float: bool,
}

/// The format chunk's body read as a [`Format`], or why it cannot be read.
pub(crate) fn parse_format(body: &[u8]) -> Result<Format, String> {
    if body.len() < 16 {
        return Err(format!(
            "its format chunk is {} bytes, shorter than the 16 every WAV has",
            body.len()
        ));
    }
    let mut tag = le_u16(body, 0);
    let channels = le_u16(body, 2);
    let rate_hz = le_u32(body, 4);
    let block_align = le_u16(body, 12);
    let mut valid_bits = le_u16(body, 14);
    if channels == 0 || rate_hz == 0 {
        return Err("WAV header has no channels or a zero sample rate".into());
    }
    if block_align == 0 || !block_align.is_multiple_of(channels) {
        return Err(format!(
            "its block of {block_align} bytes does not hold {channels} channels of whole bytes"
        ));
    }
    let container_bytes = block_align / channels;
    if tag == TAG_EXTENSIBLE {
        if body.len() < 40 || body[26..40] != SUBFORMAT_TAIL {
            return Err(
                "its extensible format names a sub-format other than integer PCM or float".into(),
            );
        }
        tag = le_u16(body, 24);
        // Zero valid bits: the writer did not say, so every bit of the container is valid.
        let extensible_bits = le_u16(body, 18);
        if extensible_bits != 0 {
            valid_bits = extensible_bits;
        }
    }
    match tag {
        TAG_PCM if (1..=4).contains(&container_bytes) => {
            if valid_bits == 0 || valid_bits > container_bytes * 8 {
                return Err(format!(
                    "its header gives {valid_bits} valid bits in {container_bytes}-byte samples"
                ));
            }
            Ok(Format {
                channels,
                rate_hz,
                container_bytes,
                valid_bits,
                float: false,
            })
        }
        TAG_FLOAT if container_bytes == 4 || container_bytes == 8 => Ok(Format {
            channels,
            rate_hz,
            container_bytes,
            valid_bits: container_bytes * 8,
            float: true,
        }),
        TAG_PCM | TAG_FLOAT => Err(format!(
            "{container_bytes}-byte {} samples are not supported (integers of 1 to 4 bytes, \
             floats of 4 or 8)",
            if tag == TAG_PCM { "integer" } else { "float" }
        )),
        _ => Err(format!(
            "its format tag {tag:#06x} is compressed or unknown audio (only integer PCM and \
             IEEE float are read)"
        )),
    }
}

/// Reads exactly `buf.len()` bytes; false at a clean end of the file before the first byte.
fn read_or_end(source: &mut impl Read, buf: &mut [u8]) -> Result<bool, String> {
    match fill(source, buf)? {
        0 if !buf.is_empty() => Ok(false),
        got if got < buf.len() => Err("the file ends inside a chunk header".into()),
        _ => Ok(true),
    }
}

/// Skips `len` bytes of `source`, which must hold them.
fn skip(source: &mut impl Read, len: u64, what: &str) -> Result<(), String> {
    let skipped = std::io::copy(&mut source.take(len), &mut std::io::sink())
        .map_err(|e| format!("cannot read WAV: {e}"))?;
    if skipped < len {
        return Err(format!("the file ends inside its {what} chunk"));
    }
    Ok(())
}

/// Walks `source`'s chunks up to `data`: its format and the length of its samples in bytes.
fn read_header(source: &mut impl Read) -> Result<(Format, u64), String> {
    let mut riff = [0u8; 12];
    let whole = read_or_end(source, &mut riff).is_ok_and(|read| read);
    if !whole || &riff[8..12] != b"WAVE" {
        return Err("cannot read WAV: not a RIFF WAVE file".into());
    }
    match &riff[0..4] {
        b"RIFF" => {}
        b"RF64" | b"BW64" => {
            return Err(
                "it is an RF64 WAV (the 64-bit form of WAV), which is not supported".into(),
            );
        }
        _ => return Err("cannot read WAV: not a RIFF WAVE file".into()),
    }
    let mut format = None;
    loop {
        let mut header = [0u8; 8];
        if !read_or_end(source, &mut header)? {
            return Err(if format.is_some() {
                "the WAV file has no data chunk".into()
            } else {
                "the WAV file has no format chunk".into()
            });
        }
        let len = le_u32(&header, 4);
        match &header[0..4] {
            b"fmt " => {
                if len > MAX_FORMAT_BYTES {
                    return Err(format!("its format chunk of {len} bytes is too long"));
                }
                let mut body = vec![0u8; len as usize + (len as usize & 1)];
                if !read_or_end(source, &mut body)? {
                    return Err("the file ends inside its format chunk".into());
                }
                format = Some(parse_format(&body[..len as usize])?);
            }
            b"data" => {
                let Some(format) = format else {
                    return Err(
                        "its samples come before the format chunk that describes them".into(),
                    );
                };
                return Ok((format, u64::from(len)));
            }
            id => skip(
                source,
                u64::from(len) + u64::from(len & 1),
                &String::from_utf8_lossy(id),
            )?,
        }
    }
}

/// After the samples read from a `data` chunk, `rest` bytes short of its end (a partial frame
/// and the pad byte of an odd length): true when the chunks that follow hold another `data`
/// chunk (samples split over two, which WAV does not allow, and the second would be lost). What
/// does not read as chunks (trailing bytes, a tag) ends the walk quietly.
fn another_data_chunk_follows(source: &mut impl Read, rest: u64) -> bool {
    if skip(source, rest, "data").is_err() {
        return false;
    }
    loop {
        let mut header = [0u8; 8];
        if !read_or_end(source, &mut header).unwrap_or(false) {
            return false;
        }
        if &header[0..4] == b"data" {
            return true;
        }
        let len = u64::from(le_u32(&header, 4));
        if skip(source, len + (len & 1), "").is_err() {
            return false;
        }
    }
}

/// How many frames the data chunk holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Frames {
    /// As many as its length says.
    Exactly(usize),
    /// Up to the end of the file, at most this many: its length is the 0xFFFFFFFF that a
    /// writer which never came back to fill it in (a recorder streaming its file) leaves.
    ToTheEnd(usize),
}

/// Data-chunk length that stands for "up to the end of the file" ([`Frames::ToTheEnd`]).
const UNKNOWN_LENGTH: u64 = 0xffff_ffff;

/// Reads a whole WAV from `source`: its rate and one buffer per channel, at most
/// `max_samples` samples (all channels), a count the header announces refused before any is
/// read. A partial frame at the end is no sound; a second `data` chunk is refused.
pub(crate) fn read_audio(
    source: &mut impl Read,
    max_samples: u64,
) -> Result<(u32, Vec<Vec<f32>>), String> {
    let (format, data_bytes) = read_header(source)?;
    let nch = u64::from(format.channels);
    let frame_bytes = nch * u64::from(format.container_bytes);
    let frames = if data_bytes == UNKNOWN_LENGTH {
        Frames::ToTheEnd((max_samples / nch) as usize)
    } else {
        let samples = data_bytes / frame_bytes * nch;
        if samples > max_samples {
            return Err(format!(
                "the WAV header announces {samples} samples, past the limit of {max_samples}"
            ));
        }
        Frames::Exactly((data_bytes / frame_bytes) as usize)
    };
    let channels = read_samples(source, format, frames)?;
    // The partial frame and the pad byte of an odd length are what is left of the chunk.
    if data_bytes != UNKNOWN_LENGTH
        && another_data_chunk_follows(source, data_bytes % frame_bytes + (data_bytes & 1))
    {
        return Err(
            "it holds a second data chunk (samples split over two chunks, which WAV \
                    does not allow; only the first would be read)"
                .into(),
        );
    }
    if channels[0].is_empty() {
        return Err("the WAV file holds no samples".into());
    }
    Ok((format.rate_hz, channels))
}

/// Fills `buf` from `source` up to its end: the bytes read.
fn fill(source: &mut impl Read, buf: &mut [u8]) -> Result<usize, String> {
    let mut got = 0;
    while got < buf.len() {
        match source.read(&mut buf[got..]) {
            Ok(0) => break,
            Ok(n) => got += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(format!("cannot read WAV: {e}")),
        }
    }
    Ok(got)
}

/// Decodes the samples of `format` from `source` into one buffer per channel (see the module
/// docs): `frames` of them, or up to the end of the file (a partial last frame dropped), which
/// is refused past its limit.
pub(crate) fn read_samples(
    source: &mut impl Read,
    format: Format,
    frames: Frames,
) -> Result<Vec<Vec<f32>>, String> {
    let nch = usize::from(format.channels);
    let bytes = usize::from(format.container_bytes);
    let (want, to_end) = match frames {
        Frames::Exactly(n) => (n, false),
        // One more than the limit: reading it says the file is past the limit.
        Frames::ToTheEnd(limit) => (limit.saturating_add(1), true),
    };
    // Bounded by samples, not frames: a header may claim thousands of channels.
    let block_frames = (BLOCK_SAMPLES / nch).max(1);
    let mut channels = vec![Vec::with_capacity(want.min(block_frames)); nch];
    let mut block = vec![0u8; block_frames.min(want.max(1)) * nch * bytes];
    // Integers: the container's value over its full scale; unused low bits seen set, and
    // whether every sample fits the valid bits counted from the bottom. (Floats use none of
    // this; their 64-bit container would overflow it.)
    let container_bits = (u32::from(format.container_bytes) * 8).min(32);
    let scale = 1.0 / (1u64 << (container_bits - 1)) as f32;
    let valid_bits = u32::from(format.valid_bits).min(container_bits);
    let low_mask = (1u64 << (container_bits - valid_bits)) - 1;
    let bottom_range = -(1i64 << (valid_bits - 1))..(1i64 << (valid_bits - 1));
    let mut low_bits_set = false;
    let mut fits_bottom = true;
    let mut left = want;
    while left > 0 {
        let n = left.min(block_frames);
        let len = n * nch * bytes;
        let got = fill(source, &mut block[..len])?;
        let used = if got == len {
            len
        } else if to_end {
            // The end of the file: the last whole frame, and nothing more to read.
            left = n;
            got - got % (nch * bytes)
        } else {
            return Err(format!(
                "the file ends inside the {want} frames its data chunk announces (cut short?)"
            ));
        };
        for (i, sample) in block[..used].chunks_exact(bytes).enumerate() {
            let v = match (format.float, bytes) {
                (true, 4) => f32::from_le_bytes([sample[0], sample[1], sample[2], sample[3]]),
                (true, _) => f64::from_le_bytes(sample.try_into().expect("8 bytes")) as f32,
                (false, 1) => f32::from(i16::from(sample[0]) - 128) * scale,
                (false, _) => {
                    let mut raw = [0u8; 4];
                    raw[4 - bytes..].copy_from_slice(sample);
                    // Sign-extended from the container's top bit.
                    let v = i64::from(i32::from_le_bytes(raw) >> (32 - container_bits));
                    low_bits_set |= (v as u64) & low_mask != 0;
                    fits_bottom &= bottom_range.contains(&v);
                    v as f32 * scale
                }
            };
            channels[i % nch].push(v);
        }
        left -= n;
    }
    if let Frames::ToTheEnd(limit) = frames
        && channels[0].len() > limit
    {
        return Err(format!(
            "its data chunk's length is not filled in, and the samples run past the limit of \
             {} samples",
            limit * nch
        ));
    }
    if low_bits_set {
        if !fits_bottom {
            return Err(format!(
                "its samples use more than the {valid_bits} valid bits its header announces"
            ));
        }
        // The valid bits sit at the bottom of the container: rescale to their own full scale.
        let up = (1u64 << (container_bits - valid_bits)) as f32;
        for v in channels.iter_mut().flatten() {
            *v *= up;
        }
    }
    Ok(channels)
}

#[cfg(test)]
mod tests;
