//! The median's comparator network in plain code (the compiler vectorises the 8 lanes).

use crate::pipeline::simd::median::MEDIAN_LANES;

/// See [`crate::pipeline::simd::median::compare_exchange`]; pairs out of range are skipped.
pub(in crate::pipeline::simd) fn compare_exchange(
    pairs: &[(usize, usize)],
    v: &mut [[f32; MEDIAN_LANES]],
) {
    for &(a, b) in pairs {
        let (Some(&va), Some(&vb)) = (v.get(a), v.get(b)) else {
            continue;
        };
        // Finite inputs only, so the plain comparisons are exact min/max.
        let lo: [f32; MEDIAN_LANES] =
            std::array::from_fn(|l| if va[l] < vb[l] { va[l] } else { vb[l] });
        let hi: [f32; MEDIAN_LANES] =
            std::array::from_fn(|l| if va[l] < vb[l] { vb[l] } else { va[l] });
        if let Some(s) = v.get_mut(a) {
            *s = lo;
        }
        if let Some(s) = v.get_mut(b) {
            *s = hi;
        }
    }
}
