//! Middlebury `.flo` flow files: magic 202021.25, width, height, then interleaved (u, v) `f32` pairs.

use std::path::Path;

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
/// [`LoadError::Io`] naming the file when it is unreadable, has a bad magic number or is truncated.
pub fn read_flo(path: &Path) -> Result<(Image, Image), LoadError> {
    let bad = |problem: &str| LoadError::Io {
        problem: problem.to_string(),
        path: path.to_path_buf(),
    };
    let bytes = std::fs::read(path).map_err(|e| bad(&format!("cannot read flow file: {e}")))?;
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
    let (Ok(w), Ok(h)) = (usize::try_from(w), usize::try_from(h)) else {
        return Err(bad("negative size in .flo header"));
    };
    if bytes.len() != 12 + w * h * 8 {
        return Err(bad("truncated .flo data"));
    }
    let mut u = Image::zeros(w, h);
    let mut v = Image::zeros(w, h);
    for i in 0..w * h {
        u.data[i] = word(3 + 2 * i).map_or(0.0, f32::from_le_bytes);
        v.data[i] = word(4 + 2 * i).map_or(0.0, f32::from_le_bytes);
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
