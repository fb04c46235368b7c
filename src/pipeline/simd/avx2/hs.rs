//! The Horn–Schunck half-row kernel on AVX2 intrinsics: whole vectors of the lane-major layout loaded once and carried, the portable build's operations in the same order.

use std::arch::x86_64::__m256;

use crate::pipeline::simd::Avx2Proof;
use crate::pipeline::simd::hs::{
    GROOVE_COEFS, HalfEdges, HalfRowInputs, LANES, PAIR, PLAIN_COEFS, SolveScalars,
};

/// The half-row with AVX2 intrinsics (see [`crate::pipeline::simd::hs::update_half_row`]).
#[inline]
pub(in crate::pipeline::simd) fn blocks<const GROOVE: bool, const RELAX: bool>(
    _: Avx2Proof,
    k: SolveScalars,
    edges: HalfEdges,
    m: usize,
    rows: HalfRowInputs<'_>,
    dst: &mut [f32],
) {
    // SAFETY: an `Avx2Proof` exists only once the CPU reported AVX2, all `blocks_avx2` requires.
    unsafe { blocks_avx2::<GROOVE, RELAX>(k, edges, m, rows, dst) };
}

/// The portable block on 8 columns at once, operation for operation (no fused multiply–add),
/// so the result has the same bits as the portable build.
/// Every load starts a vector of the lane-major layout, so none straddles two cache lines
/// when the rows start lines; each vector of the other half is loaded once and carried.
#[target_feature(enable = "avx2")]
fn blocks_avx2<const GROOVE: bool, const RELAX: bool>(
    k: SolveScalars,
    edges: HalfEdges,
    m: usize,
    rows: HalfRowInputs<'_>,
    dst: &mut [f32],
) {
    use std::arch::x86_64::{
        _mm256_blend_ps, _mm256_blendv_ps, _mm256_castsi256_ps, _mm256_cmpeq_epi32,
        _mm256_loadu_ps, _mm256_permutevar8x32_ps, _mm256_set1_epi32, _mm256_set1_ps,
        _mm256_setr_epi32,
    };
    let ncoef = if GROOVE { GROOVE_COEFS } else { PLAIN_COEFS };
    // Everything the loop reads and writes: m vector pairs in each row, m blocks of
    // coefficients.
    let len = m * PAIR;
    let (Some(l), Some(up), Some(down), Some(out), Some(c)) = (
        rows.across.get(..len),
        rows.up.get(..len),
        rows.down.get(..len),
        dst.get_mut(..len),
        rows.coef.get(..m * LANES * ncoef),
    ) else {
        return;
    };
    let kc = Broadcast {
        quarter: _mm256_set1_ps(0.25),
        quarter_lambda: _mm256_set1_ps(k.quarter_lambda),
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
        dn: down.as_ptr(),
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
        let shift_down = _mm256_setr_epi32(1, 2, 3, 4, 5, 6, 7, 7);
        let right = (
            _mm256_blend_ps::<0x80>(_mm256_permutevar8x32_ps(first.0, shift_down), left.0),
            _mm256_blend_ps::<0x80>(_mm256_permutevar8x32_ps(first.1, shift_down), left.1),
        );
        step(m - 1, left, right);
    } else {
        // Vector m − 1 moved up a lane, lane 0 (column 0) mirrored.
        let shift_up = _mm256_setr_epi32(0, 0, 1, 2, 3, 4, 5, 6);
        let (wrap, first) = (pair(m - 1), pair(0));
        let mut left = (
            _mm256_blend_ps::<0x01>(_mm256_permutevar8x32_ps(wrap.0, shift_up), first.0),
            _mm256_blend_ps::<0x01>(_mm256_permutevar8x32_ps(wrap.1, shift_up), first.1),
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
struct Broadcast {
    quarter: __m256,
    quarter_lambda: __m256,
    omega: __m256,
}

/// Where [`blocks_avx2`] is: one pointer per row (up, down, the coefficient block, the
/// output) and the distance in floats from each u vector to its v vector.
struct BlockPtrs {
    up: *const f32,
    dn: *const f32,
    c: *const f32,
    o: *mut f32,
    dv: isize,
}

impl BlockPtrs {
    /// Moves on by one vector pair, `ncoef` vectors of coefficients.
    ///
    /// # Safety
    /// The next block must lie inside the rows, or start one past their end.
    #[inline(always)]
    unsafe fn advance(&mut self, ncoef: usize) {
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
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn block_avx2<const GROOVE: bool, const RELAX: bool>(
    k: &Broadcast,
    p: &BlockPtrs,
    [lu, ru, lv, rv]: [__m256; 4],
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
                _mm256_add_ps(_mm256_mul_ps(k.quarter_lambda, su), _mm256_mul_ps(c(0), uu)),
                _mm256_mul_ps(c(1), du),
            );
            let nv = _mm256_mul_ps(k.quarter_lambda, sv);
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
