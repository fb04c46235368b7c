//! Video import (feature `video`): decodes an AVI/MP4/MKV clip to grey frames and writes them as a scan folder.
//!
//! Every frame is decoded in order (FFmpeg through `ffmpeg-next`), converted to grey — 16-bit
//! when the source format holds more than 8 bits per component, else 8-bit — and streamed into
//! groups of `frames_per_group` frames whose first frames lie `group_stride_frames` apart
//! (a stride below the group size repeats frames in consecutive groups; above it, frames between
//! groups are skipped). A trailing group the clip cannot fill is dropped.
//!
//! The scan is written into a hidden temporary sibling folder and renamed into place at the end,
//! so a failed or cancelled import leaves nothing behind; the target must not exist or be empty.
//! `scan.toml` is built from [`ClipMeta`] with [`ScanMeta`] and checked by [`ScanMeta::validate`]
//! (the check [`super::Scan::open`] applies); an extra `[video_import]` table records the source
//! clip and the grouping (the format keeps such tables and ignores them).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use ffmpeg::format::Pixel;
use ffmpeg::media::Type;
use ffmpeg::software::scaling;
use ffmpeg::util::frame::video::Video as VideoFrame;
use ffmpeg_next as ffmpeg;
use serde::Serialize;

use super::LoadError;
use super::atomic::{dir_is_missing_or_empty, write_atomic};
use super::frames::save_grey_png;
use super::scan::{
    CameraMeta, Cut, FORMAT_VERSION, MIN_FRAMES_PER_GROUP, MotionMeta, RecordMeta, ScanMeta,
};
use crate::image::Image;

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
}

/// How a clip's frames are cut into groups.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct GroupLayout {
    /// Frames in each group (at least [`MIN_FRAMES_PER_GROUP`]).
    pub frames_per_group: usize,
    /// Frames between the first frames of consecutive groups; `None` = `frames_per_group`
    /// (no shared frames). Smaller values repeat frames; larger values skip frames.
    pub group_stride_frames: Option<usize>,
    /// Clip frames skipped before the first group.
    pub first_frame: usize,
    /// Write at most this many groups (decoding stops once they are full).
    pub max_groups: Option<usize>,
}

impl Default for GroupLayout {
    fn default() -> Self {
        Self {
            frames_per_group: DEFAULT_FRAMES_PER_GROUP,
            group_stride_frames: None,
            first_frame: 0,
            max_groups: None,
        }
    }
}

impl GroupLayout {
    /// Frames between the first frames of consecutive groups.
    #[must_use]
    pub fn stride(&self) -> usize {
        self.group_stride_frames.unwrap_or(self.frames_per_group)
    }

    /// Checks the grouping; returns the first problem.
    ///
    /// # Errors
    /// A sentence naming the setting.
    pub fn validate(&self) -> Result<(), String> {
        if self.frames_per_group < MIN_FRAMES_PER_GROUP {
            return Err(format!(
                "frames_per_group must be at least {MIN_FRAMES_PER_GROUP} (the derivative filters need {MIN_FRAMES_PER_GROUP}), got {}",
                self.frames_per_group
            ));
        }
        if self.stride() == 0 {
            return Err("group_stride_frames must be at least 1, got 0".into());
        }
        if self.max_groups == Some(0) {
            return Err("max_groups must be at least 1, got 0".into());
        }
        Ok(())
    }

    /// Full groups in `frames` frames counted from the first frame used (before `max_groups`).
    #[must_use]
    pub fn full_groups(&self, frames: usize) -> usize {
        if frames < self.frames_per_group {
            0
        } else {
            (frames - self.frames_per_group) / self.stride() + 1
        }
    }

    /// Groups written from `frames` frames (from the first frame used), `max_groups` applied.
    #[must_use]
    pub fn groups_written(&self, frames: usize) -> usize {
        let n = self.full_groups(frames);
        self.max_groups.map_or(n, |m| n.min(m))
    }

    /// Frames (from the first frame used) needed to fill `max_groups`, if set.
    fn frames_needed(&self) -> Option<usize> {
        self.max_groups
            .map(|m| (m - 1) * self.stride() + self.frames_per_group)
    }

    /// The groups frame `j` (from the first frame used) belongs to, with its index in each.
    fn placements(&self, j: usize) -> impl Iterator<Item = (usize, usize)> + '_ {
        let stride = self.stride();
        let lo = (j + 1)
            .saturating_sub(self.frames_per_group)
            .div_ceil(stride);
        let hi = j / stride;
        let cap = self.max_groups.unwrap_or(usize::MAX);
        (lo..=hi)
            .filter(move |&g| g < cap && j - g * stride < self.frames_per_group)
            .map(move |g| (g, j - g * stride))
    }
}

/// The metadata a clip does not carry: the caller supplies it and it becomes `scan.toml`.
#[derive(Clone, Debug, PartialEq)]
pub struct ClipMeta {
    /// Turntable speed the disc was cut at.
    pub rpm: f64,
    /// Groove radius at the first group.
    pub radius_mm: f64,
    /// Cut type.
    pub cut: Cut,
    /// Size of one pixel on the land plane.
    pub pixel_pitch_um: f64,
    /// Optical centre to the land plane.
    pub working_distance_mm: f64,
    /// Record travel between consecutive frames.
    pub frame_step_um: f64,
    /// Travel between the first frames of consecutive groups; `None` = stride × `frame_step_um`.
    pub group_step_um: Option<f64>,
}

impl Default for ClipMeta {
    /// The example values of docs/FORMAT.md (a 78 rpm disc under the paper's microscope).
    fn default() -> Self {
        Self {
            rpm: 78.0,
            radius_mm: 115.0,
            cut: Cut::Lateral,
            pixel_pitch_um: 0.39,
            working_distance_mm: 4.0,
            frame_step_um: 0.78,
            group_step_um: None,
        }
    }
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

impl ClipMeta {
    /// The scan metadata for `layout` (no extra tables), validated as [`super::Scan::open`] does.
    ///
    /// # Errors
    /// [`VideoError::Settings`] naming the first invalid key.
    pub fn scan_meta(&self, layout: &GroupLayout) -> Result<ScanMeta, VideoError> {
        let group_step_um = self
            .group_step_um
            .unwrap_or(layout.stride() as f64 * self.frame_step_um);
        let meta = ScanMeta {
            format: FORMAT_VERSION,
            record: RecordMeta {
                rpm: self.rpm,
                radius_mm: self.radius_mm,
                cut: self.cut,
                group_radius_mm: None,
            },
            camera: CameraMeta {
                pixel_pitch_um: self.pixel_pitch_um,
                working_distance_mm: self.working_distance_mm,
            },
            motion: MotionMeta {
                frame_step_um: self.frame_step_um,
                group_step_um,
            },
            dual_focus: None,
            extra: toml::Table::new(),
        };
        meta.validate()
            .map_err(|problem| VideoError::Settings { problem })?;
        Ok(meta)
    }
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
}

/// Bits of the first component of `format` (8 when FFmpeg does not know the format).
fn component_depth_bits(format: Pixel) -> i32 {
    let Some(desc) = format.descriptor() else {
        return 8;
    };
    // SAFETY: `descriptor()` only returns `Some` for FFmpeg's static, non-null table entry of
    // this format; every entry has `comp[0]` filled in.
    unsafe { (*desc.as_ptr()).comp[0].depth }
}

/// Removes the temporary folder unless the import finished.
struct TempDir {
    path: PathBuf,
    keep: bool,
}

impl Drop for TempDir {
    fn drop(&mut self) {
        if !self.keep {
            let _ = std::fs::remove_dir_all(&self.path);
        }
    }
}

fn io_err(problem: String, path: &Path) -> VideoError {
    VideoError::Load(LoadError::Io {
        problem,
        path: path.to_path_buf(),
    })
}

/// Creates the hidden sibling folder the scan is written into.
fn make_temp_dir(out_dir: &Path) -> Result<TempDir, VideoError> {
    let name = out_dir
        .file_name()
        .map_or_else(|| "scan".into(), |n| n.to_string_lossy().into_owned());
    let parent = match out_dir.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    std::fs::create_dir_all(&parent)
        .map_err(|e| io_err(format!("cannot create output folder: {e}"), &parent))?;
    let path = parent.join(format!(".{name}.import-{}.tmp", std::process::id()));
    std::fs::create_dir(&path)
        .map_err(|e| io_err(format!("cannot create temporary folder: {e}"), &path))?;
    Ok(TempDir { path, keep: false })
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

/// Converts decoded frames to grey images, through swscale when the format is not grey already.
struct GreyConverter {
    target: Pixel,
    scaler: Option<(scaling::Context, Pixel, u32, u32)>,
    converted: VideoFrame,
}

impl GreyConverter {
    fn new(sixteen_bit: bool) -> Self {
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

    fn convert(&mut self, frame: &VideoFrame) -> Result<Image, ffmpeg::Error> {
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
struct Splitter<'a> {
    layout: &'a GroupLayout,
    dir: &'a Path,
    sixteen_bit: bool,
    group_digits: usize,
    frame_digits: usize,
    /// Frames taken so far, counted from the first frame used.
    taken: usize,
}

impl Splitter<'_> {
    fn group_dir(&self, g: usize) -> PathBuf {
        let gw = self.group_digits;
        self.dir.join(format!("g{g:0gw$}"))
    }

    /// Writes frame `self.taken` into every group holding it.
    fn push(&mut self, img: &Image) -> Result<(), VideoError> {
        let j = self.taken;
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
                self.sixteen_bit,
                false,
            )?;
        }
        self.taken += 1;
        Ok(())
    }

    /// Whether `max_groups` groups are full.
    fn done(&self) -> bool {
        self.layout.frames_needed().is_some_and(|n| self.taken >= n)
    }

    /// Removes the folders of trailing groups the clip did not fill; returns the full groups.
    fn finish(&self) -> Result<usize, VideoError> {
        let full = self.layout.groups_written(self.taken);
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

/// Frames in the clip's stream as the container states or its duration implies; 0 = unknown.
fn estimated_frames(stream: &ffmpeg::format::stream::Stream<'_>) -> usize {
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

/// Imports `clip` as a scan in `out_dir` (missing or empty; created).
///
/// `progress(decoded, total)` is called with 0 first and after every decoded frame; `total` is
/// the number of frames expected to be decoded (0 when the container does not say). Raising
/// `cancel` stops before the next frame with [`VideoError::Cancelled`]; nothing is left behind
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
    progress: &(dyn Fn(usize, usize) + Sync),
    cancel: &AtomicBool,
) -> Result<ImportSummary, VideoError> {
    layout
        .validate()
        .map_err(|problem| VideoError::Settings { problem })?;
    let mut scan_meta = meta.scan_meta(layout)?;
    if !clip.is_file() {
        return Err(VideoError::Missing {
            path: clip.to_path_buf(),
        });
    }
    check_out_dir(out_dir)?;

    ffmpeg::init().map_err(|e| VideoError::NotAVideo {
        problem: format!("FFmpeg failed to start: {e}"),
        path: clip.to_path_buf(),
    })?;
    // Our errors name the file; FFmpeg's own log lines would only repeat them on stderr.
    ffmpeg::util::log::set_level(ffmpeg::util::log::Level::Fatal);
    let mut input = ffmpeg::format::input(clip).map_err(|e| VideoError::NotAVideo {
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
    let mut decoder = ffmpeg::codec::context::Context::from_parameters(params)
        .and_then(|c| c.decoder().video())
        .map_err(unsupported)?;
    let sixteen_bit = component_depth_bits(decoder.format()) > 8;
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

    let tmp = make_temp_dir(out_dir)?;
    let mut splitter = Splitter {
        layout,
        dir: &tmp.path,
        sixteen_bit,
        group_digits: crate::synth::digits(est_groups, 5),
        frame_digits: crate::synth::digits(layout.frames_per_group, 3),
        taken: 0,
    };
    let mut converter = GreyConverter::new(sixteen_bit);
    let mut size: Option<(usize, usize)> = None;
    let mut decoded = 0usize;
    let mut frame = VideoFrame::empty();
    progress(0, total);

    // Sends a packet (or, with `None`, the end of stream) and takes every frame the decoder has
    // ready; returns false once enough groups are full.
    let mut feed = |decoder: &mut ffmpeg::decoder::Video,
                    packet: Option<&ffmpeg::Packet>|
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
        sent.map_err(|e| decode_err(decoded, e.to_string()))?;
        while decoder.receive_frame(&mut frame).is_ok() {
            if cancel.load(Ordering::Relaxed) {
                return Err(VideoError::Cancelled);
            }
            if decoded >= layout.first_frame {
                let img = converter
                    .convert(&frame)
                    .map_err(|e| decode_err(decoded, format!("grey conversion failed: {e}")))?;
                let this = (img.width, img.height);
                let first = *size.get_or_insert(this);
                if this != first {
                    return Err(decode_err(
                        decoded,
                        format!(
                            "frame is {}x{} but the clip's first frame is {}x{}",
                            this.0, this.1, first.0, first.1
                        ),
                    ));
                }
                splitter.push(&img)?;
            }
            decoded += 1;
            progress(decoded, total.max(decoded));
            if splitter.done() {
                return Ok(false);
            }
        }
        Ok(true)
    };
    let mut more = true;
    for (stream, packet) in input.packets() {
        if cancel.load(Ordering::Relaxed) {
            return Err(VideoError::Cancelled);
        }
        if stream.index() == stream_index {
            more = feed(&mut decoder, Some(&packet))?;
            if !more {
                break;
            }
        }
    }
    if more {
        // End of stream: the decoder may still hold delayed frames.
        feed(&mut decoder, None)?;
    }
    drop(feed);
    // The container's frame count is only an estimate; end the bar at what was decoded.
    progress(decoded, decoded);

    if decoded == 0 {
        return Err(VideoError::NoFrames {
            path: clip.to_path_buf(),
        });
    }
    let groups = splitter.finish()?;
    if groups == 0 {
        return Err(VideoError::TooFewFrames {
            found: splitter.taken,
            needed: layout.frames_per_group,
            path: clip.to_path_buf(),
        });
    }
    let source = clip
        .file_name()
        .map_or_else(|| clip.to_string_lossy(), |n| n.to_string_lossy())
        .into_owned();
    let info = ImportInfo {
        source: &source,
        codec: &codec,
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
    let meta_text = scan_meta
        .to_toml_string()
        .map_err(|e| VideoError::Settings {
            problem: format!("cannot write scan.toml: {e}"),
        })?;
    write_atomic(&tmp.path.join("scan.toml"), meta_text.as_bytes(), false)?;
    if cancel.load(Ordering::Relaxed) {
        return Err(VideoError::Cancelled);
    }
    finish_into(tmp, out_dir)?;
    let (width, height) = size.unwrap_or((0, 0));
    Ok(ImportSummary {
        out_dir: out_dir.to_path_buf(),
        groups,
        frames_per_group: layout.frames_per_group,
        group_stride_frames: layout.stride(),
        frames_decoded: decoded,
        width,
        height,
        bit_depth: if sixteen_bit { 16 } else { 8 },
        codec,
    })
}

/// Renames the finished temporary folder to `out_dir` (replacing it only when it is empty).
fn finish_into(mut tmp: TempDir, out_dir: &Path) -> Result<(), VideoError> {
    check_out_dir(out_dir)?;
    if out_dir.exists() {
        // An empty folder: `remove_dir` refuses anything else, so nothing can be lost.
        std::fs::remove_dir(out_dir).map_err(|e| {
            io_err(
                format!("cannot replace the empty output folder: {e}"),
                out_dir,
            )
        })?;
    }
    std::fs::rename(&tmp.path, out_dir).map_err(|e| {
        io_err(
            format!("cannot move the imported scan into place: {e}"),
            out_dir,
        )
    })?;
    tmp.keep = true;
    Ok(())
}

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

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
#[path = "video_tests.rs"]
mod tests;
