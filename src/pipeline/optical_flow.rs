//! Optical flow: Horn–Schunck with the groove-orientation constraint (paper eqs. 20–23), plain Horn–Schunck and Lucas–Kanade.
//!
//! # The energy
//!
//! Both Horn–Schunck variants minimise, over the residual flow `(u, v)` left after
//! pre-warping (the total horizontal flow is `u + B`, `B` = [`Derivatives::base_flow_px`]),
//!
//! ```text
//! E = Σ_p (Ix·u + Iy·v + It)²                                     data (brightness constancy)
//!   + (λ/4)·Σ_{4-neighbour edges p~q} (v_p − v_q)²                  smoothness of v
//!   + (λ/4)·Σ_{edges not on a wall} (u_p − u_q)²                    smoothness of u
//!   + (λ/4 + γ)·Σ_{vertical wall edges e} r_e²                      groove orientation
//! ```
//!
//! Without walls this is plain Horn–Schunck; the λ/4 scaling makes its update the textbook
//! one, `u = ū − Ix·(Ix·ū + Iy·v̄ + It)/(λ + Ix² + Iy²)`, so λ plays the role of Horn &
//! Schunck's α². The left and right image borders mirror (a missing neighbour is the opposite
//! one); the top and bottom are free (a missing edge is simply absent), so a sloped u profile
//! on a wall that reaches the frame edge is not flattened there.
//!
//! # The groove constraint (paper eqs. 20–23)
//!
//! A wall is a plane at 45° across the groove. For a camera translating by U along x,
//! `u = −f·U/Z`, so `∂u/∂y = −(u/Z)·∂Z/∂y`. On a plane with `∂Z/∂Y = c` the image-row
//! derivative is `∂Z/∂y = c·Z/(f − c·y)` (y from the image centre), hence
//!
//! ```text
//! ∂u/∂y = −c·u/(f − c·y)        (paper: ∂u/∂y = −u/(c·f), the same for |y| ≪ f, c = ±1)
//! ```
//!
//! `c = ∂Z/∂Y = ±1` is the wall side ([`WallSideMap`]: +1 where depth grows toward +y, −1
//! where it shrinks, 0 on the land and bottom, where no constraint applies). We keep the
//! exact `f − c·y` form: at the frame edge (|y| ≈ 500 px, f ≈ 10 256 px) the short form
//! misstates the slope by 5 %. The constraint is a penalty on each vertical edge
//! `e = (y, y+1)` whose two pixels carry the same non-zero c, discretised at the edge midpoint:
//!
//! ```text
//! r_e = (u_{y+1} − u_y) + k_e·((u_y + u_{y+1})/2 + B),   k_e = c/(f − c·ŷ_e)
//!     = β_e·u_{y+1} − α_e·u_y + k_e·B,                   α_e = 1 − k_e/2, β_e = 1 + k_e/2
//! ```
//!
//! with `ŷ_e` the edge midpoint's row relative to the image centre. On such an edge the
//! ordinary smoothness `(λ/4)·(Δu)²`, which pulls ∂u/∂y toward 0 and so against the wall's
//! known slope, is measured against the groove orientation instead, `(λ/4)·r_e²`, and the
//! extra penalty `γ·r_e²` (`γ = groove_weight·λ`) enforces the orientation beyond plain
//! smoothing. (A purely additive `γ·r_e²` beside `(λ/4)·(Δu)²` leaves the two terms fighting:
//! on the synthetic tilted plane it made the flow worse than plain Horn–Schunck.)
//!
//! # Euler–Lagrange equations and the Gauss–Seidel update
//!
//! Write `q = λ/4`, `w = q + γ`, and `m_o, m_d ∈ {0, 1}` for whether the edge above (o) and
//! below (d) pixel p is a wall edge. Setting `½·∂E/∂u_p = ½·∂E/∂v_p = 0`:
//!
//! ```text
//! Ix·(Ix·u + Iy·v + It) + q·Σ_{non-wall neighbours}(u − u_q) + w·(m_o·β_o·r_o − m_d·α_d·r_d) = 0
//! Iy·(Ix·u + Iy·v + It) + λ·(v − v̄)                                                        = 0
//! ```
//!
//! Collecting the terms in `u_p` (`Σ4` = sum over the 4 neighbours, `v̄ = Σ4 v / 4`):
//!
//! ```text
//! A   = λ + m_d·(w·α_d² − q) + m_o·(w·β_o² − q)
//! N_u = q·Σ4 u + m_d·(w·α_d·β_d − q)·u_{y+1} + m_o·(w·α_o·β_o − q)·u_{y−1}
//!       − w·(m_o·β_o·k_o − m_d·α_d·k_d)·B
//! N_v = λ·v̄
//! [A + Ix²   Ix·Iy ] [u]   [N_u − Ix·It]
//! [Ix·Iy   λ + Iy² ] [v] = [N_v − Iy·It]
//! ```
//!
//! A Gauss–Seidel step solves this 2×2 system for `(u_p, v_p)` with the neighbours fixed
//! (det = (A + Ix²)(λ + Iy²) − Ix²Iy²):
//!
//! ```text
//! u = ((λ + Iy²)·(N_u − Ix·It) − Ix·Iy·(N_v − Iy·It)) / det
//! v = ((A + Ix²)·(N_v − Iy·It) − Ix·Iy·(N_u − Ix·It)) / det
//! ```
//!
//! Off the walls `A = λ`, `N_u = λ·ū` and this reduces to the plain update. All per-pixel
//! factors are precomputed once; an iteration is then a branch-free stencil. Gauss–Seidel
//! may be over-relaxed (SOR, `u ← u + ω·(u_GS − u)`, [`FlowParams::sor_omega`]): the same
//! fixed point, reached in far fewer sweeps (about 40 instead of 150 on the test textures).
//!
//! # Solver
//!
//! Pixels are stored red–black split (even and odd columns in separate contiguous half-rows),
//! so one colour of a row is a dense, vectorisable stencil over the other colour. A
//! half-row's per-pixel factors are interleaved in blocks of 8 columns (all factors of 8
//! columns in one run), so the kernel reads them as one stream and keeps every pointer in a
//! register (9–14 % faster than one array per factor). Several
//! iterations are run per pass over the image (temporal blocking): a wavefront keeps a band
//! of rows in cache while they are updated `2K` times (trapezoids per thread, then the small
//! inverted triangles at the band seams). Red–black Gauss–Seidel and Jacobi (ping-pong
//! buffers) share this machinery. Convergence (`mean |Δu| + |Δv| < τ`) is measured on the
//! last iteration of each block, and also on its middle one; the next block is cut to the
//! iterations a geometric fit of those two changes predicts are still needed, so a solve
//! stops close to where τ is reached rather than up to a whole block past it.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::mem::MaybeUninit;

use super::StageError;
use super::derivatives::Derivatives;
use crate::image::{Image, zeros_par};

/// Which flow algorithm runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum FlowMethod {
    /// Horn–Schunck plus ∂u/∂y = −u/(c·f) on the walls.
    #[default]
    GrooveHornSchunck,
    /// Plain Horn–Schunck.
    HornSchunck,
    /// Lucas–Kanade with the smallest-eigenvalue confidence.
    LucasKanade,
}

/// Iteration scheme of the Horn–Schunck variants.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Solver {
    /// In-place Gauss–Seidel sweeps (red–black ordering may be used for parallelism).
    #[default]
    GaussSeidel,
    /// Jacobi iteration.
    Jacobi,
}

/// Knobs of [`compute_flow`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FlowParams {
    /// Algorithm.
    pub method: FlowMethod,
    /// Iteration scheme.
    pub solver: Solver,
    /// Smoothness weight λ (α in Horn–Schunck).
    pub lambda: f32,
    /// Iteration cap (paper: 100). The groove method's wall-estimating plain pass may run up to
    /// [`WALL_PRESOLVE_MAX_ITERATIONS`] whatever this is.
    pub max_iterations: u32,
    /// Convergence threshold τ: stop when the mean absolute update falls below it (px). The
    /// default, 10⁻⁴, is set for the groove method (its wall-estimating plain pass converges to
    /// [`WALL_PRESOLVE_TOLERANCE_PX`] regardless); a plain Horn–Schunck field meant to be fully
    /// converged (a `.flo` export, the depth scenes) is closer with 10⁻⁵.
    pub tolerance_px: f32,
    /// Pixels whose gradient magnitude is below this carry no flow (confidence 0).
    pub gradient_threshold: f32,
    /// Lucas–Kanade window side, px (odd).
    pub lk_window_px: usize,
    /// Weight γ of the groove-orientation penalty, as a multiple of λ (γ = groove_weight·λ).
    pub groove_weight: f32,
    /// Over-relaxation factor ω of the Gauss–Seidel sweeps, in (0, 2): 1 is plain
    /// Gauss–Seidel, 1 < ω < 2 is SOR (the same solution, reached in fewer iterations).
    /// Jacobi ignores it.
    pub sor_omega: f32,
}

impl Default for FlowParams {
    fn default() -> Self {
        Self {
            method: FlowMethod::GrooveHornSchunck,
            solver: Solver::GaussSeidel,
            lambda: 0.05,
            max_iterations: 100,
            tolerance_px: 1e-4,
            gradient_threshold: 1e-3,
            lk_window_px: 7,
            groove_weight: 1.0,
            sor_omega: 1.7,
        }
    }
}

/// Per-pixel wall side c ∈ {−1, 0, +1} for the groove-orientation constraint (0: land or bottom).
///
/// c = ∂Z/∂Y: +1 where the surface gets deeper toward +y (the upper wall of a groove seen
/// with the land at the top), −1 where it gets shallower.
#[derive(Clone, Debug, PartialEq)]
pub struct WallSideMap {
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Row-major signs.
    pub sign: Vec<i8>,
}

/// A dense flow field in pixels per frame, in the coordinates of frame `frame_index`.
#[derive(Clone, Debug, PartialEq)]
pub struct FlowField {
    /// Horizontal flow (base flow added back).
    pub u: Image,
    /// Vertical flow.
    pub v: Image,
    /// Per-pixel confidence (gradient magnitude, or the LK smallest eigenvalue); 0 = no flow.
    pub confidence: Image,
    /// Iterations run.
    pub iterations: u32,
    /// True when τ was reached before the cap.
    pub converged: bool,
    /// Frame whose grid the field uses.
    pub frame_index: usize,
}

/// Largest accepted Lucas–Kanade window side, px.
pub const MAX_LK_WINDOW_PX: usize = 255;
/// Box over which [`estimate_wall_sides`] averages u before differentiating (columns, along the groove).
pub const WALL_BOX_X_PX: usize = 31;
/// Box over which [`estimate_wall_sides`] averages u before differentiating (rows).
pub const WALL_BOX_Y_PX: usize = 7;
/// Half the row span of the central difference [`estimate_wall_sides`] takes of the smoothed u.
pub const WALL_SLOPE_SPAN_PX: usize = 4;
/// A wall's |∂u/∂y| must be at least this fraction of the 45° value |u|/f.
pub const WALL_SLOPE_MIN_RATIO: f64 = 0.5;
/// ... and at most this multiple of it (steeper changes are borders or noise, not walls).
pub const WALL_SLOPE_MAX_RATIO: f64 = 2.0;
/// Bytes of rows the temporal blocking tries to keep cache-resident per thread.
const BLOCK_CACHE_BYTES: usize = 896 * 1024;
/// Longest block of iterations between convergence checks.
const MAX_BLOCK_ITERATIONS: usize = 16;
/// Convergence threshold of the plain pass whose flow [`estimate_wall_sides`] reads when the
/// groove method estimates its own walls (the user's τ when that is tighter). Wall sides come
/// from a parallax slope of about 2·10⁻⁴ px/px, so that pass must converge whatever τ the
/// groove pass uses: on the paper's optics, letting it stop at τ = 5·10⁻⁵ px (36 iterations)
/// put the constraint on the wrong pixels and the recovered 1 kHz tone fell to r 0.54.
pub const WALL_PRESOLVE_TOLERANCE_PX: f32 = 1e-5;
/// Iteration cap of that plain pass (the user's cap when that is larger), for the same reason:
/// capped at 30 iterations it gave r 0.47 on that tone, at 50 r 0.956, at 100 (the paper's cap,
/// where it stops on the paper's optics) r 0.993.
pub const WALL_PRESOLVE_MAX_ITERATIONS: u32 = 100;

/// Computes the flow of one derivative set.
///
/// `focal_px` is the focal length in pixels (the constraint's f); `walls` gives c per pixel
/// (when `None` the groove method estimates it itself: a plain Horn–Schunck pass, then
/// [`estimate_wall_sides`] on its u, then the groove pass warm-started from the plain flow;
/// `iterations` counts both). The plain pass stops at [`WALL_PRESOLVE_TOLERANCE_PX`] or τ,
/// whichever is tighter, within [`WALL_PRESOLVE_MAX_ITERATIONS`] or `max_iterations`,
/// whichever is larger; the groove pass at τ within `max_iterations`.
///
/// Horn–Schunck confidence is the gradient magnitude (0 below `gradient_threshold`; the
/// flow there is the smoothness fill-in). Lucas–Kanade confidence is the smallest
/// eigenvalue of the window-mean structure tensor; where it is below
/// `gradient_threshold²` the residual flow is set to 0 and the confidence to 0.
///
/// # Errors
/// [`StageError`] on invalid params (NaN, λ ≤ 0, zero iterations) or mismatched sizes.
pub fn compute_flow(
    d: &Derivatives,
    focal_px: f64,
    walls: Option<&WallSideMap>,
    params: &FlowParams,
) -> Result<FlowField, StageError> {
    compute_flow_from(d, focal_px, walls, None, params)
}

/// [`compute_flow`] with the Horn–Schunck iteration started from `init` (a flow field in this
/// window's pixel grid, total flow as in [`FlowField::u`], e.g. the previous window's result
/// moved with the content) instead of from zero. The fixed point is the same; a good start
/// reaches the tolerance in far fewer sweeps. With `walls` given and an `init`, the groove
/// solve runs alone (no plain pre-solve). Lucas–Kanade ignores `init`.
///
/// # Errors
/// As [`compute_flow`], and when `init` is not the derivatives' size.
pub fn compute_flow_from(
    d: &Derivatives,
    focal_px: f64,
    walls: Option<&WallSideMap>,
    init: Option<&FlowField>,
    params: &FlowParams,
) -> Result<FlowField, StageError> {
    validate(params)?;
    let (width, height) = check_derivatives(d)?;
    let n = width * height;
    if !d.base_flow_px.is_finite() {
        return Err(bad_input(format!(
            "base flow {} is not finite",
            d.base_flow_px
        )));
    }
    let groove = match params.method {
        FlowMethod::LucasKanade => return Ok(lucas_kanade(d, params)),
        FlowMethod::HornSchunck => false,
        FlowMethod::GrooveHornSchunck => true,
    };
    if width < 2 || height < 2 {
        return Err(bad_input(format!(
            "Horn–Schunck needs at least 2x2 pixels, got {width}x{height}"
        )));
    }
    let lay = Layout::new(width, height);
    let simd = Simd::detect();
    if let Some(f) = init {
        for (name, im) in [("u", &f.u), ("v", &f.v)] {
            if im.width != width || im.height != height || im.data.len() != n {
                return Err(bad_input(format!(
                    "initial flow {name} is {}x{}, derivatives are {width}x{height}",
                    im.width, im.height
                )));
            }
        }
    }
    let start = || match init {
        Some(f) => SplitState::from_images(&lay, &f.u, &f.v, d.base_flow_px),
        None => SplitState::zeros(&lay),
    };
    let plain = || Problem::plain(&lay, d, params.lambda);
    let (state, iterations, converged) = if groove {
        if !(focal_px.is_finite() && focal_px > 0.0) {
            return Err(StageError::InvalidParam {
                name: "focal_px".to_string(),
                problem: format!("{focal_px} is not a positive finite focal length"),
            });
        }
        let mut st = start();
        let mut first_iterations = 0;
        let estimated;
        let walls = match walls {
            Some(w) => {
                if w.width != width || w.height != height || w.sign.len() != n {
                    return Err(bad_input(format!(
                        "wall map is {}x{} ({} values), derivatives are {width}x{height}",
                        w.width,
                        w.height,
                        w.sign.len()
                    )));
                }
                w
            }
            None => {
                let presolve = FlowParams {
                    tolerance_px: params.tolerance_px.min(WALL_PRESOLVE_TOLERANCE_PX),
                    max_iterations: params.max_iterations.max(WALL_PRESOLVE_MAX_ITERATIONS),
                    ..params.clone()
                };
                let (it, _) = plain().solve(&mut st, &presolve, simd);
                first_iterations = it;
                let (u, v) = st.to_images(&lay, d.base_flow_px);
                let interim = FlowField {
                    u,
                    v,
                    confidence: Image::zeros(width, height),
                    iterations: it,
                    converged: false,
                    frame_index: d.frame_index,
                };
                estimated = estimate_wall_sides(&interim, focal_px)?;
                &estimated
            }
        };
        let problem = Problem::groove(&lay, d, walls, focal_px, params, simd);
        let (it, conv) = problem.solve(&mut st, params, simd);
        (st, first_iterations.saturating_add(it), conv)
    } else {
        let mut st = start();
        let (it, conv) = plain().solve(&mut st, params, simd);
        (st, it, conv)
    };
    let (u, v) = state.to_images(&lay, d.base_flow_px);
    Ok(FlowField {
        u,
        v,
        confidence: gradient_confidence(d, params.gradient_threshold),
        iterations,
        converged,
        frame_index: d.frame_index,
    })
}

/// The flow stage's confidence map alone: which pixels carry flow, as [`compute_flow`] would
/// report them, without solving for u and v. For the Horn–Schunck methods that is the gradient
/// magnitude at or above `gradient_threshold`, and u and v are left empty (0×0, no iterations);
/// Lucas–Kanade's confidence is its smallest eigenvalue, so it runs in full (it has no
/// iterations to skip). The dual-focus stripes read nothing else from the flow stage.
///
/// # Errors
/// As [`compute_flow`].
pub fn flow_confidence_only(d: &Derivatives, params: &FlowParams) -> Result<FlowField, StageError> {
    validate(params)?;
    if params.method == FlowMethod::LucasKanade {
        return compute_flow(d, 1.0, None, params);
    }
    check_derivatives(d)?;
    Ok(FlowField {
        u: Image::zeros(0, 0),
        v: Image::zeros(0, 0),
        confidence: gradient_confidence(d, params.gradient_threshold),
        iterations: 0,
        converged: false,
        frame_index: d.frame_index,
    })
}

/// The derivatives' size (width, height) when Ix, Iy and It share it and it is not empty.
fn check_derivatives(d: &Derivatives) -> Result<(usize, usize), StageError> {
    let (width, height) = (d.ix.width, d.ix.height);
    for (name, im) in [("ix", &d.ix), ("iy", &d.iy), ("it", &d.it)] {
        if im.width != width || im.height != height || im.data.len() != width * height {
            return Err(bad_input(format!(
                "derivative {name} is {}x{} ({} values), ix is {width}x{height}",
                im.width,
                im.height,
                im.data.len()
            )));
        }
    }
    if width * height == 0 {
        return Err(bad_input("empty derivative images".to_string()));
    }
    Ok((width, height))
}

fn bad_input(problem: String) -> StageError {
    StageError::BadInput {
        stage: "optical flow",
        problem,
    }
}

fn validate(p: &FlowParams) -> Result<(), StageError> {
    super::check_range(
        "flow.lambda",
        f64::from(p.lambda),
        f64::from(f32::MIN_POSITIVE),
        f64::from(f32::MAX),
    )?;
    super::check_range(
        "flow.tolerance_px",
        f64::from(p.tolerance_px),
        0.0,
        f64::from(f32::MAX),
    )?;
    super::check_range(
        "flow.gradient_threshold",
        f64::from(p.gradient_threshold),
        0.0,
        f64::from(f32::MAX),
    )?;
    super::check_range(
        "flow.groove_weight",
        f64::from(p.groove_weight),
        0.0,
        f64::from(f32::MAX),
    )?;
    if !(p.sor_omega > 0.0 && p.sor_omega < 2.0) {
        return Err(StageError::InvalidParam {
            name: "flow.sor_omega".to_string(),
            problem: format!("{} is not in (0, 2)", p.sor_omega),
        });
    }
    if p.max_iterations == 0 {
        return Err(StageError::InvalidParam {
            name: "flow.max_iterations".to_string(),
            problem: "must be at least 1".to_string(),
        });
    }
    if p.lk_window_px.is_multiple_of(2) || p.lk_window_px < 3 || p.lk_window_px > MAX_LK_WINDOW_PX {
        return Err(StageError::InvalidParam {
            name: "flow.lk_window_px".to_string(),
            problem: format!(
                "{} must be odd and in [3, {MAX_LK_WINDOW_PX}]",
                p.lk_window_px
            ),
        });
    }
    Ok(())
}

/// `sqrt(Ix² + Iy²)`, zeroed below `threshold` (a row at a time, so the loop vectorises).
fn gradient_confidence(d: &Derivatives, threshold: f32) -> Image {
    let w = d.ix.width.max(1);
    let mut data = zeros_par(d.ix.data.len());
    data.par_chunks_mut(w)
        .zip(d.ix.data.par_chunks(w))
        .zip(d.iy.data.par_chunks(w))
        .for_each(|((out, ix), iy)| {
            for ((o, &gx), &gy) in out.iter_mut().zip(ix).zip(iy) {
                let g = (gx * gx + gy * gy).sqrt();
                *o = if g >= threshold && g.is_finite() {
                    g
                } else {
                    0.0
                };
            }
        });
    Image {
        width: d.ix.width,
        height: d.ix.height,
        data,
    }
}

// ---------------------------------------------------------------------------------------------
// Wall sides
// ---------------------------------------------------------------------------------------------

/// Estimates the wall side c per pixel from a flow field (u with its base flow).
///
/// u is box-averaged over [`WALL_BOX_X_PX`] × [`WALL_BOX_Y_PX`] (long along the groove),
/// then its row slope `s = ∂ū/∂y` is taken as a central difference over
/// ±[`WALL_SLOPE_SPAN_PX`] rows. On a 45° wall `|s| ≈ |u|/f` and `c = −sign(s·u)` (from
/// `∂u/∂y = −c·u/f`); a pixel gets that c when `|s|` lies within
/// [[`WALL_SLOPE_MIN_RATIO`], [`WALL_SLOPE_MAX_RATIO`]] × `|ū|/f`, and 0 otherwise (land and
/// bottom have `s ≈ 0`; much steeper changes are borders or noise). The parallax slope is
/// small (2·10⁻⁴ px/px at the paper's optics), so this needs a well-converged, low-noise flow.
///
/// # Errors
/// [`StageError::InvalidParam`] when `focal_px` is not positive and finite;
/// [`StageError::BadInput`] when u is empty or malformed.
pub fn estimate_wall_sides(flow: &FlowField, focal_px: f64) -> Result<WallSideMap, StageError> {
    if !(focal_px.is_finite() && focal_px > 0.0) {
        return Err(StageError::InvalidParam {
            name: "focal_px".to_string(),
            problem: format!("{focal_px} is not a positive finite focal length"),
        });
    }
    let u = &flow.u;
    let (width, height) = (u.width, u.height);
    if width == 0 || height == 0 || u.data.len() != width * height {
        return Err(bad_input(format!(
            "flow u is {width}x{height} with {} values",
            u.data.len()
        )));
    }
    let smooth = box_mean(u, WALL_BOX_X_PX / 2, WALL_BOX_Y_PX / 2);
    let mut sign = vec![0_i8; width * height];
    sign.par_chunks_mut(width).enumerate().for_each(|(y, row)| {
        let y0 = y.saturating_sub(WALL_SLOPE_SPAN_PX);
        let y1 = (y + WALL_SLOPE_SPAN_PX).min(height - 1);
        if y1 == y0 {
            return;
        }
        let span = (y1 - y0) as f64;
        let (r0, r1, rc) = (
            &smooth[y0 * width..(y0 + 1) * width],
            &smooth[y1 * width..(y1 + 1) * width],
            &smooth[y * width..(y + 1) * width],
        );
        for (x, c) in row.iter_mut().enumerate() {
            let slope = (r1[x] - r0[x]) / span;
            let expected = rc[x].abs() / focal_px;
            let mag = slope.abs();
            if expected > 0.0
                && mag >= WALL_SLOPE_MIN_RATIO * expected
                && mag <= WALL_SLOPE_MAX_RATIO * expected
            {
                *c = if slope * rc[x] < 0.0 { 1 } else { -1 };
            }
        }
    });
    Ok(WallSideMap {
        width,
        height,
        sign,
    })
}

/// Mean over the in-image part of a (2rx+1)×(2ry+1) box, in f64.
fn box_mean(im: &Image, rx: usize, ry: usize) -> Vec<f64> {
    let (w, h) = (im.width, im.height);
    // Horizontal box means from running sums along each row.
    let mut horiz = vec![0.0_f64; w * h];
    horiz
        .par_chunks_mut(w)
        .zip(im.data.par_chunks(w))
        .for_each_init(Vec::new, |prefix: &mut Vec<f64>, (dst, src)| {
            prefix.clear();
            prefix.push(0.0_f64);
            let mut acc = 0.0;
            for &v in src {
                acc += f64::from(if v.is_finite() { v } else { 0.0 });
                prefix.push(acc);
            }
            let mean = |x: usize| {
                let a = x.saturating_sub(rx);
                let b = (x + rx + 1).min(w);
                (prefix[b] - prefix[a]) / (b - a) as f64
            };
            // Columns whose box lies inside the row, [rx, w − rx) (empty when w ≤ 2·rx): one
            // vectorisable loop over two offset slices of the running sums.
            let lo = rx.min(w);
            let hi = w.saturating_sub(rx).max(lo);
            let full = (2 * rx + 1) as f64;
            if let (Some(mid), Some(ends), Some(starts)) = (
                dst.get_mut(lo..hi),
                prefix.get(lo + rx + 1..hi + rx + 1),
                prefix.get(lo.saturating_sub(rx)..hi.saturating_sub(rx)),
            ) {
                for ((d, &b), &a) in mid.iter_mut().zip(ends).zip(starts) {
                    *d = (b - a) / full;
                }
            }
            for x in (0..lo).chain(hi..w) {
                if let Some(d) = dst.get_mut(x) {
                    *d = mean(x);
                }
            }
        });
    let mut out = vec![0.0_f64; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(y, dst)| {
        let a = y.saturating_sub(ry);
        let b = (y + ry + 1).min(h);
        for yy in a..b {
            for (d, s) in dst.iter_mut().zip(&horiz[yy * w..(yy + 1) * w]) {
                *d += s;
            }
        }
        let inv = 1.0 / (b - a) as f64;
        for d in dst.iter_mut() {
            *d *= inv;
        }
    });
    out
}

// ---------------------------------------------------------------------------------------------
// Lucas–Kanade
// ---------------------------------------------------------------------------------------------

/// Lucas–Kanade: per pixel, least squares over a square window of the structure tensor.
fn lucas_kanade(d: &Derivatives, params: &FlowParams) -> FlowField {
    let (w, h) = (d.ix.width, d.ix.height);
    let r = params.lk_window_px / 2;
    // Window sums of IxIx, IxIy, IyIy, IxIt, IyIt (in-image part of the window).
    let products: [Image; 5] = std::array::from_fn(|k| {
        let data =
            d.ix.data
                .par_iter()
                .zip(d.iy.data.par_iter())
                .zip(d.it.data.par_iter())
                .map(|((&gx, &gy), &gt)| match k {
                    0 => gx * gx,
                    1 => gx * gy,
                    2 => gy * gy,
                    3 => gx * gt,
                    _ => gy * gt,
                })
                .collect();
        Image {
            width: w,
            height: h,
            data,
        }
    });
    let sums = products.map(|p| box_mean(&p, r, r));
    let min_eigen = f64::from(params.gradient_threshold) * f64::from(params.gradient_threshold);
    let base = d.base_flow_px;
    let mut u = vec![base; w * h];
    let mut v = vec![0.0_f32; w * h];
    let mut conf = vec![0.0_f32; w * h];
    u.par_iter_mut()
        .zip(v.par_iter_mut())
        .zip(conf.par_iter_mut())
        .enumerate()
        .for_each(|(i, ((u, v), c))| {
            let (a, b, cc, p, q) = (sums[0][i], sums[1][i], sums[2][i], sums[3][i], sums[4][i]);
            let half_trace = 0.5 * (a + cc);
            let diff = 0.5 * (a - cc);
            let lambda_min = half_trace - (diff * diff + b * b).sqrt();
            let det = a * cc - b * b;
            if lambda_min.is_finite() && lambda_min >= min_eigen && lambda_min > 0.0 && det > 0.0 {
                *u = base + ((-cc * p + b * q) / det) as f32;
                *v = ((b * p - a * q) / det) as f32;
                *c = lambda_min as f32;
            }
        });
    let wrap = |data| Image {
        width: w,
        height: h,
        data,
    };
    FlowField {
        u: wrap(u),
        v: wrap(v),
        confidence: wrap(conf),
        iterations: 1,
        converged: true,
        frame_index: d.frame_index,
    }
}

// ---------------------------------------------------------------------------------------------
// Horn–Schunck: layout and coefficients
// ---------------------------------------------------------------------------------------------

/// Sizes of the red–black split: half-row `E` holds even columns, `O` odd ones.
#[derive(Clone, Copy, Debug)]
struct Layout {
    width: usize,
    height: usize,
    /// Even-column count, ⌈w/2⌉.
    ne: usize,
    /// Odd-column count, ⌊w/2⌋.
    no: usize,
}

impl Layout {
    fn new(width: usize, height: usize) -> Self {
        Self {
            width,
            height,
            ne: width.div_ceil(2),
            no: width / 2,
        }
    }

    /// Columns in half `hp` (0 = even, 1 = odd).
    fn half(&self, hp: usize) -> usize {
        if hp == 0 { self.ne } else { self.no }
    }
}

/// Flow state in split layout: per row, `[u(n) | v(n)]` for each half.
#[derive(Clone, Debug, Default)]
struct SplitState {
    e: Vec<f32>,
    o: Vec<f32>,
}

impl SplitState {
    fn zeros(lay: &Layout) -> Self {
        Self {
            e: zeros_par(2 * lay.ne * lay.height),
            o: zeros_par(2 * lay.no * lay.height),
        }
    }

    /// From images (the inverse of [`SplitState::to_images`]); `base` is subtracted from u and
    /// non-finite values start at 0.
    fn from_images(lay: &Layout, u: &Image, v: &Image, base: f32) -> Self {
        let mut st = Self::zeros(lay);
        let w = lay.width;
        let split = |row: &[f32], even: &mut [f32], odd: &mut [f32], base: f32| {
            split_columns(row, even, odd, |d, x| {
                let y = x - base;
                *d = if y.is_finite() { y } else { 0.0 };
            });
        };
        st.e.par_chunks_mut(2 * lay.ne)
            .zip(st.o.par_chunks_mut(2 * lay.no.max(1)))
            .zip(u.data.par_chunks(w))
            .zip(v.data.par_chunks(w))
            .for_each(|(((er, or), ur), vr)| {
                let (eu, ev) = er.split_at_mut(lay.ne);
                let (ou, ov) = or.split_at_mut(lay.no.min(or.len()));
                split(ur, eu, ou, base);
                split(vr, ev, ov, 0.0);
            });
        st
    }

    /// Back to images; `base` is added to u.
    fn to_images(&self, lay: &Layout, base: f32) -> (Image, Image) {
        let (w, h) = (lay.width, lay.height);
        let mut u = zeros_par(w * h);
        let mut v = zeros_par(w * h);
        // Interleaves a row's even and odd columns.
        let merge = |row: &mut [f32], even: &[f32], odd: &[f32], base: f32| {
            let mut pairs = row.chunks_exact_mut(2);
            for ((pair, &e), &o) in (&mut pairs).zip(even).zip(odd) {
                pair[0] = e + base;
                pair[1] = o + base;
            }
            if let (Some(last), Some(&e_last)) =
                (pairs.into_remainder().first_mut(), even.get(odd.len()))
            {
                *last = e_last + base;
            }
        };
        u.par_chunks_mut(w)
            .zip(v.par_chunks_mut(w))
            .zip(self.e.par_chunks(2 * lay.ne))
            .zip(self.o.par_chunks(2 * lay.no.max(1)))
            .for_each(|(((ur, vr), er), or)| {
                let (eu, ev) = er.split_at(lay.ne);
                let (ou, ov) = or.split_at(lay.no.min(or.len()));
                merge(ur, eu, ou, base);
                // Adding −0 leaves every value, −0 included, as it is.
                merge(vr, ev, ov, -0.0);
            });
        let wrap = |data| Image {
            width: w,
            height: h,
            data,
        };
        (wrap(u), wrap(v))
    }
}

/// Splits a row of w values into its ⌈w/2⌉ even columns and ⌊w/2⌋ odd ones: `put(slot, value)`
/// for each. With `even` and `odd` of exactly those lengths every slot is put once: the
/// ⌊w/2⌋ column pairs fill `odd` and the first ⌊w/2⌋ of `even`, an odd width's last column
/// the last of `even`.
#[inline(always)]
fn split_columns<T>(row: &[f32], even: &mut [T], odd: &mut [T], put: impl Fn(&mut T, f32)) {
    let pairs = row.chunks_exact(2);
    if let (Some(&last), Some(e_last)) = (pairs.remainder().first(), even.get_mut(odd.len())) {
        put(e_last, last);
    }
    for ((pair, e), o) in pairs.zip(even.iter_mut()).zip(odd.iter_mut()) {
        put(e, pair[0]);
        put(o, pair[1]);
    }
}

/// Coefficients per plain pixel: `gx, gy, gt` = `Ix, Iy, It / sqrt(λ + Ix² + Iy²)`.
const PLAIN_COEFS: usize = 3;
/// Coefficients per groove pixel: `wu, wd, puu, puv, pvv, pu0, pv0` (see [`GrooveRow::fill`]).
const GROOVE_COEFS: usize = 7;

/// Which stencil the solver runs.
#[derive(Clone, Copy, Debug)]
enum Kernel {
    /// `u = ū − gx·t, v = v̄ − gy·t, t = gx·ū + gy·v̄ + gt`.
    Plain,
    /// The general 2×2 update; `q` = λ/4.
    Groove { q: f32 },
}

impl Kernel {
    fn coefs(self) -> usize {
        match self {
            Kernel::Plain => PLAIN_COEFS,
            Kernel::Groove { .. } => GROOVE_COEFS,
        }
    }
}

/// Columns per coefficient block: a row kernel reads every coefficient of 8 columns from one
/// contiguous block (one stream per half-row instead of one per coefficient).
const LANES: usize = 8;

/// Where the coefficients of one half-row live. Column `i` takes slot `(i − first) mod n`,
/// `first` being the half's first core column (1 in the even half, whose column 0 has no left
/// neighbour; 0 in the odd half), so the kernel's core runs over whole blocks from slot 0 and
/// the even half's column 0 takes the last slot. Slot `j` keeps coefficient `k` at
/// `(j / 8)·8·C + 8·k + j mod 8`; the last block is padded with zeros.
#[derive(Clone, Copy, Debug)]
struct CoefRow {
    /// Columns in the half.
    n: usize,
    /// First core column (slot 0).
    first: usize,
    /// Coefficients per column.
    c: usize,
}

impl CoefRow {
    /// Half `hp` (0 = even, 1 = odd) of `lay` with `c` coefficients per column.
    fn new(lay: &Layout, hp: usize, c: usize) -> Self {
        Self {
            n: lay.half(hp),
            first: usize::from(hp == 0),
            c,
        }
    }

    /// Values per half-row, padding included.
    fn len(self) -> usize {
        self.n.div_ceil(LANES) * LANES * self.c
    }

    /// Index of coefficient `k` of slot `j`.
    #[inline(always)]
    fn at_slot(self, j: usize, k: usize) -> usize {
        (j / LANES) * LANES * self.c + k * LANES + j % LANES
    }

    /// Writes this half-row's blocks into `dst` (a half-row of [`CoefRow::len`] values) from
    /// `cols[k]`, coefficient k over the half's n columns: slot j holds column
    /// (j + first) mod n; the padding holds 0. Block by block, so each cache line is written
    /// whole at once.
    fn scatter<const C: usize>(self, cols: &[Vec<f32>; C], dst: &mut [MaybeUninit<f32>]) {
        // Slots below `plain` hold columns j + first.
        let plain = self.n - self.first;
        for (b, block) in dst.chunks_exact_mut(LANES * C).enumerate() {
            let j0 = b * LANES;
            let start = j0 + self.first;
            for (out, col) in block.chunks_exact_mut(LANES).zip(cols) {
                match col.get(start..start + LANES) {
                    Some(src) if j0 + LANES <= plain => {
                        for (d, &x) in out.iter_mut().zip(src) {
                            d.write(x);
                        }
                    }
                    _ => {
                        for (l, d) in out.iter_mut().enumerate() {
                            let j = j0 + l;
                            let column = if j < plain {
                                Some(j + self.first)
                            } else {
                                (j < self.n).then(|| j - plain)
                            };
                            d.write(column.and_then(|i| col.get(i)).copied().unwrap_or(0.0));
                        }
                    }
                }
            }
        }
    }

    /// Index of coefficient `k` of column `i` (< n).
    #[inline(always)]
    fn at(self, i: usize, k: usize) -> usize {
        let j = if i >= self.first {
            i - self.first
        } else {
            self.n - self.first + i
        };
        self.at_slot(j, k)
    }
}

/// A Horn–Schunck system ready to iterate: per half-row blocks of coefficients laid out as
/// [`CoefRow`] says.
struct Problem {
    lay: Layout,
    kernel: Kernel,
    coef_e: Vec<f32>,
    coef_o: Vec<f32>,
}

impl Problem {
    /// Fills the coefficient arrays a row at a time: `f(y, rows)` writes coefficient k of every
    /// column of image row `y` into `rows[k]` (natural column order, so the caller's loop can
    /// vectorise); the rows are then split into their even and odd halves, in blocks.
    fn build_rows<const C: usize>(
        lay: &Layout,
        kernel: Kernel,
        f: impl Fn(usize, &mut [Vec<f32>; C]) + Sync,
    ) -> Self {
        let w = lay.width;
        let halves = [CoefRow::new(lay, 0, C), CoefRow::new(lay, 1, C)];
        let (len_e, len_o) = (halves[0].len() * lay.height, halves[1].len() * lay.height);
        let mut coef_e: Vec<f32> = Vec::with_capacity(len_e);
        let mut coef_o: Vec<f32> = Vec::with_capacity(len_o);
        // Width ≥ 2 (checked by the caller), so both halves have columns; `max(1)` only keeps
        // the chunk size valid.
        coef_e.spare_capacity_mut()[..len_e]
            .par_chunks_mut(halves[0].len().max(1))
            .zip(coef_o.spare_capacity_mut()[..len_o].par_chunks_mut(halves[1].len().max(1)))
            .enumerate()
            .for_each_init(
                // The image row's C coefficients, then their even and odd columns.
                || [w, lay.ne, lay.no].map(|n| std::array::from_fn(|_| vec![0.0_f32; n])),
                |[rows, even, odd]: &mut [[Vec<f32>; C]; 3], (y, (re, ro))| {
                    f(y, rows);
                    for ((full, e), o) in rows.iter_mut().zip(even.iter_mut()).zip(odd.iter_mut()) {
                        // `f` may not change the length: every column is split below.
                        full.resize(w, 0.0);
                        split_columns(full, e, o, |d, x| *d = x);
                    }
                    halves[0].scatter(even, re);
                    halves[1].scatter(odd, ro);
                },
            );
        // SAFETY: the capacities are at least `len_e` and `len_o`, and the loop above wrote
        // every element of both: the chunks cover them, a chunk is one half-row of
        // `CoefRow::len` values, and `CoefRow::scatter` writes every coefficient of every slot
        // and the padding: each of its blocks' C runs of 8.
        unsafe {
            coef_e.set_len(len_e);
            coef_o.set_len(len_o);
        }
        Self {
            lay: *lay,
            kernel,
            coef_e,
            coef_o,
        }
    }

    fn plain(lay: &Layout, d: &Derivatives, lambda: f32) -> Self {
        let w = lay.width;
        Self::build_rows::<PLAIN_COEFS>(lay, Kernel::Plain, |y, [gx, gy, gt]| {
            let span = y * w..(y + 1) * w;
            let (Some(ix), Some(iy), Some(it)) = (
                d.ix.data.get(span.clone()),
                d.iy.data.get(span.clone()),
                d.it.data.get(span),
            ) else {
                return;
            };
            let outs = gx.iter_mut().zip(gy.iter_mut()).zip(gt.iter_mut());
            for (((a, b), c), ((&ix, &iy), &it)) in outs.zip(ix.iter().zip(iy).zip(it)) {
                let s = 1.0 / (lambda + ix * ix + iy * iy).sqrt();
                (*a, *b, *c) = (ix * s, iy * s, it * s);
            }
        })
    }

    /// The groove system, its coefficient rows built with `simd`.
    fn groove(
        lay: &Layout,
        d: &Derivatives,
        walls: &WallSideMap,
        focal_px: f64,
        params: &FlowParams,
        simd: Simd,
    ) -> Self {
        let (w, h) = (lay.width, lay.height);
        let lambda = f64::from(params.lambda);
        let gamma = f64::from(params.groove_weight) * lambda;
        let base = f64::from(d.base_flow_px);
        Self::build_rows::<GROOVE_COEFS>(
            lay,
            Kernel::Groove {
                q: 0.25 * params.lambda,
            },
            |y, rows| {
                let span = y * w..(y + 1) * w;
                let (Some(ix), Some(iy), Some(it), Some(sides)) = (
                    d.ix.data.get(span.clone()),
                    d.iy.data.get(span.clone()),
                    d.it.data.get(span.clone()),
                    walls.sign.get(span),
                ) else {
                    return;
                };
                // A missing row above or below stands in as the row itself, with its edges
                // switched off, so the loop over the row is branch-free and vectorises.
                let (above, has_above) = y
                    .checked_sub(1)
                    .and_then(|yy| walls.sign.get(yy * w..(yy + 1) * w))
                    .map_or((sides, false), |r| (r, true));
                let (below, has_below) = walls
                    .sign
                    .get((y + 1) * w..(y + 2) * w)
                    .map_or((sides, false), |r| (r, true));
                let row = GrooveRow {
                    lambda: params.lambda,
                    edges: groove_row_edges(y, h, focal_px, lambda, gamma, base),
                    ix,
                    iy,
                    it,
                    sides,
                    above,
                    below,
                    has_above,
                    has_below,
                };
                simd.groove_row(&row, rows);
            },
        )
    }

    /// Iterates from the state in `st`; returns (iterations, converged).
    fn solve(&self, st: &mut SplitState, params: &FlowParams, simd: Simd) -> (u32, bool) {
        self.solve_with(st, params, simd, rayon::current_num_threads(), None)
    }

    /// [`Problem::solve`] with at most `max_bands` row bands and, if given, a fixed block length.
    fn solve_with(
        &self,
        st: &mut SplitState,
        params: &FlowParams,
        simd: Simd,
        max_bands: usize,
        block_override: Option<usize>,
    ) -> (u32, bool) {
        let lay = &self.lay;
        let jacobi = params.solver == Solver::Jacobi;
        let floats_per_px = self.kernel.coefs() + if jacobi { 4 } else { 2 };
        let row_bytes = lay.width * floats_per_px * std::mem::size_of::<f32>();
        let rows_fit = (BLOCK_CACHE_BYTES / row_bytes.max(1)).max(4);
        // Levels (half-sweeps for red–black, sweeps for Jacobi) per block.
        let per_iteration = if jacobi { 1 } else { 2 };
        let block_iterations = block_override
            .unwrap_or((rows_fit - 2) / per_iteration)
            .clamp(1, MAX_BLOCK_ITERATIONS);
        let threads = max_bands.max(1);
        let mut other = if jacobi { Some(st.clone()) } else { None };
        let max = params.max_iterations as usize;
        let pixels = (lay.width * lay.height) as f64;
        let tolerance = f64::from(params.tolerance_px);
        // With τ = 0 nothing can converge: the changes are not measured at all.
        let measure = tolerance > 0.0;
        let mut done = 0;
        let mut next = block_iterations;
        let mut last: Option<(usize, f64)> = None;
        while done < max {
            let k = next.min(max - done);
            let levels = k * per_iteration;
            let bands = threads.min(lay.height / (2 * levels + 2)).max(1);
            let (mid, delta) = match other.as_mut() {
                None => self.block(
                    simd,
                    &mut [&mut *st],
                    levels,
                    bands,
                    params.sor_omega,
                    measure,
                ),
                Some(b) => {
                    let delta =
                        self.block(simd, &mut [&mut *st, &mut *b], levels, bands, 1.0, measure);
                    if !levels.is_multiple_of(2) {
                        std::mem::swap(st, b);
                    }
                    delta
                }
            };
            done += k;
            let per_px = delta / pixels;
            if per_px < tolerance {
                return (u32::try_from(done).unwrap_or(u32::MAX), true);
            }
            if block_override.is_none() {
                // The decay rate from the block's middle iteration (or, for a short block, the
                // previous block's last) to its last one predicts the iterations still needed.
                let before = (k >= 2).then(|| (done - k + k / 2, mid / pixels)).or(last);
                next = before
                    .and_then(|b| iterations_to_tolerance(b, (done, per_px), tolerance))
                    .unwrap_or(block_iterations)
                    .clamp(1, block_iterations);
            }
            last = Some((done, per_px));
        }
        (u32::try_from(done).unwrap_or(u32::MAX), false)
    }

    /// Runs `levels` levels (red–black half-sweeps with one state, Jacobi sweeps with two:
    /// level h reads state `h % 2` and writes the other) over the whole image, temporally
    /// blocked: each of `bands` row bands first runs the trapezoid that needs no rows of its
    /// neighbours (a wavefront, so the rows being updated stay in cache), then the inverted
    /// triangles around each band seam finish the levels. Returns Σ(|Δu| + |Δv|) over the
    /// middle iteration (the ⌊k/2⌋-th of k; 0 when k < 2) and over the last one, or zeros
    /// when not `measure`.
    fn block(
        &self,
        simd: Simd,
        states: &mut [&mut SplitState],
        levels: usize,
        bands: usize,
        omega: f32,
        measure: bool,
    ) -> (f64, f64) {
        let h = self.lay.height;
        let bounds: Vec<(usize, usize)> = (0..bands)
            .map(|b| (b * h / bands, (b + 1) * h / bands))
            .collect();
        // Levels per iteration: two half-sweeps (red–black, one state) or one sweep (Jacobi).
        let per = if states.len() == 1 { 2 } else { 1 };
        let iterations = levels / per;
        let mid = iterations / 2;
        let sched = Schedule {
            levels,
            measure_from: if measure {
                levels.saturating_sub(per)
            } else {
                usize::MAX
            },
            mid: if measure && mid >= 1 && mid < iterations {
                (mid - 1) * per..mid * per
            } else {
                0..0
            },
            omega,
        };
        let chunks = split_chunks(&self.lay, states, &bounds);
        let add = |a: (f64, f64), b: (f64, f64)| (a.0 + b.0, a.1 + b.1);
        let mut delta = chunks
            .into_par_iter()
            .map(|mut ch| self.phase_one(simd, &mut ch, &sched))
            .reduce(|| (0.0, 0.0), add);
        if bands > 1 {
            let reach = levels + 1;
            let zones: Vec<(usize, usize)> = bounds[1..]
                .iter()
                .map(|&(seam, _)| (seam - reach, seam + reach))
                .collect();
            let chunks = split_chunks(&self.lay, states, &zones);
            delta = add(
                delta,
                chunks
                    .into_par_iter()
                    .map(|mut ch| self.phase_two(simd, &mut ch, &sched))
                    .reduce(|| (0.0, 0.0), add),
            );
        }
        delta
    }

    /// The band's own trapezoid: level h covers rows `[a + h + 1, b − h − 1)` (no shrink at
    /// the image top and bottom), visited as a wavefront (row s − h at step s).
    fn phase_one(&self, simd: Simd, ch: &mut Chunk, s: &Schedule) -> (f64, f64) {
        let (a, b, h_img) = (ch.y0, ch.y0 + ch.rows, self.lay.height);
        let lo = |lvl: usize| if a == 0 { 0 } else { a + lvl + 1 };
        let hi = |lvl: usize| {
            if b == h_img {
                h_img
            } else {
                b.saturating_sub(lvl + 1)
            }
        };
        let mut scratch = Vec::new();
        let mut delta = (0.0, 0.0);
        for step in a..b + s.levels {
            for lvl in 0..s.levels.min(step + 1) {
                let y = step - lvl;
                if y >= lo(lvl) && y < hi(lvl) {
                    s.add(lvl, &mut delta, |measure| {
                        self.update_row(simd, ch, y, lvl, measure, s.omega, &mut scratch)
                    });
                }
            }
        }
        delta
    }

    /// The seam's inverted triangles: level h covers rows `[seam − h − 1, seam + h + 1)`.
    fn phase_two(&self, simd: Simd, ch: &mut Chunk, s: &Schedule) -> (f64, f64) {
        let seam = ch.y0 + s.levels + 1;
        let mut scratch = Vec::new();
        let mut delta = (0.0, 0.0);
        for lvl in 0..s.levels {
            for y in seam - lvl - 1..seam + lvl + 1 {
                s.add(lvl, &mut delta, |measure| {
                    self.update_row(simd, ch, y, lvl, measure, s.omega, &mut scratch)
                });
            }
        }
        delta
    }

    /// Updates image row `y` at level `lvl`; returns Σ(|Δu| + |Δv|) when `measure`.
    #[allow(clippy::too_many_arguments)]
    fn update_row(
        &self,
        simd: Simd,
        ch: &mut Chunk,
        y: usize,
        lvl: usize,
        measure: bool,
        omega: f32,
        scratch: &mut Vec<f32>,
    ) -> f64 {
        let lay = &self.lay;
        // Top and bottom rows have no neighbour beyond the image: that slot is fed the pixel's
        // own previous value, so at the fixed point the missing edge contributes nothing (free
        // boundary). Any valid row index stands in for it when slicing.
        let (up_own, dn_own) = (y == 0, y + 1 == lay.height);
        let up = if up_own { y + 1 } else { y - 1 };
        let dn = if dn_own { y - 1 } else { y + 1 };
        let (r, r_up, r_dn) = (y - ch.y0, up - ch.y0, dn - ch.y0);
        let mut delta = 0.0;
        if ch.bufs.len() == 1 {
            // Red–black: colour lvl % 2; red = (x + y) even, i.e. half (y + colour) % 2.
            let hp = (y + lvl) % 2;
            let (n_same, n_other) = (lay.half(hp), lay.half(1 - hp));
            let Some((e, o)) = ch.bufs.first_mut() else {
                return 0.0;
            };
            let (same, other): (&mut [f32], &[f32]) = if hp == 0 { (e, o) } else { (o, e) };
            let lr = &other[r * 2 * n_other..(r + 1) * 2 * n_other];
            let (up_row, mid, dn_row) = rows3(same, 2 * n_same, r, r_up, r_dn);
            let keep_old = measure || up_own || dn_own;
            if keep_old {
                scratch.clear();
                scratch.extend_from_slice(mid);
            }
            let up_row = if up_own { &scratch[..] } else { up_row };
            let dn_row = if dn_own { &scratch[..] } else { dn_row };
            self.run_row(simd, hp, y, omega, lr, up_row, dn_row, mid);
            if measure {
                delta += abs_diff_sum(mid, scratch);
            }
        } else {
            // Jacobi: read state lvl % 2, write the other, both halves.
            let (first, second) = ch.bufs.split_at_mut(1);
            let (Some(s0), Some(s1)) = (first.first_mut(), second.first_mut()) else {
                return 0.0;
            };
            let (src, dst) = if lvl.is_multiple_of(2) {
                (s0, s1)
            } else {
                (s1, s0)
            };
            for hp in 0..2 {
                let (n_same, n_other) = (lay.half(hp), lay.half(1 - hp));
                let (src_same, src_other, dst_same): (&[f32], &[f32], &mut [f32]) = if hp == 0 {
                    (&*src.0, &*src.1, &mut *dst.0)
                } else {
                    (&*src.1, &*src.0, &mut *dst.1)
                };
                let row = |rr: usize, n: usize| rr * 2 * n..(rr + 1) * 2 * n;
                let lr = &src_other[row(r, n_other)];
                let old = &src_same[row(r, n_same)];
                let up_row = if up_own {
                    old
                } else {
                    &src_same[row(r_up, n_same)]
                };
                let dn_row = if dn_own {
                    old
                } else {
                    &src_same[row(r_dn, n_same)]
                };
                let mid = &mut dst_same[row(r, n_same)];
                self.run_row(simd, hp, y, omega, lr, up_row, dn_row, mid);
                if measure {
                    delta += abs_diff_sum(mid, old);
                }
            }
        }
        delta
    }

    /// One half-row through the selected kernel.
    #[allow(clippy::too_many_arguments)]
    fn run_row(
        &self,
        simd: Simd,
        hp: usize,
        y: usize,
        omega: f32,
        lr: &[f32],
        up: &[f32],
        dn: &[f32],
        dst: &mut [f32],
    ) {
        let len = CoefRow::new(&self.lay, hp, self.kernel.coefs()).len();
        let coef_all = if hp == 0 { &self.coef_e } else { &self.coef_o };
        let coef = &coef_all[y * len..(y + 1) * len];
        let odd = hp == 1;
        let relax = omega != 1.0;
        let k = Consts {
            q: match self.kernel {
                Kernel::Plain => 0.0,
                Kernel::Groove { q } => q,
            },
            omega,
        };
        match self.kernel {
            Kernel::Plain if relax => simd.row::<false, true>(k, odd, lr, up, dn, coef, dst),
            Kernel::Plain => simd.row::<false, false>(k, odd, lr, up, dn, coef, dst),
            Kernel::Groove { .. } if relax => simd.row::<true, true>(k, odd, lr, up, dn, coef, dst),
            Kernel::Groove { .. } => simd.row::<true, false>(k, odd, lr, up, dn, coef, dst),
        }
    }
}

/// Iterations still needed for the per-pixel change to fall below `tolerance`, if the
/// changes `d0` after `k0` iterations and `d1` after `k1` fit a geometric decay; a block ends
/// there instead of running its full length past the point of convergence.
fn iterations_to_tolerance(
    (k0, d0): (usize, f64),
    (k1, d1): (usize, f64),
    tolerance: f64,
) -> Option<usize> {
    if k1 <= k0 || !(d1 > 0.0 && d0 > d1 && tolerance > 0.0) {
        return None;
    }
    let log_rate = (d1 / d0).ln() / (k1 - k0) as f64;
    let n = ((tolerance / d1).ln() / log_rate).ceil();
    (n.is_finite() && n >= 1.0).then(|| n.min(usize::MAX as f64) as usize)
}

/// Level count and the first measured level of one block.
struct Schedule {
    levels: usize,
    /// Levels of the last iteration, whose changes are measured.
    measure_from: usize,
    /// Levels of the middle iteration, measured too (empty for short blocks).
    mid: std::ops::Range<usize>,
    /// Over-relaxation factor (1 for Jacobi).
    omega: f32,
}

impl Schedule {
    /// Runs `update(measure)` for one row at level `lvl` and adds what it measured to the
    /// middle-iteration (`.0`) or last-iteration (`.1`) sum.
    #[inline(always)]
    fn add(&self, lvl: usize, delta: &mut (f64, f64), update: impl FnOnce(bool) -> f64) {
        if lvl >= self.measure_from {
            delta.1 += update(true);
        } else if self.mid.contains(&lvl) {
            delta.0 += update(true);
        } else {
            update(false);
        }
    }
}

/// Mutable rows `[y0, y0 + rows)` of one (red–black) or two (Jacobi) states: `(e, o)` each.
struct Chunk<'a> {
    y0: usize,
    rows: usize,
    bufs: Vec<(&'a mut [f32], &'a mut [f32])>,
}

/// Cuts every state into the disjoint, sorted row ranges `bounds`.
fn split_chunks<'a>(
    lay: &Layout,
    states: &'a mut [&mut SplitState],
    bounds: &[(usize, usize)],
) -> Vec<Chunk<'a>> {
    let mut chunks: Vec<Chunk<'a>> = bounds
        .iter()
        .map(|&(lo, hi)| Chunk {
            y0: lo,
            rows: hi - lo,
            bufs: Vec::with_capacity(states.len()),
        })
        .collect();
    let (se, so) = (2 * lay.ne, 2 * lay.no);
    for st in states.iter_mut() {
        let st: &'a mut SplitState = st;
        let (mut e, mut o): (&'a mut [f32], &'a mut [f32]) = (&mut st.e, &mut st.o);
        let mut at = 0;
        for ch in &mut chunks {
            let skip = ch.y0 - at;
            let (_, e_rest) = std::mem::take(&mut e).split_at_mut(skip * se);
            let (_, o_rest) = std::mem::take(&mut o).split_at_mut(skip * so);
            let (ce, e_next) = e_rest.split_at_mut(ch.rows * se);
            let (co, o_next) = o_rest.split_at_mut(ch.rows * so);
            ch.bufs.push((ce, co));
            e = e_next;
            o = o_next;
            at = ch.y0 + ch.rows;
        }
    }
    chunks
}

/// Rows `up` and `dn` (read) and `mid` (written) of a buffer with row stride `stride`;
/// `up`, `dn` ∈ {mid − 1, mid + 1}.
fn rows3(
    buf: &mut [f32],
    stride: usize,
    mid: usize,
    up: usize,
    dn: usize,
) -> (&[f32], &mut [f32], &[f32]) {
    let (before, rest) = buf.split_at_mut(mid * stride);
    let (m, after) = rest.split_at_mut(stride);
    let (before, after): (&[f32], &[f32]) = (before, after);
    let pick = |r: usize| -> &[f32] {
        if r < mid {
            &before[r * stride..(r + 1) * stride]
        } else {
            &after[(r - mid - 1) * stride..(r - mid) * stride]
        }
    };
    (pick(up), m, pick(dn))
}

/// Σ|a − b| with lane accumulators so the loop vectorises.
fn abs_diff_sum(a: &[f32], b: &[f32]) -> f64 {
    const LANES: usize = 16;
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut acc = [0.0_f32; LANES];
    let mut ca = a.chunks_exact(LANES);
    let mut cb = b.chunks_exact(LANES);
    for (x, y) in (&mut ca).zip(&mut cb) {
        for k in 0..LANES {
            acc[k] += (x[k] - y[k]).abs();
        }
    }
    let tail: f32 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(x, y)| (x - y).abs())
        .sum();
    f64::from(acc.iter().sum::<f32>()) + f64::from(tail)
}

/// The edge terms of one row (see the module docs) for c = −1 (index 0) and c = +1 (1),
/// computed in f64 and rounded once: `A − λ` and the weight of u across an edge above (o) or
/// below (d), and the base-flow term of N_u for an edge above only, below only, or both. The
/// last is kept whole because its two halves nearly cancel (k_o ≈ k_d).
#[derive(Clone, Copy, Debug, Default)]
struct RowEdges {
    a_o: [f32; 2],
    a_d: [f32; 2],
    wu: [f32; 2],
    wd: [f32; 2],
    e_o: [f32; 2],
    e_d: [f32; 2],
    e_od: [f32; 2],
}

/// [`RowEdges`] of row `y`: an edge between rows at height y_mid carries
/// k = c/(f − c·ŷ) (ŷ = y_mid about the image centre), α = 1 − k/2, β = 1 + k/2.
fn groove_row_edges(
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
struct GrooveRow<'a> {
    lambda: f32,
    edges: RowEdges,
    ix: &'a [f32],
    iy: &'a [f32],
    it: &'a [f32],
    /// Wall side per pixel of this row, the row above and the row below (a missing row stands
    /// in as this one, with `has_*` false).
    sides: &'a [i8],
    above: &'a [i8],
    below: &'a [i8],
    has_above: bool,
    has_below: bool,
}

impl GrooveRow<'_> {
    /// Writes coefficient k of every column to `out[k]` (see the module docs):
    /// `[wu, wd, puu, puv, pvv, pu0, pv0]` such that with `N_u = q·Σ4u + wu·u_up + wd·u_down`,
    /// `N_v = q·Σ4v` (q = λ/4): `u = puu·N_u + puv·N_v + pu0`, `v = puv·N_u + pvv·N_v + pv0`.
    /// The determinant is expanded to `(A + Ix²)(λ + Iy²) − Ix²Iy² = A·(λ + Iy²) + λ·Ix²`, a
    /// sum of positive terms, so f32 keeps it accurate. Branch-free, so it vectorises.
    #[inline(always)]
    fn fill(&self, out: &mut [Vec<f32>; GROOVE_COEFS]) {
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

// ---------------------------------------------------------------------------------------------
// Horn–Schunck: the row kernels
// ---------------------------------------------------------------------------------------------

/// The vector instruction set the row kernels may use (detected once per call). AVX-512
/// measured no faster than AVX2 here: the sweeps are bound by cache bandwidth.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Simd {
    /// Whatever the build target allows.
    Baseline,
    /// 256-bit AVX2.
    #[cfg(target_arch = "x86_64")]
    Avx2,
}

impl Simd {
    fn detect() -> Self {
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2") {
                return Simd::Avx2;
            }
        }
        Simd::Baseline
    }

    /// One row of the groove coefficients: see [`GrooveRow::fill`].
    fn groove_row(self, row: &GrooveRow, out: &mut [Vec<f32>; GROOVE_COEFS]) {
        match self {
            Simd::Baseline => row.fill(out),
            // SAFETY: `Simd::Avx2` is only created by `detect` after the CPU reported AVX2,
            // which is all `groove_row_avx2` requires.
            #[cfg(target_arch = "x86_64")]
            Simd::Avx2 => unsafe { groove_row_avx2(row, out) },
        }
    }

    /// Updates one half-row: see [`row_impl`].
    #[allow(clippy::too_many_arguments)]
    fn row<const GROOVE: bool, const RELAX: bool>(
        self,
        k: Consts,
        odd: bool,
        lr: &[f32],
        up: &[f32],
        dn: &[f32],
        coef: &[f32],
        dst: &mut [f32],
    ) {
        match self {
            Simd::Baseline => row_impl::<GROOVE, RELAX, false>(k, odd, lr, up, dn, coef, dst),
            // SAFETY: `Simd::Avx2` is only created by `detect` after the CPU reported AVX2,
            // which is all `row_avx2` requires.
            #[cfg(target_arch = "x86_64")]
            Simd::Avx2 => unsafe { row_avx2::<GROOVE, RELAX>(k, odd, lr, up, dn, coef, dst) },
        }
    }
}

/// [`GrooveRow::fill`] compiled for AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn groove_row_avx2(row: &GrooveRow, out: &mut [Vec<f32>; GROOVE_COEFS]) {
    row.fill(out);
}

/// [`row_impl`] compiled for AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[allow(clippy::too_many_arguments)]
fn row_avx2<const GROOVE: bool, const RELAX: bool>(
    k: Consts,
    odd: bool,
    lr: &[f32],
    up: &[f32],
    dn: &[f32],
    coef: &[f32],
    dst: &mut [f32],
) {
    row_impl::<GROOVE, RELAX, true>(k, odd, lr, up, dn, coef, dst);
}

/// Neighbours of one pixel: left, right, up, down of u, then of v.
#[derive(Clone, Copy)]
struct Neighbours {
    lu: f32,
    ru: f32,
    uu: f32,
    du: f32,
    lv: f32,
    rv: f32,
    uv: f32,
    dv: f32,
}

/// Plain Horn–Schunck update from `gx, gy, gt` (gradients over sqrt(λ + Ix² + Iy²)).
#[inline(always)]
fn plain_update(nb: Neighbours, gx: f32, gy: f32, gt: f32) -> (f32, f32) {
    let ub = 0.25 * ((nb.lu + nb.ru) + (nb.uu + nb.du));
    let vb = 0.25 * ((nb.lv + nb.rv) + (nb.uv + nb.dv));
    let t = gx * ub + gy * vb + gt;
    (ub - gx * t, vb - gy * t)
}

/// Groove Horn–Schunck update from `[wu, wd, puu, puv, pvv, pu0, pv0]` (see [`GrooveRow::fill`]).
#[inline(always)]
fn groove_update(q: f32, nb: Neighbours, c: [f32; GROOVE_COEFS]) -> (f32, f32) {
    let [wu, wd, puu, puv, pvv, pu0, pv0] = c;
    let nu = q * ((nb.lu + nb.ru) + (nb.uu + nb.du)) + wu * nb.uu + wd * nb.du;
    let nv = q * ((nb.lv + nb.rv) + (nb.uv + nb.dv));
    (puu * nu + puv * nv + pu0, puv * nu + pvv * nv + pv0)
}

/// Updates one half-row `dst = [u(n) | v(n)]` from the other half of the same row
/// `lr = [u(m) | v(m)]`, the same half of the rows above and below (`up`, `dn`, mirrored at
/// the image edges) and the half-row's coefficients `coef` (laid out as [`CoefRow`] says).
///
/// Even half (`odd == false`): column 2i has left/right neighbours `lr[i − 1]`, `lr[i]`; odd
/// half: `lr[i]`, `lr[i + 1]`. A neighbour beyond the image border is mirrored, i.e. replaced
/// by the opposite one. The core, where both neighbours are inside, runs in whole blocks of
/// [`LANES`] columns (with AVX2 intrinsics when `AVX2`, which only [`row_avx2`] sets); the
/// core's last partial block and the border columns go one at a time.
#[inline(always)]
fn row_impl<const GROOVE: bool, const RELAX: bool, const AVX2: bool>(
    k: Consts,
    odd: bool,
    lr: &[f32],
    up: &[f32],
    dn: &[f32],
    coef: &[f32],
    dst: &mut [f32],
) {
    let n = dst.len() / 2;
    let nl = lr.len() / 2;
    let ncoef = if GROOVE { GROOVE_COEFS } else { PLAIN_COEFS };
    let off = usize::from(odd);
    let cr = CoefRow {
        n,
        first: 1 - off,
        c: ncoef,
    };
    if n == 0 || nl == 0 || up.len() < 2 * n || dn.len() < 2 * n || coef.len() < cr.len() {
        return;
    }
    let (lu, lv) = lr.split_at(nl);
    let (uu, uv) = up.split_at(n);
    let (du, dv) = dn.split_at(n);
    let (ou, ov) = dst.split_at_mut(n);
    // Core: columns [i0, i1), where left = lr[i + off − 1] and right = lr[i + off] are both
    // inside; its left neighbours start at lr[i0 + off − 1] = lr[0].
    let i0 = cr.first;
    let i1 = n.min(nl - off).max(i0);
    let m = i1 - i0;
    if m > 0 {
        let cols = i0..i1;
        let rows = Rows {
            lu: &lu[..=m],
            lv: &lv[..=m],
            uu: &uu[cols.clone()],
            du: &du[cols.clone()],
            uv: &uv[cols.clone()],
            dv: &dv[cols.clone()],
            coef: &coef[..m.div_ceil(LANES) * LANES * ncoef],
        };
        let (ou, ov) = (&mut ou[cols.clone()], &mut ov[cols]);
        #[cfg(target_arch = "x86_64")]
        if AVX2 {
            // SAFETY: `AVX2` is only set by `row_avx2`, whose caller checked that the CPU has
            // AVX2, all `blocks_avx2` requires.
            unsafe { blocks_avx2::<GROOVE, RELAX>(k, &rows, ou, ov) };
        } else {
            blocks_portable::<GROOVE, RELAX>(k, &rows, ou, ov);
        }
        #[cfg(not(target_arch = "x86_64"))]
        blocks_portable::<GROOVE, RELAX>(k, &rows, ou, ov);
    }
    // The border columns: mirror the missing neighbour.
    for i in (0..i0.min(n)).chain(i1..n) {
        let left = (i + off).checked_sub(1);
        let right = (i + off < nl).then_some(i + off);
        let (li, ri) = match (left, right) {
            (Some(l), Some(r)) => (l, r),
            (Some(l), None) => (l, l),
            (None, Some(r)) => (r, r),
            (None, None) => continue,
        };
        let nb = Neighbours {
            lu: lu[li],
            ru: lu[ri],
            uu: uu[i],
            du: du[i],
            lv: lv[li],
            rv: lv[ri],
            uv: uv[i],
            dv: dv[i],
        };
        let c = |j: usize| coef[cr.at(i, j)];
        let (a, b) = if GROOVE {
            groove_update(k.q, nb, std::array::from_fn(c))
        } else {
            plain_update(nb, c(0), c(1), c(2))
        };
        (ou[i], ov[i]) = relax::<RELAX>(k.omega, (ou[i], ov[i]), (a, b));
    }
}

/// The inputs of a half-row's core of m columns: left neighbours `lu[i]`, right ones
/// `lu[i + 1]` (so `lu` and `lv` hold m + 1 values), the rows above and below, and the core's
/// ⌈m/8⌉ coefficient blocks (the last one padded).
struct Rows<'a> {
    lu: &'a [f32],
    lv: &'a [f32],
    uu: &'a [f32],
    du: &'a [f32],
    uv: &'a [f32],
    dv: &'a [f32],
    coef: &'a [f32],
}

/// Eight f32 lanes for the portable core: element-wise operations the compiler turns into
/// vector instructions of whatever the target has.
#[derive(Clone, Copy)]
struct L8([f32; LANES]);

impl L8 {
    /// The first 8 values of `s`, zeros past its end.
    #[inline(always)]
    fn load(s: &[f32]) -> Self {
        let mut out = [0.0; LANES];
        let len = s.len().min(LANES);
        out[..len].copy_from_slice(&s[..len]);
        Self(out)
    }

    #[inline(always)]
    fn splat(x: f32) -> Self {
        Self([x; LANES])
    }

    #[inline(always)]
    fn zip(self, o: Self, f: impl Fn(f32, f32) -> f32) -> Self {
        let mut out = self.0;
        for (a, &b) in out.iter_mut().zip(&o.0) {
            *a = f(*a, b);
        }
        Self(out)
    }

    #[inline(always)]
    fn add(self, o: Self) -> Self {
        self.zip(o, |a, b| a + b)
    }

    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        self.zip(o, |a, b| a - b)
    }

    #[inline(always)]
    fn mul(self, o: Self) -> Self {
        self.zip(o, |a, b| a * b)
    }
}

/// The core blocks in portable code: [`blocks_avx2`] operation for operation on [`L8`]; the
/// last block may be partial (its missing lanes compute on zeros and are not stored).
#[inline(always)]
fn blocks_portable<const GROOVE: bool, const RELAX: bool>(
    k: Consts,
    r: &Rows,
    ou: &mut [f32],
    ov: &mut [f32],
) {
    let ncoef = if GROOVE { GROOVE_COEFS } else { PLAIN_COEFS };
    let (quarter, q, omega) = (L8::splat(0.25), L8::splat(k.q), L8::splat(k.omega));
    let cols = ou
        .chunks_mut(LANES)
        .zip(ov.chunks_mut(LANES))
        .zip(r.coef.chunks_exact(LANES * ncoef))
        .enumerate();
    for (bi, ((ou, ov), coef)) in cols {
        let i = bi * LANES;
        let at = |s: &[f32], j: usize| L8::load(s.get(j..).unwrap_or_default());
        let (lu, ru, uu, du) = (at(r.lu, i), at(r.lu, i + 1), at(r.uu, i), at(r.du, i));
        let (lv, rv, uv, dv) = (at(r.lv, i), at(r.lv, i + 1), at(r.uv, i), at(r.dv, i));
        let c = |j: usize| at(coef, j * LANES);
        let su = lu.add(ru).add(uu.add(du));
        let sv = lv.add(rv).add(uv.add(dv));
        let (mut a, mut b) = if GROOVE {
            let nu = q.mul(su).add(c(0).mul(uu)).add(c(1).mul(du));
            let nv = q.mul(sv);
            let (puu, puv, pvv) = (c(2), c(3), c(4));
            (
                puu.mul(nu).add(puv.mul(nv)).add(c(5)),
                puv.mul(nu).add(pvv.mul(nv)).add(c(6)),
            )
        } else {
            let (ub, vb) = (quarter.mul(su), quarter.mul(sv));
            let (gx, gy) = (c(0), c(1));
            let t = gx.mul(ub).add(gy.mul(vb)).add(c(2));
            (ub.sub(gx.mul(t)), vb.sub(gy.mul(t)))
        };
        if RELAX {
            let (old_u, old_v) = (L8::load(ou), L8::load(ov));
            a = old_u.add(omega.mul(a.sub(old_u)));
            b = old_v.add(omega.mul(b.sub(old_v)));
        }
        let (nu, nv) = (ou.len(), ov.len());
        ou.copy_from_slice(&a.0[..nu]);
        ov.copy_from_slice(&b.0[..nv]);
    }
}

/// The core blocks with AVX2 intrinsics: [`plain_update`] / [`groove_update`] and [`relax`]
/// on 8 columns at once, operation for operation (no fused multiply–add), so the result has
/// the same bits as [`blocks_portable`]. A last partial block is loaded and stored through a
/// lane mask.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn blocks_avx2<const GROOVE: bool, const RELAX: bool>(
    k: Consts,
    r: &Rows,
    ou: &mut [f32],
    ov: &mut [f32],
) {
    use std::arch::x86_64::{
        _mm256_cmpgt_epi32, _mm256_loadu_ps, _mm256_maskload_ps, _mm256_maskstore_ps,
        _mm256_set1_epi32, _mm256_set1_ps, _mm256_setr_epi32, _mm256_storeu_ps,
    };
    let ncoef = if GROOVE { GROOVE_COEFS } else { PLAIN_COEFS };
    let m = ou.len().min(ov.len());
    // Every slice read below holds at least m (+ 1 for the neighbour rows) values, the
    // coefficients ⌈m/8⌉ whole blocks, so the pointer arithmetic stays inside them.
    if r.lu.len() <= m
        || r.lv.len() <= m
        || [r.uu, r.du, r.uv, r.dv].iter().any(|s| s.len() < m)
        || r.coef.len() < m.div_ceil(LANES) * LANES * ncoef
    {
        return;
    }
    let k = AvxConsts {
        quarter: _mm256_set1_ps(0.25),
        q: _mm256_set1_ps(k.q),
        omega: _mm256_set1_ps(k.omega),
    };
    // One advancing pointer per row, the v half at a fixed distance from the u half: fewer
    // live pointers than one per stream, so the loop keeps them all in registers.
    let dist = |v: *const f32, u: *const f32| (v as isize - u as isize) / 4;
    let mut p = BlockPtrs {
        l: r.lu.as_ptr(),
        up: r.uu.as_ptr(),
        dn: r.du.as_ptr(),
        c: r.coef.as_ptr(),
        o: ou.as_mut_ptr(),
        dl: dist(r.lv.as_ptr(), r.lu.as_ptr()),
        dup: dist(r.uv.as_ptr(), r.uu.as_ptr()),
        ddn: dist(r.dv.as_ptr(), r.du.as_ptr()),
        dout: dist(ov.as_ptr(), ou.as_ptr()),
    };
    for _ in 0..m / LANES {
        // SAFETY: the m/8 whole blocks lie inside the slices checked above (lu, lv up to
        // m + 1; the rows; the coefficient blocks), read and written; each v pointer is its
        // u pointer moved by the distance between the two slices' starts, and the pointers
        // end at most one past the rows.
        unsafe {
            block_avx2::<GROOVE, RELAX>(
                &k,
                &p,
                |at| _mm256_loadu_ps(at),
                |at, x| _mm256_storeu_ps(at, x),
            );
            p.advance(ncoef);
        }
    }
    let tail = m % LANES;
    if tail > 0 {
        // Lanes below `tail` (at most 7, so the cast is exact).
        let mask = _mm256_cmpgt_epi32(
            _mm256_set1_epi32(tail as i32),
            _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7),
        );
        // SAFETY: as above for the lanes below `tail`, the only ones the masked loads and
        // stores touch (the right neighbours reach lu[m], inside); the coefficient block is
        // whole (padded).
        unsafe {
            block_avx2::<GROOVE, RELAX>(
                &k,
                &p,
                |at| _mm256_maskload_ps(at, mask),
                |at, x| _mm256_maskstore_ps(at, mask, x),
            );
        }
    }
}

/// Broadcast constants of [`blocks_avx2`].
#[cfg(target_arch = "x86_64")]
struct AvxConsts {
    quarter: std::arch::x86_64::__m256,
    q: std::arch::x86_64::__m256,
    omega: std::arch::x86_64::__m256,
}

/// Where [`blocks_avx2`] is: one pointer per row (left/right neighbours, up, down, the
/// coefficient block, the output), and the distance in floats from each row's u half to its
/// v half.
#[cfg(target_arch = "x86_64")]
struct BlockPtrs {
    l: *const f32,
    up: *const f32,
    dn: *const f32,
    c: *const f32,
    o: *mut f32,
    dl: isize,
    dup: isize,
    ddn: isize,
    dout: isize,
}

#[cfg(target_arch = "x86_64")]
impl BlockPtrs {
    /// Moves on by one block of columns, `ncoef` blocks of coefficients.
    ///
    /// # Safety
    /// The next block must lie inside the rows, or start one past their end.
    #[inline(always)]
    unsafe fn advance(&mut self, ncoef: usize) {
        // SAFETY: the caller's.
        unsafe {
            self.l = self.l.add(LANES);
            self.up = self.up.add(LANES);
            self.dn = self.dn.add(LANES);
            self.c = self.c.add(LANES * ncoef);
            self.o = self.o.add(LANES);
        }
    }
}

/// One block of 8 columns at `p`, the rows read through `load` and written through `store`
/// (plain or masked); the coefficient block is read whole.
///
/// # Safety
/// `load` and `store` must be sound at every address the block reaches from `p`: the rows'
/// u and v halves at lanes 0..8 (the left/right row also at 1..9) and the output's u and v
/// halves; the coefficient block must lie inside its row.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn block_avx2<const GROOVE: bool, const RELAX: bool>(
    k: &AvxConsts,
    p: &BlockPtrs,
    load: impl Fn(*const f32) -> std::arch::x86_64::__m256,
    store: impl Fn(*mut f32, std::arch::x86_64::__m256),
) {
    use std::arch::x86_64::{_mm256_add_ps, _mm256_loadu_ps, _mm256_mul_ps, _mm256_sub_ps};
    // SAFETY: the caller's.
    unsafe {
        let (lu, ru, uu, du) = (load(p.l), load(p.l.add(1)), load(p.up), load(p.dn));
        let (lv, rv, uv, dv) = (
            load(p.l.offset(p.dl)),
            load(p.l.offset(p.dl + 1)),
            load(p.up.offset(p.dup)),
            load(p.dn.offset(p.ddn)),
        );
        let c = |j: usize| _mm256_loadu_ps(p.c.add(j * LANES));
        let su = _mm256_add_ps(_mm256_add_ps(lu, ru), _mm256_add_ps(uu, du));
        let sv = _mm256_add_ps(_mm256_add_ps(lv, rv), _mm256_add_ps(uv, dv));
        let (mut a, mut b) = if GROOVE {
            let nu = _mm256_add_ps(
                _mm256_add_ps(_mm256_mul_ps(k.q, su), _mm256_mul_ps(c(0), uu)),
                _mm256_mul_ps(c(1), du),
            );
            let nv = _mm256_mul_ps(k.q, sv);
            let (puu, puv, pvv) = (c(2), c(3), c(4));
            (
                _mm256_add_ps(
                    _mm256_add_ps(_mm256_mul_ps(puu, nu), _mm256_mul_ps(puv, nv)),
                    c(5),
                ),
                _mm256_add_ps(
                    _mm256_add_ps(_mm256_mul_ps(puv, nu), _mm256_mul_ps(pvv, nv)),
                    c(6),
                ),
            )
        } else {
            let (ub, vb) = (_mm256_mul_ps(k.quarter, su), _mm256_mul_ps(k.quarter, sv));
            let (gx, gy) = (c(0), c(1));
            let t = _mm256_add_ps(
                _mm256_add_ps(_mm256_mul_ps(gx, ub), _mm256_mul_ps(gy, vb)),
                c(2),
            );
            (
                _mm256_sub_ps(ub, _mm256_mul_ps(gx, t)),
                _mm256_sub_ps(vb, _mm256_mul_ps(gy, t)),
            )
        };
        let pov = p.o.offset(p.dout);
        if RELAX {
            let (old_u, old_v) = (load(p.o), load(pov));
            a = _mm256_add_ps(old_u, _mm256_mul_ps(k.omega, _mm256_sub_ps(a, old_u)));
            b = _mm256_add_ps(old_v, _mm256_mul_ps(k.omega, _mm256_sub_ps(b, old_v)));
        }
        store(p.o, a);
        store(pov, b);
    }
}

/// Successive over-relaxation: `old + ω·(new − old)` when `RELAX`, else `new`.
#[inline(always)]
fn relax<const RELAX: bool>(omega: f32, old: (f32, f32), new: (f32, f32)) -> (f32, f32) {
    if RELAX {
        (
            old.0 + omega * (new.0 - old.0),
            old.1 + omega * (new.1 - old.1),
        )
    } else {
        new
    }
}

/// Scalars every row update of one solve shares.
#[derive(Clone, Copy, Debug)]
struct Consts {
    /// λ/4 (groove kernel).
    q: f32,
    /// Over-relaxation factor ω (used when the kernel relaxes).
    omega: f32,
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests fail loudly on purpose
mod tests {
    use super::*;
    use crate::pipeline::derivatives::{DerivativeMode, DerivativeParams, compute_derivatives};
    use proptest::prelude::*;

    /// splitmix64, for reproducible textures.
    struct Rng(u64);

    impl Rng {
        fn next_f64(&mut self) -> f64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^= z >> 31;
            (z >> 11) as f64 / (1_u64 << 53) as f64
        }
    }

    /// A smooth random texture: a sum of plane waves with wavelengths in [8, 32] px.
    struct Texture(Vec<[f64; 4]>);

    impl Texture {
        fn new(seed: u64) -> Self {
            let mut rng = Rng(seed);
            let n = 48;
            let waves = (0..n)
                .map(|_| {
                    let wavelength = 8.0 + 24.0 * rng.next_f64();
                    let dir = std::f64::consts::TAU * rng.next_f64();
                    let k = std::f64::consts::TAU / wavelength;
                    let phase = std::f64::consts::TAU * rng.next_f64();
                    [k * dir.cos(), k * dir.sin(), phase, 0.5 / (n as f64).sqrt()]
                })
                .collect();
            Self(waves)
        }

        fn at(&self, x: f64, y: f64) -> f32 {
            let s: f64 = self
                .0
                .iter()
                .map(|[kx, ky, ph, a]| a * (kx * x + ky * y + ph).sin())
                .sum();
            (0.5 + s) as f32
        }
    }

    /// Frames of the texture translating by (sx, sy) px per frame.
    fn translating(w: usize, h: usize, frames: usize, sx: f64, sy: f64, seed: u64) -> Vec<Image> {
        let tex = Texture::new(seed);
        (0..frames)
            .map(|k| {
                let t = k as f64;
                Image::from_fn(w, h, |x, y| tex.at(x as f64 - sx * t, y as f64 - sy * t))
            })
            .collect()
    }

    /// Frames of a plane tilted across y (∂Z/∂Y = `slope`) under a camera moving along x by
    /// `step` px per frame at the depth of the centre row: u(y) = −step·(1 − slope·yc/f).
    fn tilted_plane(
        w: usize,
        h: usize,
        frames: usize,
        step: f64,
        slope: f64,
        f: f64,
    ) -> Vec<Image> {
        let tex = Texture::new(7);
        let (xc0, yc0) = ((w as f64 - 1.0) * 0.5, (h as f64 - 1.0) * 0.5);
        (0..frames)
            .map(|k| {
                Image::from_fn(w, h, |x, y| {
                    let (xc, yc) = (x as f64 - xc0, y as f64 - yc0);
                    let z = f / (1.0 - slope * yc / f);
                    let (wx, wy) = (xc * z / f, yc * z / f);
                    tex.at(wx + step * k as f64, wy)
                })
            })
            .collect()
    }

    fn true_u_tilted(y: usize, h: usize, step: f64, slope: f64, f: f64) -> f64 {
        let yc = y as f64 - (h as f64 - 1.0) * 0.5;
        -step * (1.0 - slope * yc / f)
    }

    /// Mean |u − eu(x, y)| and |v − ev| over the interior (margin px from each border).
    fn mean_abs_err(
        flow: &FlowField,
        margin: usize,
        eu: impl Fn(usize, usize) -> f64,
        ev: f64,
    ) -> (f64, f64) {
        let (w, h) = (flow.u.width, flow.u.height);
        let (mut su, mut sv, mut n) = (0.0, 0.0, 0.0);
        for y in margin..h - margin {
            for x in margin..w - margin {
                su += (f64::from(flow.u.data[y * w + x]) - eu(x, y)).abs();
                sv += (f64::from(flow.v.data[y * w + x]) - ev).abs();
                n += 1.0;
            }
        }
        (su / n, sv / n)
    }

    fn params(method: FlowMethod) -> FlowParams {
        FlowParams {
            method,
            ..FlowParams::default()
        }
    }

    fn no_prewarp() -> DerivativeParams {
        DerivativeParams {
            mode: DerivativeMode::Simoncelli,
            prewarp: false,
        }
    }

    /// Middle derivative set of a 12-frame group.
    fn middle(frames: &[Image], land: f64, dp: &DerivativeParams) -> Derivatives {
        let mut sets = compute_derivatives(frames, land, dp).unwrap();
        let k = sets.len() / 2;
        sets.swap_remove(k)
    }

    const MARGIN_PX: usize = 8;

    #[test]
    fn translation_recovered_by_every_method() {
        let (w, h) = (96, 80);
        for &(sx, sy) in &[
            (0.3, 0.0),
            (0.7, 0.0),
            (1.0, 0.0),
            (0.0, 0.3),
            (0.0, 0.7),
            (0.0, 1.0),
            (0.5, -0.5),
        ] {
            let frames = translating(w, h, 12, sx, sy, 1);
            let d = middle(&frames, 0.0, &no_prewarp());
            // Jacobi converges about half as fast as Gauss–Seidel: give it more sweeps.
            for (method, solver, iterations) in [
                (FlowMethod::HornSchunck, Solver::GaussSeidel, 100),
                (FlowMethod::HornSchunck, Solver::Jacobi, 300),
                (FlowMethod::LucasKanade, Solver::GaussSeidel, 1),
            ] {
                let p = FlowParams {
                    solver,
                    max_iterations: iterations,
                    ..params(method)
                };
                let flow = compute_flow(&d, 1e4, None, &p).unwrap();
                let (eu, ev) = mean_abs_err(&flow, MARGIN_PX, |_, _| sx, sy);
                eprintln!(
                    "shift ({sx}, {sy}) {method:?} {solver:?}: mean |du| {eu:.5} |dv| {ev:.5} in {} iterations",
                    flow.iterations
                );
                assert!(
                    eu <= 0.01 && ev <= 0.01,
                    "{method:?} {solver:?} ({sx},{sy}): {eu} {ev}"
                );
            }
        }
    }

    #[test]
    fn prewarp_recovers_large_land_flow() {
        let (w, h) = (96, 80);
        for land in [-2.0, -2.3, -2.5, -3.0] {
            let frames = translating(w, h, 12, land, 0.0, 3);
            let d = middle(&frames, land, &DerivativeParams::default());
            assert!((f64::from(d.base_flow_px) - land).abs() < 1e-6);
            for method in [FlowMethod::HornSchunck, FlowMethod::LucasKanade] {
                let flow = compute_flow(&d, 1e4, None, &params(method)).unwrap();
                let (eu, ev) = mean_abs_err(&flow, MARGIN_PX, |_, _| land, 0.0);
                eprintln!("prewarp land {land} {method:?}: mean |du| {eu:.5} |dv| {ev:.5}");
                assert!(eu <= 0.01 && ev <= 0.01, "{land} {method:?}: {eu} {ev}");
            }
        }
    }

    /// Least-squares line through the interior row means of u: (value at the centre row, slope).
    fn row_profile(flow: &FlowField, margin: usize) -> (f64, f64) {
        let (w, h) = (flow.u.width, flow.u.height);
        let yc = (h as f64 - 1.0) * 0.5;
        let (mut sy, mut syy, mut su, mut syu, mut n) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for y in margin..h - margin {
            let mean: f64 = flow.u.row(y)[margin..w - margin]
                .iter()
                .map(|&v| f64::from(v))
                .sum::<f64>()
                / (w - 2 * margin) as f64;
            let t = y as f64 - yc;
            sy += t;
            syy += t * t;
            su += mean;
            syu += t * mean;
            n += 1.0;
        }
        let slope = (n * syu - sy * su) / (n * syy - sy * sy);
        ((su - slope * sy) / n, slope)
    }

    const TILT_FOCAL_PX: f64 = 400.0;

    #[test]
    fn tilted_plane_gives_linear_u_profile() {
        let (w, h) = (96, 96);
        for (slope, prewarp) in [(1.0, false), (-1.0, false), (1.0, true)] {
            let frames = tilted_plane(w, h, 12, 1.0, slope, TILT_FOCAL_PX);
            let dp = DerivativeParams {
                prewarp,
                ..DerivativeParams::default()
            };
            let d = middle(&frames, -1.0, &dp);
            let flow =
                compute_flow(&d, TILT_FOCAL_PX, None, &params(FlowMethod::HornSchunck)).unwrap();
            let (centre, fitted) = row_profile(&flow, MARGIN_PX);
            let expected = slope / TILT_FOCAL_PX;
            let (eu, ev) = mean_abs_err(
                &flow,
                MARGIN_PX,
                |_, y| true_u_tilted(y, h, 1.0, slope, TILT_FOCAL_PX),
                0.0,
            );
            eprintln!(
                "tilt {slope} prewarp {prewarp}: u(centre) {centre:.5} slope {fitted:.6} (true {expected:.6}) mean |du| {eu:.5} |dv| {ev:.5}"
            );
            assert!((centre + 1.0).abs() < 0.005, "{centre}");
            assert!(
                (fitted - expected).abs() < 0.05 * expected.abs(),
                "{fitted} vs {expected}"
            );
            assert!(eu < 0.01 && ev < 0.01, "{eu} {ev}");
        }
    }

    #[test]
    fn groove_constraint_is_not_worse_on_a_wall() {
        let (w, h) = (96, 96);
        for slope in [1.0, -1.0] {
            let frames = tilted_plane(w, h, 12, 1.0, slope, TILT_FOCAL_PX);
            let d = middle(&frames, -1.0, &DerivativeParams::default());
            let truth = |_: usize, y: usize| true_u_tilted(y, h, 1.0, slope, TILT_FOCAL_PX);
            let plain =
                compute_flow(&d, TILT_FOCAL_PX, None, &params(FlowMethod::HornSchunck)).unwrap();
            let walls = WallSideMap {
                width: w,
                height: h,
                sign: vec![slope as i8; w * h],
            };
            let mut errs = vec![mean_abs_err(&plain, MARGIN_PX, truth, 0.0).0];
            // A stiff constraint (γ = 10λ) couples rows strongly and needs more sweeps.
            for (weight, iterations, tolerance_px) in [(1.0, 100, 1e-5), (10.0, 1000, 0.0)] {
                let p = FlowParams {
                    groove_weight: weight,
                    max_iterations: iterations,
                    tolerance_px,
                    ..params(FlowMethod::GrooveHornSchunck)
                };
                let given = compute_flow(&d, TILT_FOCAL_PX, Some(&walls), &p).unwrap();
                let estimated = compute_flow(&d, TILT_FOCAL_PX, None, &p).unwrap();
                errs.push(mean_abs_err(&given, MARGIN_PX, truth, 0.0).0);
                errs.push(mean_abs_err(&estimated, MARGIN_PX, truth, 0.0).0);
            }
            eprintln!(
                "tilt {slope}: |du| plain, groove(γ=λ, given/estimated walls), groove(γ=10λ, ...): {errs:?}"
            );
            for &e in &errs[1..] {
                assert!(e <= errs[0] * 1.02 + 1e-5, "{errs:?}");
            }
        }
    }

    #[test]
    fn box_mean_matches_the_in_image_window_mean() {
        for (w, h) in [(1, 1), (3, 2), (9, 5), (40, 11)] {
            let im = Image::from_fn(w, h, |x, y| ((x * 7 + y * 13) % 11) as f32 - 4.0);
            let (rx, ry) = (4, 2);
            let got = box_mean(&im, rx, ry);
            for y in 0..h {
                for x in 0..w {
                    let (x0, x1) = (x.saturating_sub(rx), (x + rx).min(w - 1));
                    let (y0, y1) = (y.saturating_sub(ry), (y + ry).min(h - 1));
                    let vals: Vec<f64> = (y0..=y1)
                        .flat_map(|yy| (x0..=x1).map(move |xx| (xx, yy)))
                        .map(|(xx, yy)| f64::from(im.data[yy * w + xx]))
                        .collect();
                    let want = vals.iter().sum::<f64>() / vals.len() as f64;
                    assert!(
                        (got[y * w + x] - want).abs() < 1e-9,
                        "{w}x{h} at ({x}, {y})"
                    );
                }
            }
        }
    }

    #[test]
    fn wall_sides_estimated_from_parallax() {
        let (w, h) = (96, 96);
        for (slope, want) in [(1.0, 1_i8), (-1.0, -1), (0.0, 0)] {
            let frames = tilted_plane(w, h, 12, 1.0, slope, TILT_FOCAL_PX);
            let d = middle(&frames, -1.0, &DerivativeParams::default());
            let flow =
                compute_flow(&d, TILT_FOCAL_PX, None, &params(FlowMethod::HornSchunck)).unwrap();
            let map = estimate_wall_sides(&flow, TILT_FOCAL_PX).unwrap();
            assert_eq!((map.width, map.height, map.sign.len()), (w, h, w * h));
            let m = 2 * MARGIN_PX;
            let (mut hits, mut n) = (0, 0);
            for y in m..h - m {
                for x in m..w - m {
                    hits += usize::from(map.sign[y * w + x] == want);
                    n += 1;
                }
            }
            let frac = hits as f64 / n as f64;
            eprintln!("tilt {slope}: {frac:.3} of interior pixels got c = {want}");
            assert!(frac > 0.9, "{frac}");
        }
        assert!(estimate_wall_sides(&compute_flow_dummy(), f64::NAN).is_err());
    }

    #[test]
    fn wall_presolve_converges_whatever_the_groove_tolerance_and_cap() {
        // A loose τ or a low cap must not cut short the plain pass the wall sides are
        // estimated from: the groove flow still starts from a plain pass run to the wall
        // tolerance.
        let (w, h) = (96, 96);
        let frames = tilted_plane(w, h, 12, 1.0, 1.0, TILT_FOCAL_PX);
        let d = middle(&frames, -1.0, &DerivativeParams::default());
        let plain = compute_flow(
            &d,
            TILT_FOCAL_PX,
            None,
            &FlowParams {
                tolerance_px: WALL_PRESOLVE_TOLERANCE_PX,
                ..params(FlowMethod::HornSchunck)
            },
        )
        .unwrap();
        assert!(
            plain.iterations > 2 * MAX_BLOCK_ITERATIONS as u32,
            "{}",
            plain.iterations
        );
        assert!(
            plain.iterations < WALL_PRESOLVE_MAX_ITERATIONS,
            "{}",
            plain.iterations
        );
        for (tolerance_px, max_iterations) in [(1e-3, 100), (1e-5, 20)] {
            let p = FlowParams {
                tolerance_px,
                max_iterations,
                ..params(FlowMethod::GrooveHornSchunck)
            };
            let groove = compute_flow(&d, TILT_FOCAL_PX, None, &p).unwrap();
            eprintln!(
                "plain pass {} iterations; groove at τ = {tolerance_px}, cap {max_iterations}: {} in all",
                plain.iterations, groove.iterations
            );
            assert!(
                groove.iterations > plain.iterations,
                "{}",
                groove.iterations
            );
        }
    }

    fn compute_flow_dummy() -> FlowField {
        FlowField {
            u: Image::zeros(4, 4),
            v: Image::zeros(4, 4),
            confidence: Image::zeros(4, 4),
            iterations: 0,
            converged: false,
            frame_index: 0,
        }
    }

    /// The groove energy of the module docs, evaluated directly (f64).
    #[allow(clippy::too_many_arguments)]
    fn energy(
        d: &Derivatives,
        sign: &[i8],
        u: &[f64],
        v: &[f64],
        lambda: f64,
        gamma: f64,
        f: f64,
    ) -> f64 {
        let (w, h) = (d.ix.width, d.ix.height);
        let b = f64::from(d.base_flow_px);
        let mut e = 0.0;
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let r = f64::from(d.ix.data[i]) * u[i]
                    + f64::from(d.iy.data[i]) * v[i]
                    + f64::from(d.it.data[i]);
                e += r * r;
                if x + 1 < w {
                    e += 0.25 * lambda * ((u[i + 1] - u[i]).powi(2) + (v[i + 1] - v[i]).powi(2));
                }
                if y + 1 < h {
                    let j = i + w;
                    e += 0.25 * lambda * (v[j] - v[i]).powi(2);
                    if sign[i] != 0 && sign[i] == sign[j] {
                        let c = f64::from(sign[i]);
                        let ym = y as f64 + 0.5 - (h as f64 - 1.0) * 0.5;
                        let k = c / (f - c * ym);
                        let re = u[j] - u[i] + k * (0.5 * (u[i] + u[j]) + b);
                        e += (0.25 * lambda + gamma) * re * re;
                    } else {
                        e += 0.25 * lambda * (u[j] - u[i]).powi(2);
                    }
                }
            }
        }
        e
    }

    #[test]
    fn groove_solution_satisfies_euler_lagrange() {
        let (w, h) = (14, 12);
        let frames = tilted_plane(w, h, 7, 1.0, 1.0, 40.0);
        let d = middle(&frames, -1.0, &DerivativeParams::default());
        // Stripes of wall sides, including land (0) rows and a side change.
        let sign: Vec<i8> = (0..w * h)
            .map(|i| match i / w {
                0..=2 => 0,
                3..=6 => 1,
                7 => 0,
                _ => -1,
            })
            .collect();
        let walls = WallSideMap {
            width: w,
            height: h,
            sign: sign.clone(),
        };
        let (focal, lambda, weight) = (20.0, 0.05, 3.0);
        for solver in [Solver::GaussSeidel, Solver::Jacobi] {
            let p = FlowParams {
                solver,
                lambda,
                groove_weight: weight,
                max_iterations: 20_000,
                tolerance_px: 0.0,
                ..params(FlowMethod::GrooveHornSchunck)
            };
            let flow = compute_flow(&d, focal, Some(&walls), &p).unwrap();
            let base = f64::from(d.base_flow_px);
            let mut u: Vec<f64> = flow.u.data.iter().map(|&x| f64::from(x) - base).collect();
            let mut v: Vec<f64> = flow.v.data.iter().map(|&x| f64::from(x)).collect();
            let gamma = f64::from(weight) * f64::from(lambda);
            let en =
                |u: &[f64], v: &[f64]| energy(&d, &sign, u, v, f64::from(lambda), gamma, focal);
            let step = 1e-4;
            let mut worst: f64 = 0.0;
            let mut scale: f64 = 0.0;
            // All rows (top and bottom are free boundaries); the mirrored outer columns
            // minimise the energy with half weights there, so they are left out.
            for y in 0..h {
                for x in 1..w - 1 {
                    let i = y * w + x;
                    for comp in 0..2 {
                        let field = if comp == 0 { &mut u } else { &mut v };
                        let keep = field[i];
                        field[i] = keep + step;
                        let ep = en(&u, &v);
                        let field = if comp == 0 { &mut u } else { &mut v };
                        field[i] = keep - step;
                        let em = en(&u, &v);
                        let field = if comp == 0 { &mut u } else { &mut v };
                        field[i] = keep;
                        worst = worst.max(((ep - em) / (2.0 * step)).abs());
                        // Gradient size at the zero flow, for scale.
                        let i_t = f64::from(d.it.data[i]);
                        let g = if comp == 0 {
                            d.ix.data[i]
                        } else {
                            d.iy.data[i]
                        };
                        scale = scale.max((2.0 * f64::from(g) * i_t).abs());
                    }
                }
            }
            eprintln!(
                "{solver:?}: worst interior |∂E/∂(u,v)| {worst:.3e} vs {scale:.3e} at zero flow"
            );
            assert!(worst < 1e-4 * scale, "{worst} vs {scale}");
        }
    }

    #[test]
    fn blocking_bands_and_simd_do_not_change_the_result() {
        let (w, h) = (37, 230);
        let frames = tilted_plane(w, h, 7, 0.6, 1.0, 100.0);
        let d = middle(&frames, 0.0, &no_prewarp());
        let lay = Layout::new(w, h);
        let walls = WallSideMap {
            width: w,
            height: h,
            sign: (0..w * h).map(|i| [0, 1, -1][(i / w / 40) % 3]).collect(),
        };
        let p = FlowParams::default();
        let built = Problem::groove(&lay, &d, &walls, 100.0, &p, Simd::Baseline);
        let fast = Problem::groove(&lay, &d, &walls, 100.0, &p, Simd::detect());
        assert!(built.coef_e == fast.coef_e && built.coef_o == fast.coef_o);
        assert!(
            built
                .coef_e
                .iter()
                .chain(&built.coef_o)
                .all(|c| c.is_finite())
        );
        for solver in [Solver::GaussSeidel, Solver::Jacobi] {
            for omega in [1.0, 1.7] {
                let p = FlowParams {
                    solver,
                    sor_omega: omega,
                    max_iterations: 37,
                    tolerance_px: 0.0,
                    ..FlowParams::default()
                };
                for problem in [
                    Problem::plain(&lay, &d, p.lambda),
                    Problem::groove(&lay, &d, &walls, 100.0, &p, Simd::detect()),
                ] {
                    let mut reference = SplitState::zeros(&lay);
                    let (it, _) =
                        problem.solve_with(&mut reference, &p, Simd::Baseline, 1, Some(1));
                    assert_eq!(it, 37);
                    for (bands, block) in [(1, None), (2, Some(5)), (3, Some(4)), (4, Some(16))] {
                        let mut st = SplitState::zeros(&lay);
                        problem.solve_with(&mut st, &p, Simd::detect(), bands, block);
                        assert!(
                            st.e == reference.e && st.o == reference.o,
                            "{solver:?} ω {omega} bands {bands} block {block:?}"
                        );
                    }
                }
            }
        }
    }

    /// Straightforward red–black Gauss–Seidel on the full grid, for comparison.
    fn naive_plain_gs(d: &Derivatives, lambda: f32, iterations: usize) -> (Vec<f32>, Vec<f32>) {
        let (w, h) = (d.ix.width, d.ix.height);
        let mut u = vec![0.0_f32; w * h];
        let mut v = vec![0.0_f32; w * h];
        // Mirrored left/right columns; beyond the top and bottom rows the pixel itself.
        let at = |f: &[f32], x: isize, y: isize, own: usize| {
            let x = if x < 0 {
                1
            } else if x >= w as isize {
                w as isize - 2
            } else {
                x
            };
            if y < 0 || y >= h as isize {
                return f[own];
            }
            f[y as usize * w + x as usize]
        };
        for _ in 0..iterations {
            for colour in 0..2 {
                for y in 0..h {
                    for x in 0..w {
                        if (x + y) % 2 != colour {
                            continue;
                        }
                        let (xi, yi) = (x as isize, y as isize);
                        let i = y * w + x;
                        let ub = 0.25
                            * ((at(&u, xi - 1, yi, i) + at(&u, xi + 1, yi, i))
                                + (at(&u, xi, yi - 1, i) + at(&u, xi, yi + 1, i)));
                        let vb = 0.25
                            * ((at(&v, xi - 1, yi, i) + at(&v, xi + 1, yi, i))
                                + (at(&v, xi, yi - 1, i) + at(&v, xi, yi + 1, i)));
                        let (gx, gy, gt) = (d.ix.data[i], d.iy.data[i], d.it.data[i]);
                        let t = (gx * ub + gy * vb + gt) / (lambda + gx * gx + gy * gy);
                        u[i] = ub - gx * t;
                        v[i] = vb - gy * t;
                    }
                }
            }
        }
        (u, v)
    }

    #[test]
    fn fast_solver_matches_naive_gauss_seidel() {
        for (w, h) in [(31, 29), (40, 64), (2, 2), (3, 5)] {
            let frames = translating(w, h, 7, 0.4, -0.2, 9);
            let d = middle(&frames, 0.0, &no_prewarp());
            let p = FlowParams {
                sor_omega: 1.0,
                max_iterations: 23,
                tolerance_px: 0.0,
                ..params(FlowMethod::HornSchunck)
            };
            let flow = compute_flow(&d, 1e4, None, &p).unwrap();
            let (u, v) = naive_plain_gs(&d, p.lambda, 23);
            let diff = flow
                .u
                .data
                .iter()
                .zip(&u)
                .chain(flow.v.data.iter().zip(&v))
                .map(|(a, b)| (a - b).abs())
                .fold(0.0_f32, f32::max);
            assert!(diff < 1e-5, "{w}x{h}: {diff}");
        }
    }

    #[test]
    fn coefficient_slots_cover_each_half_row_once() {
        for w in [2, 3, 16, 17, 31, 40, 1280] {
            let lay = Layout::new(w, 1);
            for hp in 0..2 {
                let cr = CoefRow::new(&lay, hp, GROOVE_COEFS);
                let mut seen = vec![false; cr.len()];
                for i in 0..cr.n {
                    for k in 0..cr.c {
                        let at = cr.at(i, k);
                        assert!(!seen[at], "w {w} half {hp}: column {i} coefficient {k}");
                        seen[at] = true;
                    }
                }
                // The core starts at slot 0 and runs on in slot order.
                for i in cr.first..cr.n {
                    assert_eq!(cr.at(i, 1), cr.at_slot(i - cr.first, 1));
                }
                // What is left is the padding of the last block.
                let unseen = seen.iter().filter(|s| !**s).count();
                assert_eq!(unseen, (cr.n.div_ceil(LANES) * LANES - cr.n) * cr.c);
            }
        }
    }

    #[test]
    fn geometric_decay_predicts_the_iterations_left() {
        // 1e-2 after 16 iterations, 1e-3 after 32: a tenth per 16 iterations, so 1e-5 needs
        // 32 more.
        assert_eq!(
            iterations_to_tolerance((16, 1e-2), (32, 1e-3), 1e-5),
            Some(32)
        );
        assert_eq!(
            iterations_to_tolerance((16, 1e-2), (32, 1e-3), 0.9e-3),
            Some(1)
        );
        // Growing, flat or missing changes predict nothing.
        assert_eq!(iterations_to_tolerance((16, 1e-3), (32, 1e-2), 1e-5), None);
        assert_eq!(iterations_to_tolerance((16, 1e-3), (32, 1e-3), 1e-5), None);
        assert_eq!(iterations_to_tolerance((16, 1e-3), (32, 0.0), 1e-5), None);
        assert_eq!(iterations_to_tolerance((16, 1e-2), (32, 1e-3), 0.0), None);
    }

    #[test]
    fn adaptive_blocks_stop_close_to_where_every_iteration_is_checked() {
        let (w, h) = (64, 48);
        let frames = translating(w, h, 7, 0.4, -0.2, 5);
        let d = middle(&frames, 0.0, &no_prewarp());
        let lay = Layout::new(w, h);
        let p = FlowParams {
            max_iterations: 1000,
            tolerance_px: 1e-6,
            sor_omega: 1.0,
            ..params(FlowMethod::HornSchunck)
        };
        let problem = Problem::plain(&lay, &d, p.lambda);
        let mut st = SplitState::zeros(&lay);
        let (exact, ok) = problem.solve_with(&mut st, &p, Simd::detect(), 1, Some(1));
        assert!(ok && exact > 2 * MAX_BLOCK_ITERATIONS as u32, "{exact}");
        let mut st = SplitState::zeros(&lay);
        let (adaptive, ok) = problem.solve(&mut st, &p, Simd::detect());
        assert!(ok);
        assert!(
            adaptive >= exact && adaptive <= exact + 3,
            "checked every iteration: {exact}, adaptive blocks: {adaptive}"
        );
    }

    #[test]
    fn invalid_params_are_rejected() {
        let frames = translating(16, 16, 7, 0.3, 0.0, 1);
        let d = middle(&frames, 0.0, &no_prewarp());
        let bad = [
            FlowParams {
                lambda: f32::NAN,
                ..FlowParams::default()
            },
            FlowParams {
                lambda: 0.0,
                ..FlowParams::default()
            },
            FlowParams {
                lambda: -1.0,
                ..FlowParams::default()
            },
            FlowParams {
                max_iterations: 0,
                ..FlowParams::default()
            },
            FlowParams {
                tolerance_px: f32::NAN,
                ..FlowParams::default()
            },
            FlowParams {
                gradient_threshold: -1.0,
                ..FlowParams::default()
            },
            FlowParams {
                lk_window_px: 8,
                ..FlowParams::default()
            },
            FlowParams {
                lk_window_px: 1,
                ..FlowParams::default()
            },
            FlowParams {
                groove_weight: f32::INFINITY,
                ..FlowParams::default()
            },
            FlowParams {
                sor_omega: 2.0,
                ..FlowParams::default()
            },
        ];
        for p in &bad {
            assert!(
                matches!(
                    compute_flow(&d, 1e4, None, p),
                    Err(StageError::InvalidParam { .. })
                ),
                "{p:?}"
            );
        }
        assert!(matches!(
            compute_flow(&d, f64::NAN, None, &FlowParams::default()),
            Err(StageError::InvalidParam { .. })
        ));
        let walls = WallSideMap {
            width: 3,
            height: 3,
            sign: vec![0; 9],
        };
        assert!(matches!(
            compute_flow(&d, 1e4, Some(&walls), &FlowParams::default()),
            Err(StageError::BadInput { .. })
        ));
        let mut short = d.clone();
        short.it.data.pop();
        assert!(compute_flow(&short, 1e4, None, &params(FlowMethod::HornSchunck)).is_err());
    }

    #[test]
    fn confidence_is_gradient_magnitude_above_threshold() {
        let frames = translating(24, 20, 7, 0.3, 0.0, 2);
        let mut d = middle(&frames, 0.0, &no_prewarp());
        for k in 0..24 {
            d.ix.data[k] = 0.0;
            d.iy.data[k] = 0.0;
        }
        let p = params(FlowMethod::HornSchunck);
        let flow = compute_flow(&d, 1e4, None, &p).unwrap();
        assert!(flow.confidence.data[..24].iter().all(|&c| c == 0.0));
        let i = 10 * 24 + 10;
        let g = d.ix.data[i].hypot(d.iy.data[i]);
        assert!((flow.confidence.data[i] - g).abs() < 1e-6);
        assert!(flow.converged && flow.iterations < p.max_iterations);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]
        #[test]
        fn flow_has_input_size_and_no_nan(
            w in 2_usize..24,
            h in 2_usize..24,
            seed in 0_u64..1000,
            method in 0_usize..3,
            jacobi in any::<bool>(),
            amp in 0.0_f32..3.0,
        ) {
            let mut rng = Rng(seed);
            let mut img = || Image::from_fn(w, h, |_, _| amp * (rng.next_f64() as f32 - 0.5));
            let d = Derivatives {
                ix: img(),
                iy: img(),
                it: img(),
                image: Image::zeros(w, h),
                frame_index: 3,
                base_flow_px: -2.0,
            };
            let p = FlowParams {
                method: [FlowMethod::GrooveHornSchunck, FlowMethod::HornSchunck, FlowMethod::LucasKanade][method],
                solver: if jacobi { Solver::Jacobi } else { Solver::GaussSeidel },
                max_iterations: 30,
                ..FlowParams::default()
            };
            let flow = compute_flow(&d, 50.0, None, &p).unwrap();
            for im in [&flow.u, &flow.v, &flow.confidence] {
                prop_assert_eq!((im.width, im.height, im.data.len()), (w, h, w * h));
                prop_assert!(im.data.iter().all(|x| x.is_finite()));
            }
            prop_assert_eq!(flow.frame_index, 3);
        }
    }
}
