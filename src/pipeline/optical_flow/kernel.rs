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
        edges: Edges,
        lr: &[f32],
        up: &[f32],
        dn: &[f32],
        coef: &[f32],
        dst: &mut [f32],
    ) {
        match self {
            Simd::Baseline => row_impl::<GROOVE, RELAX, false>(k, edges, lr, up, dn, coef, dst),
            // SAFETY: `Simd::Avx2` is only created by `detect` after the CPU reported AVX2,
            // which is all `row_avx2` requires.
            #[cfg(target_arch = "x86_64")]
            Simd::Avx2 => unsafe { row_avx2::<GROOVE, RELAX>(k, edges, lr, up, dn, coef, dst) },
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
    edges: Edges,
    lr: &[f32],
    up: &[f32],
    dn: &[f32],
    coef: &[f32],
    dst: &mut [f32],
) {
    row_impl::<GROOVE, RELAX, true>(k, edges, lr, up, dn, coef, dst);
}

/// Where a half-row's neighbours in the other half stop being whole vectors (see [`Layout`]).
#[derive(Clone, Copy, Debug)]
pub(super) struct Edges {
    /// The odd half (column i's neighbours are the other half's i and i + 1) or the even one
    /// (i − 1 and i).
    pub(super) odd: bool,
    /// The half's vector and lane holding the image's last column, whose missing right
    /// neighbour is mirrored (`usize::MAX` when the other half holds that column).
    pub(super) last: (usize, usize),
}

impl Edges {
    /// Half `hp` of `lay`.
    #[inline]
    pub(super) fn new(lay: &Layout, hp: usize) -> Self {
        // The last image column is even (half 0) when the width is odd.
        let holds_last = (lay.width % 2 == 1) == (hp == 0);
        let i = lay.half(hp).saturating_sub(1);
        Self {
            odd: hp == 1,
            last: if holds_last && lay.m > 0 {
                (i % lay.m, i / lay.m)
            } else {
                (usize::MAX, 0)
            },
        }
    }
}

/// Updates one stored half-row `dst` from the other half of the same row `lr`, the same half
/// of the rows above and below (`up`, `dn`, mirrored at the image edges) and the half-row's
/// coefficient blocks `coef` ([`CoefRow`]), all lane-major ([`Layout`]): m pairs of u and v
/// vectors in each row, m = `dst.len() / 16`.
///
/// Even half: column i's left and right neighbours are the other half's columns i − 1 and i,
/// for vector k its vectors k − 1 and k; for k = 0 the left ones are vector m − 1 moved up a
/// lane, column 0's (lane 0) missing one mirrored, i.e. replaced by the right one. Odd half:
/// columns i and i + 1, vectors k and k + 1; for k = m − 1 the right ones are vector 0 moved
/// down a lane. The image's last column mirrors its missing right neighbour (`edges.last`).
/// Padding slots compute values that no column reads. With AVX2 intrinsics when `AVX2`, which
/// only [`row_avx2`] sets.
#[inline(always)]
pub(super) fn row_impl<const GROOVE: bool, const RELAX: bool, const AVX2: bool>(
    k: Consts,
    edges: Edges,
    lr: &[f32],
    up: &[f32],
    dn: &[f32],
    coef: &[f32],
    dst: &mut [f32],
) {
    let ncoef = if GROOVE { GROOVE_COEFS } else { PLAIN_COEFS };
    let m = dst.len() / PAIR;
    let len = m * PAIR;
    if m == 0
        || lr.len() < len
        || up.len() < len
        || dn.len() < len
        || coef.len() < m * LANES * ncoef
    {
        return;
    }
    #[cfg(target_arch = "x86_64")]
    if AVX2 {
        // SAFETY: `AVX2` is only set by `row_avx2`, whose caller checked that the CPU has
        // AVX2, all `blocks_avx2` requires.
        unsafe { blocks_avx2::<GROOVE, RELAX>(k, edges, m, lr, up, dn, coef, dst) };
        return;
    }
    blocks_portable::<GROOVE, RELAX>(k, edges, m, lr, up, dn, coef, dst);
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

    /// `[first, a0, …, a6]`: moved up a lane.
    #[inline(always)]
    pub(super) fn up_lane(self, first: f32) -> Self {
        let mut out = [first; LANES];
        out[1..].copy_from_slice(&self.0[..LANES - 1]);
        Self(out)
    }

    /// `[a1, …, a7, last]`: moved down a lane.
    #[inline(always)]
    pub(super) fn down_lane(self, last: f32) -> Self {
        let mut out = [last; LANES];
        out[..LANES - 1].copy_from_slice(&self.0[1..]);
        Self(out)
    }

    /// Lane by lane, `self` where `mask` is set, else `other`.
    #[inline(always)]
    pub(super) fn select(self, other: Self, mask: [bool; LANES]) -> Self {
        Self(std::array::from_fn(|l| {
            if mask[l] { self.0[l] } else { other.0[l] }
        }))
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

/// The half-row in portable code: [`blocks_avx2`] operation for operation on [`L8`] (the
/// lane moves at the edges move values only, so both give the same bits).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(super) fn blocks_portable<const GROOVE: bool, const RELAX: bool>(
    k: Consts,
    edges: Edges,
    m: usize,
    lr: &[f32],
    up: &[f32],
    dn: &[f32],
    coef: &[f32],
    dst: &mut [f32],
) {
    let ncoef = if GROOVE { GROOVE_COEFS } else { PLAIN_COEFS };
    // A stored row as its m (u, v) vector pairs.
    fn pairs(s: &[f32], m: usize) -> &[[f32; PAIR]] {
        s.get(..m * PAIR)
            .map_or(&[][..], |p| p.as_chunks::<PAIR>().0)
    }
    // The u (`part` 0) or v (1) vector of a pair, copied as one fixed run (which stays in
    // vector registers; a lane-by-lane copy did not, and doubled the time).
    #[inline(always)]
    fn half(p: &[f32; PAIR], part: usize) -> L8 {
        let (u, v) = p.split_at(LANES);
        L8::load(if part == 0 { u } else { v })
    }
    let lr = pairs(lr, m);
    let at = |i: usize| {
        lr.get(i).map_or((L8::splat(0.0), L8::splat(0.0)), |p| {
            (half(p, 0), half(p, 1))
        })
    };
    let (last_k, last_lane) = edges.last;
    // The mirrored lane as a mask: a lane written through a run-time index would push the
    // whole vector out of registers.
    let mirror: [bool; LANES] = std::array::from_fn(|l| l == last_lane);
    let outs = dst
        .get_mut(..m * PAIR)
        .map_or(&mut [][..], |d| d.as_chunks_mut::<PAIR>().0);
    let ins = pairs(up, m)
        .iter()
        .zip(pairs(dn, m))
        .zip(coef.chunks_exact(LANES * ncoef));
    for (kk, (out, ((up, dn), c))) in outs.iter_mut().zip(ins).enumerate() {
        let (left, mut right) = if edges.odd {
            let left = at(kk);
            let right = if kk + 1 < m {
                at(kk + 1)
            } else {
                let first = at(0);
                (
                    first.0.down_lane(left.0.0[LANES - 1]),
                    first.1.down_lane(left.1.0[LANES - 1]),
                )
            };
            (left, right)
        } else {
            let right = at(kk);
            let left = if kk > 0 {
                at(kk - 1)
            } else {
                let wrap = at(m - 1);
                (wrap.0.up_lane(right.0.0[0]), wrap.1.up_lane(right.1.0[0]))
            };
            (left, right)
        };
        if kk == last_k {
            right = (
                left.0.select(right.0, mirror),
                left.1.select(right.1, mirror),
            );
        }
        let inputs = BlockInputs {
            lu: left.0,
            ru: right.0,
            uu: half(up, 0),
            du: half(dn, 0),
            lv: left.1,
            rv: right.1,
            uv: half(up, 1),
            dv: half(dn, 1),
            old: (half(out, 0), half(out, 1)),
        };
        let (a, b) = portable_block::<GROOVE, RELAX>(k, &inputs, |j| {
            L8::load(c.get(j * LANES..).unwrap_or_default())
        });
        let (ou, ov) = out.split_at_mut(LANES);
        ou.copy_from_slice(&a.0);
        ov.copy_from_slice(&b.0);
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

/// The half-row with AVX2 intrinsics: [`portable_block`] on 8 columns at once, operation for
/// operation (no fused multiply–add), so the result has the same bits as [`blocks_portable`].
/// Every load starts a vector of the lane-major layout, so none straddles two cache lines
/// when the rows start lines; each vector of the other half is loaded once and carried.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[allow(clippy::too_many_arguments)]
pub(super) fn blocks_avx2<const GROOVE: bool, const RELAX: bool>(
    k: Consts,
    edges: Edges,
    m: usize,
    lr: &[f32],
    up: &[f32],
    dn: &[f32],
    coef: &[f32],
    dst: &mut [f32],
) {
    use std::arch::x86_64::{
        __m256, _mm256_blend_ps, _mm256_blendv_ps, _mm256_castsi256_ps, _mm256_cmpeq_epi32,
        _mm256_loadu_ps, _mm256_permutevar8x32_ps, _mm256_set1_epi32, _mm256_set1_ps,
        _mm256_setr_epi32,
    };
    let ncoef = if GROOVE { GROOVE_COEFS } else { PLAIN_COEFS };
    // Everything the loop reads and writes: m vector pairs in each row, m blocks of
    // coefficients.
    let len = m * PAIR;
    let (Some(l), Some(up), Some(dn), Some(out), Some(c)) = (
        lr.get(..len),
        up.get(..len),
        dn.get(..len),
        dst.get_mut(..len),
        coef.get(..m * LANES * ncoef),
    ) else {
        return;
    };
    let kc = AvxConsts {
        quarter: _mm256_set1_ps(0.25),
        q: _mm256_set1_ps(k.q),
        omega: _mm256_set1_ps(k.omega),
    };
    let (last_k, last_lane) = edges.last;
    // All ones in the mirrored lane (lane numbers are below 8, so the cast is exact).
    let mirror = _mm256_castsi256_ps(_mm256_cmpeq_epi32(
        _mm256_set1_epi32(last_lane as i32),
        _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7),
    ));
    let lp = l.as_ptr();
    // Vector pair `i` (< m) of the other half: its u and v.
    // SAFETY (every call): i < m, so both loads lie inside `l`, checked above.
    let pair = |i: usize| unsafe {
        (
            _mm256_loadu_ps(lp.add(i * PAIR)),
            _mm256_loadu_ps(lp.add(i * PAIR + LANES)),
        )
    };
    let mut p = BlockPtrs {
        up: up.as_ptr(),
        dn: dn.as_ptr(),
        c: c.as_ptr(),
        o: out.as_mut_ptr(),
        dv: LANES as isize,
    };
    // One block at `p`, its right neighbours mirrored into the last column's lane there.
    let mut step = |kk: usize, left: (__m256, __m256), mut right: (__m256, __m256)| {
        if kk == last_k {
            right = (
                _mm256_blendv_ps(right.0, left.0, mirror),
                _mm256_blendv_ps(right.1, left.1, mirror),
            );
        }
        // SAFETY: `p` is at block kk < m: its u and v vectors of up, dn and the output and
        // its coefficient block lie inside the slices checked above.
        unsafe {
            block_avx2::<GROOVE, RELAX>(&kc, &p, [left.0, right.0, left.1, right.1]);
            p.advance(ncoef);
        }
    };
    if edges.odd {
        let first = pair(0);
        let mut left = first;
        for kk in 0..m - 1 {
            let right = pair(kk + 1);
            step(kk, left, right);
            left = right;
        }
        // Vector 0 moved down a lane, lane 7 mirrored (or padding).
        let down = _mm256_setr_epi32(1, 2, 3, 4, 5, 6, 7, 7);
        let right = (
            _mm256_blend_ps::<0x80>(_mm256_permutevar8x32_ps(first.0, down), left.0),
            _mm256_blend_ps::<0x80>(_mm256_permutevar8x32_ps(first.1, down), left.1),
        );
        step(m - 1, left, right);
    } else {
        // Vector m − 1 moved up a lane, lane 0 (column 0) mirrored.
        let upw = _mm256_setr_epi32(0, 0, 1, 2, 3, 4, 5, 6);
        let (wrap, first) = (pair(m - 1), pair(0));
        let mut left = (
            _mm256_blend_ps::<0x01>(_mm256_permutevar8x32_ps(wrap.0, upw), first.0),
            _mm256_blend_ps::<0x01>(_mm256_permutevar8x32_ps(wrap.1, upw), first.1),
        );
        let mut right = first;
        for kk in 0..m {
            if kk > 0 {
                right = pair(kk);
            }
            step(kk, left, right);
            left = right;
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

/// Where [`blocks_avx2`] is: one pointer per row (up, down, the coefficient block, the
/// output) and the distance in floats from each u vector to its v vector.
#[cfg(target_arch = "x86_64")]
pub(super) struct BlockPtrs {
    pub(super) up: *const f32,
    pub(super) dn: *const f32,
    pub(super) c: *const f32,
    pub(super) o: *mut f32,
    pub(super) dv: isize,
}

#[cfg(target_arch = "x86_64")]
impl BlockPtrs {
    /// Moves on by one vector pair, `ncoef` vectors of coefficients.
    ///
    /// # Safety
    /// The next block must lie inside the rows, or start one past their end.
    #[inline(always)]
    pub(super) unsafe fn advance(&mut self, ncoef: usize) {
        // SAFETY: the caller's.
        unsafe {
            self.up = self.up.add(PAIR);
            self.dn = self.dn.add(PAIR);
            self.c = self.c.add(LANES * ncoef);
            self.o = self.o.add(PAIR);
        }
    }
}

/// One block of 8 columns at `p`, its left and right neighbours given (`[lu, ru, lv, rv]`);
/// the coefficient block is read whole.
///
/// # Safety
/// The u and v vectors of up, dn and the output at `p`, and the coefficient block, must lie
/// inside their rows.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
pub(super) unsafe fn block_avx2<const GROOVE: bool, const RELAX: bool>(
    k: &AvxConsts,
    p: &BlockPtrs,
    [lu, ru, lv, rv]: [std::arch::x86_64::__m256; 4],
) {
    use std::arch::x86_64::{
        _mm256_add_ps, _mm256_loadu_ps, _mm256_mul_ps, _mm256_storeu_ps, _mm256_sub_ps,
    };
    // SAFETY: the caller's.
    unsafe {
        let load = |at: *const f32| _mm256_loadu_ps(at);
        let (uu, du) = (load(p.up), load(p.dn));
        let (uv, dv) = (load(p.up.offset(p.dv)), load(p.dn.offset(p.dv)));
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
        let pov = p.o.offset(p.dv);
        if RELAX {
            let (old_u, old_v) = (load(p.o), load(pov));
            a = _mm256_add_ps(old_u, _mm256_mul_ps(k.omega, _mm256_sub_ps(a, old_u)));
            b = _mm256_add_ps(old_v, _mm256_mul_ps(k.omega, _mm256_sub_ps(b, old_v)));
        }
        _mm256_storeu_ps(p.o, a);
        _mm256_storeu_ps(pov, b);
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
