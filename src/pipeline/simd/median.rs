//! The comparator network of the depth median: a list of compare–exchanges run on 8 pixels at once, portable or on AVX2.

use super::Isa;

/// Pixels filtered together: one value of each per lane.
pub const MEDIAN_LANES: usize = 8;

/// Runs the comparators `pairs` over `v` in order: for each `(low, high)` the smaller of the two
/// values, lane by lane, goes to `low` and the larger to `high` (finite inputs only, so the
/// choice on a tie does not matter; both builds make the same one). Pairs that index past `v`
/// are skipped.
pub fn compare_exchange(isa: Isa, pairs: &[(usize, usize)], v: &mut [[f32; MEDIAN_LANES]]) {
    match isa {
        Isa::Portable => super::portable::median::compare_exchange(pairs, v),
        #[cfg(target_arch = "x86_64")]
        Isa::Avx2(proof) => super::avx2::median::compare_exchange(proof, pairs, v),
        #[cfg(not(target_arch = "x86_64"))]
        Isa::Avx2(_) => super::portable::median::compare_exchange(pairs, v),
    }
}
