//! Replays the fuzz corpus (seeds and every crash found, fixed) through the fuzz targets, plus a short seeded mutation run of each.

#![allow(clippy::unwrap_used)] // tests may panic

use std::path::Path;

mod common;

use common::Rng;

#[path = "../fuzz/src/targets.rs"]
mod targets;

/// Mutations tried per seed in `cargo test` (the long runs are `scripts/fuzz.sh`).
const MUTATIONS_PER_SEED: usize = 200;

/// The corpus files of one target, sorted.
fn corpus(name: &str) -> Vec<(String, Vec<u8>)> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fuzz/corpus")
        .join(name);
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    files
        .into_iter()
        .map(|p| {
            (
                p.file_name().unwrap().to_string_lossy().into_owned(),
                std::fs::read(&p).unwrap(),
            )
        })
        .collect()
}

/// One libFuzzer-style mutation: flip a bit, set a byte to an edge value, cut, insert, or
/// copy a run of bytes elsewhere.
fn mutate(rng: &mut Rng, data: &mut Vec<u8>) {
    if data.is_empty() {
        data.push(rng.next() as u8);
        return;
    }
    let at = rng.below(data.len());
    match rng.below(5) {
        0 => data[at] ^= 1 << rng.below(8),
        1 => data[at] = [0, 0x7f, 0x80, 0xff][rng.below(4)],
        2 => data.truncate(at),
        3 => data.insert(at, rng.next() as u8),
        _ => {
            let from = rng.below(data.len());
            let len = rng.below(16).min(data.len() - from.max(at));
            data.copy_within(from..from + len, at);
        }
    }
}

#[test]
fn every_target_has_seeds_and_runs_them_and_their_mutations_without_a_panic() {
    for target in targets::TARGETS {
        let seeds = corpus(target.name);
        assert!(!seeds.is_empty(), "no seeds for {}", target.name);
        let mut rng = Rng(0x9E37_79B9_7F4A_7C15 ^ target.name.len() as u64);
        for (name, seed) in &seeds {
            let replay = std::panic::catch_unwind(|| (target.run)(seed));
            assert!(replay.is_ok(), "{}/{name} panics", target.name);
            let mut data = seed.clone();
            for k in 0..MUTATIONS_PER_SEED {
                if k % 16 == 0 {
                    data.clone_from(seed);
                }
                mutate(&mut rng, &mut data);
                let input = data.clone();
                let outcome = std::panic::catch_unwind(|| (target.run)(&input));
                assert!(
                    outcome.is_ok(),
                    "{}: mutation {k} of {name} panics; input: {input:?}",
                    target.name
                );
            }
        }
    }
}

#[test]
fn the_targets_find_what_they_check() {
    // The frame target's own checks hold on every seed, and a seed that decodes is a frame.
    let frame = targets::target("frame").unwrap();
    for (name, bytes) in corpus("frame") {
        (frame.run)(&bytes);
        let decoded = groovescope::io::frames::decode_frame(&bytes, Path::new(&name));
        assert_eq!(decoded.is_ok(), !name.starts_with("huge"), "{name}");
    }
    // A .flo seed round-trips; one byte less does not read.
    let (_, flo) = &corpus("flo")[0];
    assert!(groovescope::io::flo::decode_flo(&flo[..flo.len() - 1], Path::new("f")).is_err());
}
