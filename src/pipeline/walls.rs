//! Wall lines: where each groove wall lies in every column, found from the depth map (depth path) or stripes (dual focus).

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::depth::DepthMap;
use super::{StageError, check_range, sampled_quantiles};
use crate::io::Geometry;

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
    /// How the wall bands are found.
    pub method: WallMethod,
    /// |∂Z/∂Y| above this marks a wall pixel (45° walls give 1); with `depth_levels`, the
    /// least mean slope of a wall band.
    pub min_slope: f32,
    /// Rows trimmed from each end of a wall band, px (keeps edge pixels out of fits).
    pub trim_px: usize,
    /// Half-side of the box that smooths the depth map before differencing, px; also the
    /// half-span of the central difference along y.
    pub smooth_px: usize,
    /// Columns over which the median band is taken to reject spurious bands (odd, px).
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

/// A run of wall rows in one column, `top..=bottom`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Run {
    sign: i8,
    top: usize,
    bottom: usize,
}

impl Run {
    fn len(self) -> usize {
        self.bottom + 1 - self.top
    }
}

/// Checks the params.
fn validate(p: &WallParams) -> Result<(), StageError> {
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

/// Box mean of half-side `r` that ignores NaN (NaN where the box holds no finite value).
fn smooth_nan(z: &[f32], width: usize, height: usize, r: usize) -> Vec<f32> {
    // Horizontal running sums per row: (Σz, count).
    let mut hsum = vec![0.0_f64; width * height];
    let mut hcnt = vec![0.0_f32; width * height];
    hsum.par_chunks_mut(width)
        .zip(hcnt.par_chunks_mut(width))
        .zip(z.par_chunks(width))
        .for_each(|((sum, cnt), row)| {
            let (mut s, mut c) = (0.0_f64, 0.0_f32);
            let val = |x: usize| row.get(x).copied().filter(|v| v.is_finite());
            for x in 0..r.min(width) {
                if let Some(v) = val(x) {
                    s += f64::from(v);
                    c += 1.0;
                }
            }
            for x in 0..width {
                if let Some(v) = val(x + r) {
                    s += f64::from(v);
                    c += 1.0;
                }
                if x > r
                    && let Some(v) = val(x - r - 1)
                {
                    s -= f64::from(v);
                    c -= 1.0;
                }
                if let (Some(o), Some(n)) = (sum.get_mut(x), cnt.get_mut(x)) {
                    *o = s;
                    *n = c;
                }
            }
        });
    let mut out = vec![f32::NAN; width * height];
    out.par_chunks_mut(width).enumerate().for_each(|(y, row)| {
        let lo = y.saturating_sub(r);
        let hi = (y + r).min(height - 1);
        for (x, o) in row.iter_mut().enumerate() {
            let (mut s, mut c) = (0.0_f64, 0.0_f32);
            for yy in lo..=hi {
                let i = yy * width + x;
                if let (Some(&hs), Some(&hc)) = (hsum.get(i), hcnt.get(i)) {
                    s += hs;
                    c += hc;
                }
            }
            if c > 0.5 {
                *o = (s / f64::from(c)) as f32;
            }
        }
    });
    out
}

/// ∂Z/∂Y (physical, dimensionless) per pixel from the smoothed depth `zs`, by a central
/// difference of half-span `h` rows. With Y = (y − cy)·Z/f, dY/dy = (Z + (y − cy)·dZ/dy)/f.
fn slope_map(zs: &[f32], width: usize, height: usize, f: f64, cy: f64, h: usize) -> Vec<f32> {
    let mut out = vec![f32::NAN; width * height];
    out.par_chunks_mut(width).enumerate().for_each(|(y, row)| {
        if y < h || y + h >= height {
            return;
        }
        let (up, mid, down) = ((y - h) * width, y * width, (y + h) * width);
        for (x, o) in row.iter_mut().enumerate() {
            let (Some(&a), Some(&z), Some(&b)) =
                (zs.get(up + x), zs.get(mid + x), zs.get(down + x))
            else {
                continue;
            };
            let dz = (f64::from(b) - f64::from(a)) / (2.0 * h as f64);
            let dy = f64::from(z) + (y as f64 - cy) * dz;
            if dy.is_finite() && dy > 0.0 {
                *o = (f * dz / dy) as f32;
            }
        }
    });
    out
}

/// Runs of wall rows in column `x`. Runs of one sign merge across at most `MAX_GAP_PX` known
/// non-wall rows; rows of unknown slope (NaN: holes in the map) neither count nor break a run.
fn column_runs(slope: &[f32], width: usize, height: usize, x: usize, min_slope: f32) -> Vec<Run> {
    let mut runs: Vec<Run> = Vec::new();
    let mut flat = 0_usize;
    for y in 0..height {
        let s = slope.get(y * width + x).copied().unwrap_or(f32::NAN);
        let sign = if s.is_nan() {
            continue;
        } else if s > min_slope {
            1
        } else if s < -min_slope {
            -1
        } else {
            flat += 1;
            continue;
        };
        match runs.last_mut() {
            Some(last) if last.sign == sign && flat <= MAX_GAP_PX => last.bottom = y,
            _ => runs.push(Run {
                sign,
                top: y,
                bottom: y,
            }),
        }
        flat = 0;
    }
    runs.retain(|r| r.len() >= MIN_RUN_PX);
    runs
}

/// The groove in one column: the longest consecutive (left = rising, right = falling) pair of
/// runs, else the single longest run. Returns [left, right] bands as (top, bottom) rows.
fn column_bands(runs: &[Run]) -> [Option<(f32, f32)>; 2] {
    let band = |r: Run| Some((r.top as f32, r.bottom as f32));
    let best_pair = runs
        .windows(2)
        .filter_map(|w| match w {
            [l, r] if l.sign > 0 && r.sign < 0 => Some((*l, *r)),
            _ => None,
        })
        .max_by_key(|(l, r)| l.len() + r.len());
    if let Some((l, r)) = best_pair {
        return [band(l), band(r)];
    }
    match runs.iter().max_by_key(|r| r.len()) {
        Some(&r) if r.sign > 0 => [band(r), None],
        Some(&r) => [None, band(r)],
        None => [None, None],
    }
}

/// Depth levels of the land and of the groove bottom over a smoothed depth map: the
/// [`LAND_QUANTILE`] and [`BOTTOM_QUANTILE`] quantiles of its finite values (sampled).
/// None when they are less than [`MIN_DEPTH_NOISE_RATIO`] × the map's noise apart (no groove).
fn depth_levels(zs: &[f32], noise_um: f32) -> Option<(f32, f32)> {
    let (lo, hi) = sampled_quantiles(zs, LAND_QUANTILE, BOTTOM_QUANTILE, LEVEL_SAMPLES)?;
    (hi - lo > MIN_DEPTH_NOISE_RATIO * noise_um && hi > lo).then_some((lo, hi))
}

/// Noise of a depth map (µm): 1.4826 × the median |Z(x, y + 1) − Z(x, y)| / √2 over finite
/// pairs (sampled). Walls cover a minority of the rows, so their slope barely moves the median.
fn depth_noise_um(z: &[f32], width: usize) -> f32 {
    let pairs = z.len().saturating_sub(width);
    let stride = pairs.div_ceil(LEVEL_SAMPLES).max(1);
    let mut d: Vec<f32> = (0..pairs)
        .step_by(stride)
        .filter_map(|i| {
            let (a, b) = (*z.get(i)?, *z.get(i + width)?);
            let d = (b - a).abs();
            d.is_finite().then_some(d)
        })
        .collect();
    median(&mut d).map_or(0.0, |m| 1.4826 * m / std::f32::consts::SQRT_2)
}

/// The groove in one column of the smoothed depth map by iso-depth levels (land, bottom): the
/// longest run of rows deeper than mid-depth is the groove's inside; each wall's band is found
/// between the rows where the profile is [`LAND_SHARE`] of the depth below the land and above
/// the bottom, walking outward and inward from the mid-depth crossing, and widened to the whole
/// wall (a straight wall spans 1/(1 − 2·`LAND_SHARE`) times that). A band whose mean slope
/// ΔZ/ΔY (`um_per_row` converts rows) is below `min_slope`, or shorter than [`MIN_RUN_PX`],
/// is left out. Returns [left, right] bands as (top, bottom) rows.
fn column_bands_by_level(
    zs: &[f32],
    (width, height): (usize, usize),
    x: usize,
    (land, bottom): (f32, f32),
    um_per_row: f32,
    min_slope: f32,
) -> [Option<(f32, f32)>; 2] {
    let depth = bottom - land;
    let at = |y: usize| zs.get(y * width + x).copied().unwrap_or(f32::NAN);
    let mid = land + 0.5 * depth;
    let shallow = land + LAND_SHARE * depth;
    let deep = bottom - LAND_SHARE * depth;
    // Longest run of rows deeper than mid-depth (NaN rows neither count nor break it).
    let mut best: Option<(usize, usize)> = None;
    let mut cur: Option<(usize, usize)> = None;
    for y in 0..height {
        let z = at(y);
        if z.is_nan() {
            continue;
        }
        if z > mid {
            let run = cur.map_or((y, y), |(a, _)| (a, y));
            cur = Some(run);
            if best.is_none_or(|(ba, bb)| run.1 - run.0 > bb - ba) {
                best = Some(run);
            }
        } else {
            cur = None;
        }
    }
    let Some((a, b)) = best else {
        return [None, None];
    };
    // From row `from`, steps up or down while the next row is finite and `keep`s it: the last
    // row, and whether the walk ended on a level (not on a hole or the image edge).
    let walk = |from: usize, up: bool, keep: &dyn Fn(f32) -> bool| -> (usize, bool) {
        let mut y = from;
        loop {
            let next = if up {
                y.checked_sub(1)
            } else {
                (y + 1 < height).then_some(y + 1)
            };
            match next.map(|n| (n, at(n))) {
                Some((n, z)) if !z.is_nan() && keep(z) => y = n,
                Some((_, z)) => return (y, !z.is_nan()),
                None => return (y, false),
            }
        }
    };
    // Sub-row mid-depth crossing between rows `outer` (shallower) and `inner` (deeper).
    let crossing = |outer: Option<usize>, inner: usize| -> f32 {
        match outer.map(|o| (o, at(o))) {
            Some((o, zo)) if zo.is_finite() && at(inner) > zo => {
                let t = ((mid - zo) / (at(inner) - zo)).clamp(0.0, 1.0);
                o as f32 + t * (inner as f32 - o as f32)
            }
            _ => inner as f32,
        }
    };
    // The band about a wall's centre `c` from its two measured sides (rows from the centre to
    // the land and to the bottom levels; None when a hole or the edge cut that side short): a
    // straight wall is symmetric about its mid-depth row, so the shorter complete side sets it.
    let band = |c: f32, sides: [Option<f32>; 2]| -> Option<(f32, f32)> {
        let h = sides.into_iter().flatten().reduce(f32::min)?.max(0.5);
        let slope = (0.5 - LAND_SHARE) * depth / (h * um_per_row);
        let half = h / (1.0 - 2.0 * LAND_SHARE);
        (2.0 * half >= MIN_RUN_PX as f32 && slope >= min_slope).then_some((c - half, c + half))
    };
    let side = |(row, complete): (usize, bool), c: f32| complete.then(|| (row as f32 - c).abs());
    // Left (upper) wall: its mid-depth crossing just above row a.
    let cl = crossing(a.checked_sub(1), a);
    let left = band(
        cl,
        [
            side(walk(a, true, &|z| z > shallow), cl),
            side(walk(a, false, &|z| z < deep), cl),
        ],
    );
    // Right (lower) wall: its crossing just below row b.
    let cr = crossing((b + 1 < height).then_some(b + 1), b);
    let right = band(
        cr,
        [
            side(walk(b, true, &|z| z < deep), cr),
            side(walk(b, false, &|z| z > shallow), cr),
        ],
    );
    [left, right]
}

/// Median of the finite values (None when there are none); reorders `v`.
fn median(v: &mut [f32]) -> Option<f32> {
    if v.is_empty() {
        return None;
    }
    let mid = v.len() / 2;
    let (_, m, _) = v.select_nth_unstable_by(mid, f32::total_cmp);
    Some(*m)
}

/// Keeps each column's band only when it agrees with the median band of the nearby columns.
fn reject_spurious(tops: &[f32], bottoms: &[f32], window: usize) -> Vec<Option<(f32, f32)>> {
    let n = tops.len();
    let half = window / 2;
    (0..n)
        .into_par_iter()
        .map_init(
            || (Vec::new(), Vec::new()),
            |(ts, bs), x| {
                let (Some(&t), Some(&b)) = (tops.get(x), bottoms.get(x)) else {
                    return None;
                };
                if !(t.is_finite() && b.is_finite()) {
                    return None;
                }
                let lo = x.saturating_sub(half);
                let hi = (x + half).min(n - 1);
                ts.clear();
                bs.clear();
                for j in lo..=hi {
                    if let (Some(&tj), Some(&bj)) = (tops.get(j), bottoms.get(j))
                        && tj.is_finite()
                        && bj.is_finite()
                    {
                        ts.push(tj);
                        bs.push(bj);
                    }
                }
                if (ts.len() as f32) < MIN_WINDOW_SHARE * (hi + 1 - lo) as f32 {
                    return None;
                }
                let (mt, mb) = (median(ts)?, median(bs)?);
                let tol = MIN_TOLERANCE_PX.max(TOLERANCE_SHARE * (mb - mt));
                ((t - mt).abs() <= tol && (b - mb).abs() <= tol).then_some((t, b))
            },
        )
        .collect()
}

/// Builds a [`WallLine`] from per-column bands: trims, then fills voids by linear
/// interpolation (nearest value past the ends). None when no column has a band.
fn build_line(side: WallSide, bands: &[Option<(f32, f32)>], trim_px: usize) -> Option<WallLine> {
    let trim = trim_px as f32;
    let mut rows: Vec<f32> = Vec::with_capacity(bands.len());
    let mut half: Vec<f32> = Vec::with_capacity(bands.len());
    for b in bands {
        let (r, h) = match *b {
            Some((t, btm)) if (btm - t) / 2.0 - trim >= 0.0 => {
                ((t + btm) / 2.0, (btm - t) / 2.0 - trim)
            }
            _ => (f32::NAN, f32::NAN),
        };
        rows.push(r);
        half.push(h);
    }
    let known: Vec<usize> = (0..rows.len())
        .filter(|&x| rows.get(x).is_some_and(|r| r.is_finite()))
        .collect();
    let (&first, &last) = (known.first()?, known.last()?);
    let mut filled = vec![false; rows.len()];
    let mut k = 0; // index into `known` of the last known column at or before x
    for x in 0..rows.len() {
        if rows.get(x).is_some_and(|r| r.is_finite()) {
            while known.get(k + 1).is_some_and(|&j| j <= x) {
                k += 1;
            }
            continue;
        }
        let (a, b) = if x < first {
            (first, first)
        } else if x > last {
            (last, last)
        } else {
            (
                known.get(k).copied().unwrap_or(first),
                known.get(k + 1).copied().unwrap_or(last),
            )
        };
        let t = if b > a {
            (x - a) as f32 / (b - a) as f32
        } else {
            0.0
        };
        let lerp = |v: &[f32]| {
            let (va, vb) = (
                v.get(a).copied().unwrap_or(f32::NAN),
                v.get(b).copied().unwrap_or(f32::NAN),
            );
            va + (vb - va) * t
        };
        let (r, h) = (lerp(&rows), lerp(&half));
        if let (Some(ro), Some(ho), Some(fo)) =
            (rows.get_mut(x), half.get_mut(x), filled.get_mut(x))
        {
            *ro = r;
            *ho = h;
            *fo = true;
        }
    }
    Some(WallLine {
        side,
        rows,
        half_width_px: half,
        depth_um: None,
        projection_depth_um: None,
        filled,
    })
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
    validate(params)?;
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

/// Synthetic grooves and noise shared by the depth, wall and orientation tests.
#[cfg(test)]
pub(crate) mod test_support {
    use super::{DepthMap, WallSide};
    use crate::image::Image;
    use crate::io::Geometry;

    /// The paper's optics: 0.39 µm/px, 4 mm working distance, 0.78 µm frame step.
    pub(crate) fn paper_geometry() -> Geometry {
        Geometry {
            focal_px: 4000.0 / 0.39,
            pixel_pitch_um: 0.39,
            working_distance_um: 4000.0,
            frame_step_um: 0.78,
        }
    }

    /// A small deterministic generator (xorshift64*) with uniform and Gaussian draws.
    pub(crate) struct Rng(u64);

    impl Rng {
        pub(crate) fn new(seed: u64) -> Self {
            Self(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
        }

        /// Uniform in [0, 1).
        pub(crate) fn uniform(&mut self) -> f64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
        }

        /// Standard normal (Box–Muller).
        pub(crate) fn gauss(&mut self) -> f64 {
            let u1 = self.uniform().max(1e-300);
            let u2 = self.uniform();
            (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
        }
    }

    /// A V-groove with a flat bottom in a flat land, displaced laterally by d(X):
    /// Z = land + clamp(depth + bottom_half − |Y − d(X)|, 0, depth) (45° walls).
    pub(crate) struct Groove {
        pub(crate) geom: Geometry,
        pub(crate) land_um: f64,
        pub(crate) depth_um: f64,
        pub(crate) bottom_half_um: f64,
        pub(crate) d: Box<dyn Fn(f64) -> f64>,
    }

    impl Groove {
        /// A 60 µm deep groove with a 10 µm bottom at the working distance.
        pub(crate) fn new(geom: Geometry, d: impl Fn(f64) -> f64 + 'static) -> Self {
            Self {
                geom,
                land_um: geom.working_distance_um,
                depth_um: 60.0,
                bottom_half_um: 5.0,
                d: Box::new(d),
            }
        }

        /// Z (µm) at the physical point (X, Y).
        pub(crate) fn z_at(&self, x_um: f64, y_um: f64) -> f64 {
            let inner = self.depth_um + self.bottom_half_um - (y_um - (self.d)(x_um)).abs();
            self.land_um + inner.clamp(0.0, self.depth_um)
        }

        /// Z seen at pixel (x, y): the fixed point of Z = z_at((x − cx)·Z/f, (y − cy)·Z/f).
        pub(crate) fn z_px(&self, x: f64, y: f64, width: usize, height: usize) -> f64 {
            self.z_px_from(x, y, width, height, 0.0)
        }

        /// Z seen at pixel (x, y) with the camera moved to X = `cam_um`.
        pub(crate) fn z_px_from(
            &self,
            x: f64,
            y: f64,
            width: usize,
            height: usize,
            cam_um: f64,
        ) -> f64 {
            let f = self.geom.focal_px;
            let (px, py) = (
                (x - (width as f64 - 1.0) / 2.0) / f,
                (y - (height as f64 - 1.0) / 2.0) / f,
            );
            let mut z = self.land_um;
            for _ in 0..40 {
                z = self.z_at(px * z + cam_um, py * z);
            }
            z
        }

        /// The rendered depth map.
        pub(crate) fn depth_map(&self, width: usize, height: usize) -> DepthMap {
            DepthMap {
                z_um: Image::from_fn(width, height, |x, y| {
                    self.z_px(x as f64, y as f64, width, height) as f32
                }),
                variance: Image::zeros(width, height),
                frame_index: 0,
                warnings: Vec::new(),
            }
        }

        /// The wall band in column x: (centre row, half height) in px, from the rows where the
        /// wall meets the land and the bottom.
        pub(crate) fn wall_band_px(
            &self,
            side: WallSide,
            x: usize,
            width: usize,
            height: usize,
        ) -> (f64, f64) {
            let f = self.geom.focal_px;
            let (cx, cy) = ((width as f64 - 1.0) / 2.0, (height as f64 - 1.0) / 2.0);
            let row_at = |z: f64, off: f64| {
                let big_x = (x as f64 - cx) * z / f;
                cy + f * ((self.d)(big_x) + off) / z
            };
            let (outer, inner) = (self.depth_um + self.bottom_half_um, self.bottom_half_um);
            let (a, b) = match side {
                WallSide::Left => (
                    row_at(self.land_um, -outer),
                    row_at(self.land_um + self.depth_um, -inner),
                ),
                WallSide::Right => (
                    row_at(self.land_um + self.depth_um, inner),
                    row_at(self.land_um, outer),
                ),
            };
            ((a + b) / 2.0, (b - a).abs() / 2.0)
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // Tests fail loudly on purpose.
mod tests {
    use super::test_support::{Groove, Rng, paper_geometry};
    use super::*;

    /// Checks each line against the true band: centre within `tol_px` in at least `share` of
    /// the columns, half height close to the true one less the trim.
    fn check_against_truth(
        lines: &[WallLine],
        g: &Groove,
        w: usize,
        h: usize,
        tol_px: f64,
        share: f64,
    ) {
        assert_eq!(lines.len(), 2);
        assert_eq!(lines[0].side, WallSide::Left);
        assert_eq!(lines[1].side, WallSide::Right);
        let trim = WallParams::default().trim_px as f64;
        for line in lines {
            assert_eq!(line.rows.len(), w);
            let mut good = 0;
            let mut bad = Vec::new();
            for x in 0..w {
                let (row, hw) = g.wall_band_px(line.side, x, w, h);
                let got = f64::from(line.rows[x]);
                assert!(got.is_finite());
                if (got - row).abs() <= tol_px
                    && (f64::from(line.half_width_px[x]) - (hw - trim)).abs() <= 4.0
                {
                    good += 1;
                } else if bad.len() < 10 {
                    bad.push(format!(
                        "x {x}: row {got} vs {row}, hw {} vs {}",
                        line.half_width_px[x],
                        hw - trim
                    ));
                }
            }
            assert!(
                good as f64 >= share * w as f64,
                "{:?}: {good} of {w}; {bad:?}",
                line.side
            );
        }
    }

    #[test]
    fn finds_both_walls_of_a_wiggling_groove() {
        let geom = paper_geometry();
        let g = Groove::new(geom, |x_um| {
            15.0 * (std::f64::consts::TAU * x_um / 120.0).sin()
        });
        let (w, h) = (400, 600);
        let depth = g.depth_map(w, h);
        for method in [WallMethod::DepthLevels, WallMethod::SlopeRuns] {
            let params = WallParams {
                method,
                ..WallParams::default()
            };
            let lines = find_walls(&depth, &geom, &params).unwrap();
            check_against_truth(&lines, &g, w, h, 1.0, 0.98);
            assert!(
                lines
                    .iter()
                    .all(|l| l.depth_um.is_none() && l.projection_depth_um.is_none())
            );
        }
    }

    #[test]
    fn depth_levels_find_the_walls_of_a_blurred_noisy_map() {
        // What the Kalman filter gives: the groove profile rounded by a wide blur, noise of a
        // few µm, and deep spikes on the bottom.
        let geom = paper_geometry();
        let g = Groove::new(geom, |x_um| {
            8.0 * (std::f64::consts::TAU * x_um / 140.0).sin()
        });
        let (w, h) = (400, 600);
        let sharp = g.depth_map(w, h);
        let mut depth = sharp.clone();
        depth.z_um.data = smooth_nan(&sharp.z_um.data, w, h, 12);
        let mut rng = Rng::new(11);
        for v in &mut depth.z_um.data {
            *v += 2.0 * rng.gauss() as f32;
        }
        for k in 0..12 {
            let (cx, cy) = (20 + 33 * k, 300 + (k % 3) * 6);
            for y in cy - 4..cy + 4 {
                for x in cx - 4..cx + 4 {
                    depth.z_um.data[y * w + x] += 25.0;
                }
            }
        }
        let lines = find_walls(&depth, &geom, &WallParams::default()).unwrap();
        check_against_truth(&lines, &g, w, h, 3.0, 0.95);
    }

    #[test]
    fn rejects_noise_dust_and_fills_voids() {
        let geom = paper_geometry();
        let g = Groove::new(geom, |x_um| {
            10.0 * (std::f64::consts::TAU * x_um / 150.0).sin()
        });
        let (w, h) = (400, 600);
        let mut depth = g.depth_map(w, h);
        let mut rng = Rng::new(3);
        for v in &mut depth.z_um.data {
            *v += rng.gauss() as f32;
        }
        // A dust particle: a raised 25×25 patch on the land; a hole; a dead stripe of columns.
        for y in 30..55 {
            for x in 100..125 {
                depth.z_um.data[y * w + x] -= 40.0;
            }
        }
        for y in 280..300 {
            for x in 300..330 {
                depth.z_um.data[y * w + x] = f32::NAN;
            }
        }
        for y in 0..h {
            for x in 200..212 {
                depth.z_um.data[y * w + x] = f32::NAN;
            }
        }
        let lines = find_walls(&depth, &geom, &WallParams::default()).unwrap();
        check_against_truth(&lines, &g, w, h, 2.0, 0.95);
        for line in &lines {
            assert!(line.filled[205], "{:?}", line.side);
            assert!(!line.filled[50], "{:?}", line.side);
        }
    }

    #[test]
    fn flat_map_has_no_walls_and_params_are_checked() {
        let geom = paper_geometry();
        let depth = DepthMap {
            z_um: crate::image::Image::filled(50, 80, 4000.0),
            variance: crate::image::Image::zeros(50, 80),
            frame_index: 0,
            warnings: Vec::new(),
        };
        assert!(matches!(
            find_walls(&depth, &geom, &WallParams::default()),
            Err(StageError::NotFound { .. })
        ));
        let bad = WallParams {
            min_slope: f32::NAN,
            ..WallParams::default()
        };
        assert!(matches!(
            find_walls(&depth, &geom, &bad),
            Err(StageError::InvalidParam { .. })
        ));
        let bad = WallParams {
            column_window_px: 0,
            ..WallParams::default()
        };
        assert!(matches!(
            find_walls(&depth, &geom, &bad),
            Err(StageError::InvalidParam { .. })
        ));
    }

    #[test]
    fn a_single_visible_wall_is_still_returned() {
        let geom = paper_geometry();
        let g = Groove::new(geom, |_| 0.0);
        let (w, h) = (120, 600);
        let full = g.depth_map(w, h);
        // Keep only the upper 280 rows: land, the left wall and part of the bottom.
        let top = 280;
        let depth = DepthMap {
            z_um: crate::image::Image::from_vec(w, top, full.z_um.data[..w * top].to_vec())
                .unwrap(),
            variance: crate::image::Image::zeros(w, top),
            frame_index: 0,
            warnings: Vec::new(),
        };
        let lines = find_walls(&depth, &geom, &WallParams::default()).unwrap();
        assert_eq!(lines.len(), 1);
        assert_eq!(lines[0].side, WallSide::Left);
    }
}
