//! What a scan's metadata says, as plain data: the record, camera, motion and dual-focus tables of `scan.toml` and the geometry the stages derive from them (read and written by `io::scan`).

use serde::{Deserialize, Serialize};

use crate::pipeline::compact as shown;

/// The scan format version this build reads and writes.
pub const FORMAT_VERSION: u32 = 1;
/// Fastest turntable speed a scan or a still may give (rpm): far past any record, short of the
/// numbers that overflow the geometry.
pub const MAX_RPM: f64 = 1000.0;
/// Largest groove radius a scan or a still may give (mm): likewise.
pub const MAX_RADIUS_MM: f64 = 1000.0;

/// How the sound was cut into the groove.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Cut {
    /// Lateral (mono) modulation: both walls move together across the groove.
    #[default]
    Lateral,
    /// 45/45 stereo: each wall carries one channel along its normal.
    Stereo,
    /// Vertical (hill-and-dale): the groove moves up and down.
    Vertical,
}

impl Cut {
    /// Its name as scan.toml and the command line spell it.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Cut::Lateral => "lateral",
            Cut::Stereo => "stereo",
            Cut::Vertical => "vertical",
        }
    }
}

/// The `[record]` table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RecordMeta {
    /// Turntable speed the disc was cut at.
    pub rpm: f64,
    /// Groove radius at the first group.
    pub radius_mm: f64,
    /// Cut type.
    #[serde(default)]
    pub cut: Cut,
    /// Optional radius of every group (spiral groove); overrides `radius_mm` where given.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub group_radius_mm: Option<Vec<f64>>,
}

/// The `[camera]` table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraMeta {
    /// Size of one pixel on the land (record surface) plane.
    pub pixel_pitch_um: f64,
    /// Optical centre to the land plane.
    pub working_distance_mm: f64,
}

/// What the numbers in group folder and frame names say (docs/FORMAT.md, "Numbered names are
/// positions").
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum NumberedNames {
    /// Numbers on a regular step are places: a number skipped is a missing group or frame.
    #[default]
    Positions,
    /// The numbers set the order only (timestamps, capture counters that skip).
    Order,
}

impl NumberedNames {
    fn is_positions(&self) -> bool {
        *self == Self::Positions
    }
}

/// The `[motion]` table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MotionMeta {
    /// Record travel between consecutive frames of a group (content moves toward -x).
    pub frame_step_um: f64,
    /// Travel between the first frames of consecutive groups.
    pub group_step_um: f64,
    /// What numbered names say; only written when it is not the default, so the canonical
    /// TOML (and every fingerprint) of a scan without it is unchanged.
    #[serde(default, skip_serializing_if = "NumberedNames::is_positions")]
    pub numbered_names: NumberedNames,
}

/// Which part of the field of view the cover glass covers.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum GlassSide {
    /// Rows above `glass_edge_row` (smaller y) lie under the glass.
    #[default]
    Top,
    /// Rows below `glass_edge_row` (larger y) lie under the glass.
    Bottom,
}

/// How far from the working distance (as a factor either way) a dual-focus focal plane may
/// lie: real ones lie a groove's depth, a few per cent, beyond the land.
pub const MAX_FOCUS_RATIO: f64 = 2.0;

/// The optional `[dual_focus]` table: a cover glass over part of the view gives a second focal depth.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DualFocusMeta {
    /// Distance from the optical centre to the focal plane without glass.
    pub focus_distance_mm: f64,
    /// Cover glass thickness.
    pub glass_thickness_mm: f64,
    /// Cover glass refractive index.
    pub glass_index: f64,
    /// Which side of the edge the glass covers.
    #[serde(default)]
    pub glass_side: GlassSide,
    /// Image row of the glass edge.
    pub glass_edge_row: f64,
}

impl DualFocusMeta {
    /// Focus shift of the glass, δv = d·(1 − 1/n), in mm (paper §9).
    #[must_use]
    pub fn focus_shift_mm(&self) -> f64 {
        self.glass_thickness_mm * (1.0 - 1.0 / self.glass_index)
    }

    /// The two focal distances (without glass, under glass), in mm from the optical centre.
    #[must_use]
    pub fn focal_distances_mm(&self) -> (f64, f64) {
        (
            self.focus_distance_mm,
            self.focus_distance_mm + self.focus_shift_mm(),
        )
    }
}

/// Everything `scan.toml` says. Unknown top-level tables (for example `[synth]`) are kept, not rejected.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ScanMeta {
    /// Format version; must equal [`FORMAT_VERSION`].
    pub format: u32,
    /// `[record]`.
    pub record: RecordMeta,
    /// `[camera]`.
    pub camera: CameraMeta,
    /// `[motion]`.
    pub motion: MotionMeta,
    /// `[dual_focus]`, when the scan was made through a cover glass.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dual_focus: Option<DualFocusMeta>,
    /// Any other tables, kept verbatim (the generator writes `[synth]`).
    #[serde(flatten)]
    pub extra: toml::Table,
}

impl ScanMeta {
    /// Checks every value for sense; returns the first problem found.
    ///
    /// # Errors
    /// A sentence naming the key and the problem.
    pub fn validate(&self) -> Result<(), String> {
        fn positive(name: &str, v: f64) -> Result<(), String> {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(format!(
                    "{name} must be a positive number, got {}",
                    shown(v)
                ))
            }
        }
        if self.format != FORMAT_VERSION {
            return Err(format!(
                "format = {} is not supported (this build reads format {FORMAT_VERSION})",
                self.format
            ));
        }
        // Far past any record or microscope, short of the numbers that overflow the geometry.
        fn at_most(name: &str, v: f64, most: f64) -> Result<(), String> {
            positive(name, v)?;
            if v <= most {
                Ok(())
            } else {
                Err(format!("{name} must be at most {most}, got {}", shown(v)))
            }
        }
        at_most("record.rpm", self.record.rpm, MAX_RPM)?;
        at_most("record.radius_mm", self.record.radius_mm, MAX_RADIUS_MM)?;
        if let Some(radii) = &self.record.group_radius_mm {
            for (i, r) in radii.iter().enumerate() {
                at_most(&format!("record.group_radius_mm[{i}]"), *r, MAX_RADIUS_MM)?;
            }
        }
        // Lower bounds short of the numbers the stages refuse (a focal length of 1e-9 to 1e12
        // px, a frame step of 1e-12 µm and more), so scan.toml is named with its own key.
        fn at_least(name: &str, v: f64, least: f64) -> Result<(), String> {
            positive(name, v)?;
            if v >= least {
                Ok(())
            } else {
                Err(format!(
                    "{name} must be at least {}, got {}",
                    shown(least),
                    shown(v)
                ))
            }
        }
        at_most("camera.pixel_pitch_um", self.camera.pixel_pitch_um, 1000.0)?;
        at_least("camera.pixel_pitch_um", self.camera.pixel_pitch_um, 1e-4)?;
        at_most(
            "camera.working_distance_mm",
            self.camera.working_distance_mm,
            10_000.0,
        )?;
        at_least(
            "camera.working_distance_mm",
            self.camera.working_distance_mm,
            1e-8,
        )?;
        // No upper bound here: a step past the frame's width is refused below, with the width.
        at_least("motion.frame_step_um", self.motion.frame_step_um, 1e-9)?;
        at_least("motion.group_step_um", self.motion.group_step_um, 1e-9)?;
        if let Some(df) = &self.dual_focus {
            positive("dual_focus.focus_distance_mm", df.focus_distance_mm)?;
            positive("dual_focus.glass_thickness_mm", df.glass_thickness_mm)?;
            if !(df.glass_index.is_finite() && df.glass_index >= 1.0) {
                return Err(format!(
                    "dual_focus.glass_index must be at least 1 (a real glass), got {}",
                    shown(df.glass_index)
                ));
            }
            // Both focal planes lie in the groove, a fraction of a millimetre beyond the land:
            // far from it, the wall depths and the sample grid built on them are nonsense (a
            // focus distance in µm would ask for millions of samples a group).
            let wd = self.camera.working_distance_mm;
            // Computed numbers (the plane under the glass, the ratios) to three decimals.
            let figures = |r: f64| {
                if (1e-3..1e6).contains(&r.abs()) {
                    format!("{}", (r * 1e3).round() / 1e3)
                } else {
                    format!("{r:.3e}")
                }
            };
            let under = df.focal_distances_mm().1;
            for (name, d, typed) in [
                (
                    "dual_focus.focus_distance_mm",
                    df.focus_distance_mm,
                    shown(df.focus_distance_mm),
                ),
                (
                    "the focal plane under the glass (dual_focus.focus_distance_mm + glass_thickness_mm × (1 − 1/glass_index))",
                    under,
                    figures(under),
                ),
            ] {
                if !(d >= wd / MAX_FOCUS_RATIO && d <= wd * MAX_FOCUS_RATIO) {
                    return Err(format!(
                        "{name} = {} mm is {} times camera.working_distance_mm = {} mm, outside 1/{MAX_FOCUS_RATIO} to {MAX_FOCUS_RATIO}: both focal planes lie in the groove, near the land (distances from the optical centre, in mm)",
                        typed,
                        figures(d / wd),
                        shown(wd)
                    ));
                }
            }
            if !df.glass_edge_row.is_finite() || df.glass_edge_row < 0.0 {
                return Err(format!(
                    "dual_focus.glass_edge_row must be a row number, got {}",
                    shown(df.glass_edge_row)
                ));
            }
        }
        Ok(())
    }

    /// Checks the metadata against what the scan folder holds: `groups` group folders whose
    /// first frame is `frame_size` (width, height) px. A per-group list must have one entry a
    /// group, the glass edge must lie inside the frame, and the group step must be at most the
    /// stretch of groove a group's samples cover (its width less the stitcher's margins), or
    /// consecutive groups would leave gaps in the sound.
    ///
    /// # Errors
    /// A sentence naming the key and both numbers.
    pub fn check_against_scan(
        &self,
        groups: usize,
        frame_size: (usize, usize),
    ) -> Result<(), String> {
        if let Some(radii) = &self.record.group_radius_mm
            && radii.len() != groups
        {
            return Err(format!(
                "record.group_radius_mm has {} entries but the scan has {groups} groups",
                radii.len()
            ));
        }
        let (width, height) = frame_size;
        if let Some(df) = &self.dual_focus {
            let last_row = height.saturating_sub(1) as f64;
            if df.glass_edge_row > last_row {
                return Err(format!(
                    "dual_focus.glass_edge_row = {} lies outside the frame, whose last row is {last_row} ({height} rows)",
                    shown(df.glass_edge_row)
                ));
            }
        }
        // Past the frame's width, consecutive frames share nothing and neither flow nor the
        // borders can be followed.
        let land_shift_px = self.geometry().land_flow_px().abs();
        if land_shift_px >= width as f64 {
            return Err(format!(
                "motion.frame_step_um = {} µm moves the land {land_shift_px:.4e} px between frames, not less than the frame's {width} px width (at {} µm a pixel), so consecutive frames would share nothing",
                shown(self.motion.frame_step_um),
                self.camera.pixel_pitch_um
            ));
        }
        let margin_px = crate::pipeline::sampling::SAMPLE_MARGIN_PX;
        let view_um = (width as f64 - 1.0 - 2.0 * margin_px) * self.camera.pixel_pitch_um;
        if groups > 1 && self.motion.group_step_um > view_um {
            return Err(format!(
                "motion.group_step_um = {} µm is longer than the {view_um:.2} µm a group's frames are sampled over ({width} px of {} µm less the stitcher's {margin_px} px margin each side), so consecutive groups would not overlap and the sound would have gaps",
                shown(self.motion.group_step_um),
                self.camera.pixel_pitch_um
            ));
        }
        Ok(())
    }

    /// Camera geometry derived from the metadata, for the stages.
    #[must_use]
    pub fn geometry(&self) -> Geometry {
        Geometry {
            focal_px: self.camera.working_distance_mm * 1000.0 / self.camera.pixel_pitch_um,
            pixel_pitch_um: self.camera.pixel_pitch_um,
            working_distance_um: self.camera.working_distance_mm * 1000.0,
            frame_step_um: self.motion.frame_step_um,
        }
    }

    /// Groove radius at group `group`, in mm.
    #[must_use]
    pub fn radius_mm(&self, group: usize) -> f64 {
        self.record
            .group_radius_mm
            .as_ref()
            .and_then(|r| r.get(group).copied())
            .unwrap_or(self.record.radius_mm)
    }

    /// Groove (tangential) speed Vt = 2π·rpm/60·R at group `group`, in mm/s.
    #[must_use]
    pub fn groove_speed_mm_s(&self, group: usize) -> f64 {
        std::f64::consts::TAU * self.record.rpm / 60.0 * self.radius_mm(group)
    }
}

/// Camera and motion geometry in the units the stages use.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Geometry {
    /// Focal length in pixels = working distance / pixel pitch.
    pub focal_px: f64,
    /// Pixel size on the land plane.
    pub pixel_pitch_um: f64,
    /// Optical centre to the land plane.
    pub working_distance_um: f64,
    /// Record travel between consecutive frames (the camera translation U).
    pub frame_step_um: f64,
}

impl Geometry {
    /// Image motion of the land plane between frames, in pixels (content moves toward -x).
    #[must_use]
    pub fn land_flow_px(&self) -> f64 {
        -self.frame_step_um / self.pixel_pitch_um
    }
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::ScanMeta;

    #[test]
    fn out_of_range_values_name_the_file_and_key_in_a_short_line() {
        // 1e-13 µm passed scan.toml and was refused by a stage as `geometry.frame_step_um`,
        // without the file; 1e-300 was written out as 300 digits.
        for (key, from, to, shown) in [
            (
                "motion.frame_step_um",
                "frame_step_um = 0.78",
                "frame_step_um = 1e-13",
                "1e-13",
            ),
            (
                "motion.frame_step_um",
                "frame_step_um = 0.78",
                "frame_step_um = 1e-300",
                "1e-300",
            ),
            (
                "camera.pixel_pitch_um",
                "pixel_pitch_um = 0.39",
                "pixel_pitch_um = 1e-300",
                "1e-300",
            ),
            (
                "camera.working_distance_mm",
                "working_distance_mm = 4.0",
                "working_distance_mm = 1e-12",
                "1e-12",
            ),
        ] {
            let text = crate::io::scan::test_support::scan_toml(460.2).replace(from, to);
            assert_ne!(
                text,
                crate::io::scan::test_support::scan_toml(460.2),
                "{from}"
            );
            let msg = ScanMeta::from_toml_str(&text, Path::new("b20/scan.toml"))
                .unwrap_err()
                .to_string();
            assert!(msg.contains(key) && msg.contains("b20/scan.toml"), "{msg}");
            assert!(
                msg.contains(&format!("got {shown}")) && msg.len() < 160,
                "{msg}"
            );
        }
    }

    /// A focal plane far from the land (a focus distance in µm, a glass in metres) is refused
    /// when the scan opens, naming the key: it once grew a group's sample grid past 14 GB.
    #[test]
    fn a_focal_plane_far_from_the_land_is_refused() {
        let base = format!(
            "{}\n[dual_focus]\nfocus_distance_mm = 4.05\nglass_thickness_mm = 0.11\nglass_index = 1.515\nglass_edge_row = 300\n",
            crate::io::scan::test_support::scan_toml(460.2)
        );
        assert!(ScanMeta::from_toml_str(&base, Path::new("s/scan.toml")).is_ok());
        let refusal = |text: &str| {
            ScanMeta::from_toml_str(text, Path::new("s/scan.toml"))
                .unwrap_err()
                .to_string()
        };
        for (from, to, key) in [
            (
                "focus_distance_mm = 4.05",
                "focus_distance_mm = 1e300",
                "dual_focus.focus_distance_mm = 1e300",
            ),
            (
                "focus_distance_mm = 4.05",
                "focus_distance_mm = 4050",
                "dual_focus.focus_distance_mm = 4050",
            ),
            (
                "focus_distance_mm = 4.05",
                "focus_distance_mm = 1e-300",
                "dual_focus.focus_distance_mm = 1e-300",
            ),
            (
                "glass_thickness_mm = 0.11",
                "glass_thickness_mm = 110",
                "the focal plane under the glass",
            ),
        ] {
            let msg = refusal(&base.replace(from, to));
            assert!(msg.contains(key) && msg.contains("s/scan.toml"), "{msg}");
            assert!(msg.contains("camera.working_distance_mm = 4 mm"), "{msg}");
        }
        // A glass index below 1 is named as such, not as the plane it would put behind the camera.
        let msg = refusal(&base.replace("glass_index = 1.515", "glass_index = 0"));
        assert!(
            msg.contains("dual_focus.glass_index must be at least 1"),
            "{msg}"
        );
        // A group step of 1e-300 µm (13 groups on one spot) is refused like a frame step.
        let msg = refusal(&crate::io::scan::test_support::scan_toml(1e-300));
        assert!(
            msg.contains("motion.group_step_um must be at least 1e-9"),
            "{msg}"
        );
    }
}
