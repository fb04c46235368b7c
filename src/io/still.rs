//! Still images, streamed: a PNG or TIFF read a few rows at a time as grey `f32`, so a flatbed
//! scan of a whole side (hundreds of megapixels) is never held in memory; and grey stills saved
//! as 8/16-bit PNG or TIFF.
//!
//! PNGs stream row by row (an interlaced PNG is decoded whole, up to
//! [`MAX_WHOLE_DECODE_PIXELS`]); TIFFs stream strip by strip (a tiled TIFF is decoded whole).
//! Colour is converted to grey with Rec. 709 weights, like scan frames.

use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};

use super::LoadError;
use super::frames::{load_frame, save_grey_as};
use crate::image::Image;

/// Largest still side accepted, px.
pub const MAX_STILL_SIDE_PX: usize = 1 << 22;
/// Largest still accepted, pixels (2³¹ ≈ 2.1 Gpx: a whole side at 2400 dpi is about 0.83 Gpx).
pub const MAX_STILL_PIXELS: usize = 1 << 31;
/// Largest image decoded whole when it cannot be streamed (interlaced PNG, tiled TIFF).
pub const MAX_WHOLE_DECODE_PIXELS: usize = 1 << 25;

/// Rec. 709 luma weights.
const LUMA: [f32; 3] = [0.2126, 0.7152, 0.0722];

fn bad(path: &Path, problem: impl Into<String>) -> LoadError {
    LoadError::Io {
        problem: problem.into(),
        path: path.to_path_buf(),
    }
}

/// How one PNG row's bytes become grey.
#[derive(Clone, Copy, Debug)]
struct PngLayout {
    channels: usize,
    sixteen: bool,
}

enum Source {
    Png {
        reader: Box<png::Reader<BufReader<File>>>,
        layout: PngLayout,
    },
    Tiff {
        decoder: Box<tiff::decoder::Decoder<BufReader<File>>>,
        next_strip: u32,
        strips: u32,
        /// Rows decoded but not yet handed out.
        pending: Vec<f32>,
    },
    Whole(Image),
}

/// A still opened for reading rows in order.
pub struct StillReader {
    path: PathBuf,
    width: usize,
    height: usize,
    next_row: usize,
    source: Source,
}

fn check_size(path: &Path, width: usize, height: usize) -> Result<(), LoadError> {
    if width == 0 || height == 0 {
        return Err(bad(path, "the image is empty"));
    }
    if width > MAX_STILL_SIDE_PX
        || height > MAX_STILL_SIDE_PX
        || width.saturating_mul(height) > MAX_STILL_PIXELS
    {
        return Err(bad(
            path,
            format!(
                "{width} × {height} px is larger than the still limit ({MAX_STILL_SIDE_PX} px a side, \
                 {MAX_STILL_PIXELS} px in all); cut it into strips"
            ),
        ));
    }
    Ok(())
}

/// Grey values of `count` pixels of `channels` samples each read by `sample(i)` (in [0, 1]).
fn grey_into(out: &mut Vec<f32>, count: usize, channels: usize, sample: impl Fn(usize) -> f32) {
    out.reserve(count);
    for i in 0..count {
        let b = i * channels;
        let v = if channels >= 3 {
            LUMA[0] * sample(b) + LUMA[1] * sample(b + 1) + LUMA[2] * sample(b + 2)
        } else {
            sample(b)
        };
        out.push(v);
    }
}

impl StillReader {
    /// Opens a PNG or TIFF still (by its content, not its name) and checks its size.
    ///
    /// # Errors
    /// [`LoadError::Io`] naming the file when it is missing, not a PNG or TIFF, corrupt,
    /// empty or over the size limits.
    pub fn open(path: &Path) -> Result<Self, LoadError> {
        if path.is_dir() {
            let what = if super::Scan::is_scan_dir(path) {
                "a scan, not a still image: decode it with `groovescope reconstruct`"
            } else {
                "a folder, not a still image (PNG or TIFF)"
            };
            return Err(bad(path, what));
        }
        let file =
            File::open(path).map_err(|e| bad(path, format!("cannot open the still: {e}")))?;
        let mut magic = [0u8; 4];
        {
            use std::io::Read;
            let mut f = &file;
            f.read_exact(&mut magic)
                .map_err(|_| bad(path, "the file is too short to be an image"))?;
        }
        let file = File::open(path).map_err(|e| bad(path, e.to_string()))?;
        match magic {
            [0x89, b'P', b'N', b'G'] => Self::open_png(path, file),
            [b'I', b'I', 42, 0]
            | [b'M', b'M', 0, 42]
            | [b'I', b'I', 43, 0]
            | [b'M', b'M', 0, 43] => Self::open_tiff(path, file),
            _ => Err(bad(path, "not a PNG or TIFF image")),
        }
    }

    fn open_png(path: &Path, file: File) -> Result<Self, LoadError> {
        let mut decoder =
            png::Decoder::new_with_limits(BufReader::new(file), png::Limits { bytes: 1 << 30 });
        decoder.set_transformations(png::Transformations::EXPAND);
        let header = decoder
            .read_header_info()
            .map_err(|e| bad(path, e.to_string()))?;
        let (width, height) = (header.width as usize, header.height as usize);
        let interlaced = header.interlaced;
        check_size(path, width, height)?;
        if interlaced {
            return Self::open_whole(path, width, height);
        }
        let reader = decoder.read_info().map_err(|e| bad(path, e.to_string()))?;
        let (colour, depth) = reader.output_color_type();
        let layout = PngLayout {
            channels: colour.samples(),
            sixteen: depth == png::BitDepth::Sixteen,
        };
        Ok(Self {
            path: path.to_path_buf(),
            width,
            height,
            next_row: 0,
            source: Source::Png {
                reader: Box::new(reader),
                layout,
            },
        })
    }

    fn open_tiff(path: &Path, file: File) -> Result<Self, LoadError> {
        let mut decoder = tiff::decoder::Decoder::new(BufReader::new(file))
            .map_err(|e| bad(path, e.to_string()))?
            .with_limits(tiff::decoder::Limits::unlimited());
        let (w, h) = decoder.dimensions().map_err(|e| bad(path, e.to_string()))?;
        let (width, height) = (w as usize, h as usize);
        check_size(path, width, height)?;
        let colour = decoder.colortype().map_err(|e| bad(path, e.to_string()))?;
        match colour {
            tiff::ColorType::Gray(8 | 16)
            | tiff::ColorType::GrayA(8 | 16)
            | tiff::ColorType::RGB(8 | 16)
            | tiff::ColorType::RGBA(8 | 16) => {}
            other => {
                return Err(bad(
                    path,
                    format!("unsupported TIFF pixel type {other:?} (8/16-bit grey or RGB)"),
                ));
            }
        }
        if decoder.get_chunk_type() != tiff::decoder::ChunkType::Strip {
            return Self::open_whole(path, width, height);
        }
        let strips = decoder
            .strip_count()
            .map_err(|e| bad(path, e.to_string()))?;
        Ok(Self {
            path: path.to_path_buf(),
            width,
            height,
            next_row: 0,
            source: Source::Tiff {
                decoder: Box::new(decoder),
                next_strip: 0,
                strips,
                pending: Vec::new(),
            },
        })
    }

    fn open_whole(path: &Path, width: usize, height: usize) -> Result<Self, LoadError> {
        if width * height > MAX_WHOLE_DECODE_PIXELS {
            return Err(bad(
                path,
                format!(
                    "an interlaced PNG or tiled TIFF is decoded whole, and {width} × {height} px is over \
                     that limit ({MAX_WHOLE_DECODE_PIXELS} px); save it non-interlaced or in strips"
                ),
            ));
        }
        let image = load_frame(path)?;
        Ok(Self {
            path: path.to_path_buf(),
            width,
            height,
            next_row: 0,
            source: Source::Whole(image),
        })
    }

    /// An in-memory image served the same way (for tests and the workbench).
    #[must_use]
    pub fn from_image(image: Image, name: &Path) -> Self {
        Self {
            path: name.to_path_buf(),
            width: image.width,
            height: image.height,
            next_row: 0,
            source: Source::Whole(image),
        }
    }

    /// Image width, px.
    #[must_use]
    pub fn width(&self) -> usize {
        self.width
    }

    /// Image height, px.
    #[must_use]
    pub fn height(&self) -> usize {
        self.height
    }

    /// The file.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Index of the next row [`read_rows`](Self::read_rows) returns.
    #[must_use]
    pub fn next_row(&self) -> usize {
        self.next_row
    }

    /// Clears `out` and fills it with up to `max_rows` next rows (grey, `width` values each);
    /// returns how many were read (0 at the end).
    ///
    /// # Errors
    /// [`LoadError::Io`] naming the file when the data is truncated or corrupt.
    pub fn read_rows(&mut self, out: &mut Vec<f32>, max_rows: usize) -> Result<usize, LoadError> {
        out.clear();
        let want = max_rows.min(self.height - self.next_row);
        let w = self.width;
        let path = self.path.clone();
        let mut got = 0;
        while got < want {
            match &mut self.source {
                Source::Png { reader, layout } => {
                    let row = reader
                        .next_row()
                        .map_err(|e| bad(&path, format!("row {}: {e}", self.next_row + got)))?
                        .ok_or_else(|| {
                            bad(
                                &path,
                                format!("the image ends at row {}", self.next_row + got),
                            )
                        })?;
                    let data = row.data();
                    let ch = layout.channels;
                    if layout.sixteen {
                        if data.len() < 2 * w * ch {
                            return Err(bad(&path, "a row is shorter than the image width"));
                        }
                        grey_into(out, w, ch, |i| {
                            f32::from(u16::from_be_bytes([data[2 * i], data[2 * i + 1]])) / 65535.0
                        });
                    } else {
                        if data.len() < w * ch {
                            return Err(bad(&path, "a row is shorter than the image width"));
                        }
                        grey_into(out, w, ch, |i| f32::from(data[i]) / 255.0);
                    }
                    got += 1;
                }
                Source::Tiff {
                    decoder,
                    next_strip,
                    strips,
                    pending,
                } => {
                    if pending.len() < w {
                        if *next_strip >= *strips {
                            return Err(bad(
                                &path,
                                format!("the image ends at row {}", self.next_row + got),
                            ));
                        }
                        let chunk = decoder
                            .read_chunk(*next_strip)
                            .map_err(|e| bad(&path, format!("strip {next_strip}: {e}")))?;
                        *next_strip += 1;
                        let ch = match decoder.colortype() {
                            Ok(tiff::ColorType::GrayA(_)) => 2,
                            Ok(tiff::ColorType::RGB(_)) => 3,
                            Ok(tiff::ColorType::RGBA(_)) => 4,
                            _ => 1,
                        };
                        let mut grey = Vec::new();
                        match &chunk {
                            tiff::decoder::DecodingResult::U8(v) => {
                                grey_into(&mut grey, v.len() / ch, ch, |i| f32::from(v[i]) / 255.0);
                            }
                            tiff::decoder::DecodingResult::U16(v) => {
                                grey_into(&mut grey, v.len() / ch, ch, |i| {
                                    f32::from(v[i]) / 65535.0
                                });
                            }
                            _ => return Err(bad(&path, "unsupported TIFF sample format")),
                        }
                        let rows = grey.len() / w;
                        grey.truncate(rows * w);
                        pending.extend_from_slice(&grey);
                        continue;
                    }
                    let take = (pending.len() / w).min(want - got);
                    out.extend(pending.drain(..take * w));
                    got += take;
                }
                Source::Whole(img) => {
                    let first = self.next_row + got;
                    let take = want - got;
                    out.extend_from_slice(&img.data[first * w..(first + take) * w]);
                    got += take;
                }
            }
        }
        self.next_row += got;
        Ok(got)
    }
}

/// Saves a grey image (values in [0, 1], clamped) as an 8- or 16-bit PNG or TIFF (by the
/// extension: `.tif`/`.tiff` is TIFF), atomically.
///
/// # Errors
/// [`LoadError::Io`] when the file exists and `overwrite` is false, or the write fails.
pub fn save_grey_image(
    img: &Image,
    path: &Path,
    sixteen_bit: bool,
    overwrite: bool,
) -> Result<(), LoadError> {
    let tiff = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("tif") || e.eq_ignore_ascii_case("tiff"));
    let format = if tiff {
        image::ImageFormat::Tiff
    } else {
        image::ImageFormat::Png
    };
    save_grey_as(img, path, sixteen_bit, overwrite, format)
}
