//! Spatio-temporal derivatives: [1/4,1/2,1/4] temporal pre-blur and Simoncelli's matched p5/d5 filters (paper §3).
//!
//! Simoncelli mode works on every 7-frame window of a group (centre frame `c = 3..N-3`):
//!
//! 1. optional pre-warp: frame `k` is resampled along x so that land-plane content lines up
//!    with the centre frame, `J_k(x) = I_k(x + (k − c)·L)` with `L` the land flow per frame
//!    (integer shifts are exact copies, fractional ones Catmull–Rom cubic; borders clamp);
//! 2. temporal pre-blur `[1/4, 1/2, 1/4]` (7 frames → 5);
//! 3. separable p5/d5: `Ix = d5(x)·p5(y)·p5(t)`, `Iy = p5(x)·d5(y)·p5(t)`,
//!    `It = p5(x)·p5(y)·d5(t)`, `image = p5(x)·p5(y)·p5(t)`.
//!
//! The pre-blur and the temporal p5/d5 are folded into one 7-tap filter each, and the
//! filters are applied as correlations (a ramp increasing in x, y or t gives a positive
//! derivative). Spatial borders are clamped. The work runs over bands of rows in parallel.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::StageError;
use crate::image::Image;
use crate::pipeline::simd::{Compiled, Isa};

#[cfg(test)]
mod reference;
mod shift;
mod simoncelli;
#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests fail loudly on purpose
mod tests;
mod two_frame;

use shift::*;
use simoncelli::*;
use two_frame::*;

/// How derivatives are taken.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum DerivativeMode {
    /// 7 frames -> pre-blur -> 5 frames -> p5/d5: one derivative set per 7-frame window.
    #[default]
    Simoncelli,
    /// Simple differences between two consecutive frames: one set per frame pair.
    TwoFrame,
}

/// Knobs of [`compute_derivatives`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DerivativeParams {
    #[doc = knob!("derivatives.mode")]
    pub mode: DerivativeMode,
    #[doc = knob!("derivatives.prewarp")]
    pub prewarp: bool,
    /// Instruction set of the filter bands (not a knob: never in the TOML; by default the
    /// CPU's best, detected once).
    #[serde(skip)]
    pub isa: Isa,
}

impl Default for DerivativeParams {
    fn default() -> Self {
        Self {
            mode: DerivativeMode::Simoncelli,
            prewarp: true,
            isa: Isa::detect(),
        }
    }
}

/// Ix, Iy, It of one temporal window, in the coordinates of frame `frame_index`.
#[derive(Clone, Debug, PartialEq)]
pub struct Derivatives {
    /// ∂I/∂x.
    pub ix: Image,
    /// ∂I/∂y.
    pub iy: Image,
    /// ∂I/∂t (per frame).
    pub it: Image,
    /// The pre-filtered grey image the derivatives belong to (for display and in-focus maps).
    pub image: Image,
    /// Frame of the group whose pixel grid these derivatives use (window centre).
    pub frame_index: usize,
    /// Flow (px/frame along x) removed by pre-warping; the flow stage adds it back.
    pub base_flow_px: f32,
}

impl Derivatives {
    /// A set in which only ∂I/∂y is known (∂I/∂x, ∂I/∂t and the image are zero): all that the
    /// stripe search reads, so an in-focus map can be fed to it directly.
    #[must_use]
    pub fn from_iy(iy: Image, frame_index: usize, base_flow_px: f32) -> Self {
        let zeros = Image::zeros(iy.width, iy.height);
        Self {
            ix: zeros.clone(),
            iy,
            it: zeros.clone(),
            image: zeros,
            frame_index,
            base_flow_px,
        }
    }

    /// A set from its four `width` × `height` planes `[ix, iy, it, image]`.
    fn from_planes(
        (width, height): (usize, usize),
        planes: [Vec<f32>; 4],
        frame_index: usize,
        base_flow_px: f64,
    ) -> Self {
        let [ix, iy, it, image] = planes.map(|data| Image {
            width,
            height,
            data,
        });
        Self {
            ix,
            iy,
            it,
            image,
            frame_index,
            base_flow_px: base_flow_px as f32,
        }
    }
}

/// Simoncelli's 5-tap prefilter as published (paper §3); [`P5`] is this scaled to unit sum.
pub const SIMONCELLI_P5: [f32; 5] = [0.036, 0.249, 0.431, 0.249, 0.036];
/// Simoncelli's 5-tap derivative filter as published, in correlation order (a ramp gives a
/// positive response); [`D5`] is this scaled to a unit response on a unit ramp.
pub const SIMONCELLI_D5: [f32; 5] = [-0.108, -0.283, 0.0, 0.283, 0.108];
/// Temporal pre-blur applied before the 5-tap temporal filters.
pub const TEMPORAL_PREBLUR: [f32; 3] = [0.25, 0.5, 0.25];
/// Frames in one Simoncelli window (pre-blur 3 taps + filter 5 taps − 1).
pub const SIMONCELLI_WINDOW_FRAMES: usize = 7;

/// The published taps round to a sum of 1.001 and a ramp gain of 0.998; rescaling makes a
/// constant image give `image == I` and a unit ramp give a derivative of exactly 1.
pub const P5: [f32; 5] = scale_taps(SIMONCELLI_P5, 0);
/// [`SIMONCELLI_D5`] rescaled to unit ramp gain (see [`P5`]).
pub const D5: [f32; 5] = scale_taps(SIMONCELLI_D5, 1);

/// Half of the Simoncelli window (frames each side of the centre).
const HALF_WINDOW: usize = SIMONCELLI_WINDOW_FRAMES / 2;
/// Spatial filter radius (5 taps).
const RADIUS: usize = 2;

/// `taps` divided by their moment Σ taps[i]·(i − 2)^`power` (power 0: the sum; 1: the response
/// to a unit ramp).
const fn scale_taps(taps: [f32; 5], power: u32) -> [f32; 5] {
    let mut moment = 0.0;
    let mut i = 0;
    while i < 5 {
        moment += taps[i] * if power == 0 { 1.0 } else { i as f32 - 2.0 };
        i += 1;
    }
    let mut out = taps;
    let mut j = 0;
    while j < 5 {
        out[j] = taps[j] / moment;
        j += 1;
    }
    out
}

/// Computes derivative sets over a group of frames.
///
/// `land_flow_px` is the known image motion of the land plane per frame (negative: content
/// moves toward -x); used only when `params.prewarp` is set.
///
/// Simoncelli mode returns one set per 7-frame window (`frames.len() − 6` sets, centred on
/// frames `3..frames.len()−3`); two-frame mode returns one set per consecutive pair
/// (`frame_index` = the earlier frame; the derivatives sit half-way between the two).
///
/// Border pixels whose filters read clamped samples carry no data: their `ix`, `iy` and `it`
/// are set to 0, so the flow stage gives them zero confidence and Horn–Schunck fills them in
/// from the interior instead of smoothing clamping artefacts into the frame. The strip is the
/// filter radius (2 px Simoncelli, 1 px two-frame) at the top and bottom, and at the left and
/// right that plus the largest pre-warp shift (+2 px for a fractional shift), e.g. 8 px at
/// 2 px/frame with 7-frame windows.
///
/// # Errors
/// [`StageError`] when there are too few frames for the mode, sizes differ, or a value is not finite.
pub fn compute_derivatives(
    frames: &[Image],
    land_flow_px: f64,
    params: &DerivativeParams,
) -> Result<Vec<Derivatives>, StageError> {
    if !land_flow_px.is_finite() {
        return Err(StageError::InvalidParam {
            name: "land_flow_px".to_string(),
            problem: format!("{land_flow_px} is not finite"),
        });
    }
    let needed = match params.mode {
        DerivativeMode::Simoncelli => SIMONCELLI_WINDOW_FRAMES,
        DerivativeMode::TwoFrame => 2,
    };
    let Some(first) = frames.first() else {
        return Err(bad_input("no frames".to_string()));
    };
    if frames.len() < needed {
        return Err(bad_input(format!(
            "{} frames, the {:?} mode needs at least {needed}",
            frames.len(),
            params.mode
        )));
    }
    if first.width == 0 || first.height == 0 || first.data.len() != first.width * first.height {
        return Err(bad_input(format!(
            "frame 0 is {}x{} with {} values",
            first.width,
            first.height,
            first.data.len()
        )));
    }
    if let Some((k, f)) = frames
        .iter()
        .enumerate()
        .find(|(_, f)| !f.same_size(first) || f.data.len() != first.data.len())
    {
        return Err(bad_input(format!(
            "frame {k} is {}x{}, frame 0 is {}x{}",
            f.width, f.height, first.width, first.height
        )));
    }
    let base_flow_px = if params.prewarp { land_flow_px } else { 0.0 };
    // The widest pre-warp of a window must leave columns whose filters read real samples:
    // without any the derivatives are all zero and the flow silently nothing.
    // The window's shifts, its filter radius, and how many frames its farthest frame is moved.
    let (shifts, radius, reach_frames) = match params.mode {
        DerivativeMode::Simoncelli => (
            window_shifts(base_flow_px, first.width),
            RADIUS,
            HALF_WINDOW as f64,
        ),
        DerivativeMode::TwoFrame => (vec![RowShift::new(base_flow_px, first.width)], 1, 1.0),
    };
    let margin = prewarp_margin(&shifts, radius);
    if 2 * margin >= first.width && 2 * radius < first.width {
        // Short figures for absurd values (1e30 px), whole pixels otherwise.
        let px = |v: f64| {
            if v.abs() < 1e6 {
                format!("{v}")
            } else {
                format!("{v:.1e}")
            }
        };
        return Err(StageError::InvalidParam {
            name: "land_flow_px".to_string(),
            problem: format!(
                "{} px per frame pre-warps the {:?} window by up to {} px: nothing of a {} px \
                 wide frame is left to compare",
                px(land_flow_px),
                params.mode,
                px((land_flow_px * reach_frames).abs().ceil()),
                first.width
            ),
        });
    }
    Ok(match params.mode {
        DerivativeMode::Simoncelli => (HALF_WINDOW..frames.len() - HALF_WINDOW)
            .map(|c| {
                simoncelli_window(
                    &frames[c - HALF_WINDOW..=c + HALF_WINDOW],
                    c,
                    base_flow_px,
                    params.isa,
                )
            })
            .collect(),
        DerivativeMode::TwoFrame => (0..frames.len() - 1)
            .map(|k| two_frame(&frames[k], &frames[k + 1], k, base_flow_px))
            .collect(),
    })
}

fn bad_input(problem: String) -> StageError {
    StageError::BadInput {
        stage: "derivatives",
        problem,
    }
}
