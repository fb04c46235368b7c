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
//! register. Several iterations are run per pass over the image (temporal blocking): a wavefront keeps a band
//! of rows in cache while they are updated `2K` times (trapezoids per thread, then the small
//! inverted triangles at the band seams). Red–black Gauss–Seidel and Jacobi (ping-pong
//! buffers) share this machinery. Convergence (`mean |Δu| + |Δv| < τ`) is measured on the
//! last iteration of each block, and also on its middle one; the next block is cut to the
//! iterations a geometric fit of those two changes predicts are still needed, so a solve
//! stops close to where τ is reached rather than up to a whole block past it.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::StageError;
use super::derivatives::Derivatives;
use crate::image::{Image, zeros_par};
use crate::pipeline::simd::{Compiled, Isa};

mod bands;
mod groove;
mod layout;
mod lucas_kanade;
#[cfg(test)]
mod reference;
mod solver;
#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests fail loudly on purpose
mod tests;
mod wall_sides;
mod warm_start;

use bands::*;
use groove::*;
use layout::*;
use lucas_kanade::*;
use solver::*;
pub use wall_sides::estimate_wall_sides;
use wall_sides::*;
pub use warm_start::flows_of_group;

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

/// Most Horn–Schunck iterations one solve may be asked for (about 4 s a window on a
/// 1280×1024 frame); a larger cap, with τ = 0, would keep a stage busy for hours.
pub const MAX_FLOW_ITERATIONS: u32 = 10_000;

/// Knobs of [`compute_flow`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FlowParams {
    #[doc = knob!("flow.method")]
    pub method: FlowMethod,
    #[doc = knob!("flow.solver")]
    pub solver: Solver,
    #[doc = knob!("flow.lambda")]
    pub lambda: f32,
    #[doc = knob!("flow.max_iterations")]
    ///
    /// The groove method's wall-estimating plain pass may run up to
    /// [`WALL_PRESOLVE_MAX_ITERATIONS`] whatever this is.
    pub max_iterations: u32,
    #[doc = knob!("flow.tolerance_px")]
    ///
    /// The default, 10⁻⁴, is set for the groove method (its wall-estimating plain pass converges to
    /// [`WALL_PRESOLVE_TOLERANCE_PX`] regardless); a plain Horn–Schunck field meant to be fully
    /// converged (a `.flo` export, the depth scenes) is closer with 10⁻⁵.
    pub tolerance_px: f32,
    #[doc = knob!("flow.gradient_threshold")]
    pub gradient_threshold: f32,
    #[doc = knob!("flow.lk_window_px")]
    pub lk_window_px: usize,
    #[doc = knob!("flow.groove_weight")]
    pub groove_weight: f32,
    #[doc = knob!("flow.sor_omega")]
    ///
    /// In (0, 2): the same solution as plain Gauss–Seidel, reached in fewer iterations.
    pub sor_omega: f32,
    /// Instruction set of the solver's kernels (not a knob: never in the TOML; by default the
    /// CPU's best, detected once).
    #[serde(skip)]
    pub isa: Isa,
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
            isa: Isa::detect(),
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

impl FlowField {
    /// A field known exactly, from a model rather than a measurement: horizontal flow `u`, no
    /// vertical flow, full confidence everywhere, converged in one iteration.
    #[must_use]
    pub fn exact(u: Image, frame_index: usize) -> Self {
        let (w, h) = (u.width, u.height);
        Self {
            u,
            v: Image::zeros(w, h),
            confidence: Image::filled(w, h, 1.0),
            iterations: 1,
            converged: true,
            frame_index,
        }
    }
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
/// Sets the iterations between convergence checks: as many as half-sweeps over this many
/// bytes of rows (state and factors) would take, so 16 for plain Horn–Schunck at 1280 px and 8
/// for the groove method. Where a τ > 0 solve stops depends on it, so it stays put even though
/// the passes that run the iterations are now sized apart ([`PASS_LEVELS`]).
const BLOCK_CACHE_BYTES: usize = 896 * 1024;
/// Longest block of iterations between convergence checks.
const MAX_BLOCK_ITERATIONS: usize = 16;
/// Most levels (red–black half-sweeps, or Jacobi sweeps) one wavefront pass runs; a longer
/// block runs as several passes, with the same bits, whose rows stay in the level-2 cache (the
/// measured pass lengths: docs/PERFORMANCE.md). The groove method's blocks of 8 iterations fit
/// in one pass.
const PASS_LEVELS: usize = 16;
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
    params.validate()?;
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
    let isa = params.isa;
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
    let plain = || HsSystem::plain(&lay, d, params.lambda);
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
                let (it, _) = plain().solve(&mut st, &presolve, isa);
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
        let problem = HsSystem::groove(&lay, d, walls, focal_px, params, isa);
        let (it, conv) = problem.solve(&mut st, params, isa);
        (st, first_iterations.saturating_add(it), conv)
    } else {
        let mut st = start();
        let (it, conv) = plain().solve(&mut st, params, isa);
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
    params.validate()?;
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

impl FlowParams {
    /// Checks every flow knob.
    ///
    /// # Errors
    /// [`StageError::InvalidParam`] naming the first bad key.
    pub fn validate(&self) -> Result<(), StageError> {
        let p = self;
        super::check_range("flow.lambda", f64::from(p.lambda), 1e-12, 1e12)?;
        super::check_range("flow.tolerance_px", f64::from(p.tolerance_px), 0.0, 1e3)?;
        super::check_range(
            "flow.gradient_threshold",
            f64::from(p.gradient_threshold),
            0.0,
            1e6,
        )?;
        if p.max_iterations == 0 || p.max_iterations > MAX_FLOW_ITERATIONS {
            return Err(StageError::InvalidParam {
                name: "flow.max_iterations".to_string(),
                problem: format!("{} is not in [1, {MAX_FLOW_ITERATIONS}]", p.max_iterations),
            });
        }
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
        if p.lk_window_px.is_multiple_of(2)
            || p.lk_window_px < 3
            || p.lk_window_px > MAX_LK_WINDOW_PX
        {
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
