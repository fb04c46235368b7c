//! Parameter panel: every knob of every stage, edited on a draft the workbench compares and applies.

use egui::{Grid, Response, Ui, emath::Numeric};

use super::StageStatus;
use crate::pipeline::derivatives::DerivativeMode;
use crate::pipeline::dsp::EqCurve;
use crate::pipeline::knobs::knob_doc;
use crate::pipeline::optical_flow::{FlowMethod, Solver};
use crate::pipeline::walls::WallMethod;
use crate::pipeline::{PathChoice, PipelineParams, Stage};

/// Drag speed of decade-spanning values, as a share of the value per point dragged.
const LOG_SPEED: f64 = 0.01;

/// The row label; hovering shows the knob's TOML key and its documentation line.
fn label(ui: &mut Ui, text: &str, key: &str) -> Response {
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
macro_rules! rows {
    ($ui:expr, $table:literal, $s:expr; $($kind:ident $text:literal $field:ident ($($arg:expr),*);)*) => {
        $($kind($ui, $text, concat!($table, ".", stringify!($field)), &mut $s.$field $(, $arg)*);)*
    };
}

/// The parameter panel. Edits `p` in place; the caller compares it with the applied params.
pub fn params_ui(ui: &mut Ui, p: &mut PipelineParams, status: &[StageStatus; Stage::ALL.len()]) {
    let st = |s: Stage| Some(&status[s.index()]);
    section(ui, "path", None, false, |ui| {
        choice(
            ui,
            "reconstruction path",
            "path",
            &mut p.path,
            &[
                (PathChoice::Auto, "auto (from scan.toml)"),
                (PathChoice::Depth, "depth (Kalman)"),
                (PathChoice::DualFocus, "dual focus (stripes)"),
            ],
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
            num "median (px)" median_px (2.0, 1..=31);
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
            num "peaks" peak_count (0.1, 1..=8);
            num "window ±θ (°)" window_theta_deg (0.1, 0.1..=90.0);
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
            ]);
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
