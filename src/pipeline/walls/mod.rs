//! Wall lines: where each groove wall lies in every column, found from the depth map (depth path) or stripes (dual focus).

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::depth::DepthMap;
use super::{StageError, check_range, median_in_place, sampled_quantiles};
use crate::meta::Geometry;

mod levels;
mod line;
mod runs;
/// Synthetic grooves and noise shared by the depth, wall and orientation tests.
#[cfg(test)]
pub(crate) mod test_support;
#[cfg(test)]
#[allow(clippy::unwrap_used)] // Tests fail loudly on purpose.
mod tests;

use levels::*;
use line::*;
use runs::*;

/// Which wall of the groove.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum WallSide {
    /// The wall at smaller y (top of the image): depth grows with y.
    Left,
    /// The wall at larger y (bottom of the image): depth shrinks with y.
    Right,
}

/// A line along one wall: a row per column (NaN = void), at a known depth when it is an iso-depth stripe.
#[derive(Clone, Debug, PartialEq)]
pub struct WallLine {
    /// The wall it lies on.
    pub side: WallSide,
    /// Row (y) per column; NaN where unknown.
    pub rows: Vec<f32>,
    /// Half-height of the wall band about the line, per column (px); used for neighbourhoods.
    pub half_width_px: Vec<f32>,
    /// True depth from the optical centre (µm) when the line is an iso-depth contour (dual focus).
    pub depth_um: Option<f64>,
    /// Distance used to back-project its pixels, X = x·d/f (µm). Under a cover glass this is
    /// the true depth minus the glass's focus shift; elsewhere it equals the depth.
    pub projection_depth_um: Option<f64>,
    /// Columns whose row was filled from a fitted line (voids).
    pub filled: Vec<bool>,
}

/// How [`find_walls`] finds each column's wall bands on the depth map.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WallMethod {
    /// Iso-depth levels: the groove's inside is the longest run of rows deeper than half the
    /// groove depth; each wall runs from the land level to the bottom level about its
    /// mid-depth crossing. Robust to the depth map's noise and to a smooth, rounded profile.
    #[default]
    DepthLevels,
    /// Runs of rows whose slope |∂Z/∂Y| exceeds `min_slope`, the longest rising run followed by
    /// a falling one (the first method; breaks up where noise bends the slope).
    SlopeRuns,
}

/// Knobs of [`find_walls`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WallParams {
    #[doc = knob!("walls.method")]
    pub method: WallMethod,
    #[doc = knob!("walls.min_slope")]
    pub min_slope: f32,
    #[doc = knob!("walls.trim_px")]
    ///
    /// Keeps edge pixels out of the fits.
    pub trim_px: usize,
    #[doc = knob!("walls.smooth_px")]
    ///
    /// Also the half-span of the central difference along y.
    pub smooth_px: usize,
    #[doc = knob!("walls.column_window_px")]
    ///
    /// Rejects spurious bands.
    pub column_window_px: usize,
}

impl Default for WallParams {
    fn default() -> Self {
        Self {
            method: WallMethod::DepthLevels,
            min_slope: 0.4,
            trim_px: 6,
            smooth_px: 3,
            column_window_px: 31,
        }
    }
}

/// Stage name used in errors.
const STAGE: &str = "walls";
/// Runs of one sign separated by at most this many non-wall rows are merged (px).
const MAX_GAP_PX: usize = 3;
/// Runs shorter than this are noise, not walls (px).
const MIN_RUN_PX: usize = 8;
/// A column's band is kept when both its ends lie within this of the local median band (px)...
const MIN_TOLERANCE_PX: f32 = 3.0;
/// ... or within this share of the median band height, whichever is larger.
const TOLERANCE_SHARE: f32 = 0.25;
/// The local median needs bands in at least this share of the window's columns.
const MIN_WINDOW_SHARE: f32 = 0.25;
/// Quantile of the map's depths taken as the land level when the walls are found by depth
/// levels (the land covers a large share of the view)...
const LAND_QUANTILE: f64 = 0.05;
/// ... and as the bottom level (a narrow flat bottom, or none, covers only a few per cent).
const BOTTOM_QUANTILE: f64 = 0.98;
/// Most depths sampled for those levels and for the noise.
const LEVEL_SAMPLES: usize = 65_536;
/// A wall band is measured between this share of the groove depth below the land and the same
/// share above the bottom (clear of the noise at either level).
const LAND_SHARE: f32 = 0.15;
/// Land and bottom levels closer than this many times the map's noise: no groove.
const MIN_DEPTH_NOISE_RATIO: f32 = 10.0;

impl WallParams {
    /// Checks every wall knob.
    ///
    /// # Errors
    /// [`StageError::InvalidParam`] naming the first bad key.
    pub fn validate(&self) -> Result<(), StageError> {
        let p = self;
        check_range("walls.min_slope", f64::from(p.min_slope), 0.0, 1e6)?;
        let too_big = |name: &str, v: usize, max: usize| {
            (v > max).then(|| StageError::InvalidParam {
                name: name.into(),
                problem: format!("{v} is above {max}"),
            })
        };
        if let Some(e) = too_big("walls.trim_px", p.trim_px, 10_000)
            .or_else(|| too_big("walls.smooth_px", p.smooth_px, 100))
            .or_else(|| too_big("walls.column_window_px", p.column_window_px, 10_001))
        {
            return Err(e);
        }
        if p.column_window_px == 0 {
            return Err(StageError::InvalidParam {
                name: "walls.column_window_px".into(),
                problem: "must be at least 1".into(),
            });
        }
        Ok(())
    }
}

/// Finds the left and right walls in a depth map: one [`WallLine`] per wall (centre of the band).
///
/// The map is smoothed by a NaN-aware box of half-side `smooth_px`. With
/// [`WallMethod::DepthLevels`] (the default) the land and bottom levels are the 5th and 98th
/// percentiles of the smoothed depths (no walls when they are within 10× the map's noise of
/// each other); in each column the longest run of rows deeper than mid-depth is the groove's
/// inside, each wall is centred on its mid-depth crossing, and its band reaches the land and
/// bottom levels (measured on the shorter complete side, between 15% and 85% of the depth).
/// With [`WallMethod::SlopeRuns`] the map is differenced along y over ±`smooth_px` rows and
/// turned into the physical slope ∂Z/∂Y; in each column, rows with ∂Z/∂Y > `min_slope` (left
/// wall) or < −`min_slope` (right wall) form runs, and the groove is the longest rising run
/// followed directly by a falling one. A column's band is kept only when it
/// agrees with the median band over `column_window_px` nearby columns; the rest are voids,
/// filled by interpolation (`filled`). Bands lose `trim_px` rows at each end. Walls that are
/// found nowhere are left out of the result (Left first).
///
/// # Errors
/// [`StageError`] when no wall can be found, on invalid params or an inconsistent map.
pub fn find_walls(
    depth: &DepthMap,
    geom: &Geometry,
    params: &WallParams,
) -> Result<Vec<WallLine>, StageError> {
    params.validate()?;
    check_range("geometry.focal_px", geom.focal_px, 1e-9, 1e12)?;
    let z = &depth.z_um;
    let (width, height) = (z.width, z.height);
    if width == 0 || height == 0 || z.data.len() != width * height {
        return Err(StageError::BadInput {
            stage: STAGE,
            problem: format!(
                "depth map of {width}x{height} holds {} values",
                z.data.len()
            ),
        });
    }
    let zs = smooth_nan(&z.data, width, height, params.smooth_px);
    let bands: Vec<[Option<(f32, f32)>; 2]> = match params.method {
        WallMethod::DepthLevels => {
            let noise = depth_noise_um(&z.data, width);
            let Some(levels) = depth_levels(&zs, noise) else {
                return Err(StageError::NotFound {
                    stage: STAGE,
                    problem: format!(
                        "the {width}x{height} depth map has no groove: its depths span less \
                         than {MIN_DEPTH_NOISE_RATIO} × its noise ({noise:.2} µm)"
                    ),
                });
            };
            // Rows to µm across the groove, at the mean of the two levels.
            let um_per_row = (f64::from(levels.0 + levels.1) / 2.0 / geom.focal_px) as f32;
            (0..width)
                .into_par_iter()
                .map(|x| {
                    column_bands_by_level(
                        &zs,
                        (width, height),
                        x,
                        levels,
                        um_per_row,
                        params.min_slope,
                    )
                })
                .collect()
        }
        WallMethod::SlopeRuns => {
            let cy = (height as f64 - 1.0) / 2.0;
            let slope = slope_map(
                &zs,
                width,
                height,
                geom.focal_px,
                cy,
                params.smooth_px.max(1),
            );
            (0..width)
                .into_par_iter()
                .map(|x| column_bands(&column_runs(&slope, width, height, x, params.min_slope)))
                .collect()
        }
    };
    let mut lines = Vec::new();
    for (i, side) in [WallSide::Left, WallSide::Right].into_iter().enumerate() {
        let (tops, bottoms): (Vec<f32>, Vec<f32>) = bands
            .iter()
            .map(|b| b.get(i).copied().flatten().unwrap_or((f32::NAN, f32::NAN)))
            .unzip();
        let kept = reject_spurious(&tops, &bottoms, params.column_window_px);
        if let Some(line) = build_line(side, &kept, params.trim_px) {
            lines.push(line);
        }
    }
    if lines.is_empty() {
        return Err(StageError::NotFound {
            stage: STAGE,
            problem: format!(
                "no wall band as steep as |dZ/dY| = {} in any column of the {width}x{height} depth map",
                params.min_slope
            ),
        });
    }
    Ok(lines)
}
