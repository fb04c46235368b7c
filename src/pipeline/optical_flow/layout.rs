//! The Horn–Schunck storage: the red–black split of the flow state and the per-pixel factors in blocks of 8 columns.

use super::*;
pub(super) use crate::pipeline::simd::hs::{
    GROOVE_COEFS, HalfEdges, HalfRowInputs, LANES, PAIR, PLAIN_COEFS, SolveScalars, update_half_row,
};
pub(super) use crate::pipeline::simd::{Aligned, RowWriter, memory::vec_pair_from_rows};

/// Sizes of the red–black split: half-row `E` holds even columns, `O` odd ones. Each half-row
/// is stored lane-major: its columns are cut into [`LANES`] runs of `m` (the last one padded),
/// and vector k holds column k of every run, lane l being column `l·m + k` of the half. The
/// left and right neighbours of vector k's columns in the other half are then whole vectors
/// too (k − 1 and k, or k and k + 1), so the kernel never loads across a vector boundary.
/// The u and v vectors alternate (`[u₀ v₀ u₁ v₁ …]`), so a row is one memory stream.
#[derive(Clone, Copy, Debug)]
pub(super) struct Layout {
    pub(super) width: usize,
    pub(super) height: usize,
    /// Even-column count, ⌈w/2⌉.
    pub(super) even_cols: usize,
    /// Odd-column count, ⌊w/2⌋.
    pub(super) odd_cols: usize,
    /// Vectors per half-row (both halves): ⌈even_cols/8⌉.
    pub(super) m: usize,
}

impl Layout {
    #[inline]
    pub(super) fn new(width: usize, height: usize) -> Self {
        let even_cols = width.div_ceil(2);
        Self {
            width,
            height,
            even_cols,
            odd_cols: width / 2,
            m: even_cols.div_ceil(LANES),
        }
    }

    /// Columns in half `half` (0 = even, 1 = odd).
    #[inline]
    pub(super) fn columns_in(&self, half: usize) -> usize {
        if half == 0 {
            self.even_cols
        } else {
            self.odd_cols
        }
    }

    /// Slots of each of a half-row's u and v (columns and padding).
    #[inline]
    pub(super) fn slots(&self) -> usize {
        self.m * LANES
    }

    /// Floats per stored half-row: m pairs of u and v vectors.
    #[inline]
    pub(super) fn stride(&self) -> usize {
        2 * self.slots()
    }

    /// Where column `i`'s u sits in a stored half-row (its v is [`LANES`] on): vector pair
    /// `i mod m`, lane `i div m`.
    #[cfg(test)]
    pub(super) fn slot(&self, i: usize) -> usize {
        (i % self.m) * PAIR + i / self.m
    }

    /// Where half `half`'s neighbours in the other half stop being whole vectors.
    #[inline]
    pub(super) fn half_edges(&self, half: usize) -> HalfEdges {
        // The last image column is even (half 0) when the width is odd.
        let holds_last = (self.width % 2 == 1) == (half == 0);
        let i = self.columns_in(half).saturating_sub(1);
        HalfEdges {
            odd: half == 1,
            last: if holds_last && self.m > 0 {
                (i % self.m, i / self.m)
            } else {
                (usize::MAX, 0)
            },
        }
    }

    /// Calls `f(i, slot)` for the half's first `n` columns in column order, `slot` being
    /// [`Layout::slot`], without division.
    #[inline(always)]
    pub(super) fn each_slot(&self, n: usize, mut f: impl FnMut(usize, usize)) {
        for lane in 0..LANES {
            for k in 0..self.m {
                let i = lane * self.m + k;
                if i >= n {
                    return;
                }
                f(i, k * PAIR + lane);
            }
        }
    }
}

/// Flow state in split layout: per row, each half's u and v vectors, lane-major as [`Layout`]
/// says (padding slots hold values no column reads). Every row starts a cache line: the
/// arrays do, and a row is m pairs of vectors, 16m floats.
#[derive(Clone, Debug, Default)]
pub(super) struct SplitState {
    pub(super) e: Aligned,
    pub(super) o: Aligned,
}

impl SplitState {
    pub(super) fn zeros(lay: &Layout) -> Self {
        let len = lay.stride() * lay.height;
        Self {
            e: Aligned::zeros(len),
            o: Aligned::zeros(len),
        }
    }

    /// From images (the inverse of [`SplitState::to_images`]); `base` is subtracted from u and
    /// non-finite values start at 0.
    pub(super) fn from_images(lay: &Layout, u: &Image, v: &Image, base: f32) -> Self {
        let mut st = Self::zeros(lay);
        let (w, stride) = (lay.width, lay.stride());
        st.e.par_chunks_mut(stride)
            .zip(st.o.par_chunks_mut(stride))
            .zip(u.data.par_chunks(w))
            .zip(v.data.par_chunks(w))
            .for_each(|(((er, or), ur), vr)| {
                for (half, dst) in [(0, er), (1, or)] {
                    lay.each_slot(lay.columns_in(half), |i, at| {
                        let x = 2 * i + half;
                        let ux = ur[x] - base;
                        dst[at] = if ux.is_finite() { ux } else { 0.0 };
                        dst[at + LANES] = if vr[x].is_finite() { vr[x] } else { 0.0 };
                    });
                }
            });
        st
    }

    /// Back to images; `base` is added to u.
    pub(super) fn to_images(&self, lay: &Layout, base: f32) -> (Image, Image) {
        let (w, h) = (lay.width, lay.height);
        let (stride, slots) = (lay.stride(), lay.slots());
        let (m, even_cols, odd_cols) = (lay.m, lay.even_cols, lay.odd_cols);
        // One pass over the state writes both images, row by row.
        let (u, v) = vec_pair_from_rows(
            w,
            h,
            // Each half's values in column order (padding slots last).
            || [vec![0.0_f32; slots], vec![0.0_f32; slots]],
            |[even, odd], y, ur, vr| {
                let (Some(er), Some(or)) = (
                    self.e.get(y * stride..(y + 1) * stride),
                    self.o.get(y * stride..(y + 1) * stride),
                ) else {
                    return;
                };
                // Adding −0 leaves every value, −0 included, as it is.
                for (part, row, base) in [(0, ur, base), (1, vr, -0.0)] {
                    from_lanes(m, er, part, even);
                    from_lanes(m, or, part, odd);
                    // Interleaves the halves: ⌊w/2⌋ pairs, then for an odd width the last even
                    // column.
                    row.with_local(|row| {
                        for (&e, &o) in even[..odd_cols].iter().zip(&odd[..odd_cols]) {
                            row.push(e + base);
                            row.push(o + base);
                        }
                        if even_cols > odd_cols
                            && let Some(&e) = even.get(even_cols - 1)
                        {
                            row.push(e + base);
                        }
                    });
                }
            },
        );
        let image = |data| Image {
            width: w,
            height: h,
            data,
        };
        (image(u), image(v))
    }
}

/// The 8×8 block with rows and columns swapped.
#[inline(always)]
fn transpose(b: &[[f32; LANES]; LANES]) -> [[f32; LANES]; LANES] {
    std::array::from_fn(|j| std::array::from_fn(|l| b[l][j]))
}

/// Part `part` (0 = u, 1 = v) of a stored half-row (`row`, m vector pairs) in column order
/// (`nat`, 8m values: the columns, then the padding), eight vectors at a time through an 8×8
/// transpose.
#[inline(always)]
pub(super) fn from_lanes(m: usize, row: &[f32], part: usize, nat: &mut [f32]) {
    let (Some(row), Some(nat)) = (row.get(..m * PAIR), nat.get_mut(..m * LANES)) else {
        return;
    };
    let pairs = row.as_chunks::<PAIR>().0;
    let vector = |k: usize| -> [f32; LANES] { std::array::from_fn(|l| pairs[k][part * LANES + l]) };
    let whole = m / LANES * LANES;
    for k0 in (0..whole).step_by(LANES) {
        let block: [[f32; LANES]; LANES] = std::array::from_fn(|j| vector(k0 + j));
        for (l, run) in transpose(&block).iter().enumerate() {
            nat[l * m + k0..l * m + k0 + LANES].copy_from_slice(run);
        }
    }
    for k in whole..m {
        let v = vector(k);
        for (l, &x) in v.iter().enumerate() {
            nat[l * m + k] = x;
        }
    }
}

/// Which stencil the solver runs.
#[derive(Clone, Copy, Debug)]
pub(super) enum Stencil {
    /// `u = ū − gx·t, v = v̄ − gy·t, t = gx·ū + gy·v̄ + gt`.
    Plain,
    /// The general 2×2 update with `quarter_lambda` = λ/4.
    Groove { quarter_lambda: f32 },
}

impl Stencil {
    #[inline]
    pub(super) fn coefs(self) -> usize {
        match self {
            Stencil::Plain => PLAIN_COEFS,
            Stencil::Groove { .. } => GROOVE_COEFS,
        }
    }
}

/// Where the coefficients of one half-row live: block k holds the `c` coefficients of vector
/// k's lanes (columns `l·m + k`, see [`Layout`]), coefficient j at `k·8·c + 8·j + l`; padding
/// slots hold zeros.
#[derive(Clone, Copy, Debug)]
pub(super) struct CoefRow {
    /// The half (0 = even, 1 = odd).
    pub(super) half: usize,
    /// Columns in the half.
    pub(super) n: usize,
    /// Vectors per half-row.
    pub(super) m: usize,
    /// Coefficients per column.
    pub(super) c: usize,
}

impl CoefRow {
    /// Half `half` (0 = even, 1 = odd) of `lay` with `c` coefficients per column.
    #[inline]
    pub(super) fn new(lay: &Layout, half: usize, c: usize) -> Self {
        Self {
            half,
            n: lay.columns_in(half),
            m: lay.m,
            c,
        }
    }

    /// Values per half-row, padding included.
    #[inline]
    pub(super) fn len(self) -> usize {
        self.m * LANES * self.c
    }

    /// Index of coefficient `j` of column `i`.
    #[cfg(test)]
    pub(super) fn at(self, i: usize, j: usize) -> usize {
        (i % self.m) * LANES * self.c + j * LANES + i / self.m
    }

    /// Writes this half-row's blocks into `dst` (a half-row of [`CoefRow::len`] values, in
    /// order) from `rows[j]`, coefficient j of every column of the image row in column order
    /// (the half's column i is image column 2i + `half`); the padding gets zeros. `C` is the
    /// coefficient count, `c`.
    pub(super) fn scatter<const C: usize>(self, rows: &[Vec<f32>; C], dst: &mut RowWriter) {
        dst.with_local(|dst| {
            for k in 0..self.m {
                for row in rows {
                    for lane in 0..LANES {
                        let i = lane * self.m + k;
                        let x = if i < self.n {
                            row.get(2 * i + self.half)
                        } else {
                            None
                        };
                        dst.push(x.copied().unwrap_or(0.0));
                    }
                }
            }
        });
    }
}
