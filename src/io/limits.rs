//! Resource limits: the most any file may make groovescope read or allocate (docs/FORMAT.md lists them).
//!
//! Every limit is checked from a header or a file size before the memory is asked for, and a
//! file past one is refused with one line naming the file, the limit and the number it asked for.

use std::io::Read;
use std::path::Path;

use super::LoadError;

/// Longest frame side, in pixels (a 1280×1024 microscope frame is far inside it).
pub const MAX_FRAME_SIDE_PX: u64 = 16_384;
/// Most pixels in one frame (8192 × 8192).
pub const MAX_FRAME_PIXELS: u64 = 64 << 20;
/// Most bytes the decoder may allocate for one frame (64 Mpx of 16-bit RGBA).
pub const MAX_FRAME_DECODED_BYTES: u64 = 512 << 20;
/// Largest frame file read (an uncompressed 16-bit RGBA TIFF of the largest frame is 512 MiB).
pub const MAX_FRAME_FILE_BYTES: u64 = 1 << 30;
/// Most group folders in one scan (a whole 78 rpm side at the usual 460 µm group step is
/// about 400,000).
pub const MAX_GROUPS: usize = 1 << 20;
/// Most frames in one group (the paper used 12 for records and 36 for synthetic scans).
pub const MAX_FRAMES_PER_GROUP: usize = 4096;
/// Most samples (all channels together) in a WAV file read: about 46 minutes of 48 kHz stereo.
pub const MAX_WAV_SAMPLES: u64 = 1 << 28;
/// Largest TOML file read (`scan.toml`, params and presets, synth settings).
pub const MAX_TOML_BYTES: u64 = 1 << 20;
/// Most cells a Hough accumulator may have (the stripe stage refuses larger ones).
pub const MAX_HOUGH_CELLS: usize = crate::pipeline::hough::MAX_ACCUMULATOR_CELLS;

/// Checks a frame's width and height (from its header) against the limits, before decoding.
///
/// # Errors
/// A sentence giving the size found and the limit it passes.
pub fn check_frame_size(width: u64, height: u64) -> Result<(), String> {
    if width == 0 || height == 0 {
        return Err(format!("frame is {width}×{height} px: it has no pixels"));
    }
    if width > MAX_FRAME_SIDE_PX || height > MAX_FRAME_SIDE_PX {
        return Err(format!(
            "frame is {width}×{height} px, past the limit of {MAX_FRAME_SIDE_PX} px a side"
        ));
    }
    let pixels = width * height;
    if pixels > MAX_FRAME_PIXELS {
        return Err(format!(
            "frame is {width}×{height} px = {pixels} pixels, past the limit of {MAX_FRAME_PIXELS}"
        ));
    }
    Ok(())
}

/// Checks a file's size before it is read whole.
///
/// # Errors
/// [`LoadError::Io`] naming the file when it cannot be examined or is larger than `max_bytes`.
pub fn check_file_size(path: &Path, max_bytes: u64, what: &str) -> Result<u64, LoadError> {
    let len = std::fs::metadata(path)
        .map_err(|e| LoadError::Io {
            problem: format!("cannot read {what}: {e}"),
            path: path.to_path_buf(),
        })?
        .len();
    if len > max_bytes {
        return Err(LoadError::Io {
            problem: format!("{what} is {len} bytes, past the limit of {max_bytes}"),
            path: path.to_path_buf(),
        });
    }
    Ok(len)
}

/// Reads a whole file of at most `max_bytes` (a file that grows while it is read is cut at
/// the limit and refused).
///
/// # Errors
/// [`LoadError::Io`] naming the file when it is missing, unreadable or too large.
pub fn read_limited(path: &Path, max_bytes: u64, what: &str) -> Result<Vec<u8>, LoadError> {
    let len = check_file_size(path, max_bytes, what)?;
    let io_err = |e: std::io::Error| LoadError::Io {
        problem: format!("cannot read {what}: {e}"),
        path: path.to_path_buf(),
    };
    let file = std::fs::File::open(path).map_err(io_err)?;
    let mut bytes = Vec::with_capacity(usize::try_from(len).unwrap_or(0));
    file.take(max_bytes + 1)
        .read_to_end(&mut bytes)
        .map_err(io_err)?;
    if bytes.len() as u64 > max_bytes {
        return Err(LoadError::Io {
            problem: format!("{what} grew past the limit of {max_bytes} bytes while it was read"),
            path: path.to_path_buf(),
        });
    }
    Ok(bytes)
}

/// Reads a TOML file (at most [`MAX_TOML_BYTES`]) as UTF-8 text.
///
/// # Errors
/// [`LoadError::Io`] naming the file when it is missing, too large or not UTF-8.
pub fn read_toml_text(path: &Path, what: &str) -> Result<String, LoadError> {
    let bytes = read_limited(path, MAX_TOML_BYTES, what)?;
    String::from_utf8(bytes).map_err(|e| LoadError::Io {
        problem: format!(
            "{what} is not UTF-8 text (byte {})",
            e.utf8_error().valid_up_to()
        ),
        path: path.to_path_buf(),
    })
}

/// Checks that `params` make a Hough accumulator of at most [`MAX_HOUGH_CELLS`] on this
/// scan's frames (the first frame's height), when the dual-focus path runs: `reconstruct`
/// refuses such params before any group runs instead of every group failing alike.
///
/// # Errors
/// A sentence naming the keys and both numbers (the caller adds the params file), or why
/// the first frame's header cannot be read.
pub fn check_hough_accumulator(
    params: &crate::pipeline::PipelineParams,
    scan: &super::Scan,
) -> Result<(), String> {
    if !params.uses_dual_focus(&scan.meta) {
        return Ok(());
    }
    let Some(frame) = scan.groups.first().and_then(|g| g.frame_path(0)) else {
        return Ok(());
    };
    let (_, height) = super::frames::frame_dimensions(&frame).map_err(|e| e.to_string())?;
    let cells = crate::pipeline::hough::accumulator_cells(&params.hough, height);
    if cells > MAX_HOUGH_CELLS {
        let h = &params.hough;
        return Err(format!(
            "hough.theta_step_deg = {} and hough.rho_step_px = {} make a Hough accumulator of {cells} cells for {height}-row frames, past the limit of {MAX_HOUGH_CELLS}",
            h.theta_step_deg, h.rho_step_px
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_sizes_past_the_limits_are_refused_with_the_numbers() {
        assert!(check_frame_size(1280, 1024).is_ok());
        let msg = check_frame_size(50_000, 50_000).unwrap_err();
        assert!(
            msg.contains("50000×50000") && msg.contains("16384"),
            "{msg}"
        );
        let msg = check_frame_size(16_384, 16_384).unwrap_err();
        assert!(
            msg.contains("268435456") && msg.contains("67108864"),
            "{msg}"
        );
        assert!(check_frame_size(0, 5).is_err());
    }

    #[test]
    fn toml_files_past_the_limit_are_refused_before_reading() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("big.toml");
        std::fs::write(&p, vec![b'#'; usize::try_from(MAX_TOML_BYTES).unwrap() + 1]).unwrap();
        let msg = read_toml_text(&p, "params").unwrap_err().to_string();
        assert!(msg.contains("big.toml") && msg.contains("1048576"), "{msg}");
        std::fs::write(&p, b"a = 1\n").unwrap();
        assert_eq!(read_toml_text(&p, "params").unwrap(), "a = 1\n");
        std::fs::write(&p, b"a = \"\xff\"\n").unwrap();
        let msg = read_toml_text(&p, "params").unwrap_err().to_string();
        assert!(msg.contains("UTF-8") && msg.contains("big.toml"), "{msg}");
    }
}
