//! Instruction sets: the token [`Isa`] that picks the portable or the AVX2 build of every hot kernel, detected once; with `src/alloc.rs`, the only home of `unsafe`.
//!
//! The build targets plain x86-64. The hottest loops are also compiled for AVX2 and chosen at
//! run time: plain code compiled with AVX2 enabled ([`Isa::compiled`]: the Simoncelli filter
//! bands, the groove coefficient rows, the Kalman filter's row bands), and three kernels on
//! AVX2 intrinsics, where plain code left their values, or their pointers, on the stack: the
//! Horn–Schunck half-row blocks ([`hs`]), the depth median's comparator network ([`median`])
//! and the orientation fit's IRLS pass ([`irls`]). No FMA is enabled, so both builds give the
//! same bits; tests compare them bit for bit.
//!
//! The layout follows rubato's sinc interpolator: this file holds the token; [`hs`], [`median`]
//! and [`irls`] hold each kernel's inputs and its dispatch on the token; `portable/` and
//! `avx2/` hold one file per kernel for each instruction set. [`memory`] holds the buffers
//! written straight into uninitialised memory (parallel zeroing, cache-line aligned arrays).
//!
//! A stage takes the token in its params (`isa`, never in the TOML), whose `Default` is
//! [`Isa::detect`]: the CPU is asked once, on the first call, and the answer is kept.

use std::sync::OnceLock;

#[cfg(target_arch = "x86_64")]
mod avx2;
pub mod hs;
pub mod irls;
pub mod median;
pub mod memory;
mod portable;

pub use memory::{Aligned, RowWriter, zeros_par};

/// Proof that the CPU runs AVX2: only [`Isa::detect`] makes one, so code holding it may use
/// AVX2 instructions.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Avx2Proof(());

/// The instruction set the hot kernels run on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Isa {
    /// Whatever the build target allows (SSE2 on plain x86-64; any other architecture).
    Portable,
    /// 256-bit AVX2, on a CPU that reported it (AVX-512 is not used: the sweeps are bound by
    /// cache bandwidth, docs/PERFORMANCE.md).
    Avx2(Avx2Proof),
}

impl Isa {
    /// The best instruction set of this CPU: asked on the first call, then remembered.
    #[must_use]
    pub fn detect() -> Self {
        static DETECTED: OnceLock<Isa> = OnceLock::new();
        *DETECTED.get_or_init(|| {
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx2") {
                return Isa::Avx2(Avx2Proof(()));
            }
            Isa::Portable
        })
    }

    /// AVX2 when this CPU has it (for the tests and benches that compare the two builds).
    #[must_use]
    pub fn avx2() -> Option<Self> {
        match Self::detect() {
            Isa::Avx2(proof) => Some(Isa::Avx2(proof)),
            Isa::Portable => None,
        }
    }

    /// Does `work` compiled for this instruction set: for [`Isa::Avx2`], its
    /// [`Compiled::run`] is inlined into a function built with AVX2 enabled, so the loops it
    /// inlines vectorise on 256-bit registers (the same arithmetic, so the same bits).
    #[inline(always)]
    pub fn compiled<W: Compiled>(self, work: W) -> W::Output {
        match self {
            Isa::Portable => work.run(),
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2(proof) => avx2::compiled(proof, work),
            #[cfg(not(target_arch = "x86_64"))]
            Isa::Avx2(_) => work.run(),
        }
    }
}

/// Work that [`Isa::compiled`] builds for an instruction set. A closure would not do: the
/// compiler may keep a closure's body out of line, and then it is built without the
/// instruction set; `run` is marked `#[inline(always)]` by every implementation instead.
pub trait Compiled {
    /// What the work gives back.
    type Output;
    /// Does the work (implementations mark it `#[inline(always)]`).
    fn run(self) -> Self::Output;
}

impl Default for Isa {
    /// [`Isa::detect`].
    fn default() -> Self {
        Self::detect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn detection_is_remembered_and_compiled_code_runs() {
        assert_eq!(Isa::detect(), Isa::detect());
        assert_eq!(Isa::default(), Isa::detect());
        if let Some(avx2) = Isa::avx2() {
            assert_eq!(avx2, Isa::detect());
        }
        struct SumOfSquares<'a>(&'a [f32]);
        impl Compiled for SumOfSquares<'_> {
            type Output = f32;
            #[inline(always)]
            fn run(self) -> f32 {
                self.0.iter().map(|x| x * x).sum()
            }
        }
        let v: Vec<f32> = (0..37).map(|i| i as f32 * 0.5).collect();
        for isa in [Some(Isa::Portable), Isa::avx2()].into_iter().flatten() {
            assert_eq!(isa.compiled(SumOfSquares(&v)), SumOfSquares(&v).run());
        }
    }
}
