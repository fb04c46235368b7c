//! The IRLS pass of the robust plane fit: Lorentzian weights and the weighted sums of the next fit over whole chunks of 4 points, and the choice between its portable and AVX2 builds.

use super::Isa;

/// Points per chunk: independent partial sums per accumulator (lane l of each chunk adds into
/// lane l).
pub const IRLS_LANES: usize = 4;
/// Accumulators of one pass: Σw, Σwx, Σwy, Σwz, Σwx², Σwxy, Σwy², Σwxz, Σwyz, then the
/// residual of the current plane under the previous weights: Σw′|r|, Σw′.
pub const IRLS_SUMS: usize = 11;

/// What one IRLS pass reads: centred points in structure-of-arrays form, the plane whose
/// residuals give the new weights, the Lorentzian's k = 1/(2σ²) and the previous weights.
#[derive(Clone, Copy, Debug)]
pub struct PassInputs<'a> {
    /// X of each point.
    pub x: &'a [f64],
    /// Y of each point.
    pub y: &'a [f64],
    /// Z of each point.
    pub z: &'a [f64],
    /// (a, b, c) of the plane Z = a·X + b·Y + c.
    pub plane: [f64; 3],
    /// 1/(2σ²) (0: unit weights).
    pub k: f64,
    /// The weights `plane` was fitted with.
    pub w_old: &'a [f64],
}

/// The whole-chunk part of one IRLS pass over the first `w_old.len()` points (a multiple of
/// [`IRLS_LANES`]; `w_new` as long): residual r = z − a·x − b·y − c of the plane, new weight
/// w = 1/(1 + r²·k) into `w_new`, and [`point_terms`] of point l of each chunk added into lane l
/// of `acc`. Both builds do the same operations in the same order (no FMA), so the sums are bit
/// for bit the same.
pub fn accumulate_chunks(
    isa: Isa,
    pass: PassInputs<'_>,
    w_new: &mut [f64],
    acc: &mut [[f64; IRLS_LANES]; IRLS_SUMS],
) {
    match isa {
        Isa::Portable => super::portable::irls::chunks(pass, w_new, acc),
        #[cfg(target_arch = "x86_64")]
        Isa::Avx2(proof) => super::avx2::irls::chunks(proof, pass, w_new, acc),
        #[cfg(not(target_arch = "x86_64"))]
        Isa::Avx2(_) => super::portable::irls::chunks(pass, w_new, acc),
    }
}

/// The sums one point adds for the next weighted fit: `w, w·x, w·y, w·z, w·x·x, w·x·y,
/// w·y·y, w·x·z, w·y·z` under its new weight `w`, then `wo·|r|, wo` under its old one (point
/// `[x, y, z, wo]`, residual `r`). The AVX2 build computes the same products in the same
/// order.
#[inline(always)]
pub fn point_terms([x, y, z, wo]: [f64; 4], r: f64, w: f64) -> [f64; IRLS_SUMS] {
    let (wx, wy) = (w * x, w * y);
    [
        w,
        wx,
        wy,
        w * z,
        wx * x,
        wx * y,
        wy * y,
        wx * z,
        wy * z,
        wo * r.abs(),
        wo,
    ]
}
