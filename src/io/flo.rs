//! Middlebury `.flo` flow files: magic 202021.25, width, height, then interleaved (u, v) `f32` pairs.

use std::path::Path;

use super::limits::{MAX_FRAME_PIXELS, check_frame_size, read_limited};
use super::{LoadError, atomic::write_atomic};
use crate::image::Image;

const FLO_MAGIC: f32 = 202_021.25;

/// Encodes a flow field (u, v of equal size) as `.flo` bytes.
#[must_use]
pub fn encode_flo(u: &Image, v: &Image) -> Vec<u8> {
    let mut out = Vec::with_capacity(12 + u.data.len() * 8);
    out.extend_from_slice(&FLO_MAGIC.to_le_bytes());
    out.extend_from_slice(&(u.width as i32).to_le_bytes());
    out.extend_from_slice(&(u.height as i32).to_le_bytes());
    for (a, b) in u.data.iter().zip(&v.data) {
        out.extend_from_slice(&a.to_le_bytes());
        out.extend_from_slice(&b.to_le_bytes());
    }
    out
}

/// Writes a `.flo` file atomically.
///
/// # Errors
/// [`LoadError`] naming the file when the sizes differ, it exists (without `overwrite`) or the write fails.
pub fn write_flo(path: &Path, u: &Image, v: &Image, overwrite: bool) -> Result<(), LoadError> {
    if !u.same_size(v) {
        return Err(LoadError::Io {
            problem: "u and v differ in size".into(),
            path: path.to_path_buf(),
        });
    }
    write_atomic(path, &encode_flo(u, v), overwrite)
}

/// Reads a `.flo` file into (u, v).
///
/// # Errors
/// [`LoadError::Io`] naming the file when it is unreadable, has a bad magic number, is past
/// the frame limits or is truncated.
pub fn read_flo(path: &Path) -> Result<(Image, Image), LoadError> {
    // 12 header bytes and 8 a pixel.
    let max_bytes = 12 + 8 * MAX_FRAME_PIXELS;
    let bytes = read_limited(path, max_bytes, "flow file")?;
    decode_flo(&bytes, path)
}

/// Decodes `.flo` bytes (see [`read_flo`]); `path` names them in errors.
///
/// # Errors
/// As [`read_flo`].
pub fn decode_flo(bytes: &[u8], path: &Path) -> Result<(Image, Image), LoadError> {
    let bad = |problem: &str| LoadError::Io {
        problem: problem.to_string(),
        path: path.to_path_buf(),
    };
    let word = |i: usize| -> Option<[u8; 4]> { bytes.get(i * 4..i * 4 + 4)?.try_into().ok() };
    let magic = word(0).map(f32::from_le_bytes);
    if magic != Some(FLO_MAGIC) {
        return Err(bad("not a Middlebury .flo file (bad magic number)"));
    }
    let (Some(w), Some(h)) = (
        word(1).map(i32::from_le_bytes),
        word(2).map(i32::from_le_bytes),
    ) else {
        return Err(bad("truncated .flo header"));
    };
    let (Ok(w), Ok(h)) = (u64::try_from(w), u64::try_from(h)) else {
        return Err(bad("negative size in .flo header"));
    };
    check_frame_size(w, h).map_err(|e| bad(&format!("flow field: {e}")))?;
    let want = 12 + w * h * 8;
    if bytes.len() as u64 != want {
        return Err(bad(&format!(
            "truncated .flo data: a {w}×{h} field takes {want} bytes, the file has {}",
            bytes.len()
        )));
    }
    #[allow(clippy::cast_possible_truncation)] // both checked against the frame limits above
    let (w, h) = (w as usize, h as usize);
    let mut u = Image::zeros(w, h);
    let mut v = Image::zeros(w, h);
    for (i, pair) in bytes[12..].chunks_exact(8).enumerate() {
        u.data[i] = f32::from_le_bytes([pair[0], pair[1], pair[2], pair[3]]);
        v.data[i] = f32::from_le_bytes([pair[4], pair[5], pair[6], pair[7]]);
    }
    Ok((u, v))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flo_round_trips() {
        let dir = tempfile::tempdir().unwrap();
        let u = Image::from_fn(4, 3, |x, y| x as f32 - y as f32);
        let v = Image::from_fn(4, 3, |x, _| 0.5 * x as f32);
        let p = dir.path().join("f.flo");
        write_flo(&p, &u, &v, false).unwrap();
        let (u2, v2) = read_flo(&p).unwrap();
        assert_eq!((u, v), (u2, v2));
        std::fs::write(&p, b"junkjunkjunk").unwrap();
        assert!(read_flo(&p).is_err());
    }
}
