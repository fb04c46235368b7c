//! The Horn–Schunck row kernels: one half-row's update, portable and on AVX2 intrinsics.

use super::*;

/// The vector instruction set the row kernels may use (detected once per call). AVX-512
/// measured no faster than AVX2 here: the sweeps are bound by cache bandwidth.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Simd {
    /// Whatever the build target allows.
    Baseline,
    /// 256-bit AVX2.
    #[cfg(target_arch = "x86_64")]
    Avx2,
}

impl Simd {
    #[inline]
    pub(super) fn detect() -> Self {
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2") {
                return Simd::Avx2;
            }
        }
        Simd::Baseline
    }

    /// One row of the groove coefficients: see [`GrooveRow::fill`].
    #[inline]
    pub(super) fn groove_row(self, row: &GrooveRow, out: &mut [Vec<f32>; GROOVE_COEFS]) {
        match self {
            Simd::Baseline => row.fill(out),
            // SAFETY: `Simd::Avx2` is only created by `detect` after the CPU reported AVX2,
            // which is all `groove_row_avx2` requires.
            #[cfg(target_arch = "x86_64")]
            Simd::Avx2 => unsafe { groove_row_avx2(row, out) },
        }
    }

    /// Updates one half-row: see [`row_impl`].
    #[allow(clippy::too_many_arguments)]
    #[inline]
    pub(super) fn row<const GROOVE: bool, const RELAX: bool>(
        self,
        k: Consts,
        odd: bool,
        lr: &[f32],
        up: &[f32],
        dn: &[f32],
        coef: &[f32],
        dst: &mut [f32],
    ) {
        match self {
            Simd::Baseline => row_impl::<GROOVE, RELAX, false>(k, odd, lr, up, dn, coef, dst),
            // SAFETY: `Simd::Avx2` is only created by `detect` after the CPU reported AVX2,
            // which is all `row_avx2` requires.
            #[cfg(target_arch = "x86_64")]
            Simd::Avx2 => unsafe { row_avx2::<GROOVE, RELAX>(k, odd, lr, up, dn, coef, dst) },
        }
    }
}

/// [`GrooveRow::fill`] compiled for AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
pub(super) fn groove_row_avx2(row: &GrooveRow, out: &mut [Vec<f32>; GROOVE_COEFS]) {
    row.fill(out);
}

/// [`row_impl`] compiled for AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[allow(clippy::too_many_arguments)]
pub(super) fn row_avx2<const GROOVE: bool, const RELAX: bool>(
    k: Consts,
    odd: bool,
    lr: &[f32],
    up: &[f32],
    dn: &[f32],
    coef: &[f32],
    dst: &mut [f32],
) {
    row_impl::<GROOVE, RELAX, true>(k, odd, lr, up, dn, coef, dst);
}

/// Updates one half-row `dst = [u(n) | v(n)]` from the other half of the same row
/// `lr = [u(m) | v(m)]`, the same half of the rows above and below (`up`, `dn`, mirrored at
/// the image edges) and the half-row's coefficients `coef` (laid out as [`CoefRow`] says).
///
/// Even half (`odd == false`): column 2i has left/right neighbours `lr[i − 1]`, `lr[i]`; odd
/// half: `lr[i]`, `lr[i + 1]`. A neighbour beyond the image border is mirrored, i.e. replaced
/// by the opposite one. The core, where both neighbours are inside, runs in whole blocks of
/// [`LANES`] columns, the last one possibly partial (with AVX2 intrinsics when `AVX2`, which
/// only [`row_avx2`] sets); the two border columns go one at a time through the portable
/// block, all lanes alike.
#[inline(always)]
pub(super) fn row_impl<const GROOVE: bool, const RELAX: bool, const AVX2: bool>(
    k: Consts,
    odd: bool,
    lr: &[f32],
    up: &[f32],
    dn: &[f32],
    coef: &[f32],
    dst: &mut [f32],
) {
    let n = dst.len() / 2;
    let nl = lr.len() / 2;
    let ncoef = if GROOVE { GROOVE_COEFS } else { PLAIN_COEFS };
    let off = usize::from(odd);
    let cr = CoefRow {
        n,
        first: 1 - off,
        c: ncoef,
    };
    if n == 0 || nl == 0 || up.len() < 2 * n || dn.len() < 2 * n || coef.len() < cr.len() {
        return;
    }
    // Core: columns [i0, i1), where left = lr[i + off − 1] and right = lr[i + off] are both
    // inside; its left neighbours start at lr[i0 + off − 1] = lr[0].
    let i0 = cr.first;
    let i1 = n.min(nl - off).max(i0);
    if i1 > i0 {
        let rows = Rows {
            lr,
            nl,
            up,
            dn,
            n,
            i0,
            m: i1 - i0,
            coef,
        };
        #[cfg(target_arch = "x86_64")]
        if AVX2 {
            // SAFETY: `AVX2` is only set by `row_avx2`, whose caller checked that the CPU has
            // AVX2, all `blocks_avx2` requires.
            unsafe { blocks_avx2::<GROOVE, RELAX>(k, &rows, dst) };
        } else {
            blocks_portable::<GROOVE, RELAX>(k, &rows, rows.outputs(dst));
        }
        #[cfg(not(target_arch = "x86_64"))]
        blocks_portable::<GROOVE, RELAX>(k, &rows, rows.outputs(dst));
    }
    // The border columns: mirror the missing neighbour.
    let (lu, lv) = lr.split_at(nl);
    let (uu, uv) = up.split_at(n);
    let (du, dv) = dn.split_at(n);
    let (ou, ov) = dst.split_at_mut(n);
    for i in (0..i0.min(n)).chain(i1..n) {
        let left = (i + off).checked_sub(1);
        let right = (i + off < nl).then_some(i + off);
        let (li, ri) = match (left, right) {
            (Some(l), Some(r)) => (l, r),
            (Some(l), None) => (l, l),
            (None, Some(r)) => (r, r),
            (None, None) => continue,
        };
        let one = L8::splat;
        let inputs = BlockInputs {
            lu: one(lu[li]),
            ru: one(lu[ri]),
            uu: one(uu[i]),
            du: one(du[i]),
            lv: one(lv[li]),
            rv: one(lv[ri]),
            uv: one(uv[i]),
            dv: one(dv[i]),
            old: (one(ou[i]), one(ov[i])),
        };
        let (a, b) = portable_block::<GROOVE, RELAX>(k, &inputs, |j| one(coef[cr.at(i, j)]));
        (ou[i], ov[i]) = (a.0[0], b.0[0]);
    }
}

/// A half-row's core, the `m` columns from `i0` whose two neighbours lie inside, and what it
/// reads: the other half of the row `lr = [u(nl) | v(nl)]` (the core's left neighbours start
/// at `lr[0]`, its right ones at `lr[1]`), this half of the rows above and below
/// (`[u(n) | v(n)]`) and the core's ⌈m/8⌉ coefficient blocks (the last one padded). The
/// output, `[u(n) | v(n)]` too, goes beside it. Each row stays whole, so the AVX2 loop reaches
/// a row's v half from its u half by a fixed distance inside one slice.
pub(super) struct Rows<'a> {
    pub(super) lr: &'a [f32],
    pub(super) nl: usize,
    pub(super) up: &'a [f32],
    pub(super) dn: &'a [f32],
    pub(super) n: usize,
    pub(super) i0: usize,
    pub(super) m: usize,
    pub(super) coef: &'a [f32],
}

impl Rows<'_> {
    /// The core's inputs as runs: left neighbours of u and v (m + 1 values each, the right
    /// ones one on), then u and v of the rows above and below (m each). `row_impl` checked
    /// the lengths this slices by.
    #[inline(always)]
    fn inputs(&self) -> [&[f32]; 6] {
        let (m, n, i0, nl) = (self.m, self.n, self.i0, self.nl);
        [
            &self.lr[..=m],
            &self.lr[nl..=nl + m],
            &self.up[i0..i0 + m],
            &self.up[n + i0..n + i0 + m],
            &self.dn[i0..i0 + m],
            &self.dn[n + i0..n + i0 + m],
        ]
    }

    /// The core's u and v runs of the output row `dst = [u(n) | v(n)]` (empty if it is short).
    #[inline(always)]
    fn outputs<'d>(&self, dst: &'d mut [f32]) -> (&'d mut [f32], &'d mut [f32]) {
        let (u, v) = dst.split_at_mut(self.n.min(dst.len()));
        let core = self.i0..self.i0 + self.m;
        match (u.get_mut(core.clone()), v.get_mut(core)) {
            (Some(u), Some(v)) => (u, v),
            _ => (&mut [], &mut []),
        }
    }
}

/// Eight f32 lanes for the portable core: element-wise operations the compiler turns into
/// vector instructions of whatever the target has.
#[derive(Clone, Copy)]
pub(super) struct L8([f32; LANES]);

impl L8 {
    /// The first 8 values of `s` (all zeros when it holds fewer).
    #[inline(always)]
    pub(super) fn load(s: &[f32]) -> Self {
        let mut out = [0.0; LANES];
        if let Some(whole) = s.get(..LANES) {
            out.copy_from_slice(whole);
        }
        Self(out)
    }

    /// The first values of `s`, up to 8, zeros after them (a copy of variable length: kept
    /// apart from [`L8::load`], which it would stop from staying in registers).
    #[inline(always)]
    pub(super) fn load_partial(s: &[f32]) -> Self {
        let mut out = [0.0; LANES];
        let len = s.len().min(LANES);
        out[..len].copy_from_slice(&s[..len]);
        Self(out)
    }

    #[inline(always)]
    pub(super) fn splat(x: f32) -> Self {
        Self([x; LANES])
    }

    #[inline(always)]
    pub(super) fn zip(self, o: Self, f: impl Fn(f32, f32) -> f32) -> Self {
        let mut out = self.0;
        for (a, &b) in out.iter_mut().zip(&o.0) {
            *a = f(*a, b);
        }
        Self(out)
    }

    #[inline(always)]
    pub(super) fn add(self, o: Self) -> Self {
        self.zip(o, |a, b| a + b)
    }

    #[inline(always)]
    pub(super) fn sub(self, o: Self) -> Self {
        self.zip(o, |a, b| a - b)
    }

    #[inline(always)]
    pub(super) fn mul(self, o: Self) -> Self {
        self.zip(o, |a, b| a * b)
    }
}

/// The core blocks in portable code: [`blocks_avx2`] operation for operation on [`L8`]. Whole
/// blocks load fixed-length runs, which the compiler keeps in vector registers; a partial last
/// block loads what there is (a copy of variable length, kept out of the whole blocks' loop),
/// computes its missing lanes on zeros and does not store them.
#[inline(always)]
pub(super) fn blocks_portable<const GROOVE: bool, const RELAX: bool>(
    k: Consts,
    r: &Rows,
    (ou, ov): (&mut [f32], &mut [f32]),
) {
    let ncoef = if GROOVE { GROOVE_COEFS } else { PLAIN_COEFS };
    let m = ou.len().min(ov.len());
    let [lu, lv, uu, uv, du, dv] = r.inputs();
    let whole = m / LANES * LANES;
    let (ou, tail_u) = ou.split_at_mut(whole);
    let (ov, tail_v) = ov.split_at_mut(whole);
    let mut coefs = r.coef.chunks_exact(LANES * ncoef);
    let cols = ou
        .chunks_exact_mut(LANES)
        .zip(ov.chunks_exact_mut(LANES))
        .zip(coefs.by_ref())
        .enumerate();
    for (bi, ((ou, ov), coef)) in cols {
        let i = bi * LANES;
        let load = |s: &[f32], j: usize| L8::load(s.get(j..).unwrap_or_default());
        // The left and right neighbours from one checked run of 9.
        let pair = |s: &[f32]| match s.get(i..i + LANES + 1) {
            Some(run) => (L8::load(run), L8::load(run.get(1..).unwrap_or_default())),
            None => (L8::splat(0.0), L8::splat(0.0)),
        };
        let ((lu, ru), (lv, rv)) = (pair(lu), pair(lv));
        let inputs = BlockInputs {
            lu,
            ru,
            uu: load(uu, i),
            du: load(du, i),
            lv,
            rv,
            uv: load(uv, i),
            dv: load(dv, i),
            old: (L8::load(ou), L8::load(ov)),
        };
        let (a, b) = portable_block::<GROOVE, RELAX>(k, &inputs, |j| load(coef, j * LANES));
        ou.copy_from_slice(&a.0);
        ov.copy_from_slice(&b.0);
    }
    if let (false, Some(coef)) = (tail_u.is_empty(), coefs.next()) {
        let at = |s: &[f32], j: usize| L8::load_partial(s.get(j..).unwrap_or_default());
        let i = whole;
        let inputs = BlockInputs {
            lu: at(lu, i),
            ru: at(lu, i + 1),
            uu: at(uu, i),
            du: at(du, i),
            lv: at(lv, i),
            rv: at(lv, i + 1),
            uv: at(uv, i),
            dv: at(dv, i),
            old: (at(tail_u, 0), at(tail_v, 0)),
        };
        let (a, b) = portable_block::<GROOVE, RELAX>(k, &inputs, |j| at(coef, j * LANES));
        let (nu, nv) = (tail_u.len().min(LANES), tail_v.len().min(LANES));
        tail_u[..nu].copy_from_slice(&a.0[..nu]);
        tail_v[..nv].copy_from_slice(&b.0[..nv]);
    }
}

/// What one block of [`blocks_portable`] reads: the neighbours of its 8 lanes and their old
/// u and v (used when relaxing).
struct BlockInputs {
    lu: L8,
    ru: L8,
    uu: L8,
    du: L8,
    lv: L8,
    rv: L8,
    uv: L8,
    dv: L8,
    old: (L8, L8),
}

/// The new u and v of one block of [`blocks_portable`], coefficient j read by `c(j)`.
#[inline(always)]
fn portable_block<const GROOVE: bool, const RELAX: bool>(
    k: Consts,
    x: &BlockInputs,
    c: impl Fn(usize) -> L8,
) -> (L8, L8) {
    let su = x.lu.add(x.ru).add(x.uu.add(x.du));
    let sv = x.lv.add(x.rv).add(x.uv.add(x.dv));
    let (mut a, mut b) = if GROOVE {
        let q = L8::splat(k.q);
        let nu = q.mul(su).add(c(0).mul(x.uu)).add(c(1).mul(x.du));
        let nv = q.mul(sv);
        let (puu, puv, pvv) = (c(2), c(3), c(4));
        (
            puu.mul(nu).add(puv.mul(nv)).add(c(5)),
            puv.mul(nu).add(pvv.mul(nv)).add(c(6)),
        )
    } else {
        let quarter = L8::splat(0.25);
        let (ub, vb) = (quarter.mul(su), quarter.mul(sv));
        let (gx, gy) = (c(0), c(1));
        let t = gx.mul(ub).add(gy.mul(vb)).add(c(2));
        (ub.sub(gx.mul(t)), vb.sub(gy.mul(t)))
    };
    if RELAX {
        let (omega, (old_u, old_v)) = (L8::splat(k.omega), x.old);
        a = old_u.add(omega.mul(a.sub(old_u)));
        b = old_v.add(omega.mul(b.sub(old_v)));
    }
    (a, b)
}

/// The core blocks with AVX2 intrinsics: [`portable_block`] on 8 columns at once, operation
/// for operation (no fused multiply–add), so the result has the same bits as
/// [`blocks_portable`]. A last partial block is loaded and stored through a
/// lane mask.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
pub(super) fn blocks_avx2<const GROOVE: bool, const RELAX: bool>(
    k: Consts,
    r: &Rows,
    dst: &mut [f32],
) {
    use std::arch::x86_64::{
        _mm256_cmpgt_epi32, _mm256_loadu_ps, _mm256_maskload_ps, _mm256_maskstore_ps,
        _mm256_set1_epi32, _mm256_set1_ps, _mm256_setr_epi32, _mm256_storeu_ps,
    };
    let ncoef = if GROOVE { GROOVE_COEFS } else { PLAIN_COEFS };
    let (m, n, i0, nl) = (r.m, r.n, r.i0, r.nl);
    // What the loop reads and writes lies inside: lr's u half up to m + 1 values and its v
    // half from nl; each of up, dn and dst from i0 and from n + i0, m values; the
    // coefficients ⌈m/8⌉ whole blocks.
    let (Some(l), Some(up), Some(dn), Some(out)) = (
        r.lr.get(..nl + m + 1),
        r.up.get(i0..n + i0 + m),
        r.dn.get(i0..n + i0 + m),
        dst.get_mut(i0..n + i0 + m),
    ) else {
        return;
    };
    if m >= nl || i0 + m > n || r.coef.len() < m.div_ceil(LANES) * LANES * ncoef {
        return;
    }
    let k = AvxConsts {
        quarter: _mm256_set1_ps(0.25),
        q: _mm256_set1_ps(k.q),
        omega: _mm256_set1_ps(k.omega),
    };
    // One advancing pointer per row, the v half at a fixed distance from the u half inside
    // the same slice: fewer live pointers than one per stream, so the loop keeps them all in
    // registers.
    let mut p = BlockPtrs {
        l: l.as_ptr(),
        up: up.as_ptr(),
        dn: dn.as_ptr(),
        c: r.coef.as_ptr(),
        o: out.as_mut_ptr(),
        dl: nl as isize,
        dup: n as isize,
        ddn: n as isize,
        dout: n as isize,
    };
    for _ in 0..m / LANES {
        // SAFETY: the m/8 whole blocks lie inside the slices checked above, read and
        // written: each u half at offsets below m (+ 1 for the right neighbours), each v half
        // the checked distance further in the same slice; the pointers end at most at the
        // core's end.
        unsafe {
            block_avx2::<GROOVE, RELAX>(
                &k,
                &p,
                |at| _mm256_loadu_ps(at),
                |at, x| _mm256_storeu_ps(at, x),
            );
            p.advance(ncoef);
        }
    }
    let tail = m % LANES;
    if tail > 0 {
        // Lanes below `tail` (at most 7, so the cast is exact).
        let mask = _mm256_cmpgt_epi32(
            _mm256_set1_epi32(tail as i32),
            _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7),
        );
        // SAFETY: as above for the lanes below `tail`, the only ones the masked loads and
        // stores touch (the right neighbours reach offset m, inside); the coefficient block
        // is whole (padded).
        unsafe {
            block_avx2::<GROOVE, RELAX>(
                &k,
                &p,
                |at| _mm256_maskload_ps(at, mask),
                |at, x| _mm256_maskstore_ps(at, mask, x),
            );
        }
    }
}

/// Broadcast constants of [`blocks_avx2`].
#[cfg(target_arch = "x86_64")]
pub(super) struct AvxConsts {
    pub(super) quarter: std::arch::x86_64::__m256,
    pub(super) q: std::arch::x86_64::__m256,
    pub(super) omega: std::arch::x86_64::__m256,
}

/// Where [`blocks_avx2`] is: one pointer per row (left/right neighbours, up, down, the
/// coefficient block, the output), and the distance in floats from each row's u half to its
/// v half.
#[cfg(target_arch = "x86_64")]
pub(super) struct BlockPtrs {
    pub(super) l: *const f32,
    pub(super) up: *const f32,
    pub(super) dn: *const f32,
    pub(super) c: *const f32,
    pub(super) o: *mut f32,
    pub(super) dl: isize,
    pub(super) dup: isize,
    pub(super) ddn: isize,
    pub(super) dout: isize,
}

#[cfg(target_arch = "x86_64")]
impl BlockPtrs {
    /// Moves on by one block of columns, `ncoef` blocks of coefficients.
    ///
    /// # Safety
    /// The next block must lie inside the rows, or start one past their end.
    #[inline(always)]
    pub(super) unsafe fn advance(&mut self, ncoef: usize) {
        // SAFETY: the caller's.
        unsafe {
            self.l = self.l.add(LANES);
            self.up = self.up.add(LANES);
            self.dn = self.dn.add(LANES);
            self.c = self.c.add(LANES * ncoef);
            self.o = self.o.add(LANES);
        }
    }
}

/// One block of 8 columns at `p`, the rows read through `load` and written through `store`
/// (plain or masked); the coefficient block is read whole.
///
/// # Safety
/// `load` and `store` must be sound at every address the block reaches from `p`: the rows'
/// u and v halves at lanes 0..8 (the left/right row also at 1..9) and the output's u and v
/// halves; the coefficient block must lie inside its row.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
pub(super) unsafe fn block_avx2<const GROOVE: bool, const RELAX: bool>(
    k: &AvxConsts,
    p: &BlockPtrs,
    load: impl Fn(*const f32) -> std::arch::x86_64::__m256,
    store: impl Fn(*mut f32, std::arch::x86_64::__m256),
) {
    use std::arch::x86_64::{_mm256_add_ps, _mm256_loadu_ps, _mm256_mul_ps, _mm256_sub_ps};
    // SAFETY: the caller's.
    unsafe {
        let (lu, ru, uu, du) = (load(p.l), load(p.l.add(1)), load(p.up), load(p.dn));
        let (lv, rv, uv, dv) = (
            load(p.l.offset(p.dl)),
            load(p.l.offset(p.dl + 1)),
            load(p.up.offset(p.dup)),
            load(p.dn.offset(p.ddn)),
        );
        let c = |j: usize| _mm256_loadu_ps(p.c.add(j * LANES));
        let su = _mm256_add_ps(_mm256_add_ps(lu, ru), _mm256_add_ps(uu, du));
        let sv = _mm256_add_ps(_mm256_add_ps(lv, rv), _mm256_add_ps(uv, dv));
        let (mut a, mut b) = if GROOVE {
            let nu = _mm256_add_ps(
                _mm256_add_ps(_mm256_mul_ps(k.q, su), _mm256_mul_ps(c(0), uu)),
                _mm256_mul_ps(c(1), du),
            );
            let nv = _mm256_mul_ps(k.q, sv);
            let (puu, puv, pvv) = (c(2), c(3), c(4));
            (
                _mm256_add_ps(
                    _mm256_add_ps(_mm256_mul_ps(puu, nu), _mm256_mul_ps(puv, nv)),
                    c(5),
                ),
                _mm256_add_ps(
                    _mm256_add_ps(_mm256_mul_ps(puv, nu), _mm256_mul_ps(pvv, nv)),
                    c(6),
                ),
            )
        } else {
            let (ub, vb) = (_mm256_mul_ps(k.quarter, su), _mm256_mul_ps(k.quarter, sv));
            let (gx, gy) = (c(0), c(1));
            let t = _mm256_add_ps(
                _mm256_add_ps(_mm256_mul_ps(gx, ub), _mm256_mul_ps(gy, vb)),
                c(2),
            );
            (
                _mm256_sub_ps(ub, _mm256_mul_ps(gx, t)),
                _mm256_sub_ps(vb, _mm256_mul_ps(gy, t)),
            )
        };
        let pov = p.o.offset(p.dout);
        if RELAX {
            let (old_u, old_v) = (load(p.o), load(pov));
            a = _mm256_add_ps(old_u, _mm256_mul_ps(k.omega, _mm256_sub_ps(a, old_u)));
            b = _mm256_add_ps(old_v, _mm256_mul_ps(k.omega, _mm256_sub_ps(b, old_v)));
        }
        store(p.o, a);
        store(pov, b);
    }
}

/// Scalars every row update of one solve shares.
#[derive(Clone, Copy, Debug)]
pub(super) struct Consts {
    /// λ/4 (groove kernel).
    pub(super) q: f32,
    /// Over-relaxation factor ω (used when the kernel relaxes).
    pub(super) omega: f32,
}
