//! The WAV reader against hound on the files hound writes, and on layouts hound misreads or refuses, built byte by byte.

use std::io::Cursor;
use std::path::Path;

use super::*;
use crate::io::wav::{Audio, read_wav_from};

/// A plain format chunk body: `tag`, channels, rate, block align and bits per sample.
fn plain(tag: u16, channels: u16, rate: u32, container_bytes: u16, bits: u16) -> Vec<u8> {
    let block = channels * container_bytes;
    let mut b = Vec::new();
    b.extend(tag.to_le_bytes());
    b.extend(channels.to_le_bytes());
    b.extend(rate.to_le_bytes());
    b.extend((rate * u32::from(block)).to_le_bytes());
    b.extend(block.to_le_bytes());
    b.extend(bits.to_le_bytes());
    b
}

/// A `WAVE_FORMAT_EXTENSIBLE` body of sub-format `tag` with `valid_bits` in each container.
fn extensible(tag: u16, channels: u16, container_bytes: u16, valid_bits: u16) -> Vec<u8> {
    let mut b = plain(
        TAG_EXTENSIBLE,
        channels,
        48_000,
        container_bytes,
        container_bytes * 8,
    );
    b.extend(22u16.to_le_bytes());
    b.extend(valid_bits.to_le_bytes());
    b.extend(0u32.to_le_bytes());
    b.extend(tag.to_le_bytes());
    b.extend(SUBFORMAT_TAIL);
    b
}

/// A RIFF WAVE file of `chunks` (id, body), each padded to an even length.
fn riff(chunks: &[(&[u8; 4], &[u8])]) -> Vec<u8> {
    let mut body = b"WAVE".to_vec();
    for (id, data) in chunks {
        body.extend(*id);
        body.extend((data.len() as u32).to_le_bytes());
        body.extend(*data);
        if data.len() % 2 == 1 {
            body.push(0);
        }
    }
    let mut out = b"RIFF".to_vec();
    out.extend((body.len() as u32).to_le_bytes());
    out.extend(body);
    out
}

fn read(bytes: Vec<u8>) -> Result<Audio, String> {
    read_wav_from(Cursor::new(bytes), Path::new("ref.wav")).map_err(|e| e.to_string())
}

/// [`read`] of a file of just the format chunk `fmt` and the samples `data`.
fn read_pcm(fmt: &[u8], data: &[u8]) -> Result<Audio, String> {
    read(riff(&[(b"fmt ", fmt), (b"data", data)]))
}

/// Little-endian 4-byte containers of `values`.
fn i32_data(values: &[i32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

#[test]
fn files_hound_writes_read_bit_for_bit_as_hound_reads_them() {
    let values: Vec<i64> = (0..500_i64).map(|i| (i * 7919) % 2001 - 1000).collect();
    for (bits, float) in [
        (8, false),
        (16, false),
        (24, false),
        (32, false),
        (32, true),
    ] {
        let spec = hound::WavSpec {
            channels: 2,
            sample_rate: 44_100,
            bits_per_sample: bits,
            sample_format: if float {
                hound::SampleFormat::Float
            } else {
                hound::SampleFormat::Int
            },
        };
        let mut bytes = Cursor::new(Vec::new());
        let mut w = hound::WavWriter::new(&mut bytes, spec).unwrap();
        let full = (1i64 << (bits - 1)) - 1;
        for v in &values {
            if float {
                w.write_sample(*v as f32 / 1000.0).unwrap();
            } else {
                w.write_sample((v * full / 1000) as i32).unwrap();
            }
        }
        w.finalize().unwrap();
        let bytes = bytes.into_inner();
        // What hound reads, scaled as groovescope scaled it before it read WAVs itself.
        let mut reader = hound::WavReader::new(Cursor::new(bytes.clone())).unwrap();
        let expected: Vec<f32> = if float {
            reader.samples::<f32>().map(Result::unwrap).collect()
        } else {
            let scale = 1.0 / (1u64 << (bits - 1)) as f32;
            let s = reader.samples::<i32>();
            s.map(|v| v.unwrap() as f32 * scale).collect()
        };
        let audio = read(bytes).unwrap();
        assert_eq!(audio.sample_rate_hz, 44_100);
        let got: Vec<f32> = (0..audio.len())
            .flat_map(|i| [audio.channels[0][i], audio.channels[1][i]])
            .collect();
        let same = got
            .iter()
            .zip(&expected)
            .all(|(a, b)| a.to_bits() == b.to_bits());
        assert!(
            same && got.len() == expected.len(),
            "{bits} bits, float {float}"
        );
    }
}

#[test]
fn valid_bits_at_the_top_of_a_larger_container_read_at_their_full_scale() {
    // 24 valid bits in 32 (WAVEFORMATEXTENSIBLE: at the top, the low byte zero).
    let samples = [1 << 22, -(1 << 21), (1 << 23) - 1, -(1 << 23)];
    let data = i32_data(&samples.map(|v| v << 8));
    let audio = read_pcm(&extensible(TAG_PCM, 1, 4, 24), &data).unwrap();
    let expected = samples.map(|v| v as f32 / (1 << 23) as f32);
    assert_eq!(audio.channels, vec![expected.to_vec()]);
    // 12 valid bits in 16, said by the plain format chunk.
    let data: Vec<u8> = [1024_i16 << 4, -2048_i16 << 4]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let audio = read_pcm(&plain(TAG_PCM, 1, 8000, 2, 12), &data).unwrap();
    assert_eq!(audio.channels, vec![vec![0.5, -1.0]]);
}

#[test]
fn valid_bits_at_the_bottom_are_read_when_every_sample_fits_them() {
    let samples = [1 << 22, -(1 << 21), 12_345, -(1 << 23)];
    let data = i32_data(&samples);
    let audio = read_pcm(&extensible(TAG_PCM, 1, 4, 24), &data).unwrap();
    let expected = samples.map(|v| v as f32 / (1 << 23) as f32);
    assert_eq!(audio.channels, vec![expected.to_vec()]);
    // One sample past 24 bits, and low bits set: neither layout fits.
    let data = i32_data(&[12_345, 1 << 30]);
    let e = read_pcm(&extensible(TAG_PCM, 1, 4, 24), &data).unwrap_err();
    assert!(
        e.contains("ref.wav") && e.contains("more than the 24 valid bits"),
        "{e}"
    );
}

#[test]
fn chunks_of_odd_length_are_skipped_with_their_pad_byte() {
    let data: Vec<u8> = [16_384_i16, -8192]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let bytes = riff(&[
        (b"JUNK", b"abc"),
        (b"fmt ", &plain(TAG_PCM, 1, 22_050, 2, 16)),
        (b"LIST", b"INFOx"),
        (b"data", &data),
        (b"id3 ", b"t"),
    ]);
    let audio = read(bytes).unwrap();
    assert_eq!(audio.sample_rate_hz, 22_050);
    assert_eq!(audio.channels, vec![vec![0.5, -0.25]]);
}

#[test]
fn float_samples_of_eight_bytes_are_read() {
    let data: Vec<u8> = [0.25_f64, -0.75, 0.5, 1.0]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    for fmt in [
        plain(TAG_FLOAT, 2, 96_000, 8, 64),
        extensible(TAG_FLOAT, 2, 8, 64),
    ] {
        let audio = read_pcm(&fmt, &data).unwrap();
        assert_eq!(audio.channels, vec![vec![0.25, 0.5], vec![-0.75, 1.0]]);
    }
}

#[test]
fn what_cannot_be_read_is_said_naming_the_file() {
    let pcm = plain(TAG_PCM, 1, 8000, 2, 16);
    let cases: Vec<(Vec<u8>, &str)> = vec![
        (
            riff(&[(b"fmt ", &plain(2, 1, 8000, 2, 4)), (b"data", &[0; 4])]),
            "format tag 0x0002",
        ),
        (
            riff(&[(b"data", &[0; 4]), (b"fmt ", &pcm)]),
            "come before the format chunk",
        ),
        (riff(&[(b"fmt ", &pcm)]), "no data chunk"),
        (
            riff(&[
                (b"fmt ", &plain(TAG_PCM, 0, 8000, 2, 16)),
                (b"data", &[0; 4]),
            ]),
            "no channels",
        ),
        (
            riff(&[
                (b"fmt ", &plain(TAG_PCM, 1, 8000, 2, 24)),
                (b"data", &[0; 4]),
            ]),
            "24 valid bits",
        ),
        (
            riff(&[
                (b"fmt ", &plain(TAG_PCM, 1, 8000, 6, 48)),
                (b"data", &[0; 6]),
            ]),
            "6-byte integer",
        ),
        (riff(&[(b"fmt ", &pcm), (b"data", &[])]), "holds no samples"),
        (b"RF64\0\0\0\0WAVE".to_vec(), "RF64"),
        // A block of 65,535 bytes for one channel (the fuzzed file that overflowed the bits).
        (
            riff(&[
                (b"fmt ", &plain(TAG_PCM, 1, 8000, 65_535, 16)),
                (b"data", &[0; 4]),
            ]),
            "65535-byte integer",
        ),
        (
            riff(&[
                (b"fmt ", &pcm),
                (b"data", &[1, 0, 2]),
                (b"LIST", b"x"),
                (b"data", &[3, 0]),
            ]),
            "second data chunk",
        ),
        (b"hello".to_vec(), "not a RIFF WAVE file"),
    ];
    for (bytes, says) in cases {
        let e = read(bytes).unwrap_err();
        assert!(
            e.contains("ref.wav") && e.contains(says),
            "{e} (wanted {says:?})"
        );
    }
    // Cut short: the data chunk announces 8 frames and holds 3.
    let mut cut = riff(&[(b"fmt ", &pcm), (b"data", &[0; 16])]);
    cut.truncate(cut.len() - 10);
    let e = read(cut).unwrap_err();
    assert!(
        e.contains("inside the 8 frames") && e.contains("cut short"),
        "{e}"
    );
    // A header past the sample limit is refused before a sample is read.
    let mut huge = riff(&[(b"fmt ", &plain(TAG_PCM, 1, 8000, 1, 8)), (b"data", &[])]);
    let at = huge.len() - 4;
    huge[at..].copy_from_slice(&0xffff_fff0_u32.to_le_bytes());
    let e = read(huge).unwrap_err();
    assert!(e.contains("past the limit"), "{e}");
}

#[test]
fn a_data_length_never_filled_in_reads_to_the_end_of_the_file() {
    // 0xFFFFFFFF, as a recorder streaming its file leaves it: three whole frames and a byte.
    let data: Vec<u8> = [8192_i16, -16_384, 4096]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let mut bytes = riff(&[(b"fmt ", &plain(TAG_PCM, 1, 8000, 2, 16)), (b"data", &data)]);
    let at = bytes.len() - data.len() - 4;
    bytes[at..at + 4].copy_from_slice(&u32::MAX.to_le_bytes());
    bytes.push(7);
    let audio = read(bytes).unwrap();
    assert_eq!(audio.channels, vec![vec![0.25, -0.5, 0.125]]);
    // Past the limit it is refused, having read one frame more than the limit.
    let format = parse_format(&plain(TAG_PCM, 1, 8000, 2, 16)).unwrap();
    let e = read_samples(&mut Cursor::new(&data), format, Frames::ToTheEnd(2)).unwrap_err();
    assert!(e.contains("past the limit of 2 samples"), "{e}");
    let ok = read_samples(&mut Cursor::new(&data), format, Frames::ToTheEnd(3)).unwrap();
    assert_eq!(ok[0].len(), 3);
}
