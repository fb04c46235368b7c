//! The groove constraint's per-pixel factors, built a row at a time from per-row edge terms.

use super::*;

/// The edge terms of one row (see the module docs) for c = −1 (index 0) and c = +1 (1),
/// computed in f64 and rounded once: `A − λ` and the weight of u across an edge above (o) or
/// below (d), and the base-flow term of N_u for an edge above only, below only, or both. The
/// last is kept whole because its two halves nearly cancel (k_o ≈ k_d).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct RowEdges {
    pub(super) a_o: [f32; 2],
    pub(super) a_d: [f32; 2],
    pub(super) wu: [f32; 2],
    pub(super) wd: [f32; 2],
    pub(super) e_o: [f32; 2],
    pub(super) e_d: [f32; 2],
    pub(super) e_od: [f32; 2],
}

/// [`RowEdges`] of row `y`: an edge between rows at height y_mid carries
/// k = c/(f − c·ŷ) (ŷ = y_mid about the image centre), α = 1 − k/2, β = 1 + k/2.
pub(super) fn groove_row_edges(
    y: usize,
    height: usize,
    focal_px: f64,
    lambda: f64,
    gamma: f64,
    base: f64,
) -> RowEdges {
    let q = 0.25 * lambda;
    // A constrained edge carries (q + γ)·r_e² in place of q·(Δu)².
    let w = q + gamma;
    let centre = (height as f64 - 1.0) * 0.5;
    let per_side = |f: &dyn Fn(f64, f64) -> f64| {
        [-1.0_f64, 1.0].map(|c| {
            let k = |y_mid: f64| c / (focal_px - c * (y_mid - centre));
            f(k(y as f64 - 0.5), k(y as f64 + 0.5)) as f32
        })
    };
    // α and β of the edge above (k_o) and below (k_d).
    let (alpha, beta) = (|k: f64| 1.0 - 0.5 * k, |k: f64| 1.0 + 0.5 * k);
    RowEdges {
        a_o: per_side(&|k_o, _| w * beta(k_o) * beta(k_o) - q),
        a_d: per_side(&|_, k_d| w * alpha(k_d) * alpha(k_d) - q),
        wu: per_side(&|k_o, _| w * alpha(k_o) * beta(k_o) - q),
        wd: per_side(&|_, k_d| w * alpha(k_d) * beta(k_d) - q),
        e_o: per_side(&|k_o, _| -w * beta(k_o) * k_o * base),
        e_d: per_side(&|_, k_d| w * alpha(k_d) * k_d * base),
        e_od: per_side(&|k_o, k_d| -w * (beta(k_o) * k_o - alpha(k_d) * k_d) * base),
    }
}

/// One image row of the groove coefficient build.
pub(super) struct GrooveRow<'a> {
    pub(super) lambda: f32,
    pub(super) edges: RowEdges,
    pub(super) ix: &'a [f32],
    pub(super) iy: &'a [f32],
    pub(super) it: &'a [f32],
    /// Wall side per pixel of this row, the row above and the row below (a missing row stands
    /// in as this one, with `has_*` false).
    pub(super) sides: &'a [i8],
    pub(super) above: &'a [i8],
    pub(super) below: &'a [i8],
    pub(super) has_above: bool,
    pub(super) has_below: bool,
}

impl GrooveRow<'_> {
    /// Writes coefficient k of every column to `out[k]` (see the module docs):
    /// `[wu, wd, puu, puv, pvv, pu0, pv0]` such that with `N_u = q·Σ4u + wu·u_up + wd·u_down`,
    /// `N_v = q·Σ4v` (q = λ/4): `u = puu·N_u + puv·N_v + pu0`, `v = puv·N_u + pvv·N_v + pv0`.
    /// The determinant is expanded to `(A + Ix²)(λ + Iy²) − Ix²Iy² = A·(λ + Iy²) + λ·Ix²`, a
    /// sum of positive terms, so f32 keeps it accurate. Branch-free, so it vectorises.
    #[inline(always)]
    pub(super) fn fill(&self, out: &mut [Vec<f32>; GROOVE_COEFS]) {
        let w = self.sides.len();
        let (Some(ix), Some(iy), Some(it), Some(above), Some(below)) = (
            self.ix.get(..w),
            self.iy.get(..w),
            self.it.get(..w),
            self.above.get(..w),
            self.below.get(..w),
        ) else {
            return;
        };
        let [o_wu, o_wd, o_uu, o_uv, o_vv, o_u0, o_v0] = out.each_mut();
        let (Some(o_wu), Some(o_wd), Some(o_uu), Some(o_uv), Some(o_vv), Some(o_u0), Some(o_v0)) = (
            o_wu.get_mut(..w),
            o_wd.get_mut(..w),
            o_uu.get_mut(..w),
            o_uv.get_mut(..w),
            o_vv.get_mut(..w),
            o_u0.get_mut(..w),
            o_v0.get_mut(..w),
        ) else {
            return;
        };
        let (lambda, g) = (self.lambda, &self.edges);
        let or0 = |m: bool, v: f32| if m { v } else { 0.0 };
        for x in 0..w {
            let c = self.sides[x];
            // Constrained edges: both ends share c ≠ 0.
            let m_o = c != 0 && self.has_above && above[x] == c;
            let m_d = c != 0 && self.has_below && below[x] == c;
            let s = usize::from(c > 0);
            let pick = |v: [f32; 2]| if s == 1 { v[1] } else { v[0] };
            let a = lambda + (or0(m_o, pick(g.a_o)) + or0(m_d, pick(g.a_d)));
            let e = if m_o && m_d {
                pick(g.e_od)
            } else {
                or0(m_o, pick(g.e_o)) + or0(m_d, pick(g.e_d))
            };
            let (gx, gy, gt) = (ix[x], iy[x], it[x]);
            let (ix2, iy2) = (gx * gx, gy * gy);
            let inv_det = 1.0 / (a * (lambda + iy2) + lambda * ix2);
            let puu = (lambda + iy2) * inv_det;
            let puv = -(gx * gy) * inv_det;
            let pvv = (a + ix2) * inv_det;
            let ru = e - gx * gt;
            let rv = -(gy * gt);
            o_wu[x] = or0(m_o, pick(g.wu));
            o_wd[x] = or0(m_d, pick(g.wd));
            o_uu[x] = puu;
            o_uv[x] = puv;
            o_vv[x] = pvv;
            o_u0[x] = puu * ru + puv * rv;
            o_v0[x] = puv * ru + pvv * rv;
        }
    }
}

/// One [`GrooveRow::fill`], to be compiled for an instruction set.
pub(super) struct GrooveFill<'a, 'b> {
    pub(super) row: &'a GrooveRow<'b>,
    pub(super) out: &'a mut [Vec<f32>; GROOVE_COEFS],
}

impl Compiled for GrooveFill<'_, '_> {
    type Output = ();
    #[inline(always)]
    fn run(self) {
        self.row.fill(self.out);
    }
}
