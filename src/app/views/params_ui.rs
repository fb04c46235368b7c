//! Parameter panel: every knob of every stage, edited on a draft the workbench compares and applies.

use egui::{Grid, Response, Ui, emath::Numeric};

use super::StageStatus;
use crate::pipeline::depth::MAX_MEDIAN_PX;
use crate::pipeline::derivatives::DerivativeMode;
use crate::pipeline::dsp::EqCurve;
use crate::pipeline::edges::border::BorderParams;
use crate::pipeline::hough::{MAX_WINDOW_THETA_DEG, STRIPE_COUNT};
use crate::pipeline::knobs::knob_doc;
use crate::pipeline::optical_flow::{FlowMethod, Solver};
use crate::pipeline::still::WallTone;
use crate::pipeline::walls::WallMethod;
use crate::pipeline::{Method, PathChoice, PipelineParams, Stage};

/// Drag speed of decade-spanning values, as a share of the value per point dragged.
const LOG_SPEED: f64 = 0.01;

#[cfg(test)]
thread_local! {
    /// While Some (a test): every section opens, and each row's key is written down.
    static DRAWN: std::cell::RefCell<Option<Vec<String>>> = const { std::cell::RefCell::new(None) };
    /// While Some (a test): each number row's key and the range it offers.
    #[cfg(test)]
    static RANGES: std::cell::RefCell<Option<Vec<(String, f64, f64)>>> =
        const { std::cell::RefCell::new(None) };
}

/// Writes down a number row's range while a test asks for it.
#[cfg(test)]
fn note_range<T: Numeric>(key: &str, range: &std::ops::RangeInclusive<T>) {
    RANGES.with(|r| {
        if let Some(rows) = r.borrow_mut().as_mut() {
            rows.push((key.to_owned(), range.start().to_f64(), range.end().to_f64()));
        }
    });
}

/// The row label; hovering shows the knob's TOML key and its documentation line.
fn label(ui: &mut Ui, text: &str, key: &str) -> Response {
    #[cfg(test)]
    DRAWN.with(|d| {
        if let Some(keys) = d.borrow_mut().as_mut() {
            keys.push(key.to_owned());
        }
    });
    let doc = knob_doc(key).unwrap_or("");
    ui.label(text).on_hover_text(format!("{key}\n{doc}"))
}

/// A number row: label (hover shows the TOML key) and a drag value labelled by it.
fn num<T: Numeric>(
    ui: &mut Ui,
    text: &str,
    key: &str,
    value: &mut T,
    speed: f64,
    range: std::ops::RangeInclusive<T>,
) {
    #[cfg(test)]
    note_range(key, &range);
    let l = label(ui, text, key);
    ui.add(
        egui::DragValue::new(value)
            .speed(speed)
            .range(range)
            .clamp_existing_to_range(false),
    )
    .labelled_by(l.id);
    ui.end_row();
}

/// A positive number spanning decades: a drag value whose speed is 1 % of the value, shown in
/// scientific notation (typing a value works too).
fn log_num<T: Numeric>(
    ui: &mut Ui,
    text: &str,
    key: &str,
    value: &mut T,
    range: std::ops::RangeInclusive<T>,
) {
    #[cfg(test)]
    note_range(key, &range);
    let l = label(ui, text, key);
    let speed = value.to_f64().abs().max(1e-12) * LOG_SPEED;
    ui.add(
        egui::DragValue::new(value)
            .speed(speed)
            .range(range)
            .clamp_existing_to_range(false)
            .custom_formatter(|v, _| format!("{v:.4e}")),
    )
    .labelled_by(l.id);
    ui.end_row();
}

fn check(ui: &mut Ui, text: &str, key: &str, value: &mut bool) {
    let l = label(ui, text, key);
    ui.checkbox(value, "").labelled_by(l.id);
    ui.end_row();
}

fn choice<T: PartialEq + Copy>(
    ui: &mut Ui,
    text: &str,
    key: &str,
    value: &mut T,
    options: &[(T, &str)],
) {
    let l = label(ui, text, key);
    let current = options
        .iter()
        .find(|(v, _)| v == value)
        .map_or("?", |(_, n)| *n);
    egui::ComboBox::from_id_salt(key)
        .selected_text(current)
        .show_ui(ui, |ui| {
            for (v, n) in options {
                ui.selectable_value(value, *v, *n);
            }
        })
        .response
        .labelled_by(l.id);
    ui.end_row();
}

fn section(
    ui: &mut Ui,
    title: &str,
    status: Option<&StageStatus>,
    open: bool,
    add: impl FnOnce(&mut Ui),
) {
    #[cfg(test)]
    let open = open || DRAWN.with(|d| d.borrow().is_some());
    let text = match status {
        Some(s) => egui::RichText::new(format!("{title}  ·  {}", s.word())).color(s.colour()),
        None => egui::RichText::new(title),
    };
    egui::CollapsingHeader::new(text)
        .id_salt(title)
        .default_open(open)
        .show(ui, |ui| {
            Grid::new(format!("grid_{title}"))
                .num_columns(2)
                .striped(true)
                .show(ui, add);
        });
}

/// Rows of one params table, `kind "label" field (further arguments);` each: a call of `kind`
/// (`num`, `log_num`, `check` or `choice`) on the field, its TOML key `table.field`.
/// A literal table builds its keys at compile time; a table named at run time (the border fit,
/// shared by `edges` and `still`) formats them.
macro_rules! rows {
    ($ui:expr, $table:literal, $s:expr; $($kind:ident $text:literal $field:ident ($($arg:expr),*);)*) => {
        $($kind($ui, $text, concat!($table, ".", stringify!($field)), &mut $s.$field $(, $arg)*);)*
    };
    ($ui:expr, $table:expr, $s:expr; $($kind:ident $text:literal $field:ident ($($arg:expr),*);)*) => {
        $($kind($ui, $text, &format!("{}.{}", $table, stringify!($field)), &mut $s.$field $(, $arg)*);)*
    };
}

/// The rows of a border model's fit (`edges.border`, `still.border`).
fn border_rows(ui: &mut Ui, table: &str, b: &mut BorderParams) {
    rows!(ui, table, b;
        num "fit half window (px)" fit_half_window_px (0.5, 1.0..=10_000.0);
        num "edge width min (px)" min_width_px (0.01, 0.001..=1000.0);
        num "edge width max (px)" max_width_px (0.1, 0.001..=10_000.0);
        num "min contrast" min_contrast (0.001, 0.0..=1e6);
        num "fit iterations" max_iterations (0.5, 1..=1000);
        log_num "fit τ (px)" tolerance_px (0.0..=1.0);
    );
}

/// The reconstruction paths, as the panel names them.
const PATHS: [(PathChoice, &str); 3] = [
    (PathChoice::Auto, "auto (from scan.toml)"),
    (PathChoice::Depth, "depth (Kalman)"),
    (PathChoice::DualFocus, "dual focus (stripes)"),
];

/// Every fusion block length the knob accepts (a power of two from 16 to 65 536).
const FUSION_BLOCKS: [(usize, &str); 13] = [
    (16, "16"),
    (32, "32"),
    (64, "64"),
    (128, "128"),
    (256, "256"),
    (512, "512"),
    (1024, "1024"),
    (2048, "2048"),
    (4096, "4096"),
    (8192, "8192"),
    (16_384, "16384"),
    (32_768, "32768"),
    (65_536, "65536"),
];

/// The decoders, as the panel names them.
const METHODS: [(Method, &str); 3] = [
    (Method::Fused, "fused (edges + flow)"),
    (Method::Edges, "edges"),
    (Method::Flow, "flow"),
];

/// The parameter panel. Edits `p` in place; the caller compares it with the applied params.
pub fn params_ui(ui: &mut Ui, p: &mut PipelineParams, status: &[StageStatus; Stage::ALL.len()]) {
    let st = |s: Stage| Some(&status[s.index()]);
    section(ui, "path", None, false, |ui| {
        choice(ui, "reconstruction path", "path", &mut p.path, &PATHS);
    });
    section(ui, "decoder", None, true, |ui| {
        choice(ui, "method", "method", &mut p.method, &METHODS);
        rows!(ui, "fusion", p.fusion;
            choice "fusion block (samples)" block_samples (&FUSION_BLOCKS);
            num "fusion smoothing (blocks)" smoothing_blocks (0.1, 0..=1024);
        );
    });
    section(ui, "edges", st(Stage::Edges), false, |ui| {
        rows!(ui, "edges", p.edges;
            num "wall angle (°)" wall_angle_deg (0.1, 1.0..=89.0);
            check "all frames" all_frames ();
            num "band (px)" band_half_height_px (0.5, 2.0..=256.0);
            num "band (σ of a blurred border)" band_sigmas (0.05, 0.0..=100.0);
            num "max band (px)" max_band_half_height_px (0.5, 2.0..=256.0);
            num "max band, noisy camera (px)" noisy_band_half_height_px (0.5, 2.0..=256.0);
            num "noisy from (grey levels)" noisy_grey_levels (0.05, 0.0..=255.0);
            num "profile bin (px)" bin_px (0.01, 0.01..=4.0);
            num "coarse column step" coarse_column_step (0.1, 1..=64);
            num "column σ (px)" column_sigma_px (0.05, 0.001..=1000.0);
            num "column rounds" column_rounds (0.1, 1..=20);
            num "border σ (µm)" border_sigma_um (0.01, 0.0001..=10_000.0);
            log_num "border floor (µm)" border_floor_um (1e-6..=1e4);
            num "max bridge (samples)" max_bridge_samples (0.1, 0..=1000);
            num "weight window (samples)" weight_window_samples (0.5, 0..=10_000);
            num "despike (σs, 0 = off)" despike_sigmas (0.1, 0.0..=1000.0);
            num "burst despike (σs, 0 = off)" burst_sigmas (0.1, 0.0..=1000.0);
            num "steepest groove slope (0 = off)" max_slope (0.01, 0.0..=1000.0);
            num "longest excursion (samples)" max_excursion_samples (0.5, 0..=1_000_000);
            check "restart disagreeing solves" restart_solves ();
            check "refine sharp borders" refine ();
            num "sharp below width (px)" hard_width_px (0.01, 0.0..=100.0);
            log_num "crossing σ (px)" crossing_sigma_px (1e-4..=100.0);
            log_num "anchor σ (px)" anchor_sigma_px (1e-4..=100.0);
            num "spline smoothness" spline_smoothness (0.1, 0.0..=1e9);
            num "spline frames" spline_frames (0.1, 1..=64);
        );
        border_rows(ui, "edges.border", &mut p.edges.border);
        rows!(ui, "edges.differentiator", p.edges.differentiator;
            num "differentiator half taps" half_taps (0.1, 1..=32);
            num "differentiator band" band (0.005, 0.05..=0.99);
            num "differentiator aperture (samples)" aperture_samples (0.01, 0.0..=4.0);
            log_num "differentiator ridge" ridge (0.0..=1e6);
            num "differentiator min run" min_run (0.1, 2..=1000);
        );
    });
    section(ui, "derivatives", st(Stage::Derivatives), false, |ui| {
        rows!(ui, "derivatives", p.derivatives;
            choice "filters" mode (&[
                (DerivativeMode::Simoncelli, "Simoncelli p5/d5"),
                (DerivativeMode::TwoFrame, "two-frame differences"),
            ]);
            check "pre-warp by land flow" prewarp ();
        );
    });
    section(ui, "flow", st(Stage::Flow), true, |ui| {
        rows!(ui, "flow", p.flow;
            choice "method" method (&[
                (FlowMethod::GrooveHornSchunck, "Horn–Schunck + groove"),
                (FlowMethod::HornSchunck, "Horn–Schunck"),
                (FlowMethod::LucasKanade, "Lucas–Kanade"),
            ]);
            choice "solver" solver (&[
                (Solver::GaussSeidel, "Gauss–Seidel"),
                (Solver::Jacobi, "Jacobi"),
            ]);
            log_num "λ (smoothness)" lambda (1e-5..=1e3);
            num "groove weight (× λ)" groove_weight (0.01, 0.0..=1e6);
            num "SOR ω (Gauss–Seidel)" sor_omega (0.01, 0.01..=1.99);
            num "iterations" max_iterations (1.0, 1..=10_000);
            log_num "τ (px)" tolerance_px (1e-9..=1.0);
            log_num "gradient threshold" gradient_threshold (1e-7..=10.0);
            num "LK window (px)" lk_window_px (2.0, 3..=63);
        );
    });
    section(ui, "depth", st(Stage::Depth), false, |ui| {
        rows!(ui, "depth", p.depth;
            check "Kalman filter" kalman ();
            log_num "process noise" process_noise (1e-12..=1.0);
            log_num "measurement noise (px²)" measurement_noise_px2 (1e-10..=10.0);
            num "median (px)" median_px (2.0, 1..=MAX_MEDIAN_PX);
            log_num "min confidence" min_confidence (1e-8..=10.0);
            num "neighbourhood (px)" neighbourhood_px (0.5, 1..=63);
        );
        rows!(ui, "walls", p.walls;
            choice "wall finder" method (&[
                (WallMethod::DepthLevels, "depth levels"),
                (WallMethod::SlopeRuns, "slope runs"),
            ]);
            num "wall min slope" min_slope (0.01, 0.0..=10.0);
            num "wall trim (px)" trim_px (0.5, 0..=100);
            num "wall smoothing (px)" smooth_px (0.5, 0..=100);
            num "wall column window (px)" column_window_px (1.0, 1..=10_001);
        );
    });
    section(ui, "hough / stripes", st(Stage::Stripes), false, |ui| {
        rows!(ui, "hough", p.hough;
            log_num "in-focus gradient" gradient_threshold (1e-5..=10.0);
            num "θ min (°)" theta_min_deg (0.5, -90.0..=90.0);
            num "θ max (°)" theta_max_deg (0.5, -90.0..=90.0);
            num "θ step (°)" theta_step_deg (0.05, 0.01..=10.0);
            num "ρ step (px)" rho_step_px (0.05, 0.05..=20.0);
            // The dual-focus geometry fixes it; the row shows it.
            num "peaks" peak_count (0.1, STRIPE_COUNT..=STRIPE_COUNT);
            num "min peak (share of the top)" min_peak_ratio (0.01, 0.0..=1.0);
            num "peak ρ band (px, 0 = auto)" peak_rho_band_px (0.5, 0.0..=2000.0);
            num "window ±θ (°)" window_theta_deg (0.1, 0.1..=MAX_WINDOW_THETA_DEG);
            num "window ±ρ (px)" window_rho_px (0.5, 0.5..=2000.0);
            num "line smoothing (px)" line_smoothing_px (0.5, 0..=200);
            num "min votes per column" min_votes_per_column (0.01, 0.0..=100.0);
            num "max voting pixels (0 = all)" max_vote_points (1000.0, 0..=100_000_000);
        );
    });
    section(ui, "orientation", st(Stage::Orientation), false, |ui| {
        rows!(ui, "orientation", p.orientation;
            check "robust (Lorentzian)" robust ();
            num "neighbourhood (px)" neighbourhood_px (1.0, 3..=1000);
            log_num "σ start (µm)" sigma_start_um (1e-4..=1e3);
            num "σ decay" sigma_decay (0.01, 0.01..=1.0);
            log_num "σ min (µm)" sigma_min_um (1e-5..=1e2);
            log_num "τ1 residual (µm)" residual_tolerance_um (1e-8..=10.0);
            num "τ2 divergence factor" divergence_factor (0.05, 1.0..=100.0);
            num "iterations" max_iterations (1.0, 1..=1000);
            num "outlier σs" outlier_sigmas (0.05, 0.1..=20.0);
            num "max wall-slope change" max_wall_slope_change (0.01, 0.0..=10.0);
        );
    });
    section(ui, "sound", st(Stage::Sound), false, |ui| {
        rows!(ui, "sound", p.sound;
            choice "output rate" output_rate_hz (&[
                (44_100, "44 100 Hz"),
                (48_000, "48 000 Hz"),
                (96_000, "96 000 Hz"),
            ]);
            num "native spacing (µm, 0 = auto)" native_spacing_um (0.001, 0.0..=100.0);
            num "normalise to peak (0 = off)" normalize_peak (0.01, 0.0..=1.0);
            num "full scale (mm/s)" full_scale_mm_s (1.0, 0.001..=10_000.0);
        );
    });
    section(ui, "still image", None, false, |ui| {
        rows!(ui, "still", p.still;
            num "block (lines)" block_lines (1.0, 4..=4096);
            num "widest groove (µm)" max_groove_width_um (1.0, 0.001..=1e6);
            num "narrowest wall (µm)" min_wall_width_um (0.1, 0.0..=1e6);
            choice "walls" walls (&[(WallTone::Dark, "dark"), (WallTone::Bright, "bright")]);
            num "min contrast" min_contrast (0.005, 0.0..=1.0);
            num "max gap (blocks)" max_gap_blocks (0.1, 0..=10_000);
            num "min track (blocks)" min_track_blocks (0.1, 1..=10_000);
            num "search (share of the wall)" search_share (0.01, 0.05..=2.0);
            num "outlier σs" outlier_sigmas (0.05, 1.0..=1000.0);
            num "path window (µm)" path_window_um (10.0, 1.0..=1e9);
            num "wall angle (°)" wall_angle_deg (0.1, 10.0..=80.0);
            num "max lost share" max_lost_share (0.01, 0.0..=1.0);
        );
        border_rows(ui, "still.border", &mut p.still.border);
    });
    section(ui, "filter / EQ (clip)", None, false, |ui| {
        rows!(ui, "dsp", p.dsp;
            check "DC block" dc_block ();
            num "DC block corner (Hz)" dc_block_hz (0.5, 0.1..=1000.0);
            check "low-pass" lowpass ();
            num "cutoff (Hz)" lowpass_hz (10.0, 10.0..=40_000.0);
            choice "EQ curve" eq (&[
                (EqCurve::Flat, "flat (velocity)"),
                (EqCurve::Riaa, "RIAA"),
                (EqCurve::Turnover500, "78: 500 Hz turnover"),
                (EqCurve::Custom, "78: a chart's numbers (below)"),
            ]);
            num "custom: turnover (Hz)" eq_turnover_hz (5.0, 1.0..=20_000.0);
            num "custom: roll-off at 10 kHz (dB)" eq_rolloff_db (0.1, 0.0..=60.0);
            num "custom: bass shelf (Hz)" eq_shelf_hz (1.0, 0.1..=20_000.0);
        );
    });
}

/// State of the all-knobs TOML editor.
#[derive(Clone, Debug, Default)]
pub struct TomlEditor {
    /// The text being edited (None: follow the params).
    pub text: Option<String>,
    /// The text as generated from the params (while `text` equals it, it follows them).
    pub generated: String,
    /// Why the last apply failed.
    pub error: Option<String>,
}

/// Every knob as TOML (documented), editable as text; returns params to apply when the
/// operator presses Apply and the text parses and validates.
pub fn toml_ui(ui: &mut Ui, p: &PipelineParams, ed: &mut TomlEditor) -> Option<PipelineParams> {
    let mut out = None;
    egui::CollapsingHeader::new("all knobs (TOML)")
        .id_salt("params_toml")
        .default_open(false)
        .show(ui, |ui| {
            let current = crate::pipeline::knobs::documented_toml(p).unwrap_or_default();
            let mut text = match ed.text.take() {
                Some(t) if t != ed.generated => t,
                _ => current.clone(),
            };
            ed.generated.clone_from(&current);
            let l = ui.weak("edit any key, then Apply (missing keys take defaults)");
            ui.add(
                egui::TextEdit::multiline(&mut text)
                    .code_editor()
                    .desired_rows(12)
                    .desired_width(f32::INFINITY),
            )
            .labelled_by(l.id);
            ui.horizontal(|ui| {
                if ui.button("Apply").clicked() {
                    let parsed = PipelineParams::from_toml_str(&text)
                        .and_then(|q| q.validate().map(|()| q).map_err(|e| e.to_string()));
                    match parsed {
                        Ok(q) => {
                            ed.error = None;
                            out = Some(q);
                        }
                        Err(e) => ed.error = Some(e),
                    }
                }
                if ui.button("Reset to current").clicked() {
                    ed.error = None;
                    text.clone_from(&current);
                }
            });
            ed.text = Some(text);
            if let Some(e) = &ed.error {
                ui.colored_label(egui::Color32::from_rgb(235, 80, 70), e);
            }
        });
    if out.is_some() {
        ed.text = None;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::app::views::StageStatus;
    use crate::pipeline::knobs::KNOB_DOCS;

    /// The rows written down: every row's key, every number row's key and range (a row per
    /// frame drawn), and the params after drawing the panel on the defaults with every section
    /// open.
    type Drawn = (Vec<String>, Vec<(String, f64, f64)>, PipelineParams);

    fn draw_every_row() -> Drawn {
        DRAWN.with(|d| *d.borrow_mut() = Some(Vec::new()));
        RANGES.with(|r| *r.borrow_mut() = Some(Vec::new()));
        let status: [StageStatus; Stage::ALL.len()] = std::array::from_fn(|_| StageStatus::Fresh);
        let mut h = egui_kittest::Harness::new_ui_state(
            |ui, p: &mut PipelineParams| params_ui(ui, p, &status),
            PipelineParams::default(),
        );
        h.run();
        (
            DRAWN.with(|d| d.borrow_mut().take()).unwrap(),
            RANGES.with(|r| r.borrow_mut().take()).unwrap(),
            h.state().clone(),
        )
    }

    #[test]
    fn every_knob_has_a_row_under_its_own_key() {
        let (drawn, _, p) = draw_every_row();
        let missing: Vec<&str> = KNOB_DOCS
            .iter()
            .map(|(k, _)| *k)
            .filter(|k| !drawn.iter().any(|d| d == k))
            .collect();
        assert!(missing.is_empty(), "no row: {missing:?}");
        let unknown: Vec<&String> = drawn
            .iter()
            .filter(|d| !KNOB_DOCS.iter().any(|(k, _)| k == d))
            .collect();
        assert!(unknown.is_empty(), "rows under no knob's key: {unknown:?}");
        assert_eq!(p, PipelineParams::default(), "drawing changed a knob");
        // The block list offers exactly the lengths the knob accepts.
        let accepted = |n: usize| {
            crate::pipeline::fusion::FusionParams {
                block_samples: n,
                ..Default::default()
            }
            .validate()
            .is_ok()
        };
        for (n, name) in FUSION_BLOCKS {
            assert!(accepted(n) && name == n.to_string(), "{n}");
        }
        let powers = (0..=20).map(|k| 1_usize << k).filter(|&n| accepted(n));
        assert_eq!(powers.count(), FUSION_BLOCKS.len());
    }

    /// The panel never offers a number its knob refuses: each row's range ends, set alone on
    /// the defaults, pass `PipelineParams::validate`. A knob bounded by a partner (a lower
    /// limit that must not pass its upper one) passes with the partner set to the same value.
    #[test]
    fn every_number_row_offers_only_values_its_knob_accepts() {
        const PARTNERS: [(&str, &str); 3] = [
            ("theta_min_deg", "theta_max_deg"),
            ("band_half_height_px", "max_band_half_height_px"),
            ("min_width_px", "max_width_px"),
        ];
        let (_, mut rows, _) = draw_every_row();
        rows.sort_by(|a, b| a.0.cmp(&b.0));
        rows.dedup_by(|a, b| a.0 == b.0);
        assert!(rows.len() > 50, "{} number rows", rows.len());
        let base = toml::Value::try_from(PipelineParams::default()).unwrap();
        // The defaults with `keys` (same table) set to `v`, validated.
        let check = |table: &str, keys: &[&str], v: f64| -> Result<(), String> {
            let mut doc = base.clone();
            for key in keys {
                let mut slot = &mut doc;
                for part in table.split('.').chain([*key]) {
                    slot = slot
                        .get_mut(part)
                        .unwrap_or_else(|| panic!("{table}.{key}"));
                }
                *slot = match slot {
                    #[allow(clippy::cast_possible_truncation)] // integer rows have integer ends
                    toml::Value::Integer(_) => toml::Value::Integer(v as i64),
                    _ => toml::Value::Float(v),
                };
            }
            let p: PipelineParams = doc.try_into().map_err(|e| e.to_string())?;
            p.validate().map_err(|e| e.to_string())
        };
        let mut refused = Vec::new();
        for (key, lo, hi) in &rows {
            let (table, name) = key.rsplit_once('.').unwrap();
            let partner = PARTNERS.iter().find_map(|&(a, b)| match name {
                n if n == a => Some(b),
                n if n == b => Some(a),
                _ => None,
            });
            for v in [*lo, *hi] {
                let alone = check(table, &[name], v);
                let ok =
                    alone.is_ok() || partner.is_some_and(|q| check(table, &[name, q], v).is_ok());
                if let (false, Err(e)) = (ok, alone) {
                    refused.push(format!("{key} = {v}: {e}"));
                }
            }
        }
        assert!(refused.is_empty(), "{refused:#?}");
    }
}
