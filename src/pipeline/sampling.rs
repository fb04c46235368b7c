//! Where a group's output samples fall: the scan's global sample grid placed on the columns of one frame.

use crate::meta::ScanMeta;

use super::audio_signal::SoundParams;
use super::{StageError, compact};

/// Columns kept clear of each frame edge when placing samples (px): pre-warping clamps there.
pub const SAMPLE_MARGIN_PX: f64 = 8.0;

/// Where a group's samples fall: the groove position of each column of the reference frame.
#[derive(Clone, Debug, PartialEq)]
pub struct SampleGrid {
    /// Frame of the group whose columns are sampled.
    pub frame_index: usize,
    /// Groove position of column 0 (µm from the scan start).
    pub column0_um: f64,
    /// Groove length per column at the walls' depth (µm).
    pub um_per_px: f64,
    /// Columns of the samples (on the scan's global sample grid).
    pub columns: Vec<f32>,
}

/// Sample spacing along the groove (µm): the param, or one output sample at the scan's groove speed.
#[must_use]
pub fn native_spacing_um(meta: &ScanMeta, sound: &SoundParams) -> f64 {
    if sound.native_spacing_um > 0.0 {
        sound.native_spacing_um
    } else {
        meta.groove_speed_mm_s(0) * 1000.0 / f64::from(sound.output_rate_hz)
    }
}

/// Most native samples one pixel of a frame may carry. Finer than the pixels the image holds
/// nothing more, and every stage's work grows with the samples: a groove speed off by a unit
/// (a radius in metres) would otherwise ask for millions of samples a group and exhaust the
/// memory. A slow disc at a high rate stays far below it (8⅓ rpm at 40 mm, 192 kHz and 0.78 µm
/// pixels: 4.3 a pixel).
pub const MAX_SAMPLES_PER_PX: f64 = 16.0;

/// Most samples one column of a frame may carry at the walls' depth: twice
/// [`MAX_SAMPLES_PER_PX`], which holds at the land, so walls up to twice the working distance
/// from the camera pass (real walls lie a groove's depth, a few per cent, beyond it).
pub const MAX_SAMPLES_PER_COLUMN: f64 = 2.0 * MAX_SAMPLES_PER_PX;

/// Why a scan's native sample grid is too fine for its frames ([`check_sample_density`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TooFine {
    /// True when the spacing comes from the scan's metadata (groove speed and output rate),
    /// false when `sound.native_spacing_um` sets it.
    pub from_scan: bool,
    /// A sentence naming the keys and the numbers.
    pub problem: String,
}

/// Checks that the native sample grid carries at most [`MAX_SAMPLES_PER_PX`] samples a pixel
/// of `meta`'s frames at the land.
///
/// # Errors
/// [`TooFine`] naming the keys to check.
pub fn check_sample_density(meta: &ScanMeta, sound: &SoundParams) -> Result<(), TooFine> {
    let spacing = native_spacing_um(meta, sound);
    let pitch = meta.camera.pixel_pitch_um;
    let per_px = pitch / spacing;
    if per_px.is_finite() && per_px > 0.0 && per_px <= MAX_SAMPLES_PER_PX {
        return Ok(());
    }
    let density = if per_px.is_finite() && per_px > 0.0 {
        format!(
            "a native sample every {spacing:.3e} µm along the groove is {per_px:.3e} samples a pixel of {pitch} µm, more than the {MAX_SAMPLES_PER_PX} a pixel can carry"
        )
    } else {
        format!("a native sample spacing of {spacing:.3e} µm is no sampling of the groove")
    };
    Err(if sound.native_spacing_um > 0.0 {
        TooFine {
            from_scan: false,
            problem: density,
        }
    } else {
        TooFine {
            from_scan: true,
            problem: format!(
                "{} = {} and record.rpm = {} give a groove speed of {:.3e} mm/s, and at {} Hz {density}: check them (a radius in mm, a speed in turns a minute), or set [sound] native_spacing_um",
                if meta.record.group_radius_mm.is_some() {
                    "record.group_radius_mm[0]"
                } else {
                    "record.radius_mm"
                },
                compact(meta.radius_mm(0)),
                compact(meta.record.rpm),
                meta.groove_speed_mm_s(0),
                sound.output_rate_hz
            ),
        }
    })
}

/// Places the scan's global sample grid on the columns of one frame of one group, whose walls
/// lie `projection_depth_um` from the optical centre.
///
/// # Errors
/// [`StageError::NotFound`] (for `stage`) when that depth puts more than
/// [`MAX_SAMPLES_PER_COLUMN`] samples on a column: [`check_sample_density`] holds at the land,
/// so only a depth far beyond the working distance (a focus distance off by a unit in
/// scan.toml, a depth map gone wrong) does that, and it would ask for millions of samples a
/// group.
pub fn sample_grid(
    meta: &ScanMeta,
    group: usize,
    frame_index: usize,
    width: usize,
    projection_depth_um: f64,
    sound: &SoundParams,
    stage: &'static str,
) -> Result<SampleGrid, StageError> {
    let geom = meta.geometry();
    let cx = (width as f64 - 1.0) / 2.0;
    let cam_s = group as f64 * meta.motion.group_step_um
        + frame_index as f64 * meta.motion.frame_step_um
        + cx * geom.pixel_pitch_um;
    let um_per_px = geom.pixel_pitch_um * projection_depth_um / geom.working_distance_um;
    let column0_um = cam_s - cx * um_per_px;
    let spacing = native_spacing_um(meta, sound);
    let lo = column0_um + SAMPLE_MARGIN_PX * um_per_px;
    let hi = column0_um + (width as f64 - 1.0 - SAMPLE_MARGIN_PX) * um_per_px;
    let mut columns = Vec::new();
    if spacing > 0.0 && hi > lo {
        // Counted in f64 first: a wild depth makes it too large for any integer.
        let count = (hi / spacing).floor() - (lo / spacing).ceil() + 1.0;
        if count.is_nan() || count > MAX_SAMPLES_PER_COLUMN * width as f64 {
            return Err(StageError::NotFound {
                stage,
                problem: format!(
                    "the walls' depth of {} µm is {:.3e}× the working distance of {} µm, which puts {count:.3e} samples on {width} columns, more than {MAX_SAMPLES_PER_COLUMN} a column (is the focus distance or the depth map far off?)",
                    compact(projection_depth_um),
                    projection_depth_um / geom.working_distance_um,
                    compact(geom.working_distance_um),
                ),
            });
        }
        let first = (lo / spacing).ceil() as i64;
        let last = (hi / spacing).floor() as i64;
        for j in first..=last {
            columns.push(((j as f64 * spacing - column0_um) / um_per_px) as f32);
        }
    }
    Ok(SampleGrid {
        frame_index,
        column0_um,
        um_per_px,
        columns,
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::sample_grid;
    use crate::io::scan::test_support::scan_meta;
    use crate::pipeline::audio_signal::SoundParams;

    /// Walls at the working distance get one sample every few columns; walls 1e300 µm away (a
    /// focus distance far off) are refused before the grid is built, where they once asked for
    /// a vector that grew past 14 GB.
    #[test]
    fn a_wild_wall_depth_is_refused_before_the_grid_is_built() {
        let meta = scan_meta(460.2);
        let sound = SoundParams::default();
        let wd_um = meta.geometry().working_distance_um;
        let grid = sample_grid(&meta, 3, 2, 1280, wd_um * 1.02, &sound, "orientation").unwrap();
        assert!(!grid.columns.is_empty());
        assert!(grid.columns.windows(2).all(|c| c[1] > c[0]));
        // About 0.02 samples a pixel at the land: 1e5 times deeper is over the limit.
        for depth in [1e300, wd_um * 1e5] {
            let e = sample_grid(&meta, 3, 2, 1280, depth, &sound, "orientation").unwrap_err();
            let msg = e.to_string();
            assert!(msg.starts_with("orientation: the walls' depth of"), "{msg}");
            assert!(msg.contains("a column"), "{msg}");
        }
    }
}
