//! Workbench tests of "Compare methods" (A/B of decoders, issue 17 item 4): the comparison runs
//! off the UI thread, shows both clips, its agreement figures hold against what is known (a
//! method against itself agrees perfectly; two methods on a clean scan agree closely), it
//! cancels, and the listen buttons switch the player's source.

use egui_kittest::kittest::Queryable;
use groovescope::app::compare::MAX_AGREEMENT_DB;
use groovescope::pipeline::Method;

use super::gui_common::*;

/// Lowest r between fused and flow over the whole clean demo scan, flow's delay taken out
/// (measured 0.944, SNR 9.6 dB; 0.892 and 6.7 dB with the delay left in): the two decoders
/// differ in their noise, not in the sound they recover.
const CLEAN_MIN_R: f64 = 0.92;
/// Lowest r of any one group there (measured 0.75 to 0.99, 0.60 with the delay left in: a
/// group is about 100 samples).
const CLEAN_GROUP_MIN_R: f64 = 0.65;
/// Flow's delay against fused on the demo scan, in samples at 44.1 kHz (measured 3.02).
const FLOW_DELAY_SAMPLES: std::ops::RangeInclusive<f64> = 1.5..=4.5;

#[test]
fn a_method_compared_with_itself_agrees_perfectly() {
    let (_tmp, mut h) = settled_on(&lateral_scan());
    wb_mut(&mut h).compare_methods([Method::Flow, Method::Flow]);
    assert!(wb(&h).is_comparing());
    assert!(wb(&h).compare_open());
    settle(&mut h);
    let cmp = wb(&h).comparison().expect("a comparison");
    assert_eq!(cmp.methods, [Method::Flow, Method::Flow]);
    assert_eq!(cmp.groups.len(), 3, "one agreement per group");
    assert!(!cmp.a.recovered.samples.is_empty());
    assert_eq!(cmp.b_on_a.len(), cmp.a.recovered.samples.len());
    for g in cmp.groups.iter().chain([&cmp.overall]) {
        assert!((g.r - 1.0).abs() < 1e-9, "group {}: r {}", g.group, g.r);
        assert_eq!(g.snr_db, MAX_AGREEMENT_DB, "group {}", g.group);
        assert!(g.samples > 0);
    }
    assert!(cmp.difference.iter().all(|d| *d == 0.0));
    assert_eq!(cmp.b_delay_samples, 0.0, "nothing to align");
    assert_last_message(&h, "r 1.000");
}

#[test]
fn fused_and_flow_on_the_clean_demo_agree_and_the_listen_buttons_switch() {
    // The demo scan: a clean recording (no damage, σ 0.5 grey levels) of 13 groups.
    let scan = demo_scan();
    let (_tmp, mut h) = settled_on(&scan);
    let groups = wb(&h).scan().unwrap().groups.len();
    // File ▸ Compare methods…, then the window's own button (A is the method in force).
    h.get_by_label("File").click();
    h.run_ok();
    h.get_by_label("Compare methods…").click();
    h.run_ok();
    assert!(wb(&h).compare_open());
    h.get_by_label("Run comparison").click();
    h.step();
    assert!(wb(&h).is_comparing(), "it runs in the background");
    settle(&mut h);
    let cmp = wb(&h).comparison().expect("a comparison");
    assert_eq!(cmp.methods, [Method::Fused, Method::Flow]);
    assert_eq!(cmp.groups.len(), groups);
    assert!(cmp.overall.r > CLEAN_MIN_R, "{:?}", cmp.overall);
    assert!(
        FLOW_DELAY_SAMPLES.contains(&cmp.b_delay_samples),
        "flow's delay {}",
        cmp.b_delay_samples
    );
    h.get_by_label_contains("B aligned: it was 3.0");
    for g in cmp.groups.iter().chain([&cmp.overall]) {
        assert!(g.r.is_finite() && g.snr_db.is_finite(), "{g:?}");
        assert!(g.r > CLEAN_GROUP_MIN_R, "group {}: r {}", g.group, g.r);
        assert!(g.snr_db > 0.0 && g.snr_db < MAX_AGREEMENT_DB, "{g:?}");
    }
    // Two different decoders: not the same sound.
    assert!(cmp.difference.iter().any(|d| *d != 0.0));
    h.get_by_label_contains("whole clip: r ");
    // Listening: no sound device here, so a message; the source still switches.
    h.get_by_label("Listen B: flow").click();
    h.run_ok();
    let buffers = wb(&h).player().buffers().unwrap();
    assert_eq!(buffers.sources.len(), 2, "A and B");
    assert_eq!(buffers.sources[1][0].len(), buffers.sources[0][0].len());
    assert_eq!(wb(&h).player().source(), 1);
    assert_last_message(&h, "audio unavailable");
    h.get_by_label("Listen A: fused").click();
    h.run_ok();
    assert_eq!(wb(&h).player().source(), 0);
    // The next clip takes the player back.
    wb_mut(&mut h).reconstruct(None);
    settle(&mut h);
    assert_eq!(wb(&h).player().buffers().unwrap().sources.len(), 3);
}

#[test]
fn a_comparison_cancels() {
    let (_tmp, mut h) = settled_on(&lateral_scan());
    wb_mut(&mut h).compare_methods([Method::Fused, Method::Edges]);
    wb_mut(&mut h).cancel_comparison();
    settle(&mut h);
    assert!(!wb(&h).is_comparing());
    assert!(wb(&h).comparison().is_none());
    assert_eq!(last_message(&h), "method comparison cancelled");
}
