//! The IRLS pass of the robust plane fit on whole chunks of 4 points, on AVX2 registers.

use crate::pipeline::simd::Avx2Proof;
use crate::pipeline::simd::irls::{IRLS_LANES as LANES, IRLS_SUMS as N_SUMS, PassInputs};

/// See [`crate::pipeline::simd::irls::accumulate_chunks`].
pub(in crate::pipeline::simd) fn chunks(
    _: Avx2Proof,
    pass: PassInputs<'_>,
    w_new: &mut [f64],
    acc: &mut [[f64; LANES]; N_SUMS],
) {
    // SAFETY: an `Avx2Proof` exists only once the CPU reported AVX2, all `chunks_avx2` requires.
    unsafe { chunks_avx2(pass, w_new, acc) }
}

/// The portable chunks on AVX2 registers: lane l of each 4-wide vector is lane l of its
/// accumulators, with the same operations in the same order (no FMA), so the sums are bit for
/// bit the same.
#[target_feature(enable = "avx2")]
fn chunks_avx2(pass: PassInputs<'_>, w_new: &mut [f64], acc: &mut [[f64; LANES]; N_SUMS]) {
    use std::arch::x86_64::{
        __m256d, _mm256_add_pd, _mm256_andnot_pd, _mm256_div_pd, _mm256_loadu_pd, _mm256_mul_pd,
        _mm256_set1_pd, _mm256_setzero_pd, _mm256_storeu_pd, _mm256_sub_pd,
    };
    const { assert!(LANES == 4) };
    let ([a, b, c], k, w_old) = (pass.plane, pass.k, pass.w_old);
    let full = w_old.len().min(w_new.len()) / LANES * LANES;
    let (Some(xs), Some(ys), Some(zs)) =
        (pass.x.get(..full), pass.y.get(..full), pass.z.get(..full))
    else {
        return;
    };
    let (va, vb, vc, vk) = (
        _mm256_set1_pd(a),
        _mm256_set1_pd(b),
        _mm256_set1_pd(c),
        _mm256_set1_pd(k),
    );
    let (one, sign) = (_mm256_set1_pd(1.0), _mm256_set1_pd(-0.0));
    let mut s: [__m256d; N_SUMS] = [_mm256_setzero_pd(); N_SUMS];
    let chunks = xs
        .chunks_exact(LANES)
        .zip(ys.chunks_exact(LANES))
        .zip(zs.chunks_exact(LANES))
        .zip(w_old.chunks_exact(LANES))
        .zip(w_new.chunks_exact_mut(LANES));
    for ((((xc, yc), zc), woc), wnc) in chunks {
        // SAFETY: every chunk holds 4 f64, as the unaligned loads and the store access.
        let (x, y, z, wo) = unsafe {
            (
                _mm256_loadu_pd(xc.as_ptr()),
                _mm256_loadu_pd(yc.as_ptr()),
                _mm256_loadu_pd(zc.as_ptr()),
                _mm256_loadu_pd(woc.as_ptr()),
            )
        };
        // r = ((z − a·x) − b·y) − c; w = 1/(1 + (r·r)·k), as in the portable lanes.
        let r = _mm256_sub_pd(
            _mm256_sub_pd(_mm256_sub_pd(z, _mm256_mul_pd(va, x)), _mm256_mul_pd(vb, y)),
            vc,
        );
        let w = _mm256_div_pd(
            one,
            _mm256_add_pd(one, _mm256_mul_pd(_mm256_mul_pd(r, r), vk)),
        );
        // SAFETY: as above.
        unsafe { _mm256_storeu_pd(wnc.as_mut_ptr(), w) };
        let (wx, wy) = (_mm256_mul_pd(w, x), _mm256_mul_pd(w, y));
        let terms = [
            w,
            wx,
            wy,
            _mm256_mul_pd(w, z),
            _mm256_mul_pd(wx, x),
            _mm256_mul_pd(wx, y),
            _mm256_mul_pd(wy, y),
            _mm256_mul_pd(wx, z),
            _mm256_mul_pd(wy, z),
            _mm256_mul_pd(wo, _mm256_andnot_pd(sign, r)),
            wo,
        ];
        for (sum, t) in s.iter_mut().zip(terms) {
            *sum = _mm256_add_pd(*sum, t);
        }
    }
    for (lanes, sum) in acc.iter_mut().zip(s) {
        let mut v = [0.0_f64; LANES];
        // SAFETY: `v` holds 4 f64.
        unsafe { _mm256_storeu_pd(v.as_mut_ptr(), sum) };
        for (l, x) in lanes.iter_mut().zip(v) {
            *l += x;
        }
    }
}
