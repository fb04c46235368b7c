//! Metadata form: edit `scan.toml` (record, camera, motion, dual focus) with live validation, then save it back.

use egui::{Color32, Grid, Ui};

use crate::io::scan::{DualFocusMeta, GlassSide};
use crate::io::{Cut, ScanMeta};

/// The form's draft.
#[derive(Clone, Debug, PartialEq)]
pub struct MetaForm {
    /// Edited metadata (its `dual_focus` is set from the two fields below on save).
    pub draft: ScanMeta,
    /// Whether the scan has a cover glass.
    pub dual: bool,
    /// Dual-focus values (kept while `dual` is off).
    pub dual_draft: DualFocusMeta,
}

impl MetaForm {
    /// A form showing `meta`.
    #[must_use]
    pub fn new(meta: &ScanMeta) -> Self {
        Self {
            draft: meta.clone(),
            dual: meta.dual_focus.is_some(),
            dual_draft: meta.dual_focus.clone().unwrap_or(DualFocusMeta {
                focus_distance_mm: meta.camera.working_distance_mm,
                glass_thickness_mm: 0.11,
                glass_index: 1.515,
                glass_side: GlassSide::Top,
                glass_edge_row: 0.0,
            }),
        }
    }

    /// The metadata the form describes.
    #[must_use]
    pub fn meta(&self) -> ScanMeta {
        let mut m = self.draft.clone();
        m.dual_focus = self.dual.then(|| self.dual_draft.clone());
        m
    }
}

/// What the form asks for.
#[derive(Clone, Debug, PartialEq)]
pub enum MetaAction {
    /// Write this metadata to `scan.toml`.
    Save(ScanMeta),
    /// Throw the edits away.
    Revert,
}

/// A grid row: a label and a drag value (`speed` per point dragged) labelled by it.
pub(crate) fn number_row(ui: &mut Ui, text: &str, value: &mut f64, speed: f64) {
    let l = ui.label(text);
    ui.add(egui::DragValue::new(value).speed(speed).max_decimals(6))
        .labelled_by(l.id);
    ui.end_row();
}

/// A heading row, then one [`number_row`] per `(label, value, speed)`.
fn section_rows<const N: usize>(ui: &mut Ui, heading: &str, rows: [(&str, &mut f64, f64); N]) {
    ui.strong(heading);
    ui.end_row();
    for (text, value, speed) in rows {
        number_row(ui, text, value, speed);
    }
}

/// The metadata form; `original` is what `scan.toml` holds now.
pub fn meta_ui(ui: &mut Ui, form: &mut MetaForm, original: &ScanMeta) -> Option<MetaAction> {
    let mut action = None;
    egui::ScrollArea::vertical().show(ui, |ui| {
        Grid::new("meta_form")
            .num_columns(2)
            .striped(true)
            .show(ui, |ui| {
                let record = &mut form.draft.record;
                section_rows(
                    ui,
                    "record",
                    [
                        ("rpm", &mut record.rpm, 0.1),
                        ("radius (mm)", &mut record.radius_mm, 0.1),
                    ],
                );
                let l = ui.label("cut");
                egui::ComboBox::from_id_salt("meta_cut")
                    .selected_text(format!("{:?}", form.draft.record.cut))
                    .show_ui(ui, |ui| {
                        for c in [Cut::Lateral, Cut::Stereo, Cut::Vertical] {
                            ui.selectable_value(&mut form.draft.record.cut, c, format!("{c:?}"));
                        }
                    })
                    .response
                    .labelled_by(l.id);
                ui.end_row();
                if let Some(r) = &form.draft.record.group_radius_mm {
                    ui.label("per-group radii");
                    ui.label(format!("{} values (kept)", r.len()));
                    ui.end_row();
                }
                let (camera, motion) = (&mut form.draft.camera, &mut form.draft.motion);
                section_rows(
                    ui,
                    "camera",
                    [
                        ("pixel pitch (µm)", &mut camera.pixel_pitch_um, 0.001),
                        (
                            "working distance (mm)",
                            &mut camera.working_distance_mm,
                            0.01,
                        ),
                    ],
                );
                section_rows(
                    ui,
                    "motion",
                    [
                        ("frame step (µm)", &mut motion.frame_step_um, 0.001),
                        ("group step (µm)", &mut motion.group_step_um, 0.1),
                    ],
                );
                ui.strong("dual focus");
                ui.end_row();
                let l = ui.label("cover glass");
                ui.checkbox(&mut form.dual, "").labelled_by(l.id);
                ui.end_row();
                if form.dual {
                    let d = &mut form.dual_draft;
                    number_row(ui, "focus distance (mm)", &mut d.focus_distance_mm, 0.001);
                    number_row(ui, "glass thickness (mm)", &mut d.glass_thickness_mm, 0.001);
                    number_row(ui, "glass index", &mut d.glass_index, 0.001);
                    let l = ui.label("glass side");
                    ui.horizontal(|ui| {
                        ui.selectable_value(&mut d.glass_side, GlassSide::Top, "top");
                        ui.selectable_value(&mut d.glass_side, GlassSide::Bottom, "bottom");
                    })
                    .response
                    .labelled_by(l.id);
                    ui.end_row();
                    number_row(ui, "glass edge row", &mut d.glass_edge_row, 1.0);
                }
            });
        let meta = form.meta();
        ui.separator();
        let g = meta.geometry();
        ui.label(format!(
            "focal length {:.1} px  ·  land flow {:+.3} px/frame  ·  groove speed {:.1} mm/s",
            g.focal_px,
            g.land_flow_px(),
            meta.groove_speed_mm_s(0)
        ));
        if let Some(d) = &meta.dual_focus {
            ui.label(format!("glass focus shift {:.4} mm", d.focus_shift_mm()));
        }
        let valid = meta.validate();
        if let Err(e) = &valid {
            ui.colored_label(Color32::from_rgb(235, 80, 70), e);
        }
        let changed = meta != *original;
        ui.horizontal(|ui| {
            if ui
                .add_enabled(
                    changed && valid.is_ok(),
                    egui::Button::new("Save scan.toml"),
                )
                .clicked()
            {
                action = Some(MetaAction::Save(meta.clone()));
            }
            if ui
                .add_enabled(changed, egui::Button::new("Revert"))
                .clicked()
            {
                action = Some(MetaAction::Revert);
            }
            if !changed {
                ui.weak("no unsaved changes");
            }
        });
    });
    action
}
