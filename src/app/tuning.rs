//! The knobs of the open scan: the params in force, their undo history, and where they came
//! from (the defaults or a preset file), so the panel can say *defaults*, *preset (path)* or
//! *modified since preset*, and an export records exactly what was used.
//!
//! One `Tuning` belongs to one scan: opening a scan builds a new one from that scan's
//! `preset.toml` (or the defaults), so nothing of the previous disc carries over.

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::Serialize;

use super::history::History;
use crate::io::lock::OutputLock;
use crate::io::write_atomic;
use crate::pipeline::PipelineParams;

/// Name of the per-disc preset loaded automatically from a scan folder.
pub const SCAN_PRESET_FILE: &str = "preset.toml";

/// Saves `params` as a TOML preset.
///
/// # Errors
/// A message naming the file when it exists and `overwrite` is false, or the write fails.
pub fn save_preset(params: &PipelineParams, path: &Path, overwrite: bool) -> Result<(), String> {
    let text = params.to_toml_string().map_err(|e| e.to_string())?;
    let _lock = OutputLock::acquire(path).map_err(|e| e.to_string())?;
    write_atomic(path, text.as_bytes(), overwrite).map_err(|e| e.to_string())
}

/// Reads and validates a TOML preset.
///
/// # Errors
/// A message naming the file and the bad key or value.
pub fn load_preset(path: &Path) -> Result<PipelineParams, String> {
    let text = crate::io::limits::read_toml_text(path, "preset").map_err(|e| e.to_string())?;
    let params = PipelineParams::from_toml_str(&text)
        .map_err(|e| format!("invalid preset: {e}: {}", path.display()))?;
    params
        .validate()
        .map_err(|e| format!("invalid preset: {e}: {}", path.display()))?;
    Ok(params)
}

/// Where the params of a scan started from.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ParamSource {
    /// `PipelineParams::default()`.
    Defaults,
    /// A preset file (loaded or saved).
    Preset(PathBuf),
}

/// What the params in force are, as the panel and an export's sidecar say it.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct ParamState {
    /// Where they started from.
    pub source: ParamSource,
    /// True when they differ from that start.
    pub modified: bool,
}

impl ParamState {
    /// One line for the panel: `defaults`, `preset PATH`, `modified since preset PATH`,
    /// `modified from the defaults`.
    #[must_use]
    pub fn line(&self) -> String {
        match (&self.source, self.modified) {
            (ParamSource::Defaults, false) => "parameters: defaults".into(),
            (ParamSource::Defaults, true) => "parameters: modified from the defaults".into(),
            (ParamSource::Preset(p), false) => format!("parameters: preset {}", p.display()),
            (ParamSource::Preset(p), true) => {
                format!("parameters: modified since preset {}", p.display())
            }
        }
    }

    /// The preset file, if the params started from one.
    #[must_use]
    pub fn preset_file(&self) -> Option<&Path> {
        match &self.source {
            ParamSource::Preset(p) => Some(p),
            ParamSource::Defaults => None,
        }
    }
}

/// The params of one scan, their history and their origin.
#[derive(Clone, Debug)]
pub struct Tuning {
    params: PipelineParams,
    history: History,
    source: ParamSource,
    /// The params as they came from `source` (compared to say "modified").
    baseline: PipelineParams,
}

impl Default for Tuning {
    fn default() -> Self {
        Self {
            params: PipelineParams::default(),
            history: History::default(),
            source: ParamSource::Defaults,
            baseline: PipelineParams::default(),
        }
    }
}

impl Tuning {
    /// The tuning a scan in `dir` opens with: its `preset.toml` when there is one, else the
    /// defaults; plus a message saying which (an error when the preset cannot be used, in
    /// which case the defaults are used).
    pub fn for_scan(dir: &Path) -> (Self, Result<String, String>) {
        let preset = dir.join(SCAN_PRESET_FILE);
        if !preset.is_file() {
            return (
                Self::default(),
                Ok(format!(
                    "no {SCAN_PRESET_FILE} in the scan folder: running on the defaults"
                )),
            );
        }
        match load_preset(&preset) {
            Ok(params) => {
                let msg = format!("loaded the scan's preset {}", preset.display());
                (
                    Self {
                        params: params.clone(),
                        history: History::default(),
                        source: ParamSource::Preset(preset),
                        baseline: params,
                    },
                    Ok(msg),
                )
            }
            Err(e) => (
                Self::default(),
                Err(format!("{e} (running on the defaults)")),
            ),
        }
    }

    /// The params in force.
    #[must_use]
    pub fn params(&self) -> &PipelineParams {
        &self.params
    }

    /// Where the params came from and whether they were changed since.
    #[must_use]
    pub fn state(&self) -> ParamState {
        ParamState {
            source: self.source.clone(),
            modified: self.params != self.baseline,
        }
    }

    /// True when the params differ from the preset or defaults they started from.
    #[must_use]
    pub fn is_modified(&self) -> bool {
        self.params != self.baseline
    }

    /// Applies `new` as one undoable change (edits in a burst to one stage merge); false when
    /// nothing changed.
    pub fn set(&mut self, new: PipelineParams, now: Instant) -> bool {
        if new == self.params {
            return false;
        }
        let stage = self.params.first_changed_stage(&new);
        self.history.record(&self.params, stage, now);
        self.params = new;
        true
    }

    /// Applies `new` as an undo step of its own (a preset, a TOML apply, a symptom preset).
    pub fn replace(&mut self, new: PipelineParams, now: Instant) -> bool {
        self.history.seal();
        let changed = self.set(new, now);
        self.history.seal();
        changed
    }

    /// Ends the current burst of edits, so the next edit is its own undo step.
    pub fn seal(&mut self) {
        self.history.seal();
    }

    /// Params loaded from the preset file `path` (an undoable change); they become the new
    /// baseline.
    pub fn load_preset(&mut self, path: &Path, params: PipelineParams, now: Instant) -> bool {
        self.source = ParamSource::Preset(path.to_path_buf());
        self.baseline = params.clone();
        self.replace(params, now)
    }

    /// The params in force were saved to `path`: it is the new baseline.
    pub fn saved_as(&mut self, path: &Path) {
        self.source = ParamSource::Preset(path.to_path_buf());
        self.baseline = self.params.clone();
    }

    /// Goes back one step; false when there is nothing to undo.
    pub fn undo(&mut self) -> bool {
        let step = self.history.undo(&self.params);
        self.take_step(step)
    }

    /// Goes forward one step; false when there is nothing to redo.
    pub fn redo(&mut self) -> bool {
        let step = self.history.redo(&self.params);
        self.take_step(step)
    }

    /// Puts the params of an undo or redo step in force; false when there was no step.
    fn take_step(&mut self, step: Option<PipelineParams>) -> bool {
        let Some(p) = step else {
            return false;
        };
        self.params = p;
        true
    }

    /// True when there is something to undo / redo.
    #[must_use]
    pub fn can_undo_redo(&self) -> (bool, bool) {
        (self.history.can_undo(), self.history.can_redo())
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;
    use crate::test_support::path_in_temp_dir;

    #[test]
    fn preset_round_trips_and_bad_presets_name_the_key() {
        let (_dir, p) = path_in_temp_dir("disc.toml");
        let mut params = PipelineParams::default();
        params.flow.lambda = 0.25;
        params.hough.theta_min_deg = -30.0;
        save_preset(&params, &p, false).unwrap();
        assert!(
            save_preset(&params, &p, false).is_err(),
            "no silent overwrite"
        );
        assert_eq!(load_preset(&p).unwrap(), params);
        std::fs::write(&p, "[flow]\nlamda = 3\n").unwrap();
        let err = load_preset(&p).unwrap_err();
        assert!(err.contains("lamda") && err.contains("disc.toml"), "{err}");
        std::fs::write(&p, "[flow]\nlambda = -3.0\n").unwrap();
        let err = load_preset(&p).unwrap_err();
        assert!(err.contains("flow.lambda"), "{err}");
    }

    #[test]
    fn a_scan_opens_on_its_preset_or_on_the_defaults_and_says_which() {
        let dir = tempfile::tempdir().unwrap();
        let (t, msg) = Tuning::for_scan(dir.path());
        assert_eq!(t.params(), &PipelineParams::default());
        assert_eq!(t.state().line(), "parameters: defaults");
        assert!(msg.unwrap().contains("defaults"));

        let mut p = PipelineParams::default();
        p.flow.lambda = 0.2;
        let preset = dir.path().join(SCAN_PRESET_FILE);
        std::fs::write(&preset, p.to_toml_string().unwrap()).unwrap();
        let (mut t, msg) = Tuning::for_scan(dir.path());
        assert_eq!(t.params().flow.lambda, 0.2);
        assert!(msg.unwrap().contains("preset.toml"));
        assert_eq!(t.state().preset_file(), Some(preset.as_path()));
        assert!(!t.is_modified());
        let mut q = t.params().clone();
        q.flow.lambda = 0.4;
        assert!(t.set(q, Instant::now()));
        assert!(
            t.state()
                .line()
                .starts_with("parameters: modified since preset")
        );
        assert!(t.undo());
        assert!(!t.is_modified());

        std::fs::write(&preset, "[flow]\nlambda = -1.0\n").unwrap();
        let (t, msg) = Tuning::for_scan(dir.path());
        assert_eq!(t.params(), &PipelineParams::default());
        let err = msg.unwrap_err();
        assert!(
            err.contains("flow.lambda") && err.contains("defaults"),
            "{err}"
        );
    }

    #[test]
    fn saving_makes_the_params_the_new_baseline() {
        let mut t = Tuning::default();
        let mut p = PipelineParams::default();
        p.hough.window_rho_px += 1.0;
        t.set(p, Instant::now());
        assert_eq!(t.state().line(), "parameters: modified from the defaults");
        t.saved_as(Path::new("/discs/a/preset.toml"));
        assert_eq!(t.state().line(), "parameters: preset /discs/a/preset.toml");
    }
}
