//! A plain reference of both Horn–Schunck solves, written straight from the module docs' equations: f64, one pixel at a time, no layout, blocking or precomputed factors; the fast solver is tested against it.

use super::*;

/// How the reference iterates.
#[derive(Clone, Copy, Debug)]
pub(super) enum Sweep {
    /// Red–black Gauss–Seidel ((x + y) even first), relaxed by ω.
    GaussSeidel {
        /// Over-relaxation factor ω.
        omega: f64,
    },
    /// Jacobi: every pixel from the previous iteration's values.
    Jacobi,
}

/// The groove constraint of the reference: wall sides, focal length (px) and γ/λ.
#[derive(Clone, Copy, Debug)]
pub(super) struct GrooveConstraint<'a> {
    pub(super) walls: &'a WallSideMap,
    pub(super) focal_px: f64,
    pub(super) groove_weight: f64,
}

/// `iterations` sweeps of the Horn–Schunck update from zero residual flow; returns the total
/// flow (u with the base flow B added back, and v), row-major.
///
/// Each pixel solves the 2×2 system of the module docs with its neighbours fixed:
///
/// ```text
/// A   = λ + m_d·(w·α_d² − q) + m_o·(w·β_o² − q)
/// N_u = q·Σ4 u + m_d·(w·α_d·β_d − q)·u_{y+1} + m_o·(w·α_o·β_o − q)·u_{y−1}
///       − w·(m_o·β_o·k_o − m_d·α_d·k_d)·B
/// N_v = λ·v̄
/// u = ((λ + Iy²)·(N_u − Ix·It) − Ix·Iy·(N_v − Iy·It)) / det
/// v = ((A + Ix²)·(N_v − Iy·It) − Ix·Iy·(N_u − Ix·It)) / det,   det = (A + Ix²)(λ + Iy²) − Ix²Iy²
/// ```
///
/// with q = λ/4, w = q + γ, γ = `groove_weight`·λ, and for the edge above (o) or below (d) of
/// a pixel with wall side c ≠ 0 whose other end has the same side: m = 1,
/// k = c/(f − c·ŷ) (ŷ the edge midpoint's row from the image centre), α = 1 − k/2,
/// β = 1 + k/2. Without a groove constraint every m is 0 and this is plain Horn–Schunck. A
/// missing left or right neighbour is the opposite one (mirrored borders); a missing neighbour
/// above or below is the pixel itself, so at the fixed point the absent edge adds nothing (a
/// free border).
pub(super) fn horn_schunck(
    d: &Derivatives,
    groove: Option<GrooveConstraint<'_>>,
    lambda: f64,
    sweep: Sweep,
    iterations: usize,
) -> (Vec<f64>, Vec<f64>) {
    let (w, h) = (d.ix.width, d.ix.height);
    let n = w * h;
    let base = f64::from(d.base_flow_px);
    let q = lambda / 4.0;
    let mut u = vec![0.0_f64; n];
    let mut v = vec![0.0_f64; n];
    // Mirrored column of a missing left or right neighbour.
    let column = |x: isize| -> usize {
        if x < 0 {
            1.min(w - 1)
        } else if x as usize >= w {
            w.saturating_sub(2)
        } else {
            x as usize
        }
    };
    let update = |u: &[f64], v: &[f64], x: usize, y: usize| -> (f64, f64) {
        let i = y * w + x;
        let (left, right) = (
            y * w + column(x as isize - 1),
            y * w + column(x as isize + 1),
        );
        let up = if y > 0 { i - w } else { i };
        let down = if y + 1 < h { i + w } else { i };
        let sum4 = |f: &[f64]| f[left] + f[right] + f[up] + f[down];
        let (gx, gy, gt) = (
            f64::from(d.ix.data[i]),
            f64::from(d.iy.data[i]),
            f64::from(d.it.data[i]),
        );
        let mut a = lambda;
        let mut n_u = q * sum4(u);
        let n_v = q * sum4(v);
        if let Some(g) = groove {
            let c = g.walls.sign[i];
            let wgt = q + g.groove_weight * lambda;
            let centre = (h as f64 - 1.0) / 2.0;
            let k = |y_mid: f64| {
                let c = f64::from(c);
                c / (g.focal_px - c * (y_mid - centre))
            };
            if c != 0 && y > 0 && g.walls.sign[i - w] == c {
                let k_o = k(y as f64 - 0.5);
                let (alpha_o, beta_o) = (1.0 - k_o / 2.0, 1.0 + k_o / 2.0);
                a += wgt * beta_o * beta_o - q;
                n_u += (wgt * alpha_o * beta_o - q) * u[i - w] - wgt * beta_o * k_o * base;
            }
            if c != 0 && y + 1 < h && g.walls.sign[i + w] == c {
                let k_d = k(y as f64 + 0.5);
                let (alpha_d, beta_d) = (1.0 - k_d / 2.0, 1.0 + k_d / 2.0);
                a += wgt * alpha_d * alpha_d - q;
                n_u += (wgt * alpha_d * beta_d - q) * u[i + w] + wgt * alpha_d * k_d * base;
            }
        }
        let det = (a + gx * gx) * (lambda + gy * gy) - gx * gx * gy * gy;
        let (ru, rv) = (n_u - gx * gt, n_v - gy * gt);
        (
            ((lambda + gy * gy) * ru - gx * gy * rv) / det,
            ((a + gx * gx) * rv - gx * gy * ru) / det,
        )
    };
    for _ in 0..iterations {
        match sweep {
            Sweep::GaussSeidel { omega } => {
                for colour in 0..2 {
                    for y in 0..h {
                        for x in (0..w).filter(|x| (x + y) % 2 == colour) {
                            let (nu, nv) = update(&u, &v, x, y);
                            let i = y * w + x;
                            u[i] += omega * (nu - u[i]);
                            v[i] += omega * (nv - v[i]);
                        }
                    }
                }
            }
            Sweep::Jacobi => {
                let (old_u, old_v) = (u.clone(), v.clone());
                for y in 0..h {
                    for x in 0..w {
                        (u[y * w + x], v[y * w + x]) = update(&old_u, &old_v, x, y);
                    }
                }
            }
        }
    }
    for x in &mut u {
        *x += base;
    }
    (u, v)
}
