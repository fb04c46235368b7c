//! The NaN-aware median filter of the inverse depth: a pruned sorting network on 8 pixels at a time, selection elsewhere.

use super::*;

pub(super) use crate::pipeline::simd::median::{MEDIAN_LANES, compare_exchange};
/// Largest window (m²) handled by the network; larger ones use selection per pixel.
pub(super) const MAX_NETWORK_INPUTS: usize = 49;

/// A selection network that leaves the median of `n` inputs at `target`: Batcher's odd–even
/// merge sort on `n` inputs padded to a power of two with −∞ (the first slots) and +∞, with
/// the comparators that touch a pad resolved while it is built (they are no-ops or relabel
/// the slots), then pruned to the comparators the median depends on. It works on the `n`
/// inputs alone (5×5: 114 comparators instead of the 191 of the padded sort).
pub(super) struct MedianNetwork {
    pub(super) n: usize,
    pub(super) target: usize,
    /// (low, high): the smaller value goes to `low`, the larger to `high`; both < `n`.
    pub(super) pairs: Vec<(usize, usize)>,
}

impl MedianNetwork {
    pub(super) fn new(n: usize) -> Self {
        #[derive(Clone, Copy, PartialEq)]
        enum Slot {
            Low,
            Input(usize),
            High,
        }
        let size = n.next_power_of_two();
        let lo_pad = (size - n) / 2;
        let mut slots: Vec<Slot> = (0..size)
            .map(|s| match s.checked_sub(lo_pad) {
                None => Slot::Low,
                Some(i) if i < n => Slot::Input(i),
                Some(_) => Slot::High,
            })
            .collect();
        let mut pairs = Vec::new();
        let mut p = 1;
        while p < size {
            let mut k = p;
            while k >= 1 {
                let mut j = k % p;
                while j + k < size {
                    for i in 0..k.min(size - j - k) {
                        let (a, b) = (i + j, i + j + k);
                        if a / (2 * p) != b / (2 * p) {
                            continue;
                        }
                        let (Some(&sa), Some(&sb)) = (slots.get(a), slots.get(b)) else {
                            continue;
                        };
                        match (sa, sb) {
                            (Slot::Input(x), Slot::Input(y)) => pairs.push((x, y)),
                            // Already in order: nothing moves.
                            (Slot::Low, _) | (_, Slot::High) => {}
                            // Out of order: the values swap slots.
                            _ => slots.swap(a, b),
                        }
                    }
                    j += 2 * k;
                }
                k /= 2;
            }
            p *= 2;
        }
        let target = match slots.get(lo_pad + n / 2) {
            Some(&Slot::Input(t)) => t,
            _ => 0,
        };
        let mut needed = vec![false; n];
        if let Some(t) = needed.get_mut(target) {
            *t = true;
        }
        let mut kept: Vec<(usize, usize)> = Vec::new();
        for &(a, b) in pairs.iter().rev() {
            let hit =
                needed.get(a).copied().unwrap_or(false) || needed.get(b).copied().unwrap_or(false);
            if hit {
                for i in [a, b] {
                    if let Some(nd) = needed.get_mut(i) {
                        *nd = true;
                    }
                }
                kept.push((a, b));
            }
        }
        kept.reverse();
        Self {
            n,
            target,
            pairs: kept,
        }
    }

    /// Medians of `MEDIAN_LANES` pixels whose windows were loaded into `v[..n]` (finite values
    /// only), the comparators run for `isa` (the same results on every instruction set); None
    /// when `v` is shorter.
    pub(super) fn run(
        &self,
        isa: Isa,
        v: &mut [[f32; MEDIAN_LANES]],
    ) -> Option<[f32; MEDIAN_LANES]> {
        let v = v.get_mut(..self.n)?;
        compare_exchange(isa, &self.pairs, v);
        v.get(self.target).copied()
    }
}

/// Median of the finite values in the window of half-sides (rx, ry) about (x, y), by selection.
pub(super) fn median_select(
    v: &[f32],
    width: usize,
    x: usize,
    y: usize,
    rx: usize,
    ry: usize,
    buf: &mut Vec<f32>,
) -> f32 {
    buf.clear();
    for yy in y - ry..=y + ry {
        let base = yy * width + x;
        if let Some(s) = v.get(base - rx..=base + rx) {
            buf.extend(s.iter().copied().filter(|e| e.is_finite()));
        }
    }
    median_in_place(buf).unwrap_or(f32::NAN)
}

/// Median filter (side `m`, NaN-aware) of `v` → `out`; NaN where the window holds no finite
/// value. Near the borders the window shrinks symmetrically about the pixel, so a linear ramp
/// is left unbiased. Interior blocks of finite values go through a sorting network, eight
/// pixels at a time; the rest use selection.
pub(super) fn median_filter(
    v: &[f32],
    width: usize,
    height: usize,
    m: usize,
    out: &mut [f32],
    isa: Isa,
) {
    let r = m / 2;
    if r == 0 {
        out.copy_from_slice(v);
        return;
    }
    let n = m * m;
    let net = (n <= MAX_NETWORK_INPUTS).then(|| MedianNetwork::new(n));
    // Per row, the count of non-finite values left of each column (w + 1 entries), so that a
    // block's window is checked with two lookups per row.
    let stride = width + 1;
    let mut bad = vec![0_u32; stride * height];
    bad.par_chunks_mut(stride)
        .zip(v.par_chunks(width))
        .for_each(|(counts, row)| {
            let mut c = 0;
            for (k, &e) in counts.iter_mut().skip(1).zip(row) {
                c += u32::from(!e.is_finite());
                *k = c;
            }
        });
    let clean = |y0: usize, y1: usize, x0: usize, x1: usize| {
        (y0..y1).all(|yy| bad.get(yy * stride + x1) == bad.get(yy * stride + x0))
    };
    out.par_chunks_mut(width).enumerate().for_each_init(
        || (Vec::new(), Vec::new()),
        |(buf, lanes): &mut (Vec<f32>, Vec<[f32; MEDIAN_LANES]>), (y, row)| {
            let ry = r.min(y).min(height - 1 - y);
            let mut x = 0;
            while x < width {
                let block_ok = ry == r
                    && x >= r
                    && x + MEDIAN_LANES + r <= width
                    && clean(y - r, y + r + 1, x - r, x + MEDIAN_LANES + r);
                if let (true, Some(net)) = (block_ok, net.as_ref()) {
                    lanes.clear();
                    for yy in y - r..=y + r {
                        let row0 = yy * width + x - r;
                        for base in row0..row0 + m {
                            if let Some(src) = v.get(base..base + MEDIAN_LANES) {
                                let mut lane = [0.0; MEDIAN_LANES];
                                lane.copy_from_slice(src);
                                lanes.push(lane);
                            }
                        }
                    }
                    if let Some(med) = net.run(isa, lanes) {
                        if let Some(o) = row.get_mut(x..x + MEDIAN_LANES) {
                            o.copy_from_slice(&med);
                        }
                        x += MEDIAN_LANES;
                        continue;
                    }
                }
                let rx = r.min(x).min(width - 1 - x);
                if let Some(o) = row.get_mut(x) {
                    *o = median_select(v, width, x, y, rx, ry, buf);
                }
                x += 1;
            }
        },
    );
}
