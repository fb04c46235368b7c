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
    /// Filter family.
    pub mode: DerivativeMode,
    /// Shift every frame back by the known land motion before filtering, so the flow stage
    /// only measures the small residual (keeps the linearisation valid for steps > 1 px).
    pub prewarp: bool,
}

impl Default for DerivativeParams {
    fn default() -> Self {
        Self {
            mode: DerivativeMode::Simoncelli,
            prewarp: true,
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
pub const P5: [f32; 5] = scale_to_unit_sum(SIMONCELLI_P5);
/// [`SIMONCELLI_D5`] rescaled to unit ramp gain (see [`P5`]).
pub const D5: [f32; 5] = scale_to_unit_moment(SIMONCELLI_D5);

/// Half of the Simoncelli window (frames each side of the centre).
const HALF_WINDOW: usize = SIMONCELLI_WINDOW_FRAMES / 2;
/// Rows per parallel work item of the separable filters.
const BAND_ROWS: usize = 16;
/// Spatial filter radius (5 taps).
const RADIUS: usize = 2;

const fn scale_to_unit_sum(taps: [f32; 5]) -> [f32; 5] {
    let mut sum = 0.0;
    let mut i = 0;
    while i < 5 {
        sum += taps[i];
        i += 1;
    }
    let mut out = taps;
    let mut j = 0;
    while j < 5 {
        out[j] = taps[j] / sum;
        j += 1;
    }
    out
}

const fn scale_to_unit_moment(taps: [f32; 5]) -> [f32; 5] {
    let mut moment = 0.0;
    let mut i = 0;
    while i < 5 {
        moment += taps[i] * (i as f32 - 2.0);
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

/// The pre-blur convolved with a 5-tap temporal filter: one 7-tap filter over the window.
fn fold_preblur(taps: &[f32; 5]) -> [f32; SIMONCELLI_WINDOW_FRAMES] {
    let mut out = [0.0_f32; SIMONCELLI_WINDOW_FRAMES];
    for (m, &t) in taps.iter().enumerate() {
        for (i, &b) in TEMPORAL_PREBLUR.iter().enumerate() {
            out[m + i] += t * b;
        }
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
    Ok(match params.mode {
        DerivativeMode::Simoncelli => (HALF_WINDOW..frames.len() - HALF_WINDOW)
            .map(|c| simoncelli_window(&frames[c - HALF_WINDOW..=c + HALF_WINDOW], c, base_flow_px))
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

/// A row resampler: `dst[x] = src(x + shift)` with clamped borders.
///
/// Integer shifts copy samples exactly; fractional ones use the Catmull–Rom cubic
/// (Keys, a = −1/2) through the four nearest samples.
#[derive(Clone, Copy, Debug)]
struct RowShift {
    /// Integer part (floor) of the shift, limited so index arithmetic cannot overflow.
    whole: isize,
    /// Cubic weights for samples `whole − 1 ..= whole + 2`; `None` for an integer shift.
    weights: Option<[f32; 4]>,
}

impl RowShift {
    fn new(shift_px: f64, width: usize) -> Self {
        let floor = shift_px.floor();
        let frac = shift_px - floor;
        // Anything beyond the row clamps to the border sample anyway.
        let limit = width as f64 + 4.0;
        let whole = floor.clamp(-limit, limit) as isize;
        let weights = (frac != 0.0).then(|| {
            let f = frac as f32;
            let f2 = f * f;
            let f3 = f2 * f;
            [
                0.5 * (-f3 + 2.0 * f2 - f),
                0.5 * (3.0 * f3 - 5.0 * f2 + 2.0),
                0.5 * (-3.0 * f3 + 4.0 * f2 + f),
                0.5 * (f3 - f2),
            ]
        });
        Self { whole, weights }
    }

    fn is_identity(&self) -> bool {
        self.whole == 0 && self.weights.is_none()
    }

    /// Resamples `src` into `dst` (same length).
    #[inline(always)]
    fn apply(&self, src: &[f32], dst: &mut [f32]) {
        let w = src.len().min(dst.len());
        if w == 0 {
            return;
        }
        let (src, dst) = (&src[..w], &mut dst[..w]);
        let last = w as isize - 1;
        let at = |i: isize| src[i.clamp(0, last) as usize];
        let n = self.whole;
        match self.weights {
            None => {
                // Interior: x + n inside the row.
                let lo = (-n).clamp(0, w as isize) as usize;
                let hi = (w as isize - n).clamp(lo as isize, w as isize) as usize;
                for (x, d) in dst.iter_mut().enumerate().take(lo) {
                    *d = at(x as isize + n);
                }
                if hi > lo {
                    let s0 = (lo as isize + n) as usize;
                    dst[lo..hi].copy_from_slice(&src[s0..s0 + (hi - lo)]);
                }
                for (x, d) in dst.iter_mut().enumerate().skip(hi) {
                    *d = at(x as isize + n);
                }
            }
            Some([w0, w1, w2, w3]) => {
                // Interior: x + n − 1 ≥ 0 and x + n + 2 ≤ w − 1.
                let lo = (1 - n).clamp(0, w as isize) as usize;
                let hi = (w as isize - 2 - n).clamp(lo as isize, w as isize) as usize;
                let edge = |x: usize| {
                    let b = x as isize + n;
                    w0 * at(b - 1) + w1 * at(b) + w2 * at(b + 1) + w3 * at(b + 2)
                };
                for (x, d) in dst.iter_mut().enumerate().take(lo) {
                    *d = edge(x);
                }
                if hi > lo {
                    let len = hi - lo;
                    let s0 = (lo as isize + n - 1) as usize;
                    let a = &src[s0..s0 + len];
                    let b = &src[s0 + 1..s0 + 1 + len];
                    let c = &src[s0 + 2..s0 + 2 + len];
                    let e = &src[s0 + 3..s0 + 3 + len];
                    let out = &mut dst[lo..hi];
                    for i in 0..len {
                        out[i] = w0 * a[i] + w1 * b[i] + w2 * c[i] + w3 * e[i];
                    }
                }
                for (x, d) in dst.iter_mut().enumerate().skip(hi) {
                    *d = edge(x);
                }
            }
        }
    }
}

/// `dst[x] = Σ_j taps[j]·src[clamp(x + j − 2)]` (a 5-tap correlation with clamped borders).
#[inline(always)]
fn correlate_row5(src: &[f32], taps: &[f32; 5], dst: &mut [f32]) {
    let w = src.len().min(dst.len());
    if w == 0 {
        return;
    }
    let (src, dst) = (&src[..w], &mut dst[..w]);
    let last = w as isize - 1;
    let edge = |x: usize| -> f32 {
        taps.iter()
            .enumerate()
            .map(|(j, &t)| t * src[(x as isize + j as isize - 2).clamp(0, last) as usize])
            .sum()
    };
    if w <= 2 * RADIUS {
        for (x, d) in dst.iter_mut().enumerate() {
            *d = edge(x);
        }
        return;
    }
    let len = w - 2 * RADIUS;
    let [t0, t1, t2, t3, t4] = *taps;
    let (a, b, c, d, e) = (
        &src[0..len],
        &src[1..len + 1],
        &src[2..len + 2],
        &src[3..len + 3],
        &src[4..len + 4],
    );
    let out = &mut dst[RADIUS..RADIUS + len];
    for i in 0..len {
        out[i] = t0 * a[i] + t1 * b[i] + t2 * c[i] + t3 * d[i] + t4 * e[i];
    }
    for x in (0..RADIUS).chain(w - RADIUS..w) {
        dst[x] = edge(x);
    }
}

/// `dst = Σ_j taps[j]·rows[j]` over five rows of equal length.
#[inline(always)]
fn combine_rows5(rows: [&[f32]; 5], taps: &[f32; 5], dst: &mut [f32]) {
    let len = dst.len();
    let [a, b, c, d, e] = rows.map(|r| &r[..len.min(r.len())]);
    if [a, b, c, d, e].iter().any(|r| r.len() != len) {
        return;
    }
    let [t0, t1, t2, t3, t4] = *taps;
    for i in 0..len {
        dst[i] = t0 * a[i] + t1 * b[i] + t2 * c[i] + t3 * d[i] + t4 * e[i];
    }
}

/// Rows `r..r + 5` of a buffer with row length `width`.
fn five_rows(buf: &[f32], r: usize, width: usize) -> [&[f32]; 5] {
    std::array::from_fn(|j| row_of(buf, r + j, width))
}

/// Row `y` of a buffer with row length `width`.
fn row_of(buf: &[f32], y: usize, width: usize) -> &[f32] {
    &buf[y * width..(y + 1) * width]
}

/// `acc = t·src` when `first`, else `acc += t·src`.
#[inline(always)]
fn axpy(acc: &mut [f32], t: f32, src: &[f32], first: bool) {
    let len = acc.len().min(src.len());
    let (acc, src) = (&mut acc[..len], &src[..len]);
    if first {
        for i in 0..len {
            acc[i] = t * src[i];
        }
    } else {
        for i in 0..len {
            acc[i] += t * src[i];
        }
    }
}

/// Columns at each side whose spatial filter, or the pre-warped samples it reads, reach
/// outside the frame: `filter_radius` without pre-warping.
fn prewarp_margin(shifts: &[RowShift], filter_radius: usize) -> usize {
    let reach = shifts
        .iter()
        .filter(|s| !s.is_identity())
        .map(|s| {
            // Cubic support is whole − 1 ..= whole + 2.
            let (lo, hi) = if s.weights.is_some() {
                (s.whole - 1, s.whole + 2)
            } else {
                (s.whole, s.whole)
            };
            lo.unsigned_abs().max(hi.unsigned_abs())
        })
        .max();
    reach.unwrap_or(0) + filter_radius
}

/// Zeroes the first and last `margin` values of a row (no data there).
fn blank_margins(row: &mut [f32], margin: usize) {
    let w = row.len();
    let m = margin.min(w);
    row[..m].fill(0.0);
    row[w - m..].fill(0.0);
}

/// Scratch rows one band of [`simoncelli_window`] works in.
struct BandScratch {
    /// Temporally smoothed rows (band + 2·RADIUS rows).
    p: Vec<f32>,
    /// Temporally differentiated rows (band + 2·RADIUS rows).
    d: Vec<f32>,
    /// One pre-warped input row.
    shifted: Vec<f32>,
    /// Vertical pass outputs for one row.
    yp: Vec<f32>,
    yd: Vec<f32>,
    ypd: Vec<f32>,
}

impl BandScratch {
    fn new(width: usize) -> Self {
        let rows = BAND_ROWS + 2 * RADIUS;
        Self {
            p: vec![0.0; rows * width],
            d: vec![0.0; rows * width],
            shifted: vec![0.0; width],
            yp: vec![0.0; width],
            yd: vec![0.0; width],
            ypd: vec![0.0; width],
        }
    }
}

/// What every band of one Simoncelli window shares.
struct BandCtx<'a> {
    window: &'a [Image],
    shifts: &'a [RowShift],
    p7: &'a [f32; SIMONCELLI_WINDOW_FRAMES],
    d7: &'a [f32; SIMONCELLI_WINDOW_FRAMES],
    /// Left/right columns without data (see [`prewarp_margin`]).
    margin: usize,
}

/// [`simoncelli_band`] compiled for AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn simoncelli_band_avx2(ctx: &BandCtx, s: &mut BandScratch, y0: usize, outs: [&mut [f32]; 4]) {
    simoncelli_band(ctx, s, y0, outs);
}

/// Rows `y0..` of one window: temporal 7-tap filters (with pre-warp) into `s.p`/`s.d`, then
/// the vertical and horizontal 5-tap passes into `outs = [ix, iy, it, image]` (whole rows).
#[inline(always)]
fn simoncelli_band(ctx: &BandCtx, s: &mut BandScratch, y0: usize, outs: [&mut [f32]; 4]) {
    let [ix_b, iy_b, it_b, im_b] = outs;
    let (width, height) = (ctx.window[0].width, ctx.window[0].height);
    let rows = ix_b.len() / width;
    // Temporal filtering of rows y0 − 2 ..= y0 + rows + 1 (clamped).
    for r in 0..rows + 2 * RADIUS {
        let y = (y0 as isize + r as isize - RADIUS as isize).clamp(0, height as isize - 1) as usize;
        let p_row = &mut s.p[r * width..(r + 1) * width];
        let d_row = &mut s.d[r * width..(r + 1) * width];
        let mut first_d = true;
        for (k, frame) in ctx.window.iter().enumerate() {
            let src = frame.row(y);
            let row: &[f32] = if ctx.shifts[k].is_identity() {
                src
            } else {
                ctx.shifts[k].apply(src, &mut s.shifted);
                &s.shifted
            };
            axpy(p_row, ctx.p7[k], row, k == 0);
            if ctx.d7[k] != 0.0 {
                axpy(d_row, ctx.d7[k], row, first_d);
                first_d = false;
            }
        }
    }
    for r in 0..rows {
        combine_rows5(five_rows(&s.p, r, width), &P5, &mut s.yp);
        combine_rows5(five_rows(&s.p, r, width), &D5, &mut s.yd);
        combine_rows5(five_rows(&s.d, r, width), &P5, &mut s.ypd);
        let out = r * width..(r + 1) * width;
        correlate_row5(&s.yp, &D5, &mut ix_b[out.clone()]);
        correlate_row5(&s.yp, &P5, &mut im_b[out.clone()]);
        correlate_row5(&s.yd, &P5, &mut iy_b[out.clone()]);
        correlate_row5(&s.ypd, &P5, &mut it_b[out.clone()]);
        let y = y0 + r;
        let m = if y < RADIUS || y + RADIUS >= height {
            width
        } else {
            ctx.margin
        };
        blank_margins(&mut ix_b[out.clone()], m);
        blank_margins(&mut iy_b[out.clone()], m);
        blank_margins(&mut it_b[out], m);
    }
}

/// One Simoncelli derivative set from a 7-frame window centred on group frame `centre`.
fn simoncelli_window(window: &[Image], centre: usize, base_flow_px: f64) -> Derivatives {
    let (width, height) = (window[0].width, window[0].height);
    let p7 = fold_preblur(&P5);
    let d7 = fold_preblur(&D5);
    let shifts: Vec<RowShift> = (0..window.len())
        .map(|k| RowShift::new((k as f64 - HALF_WINDOW as f64) * base_flow_px, width))
        .collect();

    let margin = prewarp_margin(&shifts, RADIUS);
    #[cfg(target_arch = "x86_64")]
    let avx2 = std::arch::is_x86_feature_detected!("avx2");
    let n = width * height;
    let (mut ix, mut iy, mut it, mut image) =
        (vec![0.0; n], vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    let chunk = BAND_ROWS * width;
    ix.par_chunks_mut(chunk)
        .zip(iy.par_chunks_mut(chunk))
        .zip(it.par_chunks_mut(chunk))
        .zip(image.par_chunks_mut(chunk))
        .enumerate()
        .for_each_init(
            || BandScratch::new(width),
            |s, (band, (((ix_b, iy_b), it_b), im_b))| {
                let ctx = BandCtx {
                    window,
                    shifts: &shifts,
                    p7: &p7,
                    d7: &d7,
                    margin,
                };
                let outs = [ix_b, iy_b, it_b, im_b];
                #[cfg(target_arch = "x86_64")]
                if avx2 {
                    // SAFETY: `avx2` is true only when the CPU reported AVX2.
                    unsafe { simoncelli_band_avx2(&ctx, s, band * BAND_ROWS, outs) };
                    return;
                }
                simoncelli_band(&ctx, s, band * BAND_ROWS, outs);
            },
        );
    let wrap = |data| Image {
        width,
        height,
        data,
    };
    Derivatives {
        ix: wrap(ix),
        iy: wrap(iy),
        it: wrap(it),
        image: wrap(image),
        frame_index: centre,
        base_flow_px: base_flow_px as f32,
    }
}

/// One two-frame derivative set: central differences in x and y averaged over both frames,
/// `It` = difference of the frames (the second pre-warped by `base_flow_px`).
fn two_frame(a: &Image, b: &Image, index: usize, base_flow_px: f64) -> Derivatives {
    let (width, height) = (a.width, a.height);
    let shift = RowShift::new(base_flow_px, width);
    let margin = prewarp_margin(&[shift], 1);
    let warped: Vec<f32> = if shift.is_identity() {
        b.data.clone()
    } else {
        let mut out = vec![0.0; width * height];
        out.par_chunks_mut(width)
            .zip(b.data.par_chunks(width))
            .for_each(|(dst, src)| shift.apply(src, dst));
        out
    };
    let n = width * height;
    let (mut ix, mut iy, mut it, mut image) =
        (vec![0.0; n], vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    let last_x = width - 1;
    ix.par_chunks_mut(width)
        .zip(iy.par_chunks_mut(width))
        .zip(it.par_chunks_mut(width))
        .zip(image.par_chunks_mut(width))
        .enumerate()
        .for_each(|(y, (((ix_r, iy_r), it_r), im_r))| {
            let up = y.saturating_sub(1);
            let dn = (y + 1).min(height - 1);
            let (a0, a_up, a_dn) = (
                row_of(&a.data, y, width),
                row_of(&a.data, up, width),
                row_of(&a.data, dn, width),
            );
            let (b0, b_up, b_dn) = (
                row_of(&warped, y, width),
                row_of(&warped, up, width),
                row_of(&warped, dn, width),
            );
            for x in 0..width {
                let (l, r) = (x.saturating_sub(1), (x + 1).min(last_x));
                ix_r[x] = 0.25 * ((a0[r] - a0[l]) + (b0[r] - b0[l]));
                iy_r[x] = 0.25 * ((a_dn[x] - a_up[x]) + (b_dn[x] - b_up[x]));
                it_r[x] = b0[x] - a0[x];
                im_r[x] = 0.5 * (a0[x] + b0[x]);
            }
            let m = if y == 0 || y + 1 == height {
                width
            } else {
                margin
            };
            blank_margins(ix_r, m);
            blank_margins(iy_r, m);
            blank_margins(it_r, m);
        });
    let wrap = |data| Image {
        width,
        height,
        data,
    };
    Derivatives {
        ix: wrap(ix),
        iy: wrap(iy),
        it: wrap(it),
        image: wrap(image),
        frame_index: index,
        base_flow_px: base_flow_px as f32,
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests fail loudly on purpose
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn simoncelli(prewarp: bool) -> DerivativeParams {
        DerivativeParams {
            mode: DerivativeMode::Simoncelli,
            prewarp,
        }
    }

    #[test]
    fn filters_are_normalised() {
        assert!((P5.iter().sum::<f32>() - 1.0).abs() < 1e-6);
        let moment: f32 = D5
            .iter()
            .enumerate()
            .map(|(j, &t)| t * (j as f32 - 2.0))
            .sum();
        assert!((moment - 1.0).abs() < 1e-6);
        let d7 = fold_preblur(&D5);
        let m7: f32 = d7
            .iter()
            .enumerate()
            .map(|(j, &t)| t * (j as f32 - 3.0))
            .sum();
        assert!((m7 - 1.0).abs() < 1e-6 && d7[3].abs() < 1e-9);
        assert!((fold_preblur(&P5).iter().sum::<f32>() - 1.0).abs() < 1e-6);
    }

    #[test]
    fn ramps_give_positive_unit_derivatives() {
        let (w, h) = (20, 16);
        let frames: Vec<Image> = (0..9)
            .map(|k| {
                Image::from_fn(w, h, |x, y| {
                    0.01 * x as f32 + 0.02 * y as f32 + 0.03 * k as f32
                })
            })
            .collect();
        for mode in [DerivativeMode::Simoncelli, DerivativeMode::TwoFrame] {
            let p = DerivativeParams {
                mode,
                prewarp: false,
            };
            let sets = compute_derivatives(&frames, -2.0, &p).unwrap();
            let expected = if mode == DerivativeMode::Simoncelli {
                3
            } else {
                8
            };
            assert_eq!(sets.len(), expected);
            for d in &sets {
                assert_eq!(d.base_flow_px, 0.0);
                // Interior pixel, away from clamped borders.
                let (x, y) = (10, 8);
                assert!((d.ix.get(x, y).unwrap() - 0.01).abs() < 1e-6);
                assert!((d.iy.get(x, y).unwrap() - 0.02).abs() < 1e-6);
                assert!((d.it.get(x, y).unwrap() - 0.03).abs() < 1e-6);
            }
        }
        let sets = compute_derivatives(&frames, -2.0, &simoncelli(false)).unwrap();
        let idx: Vec<usize> = sets.iter().map(|d| d.frame_index).collect();
        assert_eq!(idx, vec![3, 4, 5]);
        // The smoothed image of a ramp is the ramp (p5 is symmetric and sums to 1).
        let c = &sets[1];
        let want = 0.01 * 10.0 + 0.02 * 8.0 + 0.03 * 4.0;
        assert!((c.image.get(10, 8).unwrap() - want).abs() < 1e-5);
    }

    #[test]
    fn analytic_translating_pattern() {
        // I = sin(a(x − u·t))·cos(b·y).
        let (a, b, u) = (
            std::f64::consts::TAU / 32.0,
            std::f64::consts::TAU / 40.0,
            0.5,
        );
        let (w, h) = (80, 64);
        let frames: Vec<Image> = (0..7)
            .map(|k| {
                Image::from_fn(w, h, |x, y| {
                    ((a * (x as f64 - u * k as f64)).sin() * (b * y as f64).cos()) as f32
                })
            })
            .collect();
        let sets = compute_derivatives(&frames, 0.0, &simoncelli(false)).unwrap();
        assert_eq!(sets.len(), 1);
        let d = &sets[0];
        assert_eq!(d.frame_index, 3);
        let t = 3.0;
        let (mut worst_x, mut worst_y, mut worst_t, mut worst_flow) =
            (0.0_f64, 0.0_f64, 0.0_f64, 0.0_f64);
        for y in 4..h - 4 {
            for x in 4..w - 4 {
                let (xf, yf) = (x as f64, y as f64);
                let phase = a * (xf - u * t);
                let ix = a * phase.cos() * (b * yf).cos();
                let iy = -b * phase.sin() * (b * yf).sin();
                let it = -u * ix;
                let got = |im: &Image| f64::from(im.get(x, y).unwrap());
                worst_x = worst_x.max((got(&d.ix) - ix).abs());
                worst_y = worst_y.max((got(&d.iy) - iy).abs());
                worst_t = worst_t.max((got(&d.it) - it).abs());
                // The ratio It/Ix is what the flow uses: it must be much closer than the gains.
                if ix.abs() > 0.5 * a {
                    worst_flow = worst_flow.max((-got(&d.it) / got(&d.ix) - u).abs());
                }
            }
        }
        // p5 smooths a 32 px (40 px) wave by ~3 % (2 %): allow 6 % of the amplitude.
        assert!(worst_x < 0.06 * a, "Ix off by {worst_x}");
        assert!(worst_y < 0.06 * b, "Iy off by {worst_y}");
        assert!(worst_t < 0.06 * a * u, "It off by {worst_t}");
        assert!(worst_flow < 0.005 * u, "It/Ix off by {worst_flow}");
    }

    #[test]
    fn integer_prewarp_aligns_exactly() {
        let (w, h) = (40, 12);
        // Content moves 2 px toward −x per frame.
        let frames: Vec<Image> = (0..12)
            .map(|k| {
                Image::from_fn(w, h, |x, y| {
                    (0.37 * (x + 2 * k) as f32).sin() + 0.1 * y as f32
                })
            })
            .collect();
        let sets = compute_derivatives(&frames, -2.0, &simoncelli(true)).unwrap();
        assert_eq!(sets.len(), 6);
        for d in &sets {
            assert_eq!(d.base_flow_px, -2.0);
            // Interior: no shifted sample was clamped (|shift| ≤ 6 px).
            for y in 0..h {
                for x in 8..w - 8 {
                    assert!(d.it.get(x, y).unwrap().abs() < 1e-5);
                }
            }
        }
        let shift = RowShift::new(-2.0, w);
        assert!(shift.weights.is_none());
        let src: Vec<f32> = (0..w).map(|x| x as f32).collect();
        let mut dst = vec![0.0; w];
        shift.apply(&src, &mut dst);
        assert_eq!(&dst[..3], &[0.0, 0.0, 0.0]);
        assert_eq!(dst[10], 8.0);
    }

    #[test]
    fn cubic_shift_is_exact_on_cubics_and_clamps() {
        let w = 30;
        let f = |x: f64| 0.5 + 0.1 * x - 0.01 * x * x + 0.0005 * x * x * x;
        let src: Vec<f32> = (0..w).map(|x| f(x as f64) as f32).collect();
        let mut dst = vec![0.0; w];
        for s in [0.25, -1.5, 3.7] {
            RowShift::new(s, w).apply(&src, &mut dst);
            for (x, &got) in dst.iter().enumerate().take(w - 6).skip(3) {
                // Catmull–Rom reproduces quadratics exactly; cubic terms leave a small error.
                let want = f(x as f64 + s);
                assert!(
                    (f64::from(got) - want).abs() < 2e-3,
                    "{s} {x}: {got} vs {want}"
                );
            }
        }
        RowShift::new(1e9, w).apply(&src, &mut dst);
        assert!(dst.iter().all(|&v| v == src[w - 1]));
        RowShift::new(-1e9, w).apply(&src, &mut dst);
        assert!(dst.iter().all(|&v| v == src[0]));
    }

    #[test]
    fn bad_input_is_rejected() {
        let frame = Image::zeros(8, 6);
        let six = vec![frame.clone(); 6];
        assert!(matches!(
            compute_derivatives(&six, 0.0, &simoncelli(true)),
            Err(StageError::BadInput { .. })
        ));
        let one = vec![frame.clone(); 1];
        let two_frame = DerivativeParams {
            mode: DerivativeMode::TwoFrame,
            prewarp: true,
        };
        assert!(compute_derivatives(&one, 0.0, &two_frame).is_err());
        assert_eq!(compute_derivatives(&six, 0.0, &two_frame).unwrap().len(), 5);
        let mut mixed = vec![frame.clone(); 7];
        mixed[4] = Image::zeros(8, 5);
        assert!(matches!(
            compute_derivatives(&mixed, 0.0, &simoncelli(true)),
            Err(StageError::BadInput { .. })
        ));
        let seven = vec![frame; 7];
        for bad in [f64::NAN, f64::INFINITY] {
            assert!(matches!(
                compute_derivatives(&seven, bad, &simoncelli(false)),
                Err(StageError::InvalidParam { .. })
            ));
        }
        assert!(compute_derivatives(&[], 0.0, &simoncelli(false)).is_err());
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]
        #[test]
        fn outputs_match_input_size_and_are_finite(
            w in 1_usize..20,
            h in 1_usize..20,
            n in 7_usize..10,
            land in -8.0_f64..8.0,
            prewarp in any::<bool>(),
            two in any::<bool>(),
            seed in 0_u32..1000,
        ) {
            let frames: Vec<Image> = (0..n)
                .map(|k| Image::from_fn(w, h, |x, y| {
                    let v = (x * 31 + y * 17 + k * 7 + seed as usize) % 23;
                    v as f32 / 23.0
                }))
                .collect();
            let p = DerivativeParams {
                mode: if two { DerivativeMode::TwoFrame } else { DerivativeMode::Simoncelli },
                prewarp,
            };
            let sets = compute_derivatives(&frames, land, &p).unwrap();
            prop_assert_eq!(sets.len(), if two { n - 1 } else { n - 6 });
            for d in &sets {
                for im in [&d.ix, &d.iy, &d.it, &d.image] {
                    prop_assert_eq!((im.width, im.height, im.data.len()), (w, h, w * h));
                    prop_assert!(im.data.iter().all(|v| v.is_finite()));
                }
            }
        }
    }
}
