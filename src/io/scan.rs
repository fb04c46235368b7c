//! The scan directory contract: `scan.toml` metadata, group folders and their frames (see docs/FORMAT.md).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::LoadError;
use super::frames::frame_dimensions;
use super::limits::{MAX_FRAMES_PER_GROUP, MAX_GROUPS, read_toml_text};

/// The scan format version this build reads and writes.
pub const FORMAT_VERSION: u32 = 1;
/// Fewest frames a group may hold: the derivative stage needs 7.
pub const MIN_FRAMES_PER_GROUP: usize = 7;

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

/// The `[motion]` table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MotionMeta {
    /// Record travel between consecutive frames of a group (content moves toward -x).
    pub frame_step_um: f64,
    /// Travel between the first frames of consecutive groups.
    pub group_step_um: f64,
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
    /// Parses and validates `scan.toml` text; `path` is used in errors only.
    ///
    /// # Errors
    /// A [`LoadError::Metadata`] naming the file and the missing or invalid key.
    pub fn from_toml_str(text: &str, path: &Path) -> Result<Self, LoadError> {
        let meta: ScanMeta = toml::from_str(text).map_err(|e| LoadError::Metadata {
            problem: e.message().to_string(),
            path: path.to_path_buf(),
        })?;
        meta.validate().map_err(|problem| LoadError::Metadata {
            problem,
            path: path.to_path_buf(),
        })?;
        Ok(meta)
    }

    /// Reads `scan.toml` from a file.
    ///
    /// # Errors
    /// [`LoadError`] when the file cannot be read or is invalid.
    pub fn load(path: &Path) -> Result<Self, LoadError> {
        let text = read_toml_text(path, "scan metadata")?;
        Self::from_toml_str(&text, path)
    }

    /// The TOML text of this metadata.
    ///
    /// # Errors
    /// When serialisation fails (it does not for validated metadata).
    pub fn to_toml_string(&self) -> Result<String, toml::ser::Error> {
        toml::to_string_pretty(self)
    }

    /// Checks every value for sense; returns the first problem found.
    ///
    /// # Errors
    /// A sentence naming the key and the problem.
    pub fn validate(&self) -> Result<(), String> {
        fn positive(name: &str, v: f64) -> Result<(), String> {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(format!("{name} must be a positive number, got {v}"))
            }
        }
        if self.format != FORMAT_VERSION {
            return Err(format!(
                "format = {} is not supported (this build reads format {FORMAT_VERSION})",
                self.format
            ));
        }
        positive("record.rpm", self.record.rpm)?;
        positive("record.radius_mm", self.record.radius_mm)?;
        if let Some(radii) = &self.record.group_radius_mm {
            for (i, r) in radii.iter().enumerate() {
                positive(&format!("record.group_radius_mm[{i}]"), *r)?;
            }
        }
        positive("camera.pixel_pitch_um", self.camera.pixel_pitch_um)?;
        positive(
            "camera.working_distance_mm",
            self.camera.working_distance_mm,
        )?;
        positive("motion.frame_step_um", self.motion.frame_step_um)?;
        positive("motion.group_step_um", self.motion.group_step_um)?;
        if let Some(df) = &self.dual_focus {
            positive("dual_focus.focus_distance_mm", df.focus_distance_mm)?;
            positive("dual_focus.glass_thickness_mm", df.glass_thickness_mm)?;
            if !(df.glass_index.is_finite() && df.glass_index >= 1.0) {
                return Err(format!(
                    "dual_focus.glass_index must be at least 1 (a real glass), got {}",
                    df.glass_index
                ));
            }
            if !df.glass_edge_row.is_finite() || df.glass_edge_row < 0.0 {
                return Err(format!(
                    "dual_focus.glass_edge_row must be a row number, got {}",
                    df.glass_edge_row
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
                    df.glass_edge_row
                ));
            }
        }
        let margin_px = crate::pipeline::sampling::SAMPLE_MARGIN_PX;
        let view_um = (width as f64 - 1.0 - 2.0 * margin_px) * self.camera.pixel_pitch_um;
        if groups > 1 && self.motion.group_step_um > view_um {
            return Err(format!(
                "motion.group_step_um = {} µm is longer than the {view_um:.2} µm a group's frames are sampled over ({width} px of {} µm less the stitcher's {margin_px} px margin each side), so consecutive groups would not overlap and the sound would have gaps",
                self.motion.group_step_um, self.camera.pixel_pitch_um
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

/// One group: its index, folder and sorted frame files, or its chunk in a Zarr store.
#[derive(Clone, Debug, PartialEq)]
pub struct GroupEntry {
    /// Position in the scan, from 0.
    pub index: usize,
    /// The group folder (in a Zarr store: the store joined with the group's name, which
    /// names the group in messages).
    pub dir: PathBuf,
    /// Frame files sorted by name (empty in a Zarr store).
    pub frames: Vec<PathBuf>,
    /// Where the frames are in a Zarr store (None for a scan folder).
    pub zarr: Option<super::zarr::ZarrGroup>,
}

impl GroupEntry {
    /// Frames in the group.
    #[must_use]
    pub fn frame_count(&self) -> usize {
        self.zarr.as_ref().map_or(self.frames.len(), |z| z.frames)
    }

    /// The group's name: its folder's name.
    #[must_use]
    pub fn name(&self) -> String {
        self.dir.file_name().map_or_else(
            || self.index.to_string(),
            |n| n.to_string_lossy().into_owned(),
        )
    }
}

/// An opened scan: metadata plus the list of groups. Frames are read on demand.
#[derive(Clone, Debug)]
pub struct Scan {
    /// The scan folder.
    pub dir: PathBuf,
    /// Parsed `scan.toml`.
    pub meta: ScanMeta,
    /// Groups sorted by folder name.
    pub groups: Vec<GroupEntry>,
    /// `reference.wav`, when present.
    pub reference: Option<PathBuf>,
}

fn is_frame_file(p: &Path) -> bool {
    p.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| matches!(e.to_ascii_lowercase().as_str(), "png" | "tif" | "tiff"))
}

/// The entries of `dir` that pass `keep`, sorted by name; more than `limit` of them is refused.
fn sorted_entries(
    dir: &Path,
    keep: impl Fn(&Path) -> bool,
    limit: usize,
    what: &str,
) -> Result<Vec<PathBuf>, LoadError> {
    let list_err = |e: std::io::Error| LoadError::Io {
        problem: format!("cannot list folder: {e}"),
        path: dir.to_path_buf(),
    };
    let rd = std::fs::read_dir(dir).map_err(list_err)?;
    let mut out = Vec::new();
    for entry in rd {
        let path = entry.map_err(list_err)?.path();
        if !keep(&path) {
            continue;
        }
        if out.len() == limit {
            return Err(LoadError::NotAScan {
                problem: format!("the folder holds more than {limit} {what}, past the limit"),
                path: dir.to_path_buf(),
            });
        }
        out.push(path);
    }
    out.sort();
    Ok(out)
}

impl Scan {
    /// Opens a scan: a folder (reads `scan.toml` and lists the groups and their frames) or a
    /// Zarr store made by `groovescope pack` (a folder holding `zarr.json`).
    ///
    /// # Errors
    /// [`LoadError`] when the folder is not a scan, the metadata is invalid, there are no
    /// groups, or a group holds fewer than [`MIN_FRAMES_PER_GROUP`] frames.
    pub fn open(dir: &Path) -> Result<Self, LoadError> {
        if dir.join("zarr.json").is_file() {
            return super::zarr::open_scan(dir);
        }
        if !dir.is_dir() {
            return Err(LoadError::NotAScan {
                problem: "no such folder".into(),
                path: dir.to_path_buf(),
            });
        }
        let meta_path = dir.join("scan.toml");
        if !meta_path.is_file() {
            return Err(LoadError::NotAScan {
                problem: "not a scan folder: scan.toml is missing".into(),
                path: dir.to_path_buf(),
            });
        }
        let meta = ScanMeta::load(&meta_path)?;
        let mut groups = Vec::new();
        for path in sorted_entries(dir, Path::is_dir, MAX_GROUPS, "group folders")? {
            let frames = sorted_entries(
                &path,
                |p| p.is_file() && is_frame_file(p),
                MAX_FRAMES_PER_GROUP,
                "frames",
            )?;
            if frames.len() < MIN_FRAMES_PER_GROUP {
                return Err(LoadError::TooFewFrames {
                    found: frames.len(),
                    needed: MIN_FRAMES_PER_GROUP,
                    path,
                });
            }
            groups.push(GroupEntry {
                index: groups.len(),
                dir: path,
                frames,
                zarr: None,
            });
        }
        let Some(first) = groups.first().and_then(|g| g.frames.first()) else {
            return Err(LoadError::NotAScan {
                problem: "the scan holds no group folders with frames".into(),
                path: dir.to_path_buf(),
            });
        };
        let frame_size = frame_dimensions(first)?;
        meta.check_against_scan(groups.len(), frame_size)
            .map_err(|problem| LoadError::Metadata {
                problem,
                path: meta_path.clone(),
            })?;
        let reference = Some(dir.join("reference.wav")).filter(|p| p.is_file());
        Ok(Self {
            dir: dir.to_path_buf(),
            meta,
            groups,
            reference,
        })
    }

    /// Start of group `group` along the groove, in µm from the first group.
    #[must_use]
    pub fn group_start_um(&self, group: usize) -> f64 {
        group as f64 * self.meta.motion.group_step_um
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MINIMAL: &str = r#"
format = 1
[record]
rpm = 78.0
radius_mm = 115.0
cut = "lateral"
[camera]
pixel_pitch_um = 0.39
working_distance_mm = 4.0
[motion]
frame_step_um = 0.78
group_step_um = 460.2
"#;

    #[test]
    fn minimal_file_loads_and_derives_geometry() {
        let m = ScanMeta::from_toml_str(MINIMAL, Path::new("scan.toml")).unwrap();
        let g = m.geometry();
        assert!((g.focal_px - 10_256.41).abs() < 0.01);
        assert!((g.land_flow_px() + 2.0).abs() < 1e-9);
        assert!((m.groove_speed_mm_s(0) - 939.336).abs() < 0.01);
        assert!(m.dual_focus.is_none());
    }

    #[test]
    fn missing_key_names_it_and_the_file() {
        let text = MINIMAL.replace("rpm = 78.0\n", "");
        let err = ScanMeta::from_toml_str(&text, Path::new("/x/scan.toml")).unwrap_err();
        let msg = err.to_string();
        assert!(msg.contains("rpm"), "{msg}");
        assert!(msg.contains("/x/scan.toml"), "{msg}");
    }

    #[test]
    fn nan_and_negative_values_are_rejected() {
        let text = MINIMAL.replace("radius_mm = 115.0", "radius_mm = nan");
        assert!(ScanMeta::from_toml_str(&text, Path::new("s")).is_err());
        let text = MINIMAL.replace("frame_step_um = 0.78", "frame_step_um = -0.78");
        let msg = ScanMeta::from_toml_str(&text, Path::new("s"))
            .unwrap_err()
            .to_string();
        assert!(msg.contains("motion.frame_step_um"), "{msg}");
    }

    #[test]
    fn dual_focus_shift_matches_thin_lens_geometry() {
        let text = format!(
            "{MINIMAL}\n[dual_focus]\nfocus_distance_mm = 4.0\nglass_thickness_mm = 0.11\nglass_index = 1.515\nglass_edge_row = 300\n"
        );
        let m = ScanMeta::from_toml_str(&text, Path::new("s")).unwrap();
        let (a, b) = m.dual_focus.unwrap().focal_distances_mm();
        assert!((a - 4.000).abs() < 1e-12);
        assert!((b - 4.037).abs() < 0.0005, "{b}");
        let bad = text.replace("glass_index = 1.515", "glass_index = 0.9");
        assert!(ScanMeta::from_toml_str(&bad, Path::new("s")).is_err());
    }

    #[test]
    fn extra_tables_round_trip() {
        let text = format!("{MINIMAL}\n[synth]\nseed = 7\n");
        let m = ScanMeta::from_toml_str(&text, Path::new("s")).unwrap();
        let back = ScanMeta::from_toml_str(&m.to_toml_string().unwrap(), Path::new("s")).unwrap();
        assert_eq!(m, back);
        assert!(back.extra.contains_key("synth"));
    }
}
