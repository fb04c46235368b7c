//! Walls by depth levels: the land and bottom levels of the map, and each column's wall bands about its mid-depth crossings.

use super::*;

/// Depth levels of the land and of the groove bottom over a smoothed depth map: the
/// [`LAND_QUANTILE`] and [`BOTTOM_QUANTILE`] quantiles of its finite values (sampled).
/// None when they are less than [`MIN_DEPTH_NOISE_RATIO`] × the map's noise apart (no groove).
pub(super) fn depth_levels(zs: &[f32], noise_um: f32) -> Option<(f32, f32)> {
    let (lo, hi) = sampled_quantiles(zs, LAND_QUANTILE, BOTTOM_QUANTILE, LEVEL_SAMPLES)?;
    (hi - lo > MIN_DEPTH_NOISE_RATIO * noise_um && hi > lo).then_some((lo, hi))
}

/// Noise of a depth map (µm): 1.4826 × the median |Z(x, y + 1) − Z(x, y)| / √2 over finite
/// pairs (sampled). Walls cover a minority of the rows, so their slope barely moves the median.
pub(super) fn depth_noise_um(z: &[f32], width: usize) -> f32 {
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
    median_in_place(&mut d).map_or(0.0, |m| 1.4826 * m / std::f32::consts::SQRT_2)
}

/// The groove in one column of the smoothed depth map by iso-depth levels (land, bottom): the
/// longest run of rows deeper than mid-depth is the groove's inside; each wall's band is found
/// between the rows where the profile is [`LAND_SHARE`] of the depth below the land and above
/// the bottom, walking outward and inward from the mid-depth crossing, and widened to the whole
/// wall (a straight wall spans 1/(1 − 2·`LAND_SHARE`) times that). A band whose mean slope
/// ΔZ/ΔY (`um_per_row` converts rows) is below `min_slope`, or shorter than [`MIN_RUN_PX`],
/// is left out. Returns [left, right] bands as (top, bottom) rows.
pub(super) fn column_bands_by_level(
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
