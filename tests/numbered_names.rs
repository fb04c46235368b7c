//! Numbered group folders and frames are positions: unpadded names run in number order, a
//! skipped group keeps its place (refused before any work, a gap under `--keep-going`), a
//! skipped frame fails its group, and other programs' dot files and folders of no frames
//! outside the numbering are passed over; a Zarr store's group names are read the same way.
#![allow(clippy::unwrap_used)] // tests may panic

mod common;

use std::path::{Path, PathBuf};
use std::process::Output;

use common::{demo_copy, groovescope, reconstruct, stderr};

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A copy of the demo in `dir` less its file or folder `gone`, and an output path beside it.
fn demo_without(dir: &Path, gone: &str) -> (PathBuf, PathBuf) {
    let demo = demo_copy(dir);
    let path = demo.join(gone);
    if path.is_dir() {
        std::fs::remove_dir_all(path).unwrap();
    } else {
        std::fs::remove_file(path).unwrap();
    }
    (demo, dir.join("o.wav"))
}

/// A run that succeeded with a warning holding every `wanted`.
fn warned(o: &Output, wanted: &[&str]) {
    let err = stderr(o);
    assert!(o.status.success(), "{err}");
    assert!(wanted.iter().all(|w| err.contains(w)), "{err}");
}

/// The samples of the WAV at `path`, every channel. Scans that differ in their names or
/// metadata give different WAV bytes (the `bext` chunk's reference is the scan's
/// fingerprint), so "the same sound" compares these.
fn sound(path: &Path) -> Vec<Vec<f32>> {
    groovescope::io::wav::read_wav(path).unwrap().channels
}

/// The demo's sound, reconstructed from an untouched copy.
fn untouched(dir: &Path) -> Vec<Vec<f32>> {
    let out = dir.join("untouched.wav");
    let o = reconstruct(
        Path::new(&format!("{}/assets/demo", env!("CARGO_MANIFEST_DIR"))),
        &out,
        &[],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    sound(&out)
}

#[test]
fn unreadable_first_and_last_groups_keep_their_places_under_keep_going() {
    // They used to be dropped: the sound started with group 2's, 4.4 ms early, and was
    // 194 samples short at the start and 97 at the end (measured on the demo).
    let dir = tempfile::tempdir().unwrap();
    let demo = demo_copy(dir.path());
    for g in ["g00000", "g00001", "g00012"] {
        std::fs::write(demo.join(g).join("f003.png"), b"").unwrap();
    }
    let out = dir.path().join("o.wav");
    let o = reconstruct(&demo, &out, &["--keep-going"]);
    warned(&o, &["group 0:", "group 1:", "group 12:", "f003.png"]);
    let (got, want) = (sound(&out), untouched(dir.path()));
    assert_eq!(got[0].len(), want[0].len());
    // Silence where the three groups lie, then the untouched sound in its place: it lines up
    // with the untouched run at lag 0, not a group's length away.
    let r_at = |lag: usize| {
        let (a, b) = (&got[0][200 + lag..1100 + lag], &want[0][200..1100]);
        let dot = |x: &[f32], y: &[f32]| {
            x.iter()
                .zip(y)
                .map(|(p, q)| f64::from(*p) * f64::from(*q))
                .sum::<f64>()
        };
        dot(a, b) / (dot(a, a) * dot(b, b)).sqrt()
    };
    assert!(r_at(0) > 0.95, "r at lag 0: {}", r_at(0));
    assert!(
        got[0][..150].iter().all(|v| v.abs() < 0.05),
        "silence first"
    );
}

#[test]
fn unpadded_names_dot_files_and_stray_folders_give_the_untouched_scans_sound() {
    let dir = tempfile::tempdir().unwrap();
    let demo = demo_copy(dir.path());
    // g00000 → g0 … g00012 → g12: name order would run g10, g11, g12 before g2, and the
    // demo's sound would come out spliced (r 0.35 against its reference, measured).
    for g in 0..13 {
        let from = demo.join(format!("g{g:05}"));
        std::fs::rename(&from, demo.join(format!("g{g}"))).unwrap();
    }
    // What a Mac leaves on an exFAT drive, and a thumbnail cache: neither a frame nor a group.
    std::fs::write(demo.join("g2/._f000.png"), b"\0\x05\x16\x07 resource fork").unwrap();
    std::fs::create_dir(demo.join(".thumbnails")).unwrap();
    // Folders of no frames outside the numbering: before g0 by name, one would have taken
    // group 0's place and moved every group one step along the groove.
    std::fs::create_dir(demo.join("calibration")).unwrap();
    std::fs::create_dir(demo.join("notes")).unwrap();
    std::fs::write(demo.join("notes/transfer.txt"), "stylus-free transfer").unwrap();
    let out = dir.path().join("renamed.wav");
    let o = reconstruct(&demo, &out, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(sound(&out) == untouched(dir.path()));
}

#[test]
fn a_skipped_group_keeps_its_place_refused_before_work_or_a_gap_with_keep_going() {
    let dir = tempfile::tempdir().unwrap();
    let (demo, out) = demo_without(dir.path(), "g00003");
    let o = reconstruct(&demo, &out, &[]);
    assert!(!o.status.success());
    let err = stderr(&o);
    assert!(
        err.contains("numbering skips 1 group folder among groups 0..13 (g00003")
            && err.contains("--keep-going"),
        "{err}"
    );
    assert!(!out.exists() && !dir.path().join("o.wav.journal").exists());
    let plan = dir.path().join("plan.json");
    let o = groovescope(&["plan", s(&demo), "--shards", "2", "--out", s(&plan)]);
    assert!(!o.status.success() && stderr(&o).contains("g00003"));
    assert!(!plan.exists());
    let o = groovescope(&[
        "plan",
        s(&demo),
        "--shards",
        "2",
        "--out",
        s(&plan),
        "--keep-going",
        "--probe-groups",
        "4",
    ]);
    warned(
        &o,
        &["numbering skips 1 group folder", "each becomes a gap"],
    );
    // Group 0 is the probe's warm-up; of groups 1..4, the missing one failed.
    let said = String::from_utf8_lossy(&o.stdout);
    assert!(
        said.contains(
            "groups 1..4 timed after group 0 (a warm-up), over the 2 that gave sound (1 failed)"
        ),
        "{said}"
    );
    let store = dir.path().join("demo.zarr");
    let o = groovescope(&["pack", s(&demo), "--out", s(&store)]);
    assert!(
        !o.status.success() && stderr(&o).contains("group folder is missing"),
        "{}",
        stderr(&o)
    );
    assert!(!store.exists());

    let o = reconstruct(&demo, &out, &["--keep-going"]);
    warned(&o, &["group 3: group folder is missing: ", "g00003"]);
    // The groups after it stay where they lie: the sound keeps the untouched length.
    let (got, want) = (sound(&out), untouched(dir.path()));
    assert_eq!(got[0].len(), want[0].len());
    assert_ne!(got, want);
    let inspected = dir.path().join("inspect");
    let o = groovescope(&["inspect", s(&demo), "--group", "3", "--out", s(&inspected)]);
    assert!(
        !o.status.success() && stderr(&o).contains("group folder is missing"),
        "{}",
        stderr(&o)
    );
    // A spiral's radius list counts the skipped group's place too, and says so when short.
    let toml = std::fs::read_to_string(demo.join("scan.toml")).unwrap();
    let radii = ["60.0"; 12].join(", ");
    let spiral = toml.replacen(
        "radius_mm = 60.0\n",
        &format!("radius_mm = 60.0\ngroup_radius_mm = [{radii}]\n"),
        1,
    );
    std::fs::write(demo.join("scan.toml"), spiral).unwrap();
    let o = reconstruct(&demo, &dir.path().join("spiral.wav"), &["--keep-going"]);
    common::failed_with(
        &o,
        &["has 12 entries but the scan has 13 groups, 1 of them a number the group folders skip"],
    );
}

#[test]
fn timestamp_names_are_an_order_once_scan_toml_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let demo = demo_copy(dir.path());
    // Groups named by the second they were taken: one took two seconds, so its successor's
    // number skips one. As positions that is a lost group; the capture lost none.
    let start = 1_733_390_401;
    for g in 0..13 {
        let stamp = start + g + usize::from(g >= 6);
        let from = demo.join(format!("g{g:05}"));
        std::fs::rename(&from, demo.join(format!("cap{stamp}"))).unwrap();
    }
    let out = dir.path().join("stamps.wav");
    let o = reconstruct(&demo, &out, &[]);
    common::failed_with(
        &o,
        &[
            "skips 1 group folder",
            "cap1733390407",
            "numbered_names = \"order\"",
        ],
    );
    let toml = std::fs::read_to_string(demo.join("scan.toml")).unwrap();
    let said = toml.replace(
        "group_step_um = 230.88\n",
        "group_step_um = 230.88\nnumbered_names = \"order\"\n",
    );
    assert_ne!(said, toml);
    std::fs::write(demo.join("scan.toml"), said).unwrap();
    let o = reconstruct(&demo, &out, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(sound(&out) == untouched(dir.path()));
    // A store packed from it keeps the setting and the order.
    let store = dir.path().join("stamps.zarr");
    let o = groovescope(&["pack", s(&demo), "--out", s(&store), "--quiet"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let from_store = dir.path().join("store.wav");
    let o = reconstruct(&store, &from_store, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(std::fs::read(&from_store).unwrap() == std::fs::read(&out).unwrap());
}

#[test]
fn one_frame_in_two_formats_is_refused_naming_both() {
    let dir = tempfile::tempdir().unwrap();
    let demo = demo_copy(dir.path());
    // A conversion that left its source beside it: name order would interleave the sets.
    std::fs::write(demo.join("g00002/f004.tif"), b"II*\0").unwrap();
    let o = reconstruct(&demo, &dir.path().join("o.wav"), &["--keep-going"]);
    common::failed_with(
        &o,
        &[
            "f004.png and f004.tif",
            "one frame in two formats",
            "g00002",
        ],
    );
}

#[test]
fn a_skipped_frame_fails_its_group_naming_the_frame() {
    let dir = tempfile::tempdir().unwrap();
    let (demo, out) = demo_without(dir.path(), "g00005/f003.png");
    let o = reconstruct(&demo, &out, &["--keep-going"]);
    warned(&o, &["group 5: frame is missing: ", "g00005/f003.png"]);
}

#[test]
fn a_store_packed_in_name_order_or_short_of_a_group_keeps_every_group_in_its_place() {
    use groovescope::io::frames::load_frame_raw;
    use groovescope::io::zarr::{ChunkLayout, SampleType, ZarrWriter};
    // The stores `pack` wrote before numbered names were positions: the demo's groups named
    // g0 … g12 and stored in name order (g10, g11, g12 before g2), and one packed from
    // folders that had lost g5 (every group after it one place early).
    let dir = tempfile::tempdir().unwrap();
    let demo = PathBuf::from(format!("{}/assets/demo", env!("CARGO_MANIFEST_DIR")));
    let scan = groovescope::io::Scan::open(&demo).unwrap();
    let scan_toml = std::fs::read_to_string(demo.join("scan.toml")).unwrap();
    let old_store = |name: &str, lost: Option<usize>, names: &dyn Fn(usize) -> String| {
        let mut groups: Vec<usize> = (0..13).filter(|&g| Some(g) != lost).collect();
        groups.sort_by_key(|&g| names(g));
        let store = dir.path().join(name);
        let raw = |g: usize| -> Vec<_> {
            let paths = scan.groups[g].frame_paths();
            paths.map(|p| load_frame_raw(&p).unwrap()).collect()
        };
        let first = raw(0);
        let (w, h) = (first[0].width, first[0].height);
        let sample_type = SampleType::of(&first[0].samples);
        let layout = ChunkLayout {
            frames: first.len(),
            width: w,
            height: h,
            sample_type,
        };
        let mut writer = ZarrWriter::create(&store, layout, 3).unwrap();
        for g in groups {
            let source = &scan.groups[g].dir;
            writer.write_group(&names(g), &raw(g), source).unwrap();
        }
        writer.finish(&scan_toml).unwrap();
        store
    };
    let unpadded = |g: usize| format!("g{g}");
    let in_name_order = old_store("name-order.zarr", None, &unpadded);
    let out = dir.path().join("from-store.wav");
    let o = reconstruct(&in_name_order, &out, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        sound(&out) == untouched(dir.path()),
        "the store's sound differs from the folders'"
    );
    let short = old_store("short.zarr", Some(5), &unpadded);
    let o = reconstruct(&short, &dir.path().join("short.wav"), &[]);
    common::failed_with(
        &o,
        &[
            "the store's group names skip 1 group among groups 0..13 (g5; it was packed from \
             folders that lacked them): ",
            "short.zarr: run with --keep-going to read each as a gap of silence, in its place",
        ],
    );
    let o = reconstruct(&short, &dir.path().join("short.wav"), &["--keep-going"]);
    warned(
        &o,
        &[
            "group 5: group (the store was packed without it) is missing: ",
            "g5",
        ],
    );
    // One name twice (not numbered, so the stored order stands) is refused.
    let twice = old_store("twice.zarr", None, &|g| format!("take{}", g.min(1)));
    let o = reconstruct(&twice, &dir.path().join("twice.wav"), &[]);
    common::failed_with(&o, &["two of its groups carry the same name", "twice.zarr"]);
}
