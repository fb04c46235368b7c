//! Per-line border fits along one groove: each of its four borders (land|wall, wall|bottom,
//! bottom|wall, wall|land) is sought near its predicted position and fitted with the shared
//! edge-spread model ([`crate::pipeline::edges::border::fit_border`]).
//!
//! On each line a border's seed is the strongest gradient of its polarity within the search
//! window around the prediction (parabola-refined); the fit then reads the points within the
//! model's half window of the seed, but never past halfway to the neighbouring borders, so the
//! other edges of a narrow wall do not pull it. Lines are independent (fitted in parallel).

use rayon::prelude::*;

use super::ribbon::Ribbon;
use super::{StillParams, WallTone};
use crate::pipeline::edges::border::{BorderSeed, ProfilePoint, fit_border};

/// Lines per parallel task.
const LINE_CHUNK: usize = 256;

/// One border on one line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BorderFit {
    /// Position across the image (px, pixel-centre coordinates).
    pub position_px: f64,
    /// Its standard error (px).
    pub std_error_px: f64,
    /// Fitted step `high − low` along increasing cross position.
    pub contrast: f64,
    /// Fitted edge-spread σ (px).
    pub width_px: f64,
    /// Weighted residual rms (grey level).
    pub residual_rms: f64,
}

/// The borders of one groove on every line.
#[derive(Clone, Debug, PartialEq)]
pub struct BorderTracks {
    /// Lines.
    pub lines: usize,
    /// `fits[n][i]`: border `i` (land|wall, wall|bottom, bottom|wall, wall|land) on line `n`.
    pub fits: Vec<[Option<BorderFit>; 4]>,
    /// The predicted borders the search started from.
    pub predicted: Vec<[f64; 4]>,
}

impl BorderTracks {
    /// Border `i`'s positions (NaN where not fitted).
    #[must_use]
    pub fn positions(&self, i: usize) -> Vec<f64> {
        self.fits
            .iter()
            .map(|f| {
                f.get(i)
                    .copied()
                    .flatten()
                    .map_or(f64::NAN, |b| b.position_px)
            })
            .collect()
    }
}

/// Sign of the step of border `i` along increasing cross position (+1 rising).
fn step_sign(i: usize, tone: WallTone) -> f64 {
    let dark = if i.is_multiple_of(2) { -1.0 } else { 1.0 };
    match tone {
        WallTone::Dark => dark,
        WallTone::Bright => -dark,
    }
}

/// The strongest gradient of sign `sign` in `[lo, hi]` (ribbon coordinates), parabola-refined.
fn seed_at(v: &[f32], lo: f64, hi: f64, sign: f64) -> Option<f64> {
    let n = v.len();
    let a = lo.floor().max(1.0) as usize;
    let b = (hi.ceil() as usize).min(n.saturating_sub(2));
    let grad = |c: usize| -> f64 {
        match (v.get(c.wrapping_sub(1)), v.get(c + 1)) {
            (Some(l), Some(r)) => sign * 0.5 * f64::from(r - l),
            _ => f64::NAN,
        }
    };
    let mut best: Option<(usize, f64)> = None;
    for c in a..=b {
        let g = grad(c);
        if g.is_finite() && g > 0.0 && best.is_none_or(|(_, bg)| g > bg) {
            best = Some((c, g));
        }
    }
    let (c, g) = best?;
    let (gl, gr) = (grad(c.wrapping_sub(1)), grad(c + 1));
    let shift = if gl.is_finite() && gr.is_finite() {
        let den = gl - 2.0 * g + gr;
        if den < 0.0 {
            (0.5 * (gl - gr) / den).clamp(-0.5, 0.5)
        } else {
            0.0
        }
    } else {
        0.0
    };
    Some(c as f64 + shift)
}

/// Fits the four borders of one line.
fn fit_line(
    v: &[f32],
    first_cross: i64,
    predicted: &[f64; 4],
    search: &[f64; 4],
    params: &StillParams,
) -> [Option<BorderFit>; 4] {
    let off = first_cross as f64;
    let hw = params.border.fit_half_window_px;
    let mut out = [None; 4];
    for i in 0..4 {
        let p = predicted[i] - off;
        if !p.is_finite() {
            continue;
        }
        let sign = step_sign(i, params.walls);
        let Some(seed) = seed_at(v, p - search[i], p + search[i], sign) else {
            continue;
        };
        // Never read past halfway to the neighbouring predicted borders (moved with the seed).
        let shift = seed - p;
        let neighbour =
            |j: Option<usize>| j.and_then(|j| predicted.get(j)).map(|q| q - off + shift);
        let prev = neighbour(i.checked_sub(1)).filter(|q| q.is_finite());
        let next = neighbour(Some(i + 1)).filter(|q| q.is_finite());
        let lo = prev.map_or(seed - hw, |q| (0.5 * (q + seed)).max(seed - hw));
        let hi = next.map_or(seed + hw, |q| (0.5 * (q + seed)).min(seed + hw));
        let points: Vec<ProfilePoint> = (lo.ceil().max(0.0) as usize
            ..=(hi.floor().max(0.0) as usize).min(v.len().saturating_sub(1)))
            .filter_map(|c| {
                let value = f64::from(*v.get(c)?);
                value.is_finite().then_some(ProfilePoint {
                    x_px: c as f64,
                    value,
                    weight: 1.0,
                })
            })
            .collect();
        let Some(b) = fit_border(
            &points,
            BorderSeed {
                position_px: seed,
                width_px: 1.0,
            },
            &params.border,
        ) else {
            continue;
        };
        if b.contrast() * sign <= 0.0 {
            continue;
        }
        out[i] = Some(BorderFit {
            position_px: b.position_px + off,
            std_error_px: b.std_error_px,
            contrast: b.contrast(),
            width_px: b.width_px,
            residual_rms: b.residual_rms,
        });
    }
    out
}

/// Fits every border of the ribbon's groove on every line.
#[must_use]
pub fn track_borders(ribbon: &Ribbon, params: &StillParams) -> BorderTracks {
    let mut fits = vec![[None; 4]; ribbon.lines];
    fits.par_chunks_mut(LINE_CHUNK)
        .enumerate()
        .for_each(|(chunk, out)| {
            for (k, o) in out.iter_mut().enumerate() {
                let n = chunk * LINE_CHUNK + k;
                *o = fit_line(
                    ribbon.line(n),
                    ribbon.first_cross[n],
                    &ribbon.predicted[n],
                    &ribbon.search_px,
                    params,
                );
            }
        });
    BorderTracks {
        lines: ribbon.lines,
        fits,
        predicted: ribbon.predicted.clone(),
    }
}
