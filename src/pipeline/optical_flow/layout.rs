//! The Horn–Schunck storage: the red–black split of the flow state and the per-pixel factors in blocks of 8 columns.

use super::*;

/// Sizes of the red–black split: half-row `E` holds even columns, `O` odd ones.
#[derive(Clone, Copy, Debug)]
pub(super) struct Layout {
    pub(super) width: usize,
    pub(super) height: usize,
    /// Even-column count, ⌈w/2⌉.
    pub(super) ne: usize,
    /// Odd-column count, ⌊w/2⌋.
    pub(super) no: usize,
}

impl Layout {
    #[inline]
    pub(super) fn new(width: usize, height: usize) -> Self {
        Self {
            width,
            height,
            ne: width.div_ceil(2),
            no: width / 2,
        }
    }

    /// Columns in half `hp` (0 = even, 1 = odd).
    #[inline]
    pub(super) fn half(&self, hp: usize) -> usize {
        if hp == 0 { self.ne } else { self.no }
    }
}

/// Floats per 64-byte cache line.
const LINE_FLOATS: usize = 16;

/// A float array placed so that element `lead` starts a 64-byte cache line: the row kernels'
/// 8-float loads and stores from there on then never straddle two lines (a straddling load
/// costs two cache accesses; on this machine's sweeps, about a tenth of the time).
#[derive(Debug, Default)]
pub(super) struct Aligned {
    buf: Vec<f32>,
    off: usize,
    len: usize,
    lead: usize,
}

impl Aligned {
    /// `len` values written by `fill`, which must initialise every one of them.
    pub(super) fn build(
        len: usize,
        lead: usize,
        fill: impl FnOnce(&mut [MaybeUninit<f32>]),
    ) -> Self {
        let mut buf: Vec<f32> = Vec::with_capacity(len + LINE_FLOATS);
        // f32 storage is 4-byte aligned, so whole floats reach the next line boundary.
        let at = (buf.as_ptr() as usize / std::mem::size_of::<f32>() + lead) % LINE_FLOATS;
        let off = (LINE_FLOATS - at) % LINE_FLOATS;
        let spare = buf.spare_capacity_mut();
        for x in &mut spare[..off] {
            x.write(0.0);
        }
        fill(&mut spare[off..off + len]);
        // SAFETY: the capacity is at least `off + len`; the loop above initialised the first
        // `off` elements and `fill`, by its contract, the next `len`.
        unsafe { buf.set_len(off + len) };
        Self {
            buf,
            off,
            len,
            lead,
        }
    }

    /// `len` zeros, filled in parallel.
    pub(super) fn zeros(len: usize, lead: usize) -> Self {
        Self::build(len, lead, |s| {
            s.par_chunks_mut(1 << 16)
                .for_each(|c| c.fill(MaybeUninit::new(0.0)));
        })
    }
}

impl std::ops::Deref for Aligned {
    type Target = [f32];
    #[inline]
    fn deref(&self) -> &[f32] {
        &self.buf[self.off..self.off + self.len]
    }
}

impl std::ops::DerefMut for Aligned {
    #[inline]
    fn deref_mut(&mut self) -> &mut [f32] {
        &mut self.buf[self.off..self.off + self.len]
    }
}

impl Clone for Aligned {
    /// A copy placed anew (a plain copy of the vector could land on another phase).
    fn clone(&self) -> Self {
        Self::build(self.len, self.lead, |s| {
            for (d, &x) in s.iter_mut().zip(self.iter()) {
                d.write(x);
            }
        })
    }
}

impl PartialEq for Aligned {
    fn eq(&self, other: &Self) -> bool {
        **self == **other
    }
}

/// Flow state in split layout: per row, `[u(n) | v(n)]` for each half. The even half's
/// kernel core starts at its column 1, the odd half's at column 0: those elements start
/// cache lines.
#[derive(Clone, Debug, Default)]
pub(super) struct SplitState {
    pub(super) e: Aligned,
    pub(super) o: Aligned,
}

impl SplitState {
    pub(super) fn zeros(lay: &Layout) -> Self {
        Self {
            e: Aligned::zeros(2 * lay.ne * lay.height, 1),
            o: Aligned::zeros(2 * lay.no * lay.height, 0),
        }
    }

    /// From images (the inverse of [`SplitState::to_images`]); `base` is subtracted from u and
    /// non-finite values start at 0.
    pub(super) fn from_images(lay: &Layout, u: &Image, v: &Image, base: f32) -> Self {
        let mut st = Self::zeros(lay);
        let w = lay.width;
        let split = |row: &[f32], even: &mut [f32], odd: &mut [f32], base: f32| {
            split_columns(row, even, odd, |d, x| {
                let y = x - base;
                *d = if y.is_finite() { y } else { 0.0 };
            });
        };
        st.e.par_chunks_mut(2 * lay.ne)
            .zip(st.o.par_chunks_mut(2 * lay.no.max(1)))
            .zip(u.data.par_chunks(w))
            .zip(v.data.par_chunks(w))
            .for_each(|(((er, or), ur), vr)| {
                let (eu, ev) = er.split_at_mut(lay.ne);
                let (ou, ov) = or.split_at_mut(lay.no.min(or.len()));
                split(ur, eu, ou, base);
                split(vr, ev, ov, 0.0);
            });
        st
    }

    /// Back to images; `base` is added to u.
    pub(super) fn to_images(&self, lay: &Layout, base: f32) -> (Image, Image) {
        let (w, h) = (lay.width, lay.height);
        let mut u = zeros_par(w * h);
        let mut v = zeros_par(w * h);
        // Interleaves a row's even and odd columns.
        let merge = |row: &mut [f32], even: &[f32], odd: &[f32], base: f32| {
            let mut pairs = row.chunks_exact_mut(2);
            for ((pair, &e), &o) in (&mut pairs).zip(even).zip(odd) {
                pair[0] = e + base;
                pair[1] = o + base;
            }
            if let (Some(last), Some(&e_last)) =
                (pairs.into_remainder().first_mut(), even.get(odd.len()))
            {
                *last = e_last + base;
            }
        };
        u.par_chunks_mut(w)
            .zip(v.par_chunks_mut(w))
            .zip(self.e.par_chunks(2 * lay.ne))
            .zip(self.o.par_chunks(2 * lay.no.max(1)))
            .for_each(|(((ur, vr), er), or)| {
                let (eu, ev) = er.split_at(lay.ne);
                let (ou, ov) = or.split_at(lay.no.min(or.len()));
                merge(ur, eu, ou, base);
                // Adding −0 leaves every value, −0 included, as it is.
                merge(vr, ev, ov, -0.0);
            });
        let wrap = |data| Image {
            width: w,
            height: h,
            data,
        };
        (wrap(u), wrap(v))
    }
}

/// Splits a row of w values into its ⌈w/2⌉ even columns and ⌊w/2⌋ odd ones: `put(slot, value)`
/// for each. With `even` and `odd` of exactly those lengths every slot is put once: the
/// ⌊w/2⌋ column pairs fill `odd` and the first ⌊w/2⌋ of `even`, an odd width's last column
/// the last of `even`.
#[inline(always)]
pub(super) fn split_columns(
    row: &[f32],
    even: &mut [f32],
    odd: &mut [f32],
    put: impl Fn(&mut f32, f32),
) {
    let pairs = row.chunks_exact(2);
    if let (Some(&last), Some(e_last)) = (pairs.remainder().first(), even.get_mut(odd.len())) {
        put(e_last, last);
    }
    for ((pair, e), o) in pairs.zip(even.iter_mut()).zip(odd.iter_mut()) {
        put(e, pair[0]);
        put(o, pair[1]);
    }
}

/// Coefficients per plain pixel: `gx, gy, gt` = `Ix, Iy, It / sqrt(λ + Ix² + Iy²)`.
pub(super) const PLAIN_COEFS: usize = 3;
/// Coefficients per groove pixel: `wu, wd, puu, puv, pvv, pu0, pv0` (see [`GrooveRow::fill`]).
pub(super) const GROOVE_COEFS: usize = 7;

/// Which stencil the solver runs.
#[derive(Clone, Copy, Debug)]
pub(super) enum Kernel {
    /// `u = ū − gx·t, v = v̄ − gy·t, t = gx·ū + gy·v̄ + gt`.
    Plain,
    /// The general 2×2 update; `q` = λ/4.
    Groove { q: f32 },
}

impl Kernel {
    #[inline]
    pub(super) fn coefs(self) -> usize {
        match self {
            Kernel::Plain => PLAIN_COEFS,
            Kernel::Groove { .. } => GROOVE_COEFS,
        }
    }
}

/// Columns per coefficient block: a row kernel reads every coefficient of 8 columns from one
/// contiguous block (one stream per half-row instead of one per coefficient).
pub(super) const LANES: usize = 8;

/// Where the coefficients of one half-row live. Column `i` takes slot `(i − first) mod n`,
/// `first` being the half's first core column (1 in the even half, whose column 0 has no left
/// neighbour; 0 in the odd half), so the kernel's core runs over whole blocks from slot 0 and
/// the even half's column 0 takes the last slot. Slot `j` keeps coefficient `k` at
/// `(j / 8)·8·C + 8·k + j mod 8`; the last block is padded with zeros.
#[derive(Clone, Copy, Debug)]
pub(super) struct CoefRow {
    /// Columns in the half.
    pub(super) n: usize,
    /// First core column (slot 0).
    pub(super) first: usize,
    /// Coefficients per column.
    pub(super) c: usize,
}

impl CoefRow {
    /// Half `hp` (0 = even, 1 = odd) of `lay` with `c` coefficients per column.
    #[inline]
    pub(super) fn new(lay: &Layout, hp: usize, c: usize) -> Self {
        Self {
            n: lay.half(hp),
            first: usize::from(hp == 0),
            c,
        }
    }

    /// Values per half-row, padding included.
    #[inline]
    pub(super) fn len(self) -> usize {
        self.n.div_ceil(LANES) * LANES * self.c
    }

    /// Index of coefficient `k` of slot `j`.
    #[inline(always)]
    pub(super) fn at_slot(self, j: usize, k: usize) -> usize {
        (j / LANES) * LANES * self.c + k * LANES + j % LANES
    }

    /// Writes this half-row's blocks into `dst` (a half-row of [`CoefRow::len`] values) from
    /// `cols[k]`, coefficient k over the half's n columns: slot j holds column
    /// (j + first) mod n; the padding holds 0. Block by block, so each cache line is written
    /// whole at once.
    pub(super) fn scatter<const C: usize>(
        self,
        cols: &[Vec<f32>; C],
        dst: &mut [MaybeUninit<f32>],
    ) {
        // Slots below `plain` hold columns j + first.
        let plain = self.n - self.first;
        for (b, block) in dst.chunks_exact_mut(LANES * C).enumerate() {
            let j0 = b * LANES;
            let start = j0 + self.first;
            for (out, col) in block.chunks_exact_mut(LANES).zip(cols) {
                match col.get(start..start + LANES) {
                    Some(src) if j0 + LANES <= plain => {
                        for (d, &x) in out.iter_mut().zip(src) {
                            d.write(x);
                        }
                    }
                    _ => {
                        for (l, d) in out.iter_mut().enumerate() {
                            let j = j0 + l;
                            let column = if j < plain {
                                Some(j + self.first)
                            } else {
                                (j < self.n).then(|| j - plain)
                            };
                            d.write(column.and_then(|i| col.get(i)).copied().unwrap_or(0.0));
                        }
                    }
                }
            }
        }
    }

    /// Index of coefficient `k` of column `i` (< n).
    #[inline(always)]
    pub(super) fn at(self, i: usize, k: usize) -> usize {
        let j = if i >= self.first {
            i - self.first
        } else {
            self.n - self.first + i
        };
        self.at_slot(j, k)
    }
}
