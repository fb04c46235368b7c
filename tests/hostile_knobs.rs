//! Every knob at extreme values (NaN, ±∞, −1, 0, tiny, huge): either refused up front by
//! `PipelineParams::validate_for_clip`, naming a key, or run through the whole pipeline (a dual-focus
//! group, a depth-path group and a still) without a panic.
#![allow(clippy::unwrap_used)] // tests may panic

mod common;

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::Path;
use std::sync::atomic::AtomicBool;

use groovescope::accuracy::small_lateral;
use groovescope::engine::{ReconstructOptions, reconstruct};
use groovescope::io::Scan;
use groovescope::pipeline::PipelineParams;
use groovescope::pipeline::knobs::KNOB_DOCS;
use groovescope::pipeline::still::analyse_still;
use groovescope::still::finish_sound;
use groovescope::synth::still::{StillConfig, StillScene, render_still};
use toml::Value;

/// The values each numeric knob is set to in turn.
fn extremes(default: &Value) -> Vec<Value> {
    match default {
        Value::Float(_) => [
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            -1.0,
            0.0,
            1e-300,
            1e30,
            -1e30,
        ]
        .into_iter()
        .map(Value::Float)
        .collect(),
        Value::Integer(_) => [0, 1, -1, i64::MAX]
            .into_iter()
            .map(Value::Integer)
            .collect(),
        _ => Vec::new(),
    }
}

/// The default params as a TOML table.
fn default_table() -> toml::Table {
    let text = PipelineParams::default().to_toml_string().unwrap();
    toml::from_str(&text).unwrap()
}

/// Runs everything the params steer on `scans` (each one group) and a small still; `Err` holds
/// a panic's message. An error the pipeline returns is an answer, not a failure.
fn run_all(params: &PipelineParams, scans: &[&Scan]) -> Result<(), String> {
    let run = || {
        for scan in scans {
            let opts = ReconstructOptions {
                params: params.clone(),
                groups: Some(0..1),
                keep_going: true,
            };
            let _ = reconstruct(scan, &opts, &mut |_| {}, &AtomicBool::new(false));
        }
        let cfg = StillConfig {
            length_px: 240,
            across_px: 200,
            grooves: 2,
            ..StillConfig::default()
        };
        let scene = StillScene::new(&cfg, None).unwrap();
        let image = render_still(&scene).image;
        if let Ok(a) = analyse_still(&image, &scene.setup(0).unwrap(), Some(1), &params.still) {
            let _ = finish_sound(&a.signal, params);
        }
    };
    catch_unwind(AssertUnwindSafe(run)).map_err(|e| {
        e.downcast_ref::<String>()
            .cloned()
            .or_else(|| e.downcast_ref::<&str>().map(|s| (*s).to_string()))
            .unwrap_or_default()
    })
}

#[test]
fn every_knob_at_an_extreme_is_refused_by_name_or_runs_without_a_panic() {
    let dual = Scan::open(&Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/demo")).unwrap();
    let (_guard, depth_dir) = common::tone_scan("knobs", 1000.0, &small_lateral(1));
    let depth = Scan::open(&depth_dir).unwrap();
    let mut table = default_table();
    // The custom EQ curve chosen, so that its own keys' extremes reach the finish (with the
    // default flat curve nothing reads them).
    table["dsp"]["eq"] = Value::String("custom".into());
    let mut failures = Vec::new();
    let (mut refused, mut ran) = (0, 0);
    for (key, _) in KNOB_DOCS {
        let path: Vec<&str> = key.split('.').collect();
        let (leaf, tables) = path.split_last().unwrap();
        let default = tables
            .iter()
            .try_fold(&table, |t, name| t.get(*name).and_then(Value::as_table))
            .and_then(|t| t.get(*leaf));
        let Some(default) = default else {
            failures.push(format!("{key}: not in the written params"));
            continue;
        };
        for value in extremes(default) {
            let mut t = table.clone();
            let slot = tables.iter().fold(&mut t, |t, name| {
                t.get_mut(*name).and_then(Value::as_table_mut).unwrap()
            });
            slot.insert((*leaf).to_string(), value.clone());
            let text = toml::to_string(&t).unwrap();
            let params = match PipelineParams::from_toml_str(&text) {
                Ok(p) => p,
                Err(e) => {
                    refused += 1;
                    if !e.contains(key) {
                        failures.push(format!("{key} = {value}: read error names no key: {e}"));
                    }
                    continue;
                }
            };
            if let Err(e) = params.validate_for_clip() {
                refused += 1;
                let e = e.to_string();
                if e.lines().count() != 1 || !KNOB_DOCS.iter().any(|(k, _)| e.contains(k)) {
                    failures.push(format!("{key} = {value}: refusal names no key: {e}"));
                }
                continue;
            }
            ran += 1;
            if let Err(panic) = run_all(&params, &[&dual, &depth]) {
                failures.push(format!("{key} = {value}: panicked: {panic}"));
            }
        }
    }
    println!("knobs at extremes: {refused} refused, {ran} run");
    assert!(ran > 50 && refused > 100, "{refused} refused, {ran} run");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
