//! Workbench tests with no scan open (review item 2): the stage list says the stages have no
//! scan to run on, and the actions that need one (rerun, reconstruct) are disabled with a hover
//! text saying why.

use egui_kittest::kittest::{NodeT, Queryable};
use groovescope::app::View;
use groovescope::pipeline::Stage;
use groovescope::playback::DeviceChoice;

use super::gui_common::*;

#[test]
fn with_no_scan_the_stages_say_so_and_nothing_can_be_rerun_or_reconstructed() {
    let tmp = tempfile::tempdir().unwrap();
    let mut h = harness(options(tmp.path(), None, DeviceChoice::Off));
    settle(&mut h);
    assert!(wb(&h).scan().is_none());
    for s in Stage::ALL {
        assert_eq!(wb(&h).stage_status(s).word(), "no scan", "{s:?}");
    }
    let reruns: Vec<bool> = h
        .query_all_by_label("rerun")
        .map(|n| n.accesskit_node().is_disabled())
        .collect();
    assert_eq!(reruns, vec![true; Stage::ALL.len()], "rerun buttons");
    h.query_all_by_label("rerun").next().unwrap().hover();
    h.run_ok();
    assert!(
        h.query_by_label_contains("no scan open: nothing to rerun")
            .is_some()
    );
    wb_mut(&mut h).set_view(View::Waveform);
    h.run_ok();
    for label in ["Reconstruct clip", "Reconstruct around group 0"] {
        let node = h.get_by_label(label);
        assert!(node.accesskit_node().is_disabled(), "{label}");
        node.hover();
        h.run_ok();
        assert!(
            h.query_by_label_contains("no scan open: nothing to reconstruct")
                .is_some(),
            "{label}: hover text"
        );
    }
    h.get_by_label("Reconstruct around group 0").click();
    h.run_ok();
    assert!(!wb(&h).is_reconstructing());
}
