//! The Horn–Schunck half-row kernel: its inputs, the lane-major layout it reads, and the choice between its portable and AVX2 builds.
//!
//! The solver (`pipeline::optical_flow`) stores each colour of an image row as a half-row of
//! `m` vector pairs, lane-major: vector k holds column k of each of the half's [`LANES`] runs
//! of m columns, lane l being column `l·m + k`, and the u and v vectors alternate
//! (`[u₀ v₀ u₁ v₁ …]`, a pair is [`PAIR`] floats). A half-row's coefficient blocks follow the
//! same order: block k holds coefficient j of vector k's lanes at `8·j + l`.

use super::Isa;

/// Columns per vector (and per coefficient block).
pub const LANES: usize = 8;
/// Floats per stored vector pair (u, then v).
pub const PAIR: usize = 2 * LANES;
/// Coefficients per plain pixel: `gx, gy, gt` = `Ix, Iy, It / sqrt(λ + Ix² + Iy²)`.
pub const PLAIN_COEFS: usize = 3;
/// Coefficients per groove pixel: `wu, wd, puu, puv, pvv, pu0, pv0` (see the groove
/// coefficient rows of `optical_flow::groove`).
pub const GROOVE_COEFS: usize = 7;

/// Scalars every row update of one solve shares.
#[derive(Clone, Copy, Debug)]
pub struct SolveScalars {
    /// λ/4 (groove kernel).
    pub quarter_lambda: f32,
    /// Over-relaxation factor ω (used when the kernel relaxes).
    pub omega: f32,
}

/// Where a half-row's neighbours in the other half stop being whole vectors.
#[derive(Clone, Copy, Debug)]
pub struct HalfEdges {
    /// The odd half (column i's neighbours are the other half's i and i + 1) or the even one
    /// (i − 1 and i).
    pub odd: bool,
    /// The half's vector and lane holding the image's last column, whose missing right
    /// neighbour is mirrored (`usize::MAX` when the other half holds that column).
    pub last: (usize, usize),
}

/// What one half-row update reads, all lane-major (module docs): the other half of the same
/// row, the same half of the rows above and below (mirrored at the image edges: the row itself
/// stands in) and the half-row's coefficient blocks.
#[derive(Clone, Copy, Debug)]
pub struct HalfRowInputs<'a> {
    /// The other half of the same row.
    pub across: &'a [f32],
    /// The same half of the row above.
    pub up: &'a [f32],
    /// The same half of the row below.
    pub down: &'a [f32],
    /// The half-row's coefficient blocks.
    pub coef: &'a [f32],
}

/// Updates one stored half-row `dst` from `rows`: m pairs of u and v vectors in each row,
/// m = `dst.len() / 16`. Rows too short for that are left alone.
///
/// Even half: column i's left and right neighbours are the other half's columns i − 1 and i,
/// for vector k its vectors k − 1 and k; for k = 0 the left ones are vector m − 1 moved up a
/// lane, column 0's (lane 0) missing one mirrored, i.e. replaced by the right one. Odd half:
/// columns i and i + 1, vectors k and k + 1; for k = m − 1 the right ones are vector 0 moved
/// down a lane. The image's last column mirrors its missing right neighbour (`edges.last`).
/// Padding slots compute values that no column reads.
///
/// `GROOVE`: the general 2×2 update `u = puu·N_u + puv·N_v + pu0` (N_u = (λ/4)·Σ4u + wu·u_up +
/// wd·u_down, N_v = (λ/4)·Σ4v), else the plain one `u = ū − gx·t, v = v̄ − gy·t,
/// t = gx·ū + gy·v̄ + gt`. `RELAX`: `u ← u_old + ω·(u − u_old)`. Both builds give the same bits.
#[inline]
pub fn update_half_row<const GROOVE: bool, const RELAX: bool>(
    isa: Isa,
    k: SolveScalars,
    edges: HalfEdges,
    rows: HalfRowInputs<'_>,
    dst: &mut [f32],
) {
    let ncoef = if GROOVE { GROOVE_COEFS } else { PLAIN_COEFS };
    let m = dst.len() / PAIR;
    let len = m * PAIR;
    if m == 0
        || rows.across.len() < len
        || rows.up.len() < len
        || rows.down.len() < len
        || rows.coef.len() < m * LANES * ncoef
    {
        return;
    }
    match isa {
        Isa::Portable => super::portable::hs::blocks::<GROOVE, RELAX>(k, edges, m, rows, dst),
        #[cfg(target_arch = "x86_64")]
        Isa::Avx2(proof) => super::avx2::hs::blocks::<GROOVE, RELAX>(proof, k, edges, m, rows, dst),
        #[cfg(not(target_arch = "x86_64"))]
        Isa::Avx2(_) => super::portable::hs::blocks::<GROOVE, RELAX>(k, edges, m, rows, dst),
    }
}
