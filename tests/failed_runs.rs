//! What a failed or refused run leaves behind: outputs checked before any work, a journal kept
//! only when it holds groups to go on from (and the line says so), a group of another frame
//! size named, warnings printed even with `--quiet`.
#![allow(clippy::unwrap_used)] // tests may panic

mod common;

use std::path::{Path, PathBuf};

use common::{demo_copy, groovescope, names, reconstruct, stderr, two_shard_plan};
use groovescope::image::Image;
use groovescope::io::save_grey_png;

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// `reconstruct`, which must fail with one line holding every `wanted`.
fn refused(scan: &Path, out: &Path, extra: &[&str], wanted: &[&str]) {
    common::failed_with(&reconstruct(scan, out, extra), wanted);
}

#[test]
fn outputs_are_checked_before_any_group_runs() {
    let dir = tempfile::tempdir().unwrap();
    let scan = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/demo");
    let work = dir.path().join("work");
    std::fs::create_dir(&work).unwrap();
    let folder = work.join("a-folder");
    std::fs::create_dir(&folder).unwrap();
    refused(&scan, &folder, &["--force"], &["is a folder", "a-folder"]);
    let report = work.join("r.json");
    refused(
        &scan,
        &work.join("x.wav"),
        &["--report", s(&folder), "--force"],
        &["is a folder", "a-folder"],
    );
    refused(
        &scan,
        &work.join("nodir/x.wav"),
        &[],
        &["folder does not exist", "nodir"],
    );
    // A name ending in a separator names a folder: it used to run every group, then fail to
    // write, leaving a journal whose --resume failed the same way.
    for name in ["newdir/", "new.wav/"] {
        let out = format!("{}/{name}", s(&work));
        refused(
            &scan,
            Path::new(&out),
            &["--force"],
            &["names a folder, not a file", name],
        );
    }
    let same = work.join("same.wav");
    refused(
        &scan,
        &same,
        &["--report", s(&same)],
        &["same file", "same.wav"],
    );
    refused(
        &scan,
        &work.join("g.wav"),
        &["--groups", "0"],
        &["--groups must be at least 1"],
    );
    // A name the file system takes but its journal's temporary file would not: refused here,
    // not after every group has run (and again on --resume).
    let long = work.join(format!("{}.wav", "c".repeat(241)));
    refused(&scan, &long, &[], &["245 bytes long", "223"]);
    assert!(!report.exists());
    assert_eq!(names(&work), ["a-folder"], "nothing written, no journal");
}

/// A folder this process cannot write: a read-only one, or where that does not stop it (root),
/// `/sys`; None when neither is to be had.
fn unwritable_folder(dir: &Path) -> Option<PathBuf> {
    use std::os::unix::fs::PermissionsExt;
    let ro = dir.join("read-only");
    std::fs::create_dir(&ro).unwrap();
    std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o555)).unwrap();
    let writes = |d: &Path| std::fs::write(d.join("probe"), b"").is_ok();
    if !writes(&ro) {
        return Some(ro);
    }
    let _ = std::fs::remove_file(ro.join("probe"));
    let sys = PathBuf::from("/sys");
    (sys.is_dir() && !writes(&sys)).then_some(sys)
}

/// `plan --out` into a folder it cannot write is refused before the scan is opened and the
/// probe runs its groups (minutes on a side), naming the plan file: a missing scan is not even
/// reached.
#[test]
fn a_plan_into_an_unwritable_folder_is_refused_before_its_probe() {
    let (dir, demo, _work) = common::demo_and_out_folder("work");
    let Some(folder) = unwritable_folder(dir.path()) else {
        eprintln!("skipped: no folder this process cannot write");
        return;
    };
    let plan = folder.join("plan.json");
    let missing = dir.path().join("no-scan-here");
    for scan in [&demo, &missing] {
        let o = groovescope(&[
            "plan",
            s(scan),
            "--shards",
            "2",
            "--probe-groups",
            "13",
            "--out",
            s(&plan),
        ]);
        common::failed_with(&o, &["cannot lock the output", s(&plan)]);
    }
    assert!(!plan.exists());
}

#[test]
fn a_failed_run_keeps_its_journal_only_with_groups_to_go_on_from() {
    let (_dir, demo, work) = common::demo_and_out_folder("work");
    // Group 4 unreadable without --keep-going: groups 0..4 are done and journaled first.
    std::fs::write(demo.join("g00004/f003.png"), b"not a png").unwrap();
    let out = work.join("a.wav");
    refused(
        &demo,
        &out,
        &[],
        &[
            "f003.png",
            "4 finished groups are kept in",
            "a.wav.journal",
            "--resume",
            "add --keep-going to make the unreadable group a gap",
        ],
    );
    assert_eq!(names(&work), ["a.wav.journal"]);
    // Mended, the same command with --resume goes on from them.
    std::fs::copy(demo.join("g00005/f003.png"), demo.join("g00004/f003.png")).unwrap();
    let o = groovescope(&["reconstruct", s(&demo), "--out", s(&out), "--resume"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(names(&work), ["a.wav"]);
    // Its line counts the groups read back apart from those it ran (the time is this run's).
    let said = String::from_utf8_lossy(&o.stdout);
    assert!(
        said.contains("13 groups: 4 read back from the journal, 9 run in"),
        "{said}"
    );
    // A run that fails on its first group has nothing to go on from: no journal stays.
    std::fs::write(demo.join("g00000/f003.png"), b"not a png").unwrap();
    let first = work.join("b.wav");
    let o = reconstruct(&demo, &first, &[]);
    assert!(!o.status.success());
    assert!(!stderr(&o).contains("kept in"), "{}", stderr(&o));
    assert_eq!(names(&work), ["a.wav"]);
}

/// A shard that fails after its groups ran (here its report cannot be written) keeps its
/// journal and says so with the same advice as a failure among the groups: how many groups are
/// kept, where, and that --resume goes on from them; it then does, to a complete part.
#[test]
fn a_shard_failing_at_its_finish_keeps_its_groups_and_says_resume() {
    let (_dir, demo, work) = common::demo_and_out_folder("work");
    let plan = work.join("plan.json");
    let o = groovescope(&two_shard_plan(s(&demo), s(&plan)));
    assert!(o.status.success(), "{}", stderr(&o));
    // Shard 1 of 2 runs groups 6..13 of the demo's 13; a folder where its report goes.
    let part = work.join("part-1");
    std::fs::create_dir_all(part.join("report.json")).unwrap();
    let shard = ["--plan", s(&plan), "--shard", "1"];
    refused(
        &demo,
        &part,
        &shard,
        &[
            "report.json",
            "7 finished groups are kept in",
            "part-1/journal",
            "the same command with --resume goes on from them",
        ],
    );
    assert_eq!(names(&part), ["journal", "report.json"]);
    std::fs::remove_dir(part.join("report.json")).unwrap();
    let o = reconstruct(&demo, &part, &[&shard[..], &["--resume"]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(names(&part), ["part.gsp", "report.json"]);
}

/// A run stopped by a damaged frame goes on past it with `--resume --keep-going` (its journal
/// holds only groups that read, as a run with --keep-going makes them), to the sound a run with
/// --keep-going from the start makes.
#[test]
fn a_run_stopped_by_a_damaged_frame_goes_on_past_it_with_keep_going() {
    use groovescope::io::wav::read_wav;
    let (_dir, demo, work) = common::demo_and_out_folder("work");
    std::fs::write(demo.join("g00006/f002.png"), b"not a png").unwrap();
    let out = work.join("a.wav");
    refused(&demo, &out, &[], &["6 finished groups are kept in"]);
    let resumed = groovescope(&[
        "reconstruct",
        s(&demo),
        "--out",
        s(&out),
        "--resume",
        "--keep-going",
    ]);
    assert!(resumed.status.success(), "{}", stderr(&resumed));
    let said = String::from_utf8_lossy(&resumed.stdout);
    assert!(said.contains("6 read back from the journal"), "{said}");
    let whole = work.join("b.wav");
    let o = reconstruct(&demo, &whole, &["--keep-going"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(
        read_wav(&out).unwrap().channels,
        read_wav(&whole).unwrap().channels
    );
    // A journal made with --keep-going refused by a run without it: src/side/journal.rs.
    assert_eq!(names(&work), ["a.wav", "b.wav"]);
    // A frame gone from a group is said the same way.
    std::fs::copy(demo.join("g00005/f002.png"), demo.join("g00006/f002.png")).unwrap();
    std::fs::remove_file(demo.join("g00009/f003.png")).unwrap();
    refused(
        &demo,
        &work.join("c.wav"),
        &[],
        &[
            "f003.png",
            "9 finished groups are kept in",
            "add --keep-going",
        ],
    );
}

/// A shard of a plan made without --keep-going, stopped by a damaged frame, goes on past it with
/// `--resume --keep-going` as a whole run does; the merge takes its part beside one made without
/// it, to the sound of a whole run with --keep-going.
#[test]
fn a_shard_stopped_by_a_damaged_frame_goes_on_past_it_with_keep_going() {
    use groovescope::io::wav::read_wav;
    let (_dir, demo, work) = common::demo_and_out_folder("work");
    // Shard 1 of 2 runs groups 6..13 of the demo's 13.
    std::fs::write(demo.join("g00009/f002.png"), b"not a png").unwrap();
    let whole = work.join("whole.wav");
    let o = reconstruct(&demo, &whole, &["--keep-going"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let plan = work.join("plan.json");
    let o = groovescope(&["plan", s(&demo), "--shards", "2", "--out", s(&plan)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let parts = [work.join("part-0"), work.join("part-1")];
    let shard = ["--plan", s(&plan), "--shard", "1"];
    refused(
        &demo,
        &parts[1],
        &shard,
        &["3 finished groups are kept in", "add --keep-going"],
    );
    let resume = [&shard[..], &["--resume", "--keep-going"]].concat();
    let o = reconstruct(&demo, &parts[1], &resume);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = reconstruct(&demo, &parts[0], &["--plan", s(&plan), "--shard", "0"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let merged = work.join("merged.wav");
    let o = groovescope(&["merge", s(&parts[0]), s(&parts[1]), "--out", s(&merged)]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(
        read_wav(&merged).unwrap().channels,
        read_wav(&whole).unwrap().channels
    );
}

/// A shard stopped by a damaged frame at its first group (no group finished, no journal kept)
/// still says --keep-going would make it a gap, and leaves no part folder; a --keep-going
/// shard prints the gap's warning on stderr as a whole run does, --quiet or not, not only in
/// its part's report.
#[test]
fn a_shard_prints_its_gaps_warnings_and_names_keep_going_at_its_first_group() {
    let (_dir, demo, work) = common::demo_and_out_folder("work");
    // Shard 1 of 2 runs groups 6..13 of the demo's 13: its first group is damaged.
    std::fs::write(demo.join("g00006/f002.png"), b"not a png").unwrap();
    let part = work.join("part-1");
    let plan = work.join("plan.json");
    let o = groovescope(&two_shard_plan(s(&demo), s(&plan)));
    assert!(o.status.success(), "{}", stderr(&o));
    let shard = ["--plan", s(&plan), "--shard", "1"];
    refused(
        &demo,
        &part,
        &shard,
        &["g00006/f002.png", "run with --keep-going"],
    );
    assert!(!part.exists(), "{:?}", names(&work));
    let whole = reconstruct(&demo, &work.join("whole.wav"), &["--keep-going"]);
    assert!(whole.status.success(), "{}", stderr(&whole));
    let gap_lines = |o: &std::process::Output| -> Vec<String> {
        stderr(o)
            .lines()
            .filter(|l| l.starts_with("warning: group "))
            .map(str::to_owned)
            .collect()
    };
    let want = gap_lines(&whole);
    assert!(
        want.iter()
            .any(|l| l.contains("group 6:") && l.contains("filled with silence")),
        "{}",
        stderr(&whole)
    );
    let o = reconstruct(&demo, &part, &[&shard[..], &["--keep-going"]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(gap_lines(&o), want, "{}", stderr(&o));
}

#[test]
fn a_group_of_another_frame_size_is_named_or_with_keep_going_a_gap_that_quiet_still_shows() {
    // Group 3 of another size, then group 0: group 0's size used to be the scan's, and all
    // twelve good groups were then refused.
    for (group, (w, h)) in [(3, (200, 100)), (0, (300, 384))] {
        let (dir, demo) = common::demo_in_tempdir();
        let name = format!("g{group:05}");
        for entry in std::fs::read_dir(demo.join(&name)).unwrap() {
            let img = Image::from_fn(w, h, |x, y| ((x * 7 + y * 3) % 11) as f32 / 11.0);
            save_grey_png(&img, &entry.unwrap().path(), false, true).unwrap();
        }
        let size = format!("{w}x{h}");
        let out = dir.path().join("o.wav");
        refused(&demo, &out, &[], &[&size, "the scan's are 320x384", &name]);
        // (The refused run kept its finished groups for --resume: this one writes elsewhere.)
        let out = dir.path().join("gap.wav");
        let o = reconstruct(&demo, &out, &["--keep-going", "--groups", "5"]);
        assert!(o.status.success(), "{}", stderr(&o));
        let err = stderr(&o);
        assert!(
            err.contains(&format!("warning: group {group}:"))
                && err.contains(&size)
                && err.contains("silence"),
            "--quiet keeps the warning: {err}"
        );
        assert_eq!(err.matches("warning: group").count(), 1, "{err}");
        assert!(o.stdout.is_empty());
    }
}

#[test]
fn a_group_cut_short_is_named_when_run_and_leaves_the_rest_of_the_scan_usable() {
    let dir = tempfile::tempdir().unwrap();
    let demo = demo_copy(dir.path());
    for k in 4..7 {
        std::fs::remove_file(demo.join(format!("g00003/f{k:03}.png"))).unwrap();
    }
    // The scan still opens: group 3 keeps its place and fails only when it is loaded.
    let out = dir.path().join("o.wav");
    refused(&demo, &out, &[], &["4 frames", "at least 7", "g00003"]);
    let out = dir.path().join("gap.wav");
    let o = reconstruct(&demo, &out, &["--keep-going", "--groups", "5"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let err = stderr(&o);
    assert!(
        err.contains("warning: group 3") && err.contains("4 frames"),
        "{err}"
    );
    let inspected = dir.path().join("inspect");
    let o = groovescope(&["inspect", s(&demo), "--group", "4", "--out", s(&inspected)]);
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn force_never_turns_an_input_into_an_output() {
    let (dir, demo) = common::demo_in_tempdir();
    let reference = demo.join("reference.wav");
    let before = std::fs::read(&reference).unwrap();
    refused(
        &demo,
        &reference,
        &["--force"],
        &["one of this command's inputs", "reference.wav"],
    );
    let params = dir.path().join("p.toml");
    std::fs::write(&params, "[flow]\nlambda = 0.05\n").unwrap();
    let wav = dir.path().join("x.wav");
    refused(
        &demo,
        &wav,
        &["--params", s(&params), "--report", s(&params), "--force"],
        &["one of this command's inputs", "p.toml"],
    );
    assert_eq!(std::fs::read(&reference).unwrap(), before);
    // The still decoder's image, by another spelling of its path.
    let still = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/demo-still/still.png");
    let image = dir.path().join("still.png");
    std::fs::copy(&still, &image).unwrap();
    let again = dir.path().join(".").join("still.png");
    let o = groovescope(&[
        "still",
        s(&image),
        "--um-per-px",
        "6",
        "--rpm",
        "16.667",
        "--radius-mm",
        "75",
        "--out",
        s(&again),
        "--force",
        "--quiet",
    ]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("one of this command's inputs"),
        "{}",
        stderr(&o)
    );
    assert_eq!(
        std::fs::read(&image).unwrap(),
        std::fs::read(&still).unwrap()
    );
    assert!(!wav.exists());
}

#[test]
fn nothing_is_written_among_a_scans_frames_or_over_a_part() {
    // A frame replaced (`--force`), or a new file in a group read as its eighth frame, broke
    // the scan: its next run stopped with "frame is missing: g00000/f007.png".
    let (dir, demo) = common::demo_in_tempdir();
    let frame = demo.join("g00000/f000.png");
    let before = std::fs::read(&frame).unwrap();
    for (out, extra) in [
        (frame.clone(), &["--force"][..]),
        (demo.join("g00000/f999.png"), &[][..]),
    ] {
        refused(
            &demo,
            &out,
            extra,
            &["inside a folder of the scan it reads", "g00000"],
        );
    }
    let report = demo.join("g00002/r.json");
    refused(
        &demo,
        &dir.path().join("x.wav"),
        &["--report", s(&report)],
        &["g00002"],
    );
    // Nor does a command that makes a folder put it among the groups (a new folder is read as
    // a group, an old one altered), nor in the scan's own place.
    for out in [demo.join("g00005"), demo.join("inspected"), demo.clone()] {
        let o = groovescope(&["inspect", s(&demo), "--group", "3", "--out", s(&out)]);
        common::failed_with(&o, &["output folder lies inside the scan it reads"]);
    }
    let o = groovescope(&["pack", s(&demo), "--out", s(&demo.join("demo.zarr"))]);
    common::failed_with(&o, &["output folder lies inside the scan it reads"]);
    assert_eq!(std::fs::read(&frame).unwrap(), before);
    assert!(!demo.join("g00000/f999.png").exists() && !report.exists());
    assert!(!demo.join("inspected").exists() && !demo.join("demo.zarr").exists());
    // Beside the groups is the archivist's choice, and the scan still reads after it.
    let beside = demo.join("transfer.wav");
    assert!(reconstruct(&demo, &beside, &[]).status.success());
    assert!(
        reconstruct(&demo, &dir.path().join("again.wav"), &[])
            .status
            .success()
    );
    // A store is one thing: nothing goes inside it.
    let store = dir.path().join("demo.zarr");
    assert!(
        groovescope(&["pack", s(&demo), "--out", s(&store)])
            .status
            .success()
    );
    refused(
        &store,
        &store.join("x.wav"),
        &[],
        &["inside the Zarr store it reads"],
    );
    let o = groovescope(&[
        "plan",
        s(&store),
        "--shards",
        "2",
        "--out",
        s(&store.join("p.json")),
    ]);
    common::failed_with(&o, &["inside the Zarr store it reads"]);
    // merge --force over a part it reads would lose the shard.
    let plan = dir.path().join("plan.json");
    assert!(
        groovescope(&["plan", s(&demo), "--shards", "2", "--out", s(&plan)])
            .status
            .success()
    );
    let parts: Vec<PathBuf> = (0..2)
        .map(|k| dir.path().join(format!("part-{k}")))
        .collect();
    for (k, part) in parts.iter().enumerate() {
        let shard = k.to_string();
        let args = ["--plan", s(&plan), "--shard", shard.as_str()];
        assert!(reconstruct(&demo, part, &args).status.success());
    }
    // A shard's --out is the part folder it makes and fills: in a group's folder, as a group's
    // folder (an old one altered, a new one read as a group), or as the scan itself, it would
    // write part.gsp and report.json among the frames, --force or not.
    let args = ["--plan", s(&plan), "--shard", "0"];
    let before = names(&demo);
    let group_before = names(&demo.join("g00005"));
    for out in [
        demo.join("g00001/part"),
        demo.join("g00005"),
        demo.join("g00020"),
        demo.clone(),
    ] {
        for extra in [&[][..], &["--force"][..]] {
            refused(
                &demo,
                &out,
                &[&args[..], extra].concat(),
                &["output folder lies inside the scan it reads", s(&out)],
            );
        }
    }
    assert_eq!(names(&demo), before);
    assert_eq!(names(&demo.join("g00005")), group_before);
    assert!(!demo.join("g00001/part").exists());
    // Nor anywhere in a store.
    let store_plan = dir.path().join("store-plan.json");
    let o = groovescope(&two_shard_plan(s(&store), s(&store_plan)));
    assert!(o.status.success(), "{}", stderr(&o));
    let store_before = names(&store);
    for out in [store.join("part"), store.join("frames"), store.clone()] {
        refused(
            &store,
            &out,
            &["--plan", s(&store_plan), "--shard", "1"],
            &["output folder lies inside the scan it reads", s(&out)],
        );
    }
    assert_eq!(names(&store), store_before);
    let part_file = parts[0].join("part.gsp");
    let kept = std::fs::read(&part_file).unwrap();
    for given in [&parts[0], &part_file] {
        let o = groovescope(&[
            "merge",
            s(given),
            s(&parts[1]),
            "--out",
            s(&part_file),
            "--force",
        ]);
        common::failed_with(&o, &["one of this command's inputs", "part.gsp"]);
    }
    assert_eq!(std::fs::read(&part_file).unwrap(), kept);
}

#[test]
fn a_folder_output_under_a_missing_folder_is_named_not_created() {
    let dir = tempfile::tempdir().unwrap();
    let scan = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/demo");
    let out = dir.path().join("typo/out");
    let o = s(&out);
    let runs: [&[&str]; 5] = [
        &["synth", "--preset", "quick", "--out", o],
        &["synth-scene", "cube", "--out", o],
        &["synth-still", "--out", o],
        &["pack", s(&scan), "--out", o],
        &["inspect", s(&scan), "--out", o],
    ];
    for args in runs {
        common::failed_with(&groovescope(args), &["folder does not exist", "typo"]);
    }
    assert!(names(dir.path()).is_empty(), "nothing created");
}
