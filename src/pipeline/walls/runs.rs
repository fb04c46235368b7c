//! Walls by slope runs: the depth map smoothed, turned into the physical slope ∂Z/∂Y, and each column's runs of steep rows.

use super::*;

/// A run of wall rows in one column, `top..=bottom`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Run {
    pub(super) sign: i8,
    pub(super) top: usize,
    pub(super) bottom: usize,
}

impl Run {
    pub(super) fn len(self) -> usize {
        self.bottom + 1 - self.top
    }
}

/// Box mean of half-side `r` that ignores NaN (NaN where the box holds no finite value).
pub(super) fn smooth_nan(z: &[f32], width: usize, height: usize, r: usize) -> Vec<f32> {
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
pub(super) fn slope_map(
    zs: &[f32],
    width: usize,
    height: usize,
    f: f64,
    cy: f64,
    h: usize,
) -> Vec<f32> {
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
pub(super) fn column_runs(
    slope: &[f32],
    width: usize,
    height: usize,
    x: usize,
    min_slope: f32,
) -> Vec<Run> {
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
pub(super) fn column_bands(runs: &[Run]) -> [Option<(f32, f32)>; 2] {
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
