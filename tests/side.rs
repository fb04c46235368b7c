//! Whole sides: shards merged byte-identical to one process, resume after kill -9, every refusal, and a side scored in bounded memory.

#![allow(clippy::unwrap_used)] // tests may panic

mod common;

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::OnceLock;

use common::{groovescope, stderr};
use groovescope::io::wav::read_wav;
use groovescope::job::Job;
use groovescope::synth::{BUILTIN_RATE_HZ, SynthConfig, render_scan, tone};

/// Groups in the shared scan: enough that 2 and 3 shards start past the 64-group slope history.
const GROUPS: usize = 150;

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A small dual-focus scan (160×300 px, 8 frames a group, 1 µm pixels) of a 1 kHz tone, rough
/// enough that the clip's slope reference rejects fits, so shards must rebuild its history.
fn small_side_config(groups: usize) -> SynthConfig {
    SynthConfig {
        width_px: 160,
        height_px: 300,
        pixel_pitch_um: 1.0,
        group_overlap_px: 20,
        frames_per_group: 8,
        bit_depth: 8,
        max_groups: Some(groups),
        ..SynthConfig::dual_focus_demo()
    }
}

/// The shared scan, rendered once: its folder, and the WAV and JSON report of one default
/// (fused) `reconstruct` of it in one process.
type Shared = (tempfile::TempDir, PathBuf, Vec<u8>, serde_json::Value);

fn shared() -> &'static Shared {
    static SCAN: OnceLock<Shared> = OnceLock::new();
    SCAN.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let scan = dir.path().join("scan");
        let cfg = small_side_config(GROUPS);
        let sound = tone(1000.0, 0.03, BUILTIN_RATE_HZ);
        render_scan(&sound, &cfg, &scan, Job::unwatched()).unwrap();
        let (out, report) = reconstruct_with_report(&scan, dir.path(), "one", &[]);
        assert!(!groovescope::side::cli::journal_path(&out).exists());
        let wav = std::fs::read(&out).unwrap();
        (dir, scan, wav, report)
    })
}

/// `reconstruct SCAN` with `args` (a method, params) into `dir`'s `NAME.wav`, with its report
/// `NAME.json`: the WAV's path and the report.
fn reconstruct_with_report(
    scan: &Path,
    dir: &Path,
    name: &str,
    args: &[&str],
) -> (PathBuf, serde_json::Value) {
    let (wav, report) = (
        dir.join(format!("{name}.wav")),
        dir.join(format!("{name}.json")),
    );
    let fixed = [
        "reconstruct",
        s(scan),
        "--out",
        s(&wav),
        "--report",
        s(&report),
        "--quiet",
    ];
    let o = groovescope(&[&fixed[..], args].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    let r = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    (wav, r)
}

fn plan(scan: &Path, shards: usize, out: &Path, extra: &[&str]) {
    let mut args = vec![
        "plan",
        s(scan),
        "--shards",
        &shards.to_string(),
        "--out",
        s(out),
        "--probe-groups",
        "0",
    ]
    .into_iter()
    .map(String::from)
    .collect::<Vec<_>>();
    args.extend(extra.iter().map(|a| (*a).to_string()));
    let refs: Vec<&str> = args.iter().map(String::as_str).collect();
    let o = groovescope(&refs);
    assert!(o.status.success(), "{}", stderr(&o));
}

/// `reconstruct SCAN --plan PLAN --shard K --out OUT`: how every shard's command line starts.
fn shard_args<'a>(scan: &'a Path, plan: &'a Path, k: &'a str, out: &'a Path) -> [&'a str; 8] {
    [
        "reconstruct",
        s(scan),
        "--plan",
        s(plan),
        "--shard",
        k,
        "--out",
        s(out),
    ]
}

fn run_shard(scan: &Path, plan: &Path, k: usize, out: &Path) {
    let k_text = k.to_string();
    let o = groovescope(&[&shard_args(scan, plan, &k_text, out)[..], &["--quiet"]].concat());
    assert!(o.status.success(), "shard {k}: {}", stderr(&o));
}

/// A plan of `shards` shards (`extra`: more `plan` arguments) written into `dir` as
/// `NAME-plan.json`, and every shard run into `NAME-part-K`: the parts, in shard order.
fn planned_parts(
    scan: &Path,
    dir: &Path,
    name: &str,
    shards: usize,
    extra: &[&str],
) -> Vec<PathBuf> {
    let p = dir.join(format!("{name}-plan.json"));
    plan(scan, shards, &p, extra);
    (0..shards)
        .map(|k| {
            let part = dir.join(format!("{name}-part-{k}"));
            run_shard(scan, &p, k, &part);
            part
        })
        .collect()
}

fn merge(parts: &[PathBuf], out: &Path) -> std::process::Output {
    let mut args = vec!["merge".to_string()];
    args.extend(parts.iter().map(|p| s(p).to_string()));
    args.extend(["--out".into(), s(out).into(), "--quiet".into()]);
    let refs: Vec<&str> = args.iter().map(String::as_str).collect();
    groovescope(&refs)
}

/// Merges `parts` into `out` and asserts it succeeds with the bytes `want` (the one-process
/// WAV); `what` names the case in the failure message.
fn assert_merges_to(parts: &[PathBuf], out: &Path, want: &[u8], what: &str) {
    let o = merge(parts, out);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        std::fs::read(out).unwrap() == want,
        "{what}: merged WAV differs from the one-process WAV"
    );
}

#[test]
fn merged_shards_are_byte_identical_to_one_process_for_1_2_3_and_7_shards() {
    let (_keep, scan, one, _) = shared();
    let tmp = tempfile::tempdir().unwrap();
    for n in [1, 2, 3, 7] {
        let p = tmp.path().join(format!("plan{n}.json"));
        plan(scan, n, &p, &[]);
        // Shards in reverse order: each is independent of the others.
        let parts: Vec<PathBuf> = (0..n)
            .rev()
            .map(|k| {
                let dir = tmp.path().join(format!("n{n}-part-{k}"));
                run_shard(scan, &p, k, &dir);
                assert!(dir.join("part.gsp").is_file() && !dir.join("journal").exists());
                dir
            })
            .collect();
        let out = tmp.path().join(format!("merged{n}.wav"));
        assert_merges_to(&parts, &out, one, &format!("{n} shards"));
        if n == 2 {
            // Without --quiet it says its score against the scan's reference, as a
            // one-process run does.
            let mut args = vec!["merge"];
            args.extend(parts.iter().map(|p| s(p)));
            let said_out = tmp.path().join("said.wav");
            args.extend(["--out", s(&said_out)]);
            let o = groovescope(&args);
            let said = String::from_utf8_lossy(&o.stdout);
            assert!(said.contains("\nvs reference: r = "), "{said}");
        }
    }
}

/// `merge --dsp` finishes the same parts with another `[dsp]` table (a playback curve for an
/// access copy): byte-identical to a one-process run with those params, and different from
/// the plain merge; a file with any other table is refused in one line naming it, writing
/// nothing.
#[test]
fn merge_with_another_dsp_table_is_the_one_process_run_with_it() {
    let (_keep, scan, one, _) = shared();
    let tmp = tempfile::tempdir().unwrap();
    let parts = planned_parts(scan, tmp.path(), "fused", 2, &[]);
    let eq = tmp.path().join("eq.toml");
    std::fs::write(
        &eq,
        "[dsp]\neq = \"custom\"\neq_turnover_hz = 300.0\neq_rolloff_db = 16.0\n",
    )
    .unwrap();
    let want = tmp.path().join("one-eq.wav");
    let o = groovescope(&[
        "reconstruct",
        s(scan),
        "--params",
        s(&eq),
        "--out",
        s(&want),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let merge_dsp = |file: &Path, out: &Path| {
        let mut args: Vec<&str> = vec!["merge"];
        args.extend(parts.iter().map(|p| s(p)));
        args.extend(["--dsp", s(file), "--out", s(out), "--quiet"]);
        groovescope(&args)
    };
    let got = tmp.path().join("merged-eq.wav");
    let o = merge_dsp(&eq, &got);
    assert!(o.status.success(), "{}", stderr(&o));
    let got = std::fs::read(&got).unwrap();
    assert!(
        got == std::fs::read(&want).unwrap(),
        "merge --dsp differs from one process"
    );
    assert!(got != *one, "the EQ changed nothing");
    let bad = tmp.path().join("bad.toml");
    std::fs::write(&bad, "[dsp]\neq = \"riaa\"\n[flow]\nlambda = 2.0\n").unwrap();
    let out = tmp.path().join("bad.wav");
    let o = merge_dsp(&bad, &out);
    let e = stderr(&o);
    assert!(!o.status.success() && !out.exists(), "{e}");
    assert_eq!(e.trim().lines().count(), 1, "{e}");
    assert!(e.contains("`flow`") && e.contains("bad.toml"), "{e}");
    // Without a [dsp] table beside it, the same sentence (not "unknown field").
    std::fs::write(&bad, "[edges]\ndespike_sigmas = 0.0\n").unwrap();
    let e = stderr(&merge_dsp(&bad, &out));
    assert!(
        e.contains("takes only a [dsp] table") && e.contains("`edges`"),
        "{e}"
    );
    // A top-level key beside a [dsp] table was dropped unread, and the merge succeeded.
    std::fs::write(&bad, "method = \"edges\"\n[dsp]\neq = \"riaa\"\n").unwrap();
    let o = merge_dsp(&bad, &out);
    let e = stderr(&o);
    assert!(!o.status.success() && !out.exists(), "{e}");
    assert_eq!(e.trim().lines().count(), 1, "{e}");
    assert!(
        e.contains("`method` (line 1) outside it") && e.contains("bad.toml"),
        "{e}"
    );
}

/// The default method is `fused` (both signals per group, fused over the merged clip); `flow`
/// (whose shards rebuild the slope history) and `edges` merge to the one-process bytes too.
#[test]
fn merged_shards_are_byte_identical_to_one_process_for_flow_and_edges() {
    let (_keep, scan, _, _) = shared();
    let tmp = tempfile::tempdir().unwrap();
    for method in ["flow", "edges"] {
        let params = tmp.path().join(format!("{method}.toml"));
        std::fs::write(&params, format!("method = \"{method}\"\n")).unwrap();
        let one = tmp.path().join(format!("{method}-one.wav"));
        let o = groovescope(&[
            "reconstruct",
            s(scan),
            "--out",
            s(&one),
            "--method",
            method,
            "--quiet",
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let parts = planned_parts(scan, tmp.path(), method, 3, &["--params", s(&params)]);
        let out = tmp.path().join(format!("{method}-merged.wav"));
        assert_merges_to(&parts, &out, &std::fs::read(&one).unwrap(), method);
    }
    let flow = std::fs::read(tmp.path().join("flow-one.wav")).unwrap();
    let edges = std::fs::read(tmp.path().join("edges-one.wav")).unwrap();
    assert!(flow != edges, "--method changes the sound");
}

/// The fused method reads a group the flow method's stages fail on by the edges alone instead
/// of leaving it silent (the rough scan's stripes fail on a few groups); where they fail on
/// every group, the clip is the edge method's, sample for sample, and says so. And where the
/// flow has gaps everywhere (a third of the rough scan's fits are rejected, and the flow reads
/// its tone inverted), the fusion still measures both methods' noise and reads as well as the
/// edges: at equal weights, which it fell back on before, it read r 0.24 against the edges' 0.998.
#[test]
fn a_group_the_flow_method_loses_is_read_by_the_edges_alone() {
    let (_keep, scan, _, fused) = shared();
    let tmp = tempfile::tempdir().unwrap();
    let params = tmp.path().join("no-stripes.toml");
    let run = |name: &str, args: &[&str]| reconstruct_with_report(scan, tmp.path(), name, args);
    let warnings = |r: &serde_json::Value| -> Vec<String> {
        r["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .map(|w| w.as_str().unwrap().to_string())
            .collect()
    };
    let silent = |r: &serde_json::Value| {
        r["groups"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|g| g["samples"] == 0)
            .count()
    };
    let r = |r: &serde_json::Value| r["scores"]["r"].as_f64().unwrap();
    let (_, edges) = run("edges-rough", &["--method", "edges"]);
    let (fused_r, edges_r) = (r(fused), r(&edges));
    assert!(
        fused_r > 0.99 && fused_r > edges_r - 0.005,
        "fused r {fused_r}, edges r {edges_r}"
    );
    let fused_warnings = warnings(fused);
    let alone = fused_warnings
        .iter()
        .filter(|w| w.ends_with("(read by the edges alone)"));
    assert!(alone.count() >= 2, "{fused_warnings:#?}");
    assert_eq!(silent(fused), 0, "{fused_warnings:#?}");
    // An in-focus gradient no pixel reaches: the stripe stage fails on every group.
    std::fs::write(&params, "[hough]\ngradient_threshold = 10.0\n").unwrap();
    let no_stripes = ["--params", s(&params)];
    let (wav, report) = run(
        "fused-alone",
        &[&["--method", "fused"][..], &no_stripes].concat(),
    );
    let warnings = warnings(&report);
    assert_eq!(silent(&report), 0, "{warnings:#?}");
    assert!(
        warnings
            .iter()
            .any(|w| w.contains("the edges alone made the clip")),
        "{warnings:#?}"
    );
    let (edges, _) = run("edges", &[&["--method", "edges"][..], &no_stripes].concat());
    assert_eq!(
        read_wav(&wav).unwrap().channels,
        read_wav(&edges).unwrap().channels
    );
}

/// Each group's report row carries the pixel noise the edge stage measured, near the noise the
/// scan was rendered with, and a plan's merged report carries the same figures; a failed group
/// and the flow method, which reads no edges, report none.
#[test]
fn report_rows_carry_the_pixel_noise_through_parts() {
    let (_keep, scan, _, fused) = shared();
    let tmp = tempfile::tempdir().unwrap();
    let t = |name: &str| tmp.path().join(name);
    // Each row's sample count and pixel noise.
    let rows = |r: &serde_json::Value| -> Vec<(u64, Option<f64>)> {
        r["groups"]
            .as_array()
            .unwrap()
            .iter()
            .map(|g| {
                let samples = g["samples"].as_u64().unwrap();
                (samples, g["pixel_noise_grey_levels"].as_f64())
            })
            .collect()
    };
    let one = rows(fused);
    assert_eq!(one.len(), GROUPS);
    // Rendered with σ = 0.5 grey levels and quantised to 8 bits: σ² + 1/12 in all.
    let truth = (0.25_f64 + 1.0 / 12.0).sqrt();
    let mut measured = 0;
    for (g, &(samples, noise)) in one.iter().enumerate() {
        match noise {
            Some(n) => {
                assert!(
                    (n / truth - 1.0).abs() < 0.3,
                    "group {g}: {n} against {truth}"
                );
                measured += 1;
            }
            None => assert_eq!(samples, 0, "group {g} made sound but reports no noise"),
        }
    }
    assert!(measured > GROUPS * 9 / 10, "{measured} of {GROUPS} groups");
    let p = t("plan.json");
    plan(scan, 2, &p, &[]);
    let mut args = vec!["merge".to_string()];
    for k in 0..2 {
        let dir = t(&format!("part-{k}"));
        run_shard(scan, &p, k, &dir);
        args.push(s(&dir).to_string());
    }
    let (wav, report) = (t("merged.wav"), t("merged.json"));
    args.extend(["--out", s(&wav), "--report", s(&report), "--quiet"].map(String::from));
    let o = groovescope(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(o.status.success(), "{}", stderr(&o));
    let merged = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    assert_eq!(rows(&merged), one);
    let (_, flow) = reconstruct_with_report(scan, tmp.path(), "flow", &["--method", "flow"]);
    assert!(rows(&flow).iter().all(|r| r.1.is_none()));
}

#[test]
fn merge_refuses_mixed_missing_duplicated_and_truncated_parts_naming_the_part() {
    let (_keep, scan, _, _) = shared();
    let tmp = tempfile::tempdir().unwrap();
    let t = tmp.path();
    let (p2, p3) = (t.join("p2.json"), t.join("p3.json"));
    plan(scan, 2, &p2, &[]);
    plan(scan, 3, &p3, &[]);
    let part = |name: &str, plan: &Path, k: usize| {
        let dir = t.join(name);
        run_shard(scan, plan, k, &dir);
        dir
    };
    let (a0, a1) = (part("a0", &p2, 0), part("a1", &p2, 1));
    let b1 = part("b1", &p3, 1);
    let expect_refusal = |parts: &[PathBuf], words: &str, named: &Path| {
        let out = t.join("x.wav");
        let o = merge(parts, &out);
        let e = stderr(&o);
        assert!(!o.status.success() && !out.exists(), "{e}");
        assert!(e.contains(words), "{e}");
        assert!(e.contains(s(named)), "{e}");
        assert_eq!(e.trim().lines().count(), 1, "{e}");
    };
    expect_refusal(
        std::slice::from_ref(&a0),
        "the plan has 2 shards and shard 1 (groups 75..150) is missing",
        &a0,
    );
    expect_refusal(
        &[a0.clone(), a1.clone(), a1.clone()],
        "duplicates shard 1",
        &a1,
    );
    expect_refusal(&[a0.clone(), b1.clone()], "another plan", &b1);

    // Other params: a plan with another λ.
    let params = t.join("params.toml");
    std::fs::write(&params, "[flow]\nlambda = 0.2\n").unwrap();
    let pp = t.join("pp.json");
    plan(scan, 2, &pp, &["--params", s(&params)]);
    let c1 = part("c1", &pp, 1);
    expect_refusal(&[a0.clone(), c1.clone()], "other params", &c1);

    // Another scan: the same frames under other metadata.
    let other = t.join("other-scan");
    copy_dir(scan, &other);
    let meta = std::fs::read_to_string(other.join("scan.toml")).unwrap();
    std::fs::write(
        other.join("scan.toml"),
        meta.replacen("rpm = 78.0", "rpm = 80.0", 1),
    )
    .unwrap();
    let po = t.join("po.json");
    plan(&other, 2, &po, &[]);
    let d1 = t.join("d1");
    run_shard(&other, &po, 1, &d1);
    expect_refusal(&[a0.clone(), d1.clone()], "another scan", &d1);

    // A part cut short: the end record cut off, then a group record cut in half; and one
    // with a byte flipped in a group record (once called "truncated").
    for cut in [10, 400, 0] {
        let torn = t.join(format!("torn{cut}"));
        copy_dir(&a1, &torn);
        let file = torn.join("part.gsp");
        let len = std::fs::metadata(&file).unwrap().len();
        std::fs::OpenOptions::new()
            .write(true)
            .open(&file)
            .unwrap()
            .set_len(len - cut)
            .unwrap();
        if cut == 0 {
            let mut bytes = std::fs::read(&file).unwrap();
            let at = bytes.len() / 2;
            bytes[at] ^= 0x40;
            std::fs::write(&file, bytes).unwrap();
        }
        expect_refusal(&[a0.clone(), torn.clone()], "damaged or cut part", &file);
    }
    // The good pair still merges.
    let o = merge(&[a1, a0], &t.join("ok.wav"));
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn a_plan_for_another_scan_and_a_shard_out_of_range_are_refused() {
    let (_keep, scan, _, _) = shared();
    let tmp = tempfile::tempdir().unwrap();
    let t = tmp.path();
    let p = t.join("plan.json");
    plan(scan, 3, &p, &[]);
    let other = t.join("other");
    copy_dir(scan, &other);
    std::fs::remove_dir_all(other.join("g00149")).unwrap();
    let part = t.join("part");
    let run = |scan: &Path, k: &str| groovescope(&shard_args(scan, &p, k, &part));
    let o = run(&other, "0");
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(e.contains("another scan") && e.contains(s(&p)), "{e}");
    let o = run(scan, "3");
    let e = stderr(&o);
    assert!(!o.status.success());
    assert!(
        e.contains("--shard 3 is out of range") && e.contains("3 shards"),
        "{e}"
    );
    assert!(!t.join("part").join("part.gsp").exists());
    // A plan edited by hand is refused too.
    let text = std::fs::read_to_string(&p).unwrap();
    std::fs::write(
        &p,
        text.replacen("\"end_group\": 50", "\"end_group\": 51", 1),
    )
    .unwrap();
    let e = stderr(&run(scan, "0"));
    assert!(e.contains("edited or is damaged"), "{e}");
    // What a shard does not write is refused, not ignored (the report was never written).
    std::fs::write(&p, text).unwrap();
    for extra in [["--report", "r.json"], ["--bits", "16"]] {
        let mut args = vec!["reconstruct", s(scan), "--plan", s(&p), "--shard", "0"];
        args.extend(extra);
        let part = t.join("part");
        args.extend(["--out", s(&part)]);
        let e = stderr(&groovescope(&args));
        assert!(
            e.contains("do not go with --plan") && e.contains("merge"),
            "{e}"
        );
        assert!(!part.join("part.gsp").exists());
    }
}

/// Spawns `args` with `--progress-json` (its stderr to `stderr`) and reads its progress lines
/// until `done` reaches `at`; returns the child and whether it got there before finishing.
fn spawn_until(args: &[&str], at: usize, stderr: Stdio) -> (std::process::Child, bool) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_groovescope"))
        .args(args)
        .arg("--progress-json")
        .env_remove("DISPLAY")
        .stdout(Stdio::piped())
        .stderr(stderr)
        .spawn()
        .unwrap();
    let reader = BufReader::new(child.stdout.take().unwrap());
    for line in reader.lines() {
        let v: serde_json::Value = serde_json::from_str(&line.unwrap()).unwrap();
        if v["event"] == "group" && v["done"].as_u64().unwrap() as usize >= at {
            return (child, true);
        }
    }
    (child, false)
}

/// Kills `args` (SIGKILL) once its `done` reaches `kill_at`; returns whether it was killed
/// before finishing.
fn kill_at(args: &[&str], kill_at: usize) -> bool {
    let (mut child, reached) = spawn_until(args, kill_at, Stdio::null());
    if reached {
        child.kill().unwrap();
    }
    let status = child.wait().unwrap();
    reached && !status.success()
}

/// A group to kill at, from the clock (the test is the same whichever it is).
fn random_group(lo: usize, hi: usize) -> usize {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .subsec_nanos() as usize;
    lo + nanos % (hi - lo)
}

/// A run resumed with another `[dsp]` table (a playback curve chosen after it started) keeps
/// the journal's groups, which no `[dsp]` key changes, says so, and finishes with the new
/// table: the bytes of a one-process run with it.
#[test]
fn a_run_resumed_with_another_dsp_table_finishes_with_it() {
    let (_keep, scan, _, _) = shared();
    let tmp = tempfile::tempdir().unwrap();
    let eq = tmp.path().join("eq.toml");
    std::fs::write(&eq, "[dsp]\neq = \"riaa\"\nlowpass_hz = 4000.0\n").unwrap();
    let want = tmp.path().join("want.wav");
    let o = common::reconstruct(scan, &want, &["--params", s(&eq)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = tmp.path().join("side.wav");
    let k = random_group(2, GROUPS / 2);
    eprintln!("killing the whole run at group {k}");
    assert!(kill_at(&["reconstruct", s(scan), "--out", s(&out)], k));
    let o = groovescope(&[
        "reconstruct",
        s(scan),
        "--out",
        s(&out),
        "--resume",
        "--params",
        s(&eq),
    ]);
    let e = stderr(&o);
    assert!(o.status.success(), "{e}");
    assert!(
        e.contains("resuming after") && e.contains("another [dsp] table"),
        "{e}"
    );
    assert!(
        std::fs::read(&out).unwrap() == std::fs::read(&want).unwrap(),
        "resumed with another [dsp] table: differs from one process with it"
    );
}

#[test]
fn a_run_killed_at_a_random_group_resumes_to_the_same_bytes() {
    let (_keep, scan, one, _) = shared();
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("side.wav");
    let journal = tmp.path().join("side.wav.journal");
    let k = random_group(2, GROUPS / 2);
    eprintln!("killing the whole run at group {k}");
    assert!(kill_at(&["reconstruct", s(scan), "--out", s(&out)], k));
    assert!(journal.is_file(), "no journal left by the killed run");
    assert!(!out.exists(), "a partial WAV under the output name");
    // Without --resume the journal is not silently discarded.
    let o = groovescope(&["reconstruct", s(scan), "--out", s(&out), "--quiet"]);
    assert!(
        !o.status.success() && stderr(&o).contains("--resume"),
        "{}",
        stderr(&o)
    );
    // A journal from other params is refused, never mixed.
    let params = tmp.path().join("params.toml");
    std::fs::write(&params, "[flow]\nlambda = 0.3\n").unwrap();
    let o = common::reconstruct(scan, &out, &["--resume", "--params", s(&params)]);
    let e = stderr(&o);
    assert!(
        !o.status.success() && e.contains("other params") && e.contains(s(&journal)),
        "{e}"
    );
    // Resume: the same bytes as the uninterrupted run, and the journal is gone.
    let o = groovescope(&["reconstruct", s(scan), "--out", s(&out), "--resume"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("resuming after"), "{}", stderr(&o));
    assert!(std::fs::read(&out).unwrap() == *one, "resumed WAV differs");
    assert!(!journal.exists());

    // A shard killed mid-run resumes too (a Slurm requeue), and merges to the same bytes.
    let p = tmp.path().join("plan.json");
    plan(scan, 2, &p, &[]);
    let part1 = tmp.path().join("part-1");
    let k = random_group(2, GROUPS / 2 - 10);
    eprintln!("killing shard 1 at its group {k}");
    let shard_args = [
        "reconstruct",
        s(scan),
        "--plan",
        s(&p),
        "--shard",
        "1",
        "--out",
        s(&part1),
        "--resume",
    ];
    assert!(kill_at(&shard_args, k));
    assert!(part1.join("journal").is_file() && !part1.join("part.gsp").exists());
    let o = groovescope(&shard_args);
    assert!(o.status.success(), "{}", stderr(&o));
    let part0 = tmp.path().join("part-0");
    run_shard(scan, &p, 0, &part0);
    let merged = tmp.path().join("merged.wav");
    assert!(merge(&[part0, part1], &merged).status.success());
    assert!(
        std::fs::read(&merged).unwrap() == *one,
        "merged WAV after a resumed shard differs"
    );
}

/// The start of every whole frame of a journal (its header first), and where the last ends.
fn journal_frames(bytes: &[u8]) -> (Vec<usize>, usize) {
    let magic = groovescope::side::journal::JOURNAL_MAGIC.len();
    let ends: Vec<usize> = groovescope::side::record::read_frames(bytes, magic)
        .into_iter()
        .map(|(_, end)| end)
        .collect();
    let starts = std::iter::once(magic).chain(ends.iter().copied()).collect();
    (starts, ends.last().copied().unwrap_or(magic))
}

/// A shard's journal with a record damaged in its middle is refused, in one line naming the
/// journal, the record's byte offset and what to do, and left as it was: cutting it short would
/// drop the finished groups after that record without a word. A torn last record (a run
/// stopped while writing it) is dropped with a line saying so. Either way the part merges to
/// the one-process bytes, the damaged journal once cut where the line says.
#[test]
fn a_journal_damaged_in_its_middle_is_refused_and_a_torn_last_record_is_dropped_aloud() {
    let (_keep, scan, one, _) = shared();
    let tmp = tempfile::tempdir().unwrap();
    let p = tmp.path().join("plan.json");
    plan(scan, 2, &p, &[]);
    let shard0 =
        |out: &Path| groovescope(&[&shard_args(scan, &p, "0", out)[..], &["--resume"]].concat());
    let damaged = tmp.path().join("damaged");
    let k = random_group(12, GROUPS / 2 - 10);
    eprintln!("killing shard 0 at its group {k}");
    assert!(kill_at(&shard_args(scan, &p, "0", &damaged), k));
    let journal = damaged.join("journal");
    let original = std::fs::read(&journal).unwrap();
    let (starts, whole_end) = journal_frames(&original);
    assert!(starts.len() > 10, "{} frames", starts.len());

    // The torn case first, in a copy: the last whole record cut 5 bytes short.
    let torn = tmp.path().join("torn");
    std::fs::create_dir(&torn).unwrap();
    std::fs::write(torn.join("journal"), &original[..whole_end - 5]).unwrap();
    let o = shard0(&torn);
    let e = stderr(&o);
    assert!(o.status.success(), "{e}");
    assert!(
        e.contains("the journal's last record") && e.contains("dropped, and its group runs again"),
        "{e}"
    );

    // A byte flipped in a record in the middle: refused, the journal untouched, no part.
    let middle = starts[starts.len() / 2];
    let mut bytes = original.clone();
    bytes[middle + 20] ^= 0x40;
    std::fs::write(&journal, &bytes).unwrap();
    let o = shard0(&damaged);
    let e = stderr(&o);
    assert!(!o.status.success(), "resumed past a damaged record: {e}");
    assert_eq!(e.trim().lines().count(), 1, "{e}");
    assert!(
        e.contains("damaged journal")
            && e.contains(&format!("at byte {middle}"))
            && e.contains(&format!("truncate -s {middle} "))
            && e.contains("delete it to run the shard from its start")
            && e.contains(s(&journal)),
        "{e}"
    );
    assert!(std::fs::read(&journal).unwrap() == bytes, "journal altered");
    assert!(!damaged.join("part.gsp").exists());

    // Cut where the line says, it resumes from the records before the damage.
    std::fs::OpenOptions::new()
        .write(true)
        .open(&journal)
        .unwrap()
        .set_len(middle as u64)
        .unwrap();
    let o = shard0(&damaged);
    assert!(o.status.success(), "{}", stderr(&o));
    let part1 = tmp.path().join("part-1");
    run_shard(scan, &p, 1, &part1);
    for part0 in [damaged, torn] {
        let merged = tmp.path().join("merged.wav");
        let what = format!("{}", part0.display());
        assert_merges_to(&[part0, part1.clone()], &merged, one, &what);
        std::fs::remove_file(&merged).unwrap();
    }
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let dst = to.join(e.file_name());
        if e.file_type().unwrap().is_dir() {
            copy_dir(&e.path(), &dst);
        } else {
            std::fs::copy(e.path(), &dst).unwrap();
        }
    }
}

/// Ctrl-C while a shard runs the groups before its range (for its slope history) says so, and
/// that the same command starts the shard again; it does, and its rate and ETA count from its
/// own first group, not from the start of the groups before it (which made the first ETA tens
/// of times too long).
#[test]
fn a_shard_stopped_before_its_own_groups_says_so_and_its_eta_counts_only_its_own() {
    let (_keep, scan, _, _) = shared();
    let tmp = tempfile::tempdir().unwrap();
    let p = tmp.path().join("plan.json");
    plan(scan, 2, &p, &[]);
    let part = tmp.path().join("part-1");
    let args = [&shard_args(scan, &p, "1", &part)[..], &["--progress-json"]].concat();
    let spawn = || {
        Command::new(env!("CARGO_BIN_EXE_groovescope"))
            .args(&args)
            .env_remove("DISPLAY")
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    let events = |line: std::io::Result<String>| -> serde_json::Value {
        serde_json::from_str(&line.unwrap()).unwrap()
    };
    // Shard 1 runs groups 75..150 after 11..75, for the slope history.
    let mut child = spawn();
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let first = events(lines.next().unwrap());
    assert_eq!(first["event"], "context", "{first}");
    common::ctrl_c(&child);
    let rest: Vec<serde_json::Value> = lines.map(events).collect();
    let o = child.wait_with_output().unwrap();
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(
        rest.iter().all(|v| v["event"] != "group"),
        "stopped too late: {rest:?}"
    );
    assert!(
        e.contains("cancelled while running groups 11..75 before the shard")
            && e.contains("slope history")
            && e.contains("the same command starts the shard again"),
        "{e}"
    );
    assert!(!part.exists(), "{:?}", common::names(tmp.path()));

    let mut child = spawn();
    let lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let groups: Vec<serde_json::Value> = lines
        .map(events)
        .filter(|v| v["event"] == "group")
        .collect();
    assert!(child.wait().unwrap().success());
    assert_eq!(groups.len(), GROUPS - GROUPS / 2);
    // The first group's rate over its own time: the 64 groups before it took far longer.
    let g = &groups[0];
    let own_secs = 1.0 / g["groups_per_sec"].as_f64().unwrap();
    let elapsed = g["elapsed_secs"].as_f64().unwrap();
    assert!(own_secs * 4.0 < elapsed, "{g}");
    let eta = g["eta_secs"].as_f64().unwrap();
    assert!(
        (eta - own_secs * (groups.len() - 1) as f64).abs() < 1e-6 * eta,
        "{g}"
    );
}

#[test]
fn ctrl_c_stops_at_the_next_group_keeps_the_journal_and_says_so() {
    let (_keep, scan, one, _) = shared();
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("side.wav");
    let args = ["reconstruct", s(scan), "--out", s(&out)];
    let (child, reached) = spawn_until(&args, 5, Stdio::piped());
    assert!(reached);
    common::ctrl_c(&child);
    let o = child.wait_with_output().unwrap();
    let err = stderr(&o);
    // An exit of its own (status 1), not death by the signal.
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("cancelled")
            && err.contains("finished groups are kept in")
            && err.contains("--resume"),
        "{err}"
    );
    assert_eq!(
        common::names(tmp.path()),
        ["side.wav.journal"],
        "no WAV, no lock file"
    );
    let o = common::reconstruct(scan, &out, &["--resume"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(std::fs::read(&out).unwrap() == *one, "resumed WAV differs");
}

#[test]
fn ctrl_c_stops_plan_inspect_and_merge_and_they_write_nothing() {
    let (_keep, scan, _, _) = shared();
    let tmp = tempfile::tempdir().unwrap();
    // plan: Ctrl-C before its probe (13 groups) runs, or with no probe; inspect: before its
    // first stage.
    let (plan_out, inspect_out) = (tmp.path().join("plan.json"), tmp.path().join("inspect"));
    let plan_args = |probe| {
        [
            "--shards",
            "2",
            "--probe-groups",
            probe,
            "--out",
            s(&plan_out),
        ]
    };
    let cases: [(&str, &[&str]); 3] = [
        ("plan", &plan_args("13")),
        ("plan", &plan_args("0")),
        ("inspect", &["--group", "3", "--out", s(&inspect_out)]),
    ];
    for (k, (command, extra)) in cases.into_iter().enumerate() {
        let pipe = tmp.path().join(format!("{k}.toml"));
        let mut args = vec![command, s(scan), "--params", s(&pipe)];
        args.extend_from_slice(extra);
        let o = common::ctrl_c_while_reading(&args, &pipe, b"");
        common::failed_with(&o, &[&format!("{command}: cancelled; nothing written")]);
        assert_eq!(
            o.status.code(),
            Some(1),
            "an exit of its own, not the signal's"
        );
    }
    assert_eq!(
        common::names(tmp.path()),
        ["0.toml", "1.toml", "2.toml"],
        "only the pipes: no plan, no inspect folder"
    );
    // merge stops between parts once Ctrl-C has raised its flag.
    let p = tmp.path().join("whole.json");
    plan(scan, 1, &p, &[]);
    let part = tmp.path().join("part-0");
    run_shard(scan, &p, 0, &part);
    let raised = std::sync::atomic::AtomicBool::new(true);
    let err = groovescope::side::merge::merge_parts(&[part], &raised).unwrap_err();
    assert!(err.to_string().contains("cancelled"), "{err}");
}

#[test]
fn a_side_long_transfer_is_scored_in_bounded_memory() {
    // Three minutes at 44.1 kHz, scored against a copy with noise 13.1 dB down (the score
    // reads 10·log10(1 + S/N) = 13.3 dB), under a 600 MB address-space limit: the whole-signal
    // FFT the lag search used before held six buffers of 2^24 points (1.7 GB resident); by
    // blocks it needs about 100 MB, and the lag's refinement to a fraction of a sample one
    // buffer of the reference read at the fraction (4 bytes a sample, 32 MB).
    let dir = tempfile::tempdir().unwrap();
    let n = 180 * 44_100;
    let mut rng = common::Rng(0x5eed);
    let mut noise = || (rng.next() >> 11) as f32 / (1u64 << 53) as f32 - 0.5;
    let (mut reference, mut recovered) = (Vec::with_capacity(n), Vec::with_capacity(n));
    for i in 0..n {
        let v = 0.3 * (i as f32 * 0.0713).sin() * (1.0 + (i as f32 * 1e-4).sin());
        reference.push(v);
        recovered.push(v + 0.2 * noise());
    }
    let (ref_path, rec_path) = (dir.path().join("ref.wav"), dir.path().join("rec.wav"));
    common::write_raw_wav(&ref_path, 44_100, &reference);
    common::write_raw_wav(&rec_path, 44_100, &recovered);
    let out = Command::new("bash")
        .args(["-c", "ulimit -v 600000 && exec \"$0\" \"$@\""])
        .arg(env!("CARGO_BIN_EXE_groovescope"))
        .args(["eval", s(&rec_path), s(&ref_path), "--json"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json["samples"].as_u64(), Some(n as u64), "{json}");
    assert_eq!(json["lag_samples"].as_i64(), Some(0), "{json}");
    let fraction = json["lag_refined_samples"].as_f64().unwrap();
    assert!(fraction.abs() < 0.05, "{json}");
    let snr = json["snr_db"].as_f64().unwrap();
    assert!((snr - 13.3).abs() < 0.2, "{json}");
}
