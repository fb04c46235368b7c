//! The AVX2 builds: plain code compiled with AVX2 enabled, and one file per kernel on AVX2 intrinsics.

pub(super) mod hs;
pub(super) mod irls;
pub(super) mod median;

use super::{Avx2Proof, Compiled};

/// `work` compiled with AVX2 enabled (see [`super::Isa::compiled`]).
#[inline(always)]
pub(super) fn compiled<W: Compiled>(_: Avx2Proof, work: W) -> W::Output {
    // SAFETY: an `Avx2Proof` exists only once the CPU reported AVX2, all `with_avx2` requires.
    unsafe { with_avx2(work) }
}

/// Does `work`, whose `run` is inlined here and so built with AVX2.
#[target_feature(enable = "avx2")]
fn with_avx2<W: Compiled>(work: W) -> W::Output {
    work.run()
}
