//! `groovescope import-video` end to end: a lossless clip encoded at test time becomes a loadable scan.
#![allow(clippy::unwrap_used)] // tests may panic

#[cfg(not(all(feature = "video", feature = "gui")))]
mod common;
/// The headless workbench harness (it brings the plain helpers with it).
#[cfg(all(feature = "video", feature = "gui"))]
mod gui_common;
#[cfg(all(feature = "video", feature = "gui"))]
use gui_common::common;

use common::{groovescope, stderr};

fn s(p: &std::path::Path) -> &str {
    p.to_str().unwrap()
}

/// The scan metadata every import is given.
const META: [&str; 10] = [
    "--rpm",
    "78",
    "--radius-mm",
    "115",
    "--pixel-pitch-um",
    "0.39",
    "--working-distance-mm",
    "4",
    "--frame-step-um",
    "0.78",
];

#[cfg(feature = "video")]
fn clip(dir: &std::path::Path, frames: usize) -> std::path::PathBuf {
    use groovescope::image::Image;
    let imgs: Vec<Image> = (0..frames)
        .map(|k| Image::from_fn(40, 24, |x, y| ((x + 2 * k + 3 * y) % 17) as f32 / 16.0))
        .collect();
    let path = dir.join("clip.avi");
    groovescope::io::video::encode_grey_clip(&path, &imgs, false, 25).unwrap();
    path
}

#[cfg(feature = "video")]
#[test]
fn import_video_writes_a_scan_that_opens() {
    let dir = tempfile::tempdir().unwrap();
    let clip = clip(dir.path(), 30);
    let out = dir.path().join("scan");
    let mut args = vec![
        "import-video",
        s(&clip),
        "--out",
        s(&out),
        "--frames-per-group",
        "8",
        "--group-stride",
        "6",
        "--cut",
        "stereo",
        "--max-groups",
        "3",
    ];
    args.extend(META);
    let o = groovescope(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("3 groups of 8 frames, stride 6"), "{text}");
    let scan = groovescope::io::Scan::open(&out).unwrap();
    assert_eq!(scan.groups.len(), 3);
    assert!(scan.groups.iter().all(|g| g.frame_count() == 8));
    assert_eq!(scan.meta.record.cut, groovescope::io::Cut::Stereo);
    assert!((scan.meta.motion.group_step_um - 6.0 * 0.78).abs() < 1e-9);

    // A second run into the now full folder is refused and changes nothing.
    let before = std::fs::read(out.join("scan.toml")).unwrap();
    let o = groovescope(&args);
    assert!(!o.status.success());
    let err = stderr(&o);
    assert!(err.contains("not empty") && err.contains("scan"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert_eq!(std::fs::read(out.join("scan.toml")).unwrap(), before);
}

#[cfg(feature = "video")]
#[test]
fn import_video_errors_are_one_line_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let fake = dir.path().join("notes.mp4");
    std::fs::write(&fake, "not a video\n".repeat(50)).unwrap();
    let out = dir.path().join("scan");
    for (clip, want) in [
        (dir.path().join("nope.avi"), "no such video file"),
        (fake, "notes.mp4"),
    ] {
        let mut args = vec!["import-video", s(&clip), "--out", s(&out), "--quiet"];
        args.extend(META);
        let o = groovescope(&args);
        assert!(!o.status.success());
        let err = stderr(&o);
        assert!(
            err.contains(want) && err.contains(clip.file_name().unwrap().to_str().unwrap()),
            "{err}"
        );
        assert_eq!(err.trim().lines().count(), 1, "{err}");
    }
    let short = clip(dir.path(), 6);
    let mut args = vec![
        "import-video",
        s(&short),
        "--out",
        s(&out),
        "--frames-per-group",
        "7",
    ];
    args.extend(META);
    let err = stderr(&groovescope(&args));
    assert!(
        err.contains("one group needs 7") && err.contains("clip.avi"),
        "{err}"
    );
    assert!(!out.exists());
}

/// `store` holds the scan of `folder` frame for frame, and the same metadata.
#[cfg(feature = "video")]
fn assert_same_frames(folder: &std::path::Path, store: &std::path::Path) {
    use groovescope::io::{Scan, load_group};
    let (a, b) = (Scan::open(folder).unwrap(), Scan::open(store).unwrap());
    assert_eq!(a.meta, b.meta);
    assert_eq!(a.groups.len(), b.groups.len());
    assert!(b.groups.iter().all(|g| g.zarr.is_some()));
    for (ga, gb) in a.groups.iter().zip(&b.groups) {
        assert_eq!(ga.name(), gb.name());
        let (fa, fb) = (load_group(ga).unwrap(), load_group(gb).unwrap());
        assert_eq!(fa, fb, "group {}", ga.index);
    }
}

#[cfg(feature = "video")]
#[test]
fn import_video_into_a_store_resumes_and_holds_what_a_folder_import_holds() {
    use common::groups_checked;
    use groovescope::io::zarr::partial_path;
    let dir = tempfile::tempdir().unwrap();
    let clip = clip(dir.path(), 1200);
    let grouping = ["--frames-per-group", "8", "--group-stride", "6", "--quiet"];
    let folder = dir.path().join("scan");
    let mut args = vec!["import-video", s(&clip), "--out", s(&folder)];
    args.extend(grouping);
    args.extend(META);
    let o = groovescope(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    // Folders start afresh: --resume has nothing to go on with there.
    args.push("--resume");
    let o = groovescope(&args);
    assert!(stderr(&o).contains("Zarr store"), "{}", stderr(&o));

    // Ctrl-C after a few groups: kept, and the line says where and how to go on.
    let store = dir.path().join("clip.zarr");
    let partial = partial_path(&store);
    let mut args = vec![s(&clip), "--out", s(&store)];
    args.extend(grouping);
    args.extend(META);
    let run = common::StoreRun {
        command: "import-video",
        args: &args,
        partial: &partial,
    };
    let kept = run.ctrl_c_keeps(3, &["cancelled", "groups written"]);
    assert!(kept < 199 && !store.exists(), "{kept}");
    // Another grouping is another import: refused, nothing touched.
    let mut other = args.clone();
    other[4] = "9";
    other.push("--resume");
    let mut cmd = vec!["import-video"];
    cmd.extend(other);
    let o = groovescope(&cmd);
    assert!(stderr(&o).contains("something else"), "{}", stderr(&o));
    assert_eq!(groups_checked(&partial), kept);

    run.resume_to_the_end(kept, 199);
    assert_same_frames(&folder, &store);
}

#[cfg(not(feature = "video"))]
#[test]
fn import_video_without_the_feature_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("scan");
    let mut args = vec!["import-video", "clip.avi", "--out", s(&out)];
    args.extend(META);
    let o = groovescope(&args);
    assert!(!o.status.success());
    let err = stderr(&o);
    assert!(err.contains("built without video support"), "{err}");
    assert!(!out.exists());
}

/// The workbench's File > Import video… end to end, headless (egui_kittest): into a folder, or
/// with the "Zarr store" box ticked into a store.
#[cfg(all(feature = "video", feature = "gui"))]
fn workbench_imports(store: bool) {
    use egui_kittest::kittest::Queryable;
    use groovescope::app::WorkbenchOptions;
    use groovescope::playback::DeviceChoice;

    let dir = tempfile::tempdir().unwrap();
    let opts = WorkbenchOptions {
        scan: None,
        config_dir: Some(dir.path().join("config")),
        audio: DeviceChoice::Off,
        ..WorkbenchOptions::default()
    };
    let mut h = gui_common::harness(opts);
    h.run_steps(3);
    h.get_by_label("File").click();
    h.run_steps(2);
    h.get_by_label("Import video…").click();
    h.run_steps(3);
    h.get_by_label_contains("choose a video clip");

    let clip = clip(dir.path(), 14);
    let out = dir.path().join("imported");
    {
        let wb = h.state_mut().wb.as_mut().unwrap();
        let form = wb.import_video_form_mut().unwrap();
        form.clip = Some(clip);
        form.out = out.display().to_string();
        form.frames_per_group = 7;
        form.group_stride_frames = 7;
    }
    h.run_steps(2);
    if store {
        h.get_by_label_contains("Zarr store").click();
        h.run_steps(2);
        let wb = h.state_mut().wb.as_mut().unwrap();
        assert!(wb.import_video_form_mut().unwrap().store);
    }
    h.get_by_label("Import").click();
    let t0 = std::time::Instant::now();
    loop {
        h.step();
        let wb = h.state().wb.as_ref().unwrap();
        if wb.scan().is_some_and(|s| s.dir == out) {
            break;
        }
        assert!(
            t0.elapsed().as_secs() < 120,
            "the imported scan did not open"
        );
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    let wb = h.state().wb.as_ref().unwrap();
    let scan = wb.scan().unwrap();
    assert_eq!(scan.groups.len(), 2);
    assert_eq!(scan.groups.iter().all(|g| g.zarr.is_some()), store);
}

#[cfg(all(feature = "video", feature = "gui"))]
#[test]
fn workbench_imports_a_clip_and_opens_the_scan() {
    workbench_imports(false);
}

#[cfg(all(feature = "video", feature = "gui"))]
#[test]
fn workbench_imports_a_clip_into_a_store_and_opens_it() {
    workbench_imports(true);
}
