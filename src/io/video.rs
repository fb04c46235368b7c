//! Video import (feature `video`): decodes an AVI/MP4/MKV clip to grey frames and writes them as a scan folder (or, `store.rs`, a Zarr store).
//!
//! Every frame is decoded in order (FFmpeg through `ffmpeg-next`), converted to grey — 16-bit
//! when the source format holds more than 8 bits per component, else 8-bit — and streamed into
//! groups of `frames_per_group` frames whose first frames lie `group_stride_frames` apart
//! (a stride below the group size repeats frames in consecutive groups; above it, frames between
//! groups are skipped). A trailing group the clip cannot fill is dropped.
//!
//! The scan is written into a hidden temporary sibling folder and renamed into place at the end,
//! so a failed or cancelled import leaves nothing behind; the target must not exist or be empty.
//! An import killed outright (power cut, `kill -9`) cannot clean up: the next import to the same
//! target removes such a folder once the process that made it is gone (where the OS lets us see
//! that, i.e. Linux's `/proc`) and nothing has written to it for an hour, and says so in its
//! summary.
//! `scan.toml` is built from [`ClipMeta`] with [`super::ScanMeta`], checked by [`super::ScanMeta::validate`]
//! (the check [`super::Scan::open`] applies); an extra `[video_import]` table records the source
//! clip and the grouping (the format keeps such tables and ignores them).

use std::path::{Path, PathBuf};

use ffmpeg::media::Type;
use ffmpeg::util::frame::video::Video as VideoFrame;
use ffmpeg_next as ffmpeg;
use serde::Serialize;

use super::LoadError;
use super::atomic::{dir_is_missing_or_empty, write_atomic};
use super::staged::{StagedDir, remove_stale};
use crate::image::Image;
use crate::job::Job;
use grey::{GreyConverter, Splitter, component_depth_bits, estimated_frames};

/// The kind in the names of an import's temporary folders (`.NAME.import-PID.tmp`).
const IMPORT: &str = "import";

mod encode;
mod grey;
mod layout;
mod store;

pub use encode::encode_grey_clip;
pub use layout::{ClipMeta, GroupLayout};
pub use store::import_video_to_store;

/// Frames per group when the caller does not say (the paper's choice for real records).
pub const DEFAULT_FRAMES_PER_GROUP: usize = 12;

/// Why a clip could not be imported. Messages about the clip end with its path.
#[derive(Debug, thiserror::Error)]
pub enum VideoError {
    /// The clip file does not exist.
    #[error("no such video file: {}", path.display())]
    Missing {
        /// The clip.
        path: PathBuf,
    },
    /// FFmpeg cannot read the file as a container.
    #[error("not a video file ({problem}): {}", path.display())]
    NotAVideo {
        /// FFmpeg's message.
        problem: String,
        /// The clip.
        path: PathBuf,
    },
    /// The container holds no video stream (an audio file, for example).
    #[error("the file holds no video stream: {}", path.display())]
    NoVideoStream {
        /// The clip.
        path: PathBuf,
    },
    /// This FFmpeg has no decoder for the clip's codec.
    #[error("unsupported video codec {codec} ({problem}): {}", path.display())]
    UnsupportedCodec {
        /// Codec name.
        codec: String,
        /// FFmpeg's message.
        problem: String,
        /// The clip.
        path: PathBuf,
    },
    /// A packet or frame failed to decode or convert.
    #[error("cannot decode frame {frame} ({problem}): {}", path.display())]
    Decode {
        /// Index of the frame (from 0) being decoded.
        frame: usize,
        /// What went wrong.
        problem: String,
        /// The clip.
        path: PathBuf,
    },
    /// The clip decoded to no frames at all.
    #[error("the clip holds no frames: {}", path.display())]
    NoFrames {
        /// The clip.
        path: PathBuf,
    },
    /// The clip (from the first frame used) is shorter than one group.
    #[error("the clip has {found} frames from the first frame used, one group needs {needed}: {}", path.display())]
    TooFewFrames {
        /// Frames available.
        found: usize,
        /// Frames one group needs.
        needed: usize,
        /// The clip.
        path: PathBuf,
    },
    /// A grouping or metadata setting is invalid.
    #[error("invalid import setting: {problem}")]
    Settings {
        /// The key and the problem.
        problem: String,
    },
    /// The output folder exists and is not empty; nothing was written.
    #[error("refusing to write into a folder that is not empty: {}", path.display())]
    OutputExists {
        /// The folder.
        path: PathBuf,
    },
    /// A file could not be written (the message names it).
    #[error(transparent)]
    Load(#[from] LoadError),
    /// The cancel flag was raised; nothing was left behind.
    #[error("cancelled")]
    Cancelled,
    /// An import into a store stopped after writing groups, and kept them to go on from.
    #[error("{error}{kept}")]
    Kept {
        /// Why it stopped.
        error: Box<VideoError>,
        /// What it kept.
        kept: crate::io::zarr::Kept,
    },
}

/// The `[video_import]` table: where the scan came from.
#[derive(Serialize)]
struct ImportInfo<'a> {
    source: &'a str,
    codec: &'a str,
    first_frame: usize,
    frames_per_group: usize,
    group_stride_frames: usize,
}

/// What [`import_video`] wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct ImportSummary {
    /// The scan folder.
    pub out_dir: PathBuf,
    /// Groups written.
    pub groups: usize,
    /// Frames in each group.
    pub frames_per_group: usize,
    /// Frames between the first frames of consecutive groups.
    pub group_stride_frames: usize,
    /// Frames decoded from the clip (including skipped ones).
    pub frames_decoded: usize,
    /// Frame width in pixels.
    pub width: usize,
    /// Frame height in pixels.
    pub height: usize,
    /// Bits per pixel of the written PNGs (8 or 16).
    pub bit_depth: u8,
    /// The clip's codec name.
    pub codec: String,
    /// Unfinished folder imports to the same target, left by killed runs, that were removed
    /// (always none for a store: its partial store is resumed or refused instead).
    pub removed_stale: Vec<PathBuf>,
    /// Groups an interrupted import into a store had written, taken over by `--resume`.
    pub resumed_groups: usize,
}

fn io_err(problem: String, path: &Path) -> VideoError {
    VideoError::Load(LoadError::Io {
        problem,
        path: path.to_path_buf(),
    })
}

/// Fails unless `out_dir` is missing or an empty folder.
fn check_out_dir(out_dir: &Path) -> Result<(), VideoError> {
    if dir_is_missing_or_empty(out_dir)? {
        Ok(())
    } else {
        Err(VideoError::OutputExists {
            path: out_dir.to_path_buf(),
        })
    }
}

/// What takes the decoded grey frames: a scan folder's groups ([`grey::Splitter`]) or a
/// store's ([`store::StoreSink`]).
trait FrameSink {
    /// Whether frame `j` (counted from the first frame used) is still needed: a resumed store
    /// holds its first groups already, and their frames are decoded but not converted.
    fn wants(&self, _j: usize) -> bool {
        true
    }

    /// Takes frame `j`, grey, 16-bit when `sixteen_bit`.
    fn push(&mut self, j: usize, img: &Image, sixteen_bit: bool) -> Result<(), VideoError>;
}

/// A clip opened for decoding.
struct Source {
    input: ffmpeg::format::context::Input,
    stream_index: usize,
    decoder: ffmpeg::decoder::Video,
    /// The codec's name.
    codec: String,
    /// 16-bit output, when the codec parameters say (else the first frame does).
    sixteen_bit: Option<bool>,
    /// Frames expected to be decoded (0 when the container does not say).
    total: usize,
    /// Groups expected, for the width of the group numbers.
    est_groups: usize,
}

/// Opens `clip` for decoding by `layout`.
fn open_source(clip: &Path, layout: &GroupLayout) -> Result<Source, VideoError> {
    if !clip.is_file() {
        return Err(VideoError::Missing {
            path: clip.to_path_buf(),
        });
    }
    ffmpeg::init().map_err(|e| VideoError::NotAVideo {
        problem: format!("FFmpeg failed to start: {e}"),
        path: clip.to_path_buf(),
    })?;
    // Our errors name the file; FFmpeg's own log lines would only repeat them on stderr.
    ffmpeg::util::log::set_level(ffmpeg::util::log::Level::Fatal);
    let input = ffmpeg::format::input(clip).map_err(|e| VideoError::NotAVideo {
        problem: e.to_string(),
        path: clip.to_path_buf(),
    })?;
    let Some(stream) = input.streams().best(Type::Video) else {
        return Err(VideoError::NoVideoStream {
            path: clip.to_path_buf(),
        });
    };
    let stream_index = stream.index();
    let params = stream.parameters();
    let codec_id = params.id();
    let codec = format!("{codec_id:?}").to_lowercase();
    let unsupported = |e: ffmpeg::Error| VideoError::UnsupportedCodec {
        codec: codec.clone(),
        problem: e.to_string(),
        path: clip.to_path_buf(),
    };
    if ffmpeg::decoder::find(codec_id).is_none() {
        return Err(unsupported(ffmpeg::Error::DecoderNotFound));
    }
    let decoder = ffmpeg::codec::context::Context::from_parameters(params)
        .and_then(|c| c.decoder().video())
        .map_err(unsupported)?;
    // The depth is known from the codec parameters for most clips, else from the first frame.
    let sixteen_bit: Option<bool> = (decoder.format() != ffmpeg::format::Pixel::None)
        .then(|| component_depth_bits(decoder.format()) > 8);
    let mut total = estimated_frames(&stream);
    if let Some(needed) = layout.frames_needed() {
        let needed = needed + layout.first_frame;
        total = if total == 0 {
            needed
        } else {
            total.min(needed)
        };
    }
    let est_groups = layout
        .max_groups
        .unwrap_or(0)
        .max(layout.full_groups(total.saturating_sub(layout.first_frame)));
    Ok(Source {
        input,
        stream_index,
        decoder,
        codec,
        sixteen_bit,
        total,
        est_groups,
    })
}

/// What decoding gave.
struct Decoded {
    /// Frames decoded from the clip (including skipped ones).
    decoded: usize,
    /// Frames taken, from the first frame used.
    taken: usize,
    /// The frames' size.
    size: Option<(usize, usize)>,
    /// Whether they were made 16-bit.
    sixteen_bit: bool,
}

/// Decodes `src` in order into `sink`, frames from `layout.first_frame` on, until the clip
/// ends or `max_groups` groups are full. `job` is told `(decoded, total)` after every frame.
/// A frame that no group holds, or that the sink does not want, is decoded but not converted.
///
/// # Errors
/// A frame that fails to decode or convert, or a clip with no frames or too few for a group.
fn decode_into(
    src: &mut Source,
    clip: &Path,
    layout: &GroupLayout,
    job: Job<'_>,
    sink: &mut dyn FrameSink,
) -> Result<Decoded, VideoError> {
    let total = src.total;
    let mut converter: Option<GreyConverter> = None;
    let mut out = Decoded {
        decoded: 0,
        taken: 0,
        size: None,
        sixteen_bit: false,
    };
    let mut sixteen_bit = src.sixteen_bit;
    let mut frame = VideoFrame::empty();
    job.report(0, total);

    // Sends a packet (or, with `None`, the end of stream) and takes every frame the decoder has
    // ready; returns false once enough groups are full.
    let mut feed = |decoder: &mut ffmpeg::decoder::Video,
                    packet: Option<&ffmpeg::Packet>,
                    out: &mut Decoded|
     -> Result<bool, VideoError> {
        let decode_err = |frame: usize, problem: String| VideoError::Decode {
            frame,
            problem,
            path: clip.to_path_buf(),
        };
        let sent = match packet {
            Some(p) => decoder.send_packet(p),
            None => decoder.send_eof(),
        };
        sent.map_err(|e| decode_err(out.decoded, e.to_string()))?;
        while decoder.receive_frame(&mut frame).is_ok() {
            if job.is_cancelled() {
                return Err(VideoError::Cancelled);
            }
            if out.decoded >= layout.first_frame {
                let deep =
                    *sixteen_bit.get_or_insert_with(|| component_depth_bits(frame.format()) > 8);
                out.sixteen_bit = deep;
                // A frame between groups (a stride above the group size) is not converted.
                let placed = layout.placements(out.taken).next().is_some();
                if placed && sink.wants(out.taken) {
                    let img = converter
                        .get_or_insert_with(|| GreyConverter::new(deep))
                        .convert(&frame)
                        .map_err(|e| {
                            decode_err(out.decoded, format!("grey conversion failed: {e}"))
                        })?;
                    let this = (img.width, img.height);
                    let first = *out.size.get_or_insert(this);
                    if this != first {
                        return Err(decode_err(
                            out.decoded,
                            format!(
                                "frame is {}x{} but the clip's first frame is {}x{}",
                                this.0, this.1, first.0, first.1
                            ),
                        ));
                    }
                    sink.push(out.taken, &img, deep)?;
                }
                out.taken += 1;
            }
            out.decoded += 1;
            job.report(out.decoded, total.max(out.decoded));
            if layout.frames_needed().is_some_and(|n| out.taken >= n) {
                return Ok(false);
            }
        }
        Ok(true)
    };
    let mut more = true;
    for (stream, packet) in src.input.packets() {
        if job.is_cancelled() {
            return Err(VideoError::Cancelled);
        }
        if stream.index() == src.stream_index {
            more = feed(&mut src.decoder, Some(&packet), &mut out)?;
            if !more {
                break;
            }
        }
    }
    if more {
        // End of stream: the decoder may still hold delayed frames.
        feed(&mut src.decoder, None, &mut out)?;
    }
    // The container's frame count is only an estimate; end the bar at what was decoded.
    job.report(out.decoded, out.decoded);
    if out.decoded == 0 {
        return Err(VideoError::NoFrames {
            path: clip.to_path_buf(),
        });
    }
    if layout.groups_written(out.taken) == 0 {
        return Err(VideoError::TooFewFrames {
            found: out.taken,
            needed: layout.frames_per_group,
            path: clip.to_path_buf(),
        });
    }
    Ok(out)
}

/// `scan.toml` of an imported clip: `scan_meta` with a `[video_import]` table naming the clip
/// and the grouping.
fn imported_scan_toml(
    mut scan_meta: super::ScanMeta,
    clip: &Path,
    codec: &str,
    layout: &GroupLayout,
) -> Result<String, VideoError> {
    let source = clip
        .file_name()
        .map_or_else(|| clip.to_string_lossy(), |n| n.to_string_lossy())
        .into_owned();
    let info = ImportInfo {
        source: &source,
        codec,
        first_frame: layout.first_frame,
        frames_per_group: layout.frames_per_group,
        group_stride_frames: layout.stride(),
    };
    let info = toml::Table::try_from(&info).map_err(|e| VideoError::Settings {
        problem: format!("cannot write [video_import]: {e}"),
    })?;
    scan_meta
        .extra
        .insert("video_import".into(), toml::Value::Table(info));
    scan_meta
        .to_toml_string()
        .map_err(|e| VideoError::Settings {
            problem: format!("cannot write scan.toml: {e}"),
        })
}

/// The scan metadata of an import by `layout` with `meta`, once both are checked.
fn checked_settings(layout: &GroupLayout, meta: &ClipMeta) -> Result<super::ScanMeta, VideoError> {
    layout
        .validate()
        .map_err(|problem| VideoError::Settings { problem })?;
    meta.scan_meta(layout)
}

/// Imports `clip` as a scan in `out_dir` (missing or empty; created).
///
/// `job` is told `(decoded, total)` with 0 first and after every decoded frame; `total` is
/// the number of frames expected to be decoded (0 when the container does not say). Cancelling
/// `job` stops before the next frame with [`VideoError::Cancelled`]; nothing is left behind
/// then, nor after any other error.
///
/// # Errors
/// [`VideoError`] naming the clip (missing, not a video, no video stream, unsupported codec,
/// no frames, too few frames for one group), the output folder, or the file that failed.
pub fn import_video(
    clip: &Path,
    out_dir: &Path,
    layout: &GroupLayout,
    meta: &ClipMeta,
    job: Job<'_>,
) -> Result<ImportSummary, VideoError> {
    let scan_meta = checked_settings(layout, meta)?;
    let mut src = open_source(clip, layout)?;
    check_out_dir(out_dir)?;
    let removed_stale = remove_stale(out_dir, IMPORT);
    let tmp = StagedDir::create(out_dir, IMPORT)?;
    let mut splitter = Splitter {
        layout,
        dir: tmp.path(),
        group_digits: crate::synth::digits(src.est_groups, 5),
        frame_digits: crate::synth::digits(layout.frames_per_group, 3),
    };
    let decoded = decode_into(&mut src, clip, layout, job, &mut splitter)?;
    let groups = splitter.finish(decoded.taken)?;
    let meta_text = imported_scan_toml(scan_meta, clip, &src.codec, layout)?;
    write_atomic(&tmp.path().join("scan.toml"), meta_text.as_bytes(), false)?;
    if job.is_cancelled() {
        return Err(VideoError::Cancelled);
    }
    finish_into(tmp, out_dir)?;
    let (width, height) = decoded.size.unwrap_or((0, 0));
    Ok(ImportSummary {
        out_dir: out_dir.to_path_buf(),
        groups,
        frames_per_group: layout.frames_per_group,
        group_stride_frames: layout.stride(),
        frames_decoded: decoded.decoded,
        width,
        height,
        bit_depth: if decoded.sixteen_bit { 16 } else { 8 },
        codec: src.codec,
        removed_stale,
        resumed_groups: 0,
    })
}

/// Renames the finished temporary folder to `out_dir` (replacing it only when it is empty).
fn finish_into(tmp: StagedDir, out_dir: &Path) -> Result<(), VideoError> {
    check_out_dir(out_dir)?;
    Ok(tmp.finish(out_dir)?)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests;
