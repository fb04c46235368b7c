//! Sharp borders beyond the pixel grid: one smooth curve per border over the whole group,
//! fitted to where the border crosses pixel rows, so that samples whose border runs level
//! inside one row take their position from the crossings around them.
//!
//! A sharply focused, pixel-sampled border tells each column only the pair of rows it steps
//! between, and across a sample whose border stays inside one row every column says the same:
//! no fit of that sample alone can place it closer than a pixel. But the border is a smooth
//! function of groove position, and where consecutive columns step in different rows it
//! crosses the row centre between them: there its row is known to `slope/√12` (the crossing
//! lies somewhere in that column gap), far better than a pixel. So each column's step row is
//! found (where its grey level crosses the sample's threshold, the geometric mean of the fitted
//! levels, which a multiplicative texture does not cross; the crossing nearest the sample's fit),
//! every change between neighbouring columns is an observation of the curve at their midpoint
//! (a single column that steps out and back is noise and dropped), and a cubic B-spline in groove
//! position, knots every half sample, is fitted to them by weighted least squares — weights
//! `1/(slope²/12 + crossing_sigma²)` — together with `spline_smoothness·Σ(Δ³c)²`, which lets it
//! bend between crossings only as a smooth curve would, and each sample's own box average from
//! the border model (`anchor_sigma_px`) where no crossing lies within `ANCHOR_REACH` samples (a
//! border that crosses no row at all): elsewhere that average is biased toward the middle of the
//! rows the sample steps in, and the crossings place it better. (A border that only wobbles
//! about one row centre, by less than a pixel, crosses the same row both ways and shows nothing
//! of its amplitude, so such detail is lost either way.) When the border is blurred (the group's fitted edge spread above `hard_width_px`),
//! every column's own interpolated crossing is an observation instead. A second pass
//! down-weights observations the curve misses by far (Lorentzian); columns the dust check
//! rejected take no part. Each sample's border is the curve averaged over its stretch.

use super::EdgeParams;
use super::border::Border;
use super::geometry::FrameGeometry;
use super::profile::{OUTLIER_WEIGHT, SampleTask, lorentzian_weight};
use crate::image::Image;

/// Knots per output sample.
const KNOTS_PER_SAMPLE: f64 = 2.0;
/// Lorentzian σ (rows) of an observation's miss in the second pass.
const MISS_SIGMA_PX: f64 = 0.5;
/// Points per sample at which the fitted curve is averaged.
const BOX_POINTS: usize = 16;
/// Samples on each side within which a row crossing makes a level sample's own fit redundant.
const ANCHOR_REACH: usize = 2;
/// Share of the samples whose fitted edge spread, from the sharpest, is taken as the border's blur.
const BLUR_QUANTILE: f64 = 0.2;

/// One sample of a border, as the refinement needs it.
pub struct RefineSample<'a> {
    /// The stretch and the prediction.
    pub task: SampleTask<'a>,
    /// The sample's own fit (levels, width, offset from the prediction).
    pub fit: Border,
    /// The sample's border row from the fit (averaged over its stretch).
    pub row_px: f64,
    /// The reference frame's columns with their dust weights.
    pub column_weights: &'a [(usize, f32)],
}

/// A linear observation of the curve: `Σ basis·c = value` with a weight.
#[derive(Clone, Debug)]
struct Observation {
    /// First coefficient and the basis values (averaged for box observations).
    first: usize,
    basis: Vec<f64>,
    value: f64,
    weight: f64,
}

/// Uniform cubic B-spline basis at `t` (knot units): the first coefficient and four values.
fn basis(t: f64) -> Option<(usize, [f64; 4])> {
    let i = t.floor();
    let u = t - i;
    let (u2, u3) = (u * u, u * u * u);
    let first = usize::try_from(i as i64).ok()?;
    Some((
        first,
        [
            (1.0 - u) * (1.0 - u) * (1.0 - u) / 6.0,
            (3.0 * u3 - 6.0 * u2 + 4.0) / 6.0,
            (-3.0 * u3 + 3.0 * u2 + 3.0 * u + 1.0) / 6.0,
            u3 / 6.0,
        ],
    ))
}

/// A cubic B-spline in groove position.
struct Spline {
    s0: f64,
    knot: f64,
    len: usize,
    coef: Vec<f64>,
}

impl Spline {
    fn new(s_lo: f64, s_hi: f64, knot: f64) -> Option<Self> {
        let span = ((s_hi - s_lo) / knot).ceil();
        (span.is_finite() && span >= 1.0).then(|| {
            let len = span as usize + 5;
            Self {
                s0: s_lo - knot,
                knot,
                len,
                coef: vec![0.0; len],
            }
        })
    }

    /// A point observation at `s`.
    fn point(&self, s: f64) -> Option<(usize, Vec<f64>)> {
        let (i, b) = basis((s - self.s0) / self.knot)?;
        (i + 3 < self.len).then(|| (i, b.to_vec()))
    }

    /// The mean of the curve over `[lo, hi]` as one observation (basis averaged over points).
    fn boxed(&self, lo: f64, hi: f64) -> Option<(usize, Vec<f64>)> {
        let (first, _) = self.point(lo)?;
        let (last, _) = self.point(hi)?;
        let mut acc = vec![0.0; last + 4 - first];
        for k in 0..BOX_POINTS {
            let s = lo + (k as f64 + 0.5) / BOX_POINTS as f64 * (hi - lo);
            let (i, b) = self.point(s)?;
            for (p, v) in b.iter().enumerate() {
                if let Some(a) = acc.get_mut(i + p - first) {
                    *a += v / BOX_POINTS as f64;
                }
            }
        }
        Some((first, acc))
    }

    fn eval(&self, first: usize, basis: &[f64]) -> f64 {
        basis
            .iter()
            .enumerate()
            .map(|(p, b)| b * self.coef.get(first + p).copied().unwrap_or(0.0))
            .sum()
    }
}

/// A symmetric positive matrix of half-bandwidth `bw` (entries further than `bw` from the
/// diagonal are zero), its lower half stored by rows: row `i` holds columns `i − bw ..= i`.
struct Banded {
    n: usize,
    bw: usize,
    v: Vec<f64>,
}

impl Banded {
    fn zeros(n: usize, bw: usize) -> Self {
        Self {
            n,
            bw,
            v: vec![0.0; n * (bw + 1)],
        }
    }

    /// Where entry (i, j), `j ≤ i ≤ j + bw`, is stored.
    fn at(&self, i: usize, j: usize) -> usize {
        i * (self.bw + 1) + j + self.bw - i
    }

    /// Adds `x` to entry (i, j) of the lower half; an entry of the upper half (j > i) is the
    /// lower one's mirror and is skipped, as is one outside the band.
    fn add_lower(&mut self, i: usize, j: usize, x: f64) {
        if j <= i && i - j <= self.bw && i < self.n {
            let k = self.at(i, j);
            self.v[k] += x;
        }
    }

    fn get(&self, i: usize, j: usize) -> f64 {
        self.v[self.at(i, j)]
    }
}

/// Solves `a·x = b` by Cholesky in place, `a` banded: the dense algorithm with the sums over
/// entries outside the band (exact zeros, in the factor too) left out, so `O(n·bw²)` work and
/// `O(n·bw)` memory, and the same result to the bit (`tests::dense_cholesky_solve` is the
/// dense reference it is tested against).
fn cholesky_solve(a: &mut Banded, b: &mut [f64]) -> bool {
    let (n, bw) = (a.n, a.bw);
    for j in 0..n {
        let lo_j = j.saturating_sub(bw);
        let mut d = a.get(j, j);
        for k in lo_j..j {
            d -= a.get(j, k) * a.get(j, k);
        }
        if d.is_nan() || d <= 0.0 {
            return false;
        }
        let d = d.sqrt();
        let jj = a.at(j, j);
        a.v[jj] = d;
        for i in j + 1..n.min(j + bw + 1) {
            let mut s = a.get(i, j);
            for k in i.saturating_sub(bw)..j {
                s -= a.get(i, k) * a.get(j, k);
            }
            let ij = a.at(i, j);
            a.v[ij] = s / d;
        }
    }
    for i in 0..n {
        let lo = i.saturating_sub(bw);
        let mut s = b[i];
        for (k, bk) in b[lo..i].iter().enumerate() {
            s -= a.get(i, lo + k) * bk;
        }
        b[i] = s / a.get(i, i);
    }
    for i in (0..n).rev() {
        let mut s = b[i];
        for (k, bk) in b[i + 1..n.min(i + bw + 1)].iter().enumerate() {
            s -= a.get(i + 1 + k, i) * bk;
        }
        b[i] = s / a.get(i, i);
    }
    b.iter().all(|v| v.is_finite())
}

/// Weighted least squares of the observations plus the third-difference penalty; a second pass
/// down-weights observations missed by more than [`MISS_SIGMA_PX`].
fn solve(spline: &mut Spline, obs: &[Observation], smoothness: f64) -> bool {
    let m = spline.len;
    // A point observation spans 4 coefficients, a boxed one as many as its box covers, the
    // third-difference penalty 4: the normal matrix is banded that wide.
    let bw = obs.iter().map(|o| o.basis.len()).max().unwrap_or(0).max(4) - 1;
    let mut robust = vec![1.0; obs.len()];
    for pass in 0..2 {
        let mut a = Banded::zeros(m, bw);
        let mut b = vec![0.0; m];
        for (o, &rw) in obs.iter().zip(&robust) {
            let w = o.weight * rw;
            for (p, &bp) in o.basis.iter().enumerate() {
                let (Some(bi), true) = (b.get_mut(o.first + p), o.first + o.basis.len() <= m)
                else {
                    continue;
                };
                *bi += w * bp * o.value;
                for (q, &bq) in o.basis.iter().enumerate() {
                    a.add_lower(o.first + p, o.first + q, w * bp * bq);
                }
            }
        }
        let d = [-1.0, 3.0, -3.0, 1.0];
        for k in 0..m.saturating_sub(3) {
            for p in 0..4 {
                for q in 0..4 {
                    a.add_lower(k + p, k + q, smoothness * d[p] * d[q]);
                }
            }
        }
        for k in 0..m {
            a.add_lower(k, k, 1e-9);
        }
        if !cholesky_solve(&mut a, &mut b) {
            return false;
        }
        spline.coef = b;
        if pass == 0 {
            for (o, rw) in obs.iter().zip(robust.iter_mut()) {
                let miss = (spline.eval(o.first, &o.basis) - o.value).abs();
                *rw = lorentzian_weight(miss, MISS_SIGMA_PX);
            }
        }
    }
    true
}

/// One column's step: the row where its grey level crosses `threshold` nearest `centre`
/// (`rising`: from below to above with increasing row), as (last row before the step, the
/// interpolated crossing).
fn step_row(
    frame: &Image,
    x: usize,
    centre: f64,
    threshold: f64,
    rising: bool,
    reach: f64,
) -> Option<(usize, f64)> {
    let first = (centre - reach).floor().max(0.0) as usize;
    let last = ((centre + reach).ceil() as usize).min(frame.height.saturating_sub(1));
    let mut best: Option<(f64, usize, f64)> = None;
    for r in first..last {
        let (Some(v0), Some(v1)) = (frame.get(x, r), frame.get(x, r + 1)) else {
            continue;
        };
        let (v0, v1) = (f64::from(v0), f64::from(v1));
        let crosses = if rising {
            v0 < threshold && v1 >= threshold
        } else {
            v0 >= threshold && v1 < threshold
        };
        if !crosses {
            continue;
        }
        let p = r as f64 + ((threshold - v0) / (v1 - v0)).clamp(0.0, 1.0);
        let dist = (r as f64 + 0.5 - centre).abs();
        if best.is_none_or(|b| dist < b.0) {
            best = Some((dist, r, p));
        }
    }
    best.map(|b| (b.1, b.2))
}

/// The threshold between a fit's levels: their geometric mean when both are positive.
fn threshold(fit: &Border) -> f64 {
    if fit.low > 0.0 && fit.high > 0.0 {
        (fit.low * fit.high).sqrt()
    } else {
        0.5 * (fit.low + fit.high)
    }
}

/// One column of one frame: its groove position, step, and the sample it belongs to.
struct ColumnStep {
    x: usize,
    s: f64,
    row: usize,
    crossing: f64,
    slope: f64,
}

/// Refines one border's samples (`None` where a sample had no fit) over `frames` (image,
/// `cam_s_um`); returns each sample's border row averaged over its stretch, or None where the
/// refinement has no data. `cam_ref_um` places the reference frame's dust columns.
#[must_use]
pub fn refine_border(
    frames: &[(&Image, f64)],
    cam_ref_um: f64,
    geo: &FrameGeometry,
    samples: &[Option<RefineSample>],
    spacing_um: f64,
    params: &EdgeParams,
) -> Vec<Option<f64>> {
    let present: Vec<(usize, &RefineSample)> = samples
        .iter()
        .enumerate()
        .filter_map(|(j, s)| s.as_ref().map(|s| (j, s)))
        .collect();
    let none = vec![None; samples.len()];
    let (Some(first), Some(last)) = (present.first(), present.last()) else {
        return none;
    };
    let z = first.1.task.z_um;
    let Some(mut spline) = Spline::new(
        first.1.task.s_lo_um,
        last.1.task.s_hi_um,
        spacing_um / KNOTS_PER_SAMPLE,
    ) else {
        return none;
    };
    let mut widths: Vec<f64> = present.iter().map(|(_, s)| s.fit.width_px).collect();
    widths.sort_by(f64::total_cmp);
    let blur = widths[((widths.len() - 1) as f64 * BLUR_QUANTILE).round() as usize];
    let sharp = blur < params.hard_width_px;
    let half = 0.5 * geo.um_per_px(z);
    let mut rejected: Vec<(f64, f64)> = present
        .iter()
        .flat_map(|(_, s)| s.column_weights.iter())
        .filter(|c| f64::from(c.1) < OUTLIER_WEIGHT)
        .map(|c| {
            let s = geo.s_at(cam_ref_um, c.0 as f64, z);
            (s - half, s + half)
        })
        .collect();
    // Every rejected stretch is one column wide, so sorted by start they are sorted by end
    // too, and `s` lies in one of them exactly when it lies in the last one starting at or
    // before it.
    rejected.sort_by(|a, b| a.0.total_cmp(&b.0));
    let is_rejected = |s: f64| {
        let k = rejected.partition_point(|r| r.0 <= s);
        k.checked_sub(1)
            .and_then(|k| rejected.get(k))
            .is_some_and(|r| s < r.1)
    };
    let sample_at = |s: f64| -> Option<&RefineSample> {
        let k = present.partition_point(|(_, p)| p.task.s_hi_um <= s);
        present
            .get(k)
            .map(|(_, p)| *p)
            .filter(|p| s >= p.task.s_lo_um)
    };
    let mut obs = Vec::new();
    let mut crossing_at = Vec::new();
    let um_per_px = geo.um_per_px(z);
    for &(img, cam) in frames {
        // The frame's columns over the whole stretch, in order.
        let x_lo = geo.x_at(cam, first.1.task.s_lo_um, z).ceil().max(0.0) as usize;
        let x_hi = (geo.x_at(cam, last.1.task.s_hi_um, z).floor().max(0.0) as usize)
            .min(geo.width.saturating_sub(1));
        let mut steps: Vec<Option<ColumnStep>> = Vec::with_capacity(x_hi + 1 - x_lo.min(x_hi + 1));
        for x in x_lo..=x_hi {
            let s = geo.s_at(cam, x as f64, z);
            let step = sample_at(s).filter(|_| !is_rejected(s)).and_then(|smp| {
                let predicted = geo.row_at((smp.task.predict_y)(s), z);
                let centre = predicted + smp.fit.position_px;
                let rising = smp.fit.high > smp.fit.low;
                let (row, crossing) = step_row(
                    img,
                    x,
                    centre,
                    threshold(&smp.fit),
                    rising,
                    params.band_half_height_px,
                )?;
                // The border's slope in rows per column, from the prediction (only the
                // crossings of a sharp border use it).
                let ds = 0.5 * um_per_px;
                let slope = if sharp {
                    (geo.row_at((smp.task.predict_y)(s + ds), z)
                        - geo.row_at((smp.task.predict_y)(s - ds), z))
                    .abs()
                } else {
                    f64::NAN
                };
                Some(ColumnStep {
                    x,
                    s,
                    row,
                    crossing,
                    slope,
                })
            });
            steps.push(step);
        }
        if sharp {
            for k in 1..steps.len() {
                let (Some(a), Some(b)) = (&steps[k - 1], &steps[k]) else {
                    continue;
                };
                if a.row == b.row || b.x != a.x + 1 || a.row.abs_diff(b.row) > 2 {
                    continue;
                }
                // A single column stepping out and straight back is noise, not a crossing.
                let spike = |c: Option<&Option<ColumnStep>>, other: usize| {
                    c.and_then(Option::as_ref).is_some_and(|c| c.row == other)
                };
                if spike(k.checked_sub(2).and_then(|i| steps.get(i)), b.row)
                    || spike(steps.get(k + 1), a.row)
                {
                    continue;
                }
                // The border passed the centres of the rows between the two steps.
                let value = 0.5 * (a.row.min(b.row) as f64 + 1.0 + a.row.max(b.row) as f64);
                let slope = 0.5 * (a.slope + b.slope).max((b.row as f64 - a.row as f64).abs());
                let Some((i, basis)) = spline.point(0.5 * (a.s + b.s)) else {
                    continue;
                };
                obs.push(Observation {
                    first: i,
                    basis,
                    value,
                    weight: 1.0 / (slope * slope / 12.0 + params.crossing_sigma_px.powi(2)),
                });
                crossing_at.push(0.5 * (a.s + b.s));
            }
        } else {
            for c in steps.iter().flatten() {
                let Some((i, basis)) = spline.point(c.s) else {
                    continue;
                };
                obs.push(Observation {
                    first: i,
                    basis,
                    value: c.crossing,
                    weight: 1.0 / params.crossing_sigma_px.powi(2),
                });
            }
        }
    }
    let crossings = obs.len();
    // Anchors: a sample's own fit is biased toward the middle of the rows it steps in wherever
    // the border runs level, so the crossings place a sample whenever there are any nearby; the
    // fit only holds the curve where none lies within reach (a border that crosses no row).
    let mut has_crossing = vec![false; samples.len()];
    for &s in &crossing_at {
        let k = present.partition_point(|(_, p)| p.task.s_hi_um <= s);
        if let Some((j, p)) = present.get(k)
            && s >= p.task.s_lo_um
        {
            has_crossing[*j] = true;
        }
    }
    for (j, s) in &present {
        let lo = j.saturating_sub(ANCHOR_REACH);
        let hi = (j + ANCHOR_REACH + 1).min(samples.len());
        if has_crossing[lo..hi].iter().any(|&c| c) {
            continue;
        }
        let Some((i, basis)) = spline.boxed(s.task.s_lo_um, s.task.s_hi_um) else {
            continue;
        };
        obs.push(Observation {
            first: i,
            basis,
            value: s.row_px,
            weight: frames.len() as f64 / params.anchor_sigma_px.powi(2),
        });
    }
    if crossings == 0 || !solve(&mut spline, &obs, params.spline_smoothness) {
        return none;
    }
    samples
        .iter()
        .map(|s| {
            let s = s.as_ref()?;
            let (i, basis) = spline.boxed(s.task.s_lo_um, s.task.s_hi_um)?;
            Some(spline.eval(i, &basis))
        })
        .collect()
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;

    /// The reference: the symmetric positive system `a·x = b` (n×n, row-major) solved by
    /// dense Cholesky in place, as the stage did before its banded solve.
    fn dense_cholesky_solve(a: &mut [f64], b: &mut [f64], n: usize) -> bool {
        for j in 0..n {
            let mut d = a[j * n + j];
            for k in 0..j {
                d -= a[j * n + k] * a[j * n + k];
            }
            if d.is_nan() || d <= 0.0 {
                return false;
            }
            let d = d.sqrt();
            a[j * n + j] = d;
            for i in j + 1..n {
                let mut s = a[i * n + j];
                for k in 0..j {
                    s -= a[i * n + k] * a[j * n + k];
                }
                a[i * n + j] = s / d;
            }
        }
        for i in 0..n {
            let mut s = b[i];
            for k in 0..i {
                s -= a[i * n + k] * b[k];
            }
            b[i] = s / a[i * n + i];
        }
        for i in (0..n).rev() {
            let mut s = b[i];
            for k in i + 1..n {
                s -= a[k * n + i] * b[k];
            }
            b[i] = s / a[i * n + i];
        }
        b.iter().all(|v| v.is_finite())
    }

    /// The banded solve is the dense one to the bit, on normal matrices of B-spline fits
    /// (banded, positive) of several sizes and bandwidths.
    #[test]
    fn the_banded_cholesky_solve_is_the_dense_one_to_the_bit() {
        let mut seed = 0x9e37_79b9_7f4a_7c15_u64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        for (n, bw) in [(1, 3), (5, 3), (40, 3), (60, 7), (33, 12), (8, 10)] {
            let mut banded = Banded::zeros(n, bw);
            let mut dense = vec![0.0; n * n];
            // Sums of outer products of random basis-like rows: positive, banded.
            for first in 0..n {
                let len = (bw + 1).min(n - first);
                let row: Vec<f64> = (0..len).map(|_| next()).collect();
                let w = 0.5 + next();
                for p in 0..len {
                    for q in 0..len {
                        let x = w * row[p] * row[q];
                        dense[(first + p) * n + first + q] += x;
                        banded.add_lower(first + p, first + q, x);
                    }
                }
            }
            for k in 0..n {
                dense[k * n + k] += 1e-9;
                banded.add_lower(k, k, 1e-9);
            }
            let rhs: Vec<f64> = (0..n).map(|_| next() - 0.5).collect();
            let (mut xd, mut xb) = (rhs.clone(), rhs);
            assert!(dense_cholesky_solve(&mut dense, &mut xd, n));
            assert!(cholesky_solve(&mut banded, &mut xb));
            assert_eq!(xd, xb, "n {n}, bandwidth {bw}");
        }
        // Not positive: refused by both.
        let mut banded = Banded::zeros(2, 1);
        banded.add_lower(0, 0, -1.0);
        assert!(!cholesky_solve(&mut banded, &mut [1.0, 1.0]));
    }

    #[test]
    fn a_level_stretch_takes_its_height_from_the_crossings_around_it() {
        // A parabola peaking 0.3 rows above a row centre, seen only where it crosses rows
        // (every integer-s column's last row below it): the peak must come back well inside a
        // pixel, though the columns around it all step in the same row (a fit of each stretch
        // alone would put it at 10.5).
        let truth = |s: f64| 10.3 - 2e-4 * (s - 500.0).powi(2);
        let mut sp = Spline::new(0.0, 1000.0, 10.0).unwrap();
        let mut obs = Vec::new();
        for k in 1..1000 {
            let (a, b) = ((k - 1) as f64, k as f64);
            let (ra, rb) = (truth(a).floor(), truth(b).floor());
            if ra != rb {
                let (i, basis) = sp.point(0.5 * (a + b)).unwrap();
                let slope = (truth(b) - truth(a)).abs();
                obs.push(Observation {
                    first: i,
                    basis,
                    value: ra.max(rb),
                    weight: 1.0 / (slope * slope / 12.0 + 0.05f64.powi(2)),
                });
            }
        }
        assert!(solve(
            &mut sp,
            &obs,
            EdgeParams::default().spline_smoothness
        ));
        let at = |s: f64| {
            let (i, b) = sp.point(s).unwrap();
            sp.eval(i, &b)
        };
        let peak = at(500.0);
        assert!((peak - 10.3).abs() < 0.05, "peak {peak}");
        for s in [100.0, 300.0, 470.0, 700.0] {
            assert!((at(s) - truth(s)).abs() < 0.05, "{s}: {}", at(s));
        }
    }

    #[test]
    fn a_column_steps_at_its_threshold_crossing() {
        let img = Image::from_fn(1, 20, |_, r| if r < 9 { 0.15 } else { 0.75 });
        let (row, crossing) = step_row(&img, 0, 8.6, (0.15f64 * 0.75).sqrt(), true, 6.0).unwrap();
        assert_eq!(row, 8);
        let p = 8.0 + ((0.15f64 * 0.75).sqrt() - 0.15) / 0.6;
        assert!((crossing - p).abs() < 1e-6, "{crossing} vs {p}");
        assert!(step_row(&img, 0, 8.6, 0.3, false, 6.0).is_none());
    }
}
