//! The median's comparator network on AVX2 registers.

use crate::pipeline::simd::Avx2Proof;
use crate::pipeline::simd::median::MEDIAN_LANES;

/// See [`crate::pipeline::simd::median::compare_exchange`]; the same choices as the portable
/// build (min keeps the second value on a tie, max the first).
pub(in crate::pipeline::simd) fn compare_exchange(
    _: Avx2Proof,
    pairs: &[(usize, usize)],
    v: &mut [[f32; MEDIAN_LANES]],
) {
    // SAFETY: an `Avx2Proof` exists only once the CPU reported AVX2, all `network` requires.
    unsafe { network(pairs, v) }
}

#[target_feature(enable = "avx2")]
fn network(pairs: &[(usize, usize)], v: &mut [[f32; MEDIAN_LANES]]) {
    use std::arch::x86_64::{_mm256_loadu_ps, _mm256_max_ps, _mm256_min_ps, _mm256_storeu_ps};
    const { assert!(MEDIAN_LANES == 8) };

    for &(a, b) in pairs {
        let (Some(va), Some(vb)) = (v.get(a), v.get(b)) else {
            continue;
        };
        // SAFETY: `va` and `vb` are 8 f32 each, as the unaligned loads read.
        let (x, y) = unsafe { (_mm256_loadu_ps(va.as_ptr()), _mm256_loadu_ps(vb.as_ptr())) };
        if let Some(d) = v.get_mut(a) {
            // SAFETY: 8 f32, as the unaligned store writes.
            unsafe { _mm256_storeu_ps(d.as_mut_ptr(), _mm256_min_ps(x, y)) };
        }
        if let Some(d) = v.get_mut(b) {
            // SAFETY: as above.
            unsafe { _mm256_storeu_ps(d.as_mut_ptr(), _mm256_max_ps(y, x)) };
        }
    }
}
