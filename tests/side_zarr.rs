//! The Zarr scan store: pack round trip frame for frame, the same WAV from either form, a missing chunk.

#![allow(clippy::unwrap_used)] // tests may panic

mod common;

use std::path::Path;

use common::{StoreRun, groovescope, groups_checked, stderr};
use groovescope::image::Image;
use groovescope::io::zarr::{PROGRESS_FILE, partial_path};
use groovescope::io::{Scan, load_group, save_grey_png};
use groovescope::job::Job;
use groovescope::side::scan_fingerprint;
use groovescope::synth::{BUILTIN_RATE_HZ, SynthConfig, render_scan, tone};

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A scan of textured frames: 8- or 16-bit grey PNG, or RGB PNG (stored as f32 grey).
fn textured_scan(dir: &Path, groups: usize, kind: &str) {
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(dir.join("scan.toml"), common::SCAN_TOML).unwrap();
    for g in 0..groups {
        let gd = dir.join(format!("g{g:05}"));
        std::fs::create_dir_all(&gd).unwrap();
        for k in 0..7 {
            let img = Image::from_fn(33, 21, |x, y| {
                let v = 0.5 + 0.4 * ((x as f32 + 3.0 * k as f32 + g as f32) * 0.37).sin();
                v * (0.6 + 0.02 * y as f32)
            });
            let path = gd.join(format!("f{k:03}.png"));
            match kind {
                "rgb" => {
                    let rgb = image::RgbImage::from_fn(33, 21, |x, y| {
                        let v = (img.data[(y * 33 + x) as usize] * 255.0) as u8;
                        image::Rgb([v, v / 2, 255 - v])
                    });
                    rgb.save(&path).unwrap();
                }
                _ => save_grey_png(&img, &path, kind == "16", false).unwrap(),
            }
        }
    }
    std::fs::write(dir.join("reference.wav"), b"not read here").unwrap();
}

#[test]
fn pack_round_trips_every_frame_bit_for_bit_for_8_bit_16_bit_and_colour_frames() {
    let tmp = tempfile::tempdir().unwrap();
    for kind in ["8", "16", "rgb"] {
        let folder = tmp.path().join(format!("scan{kind}"));
        let store = tmp.path().join(format!("scan{kind}.zarr"));
        textured_scan(&folder, 3, kind);
        let o = groovescope(&["pack", s(&folder), "--out", s(&store)]);
        assert!(o.status.success(), "{}", stderr(&o));
        assert_same_scan(&folder, &store);
        // Packing onto a store that exists is refused; the store is untouched.
        let o = groovescope(&["pack", s(&folder), "--out", s(&store)]);
        assert!(
            !o.status.success() && stderr(&o).contains(s(&store)),
            "{}",
            stderr(&o)
        );
        assert!(Scan::open(&store).is_ok());
    }
}

/// `store` holds the scan of `folder`: the same metadata, fingerprint and reference, and
/// every group's frames bit for bit.
fn assert_same_scan(folder: &Path, store: &Path) {
    let (a, b) = (Scan::open(folder).unwrap(), Scan::open(store).unwrap());
    assert!(b.groups.iter().all(|g| g.zarr.is_some()));
    assert_eq!(a.meta, b.meta);
    assert_eq!(scan_fingerprint(&a), scan_fingerprint(&b));
    assert!(b.reference.as_ref().is_some_and(|p| p.starts_with(store)));
    for (ga, gb) in a.groups.iter().zip(&b.groups) {
        let (fa, fb) = (load_group(ga).unwrap(), load_group(gb).unwrap());
        assert_eq!(fa.len(), 7);
        for (x, y) in fa.iter().zip(&fb) {
            assert_eq!((x.width, x.height), (y.width, y.height));
            assert!(
                x.data
                    .iter()
                    .zip(&y.data)
                    .all(|(p, q)| p.to_bits() == q.to_bits()),
                "{}: group {} differs",
                store.display(),
                ga.index
            );
        }
    }
    assert!(!store.join(PROGRESS_FILE).exists(), "the progress record");
}

#[test]
fn a_stopped_or_killed_pack_resumes_where_it_stopped_to_the_same_store() {
    let tmp = tempfile::tempdir().unwrap();
    let folder = tmp.path().join("scan");
    let groups = 400;
    textured_scan(&folder, groups, "8");
    let store = tmp.path().join("side.zarr");
    let partial = partial_path(&store);
    let args = [s(&folder), "--out", s(&store), "--quiet"];
    let run = StoreRun {
        command: "pack",
        args: &args,
        partial: &partial,
    };

    // Ctrl-C: the groups packed so far are kept, and the line says where and how to go on.
    let of = format!(" of {groups} groups");
    let kept = run.ctrl_c_keeps(2, &["stopped", &of]);
    assert!(kept < groups, "{kept}");
    assert!(!store.exists());

    // Without --resume or --force the partial store is neither used nor touched.
    let o = groovescope(&["pack", s(&folder), "--out", s(&store)]);
    let e = stderr(&o);
    assert!(
        !o.status.success() && e.contains(s(&partial)) && e.contains("--resume"),
        "{e}"
    );
    assert_eq!(groups_checked(&partial), kept);
    // Nor with another zstd level: the chunks would mix two.
    let o = groovescope(&[
        "pack",
        s(&folder),
        "--out",
        s(&store),
        "--resume",
        "--zstd-level",
        "9",
    ]);
    let e = stderr(&o);
    assert!(!o.status.success() && e.contains("--zstd-level 3"), "{e}");

    // Killed outright while resuming: what it counted is whole.
    let mut args_resume = args.to_vec();
    args_resume.push("--resume");
    let resuming = StoreRun {
        args: &args_resume,
        ..run
    };
    let mut child = resuming.until(kept + 2);
    child.kill().unwrap();
    child.wait().unwrap();
    let killed_at = groups_checked(&partial);
    assert!(killed_at >= kept + 2, "{killed_at}");

    run.resume_to_the_end(killed_at, groups);
    assert_same_scan(&folder, &store);
    let left: Vec<_> = std::fs::read_dir(tmp.path())
        .unwrap()
        .flatten()
        .map(|e| e.file_name())
        .collect();
    assert_eq!(left.len(), 2, "only the scan and its store: {left:?}");
}

#[test]
fn pack_refuses_groups_of_different_frame_counts_naming_the_group_and_resumes_once_mended() {
    let tmp = tempfile::tempdir().unwrap();
    let folder = tmp.path().join("scan");
    textured_scan(&folder, 3, "8");
    std::fs::copy(
        folder.join("g00000/f000.png"),
        folder.join("g00001/f007.png"),
    )
    .unwrap();
    let store = tmp.path().join("scan.zarr");
    let o = groovescope(&["pack", s(&folder), "--out", s(&store)]);
    let e = stderr(&o);
    assert!(
        !o.status.success()
            && e.contains("g00001")
            && e.contains("same number of frames")
            && e.contains("the 1 of 3 groups")
            && e.contains("--resume"),
        "{e}"
    );
    assert!(!store.exists(), "a failed pack left its store");
    let leftovers: Vec<_> = std::fs::read_dir(tmp.path()).unwrap().collect();
    assert_eq!(leftovers.len(), 2, "the scan and the partial store");
    let partial = partial_path(&store);
    assert_eq!(groups_checked(&partial), 1);

    // A group taken over must still hold as many frames as its chunk.
    let extra = folder.join("g00000/f007.png");
    std::fs::copy(folder.join("g00000/f000.png"), &extra).unwrap();
    let o = groovescope(&["pack", s(&folder), "--out", s(&store), "--resume"]);
    let e = stderr(&o);
    assert!(
        !o.status.success() && e.contains("g00000") && e.contains("now holds 8 frames"),
        "{e}"
    );
    std::fs::remove_file(extra).unwrap();

    // Once the scan's metadata has changed it is another scan: refused, and nothing written.
    let toml = std::fs::read_to_string(folder.join("scan.toml")).unwrap();
    std::fs::write(
        folder.join("scan.toml"),
        toml.replace("rpm = 78.0", "rpm = 45.0"),
    )
    .unwrap();
    let o = groovescope(&["pack", s(&folder), "--out", s(&store), "--resume"]);
    let e = stderr(&o);
    assert!(
        !o.status.success() && e.contains("something else") && e.contains(s(&partial)),
        "{e}"
    );
    // --force starts over on the scan as it is now (and stops at group 1 again) ...
    let o = groovescope(&["pack", s(&folder), "--out", s(&store), "--force"]);
    assert!(stderr(&o).contains("the 1 of 3 groups"), "{}", stderr(&o));
    // ... and mended, it goes on from group 1.
    std::fs::remove_file(folder.join("g00001/f007.png")).unwrap();
    let o = groovescope(&["pack", s(&folder), "--out", s(&store), "--resume"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let said = String::from_utf8_lossy(&o.stdout);
    assert!(said.contains("resumed: 1 of 3 groups"), "{said}");
    assert_same_scan(&folder, &store);
    assert_eq!(Scan::open(&store).unwrap().meta.record.rpm, 45.0);

    // A pack that fails on its first group keeps nothing.
    let other = tmp.path().join("other");
    textured_scan(&other, 2, "8");
    std::fs::write(other.join("g00000/f003.png"), b"not a png").unwrap();
    let out = tmp.path().join("other.zarr");
    let o = groovescope(&["pack", s(&other), "--out", s(&out)]);
    let e = stderr(&o);
    assert!(
        !o.status.success() && e.contains("f003.png") && !e.contains("--resume"),
        "{e}"
    );
    assert!(!out.exists() && !partial_path(&out).exists());
}

#[test]
fn a_store_reconstructs_to_the_same_wav_and_a_missing_chunk_is_named_or_a_gap() {
    let tmp = tempfile::tempdir().unwrap();
    let folder = tmp.path().join("scan");
    let cfg = SynthConfig {
        width_px: 160,
        height_px: 300,
        pixel_pitch_um: 1.0,
        group_overlap_px: 20,
        frames_per_group: 8,
        bit_depth: 16,
        max_groups: Some(6),
        ..SynthConfig::dual_focus_demo()
    };
    let sound = tone(1000.0, 0.01, BUILTIN_RATE_HZ);
    render_scan(&sound, &cfg, &folder, Job::unwatched()).unwrap();
    let store = tmp.path().join("scan.zarr");
    assert!(
        groovescope(&["pack", s(&folder), "--out", s(&store), "--quiet"])
            .status
            .success()
    );
    let wav = |scan: &Path, name: &str, extra: &[&str]| {
        let out = tmp.path().join(name);
        let mut args = vec!["reconstruct", s(scan), "--out", s(&out), "--quiet"];
        args.extend_from_slice(extra);
        (groovescope(&args), out)
    };
    let (o, a) = wav(&folder, "folder.wav", &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (o, b) = wav(&store, "store.wav", &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        std::fs::read(&a).unwrap() == std::fs::read(&b).unwrap(),
        "WAVs differ"
    );
    // Both are the same Broadcast WAV: the disc, the decoder and filters, and a reference
    // made of the scan's and the params' fingerprints, which the two forms share.
    let (description, _, reference, history) =
        groovescope::io::bwf::read_bext(&std::fs::read(&a).unwrap()).unwrap();
    assert!(description.contains("lateral-cut disc at"), "{description}");
    let params = groovescope::pipeline::PipelineParams::default();
    let want = scan_fingerprint(&Scan::open(&folder).unwrap())
        + &groovescope::side::params_fingerprint(&params);
    assert_eq!(reference, want);
    assert!(
        history[1].contains("fused decoder on the dual-focus path; DC block"),
        "{history:?}"
    );

    let chunk = store.join("frames/c/2/0/0/0");
    std::fs::remove_file(&chunk).unwrap();
    let (o, _) = wav(&store, "missing.wav", &[]);
    let e = stderr(&o);
    assert!(
        !o.status.success() && e.contains("missing") && e.contains(s(&chunk)),
        "{e}"
    );
    let report = tmp.path().join("gap.json");
    let (o, out) = wav(&store, "gap.wav", &["--keep-going", "--report", s(&report)]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(out.is_file());
    let r: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    let row = &r["groups"][2];
    assert_eq!(row["group"], 2);
    assert!(
        row["warning"].as_str().unwrap().contains("missing"),
        "{row}"
    );
}
