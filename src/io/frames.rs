//! Frame loading: PNG or TIFF, 8 or 16 bit, grey or colour, converted to grey `f32` in `[0, 1]`.

use std::path::{Path, PathBuf};

use image::{DynamicImage, ImageBuffer, Luma};
use rayon::prelude::*;

use super::limits::{
    MAX_FRAME_DECODED_BYTES, MAX_FRAME_FILE_BYTES, check_frame_size, read_limited,
};
use super::{LoadError, atomic::write_atomic_with, scan::GroupEntry};
use crate::image::Image;

/// The samples of a decoded frame, before conversion to grey `f32`: 8-bit or 16-bit grey as
/// stored, or colour already converted to grey (Rec. 709 luma).
#[derive(Clone, Debug, PartialEq)]
pub enum RawSamples {
    /// 8-bit grey.
    U8(Vec<u8>),
    /// 16-bit grey.
    U16(Vec<u16>),
    /// Grey in `[0, 1]` from a colour frame.
    F32(Vec<f32>),
}

/// A decoded frame before conversion to grey `f32` (what a Zarr store keeps).
#[derive(Clone, Debug, PartialEq)]
pub struct RawFrame {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Row-major samples.
    pub samples: RawSamples,
}

/// Decodes one frame to its raw samples.
///
/// # Errors
/// [`LoadError::BadFrame`] naming the file when it is missing, past a limit of
/// [`super::limits`] or cannot be decoded.
pub fn load_frame_raw(path: &Path) -> Result<RawFrame, LoadError> {
    let bytes = read_limited(path, MAX_FRAME_FILE_BYTES, "frame").map_err(|e| match e {
        LoadError::Io { problem, path } => LoadError::BadFrame { problem, path },
        other => other,
    })?;
    decode_frame_raw(&bytes, path)
}

/// Decodes a frame held in memory to its raw samples; `path` names it in errors. The size in
/// its header is checked against the limits before any pixel memory is allocated.
///
/// # Errors
/// [`LoadError::BadFrame`] naming `path` when the bytes are not a frame within the limits.
pub fn decode_frame_raw(bytes: &[u8], path: &Path) -> Result<RawFrame, LoadError> {
    let bad = |problem: String| LoadError::BadFrame {
        problem,
        path: path.to_path_buf(),
    };
    let reader = || {
        image::ImageReader::new(std::io::Cursor::new(bytes))
            .with_guessed_format()
            .map_err(|e| bad(e.to_string()))
    };
    let (w, h) = reader()?
        .into_dimensions()
        .map_err(|e| bad(decoder_words(e)))?;
    check_frame_size(u64::from(w), u64::from(h)).map_err(bad)?;
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(w);
    limits.max_image_height = Some(h);
    limits.max_alloc = Some(MAX_FRAME_DECODED_BYTES);
    let mut reader = reader()?;
    reader.limits(limits);
    let dynimg = reader.decode().map_err(|e| bad(decoder_words(e)))?;
    let (width, height) = (dynimg.width() as usize, dynimg.height() as usize);
    let samples = match dynimg {
        DynamicImage::ImageLuma8(b) => RawSamples::U8(b.into_raw()),
        DynamicImage::ImageLuma16(b) => RawSamples::U16(b.into_raw()),
        other => {
            let rgb = other.to_rgb32f();
            RawSamples::F32(
                rgb.pixels()
                    .map(|p| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2])
                    .collect(),
            )
        }
    };
    Ok(RawFrame {
        width,
        height,
        samples,
    })
}

/// The image decoder's error as the problem with a frame: an unsupported kind of image (a
/// float TIFF, say) names the kinds frames may be.
fn decoder_words(e: image::ImageError) -> String {
    match e {
        image::ImageError::Unsupported(u) => {
            format!("unsupported image: {u}; frames are 8- or 16-bit grey or RGB PNG or TIFF")
        }
        other => other.to_string(),
    }
}

/// Grey `f32` in `[0, 1]` of a raw frame: 8-bit values / 255, 16-bit values / 65 535.
#[must_use]
pub fn grey_from_raw(raw: RawFrame) -> Image {
    let data: Vec<f32> = match raw.samples {
        RawSamples::U8(v) => v.iter().map(|&v| f32::from(v) / 255.0).collect(),
        RawSamples::U16(v) => v.iter().map(|&v| f32::from(v) / 65535.0).collect(),
        RawSamples::F32(v) => v,
    };
    Image {
        width: raw.width,
        height: raw.height,
        data,
    }
}

/// Loads one frame as grey in `[0, 1]` (Rec. 709 luma for colour frames).
///
/// # Errors
/// [`LoadError::BadFrame`] naming the file when it is missing, past a limit of
/// [`super::limits`] or cannot be decoded.
pub fn load_frame(path: &Path) -> Result<Image, LoadError> {
    load_frame_raw(path).map(grey_from_raw)
}

/// Decodes a frame held in memory; `path` names it in errors (see [`decode_frame_raw`]).
///
/// # Errors
/// [`LoadError::BadFrame`] naming `path` when the bytes are not a frame within the limits.
pub fn decode_frame(bytes: &[u8], path: &Path) -> Result<Image, LoadError> {
    decode_frame_raw(bytes, path).map(grey_from_raw)
}

/// Loads every frame of a group in parallel and checks they share one size.
///
/// # Errors
/// The first unreadable frame, the first frame whose size differs from the group's first, or
/// too few frames.
pub fn load_group(group: &GroupEntry) -> Result<Vec<Image>, LoadError> {
    load_group_frames(group, 0..group.frame_count())
}

/// What failed a group of a scan folder: [`LoadError::Missing`] when its folder, or one of
/// its frames, is one the scan's numbering skips (see docs/FORMAT.md), else `error`. Asked
/// only once reading failed, so a readable group costs no extra look-up per frame (which a
/// network file system makes slow).
#[must_use]
pub fn missing_or(group: &GroupEntry, error: LoadError) -> LoadError {
    if let Some(missing) = group.missing_error() {
        return missing;
    }
    match group.frame_paths().find(|p| !p.exists()) {
        Some(gone) => LoadError::Missing {
            what: "frame",
            path: gone,
        },
        None => error,
    }
}

/// Loads the frames `range` of a group (clamped to the group) in parallel and checks they
/// share one size. The other frames are not decoded, but they are read and checked, so an
/// unreadable frame or one of another size anywhere in the group is still reported: every
/// frame's header, and for PNG every chunk's checksum, which catches truncated files and
/// damaged image data; TIFF has no checksums, so there the image data must only lie inside
/// the file, which catches truncation.
///
/// # Errors
/// As [`load_group`], [`LoadError::Missing`] for a group folder or frame the scan's
/// numbering skips, and [`LoadError::TooFewFrames`] for a group of fewer than
/// [`super::scan::MIN_FRAMES_PER_GROUP`] frames.
pub fn load_group_frames(
    group: &GroupEntry,
    range: std::ops::Range<usize>,
) -> Result<Vec<Image>, LoadError> {
    if let Some(z) = &group.zarr {
        return super::zarr::load_group_frames(z, range);
    }
    load_folder_frames(group, range).map_err(|e| missing_or(group, e))
}

/// [`load_group_frames`] of a scan folder's group.
fn load_folder_frames(
    group: &GroupEntry,
    range: std::ops::Range<usize>,
) -> Result<Vec<Image>, LoadError> {
    let n = group.frame_names.len();
    if n < super::scan::MIN_FRAMES_PER_GROUP {
        return Err(LoadError::TooFewFrames {
            found: n,
            needed: super::scan::MIN_FRAMES_PER_GROUP,
            path: group.dir.clone(),
        });
    }
    let paths: Vec<PathBuf> = group
        .frame_paths()
        .take(range.end.min(n))
        .skip(range.start.min(n))
        .collect();
    let frames: Vec<Image> = paths
        .par_iter()
        .map(|p| load_frame(p))
        .collect::<Result<_, _>>()?;
    let Some(first) = frames.first() else {
        return Ok(frames);
    };
    let want = (first.width, first.height);
    let same_size = |found: (usize, usize), path: &Path| {
        if found == want {
            Ok(())
        } else {
            Err(LoadError::MixedSizes {
                found_w: found.0,
                found_h: found.1,
                want_w: want.0,
                want_h: want.1,
                path: path.to_path_buf(),
            })
        }
    };
    for (img, path) in frames.iter().zip(&paths) {
        same_size((img.width, img.height), path)?;
    }
    group
        .frame_names
        .par_iter()
        .enumerate()
        .filter(|(k, _)| !range.contains(k))
        .try_for_each(|(_, name)| {
            let path = group.dir.join(name);
            same_size(check_undecoded_frame(&path)?, &path)
        })?;
    Ok(frames)
}

/// Reads a frame that is not decoded and returns its size (see [`check_frame_bytes`]).
fn check_undecoded_frame(path: &Path) -> Result<(usize, usize), LoadError> {
    let bytes = read_limited(path, MAX_FRAME_FILE_BYTES, "frame").map_err(|e| match e {
        LoadError::Io { problem, path } => LoadError::BadFrame { problem, path },
        other => other,
    })?;
    check_frame_bytes(&bytes, path)
}

/// Checks a frame without decoding it and returns its size: a PNG's chunks must match their
/// checksums (`check_png_chunks`), a TIFF's image data must lie inside the file
/// (`check_tiff_extent`), any other file's header must read, and the size must be within
/// the limits. `path` names the frame in errors.
///
/// # Errors
/// [`LoadError::BadFrame`] naming `path`.
pub fn check_frame_bytes(bytes: &[u8], path: &Path) -> Result<(usize, usize), LoadError> {
    let bad = |e: &dyn std::fmt::Display| LoadError::BadFrame {
        problem: e.to_string(),
        path: path.to_path_buf(),
    };
    let (w, h) = if bytes.starts_with(&PNG_SIGNATURE) {
        check_png_chunks(bytes).map_err(|e| bad(&e))?
    } else if bytes.starts_with(b"II*\0") || bytes.starts_with(b"MM\0*") {
        check_tiff_extent(bytes).map_err(|e| bad(&e))?
    } else {
        image::ImageReader::new(std::io::Cursor::new(bytes))
            .with_guessed_format()
            .map_err(|e| bad(&e))?
            .into_dimensions()
            .map_err(|e| bad(&e))?
    };
    check_frame_size(u64::from(w), u64::from(h)).map_err(|e| bad(&e))?;
    Ok((w as usize, h as usize))
}

/// The width and height in a frame file's header, read without reading the image data.
///
/// # Errors
/// [`LoadError::BadFrame`] naming the file when its header cannot be read.
pub fn frame_dimensions(path: &Path) -> Result<(usize, usize), LoadError> {
    let bad = |e: &dyn std::fmt::Display| LoadError::BadFrame {
        problem: e.to_string(),
        path: path.to_path_buf(),
    };
    let (w, h) = image::ImageReader::open(path)
        .map_err(|e| bad(&e))?
        .with_guessed_format()
        .map_err(|e| bad(&e))?
        .into_dimensions()
        .map_err(|e| bad(&e))?;
    Ok((w as usize, h as usize))
}

/// The eight bytes every PNG file starts with.
const PNG_SIGNATURE: [u8; 8] = [0x89, b'P', b'N', b'G', 0x0D, 0x0A, 0x1A, 0x0A];

/// Walks the chunks of a PNG file without decompressing it: the first must be the 13-byte
/// `IHDR`, each must lie inside the file and match its CRC-32, there must be image data, and
/// the file must end with `IEND`. Returns the width and height `IHDR` gives.
fn check_png_chunks(bytes: &[u8]) -> Result<(u32, u32), String> {
    let mut at = PNG_SIGNATURE.len();
    let mut size = None;
    let mut has_data = false;
    loop {
        let Some(head) = bytes.get(at..at + 8) else {
            return Err(format!(
                "PNG file is truncated: it ends at byte {} without an IEND chunk",
                bytes.len()
            ));
        };
        let len = u32::from_be_bytes([head[0], head[1], head[2], head[3]]) as usize;
        let kind = &head[4..8];
        let name = || String::from_utf8_lossy(kind);
        let body = at + 4..at + 8 + len;
        let Some(crc) = bytes.get(body.end..body.end + 4) else {
            return Err(format!(
                "PNG file is truncated inside its {} chunk at byte {at} (the file has {} bytes)",
                name(),
                bytes.len()
            ));
        };
        let want = u32::from_be_bytes([crc[0], crc[1], crc[2], crc[3]]);
        if crc32fast::hash(&bytes[body]) != want {
            return Err(format!(
                "PNG data is damaged: the {} chunk at byte {at} fails its CRC check",
                name()
            ));
        }
        if at == PNG_SIGNATURE.len() {
            if kind != b"IHDR" || len != 13 {
                return Err(format!("PNG file starts with a {} chunk, not IHDR", name()));
            }
            // The header's first eight data bytes follow the 8 bytes of length and type.
            let Some(dims) = bytes.get(at + 8..at + 16) else {
                return Err("PNG header is truncated".into());
            };
            size = Some((
                u32::from_be_bytes([dims[0], dims[1], dims[2], dims[3]]),
                u32::from_be_bytes([dims[4], dims[5], dims[6], dims[7]]),
            ));
        }
        has_data |= kind == b"IDAT";
        if kind == b"IEND" {
            return match (size, has_data) {
                (Some(size), true) => Ok(size),
                _ => Err("PNG file has no image data (no IDAT chunk)".into()),
            };
        }
        at += 12 + len;
    }
}

/// Reads a TIFF file's first image directory without decoding it: the image data its strips
/// or tiles point to must lie inside the file (TIFF has no checksums, so this catches
/// truncation, not damaged bytes). Returns the width and height the directory gives.
fn check_tiff_extent(bytes: &[u8]) -> Result<(u32, u32), String> {
    use tiff::tags::Tag;
    let mut dec =
        tiff::decoder::Decoder::new(std::io::Cursor::new(bytes)).map_err(|e| e.to_string())?;
    for (offsets, counts) in [
        (Tag::StripOffsets, Tag::StripByteCounts),
        (Tag::TileOffsets, Tag::TileByteCounts),
    ] {
        let offsets = dec
            .find_tag_unsigned_vec::<u64>(offsets)
            .map_err(|e| e.to_string())?;
        let counts = dec
            .find_tag_unsigned_vec::<u64>(counts)
            .map_err(|e| e.to_string())?;
        let (Some(offsets), Some(counts)) = (offsets, counts) else {
            continue;
        };
        let end = offsets
            .iter()
            .zip(&counts)
            .map(|(o, c)| o.saturating_add(*c))
            .max()
            .unwrap_or(0);
        let len = bytes.len() as u64;
        return if end > len {
            Err(format!(
                "TIFF file is truncated: its image data runs to byte {end}, the file has {len} bytes"
            ))
        } else {
            dec.dimensions().map_err(|e| e.to_string())
        };
    }
    Err("TIFF file has no image data (no strip or tile offsets)".into())
}

/// Saves a grey image (values in `[0, 1]`, clamped) as an 8- or 16-bit PNG, atomically.
///
/// # Errors
/// [`LoadError::Io`] when the file exists and `overwrite` is false, or the write fails.
pub fn save_grey_png(
    img: &Image,
    path: &Path,
    sixteen_bit: bool,
    overwrite: bool,
) -> Result<(), LoadError> {
    save_grey_as(img, path, sixteen_bit, overwrite, image::ImageFormat::Png)
}

/// The grey values of `img`, clamped to [0, 1], on a scale of 0 to `full`, rounded and made
/// samples by `cast` (the PNG/TIFF writers' 8- and 16-bit quantisation).
fn quantised<T>(img: &Image, full: f32, cast: impl Fn(f32) -> T) -> Vec<T> {
    img.data
        .iter()
        .map(|v| cast((v.clamp(0.0, 1.0) * full).round()))
        .collect()
}

/// The samples [`save_grey_png`] would store for `img` (8- or 16-bit), without the file:
/// what a Zarr store of the frames holds, so a store written straight from images loads as one
/// packed from their PNGs would.
#[cfg(feature = "video")]
#[must_use]
pub(crate) fn raw_from_grey(img: &Image, sixteen_bit: bool) -> RawFrame {
    let samples = if sixteen_bit {
        RawSamples::U16(quantised(img, 65535.0, |q| q as u16))
    } else {
        RawSamples::U8(quantised(img, 255.0, |q| q as u8))
    };
    RawFrame {
        width: img.width,
        height: img.height,
        samples,
    }
}

/// Saves a grey image (values in `[0, 1]`, clamped, rounded to 8 or 16 bits) in `format`,
/// atomically.
///
/// # Errors
/// [`LoadError::Io`] when the file exists and `overwrite` is false, or the write fails.
pub(crate) fn save_grey_as(
    img: &Image,
    path: &Path,
    sixteen_bit: bool,
    overwrite: bool,
    format: image::ImageFormat,
) -> Result<(), LoadError> {
    let (w, h) = (img.width as u32, img.height as u32);
    let mismatch = || LoadError::Io {
        problem: "image size does not match its data".into(),
        path: path.to_path_buf(),
    };
    let encoded = if sixteen_bit {
        let raw = quantised(img, 65535.0, |q| q as u16);
        DynamicImage::ImageLuma16(
            ImageBuffer::<Luma<u16>, _>::from_raw(w, h, raw).ok_or_else(mismatch)?,
        )
    } else {
        let raw = quantised(img, 255.0, |q| q as u8);
        DynamicImage::ImageLuma8(
            ImageBuffer::<Luma<u8>, _>::from_raw(w, h, raw).ok_or_else(mismatch)?,
        )
    };
    write_atomic_with(path, overwrite, |wr| {
        encoded.write_to(wr, format).map_err(std::io::Error::other)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    /// A group of the frames `paths` in `dir`.
    fn entry(dir: &Path, paths: &[PathBuf]) -> GroupEntry {
        GroupEntry {
            index: 0,
            dir: dir.to_path_buf(),
            frame_names: paths
                .iter()
                .map(|p| p.file_name().unwrap_or_default().to_owned())
                .collect(),
            zarr: None,
            missing: None,
        }
    }

    /// Writes frames `f000.EXT`, `f001.EXT`, … with `write(k, path)`; returns their paths.
    fn write_frames(dir: &Path, n: usize, ext: &str, write: impl Fn(usize, &Path)) -> Vec<PathBuf> {
        (0..n)
            .map(|k| {
                let p = dir.join(format!("f{k:03}.{ext}"));
                write(k, &p);
                p
            })
            .collect()
    }

    /// Writes `bytes` over `frame` and asserts that loading `window` of `group` fails with
    /// an error that contains every one of `parts`.
    fn assert_refused(
        group: &GroupEntry,
        window: std::ops::Range<usize>,
        frame: &Path,
        bytes: &[u8],
        parts: &[&str],
    ) {
        std::fs::write(frame, bytes).unwrap();
        let err = load_group_frames(group, window).unwrap_err().to_string();
        assert!(parts.iter().all(|p| err.contains(p)), "{parts:?}: {err}");
    }

    /// Puts the intact `good` bytes back in `frame` and asserts that `window` of `group` loads.
    fn assert_loads_again(
        group: &GroupEntry,
        window: std::ops::Range<usize>,
        frame: &Path,
        good: &[u8],
    ) {
        std::fs::write(frame, good).unwrap();
        assert_eq!(
            load_group_frames(group, window.clone()).unwrap().len(),
            window.len()
        );
    }

    #[test]
    fn sixteen_bit_png_round_trips_exactly() {
        let dir = tempfile::tempdir().unwrap();
        let img = Image::from_fn(5, 3, |x, y| (x * 3 + y) as f32 / 20.0);
        let p = dir.path().join("f.png");
        save_grey_png(&img, &p, true, false).unwrap();
        let back = load_frame(&p).unwrap();
        for (a, b) in img.data.iter().zip(&back.data) {
            assert!((a - b).abs() < 1.0 / 65535.0);
        }
    }

    #[test]
    fn frames_outside_a_loaded_window_are_still_checked() {
        let dir = tempfile::tempdir().unwrap();
        let frame = |k: usize, w: usize| {
            let p = dir.path().join(format!("f{k:03}.png"));
            save_grey_png(&Image::filled(w, 6, 0.5), &p, false, false).unwrap();
            p
        };
        let mut frames: Vec<PathBuf> = (0..12).map(|k| frame(k, 8)).collect();
        let group = |frames: &[PathBuf]| entry(dir.path(), frames);
        let window = load_group_frames(&group(&frames), 3..10).unwrap();
        assert_eq!(window.len(), 7);
        // Another size outside the window.
        let first = std::mem::replace(&mut frames[0], frame(100, 9));
        let err = load_group_frames(&group(&frames), 3..10).unwrap_err();
        assert!(
            matches!(err, LoadError::MixedSizes { found_w: 9, .. }),
            "{err}"
        );
        assert!(err.to_string().contains("f100.png"), "{err}");
        // A corrupt frame outside the window.
        frames[0] = first;
        std::fs::write(&frames[11], b"not a png").unwrap();
        let err = load_group_frames(&group(&frames), 3..10).unwrap_err();
        assert!(matches!(err, LoadError::BadFrame { .. }), "{err}");
        assert!(err.to_string().contains("f011.png"), "{err}");
    }

    #[test]
    fn truncated_tiff_outside_the_window_is_reported() {
        let dir = tempfile::tempdir().unwrap();
        let frames = write_frames(dir.path(), 8, "tif", |k, p| {
            let img = image::GrayImage::from_fn(40, 30, |x, y| {
                image::Luma([((x * 7 + y * 13) as usize % 251 + k) as u8])
            });
            img.save(p).unwrap();
        });
        let group = entry(dir.path(), &frames);
        assert_eq!(load_group_frames(&group, 1..8).unwrap().len(), 7);
        let good = std::fs::read(&frames[0]).unwrap();
        // Cut short: here the directory sits after the image data, so it goes too.
        assert_refused(
            &group,
            1..8,
            &frames[0],
            &good[..good.len() / 2],
            &["f000.tif"],
        );
        // A directory whose strip points past the end of the file (little-endian "II"): the
        // header still reads, the extent check catches it.
        let le16 = |b: &[u8], at: usize| usize::from(u16::from_le_bytes([b[at], b[at + 1]]));
        let ifd = u32::from_le_bytes([good[4], good[5], good[6], good[7]]) as usize;
        let entry = (0..le16(&good, ifd))
            .map(|k| ifd + 2 + 12 * k)
            .find(|&e| le16(&good, e) == 273)
            .unwrap();
        let mut moved = good.clone();
        let past_end = u32::try_from(good.len()).unwrap().to_le_bytes();
        moved[entry + 8..entry + 12].copy_from_slice(&past_end);
        assert_refused(&group, 1..8, &frames[0], &moved, &["f000.tif", "truncated"]);
        assert_loads_again(&group, 1..8, &frames[0], &good);
    }

    #[test]
    fn damaged_or_truncated_png_outside_the_window_is_reported() {
        let dir = tempfile::tempdir().unwrap();
        let frames = write_frames(dir.path(), 12, "png", |k, p| {
            let img = Image::from_fn(40, 30, |x, y| ((x * 7 + y * 13 + k) % 17) as f32 / 16.0);
            save_grey_png(&img, p, false, false).unwrap();
        });
        let group = entry(dir.path(), &frames);
        let good = std::fs::read(&frames[1]).unwrap();
        // One flipped bit inside the image data: the header still reads.
        let idat = good.windows(4).position(|w| w == b"IDAT").unwrap();
        let mut flipped = good.clone();
        flipped[idat + 10] ^= 0x10;
        assert_refused(&group, 3..10, &frames[1], &flipped, &["f001.png", "CRC"]);
        // Cut short after the header.
        assert_refused(
            &group,
            3..10,
            &frames[1],
            &good[..good.len() / 2],
            &["f001.png", "truncated"],
        );
        // Intact again: the group loads.
        assert_loads_again(&group, 3..10, &frames[1], &good);
    }

    #[test]
    fn corrupt_frame_error_names_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("broken.png");
        std::fs::write(&p, b"not a png at all").unwrap();
        let msg = load_frame(&p).unwrap_err().to_string();
        assert!(msg.contains("broken.png"), "{msg}");
        // A float TIFF: the kinds of frame it may be are named.
        let mut tif = std::io::Cursor::new(Vec::new());
        tiff::encoder::TiffEncoder::new(&mut tif)
            .unwrap()
            .write_image::<tiff::encoder::colortype::Gray32Float>(4, 2, &[0.5; 8])
            .unwrap();
        let msg = decode_frame(tif.get_ref(), Path::new("f.tif"))
            .unwrap_err()
            .to_string();
        assert!(
            msg.contains("frames are 8- or 16-bit grey or RGB") && msg.contains("f.tif"),
            "{msg}"
        );
    }
}
