//! A lossless FFV1 encoder for grey frames: exact clips for tests and fixtures.

use std::path::Path;

use ffmpeg::format::Pixel;
use ffmpeg::util::frame::video::Video as VideoFrame;
use ffmpeg_next as ffmpeg;

use super::{VideoError, io_err};
use crate::image::Image;

/// Encodes grey frames losslessly (FFV1, 8- or 16-bit grey) into a clip at `path`; the container
/// follows the extension (`.avi`, `.mkv`). For tests and fixtures: an exact source to import.
///
/// # Errors
/// [`VideoError::Settings`] for no frames or mixed sizes, [`VideoError::Load`] naming `path`
/// when FFmpeg cannot write it.
pub fn encode_grey_clip(
    path: &Path,
    frames: &[Image],
    sixteen_bit: bool,
    frames_per_sec: i32,
) -> Result<(), VideoError> {
    let Some(first) = frames.first() else {
        return Err(VideoError::Settings {
            problem: "a clip needs at least one frame".into(),
        });
    };
    if frames.iter().any(|f| !f.same_size(first)) {
        return Err(VideoError::Settings {
            problem: "every frame of a clip must have the same size".into(),
        });
    }
    let fail = |e: ffmpeg::Error| io_err(format!("cannot encode video: {e}"), path);
    ffmpeg::init().map_err(fail)?;
    ffmpeg::util::log::set_level(ffmpeg::util::log::Level::Fatal);
    let (w, h) = (
        u32::try_from(first.width).map_err(|_| fail(ffmpeg::Error::InvalidData))?,
        u32::try_from(first.height).map_err(|_| fail(ffmpeg::Error::InvalidData))?,
    );
    let pixel = if sixteen_bit {
        Pixel::GRAY16LE
    } else {
        Pixel::GRAY8
    };
    let time_base = ffmpeg::Rational::new(1, frames_per_sec);
    let mut octx = ffmpeg::format::output(path).map_err(fail)?;
    let global_header = octx
        .format()
        .flags()
        .contains(ffmpeg::format::Flags::GLOBAL_HEADER);
    let codec = ffmpeg::encoder::find(ffmpeg::codec::Id::FFV1)
        .ok_or(ffmpeg::Error::EncoderNotFound)
        .map_err(fail)?;
    let mut ost = octx.add_stream(codec).map_err(fail)?;
    let mut enc = ffmpeg::codec::context::Context::new_with_codec(codec)
        .encoder()
        .video()
        .map_err(fail)?;
    enc.set_width(w);
    enc.set_height(h);
    enc.set_format(pixel);
    enc.set_time_base(time_base);
    enc.set_frame_rate(Some(ffmpeg::Rational::new(frames_per_sec, 1)));
    if global_header {
        enc.set_flags(ffmpeg::codec::Flags::GLOBAL_HEADER);
    }
    let mut enc = enc.open_as(codec).map_err(fail)?;
    ost.set_parameters(&enc);
    ost.set_time_base(time_base);
    octx.write_header().map_err(fail)?;
    let stream_tb = octx
        .stream(0)
        .map(|s| s.time_base())
        .ok_or(ffmpeg::Error::StreamNotFound)
        .map_err(fail)?;
    let mut packet = ffmpeg::Packet::empty();
    let mut write_ready = |enc: &mut ffmpeg::encoder::Video,
                           octx: &mut ffmpeg::format::context::Output| {
        while enc.receive_packet(&mut packet).is_ok() {
            packet.set_stream(0);
            packet.rescale_ts(time_base, stream_tb);
            packet.write_interleaved(octx)?;
        }
        Ok::<(), ffmpeg::Error>(())
    };
    for (i, img) in frames.iter().enumerate() {
        let mut vf = VideoFrame::new(pixel, w, h);
        let stride = vf.stride(0);
        let plane = vf.data_mut(0);
        for (y, row) in img.data.chunks_exact(img.width.max(1)).enumerate() {
            let dst = &mut plane[y * stride..];
            for (x, v) in row.iter().enumerate() {
                let v = v.clamp(0.0, 1.0);
                if sixteen_bit {
                    let q = (v * 65535.0).round() as u16;
                    dst[2 * x..2 * x + 2].copy_from_slice(&q.to_le_bytes());
                } else {
                    dst[x] = (v * 255.0).round() as u8;
                }
            }
        }
        vf.set_pts(i64::try_from(i).ok());
        enc.send_frame(&vf).map_err(fail)?;
        write_ready(&mut enc, &mut octx).map_err(fail)?;
    }
    enc.send_eof().map_err(fail)?;
    write_ready(&mut enc, &mut octx).map_err(fail)?;
    octx.write_trailer().map_err(fail)?;
    Ok(())
}
