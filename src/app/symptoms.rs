//! Symptom presets: named parameter sets ("flaked wall", "dusty", "noisy") for the damage an
//! archivist sees, kept as data in `symptoms.toml` with a one-line reason each, and applied on
//! top of the knobs in force (only their own keys change).

use serde::Deserialize;

use crate::pipeline::PipelineParams;

/// The presets' source: `src/app/symptoms.toml`.
pub const SYMPTOMS_TOML: &str = include_str!("symptoms.toml");

/// One symptom preset.
#[derive(Clone, Debug, Deserialize, PartialEq)]
pub struct SymptomPreset {
    /// Its name, as the button reads.
    pub name: String,
    /// Why these knobs help, in one line.
    pub reason: String,
    /// The keys it sets (same layout as `groovescope params`).
    pub params: toml::Table,
}

#[derive(Deserialize)]
struct SymptomFile {
    preset: Vec<SymptomPreset>,
}

/// Every symptom preset, in file order.
///
/// # Errors
/// When `symptoms.toml` does not parse (a build of the program with a broken file).
pub fn symptom_presets() -> Result<Vec<SymptomPreset>, String> {
    toml::from_str::<SymptomFile>(SYMPTOMS_TOML)
        .map(|f| f.preset)
        .map_err(|e| format!("symptoms.toml: {e}"))
}

fn merge(into: &mut toml::Table, from: &toml::Table) {
    for (k, v) in from {
        match (into.get_mut(k), v) {
            (Some(toml::Value::Table(a)), toml::Value::Table(b)) => merge(a, b),
            _ => {
                into.insert(k.clone(), v.clone());
            }
        }
    }
}

impl SymptomPreset {
    /// `base` with this preset's keys set, validated.
    ///
    /// # Errors
    /// When a key or value is not a valid parameter.
    pub fn apply(&self, base: &PipelineParams) -> Result<PipelineParams, String> {
        let text = base.to_toml_string().map_err(|e| e.to_string())?;
        let mut table: toml::Table = toml::from_str(&text).map_err(|e| e.to_string())?;
        merge(&mut table, &self.params);
        let merged = toml::to_string(&table).map_err(|e| e.to_string())?;
        let p = PipelineParams::from_toml_str(&merged)
            .map_err(|e| format!("symptom preset {:?}: {e}", self.name))?;
        p.validate()
            .map_err(|e| format!("symptom preset {:?}: {e}", self.name))?;
        Ok(p)
    }

    /// The keys it sets, as `table.key = value` lines.
    #[must_use]
    pub fn settings(&self) -> Vec<String> {
        fn walk(prefix: &str, t: &toml::Table, out: &mut Vec<String>) {
            for (k, v) in t {
                let key = if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}.{k}")
                };
                match v {
                    toml::Value::Table(inner) => walk(&key, inner, out),
                    other => out.push(format!("{key} = {other}")),
                }
            }
        }
        let mut out = Vec::new();
        walk("", &self.params, &mut out);
        out
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;

    #[test]
    fn the_three_presets_parse_apply_and_change_only_their_keys() {
        let presets = symptom_presets().unwrap();
        let names: Vec<&str> = presets.iter().map(|p| p.name.as_str()).collect();
        assert_eq!(names, ["flaked wall", "dusty", "noisy"]);
        let mut base = PipelineParams::default();
        base.hough.theta_min_deg = -30.0;
        for p in &presets {
            assert!(
                p.reason.len() > 20 && !p.reason.contains('\n'),
                "{}",
                p.name
            );
            let out = p.apply(&base).unwrap();
            assert_ne!(out, base, "{} changes something", p.name);
            assert_eq!(
                out.hough.theta_min_deg, -30.0,
                "{} keeps other knobs",
                p.name
            );
            // Every key it lists is set to its value.
            let text = out.to_toml_string().unwrap();
            let table: toml::Table = toml::from_str(&text).unwrap();
            for line in p.settings() {
                let (key, value) = line.split_once(" = ").unwrap();
                let (section, name) = key.split_once('.').unwrap();
                assert_eq!(table[section][name].to_string(), value, "{}: {key}", p.name);
            }
        }
        let noisy = &presets[2];
        assert_eq!(noisy.apply(&base).unwrap().flow.lambda, 0.15);
    }
}
