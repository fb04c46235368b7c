//! The workbench (feature `gui`): an eframe app that shows every stage of the current group from
//! the shared stage cache, reruns stale stages on a worker thread while the operator tunes,
//! reconstructs the whole clip in the background, plays it through cpal and exports it.
//!
//! Threads: the UI thread only reads results and draws; `groovescope-stages` runs
//! [`worker::Job`]s; `groovescope-reconstruct` runs the engine over all groups;
//! `groovescope-compare` reconstructs it twice for "Compare methods"; `groovescope-still` opens
//! and decodes a still image; `groovescope-dialog` shows file dialogs; `groovescope-import`
//! imports a video clip (feature `video`); the cpal callback reads a prepared buffer.

mod actions;
pub mod background;
pub mod clip_state;
pub mod compare;
mod compare_actions;
pub mod dialogs;
pub mod export;
pub mod files;
pub mod health;
pub mod history;
#[cfg(feature = "video")]
pub mod import_video;
pub mod jobs;
pub mod messages;
pub mod nav;
pub mod panels;
pub mod partial;
pub mod recent;
pub mod recon;
pub mod render;
pub mod screenshot;
pub mod shell;
pub mod stages;
pub mod still;
mod still_actions;
pub mod symptoms;
pub mod textures;
pub mod tuning;
pub mod views;
pub mod workbench;
pub mod worker;

use std::path::{Path, PathBuf};

use anyhow::Context as _;

pub use views::View;
pub use workbench::{Workbench, WorkbenchOptions};

/// Env var: save a screenshot of the window to this path once the work settled, then quit.
pub const SCREENSHOT_ENV: &str = "GROOVESCOPE_SCREENSHOT";
/// Env var: the view shown first (`overview`, `flow`, `hough`, `stripes`, `depth`, `waveform`, …).
pub const VIEW_ENV: &str = "GROOVESCOPE_VIEW";
/// Env var: set to `1` to reconstruct the clip as soon as the scan opens.
pub const RECONSTRUCT_ENV: &str = "GROOVESCOPE_RECONSTRUCT";
/// Env var: open this file dialog once the work settled, as its menu item does (`open-scan`,
/// `export-wav`, `load-preset`, `save-preset`, `export-png`, `open-still`); with `GROOVESCOPE_SCREENSHOT`
/// the picture shows what came up.
pub const DIALOG_ENV: &str = "GROOVESCOPE_DIALOG";
/// Env var: once the clip is reconstructed, apply this symptom preset (`flaked wall`, `dusty`,
/// `noisy`) and reconstruct again, so the waveform shows the two clips for A/B.
pub const COMPARE_ENV: &str = "GROOVESCOPE_COMPARE";
/// Env var: open "Compare methods" and run it with these two methods (`fused,flow`) as soon as
/// the scan opens, so a screenshot shows the comparison.
pub const COMPARE_METHODS_ENV: &str = "GROOVESCOPE_COMPARE_METHODS";
/// The workbench window could not be opened at all: no usable display (a `DISPLAY` with no X
/// server behind it, as over ssh, or a Wayland variable with no compositor).
#[derive(Debug, thiserror::Error)]
#[error("cannot open the workbench window: {0}")]
pub struct NoWindow(pub String);

/// `text` without the ` at /path/file.rs:LINE:` that winit's errors carry (the build's own
/// source paths, of no use to the operator).
fn without_source_location(text: &str) -> String {
    let Some(start) = text.find(" at /") else {
        return text.to_string();
    };
    match text[start..].find(".rs:").and_then(|i| {
        let rest = &text[start + i + 4..];
        rest.find(": ").map(|j| start + i + 4 + j)
    }) {
        Some(end) => format!("{}{}", &text[..start], &text[end..]),
        None => text[..start].to_string(),
    }
}

/// Window size (points): also the size of screenshots.
pub const WINDOW_SIZE: [f32; 2] = [1600.0, 1000.0];

/// The bundled demo scan, when it exists ([`crate::assets::find`]: the working folder, beside
/// the executable, the source tree).
#[must_use]
pub fn demo_scan() -> Option<PathBuf> {
    crate::assets::find("assets/demo", crate::io::Scan::is_scan_dir)
}

/// The scan to open when none is given: the last one used, else the demo scan.
#[must_use]
pub fn default_scan(config_dir: Option<&Path>) -> Option<PathBuf> {
    let recent = recent::RecentScans::load(config_dir);
    recent
        .scans
        .into_iter()
        .find(|p| crate::io::Scan::is_scan_dir(p))
        .or_else(demo_scan)
}

/// Opens the workbench window on `scan` (None: the last scan used, else the demo scan) and
/// returns when it closes.
///
/// `GROOVESCOPE_SCREENSHOT=PATH` (with `GROOVESCOPE_VIEW=NAME`, and `GROOVESCOPE_RECONSTRUCT=1`
/// for the waveform) saves a screenshot once the work is done and closes the window.
///
/// # Errors
/// When no window can be opened (no display), or a requested screenshot was not written.
pub fn run(scan: Option<PathBuf>) -> anyhow::Result<()> {
    // A still image opens in the still window, over the last scan (or the demo scan).
    let (scan, still) = match scan {
        Some(p) if still::is_still_image(&p) => (None, Some(p)),
        other => (other, None),
    };
    let config_dir = recent::config_dir();
    let screenshot = std::env::var_os(SCREENSHOT_ENV).map(PathBuf::from);
    let view = match std::env::var(VIEW_ENV) {
        Ok(name) => Some(View::from_name(&name).with_context(|| {
            format!(
                "unknown view {name:?} in {VIEW_ENV} (one of: {})",
                View::ALL.map(View::name).join(", ")
            )
        })?),
        Err(_) => None,
    };
    let open_dialog = match std::env::var(DIALOG_ENV) {
        Ok(name) => Some(
            dialogs::DialogKind::from_name(&name, view.unwrap_or(View::Overview)).with_context(
                || {
                    format!(
                        "unknown dialog {name:?} in {DIALOG_ENV} (one of: open-scan, export-wav, \
                         load-preset, save-preset, export-png, open-still)"
                    )
                },
            )?,
        ),
        Err(_) => None,
    };
    let compare = match std::env::var(COMPARE_ENV) {
        Ok(name) => {
            let presets = symptoms::symptom_presets().map_err(anyhow::Error::msg)?;
            let names: Vec<String> = presets.iter().map(|p| p.name.clone()).collect();
            Some(
                presets
                    .into_iter()
                    .find(|p| p.name == name.trim())
                    .with_context(|| {
                        format!(
                            "unknown symptom preset {name:?} in {COMPARE_ENV} (one of: {})",
                            names.join(", ")
                        )
                    })?,
            )
        }
        Err(_) => None,
    };
    let compare_methods = match std::env::var(COMPARE_METHODS_ENV) {
        Ok(text) => Some(
            compare::parse_pair(&text)
                .map_err(|e| anyhow::anyhow!("{COMPARE_METHODS_ENV}: {e}"))?,
        ),
        Err(_) => None,
    };
    let reconstruct_on_open = std::env::var(RECONSTRUCT_ENV).is_ok_and(|v| v == "1")
        || compare.is_some()
        || (screenshot.is_some() && view == Some(View::Waveform))
        || matches!(open_dialog, Some(dialogs::DialogKind::ExportWav(_)));
    let opts = WorkbenchOptions {
        scan: scan.or_else(|| default_scan(config_dir.as_deref())),
        config_dir,
        audio: crate::playback::DeviceChoice::from_env(),
        view,
        screenshot: screenshot.clone(),
        reconstruct_on_open,
        hide_timings: false,
        open_dialog,
        compare,
        compare_methods,
        still,
    };
    if let Some(p) = &screenshot
        && p.exists()
    {
        std::fs::remove_file(p)
            .with_context(|| format!("cannot replace the old screenshot {}", p.display()))?;
    }
    let native = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default()
            .with_title("groovescope")
            .with_inner_size(WINDOW_SIZE)
            .with_drag_and_drop(true),
        ..Default::default()
    };
    eframe::run_native(
        "groovescope",
        native,
        Box::new(move |cc| Ok(Box::new(Workbench::new(&cc.egui_ctx, opts)?))),
    )
    .map_err(|e| match e {
        eframe::Error::Winit(_) | eframe::Error::WinitEventLoop(_) => {
            anyhow::Error::new(NoWindow(without_source_location(&e.to_string())))
        }
        other => anyhow::anyhow!("cannot open the workbench window: {other}"),
    })?;
    if let Some(p) = screenshot {
        anyhow::ensure!(p.is_file(), "no screenshot was written to {}", p.display());
    }
    Ok(())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    //! The app's modules import each other without a circle: each concern's state sits in its
    //! own module, and only the window (`shell`, `panels`) and `workbench` tie them together.

    use std::collections::{BTreeMap, BTreeSet};
    use std::path::Path;

    /// Module path (`app::views::flow_ui`) → source text, for every file under `src/app`.
    fn app_modules() -> BTreeMap<String, String> {
        fn walk(dir: &Path, module: &str, out: &mut BTreeMap<String, String>) {
            for entry in std::fs::read_dir(dir).unwrap() {
                let p = entry.unwrap().path();
                let name = p.file_stem().unwrap().to_string_lossy().into_owned();
                if p.is_dir() {
                    walk(&p, &format!("{module}::{name}"), out);
                } else if p.extension().is_some_and(|e| e == "rs") {
                    let m = if name == "mod" {
                        module.to_string()
                    } else {
                        format!("{module}::{name}")
                    };
                    out.insert(m, std::fs::read_to_string(&p).unwrap());
                }
            }
        }
        let mut out = BTreeMap::new();
        walk(
            &Path::new(env!("CARGO_MANIFEST_DIR")).join("src/app"),
            "app",
            &mut out,
        );
        out
    }

    /// The paths a source text names (`crate::app::x::Y`, `super::x`, `self::x`, and in a
    /// `mod.rs` its children by name), with one level of `{a, b::c}` groups expanded; comments
    /// and the unit tests at the bottom (their own module) are skipped.
    fn named_paths(text: &str, children: &[String]) -> Vec<String> {
        let text = text.split("#[cfg(test)]").next().unwrap_or("");
        let code: String = text
            .lines()
            .map(|l| l.split("//").next().unwrap_or(""))
            .collect::<Vec<_>>()
            .join("\n");
        let ident = |c: char| c.is_ascii_alphanumeric() || c == '_';
        let mut out = Vec::new();
        let bytes: Vec<char> = code.chars().collect();
        let mut i = 0;
        while i < bytes.len() {
            let at_start = i == 0 || !ident(bytes[i - 1]) && bytes[i - 1] != ':';
            if at_start && ident(bytes[i]) {
                let mut j = i;
                while j < bytes.len() && (ident(bytes[j]) || bytes[j] == ':') {
                    j += 1;
                }
                let mut path: String = bytes[i..j].iter().collect();
                let path_trim = path.trim_end_matches(':').to_string();
                let rooted = path_trim.starts_with("crate::app")
                    || path_trim.starts_with("super")
                    || path_trim.starts_with("self::")
                    || children
                        .iter()
                        .any(|c| path_trim.starts_with(&format!("{c}::")));
                if rooted {
                    if path.ends_with("::") && bytes.get(j) == Some(&'{') {
                        let close = bytes[j..].iter().position(|&c| c == '}').unwrap_or(0) + j;
                        let inner: String = bytes[j + 1..close].iter().collect();
                        for item in inner.split(',') {
                            let item = item.trim();
                            if !item.is_empty() {
                                out.push(format!("{path}{item}"));
                            }
                        }
                        j = close;
                    } else {
                        path = path_trim;
                        out.push(path);
                    }
                }
                i = j.max(i + 1);
            } else {
                i += 1;
            }
        }
        out
    }

    /// The module of `modules` a path names from `module` (the longest known prefix).
    fn target(module: &str, path: &str, modules: &BTreeSet<String>) -> Option<String> {
        let parts: Vec<&str> = path.split("::").filter(|s| !s.is_empty()).collect();
        let mut base: Vec<String> = module.split("::").map(String::from).collect();
        let mut rest = &parts[..];
        match rest.first() {
            Some(&"crate") => {
                base = vec![];
                rest = &rest[1..];
            }
            Some(&"self") => rest = &rest[1..],
            _ => {}
        }
        while rest.first() == Some(&"super") {
            base.pop();
            rest = &rest[1..];
        }
        let mut best = None;
        let mut cur = base.clone();
        if modules.contains(&cur.join("::")) {
            best = Some(cur.join("::"));
        }
        for p in rest {
            cur.push((*p).to_string());
            let m = cur.join("::");
            if modules.contains(&m) {
                best = Some(m);
            }
        }
        best.filter(|b| b != module)
    }

    #[test]
    fn the_app_modules_import_each_other_without_a_circle() {
        let modules = app_modules();
        let names: BTreeSet<String> = modules.keys().cloned().collect();
        let mut edges: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
        for (m, text) in &modules {
            let children: Vec<String> = names
                .iter()
                .filter_map(|n| n.strip_prefix(&format!("{m}::")))
                .filter(|rest| !rest.contains("::"))
                .map(String::from)
                .collect();
            for p in named_paths(text, &children) {
                if let Some(t) = target(m, &p, &names) {
                    edges.entry(m.clone()).or_default().insert(t);
                }
            }
        }
        assert!(
            edges
                .get("app::shell")
                .is_some_and(|e| e.contains("app::workbench")),
            "the parser sees shell's imports: {edges:?}"
        );
        // Depth-first search for a back edge.
        fn visit(
            m: &str,
            edges: &BTreeMap<String, BTreeSet<String>>,
            state: &mut BTreeMap<String, u8>,
            stack: &mut Vec<String>,
        ) -> Option<Vec<String>> {
            state.insert(m.to_string(), 1);
            stack.push(m.to_string());
            for t in edges.get(m).into_iter().flatten() {
                match state.get(t.as_str()).copied().unwrap_or(0) {
                    1 => {
                        let from = stack.iter().position(|s| s == t).unwrap_or(0);
                        let mut circle = stack[from..].to_vec();
                        circle.push(t.clone());
                        return Some(circle);
                    }
                    0 => {
                        if let Some(c) = visit(t, edges, state, stack) {
                            return Some(c);
                        }
                    }
                    _ => {}
                }
            }
            stack.pop();
            state.insert(m.to_string(), 2);
            None
        }
        let mut state = BTreeMap::new();
        for m in &names {
            if state.get(m.as_str()).copied().unwrap_or(0) == 0
                && let Some(circle) = visit(m, &edges, &mut state, &mut Vec::new())
            {
                panic!("import circle: {}", circle.join(" -> "));
            }
        }
    }
}
