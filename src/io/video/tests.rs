//! Tests of the video import: a lossless clip encoded at test time, imported and checked exactly.

use std::sync::atomic::AtomicBool;

use super::*;
use crate::image::Image;
use crate::io::{Scan, load_group};
use crate::test_support::path_in_temp_dir;

const W: usize = 48;
const H: usize = 32;

/// Frame `k` of a pattern that moves 2 px toward −x per frame; values on the 8-bit grid.
fn pattern(k: usize, levels: f32) -> Image {
    Image::from_fn(W, H, |x, y| {
        let v = ((x + 2 * k) * 7 + y * 13) % 251;
        (v as f32 / 250.0 * levels).round() / levels
    })
}

fn clip(dir: &Path, name: &str, frames: usize, sixteen_bit: bool) -> (PathBuf, Vec<Image>) {
    let levels = if sixteen_bit { 65535.0 } else { 255.0 };
    let imgs: Vec<Image> = (0..frames).map(|k| pattern(k, levels)).collect();
    let path = dir.join(name);
    encode_grey_clip(&path, &imgs, sixteen_bit, 25).unwrap();
    (path, imgs)
}

fn no_progress(_: usize, _: usize) {}

/// Imports `clip` into `out` with the default metadata, no progress and no cancel.
fn import(clip: &Path, out: &Path, layout: &GroupLayout) -> Result<ImportSummary, VideoError> {
    import_with(clip, out, layout, &ClipMeta::default(), false)
}

/// Imports `clip` into `out` with `meta`, no progress, cancelled from the start when `cancel`.
fn import_with(
    clip: &Path,
    out: &Path,
    layout: &GroupLayout,
    meta: &ClipMeta,
    cancel: bool,
) -> Result<ImportSummary, VideoError> {
    import_video(
        clip,
        out,
        layout,
        meta,
        Job::new(&no_progress, &AtomicBool::new(cancel)),
    )
}

/// How many entries the folder `dir` holds.
fn entries(dir: &Path) -> usize {
    std::fs::read_dir(dir).unwrap().count()
}

fn layout(fpg: usize, stride: Option<usize>) -> GroupLayout {
    GroupLayout {
        frames_per_group: fpg,
        group_stride_frames: stride,
        ..GroupLayout::default()
    }
}

fn assert_same(a: &Image, b: &Image, tol: f32) {
    assert!(a.same_size(b));
    for (p, q) in a.data.iter().zip(&b.data) {
        assert!((p - q).abs() <= tol, "{p} vs {q}");
    }
}

#[test]
fn eight_bit_clip_imports_into_exact_overlapping_groups() {
    let (dir, out) = path_in_temp_dir("scan");
    let (path, imgs) = clip(dir.path(), "clip.avi", 20, false);
    let calls = std::sync::Mutex::new(Vec::new());
    let progress = |d: usize, t: usize| calls.lock().unwrap().push((d, t));
    let started = std::time::Instant::now();
    let s = import_video(
        &path,
        &out,
        &layout(7, Some(5)),
        &ClipMeta::default(),
        Job::reporting(&progress),
    )
    .unwrap();
    eprintln!("import of a 20-frame {W}x{H} clip: {:?}", started.elapsed());
    // Groups start at frames 0, 5, 10; the one at 15 would need frames up to 21.
    assert_eq!((s.groups, s.frames_decoded, s.bit_depth), (3, 20, 8));
    assert_eq!((s.width, s.height, s.codec.as_str()), (W, H, "ffv1"));
    let calls = calls.into_inner().unwrap();
    assert_eq!(calls.first(), Some(&(0, 20)));
    assert_eq!(calls.last(), Some(&(20, 20)));

    let scan = Scan::open(&out).unwrap();
    assert_eq!(scan.groups.len(), 3);
    assert!((scan.meta.motion.group_step_um - 5.0 * 0.78).abs() < 1e-12);
    let expected = ClipMeta::default().scan_meta(&layout(7, Some(5))).unwrap();
    assert_eq!(scan.meta.record, expected.record);
    assert_eq!(scan.meta.camera, expected.camera);
    assert_eq!(scan.meta.motion, expected.motion);
    let info = scan.meta.extra["video_import"].as_table().unwrap();
    assert_eq!(info["source"].as_str(), Some("clip.avi"));
    assert_eq!(info["group_stride_frames"].as_integer(), Some(5));
    for (g, entry) in scan.groups.iter().enumerate() {
        assert_eq!(entry.frame_count(), 7);
        for (k, frame) in load_group(entry).unwrap().iter().enumerate() {
            assert_same(frame, &imgs[g * 5 + k], 0.0);
        }
    }
    // Overlapping groups repeat frames: g0 f005 is g1 f000.
    assert_eq!(
        std::fs::read(out.join("g00000/f005.png")).unwrap(),
        std::fs::read(out.join("g00001/f000.png")).unwrap()
    );
    let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
    assert_eq!(
        names.len(),
        2,
        "only the clip and the scan: no temporary folder left"
    );
}

#[test]
fn unfinished_imports_of_killed_runs_are_removed_and_live_ones_kept() {
    let (dir, out) = path_in_temp_dir("scan");
    let (path, _) = clip(dir.path(), "clip.avi", 10, false);
    // A process id above the kernel's maximum is never running; pid 1 always is.
    let pid_max: u32 = std::fs::read_to_string("/proc/sys/kernel/pid_max")
        .ok()
        .and_then(|t| t.trim().parse().ok())
        .unwrap_or(4_194_304);
    let dead = dir.path().join(format!(".scan.import-{}.tmp", pid_max + 1));
    let live = dir.path().join(".scan.import-1.tmp");
    let other = dir
        .path()
        .join(format!(".other.import-{}.tmp", pid_max + 1));
    let recent = dir.path().join(format!(".scan.import-{}.tmp", pid_max + 2));
    let two_hours_ago = std::time::SystemTime::now() - std::time::Duration::from_secs(7200);
    for d in [&dead, &live, &other, &recent] {
        std::fs::create_dir(d).unwrap();
        let f = d.join("f000.png");
        std::fs::write(&f, b"partial").unwrap();
        if d != &recent {
            for p in [&f, d] {
                std::fs::File::open(p)
                    .unwrap()
                    .set_modified(two_hours_ago)
                    .unwrap();
            }
        }
    }
    let s = import(&path, &out, &layout(7, None)).unwrap();
    if Path::new("/proc/self").exists() {
        assert_eq!(s.removed_stale, vec![dead.clone()]);
        assert!(!dead.exists());
    } else {
        assert!(s.removed_stale.is_empty() && dead.exists());
    }
    assert!(
        live.join("f000.png").exists(),
        "a running import's folder stays"
    );
    assert!(
        other.join("f000.png").exists(),
        "another target's folder stays"
    );
    assert!(
        recent.join("f000.png").exists(),
        "a folder written to within the hour stays (another machine's import?)"
    );
    assert_eq!(s.groups, 1);
}

#[test]
fn sixteen_bit_clip_keeps_sixteen_bits_and_groups_skip_frames() {
    let (dir, out) = path_in_temp_dir("scan16");
    let (path, imgs) = clip(dir.path(), "deep.mkv", 20, true);
    let lay = GroupLayout {
        frames_per_group: 7,
        group_stride_frames: Some(9),
        first_frame: 1,
        max_groups: Some(2),
    };
    let s = import(&path, &out, &lay).unwrap();
    assert_eq!((s.groups, s.bit_depth), (2, 16));
    // Decoding stops once both groups are full: frames 1..=7 and 10..=16.
    assert_eq!(s.frames_decoded, 17);
    let scan = Scan::open(&out).unwrap();
    assert_eq!(scan.groups.len(), 2);
    for (g, entry) in scan.groups.iter().enumerate() {
        for (k, frame) in load_group(entry).unwrap().iter().enumerate() {
            assert_same(frame, &imgs[1 + g * 9 + k], 0.5 / 65535.0);
        }
    }
    // Values that 8 bits could not hold survive.
    let f = load_group(&scan.groups[0]).unwrap();
    assert!(
        f[0].data
            .iter()
            .any(|v| ((v * 255.0) - (v * 255.0).round()).abs() > 0.01)
    );
}

#[test]
fn missing_clip_is_named() {
    let (dir, out) = path_in_temp_dir("scan");
    let e = import(&dir.path().join("nope.avi"), &out, &layout(7, None)).unwrap_err();
    assert!(matches!(e, VideoError::Missing { .. }), "{e}");
    assert!(e.to_string().contains("nope.avi"), "{e}");
    assert!(!out.exists());
}

#[test]
fn text_file_named_mp4_is_not_a_video() {
    let (dir, out) = path_in_temp_dir("scan");
    let fake = dir.path().join("notes.mp4");
    std::fs::write(&fake, "these are my notes, not a movie\n".repeat(20)).unwrap();
    let e = import(&fake, &out, &layout(7, None)).unwrap_err();
    let msg = e.to_string();
    assert!(msg.contains("notes.mp4"), "{msg}");
    assert!(
        matches!(
            e,
            VideoError::NotAVideo { .. } | VideoError::NoVideoStream { .. }
        ),
        "{msg}"
    );
    assert_eq!(entries(dir.path()), 1, "nothing written");
}

#[test]
fn non_empty_output_folder_is_refused_and_untouched() {
    let (dir, out) = path_in_temp_dir("busy");
    let (path, _) = clip(dir.path(), "clip.avi", 8, false);
    std::fs::create_dir(&out).unwrap();
    std::fs::write(out.join("keep.txt"), b"mine").unwrap();
    let e = import(&path, &out, &layout(7, None)).unwrap_err();
    assert!(matches!(e, VideoError::OutputExists { .. }), "{e}");
    assert!(e.to_string().contains("busy"), "{e}");
    assert_eq!(std::fs::read(out.join("keep.txt")).unwrap(), b"mine");
    assert_eq!(entries(&out), 1);
    assert_eq!(entries(dir.path()), 2, "no temporary folder");
    // An empty folder is accepted and filled.
    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    import(&path, &empty, &layout(7, None)).unwrap();
    assert_eq!(Scan::open(&empty).unwrap().groups.len(), 1);
}

#[test]
fn clip_shorter_than_one_group_leaves_nothing() {
    let (dir, out) = path_in_temp_dir("scan");
    let (path, _) = clip(dir.path(), "short.avi", 6, false);
    let e = import(&path, &out, &layout(7, None)).unwrap_err();
    assert!(
        matches!(
            e,
            VideoError::TooFewFrames {
                found: 6,
                needed: 7,
                ..
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("short.avi"), "{e}");
    assert!(!out.exists());
    assert_eq!(entries(dir.path()), 1, "no temporary folder");
}

#[test]
fn cancel_leaves_nothing_and_bad_settings_are_named() {
    let (dir, out) = path_in_temp_dir("scan");
    let (path, _) = clip(dir.path(), "clip.avi", 8, false);
    let e = import_with(&path, &out, &layout(7, None), &ClipMeta::default(), true).unwrap_err();
    assert!(matches!(e, VideoError::Cancelled), "{e}");
    assert_eq!(entries(dir.path()), 1);

    let e = import(&path, &out, &layout(6, None)).unwrap_err();
    assert!(e.to_string().contains("frames_per_group"), "{e}");
    let bad = ClipMeta {
        rpm: f64::NAN,
        ..ClipMeta::default()
    };
    let e = import_with(&path, &out, &layout(7, None), &bad, false).unwrap_err();
    assert!(e.to_string().contains("record.rpm"), "{e}");
    assert!(!out.exists());
}

#[test]
fn placements_cover_overlap_and_gaps() {
    let l = layout(7, Some(3));
    assert_eq!(l.placements(0).collect::<Vec<_>>(), vec![(0, 0)]);
    assert_eq!(
        l.placements(6).collect::<Vec<_>>(),
        vec![(0, 6), (1, 3), (2, 0)]
    );
    let gaps = layout(7, Some(10));
    assert_eq!(gaps.placements(8).count(), 0);
    assert_eq!(gaps.placements(10).collect::<Vec<_>>(), vec![(1, 0)]);
    assert_eq!(l.full_groups(6), 0);
    assert_eq!(l.full_groups(13), 3);
}

#[test]
fn demo_frames_survive_a_clip_and_the_imported_scan_reconstructs() {
    let demo = Scan::open(Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/assets/demo"
    )))
    .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let frames: Vec<Image> = demo.groups[..2]
        .iter()
        .flat_map(|g| load_group(g).unwrap())
        .collect();
    let path = dir.path().join("demo.avi");
    encode_grey_clip(&path, &frames, false, 25).unwrap();
    let m = &demo.meta;
    let meta = ClipMeta {
        rpm: m.record.rpm,
        radius_mm: m.record.radius_mm,
        cut: m.record.cut,
        pixel_pitch_um: m.camera.pixel_pitch_um,
        working_distance_mm: m.camera.working_distance_mm,
        frame_step_um: m.motion.frame_step_um,
        group_step_um: Some(m.motion.group_step_um),
    };
    let out = dir.path().join("scan");
    let started = std::time::Instant::now();
    let s = import_with(&path, &out, &layout(7, None), &meta, false).unwrap();
    eprintln!("import of a 14-frame 320x384 clip: {:?}", started.elapsed());
    assert_eq!(s.groups, 2);
    let scan = Scan::open(&out).unwrap();
    for (a, b) in scan.groups.iter().zip(&demo.groups) {
        for (p, q) in load_group(a)
            .unwrap()
            .iter()
            .zip(load_group(b).unwrap().iter())
        {
            assert_same(p, q, 0.0);
        }
    }
    let rec = crate::engine::reconstruct(
        &scan,
        &crate::engine::ReconstructOptions {
            params: crate::pipeline::PipelineParams::default(),
            groups: None,
            keep_going: false,
        },
        &mut |_| {},
        &AtomicBool::new(false),
    );
    assert!(
        rec.is_ok(),
        "reconstruct runs on the imported scan: {:?}",
        rec.err()
    );
}

/// Speed of a camera-sized import (run with `--ignored --nocapture`): 48 frames of 1280×1024.
#[test]
#[ignore = "timing, not a check: 48 full-size frames"]
fn import_speed_full_size_frames() {
    let dir = tempfile::tempdir().unwrap();
    let imgs: Vec<Image> = (0..48)
        .map(|k| {
            Image::from_fn(1280, 1024, |x, y| {
                (((x + 2 * k) * 7 + y * 13) % 251) as f32 / 250.0
            })
        })
        .collect();
    let path = dir.path().join("big.avi");
    let t = std::time::Instant::now();
    encode_grey_clip(&path, &imgs, false, 25).unwrap();
    eprintln!("encode 48 frames 1280x1024 (FFV1): {:?}", t.elapsed());
    let t = std::time::Instant::now();
    let s = import(&path, &dir.path().join("scan"), &layout(12, None)).unwrap();
    eprintln!(
        "import 48 frames 1280x1024 into {} groups: {:?}",
        s.groups,
        t.elapsed()
    );
}

#[test]
fn component_depth_is_read_from_the_safe_descriptor_fields() {
    use ffmpeg::format::Pixel as P;
    let cases = [
        (P::GRAY8, 8),
        (P::GRAY16LE, 16),
        (P::GRAY10LE, 10),
        (P::YUV420P, 8),
        (P::YUV420P10LE, 10),
        (P::YUV444P16LE, 16),
        (P::YUVA420P10LE, 10),
        (P::NV12, 8),
        (P::P010LE, 10),
        (P::RGB24, 8),
        (P::RGB48LE, 16),
        (P::RGBA64LE, 16),
        (P::GBRP12LE, 12),
        (P::RGB565LE, 5),
        (P::PAL8, 8),
    ];
    for (format, bits) in cases {
        assert_eq!(grey::component_depth_bits(format), bits, "{format:?}");
    }
}
