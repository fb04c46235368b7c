//! Video import straight into a Zarr store: each group becomes its chunk as soon as its last frame is decoded, in a partial store that a stopped import goes on with (`--resume`).
//!
//! No PNG is written: a frame is quantised as the folder import's PNG would store it
//! ([`crate::io::frames::raw_from_grey`]), so the store holds the same samples as a folder
//! import packed afterwards. The frames of groups still being filled are held (at most
//! ⌈frames per group / stride⌉ groups). On `--resume` the clip is decoded from the start again
//! (a codec cannot start anywhere), but the frames of the groups the store holds are neither
//! converted nor written.

use std::collections::BTreeMap;
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use super::{
    ClipMeta, FrameSink, GroupLayout, ImportSummary, VideoError, checked_settings, decode_into,
    imported_scan_toml, open_source,
};
use crate::image::Image;
use crate::io::frames::{RawFrame, raw_from_grey};
use crate::io::zarr::{PackOptions, PartialStore, SampleType};
use crate::job::Job;

/// Bytes read from each end of the clip for its fingerprint.
const FINGERPRINT_END_BYTES: u64 = 1 << 20;

/// The fingerprint a partial store of this import must carry to be resumed: the clip (its
/// size and its first and last MiB), the store's `scan.toml` (the metadata given, the clip's
/// name and codec and the grouping) and `max_groups`.
fn import_fingerprint(
    clip: &Path,
    layout: &GroupLayout,
    scan_toml: &str,
) -> Result<String, VideoError> {
    let io = |e: std::io::Error| super::io_err(format!("cannot read the clip: {e}"), clip);
    let mut file = std::fs::File::open(clip).map_err(io)?;
    let size = file.metadata().map_err(io)?.len();
    let most = layout.max_groups.map_or("all".into(), |m| m.to_string());
    let mut text = format!("{size}\nmax_groups {most}\n{scan_toml}\n").into_bytes();
    let head = size.min(FINGERPRINT_END_BYTES);
    (&mut file).take(head).read_to_end(&mut text).map_err(io)?;
    let tail_start = size.saturating_sub(FINGERPRINT_END_BYTES).max(head);
    file.seek(SeekFrom::Start(tail_start)).map_err(io)?;
    file.read_to_end(&mut text).map_err(io)?;
    Ok(crate::io::fingerprint::fingerprint(&text))
}

/// Takes decoded frames into a [`PartialStore`], a group at a time.
struct StoreSink<'a> {
    layout: &'a GroupLayout,
    store: &'a mut PartialStore,
    /// The frames of the groups being filled, by group.
    open: BTreeMap<usize, Vec<RawFrame>>,
    /// Digits of the group numbers in the group names.
    group_digits: usize,
    /// The clip (names a group in errors).
    clip: &'a Path,
}

impl FrameSink for StoreSink<'_> {
    fn wants(&self, j: usize) -> bool {
        let held = self.store.groups();
        self.layout.placements(j).any(|(g, _)| g >= held)
    }

    fn push(&mut self, j: usize, img: &Image, sixteen_bit: bool) -> Result<(), VideoError> {
        let held = self.store.groups();
        let places: Vec<(usize, usize)> = self
            .layout
            .placements(j)
            .filter(|&(g, _)| g >= held)
            .collect();
        let mut raw = Some(raw_from_grey(img, sixteen_bit));
        for (i, &(g, k)) in places.iter().enumerate() {
            // Copied into every group that holds it but the last, which takes it.
            let frame = if i + 1 == places.len() {
                raw.take()
            } else {
                raw.clone()
            };
            let frames = self.open.entry(g).or_default();
            frames.extend(frame);
            if k + 1 < self.layout.frames_per_group {
                continue;
            }
            let frames = self.open.remove(&g).unwrap_or_default();
            // Groups fill in order (`placements` yields them so), the full one the store's next.
            debug_assert_eq!(
                (g, frames.len()),
                (self.store.groups(), self.layout.frames_per_group)
            );
            let name = crate::synth::group_name(g, self.group_digits);
            self.store.add_group(&name, &frames, self.clip)?;
        }
        Ok(())
    }
}

/// Imports `clip` as a Zarr store at `out` (missing or empty), writing each group's chunk as
/// soon as the group is full, in a partial store beside `out` renamed into place at the end
/// (see [`crate::io::zarr::partial`]). With `options.resume` it goes on with the partial store
/// an interrupted import of the same clip, grouping and metadata left; one that stops after
/// writing a group keeps it for that.
///
/// # Errors
/// As [`super::import_video`], and [`VideoError::Kept`] wrapping the error when a stopped
/// import kept its groups; an interrupted import's partial store without `resume` or
/// `force`, or of another clip, settings or zstd level.
pub fn import_video_to_store(
    clip: &Path,
    out: &Path,
    layout: &GroupLayout,
    meta: &ClipMeta,
    options: PackOptions,
    job: Job<'_>,
) -> Result<ImportSummary, VideoError> {
    let scan_meta = checked_settings(layout, meta)?;
    let mut src = open_source(clip, layout)?;
    // The store's scan.toml, known before decoding: the resume fingerprint covers it.
    let scan_toml = imported_scan_toml(scan_meta, clip, &src.codec, layout)?;
    let fingerprint = import_fingerprint(clip, layout, &scan_toml)?;
    let start_over = "import it again with --force to start over";
    let digits = crate::synth::digits(src.est_groups, 5);
    let names = |held: usize| {
        (0..held)
            .map(|g| crate::synth::group_name(g, digits))
            .collect()
    };
    let mut store = PartialStore::open(out, fingerprint, options, start_over, names)?;
    let mut sink = StoreSink {
        layout,
        store: &mut store,
        open: BTreeMap::new(),
        group_digits: digits,
        clip,
    };
    let done = decode_into(&mut src, clip, layout, job, &mut sink).and_then(|decoded| {
        if job.is_cancelled() {
            return Err(VideoError::Cancelled);
        }
        Ok((decoded, store.finish(&scan_toml)?))
    });
    let (decoded, done) = match done {
        Ok(d) => d,
        Err(error) => {
            return Err(match store.abandon(None) {
                Some(kept) => VideoError::Kept {
                    error: Box::new(error),
                    kept,
                },
                None => error,
            });
        }
    };
    Ok(ImportSummary {
        out_dir: done.out,
        groups: done.groups,
        frames_per_group: layout.frames_per_group,
        group_stride_frames: layout.stride(),
        frames_decoded: decoded.decoded,
        width: done.layout.width,
        height: done.layout.height,
        bit_depth: if done.layout.sample_type == SampleType::U16 {
            16
        } else {
            8
        },
        codec: src.codec,
        removed_stale: Vec::<PathBuf>::new(),
        resumed_groups: done.resumed,
    })
}
