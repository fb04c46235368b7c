//! Determinism: the same scan, group and params give bit-identical stage outputs and clip in the
//! workbench whatever the order in which stages were rerun, cancelled or superseded, whether a
//! clip reconstruction raced the stage worker, and however many threads the stages run on.

#![cfg(feature = "gui")]
#![allow(clippy::unwrap_used)] // tests may panic

mod gui_common;

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use groovescope::app::Workbench;
use groovescope::engine::{ReconstructOptions, reconstruct};
use groovescope::io::{Scan, load_group};
use groovescope::pipeline::{GroupInput, Method, PipelineParams, Stage, StageCache};
use groovescope::playback::DeviceChoice;
use gui_common::*;

/// Every stage output of a cache, as text: `{:?}` prints each float so that it reads back to
/// the same bits, so equal texts mean bit-identical outputs (NaN gaps included).
fn stage_outputs(c: &StageCache) -> Vec<(Stage, String)> {
    Stage::ALL
        .into_iter()
        .map(|s| {
            let text = match s {
                Stage::Derivatives => format!("{:?}", c.derivatives()),
                Stage::Flow => format!("{:?}", c.flows()),
                Stage::Depth => format!("{:?}", c.depth()),
                Stage::Stripes => format!("{:?}", c.stripes()),
                Stage::Orientation => format!("{:?}", c.orientation()),
                Stage::Sound => format!("{:?}", c.signal()),
                Stage::Edges => format!("{:?}", c.edges()),
            };
            (s, text)
        })
        .collect()
}

/// The workbench's stage outputs for its current group, checked to be complete and fresh.
fn workbench_outputs(wb: &Workbench) -> Vec<(Stage, String)> {
    for s in Stage::ALL {
        assert!(
            wb.cache().is_fresh(s, wb.params()),
            "{} is not fresh after settling",
            s.name()
        );
    }
    assert!(wb.cache().signal().is_some(), "the group has sound");
    stage_outputs(wb.cache())
}

/// The clip's audio and stitched signal, bit for bit.
fn clip_bits(wb: &Workbench) -> String {
    let Some(clip) = wb.clip() else {
        panic!("no clip: {:?}", wb.messages().last());
    };
    format!(
        "{:?} {:?} {:?}",
        clip.recon.audio.channels, clip.recon.stitched.channels, clip.recon.stitched.gaps
    )
}

fn assert_same(what: &str, a: &[(Stage, String)], b: &[(Stage, String)]) {
    for ((s, x), (_, y)) in a.iter().zip(b) {
        assert!(x == y, "{what}: {} differs", s.name());
    }
}

/// Applies `p` in the workbench and, once it settles, compares its group with a fresh run of
/// group 0 of `scan` with `p` (on 2 threads).
fn set_and_compare(h: &mut H, scan: &Path, p: &PipelineParams, what: &str) {
    wb_mut(h).set_params(p.clone());
    settle(h);
    assert_same(what, &cache_with(scan, 2, p), &workbench_outputs(wb(h)));
}

/// Group 0 run straight through a fresh cache on a rayon pool of `threads` threads.
fn cache_on_threads(scan: &Path, threads: usize) -> Vec<(Stage, String)> {
    cache_with(scan, threads, &PipelineParams::default())
}

/// Group 0 with `params` run straight through a fresh cache on `threads` threads.
fn cache_with(scan: &Path, threads: usize, params: &PipelineParams) -> Vec<(Stage, String)> {
    let scan = Scan::open(scan).unwrap();
    let input = GroupInput {
        group: 0,
        frames: Arc::new(load_group(&scan.groups[0]).unwrap()),
        first_frame: 0,
        meta: Arc::new(scan.meta.clone()),
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        let mut c = StageCache::default();
        c.run_from(Stage::Derivatives, &input, params, &mut |_, _| true)
            .unwrap();
        stage_outputs(&c)
    })
}

/// The engine's clip on a rayon pool of `threads` threads.
fn engine_on_threads(scan: &Path, threads: usize) -> String {
    engine_with(scan, threads, &PipelineParams::default())
}

/// The engine's clip with `params` on a rayon pool of `threads` threads.
fn engine_with(scan: &Path, threads: usize, params: &PipelineParams) -> String {
    let scan = Scan::open(scan).unwrap();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    let rec = pool.install(|| {
        reconstruct(
            &scan,
            &ReconstructOptions {
                params: params.clone(),
                ..ReconstructOptions::default()
            },
            &mut |_| {},
            &AtomicBool::new(false),
        )
        .unwrap()
    });
    format!(
        "{:?} {:?} {:?}",
        rec.audio.channels, rec.stitched.channels, rec.stitched.gaps
    )
}

/// The stage outputs and the clip of one scan, reached in three orders through the
/// workbench's stage worker, against a plain run and the engine on 1 and 2 threads.
fn check_scan(scan: &Path) {
    let tmp = tempfile::tempdir().unwrap();
    let open = || {
        harness(options(
            tmp.path(),
            Some(scan.to_path_buf()),
            DeviceChoice::Off,
        ))
    };

    // Straight: open, settle, reconstruct the clip.
    let mut h = open();
    settle(&mut h);
    let straight = workbench_outputs(wb(&h));
    wb_mut(&mut h).reconstruct(None);
    settle(&mut h);
    let straight_clip = clip_bits(wb(&h));

    // A plain cache run, and the same on 1 and 2 threads.
    assert_same("a plain run", &straight, &cache_on_threads(scan, 2));
    assert_same("one thread", &straight, &cache_on_threads(scan, 1));

    // Cancelled and superseded reruns in between: a rerun from the start, a λ change, a Hough
    // change and their undos, each while the previous job is still running.
    let mut h = open();
    settle(&mut h);
    let params = wb(&h).params().clone();
    wb_mut(&mut h).rerun(Stage::Derivatives);
    h.step();
    let mut p = params.clone();
    p.flow.lambda *= 4.0;
    wb_mut(&mut h).set_params(p.clone());
    h.step();
    p.hough.theta_min_deg += 5.0;
    p.orientation.max_wall_slope_change *= 0.5;
    wb_mut(&mut h).set_params(p);
    h.step();
    wb_mut(&mut h).undo();
    h.step();
    wb_mut(&mut h).undo();
    assert_eq!(wb(&h).params(), &params);
    settle(&mut h);
    assert_same(
        "after cancelled reruns",
        &straight,
        &workbench_outputs(wb(&h)),
    );

    // A knob of a later table that an earlier stage reads (the output rate places the
    // orientation stage's sample columns): changed in the workbench, the group must equal a
    // fresh run with the new params.
    let mut p = params.clone();
    p.sound.output_rate_hz = 48_000;
    set_and_compare(&mut h, scan, &p, "after an output-rate change");

    // An edge-stage knob: the edge stage alone reruns, and equals a fresh run.
    p.edges.column_sigma_px *= 2.0;
    set_and_compare(&mut h, scan, &p, "after an edge-knob change");

    // A clip reconstruction racing the stage worker: started as soon as the scan is open,
    // while the group's first run is still going, with a rerun from the start while it runs.
    let mut h = open();
    while wb(&h).scan().is_none() {
        h.step();
    }
    wb_mut(&mut h).reconstruct(None);
    h.step();
    wb_mut(&mut h).rerun(Stage::Derivatives);
    settle(&mut h);
    assert_same("with a racing clip", &straight, &workbench_outputs(wb(&h)));
    assert!(
        clip_bits(wb(&h)) == straight_clip,
        "the racing clip differs"
    );

    // The engine alone, on 1 and 2 threads.
    assert!(
        engine_on_threads(scan, 1) == straight_clip,
        "the engine's clip on one thread differs"
    );
    assert!(
        engine_on_threads(scan, 2) == straight_clip,
        "the engine's clip on two threads differs"
    );
    // Every method, on 1 and 2 threads.
    for method in [Method::Flow, Method::Edges, Method::Fused] {
        let p = PipelineParams {
            method,
            ..params.clone()
        };
        assert!(
            engine_with(scan, 1, &p) == engine_with(scan, 2, &p),
            "the {} clip differs between one and two threads",
            method.name()
        );
    }
}

#[test]
fn the_depth_path_gives_the_same_bits_in_any_order() {
    check_scan(&lateral_scan());
}

#[test]
fn the_dual_focus_path_gives_the_same_bits_in_any_order() {
    check_scan(&demo_scan());
}
