//! A plain reference of the Kalman depth path, written straight from the module docs: f64, one pixel and one frame at a time, 3×3 matrices as arrays, a sorted median; the fast stage is tested against it.

use super::*;

/// A 3×3 matrix, row by row.
type Mat3 = [[f64; 3]; 3];

/// One pixel's state: the plane µ = (α̃, β̃, ι̃) and its covariance P.
#[derive(Clone, Copy, Debug)]
struct PixelState {
    mu: [f64; 3],
    p: Mat3,
}

fn diag(d: [f64; 3]) -> Mat3 {
    [[d[0], 0.0, 0.0], [0.0, d[1], 0.0], [0.0, 0.0, d[2]]]
}

fn mul(a: &Mat3, b: &Mat3) -> Mat3 {
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
}

fn transpose(a: &Mat3) -> Mat3 {
    std::array::from_fn(|i| std::array::from_fn(|j| a[j][i]))
}

fn mul_vec(a: &Mat3, v: &[f64; 3]) -> [f64; 3] {
    std::array::from_fn(|i| (0..3).map(|k| a[i][k] * v[k]).sum())
}

fn add(a: &Mat3, b: &Mat3) -> Mat3 {
    std::array::from_fn(|i| std::array::from_fn(|j| a[i][j] + b[i][j]))
}

/// The inverse by cofactors; None when the determinant is not positive and finite (the
/// matrices here are covariances and informations, so positive definite when usable).
fn inverse(m: &Mat3) -> Option<Mat3> {
    let cof = |i: usize, j: usize| {
        let (r0, r1) = ((i + 1) % 3, (i + 2) % 3);
        let (c0, c1) = ((j + 1) % 3, (j + 2) % 3);
        m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0]
    };
    let det = m[0][0] * cof(0, 0) + m[0][1] * cof(0, 1) + m[0][2] * cof(0, 2);
    (det > 0.0 && det.is_finite())
        .then(|| std::array::from_fn(|i| std::array::from_fn(|j| cof(j, i) / det)))
}

/// Each pixel's weight w (confidence over the frame's mean confidence of the usable pixels,
/// 0 where unusable) and normalised flow m = u/u_land; None when no pixel is usable.
fn measurements(flow: &FlowField, u_land: f64, min_confidence: f32) -> Option<Vec<(f64, f64)>> {
    let usable = |u: f32, c: f32| c.is_finite() && c >= min_confidence && u.is_finite();
    let pixels = flow.u.data.iter().zip(&flow.confidence.data);
    let (mut sum, mut count) = (0.0, 0_usize);
    for (&u, &c) in pixels.clone() {
        if usable(u, c) {
            sum += f64::from(c);
            count += 1;
        }
    }
    if count == 0 {
        return None;
    }
    let mean = sum / count as f64;
    Some(
        pixels
            .map(|(&u, &c)| {
                if !usable(u, c) {
                    (0.0, 0.0)
                } else if mean > 0.0 {
                    (f64::from(c) / mean, f64::from(u) / u_land)
                } else {
                    (1.0, f64::from(u) / u_land)
                }
            })
            .collect(),
    )
}

/// The Kalman depth map of `flows` (the `kalman = true` path of [`estimate_depth`]): Z (µm)
/// and Var Z, NaN where unknown, in the grid of the last flow.
///
/// For every frame in order and every pixel x: **prediction** (from the second frame on) takes
/// the previous state at x + f·U·ι̃·steps/Z_ref (ι̃ of the previous state at x; linear
/// interpolation; a source left of x or past the last column starts from the prior), scales
/// α̃, β̃ by s = 1/(1 − K·α̃) (K = f·U·steps/Z_ref; a plane with 1 − K·α̃ below
/// `MIN_PLANE_SCALE` restarts from the prior) and sets P ← F·P·Fᵀ + Q·steps with
/// F = [[s², 0, 0], [K·β̃·s², s, 0], [0, 0, 1]]; **update** sums J = Σ w·h·hᵀ/R and
/// b = Σ w·m·h/R over the window (h = (dx, dy, 1), R = `measurement_noise_px2`/u_land²) and,
/// where the window holds weight, sets Λ = P⁻¹ + J, µ = Λ⁻¹·(P⁻¹·µ + b), P = Λ⁻¹. Then
/// ι̃ with Var ι̃ at or above half the prior is unknown, ι̃ is median filtered over the
/// window shrunk symmetrically at the borders (the upper median of the finite values), and
/// Z = Z_ref/ι̃, Var Z = Var ι̃·(Z_ref/ι̃²)².
pub(super) fn kalman_depth(
    flows: &[FlowField],
    geom: &Geometry,
    params: &DepthParams,
) -> (Vec<f64>, Vec<f64>) {
    let Some(first) = flows.first() else {
        return (Vec::new(), Vec::new());
    };
    let (w, h) = (first.u.width, first.u.height);
    let z_ref = geom.working_distance_um;
    let land_shift_px = geom.focal_px * geom.frame_step_um / z_ref;
    let u_land = -land_shift_px;
    let r = params.neighbourhood_px / 2;
    let r2 = (r.max(1) * r.max(1)) as f64;
    let noise_var = f64::from(params.measurement_noise_px2) / (u_land * u_land);
    let q = f64::from(params.process_noise);
    let prior = PixelState {
        mu: [0.0, 0.0, 1.0],
        p: diag([
            INITIAL_VARIANCE / r2,
            INITIAL_VARIANCE / r2,
            INITIAL_VARIANCE,
        ]),
    };
    let mut state = vec![prior; w * h];
    let mut prev_index: Option<usize> = None;
    for flow in flows {
        if let Some(p) = prev_index {
            let steps = flow.frame_index.saturating_sub(p) as f64;
            let k = land_shift_px * steps;
            let old = state.clone();
            for y in 0..h {
                for x in 0..w {
                    let xs = x as f64 + k * old[y * w + x].mu[2];
                    let i0 = xs.floor();
                    state[y * w + x] = if i0 >= x as f64 && i0 + 1.0 < w as f64 {
                        let (i, t) = (i0 as usize, xs - i0);
                        let (a, b) = (old[y * w + i], old[y * w + i + 1]);
                        let lerp = |p: f64, q: f64| (1.0 - t) * p + t * q;
                        let source = PixelState {
                            mu: std::array::from_fn(|j| lerp(a.mu[j], b.mu[j])),
                            p: std::array::from_fn(|m| {
                                std::array::from_fn(|n| lerp(a.p[m][n], b.p[m][n]))
                            }),
                        };
                        predict(source, k, [q / r2 * steps, q / r2 * steps, q * steps])
                            .unwrap_or(prior)
                    } else {
                        prior
                    };
                }
            }
        }
        prev_index = Some(flow.frame_index);
        let Some(meas) = measurements(flow, u_land, params.min_confidence) else {
            continue;
        };
        for y in 0..h {
            for x in 0..w {
                let (mut j, mut b) = ([[0.0; 3]; 3], [0.0; 3]);
                for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
                    for xx in x.saturating_sub(r)..(x + r + 1).min(w) {
                        let (wt, m) = meas[yy * w + xx];
                        let hv = [xx as f64 - x as f64, yy as f64 - y as f64, 1.0];
                        for a in 0..3 {
                            for c in 0..3 {
                                j[a][c] += wt * hv[a] * hv[c] / noise_var;
                            }
                            b[a] += wt * m * hv[a] / noise_var;
                        }
                    }
                }
                if j[2][2] > 0.0 {
                    let s = &mut state[y * w + x];
                    let finite = s.mu.iter().all(|v| v.is_finite());
                    let lam = inverse(&s.p).filter(|_| finite).unwrap_or([[0.0; 3]; 3]);
                    let mu = if finite { s.mu } else { [0.0; 3] };
                    let info_mu = mul_vec(&lam, &mu);
                    if let Some(p_post) = inverse(&add(&lam, &j)) {
                        let rhs: [f64; 3] = std::array::from_fn(|a| info_mu[a] + b[a]);
                        *s = PixelState {
                            mu: mul_vec(&p_post, &rhs),
                            p: p_post,
                        };
                    }
                }
            }
        }
    }
    let limit = UNMEASURED_SHARE * INITIAL_VARIANCE;
    let (iota, var_iota): (Vec<f64>, Vec<f64>) = state
        .iter()
        .map(|s| {
            let (i, v) = (s.mu[2], s.p[2][2]);
            if v.is_finite() && v < limit && i.is_finite() {
                (i, v)
            } else {
                (f64::NAN, f64::NAN)
            }
        })
        .unzip();
    let rm = params.median_px / 2;
    let mut z = vec![f64::NAN; w * h];
    let mut var = vec![f64::NAN; w * h];
    for y in 0..h {
        for x in 0..w {
            let (rx, ry) = (rm.min(x).min(w - 1 - x), rm.min(y).min(h - 1 - y));
            let mut window: Vec<f64> = (y - ry..=y + ry)
                .flat_map(|yy| (x - rx..=x + rx).map(move |xx| yy * w + xx))
                .map(|i| iota[i])
                .filter(|v| v.is_finite())
                .collect();
            window.sort_by(f64::total_cmp);
            let Some(&io) = window.get(window.len() / 2) else {
                continue;
            };
            if io > 0.0 {
                z[y * w + x] = z_ref / io;
                var[y * w + x] = var_iota[y * w + x] * (z_ref / (io * io)).powi(2);
            }
        }
    }
    (z, var)
}

/// The plane transform and process noise on one interpolated state (module docs); None when
/// the plane scale 1 − K·α̃ falls below `MIN_PLANE_SCALE` (diverged).
fn predict(s: PixelState, k: f64, q: [f64; 3]) -> Option<PixelState> {
    let [alpha, beta, iota] = s.mu;
    let den = 1.0 - k * alpha;
    if den < MIN_PLANE_SCALE {
        return None;
    }
    let scale = 1.0 / den;
    let f: Mat3 = [
        [scale * scale, 0.0, 0.0],
        [k * beta * scale * scale, scale, 0.0],
        [0.0, 0.0, 1.0],
    ];
    Some(PixelState {
        mu: [scale * alpha, scale * beta, iota],
        p: add(&mul(&mul(&f, &s.p), &transpose(&f)), &diag(q)),
    })
}
