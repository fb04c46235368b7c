//! The AVX2 builds: plain code compiled with AVX2 enabled, and one file per kernel on AVX2 intrinsics.

pub(super) mod hs;
pub(super) mod irls;
pub(super) mod median;

use super::Avx2Proof;

/// `f` compiled with AVX2 enabled (see [`super::Isa::compiled`]).
#[inline(always)]
pub(super) fn compiled<R>(_: Avx2Proof, f: impl FnOnce() -> R) -> R {
    // SAFETY: an `Avx2Proof` exists only once the CPU reported AVX2, all `with_avx2` requires.
    unsafe { with_avx2(f) }
}

/// Calls `f`, which the compiler inlines here and so builds with AVX2.
#[target_feature(enable = "avx2")]
fn with_avx2<R>(f: impl FnOnce() -> R) -> R {
    f()
}
