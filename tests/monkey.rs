//! Monkey test of the workbench: seeded random clicks, drags, keys, extreme knob values, view switches, undo/redo, reconstruct, cancel and export over an existing file.
//!
//! Every event must be answered within [`EVENT_BOUND`] (one UI frame), nothing may panic, the
//! workbench must settle after each sequence, and no stage may be shown fresh while its inputs
//! changed (a fresh stage belongs to the shown group, and every stage it reads is fresh too).
//! `cargo test --test monkey` runs a short version; `scripts/monkey.sh` runs 200 sequences of
//! 300 events (`GROOVESCOPE_MONKEY=SEQUENCESxEVENTS`, `GROOVESCOPE_MONKEY_SEED=N` to replay one).

#![cfg(feature = "gui")]
#![allow(clippy::unwrap_used)] // tests may panic

mod gui_common;

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use egui::accesskit::Role;
use egui::{Key, Modifiers, PointerButton, Pos2};
use egui_kittest::kittest::{NodeT, Queryable};
use groovescope::app::{View, WorkbenchOptions};
use groovescope::pipeline::Stage;
use groovescope::playback::DeviceChoice;
use gui_common::common::Rng;
use gui_common::{H, SIZE, harness, wb, wb_mut};

/// Longest one UI frame may take to answer an event.
const EVENT_BOUND: Duration = Duration::from_secs(5);
/// Longest the workbench may take to finish its work after a sequence.
const SETTLE_BOUND: Duration = Duration::from_secs(300);
/// Sequences × events in `cargo test`.
const SHORT_RUN: (usize, usize) = (3, 60);
/// Knob values a careless or hostile operator might enter.
const EXTREMES: [f64; 8] = [0.0, -1.0, -1e9, 1e30, f64::NAN, f64::INFINITY, 1e-30, 7.0];
/// Text typed into a focused field.
const TYPED: [&str; 6] = ["NaN", "-0", "1e999", "", "abc", "99999999999999999999"];

/// A random point in the window.
fn random_pos(rng: &mut Rng) -> Pos2 {
    Pos2::new(
        rng.below(SIZE[0] as usize) as f32,
        rng.below(SIZE[1] as usize) as f32,
    )
}

/// Does `act` on the `pick`-th widget of `role` (counting round), if there is one; returns
/// its label, or None where `act` passed it over (returned false).
fn act_on(
    h: &H,
    role: Role,
    pick: usize,
    act: impl FnOnce(&egui_kittest::Node<'_>, &str) -> bool,
) -> Option<String> {
    let nodes: Vec<_> = h.query_all_by_role(role).collect();
    let node = nodes.get(pick % nodes.len().max(1))?;
    let label = node.accesskit_node().label().unwrap_or_default();
    act(node, &label).then_some(label)
}

/// Clicks the `pick`-th widget of `role`, if there is one; returns its label.
fn click_role(h: &H, role: Role, pick: usize) -> Option<String> {
    act_on(h, role, pick, |node, label| {
        // Leaving the app or opening a system file dialog is not the monkey's business.
        if label.contains("Quit") || label.ends_with('…') {
            return false;
        }
        node.click();
        true
    })
}

/// Does `act` on the `pick`-th spin button (a knob), if one is shown; returns its label.
fn on_knob(h: &H, pick: usize, act: impl FnOnce(&egui_kittest::Node<'_>)) -> Option<String> {
    act_on(h, Role::SpinButton, pick, |node, _| {
        act(node);
        true
    })
}

/// One random event; returns what it was, for the failure report.
fn event(h: &mut H, rng: &mut Rng, existing: &Path) -> String {
    match rng.below(16) {
        0 | 1 => {
            let (role, name) =
                [(Role::Button, "button"), (Role::CheckBox, "checkbox")][rng.below(2)];
            let pick = rng.below(64);
            match click_role(h, role, pick) {
                Some(label) => format!("click {name} {label:?}"),
                None => format!("click {name} #{pick}: none"),
            }
        }
        2 => {
            let pos = random_pos(rng);
            let button = [PointerButton::Primary, PointerButton::Secondary][rng.below(2)];
            for pressed in [true, false] {
                h.event(egui::Event::PointerButton {
                    pos,
                    button,
                    pressed,
                    modifiers: Modifiers::NONE,
                });
            }
            format!("{button:?} click at {pos:?}")
        }
        3 => {
            let (from, to) = (random_pos(rng), random_pos(rng));
            h.drag_at(from);
            h.event(egui::Event::PointerMoved(to));
            h.drop_at(to);
            format!("drag {from:?} -> {to:?}")
        }
        4 | 5 => {
            let value = EXTREMES[rng.below(EXTREMES.len())];
            let pick = rng.below(64);
            match on_knob(h, pick, |node| node.set_value_accesskit(value)) {
                Some(label) => format!("set {label:?} to {value}"),
                None => "set a knob: none shown".into(),
            }
        }
        6 => {
            let text = TYPED[rng.below(TYPED.len())];
            let pick = rng.below(64);
            match on_knob(h, pick, |node| node.click()) {
                Some(label) => {
                    h.step();
                    h.event(egui::Event::Text(text.into()));
                    h.key_press(Key::Enter);
                    format!("type {text:?} into {label:?}")
                }
                None => "type into a knob: none shown".into(),
            }
        }
        7 => {
            let key = [
                Key::Space,
                Key::PageUp,
                Key::PageDown,
                Key::Escape,
                Key::Tab,
                Key::Enter,
            ][rng.below(6)];
            h.key_press(key);
            format!("key {key:?}")
        }
        8 => {
            let redo = rng.below(2) == 0;
            if redo {
                h.key_press_modifiers(Modifiers::COMMAND | Modifiers::SHIFT, Key::Z);
            } else {
                h.key_press_modifiers(Modifiers::COMMAND, Key::Z);
            }
            format!("key {}", if redo { "redo" } else { "undo" })
        }
        9 => {
            let v = View::ALL[rng.below(View::ALL.len())];
            wb_mut(h).set_view(v);
            format!("view {v:?}")
        }
        10 => {
            if rng.below(2) == 0 {
                wb_mut(h).undo();
                "undo".into()
            } else {
                wb_mut(h).redo();
                "redo".into()
            }
        }
        11 => {
            let groups = wb(h).scan().map_or(1, |s| s.groups.len());
            let g = rng.below(groups + 2);
            wb_mut(h).set_group(g);
            let f = rng.below(20);
            wb_mut(h).set_frame(f);
            format!("group {g}, frame {f}")
        }
        12 => {
            wb_mut(h).reconstruct(None);
            "reconstruct".into()
        }
        13 => {
            wb_mut(h).cancel_reconstruction();
            "cancel reconstruction".into()
        }
        14 => {
            wb_mut(h).request_export_wav(existing.to_path_buf(), rng.below(2) == 0);
            h.step();
            let answer = ["Replace", "Cancel"][rng.below(2)];
            // The confirmation's button is the last of that name (the clip panel may have one).
            match h.query_all_by_label(answer).last() {
                Some(node) => {
                    node.click();
                    format!("export over the existing file, then {answer}")
                }
                None => "export over the existing file (no confirmation shown)".into(),
            }
        }
        _ => {
            let stage = Stage::ALL[rng.below(Stage::ALL.len())];
            wb_mut(h).rerun(stage);
            format!("rerun {stage:?}")
        }
    }
}

/// No stage shown fresh whose inputs changed: a fresh stage belongs to the shown group, and it
/// and every stage before it that the path uses hold output of the current knobs.
fn check_consistent(h: &H) -> Result<(), String> {
    let w = wb(h);
    let statuses = w.statuses();
    let cache = w.cache();
    let dual = w
        .scan()
        .is_some_and(|s| w.params().uses_dual_focus(&s.meta));
    let unused = if dual { Stage::Depth } else { Stage::Stripes };
    for stage in Stage::ALL {
        if statuses[stage.index()].word() != "fresh" {
            continue;
        }
        if cache.group() != Some(w.group()) {
            return Err(format!(
                "{stage:?} shown fresh for group {} but the cache holds group {:?}",
                w.group(),
                cache.group()
            ));
        }
        // What it was made from: it and every stage it reads (transitively, by the stage
        // graph) that the path uses still hold output made with the current knobs (a
        // superseded job's newer output would make it stale).
        let mut inputs = vec![stage];
        let mut i = 0;
        while let Some(&s) = inputs.get(i) {
            for r in s.spec().reads {
                if !inputs.contains(r) {
                    inputs.push(*r);
                }
            }
            i += 1;
        }
        for input in &inputs {
            let word = statuses[input.index()].word();
            if *input != unused && !cache.is_fresh(*input, w.params()) {
                return Err(format!(
                    "{stage:?} shown fresh while {input:?} ({word}) holds output of other knobs"
                ));
            }
        }
    }
    Ok(())
}

/// Steps until the worker and any reconstruction are done.
fn settle(h: &mut H) -> Result<(), String> {
    let t0 = Instant::now();
    while !wb(h).is_idle() || wb(h).is_reconstructing() {
        h.step();
        if t0.elapsed() > SETTLE_BOUND {
            return Err(format!("did not settle within {SETTLE_BOUND:?}"));
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    h.step();
    Ok(())
}

/// Figures of one monkey run.
#[derive(Default)]
struct Figures {
    events: usize,
    slowest_event: Duration,
    slowest_settle: Duration,
    /// Events after which the params differed.
    param_changes: usize,
    /// Messages the workbench showed (errors for refused values among them).
    messages: usize,
    /// Whole-clip reconstructions that finished.
    clips: usize,
}

fn sequence(seed: u64, events: usize, scan: &Path, figures: &mut Figures) -> Result<(), String> {
    let tmp = tempfile::tempdir().unwrap();
    let existing = tmp.path().join("existing.wav");
    std::fs::write(&existing, b"the operator's earlier export").unwrap();
    let opts = WorkbenchOptions {
        scan: Some(scan.to_path_buf()),
        config_dir: Some(tmp.path().join("config")),
        audio: DeviceChoice::Default,
        ..WorkbenchOptions::default()
    };
    let mut h = harness(opts);
    let mut rng = Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1);
    let mut log = Vec::new();
    for k in 0..events {
        let before = wb(&h).params().clone();
        let what = event(&mut h, &mut rng, &existing);
        let t = Instant::now();
        h.step();
        let took = t.elapsed();
        figures.param_changes += usize::from(*wb(&h).params() != before);
        figures.slowest_event = figures.slowest_event.max(took);
        figures.events += 1;
        log.push(what);
        let fail = |why: String| {
            let tail = log.iter().rev().take(8).rev().cloned().collect::<Vec<_>>();
            format!("seed {seed}, event {k}: {why}; last events: {tail:?}")
        };
        if took > EVENT_BOUND {
            return Err(fail(format!("the frame took {took:?}")));
        }
        check_consistent(&h).map_err(fail)?;
        if k % 50 == 49 {
            let t = Instant::now();
            settle(&mut h).map_err(fail)?;
            figures.slowest_settle = figures.slowest_settle.max(t.elapsed());
            check_consistent(&h).map_err(fail)?;
        }
    }
    let t = Instant::now();
    settle(&mut h).map_err(|e| format!("seed {seed}: {e}"))?;
    figures.slowest_settle = figures.slowest_settle.max(t.elapsed());
    check_consistent(&h).map_err(|e| format!("seed {seed}, settled: {e}"))?;
    let messages = wb(&h).messages();
    figures.messages += messages.len();
    figures.clips += messages
        .iter()
        .filter(|m| m.text.starts_with("clip ready"))
        .count();
    // The file the monkey exported over is either the operator's or a whole WAV.
    let bytes = std::fs::read(&existing).unwrap();
    assert!(
        bytes == b"the operator's earlier export"
            || groovescope::io::wav::read_wav(&existing).is_ok(),
        "seed {seed}: the existing file is torn"
    );
    Ok(())
}

/// A copy of the demo scan (the monkey saves metadata, presets and exports beside it).
fn scan() -> PathBuf {
    gui_common::demo_scan()
}

#[test]
fn random_operator_sequences_never_panic_hang_or_show_stale_stages_as_fresh() {
    let (sequences, events) = std::env::var("GROOVESCOPE_MONKEY")
        .ok()
        .and_then(|v| {
            let (a, b) = v.split_once('x')?;
            Some((a.parse().ok()?, b.parse().ok()?))
        })
        .unwrap_or(SHORT_RUN);
    // One seed, or a range "A-B" to replay the sequences before a failure in one process.
    let seeds: Vec<u64> = match std::env::var("GROOVESCOPE_MONKEY_SEED") {
        Ok(s) => match s.split_once('-') {
            Some((a, b)) => (a.parse().unwrap()..=b.parse().unwrap()).collect(),
            None => vec![s.parse().unwrap()],
        },
        Err(_) => (1..=sequences as u64).collect(),
    };
    let started = Instant::now();
    let mut figures = Figures::default();
    for seed in &seeds {
        let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            sequence(*seed, events, &scan(), &mut figures)
        }));
        match outcome {
            Ok(Ok(())) if seeds.len() > SHORT_RUN.0 && seed % 20 == 0 => {
                eprintln!("monkey: {seed} of {} sequences done", seeds.len());
            }
            Ok(Ok(())) => {}
            Ok(Err(e)) => panic!("{e}"),
            Err(_) => panic!("seed {seed} panicked (replay: GROOVESCOPE_MONKEY_SEED={seed})"),
        }
    }
    println!(
        "monkey: {} sequences, {} events ({} changed the params, {} clips reconstructed, {} messages shown) in {:.0} s; slowest event {:.0} ms, slowest settle {:.2} s; no panic, no hang, no stale stage shown fresh",
        seeds.len(),
        figures.events,
        figures.param_changes,
        figures.clips,
        figures.messages,
        started.elapsed().as_secs_f64(),
        figures.slowest_event.as_secs_f64() * 1000.0,
        figures.slowest_settle.as_secs_f64()
    );
}
