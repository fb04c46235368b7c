//! The pieces of the blocked solve: the convergence schedule of a block, the row bands the states are cut into, and the measured changes of a row.

use super::*;

/// Iterations still needed for the per-pixel change to fall below `tolerance`, if the
/// changes `d0` after `k0` iterations and `d1` after `k1` fit a geometric decay; a block ends
/// there instead of running its full length past the point of convergence.
pub(super) fn iterations_to_tolerance(
    (k0, d0): (usize, f64),
    (k1, d1): (usize, f64),
    tolerance: f64,
) -> Option<usize> {
    if k1 <= k0 || !(d1 > 0.0 && d0 > d1 && tolerance > 0.0) {
        return None;
    }
    let log_rate = (d1 / d0).ln() / (k1 - k0) as f64;
    let n = ((tolerance / d1).ln() / log_rate).ceil();
    (n.is_finite() && n >= 1.0).then(|| n.min(usize::MAX as f64) as usize)
}

/// Level count and the first measured level of one block.
pub(super) struct Schedule {
    pub(super) levels: usize,
    /// Levels of the last iteration, whose changes are measured.
    pub(super) measure_from: usize,
    /// Levels of the middle iteration, measured too (empty for short blocks).
    pub(super) mid: std::ops::Range<usize>,
    /// Over-relaxation factor (1 for Jacobi).
    pub(super) omega: f32,
}

impl Schedule {
    /// Runs `update(measure)` for one row at level `lvl` and adds what it measured to the
    /// row's middle-iteration (`.0`) or last-iteration (`.1`) sum in `row` (present whenever
    /// the block measures).
    #[inline(always)]
    pub(super) fn add(
        &self,
        lvl: usize,
        row: Option<&mut (f64, f64)>,
        update: impl FnOnce(bool) -> f64,
    ) {
        match row {
            Some(r) if lvl >= self.measure_from => r.1 += update(true),
            Some(r) if self.mid.contains(&lvl) => r.0 += update(true),
            _ => {
                update(false);
            }
        }
    }
}

/// Mutable rows `[y0, y0 + rows)` of one (red–black) or two (Jacobi) states: `(e, o)` each,
/// and of the per-row sums of measured changes (empty when the block measures nothing).
pub(super) struct RowBand<'a> {
    pub(super) y0: usize,
    pub(super) rows: usize,
    pub(super) bufs: Vec<(&'a mut [f32], &'a mut [f32])>,
    pub(super) sums: &'a mut [(f64, f64)],
}

/// Cuts every state, and the per-row sums, into the disjoint, sorted row ranges `bounds`.
pub(super) fn split_bands<'a>(
    lay: &Layout,
    states: &'a mut [&mut SplitState],
    sums: &'a mut [(f64, f64)],
    bounds: &[(usize, usize)],
) -> Vec<RowBand<'a>> {
    let mut chunks: Vec<RowBand<'a>> = bounds
        .iter()
        .zip(split_rows(sums, 1, bounds))
        .map(|(&(lo, hi), sums)| RowBand {
            y0: lo,
            rows: hi - lo,
            bufs: Vec::with_capacity(states.len()),
            sums,
        })
        .collect();
    for st in states.iter_mut() {
        let st: &'a mut SplitState = st;
        let es = split_rows(&mut st.e, lay.stride(), bounds);
        let os = split_rows(&mut st.o, lay.stride(), bounds);
        for ((ch, e), o) in chunks.iter_mut().zip(es).zip(os) {
            ch.bufs.push((e, o));
        }
    }
    chunks
}

/// The disjoint, sorted row ranges `bounds` of an array of rows `stride` values long (each
/// empty when the array is).
pub(super) fn split_rows<'a, T>(
    mut rows: &'a mut [T],
    stride: usize,
    bounds: &[(usize, usize)],
) -> Vec<&'a mut [T]> {
    let mut at = 0;
    bounds
        .iter()
        .map(|&(lo, hi)| {
            if rows.is_empty() {
                return &mut [][..];
            }
            let (_, rest) = std::mem::take(&mut rows).split_at_mut((lo - at) * stride);
            let (mine, next) = rest.split_at_mut((hi - lo) * stride);
            rows = next;
            at = hi;
            mine
        })
        .collect()
}

/// Rows `up` and `dn` (read) and `mid` (written) of a buffer with row stride `stride`;
/// `up`, `dn` ∈ {mid − 1, mid + 1}.
#[inline]
pub(super) fn rows3(
    buf: &mut [f32],
    stride: usize,
    mid: usize,
    up: usize,
    dn: usize,
) -> (&[f32], &mut [f32], &[f32]) {
    let (before, rest) = buf.split_at_mut(mid * stride);
    let (m, after) = rest.split_at_mut(stride);
    let (before, after): (&[f32], &[f32]) = (before, after);
    let pick = |r: usize| -> &[f32] {
        if r < mid {
            &before[r * stride..(r + 1) * stride]
        } else {
            &after[(r - mid - 1) * stride..(r - mid) * stride]
        }
    };
    (pick(up), m, pick(dn))
}

/// Σ|a − b| over the first `n` columns of a stored half-row's u and v (`a`, `b`, as [`Layout`]
/// says): 16 f32 accumulators, one per lane of the u and of the v vectors, filled vector by
/// vector in stored order (padding lanes left out) and then added in lane order. The order
/// depends only on the layout, so the sum is the same whatever the bands.
#[inline]
pub(super) fn abs_diff_sum(lay: &Layout, n: usize, a: &[f32], b: &[f32]) -> f64 {
    let m = lay.m;
    let (Some(a), Some(b)) = (a.get(..m * PAIR), b.get(..m * PAIR)) else {
        return 0.0;
    };
    let mut acc = [0.0_f32; PAIR];
    // Vectors below `full` have a column in every lane (the last lane's run is the shortest);
    // after it lane l holds one only while l·m + k < n.
    let full = n.saturating_sub((LANES - 1) * m).min(m);
    let (pa, pb) = (a.as_chunks::<PAIR>().0, b.as_chunks::<PAIR>().0);
    for (x, y) in pa[..full].iter().zip(&pb[..full]) {
        for q in 0..PAIR {
            acc[q] += (x[q] - y[q]).abs();
        }
    }
    for (k, (x, y)) in pa.iter().zip(pb).enumerate().skip(full) {
        for q in (0..PAIR).filter(|q| (q % LANES) * m + k < n) {
            acc[q] += (x[q] - y[q]).abs();
        }
    }
    f64::from(acc.iter().sum::<f32>())
}
