//! Decoded frames to grey images (8- or 16-bit) and the streaming split of frames into group folders.

use std::path::{Path, PathBuf};

use ffmpeg::format::Pixel;
use ffmpeg::software::scaling;
use ffmpeg::util::frame::video::Video as VideoFrame;
use ffmpeg_next as ffmpeg;

use super::{FrameSink, GroupLayout, VideoError, io_err};
use crate::image::Image;
use crate::io::frames::save_grey_png;

/// Bits per component of `format` (8 when FFmpeg does not know the format).
///
/// Derived from FFmpeg's safe `bits_per_pixel`, which counts the chroma planes at their
/// subsampled size: the bits are divided by the components per pixel, where the two chroma
/// components of a format with three or more count 1/2^(log2_chroma_w + log2_chroma_h) each.
/// That gives gray16 16, yuv420p10 10, p010 10, rgb48 16, yuva420p10 10, and 8 or less for
/// every 8-bit and packed format (rgb565 5, nv12 8, pal8 8).
pub(super) fn component_depth_bits(format: Pixel) -> i32 {
    let Some(desc) = format.descriptor() else {
        return 8;
    };
    let components = i32::from(desc.nb_components());
    if components == 0 {
        return 8;
    }
    let chroma = if components >= 3 { 2 } else { 0 };
    let sub = 1i32 << (u32::from(desc.log2_chroma_w()) + u32::from(desc.log2_chroma_h())).min(8);
    // Components per pixel, scaled by `sub` so that it stays an integer.
    let per_pixel_scaled = (components - chroma) * sub + chroma;
    (desc.bits_per_pixel() * sub + per_pixel_scaled / 2) / per_pixel_scaled
}

/// Converts decoded frames to grey images, through swscale when the format is not grey already.
pub(super) struct GreyConverter {
    target: Pixel,
    scaler: Option<(scaling::Context, Pixel, u32, u32)>,
    converted: VideoFrame,
}

impl GreyConverter {
    pub(super) fn new(sixteen_bit: bool) -> Self {
        Self {
            target: if sixteen_bit {
                Pixel::GRAY16LE
            } else {
                Pixel::GRAY8
            },
            scaler: None,
            converted: VideoFrame::empty(),
        }
    }

    pub(super) fn convert(&mut self, frame: &VideoFrame) -> Result<Image, ffmpeg::Error> {
        let (fmt, w, h) = (frame.format(), frame.width(), frame.height());
        let grey = if fmt == self.target {
            frame
        } else {
            let stale = self
                .scaler
                .as_ref()
                .is_none_or(|(_, f, sw, sh)| (*f, *sw, *sh) != (fmt, w, h));
            if stale {
                let ctx = scaling::Context::get(
                    fmt,
                    w,
                    h,
                    self.target,
                    w,
                    h,
                    scaling::Flags::POINT | scaling::Flags::ACCURATE_RND,
                )?;
                self.scaler = Some((ctx, fmt, w, h));
            }
            if let Some((ctx, ..)) = self.scaler.as_mut() {
                ctx.run(frame, &mut self.converted)?;
            }
            &self.converted
        };
        let (wu, hu) = (w as usize, h as usize);
        let stride = grey.stride(0);
        let bytes = grey.data(0);
        let mut data = Vec::with_capacity(wu * hu);
        for y in 0..hu {
            let row = bytes.get(y * stride..).ok_or(ffmpeg::Error::InvalidData)?;
            if self.target == Pixel::GRAY16LE {
                let row = row.get(..wu * 2).ok_or(ffmpeg::Error::InvalidData)?;
                data.extend(
                    row.chunks_exact(2)
                        .map(|b| f32::from(u16::from_le_bytes([b[0], b[1]])) / 65535.0),
                );
            } else {
                let row = row.get(..wu).ok_or(ffmpeg::Error::InvalidData)?;
                data.extend(row.iter().map(|&v| f32::from(v) / 255.0));
            }
        }
        Ok(Image {
            width: wu,
            height: hu,
            data,
        })
    }
}

/// Streams decoded frames into group folders.
pub(super) struct Splitter<'a> {
    pub(super) layout: &'a GroupLayout,
    pub(super) dir: &'a Path,
    pub(super) group_digits: usize,
    pub(super) frame_digits: usize,
}

impl Splitter<'_> {
    fn group_dir(&self, g: usize) -> PathBuf {
        self.dir
            .join(crate::synth::group_name(g, self.group_digits))
    }

    /// Removes the folders of trailing groups the `taken` frames did not fill; returns the
    /// full groups.
    pub(super) fn finish(&self, taken: usize) -> Result<usize, VideoError> {
        let full = self.layout.groups_written(taken);
        let mut g = full;
        loop {
            let gdir = self.group_dir(g);
            if !gdir.is_dir() {
                break;
            }
            std::fs::remove_dir_all(&gdir)
                .map_err(|e| io_err(format!("cannot remove partial group: {e}"), &gdir))?;
            g += 1;
        }
        Ok(full)
    }
}

impl FrameSink for Splitter<'_> {
    /// Writes frame `j` into every group holding it.
    fn push(&mut self, j: usize, img: &Image, sixteen_bit: bool) -> Result<(), VideoError> {
        for (g, k) in self.layout.placements(j) {
            let gdir = self.group_dir(g);
            if k == 0 {
                std::fs::create_dir(&gdir)
                    .map_err(|e| io_err(format!("cannot create group folder: {e}"), &gdir))?;
            }
            let fw = self.frame_digits;
            save_grey_png(
                img,
                &gdir.join(format!("f{k:0fw$}.png")),
                sixteen_bit,
                false,
            )?;
        }
        Ok(())
    }
}

/// Frames in the clip's stream as the container states or its duration implies; 0 = unknown.
pub(super) fn estimated_frames(stream: &ffmpeg::format::stream::Stream<'_>) -> usize {
    if let Ok(n) = usize::try_from(stream.frames())
        && n > 0
    {
        return n;
    }
    let (rate, tb) = (stream.avg_frame_rate(), stream.time_base());
    if stream.duration() > 0 && rate.denominator() != 0 && tb.denominator() != 0 {
        let secs =
            stream.duration() as f64 * f64::from(tb.numerator()) / f64::from(tb.denominator());
        let fps = f64::from(rate.numerator()) / f64::from(rate.denominator());
        let n = (secs * fps).round();
        if n.is_finite() && n > 0.0 {
            return n as usize;
        }
    }
    0
}
