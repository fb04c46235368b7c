//! A plain reference of the Simoncelli derivatives, written straight from the module docs: f64, every output pixel a direct sum over its 5×5×5 neighbourhood of pre-warped, pre-blurred frames; the fast separable bands are tested against it.

use super::*;

/// The published taps scaled to unit sum (p5) or to a unit response on a unit ramp (d5), in f64.
fn taps() -> ([f64; 5], [f64; 5]) {
    let p = SIMONCELLI_P5.map(f64::from);
    let d = SIMONCELLI_D5.map(f64::from);
    let sum: f64 = p.iter().sum();
    let moment: f64 = d
        .iter()
        .enumerate()
        .map(|(j, t)| t * (j as f64 - 2.0))
        .sum();
    (p.map(|t| t / sum), d.map(|t| t / moment))
}

/// Row `y` of `frame` at column `x + shift` (clamped borders): the sample itself for a whole
/// shift, else the Catmull–Rom cubic (Keys, a = −1/2) through the four nearest samples.
fn shifted(frame: &Image, x: usize, y: usize, shift: f64) -> f64 {
    let last = frame.width as isize - 1;
    let at = |i: isize| f64::from(frame.data[y * frame.width + i.clamp(0, last) as usize]);
    let pos = x as f64 + shift;
    let base = pos.floor();
    let f = pos - base;
    let b = base as isize;
    if f == 0.0 {
        return at(b);
    }
    let (f2, f3) = (f * f, f * f * f);
    0.5 * (-f3 + 2.0 * f2 - f) * at(b - 1)
        + 0.5 * (3.0 * f3 - 5.0 * f2 + 2.0) * at(b)
        + 0.5 * (-3.0 * f3 + 4.0 * f2 + f) * at(b + 1)
        + 0.5 * (f3 - f2) * at(b + 2)
}

/// `[ix, iy, it, image]` of the 7-frame `window` (row-major), as [`compute_derivatives`]
/// gives them with the Simoncelli mode: frame k pre-warped by (k − 3)·`base_flow_px`, the
/// pre-blur [1/4, 1/2, 1/4] taking the 7 frames to 5, then `Ix = Σ d5(x)·p5(y)·p5(t)·J`,
/// `Iy = Σ p5(x)·d5(y)·p5(t)·J`, `It = Σ p5(x)·p5(y)·d5(t)·J`, `image = Σ p5·p5·p5·J` as
/// correlations with clamped borders. The rows within 2 of the top and bottom, and the
/// columns within 2 plus the largest pre-warp reach of the sides, carry no data: their ix, iy
/// and it are 0.
pub(super) fn simoncelli(window: &[Image], base_flow_px: f64) -> [Vec<f64>; 4] {
    let (w, h) = (window[0].width, window[0].height);
    let (p5, d5) = taps();
    let shifts: Vec<f64> = (0..SIMONCELLI_WINDOW_FRAMES)
        .map(|k| (k as f64 - 3.0) * base_flow_px)
        .collect();
    // The pre-blurred, pre-warped frame t (0..5) at (x, y).
    let blurred = |t: usize, x: usize, y: usize| {
        (0..3)
            .map(|i| {
                let b = [0.25, 0.5, 0.25][i];
                b * shifted(&window[t + i], x, y, shifts[t + i])
            })
            .sum::<f64>()
    };
    let reach = shifts
        .iter()
        .filter(|s| **s != 0.0)
        .map(|&s| {
            let whole = s.floor();
            if s == whole {
                whole.abs()
            } else {
                (whole - 1.0).abs().max((whole + 2.0).abs())
            }
        })
        .fold(0.0, f64::max) as usize;
    let margin = RADIUS + reach;
    let mut out: [Vec<f64>; 4] = std::array::from_fn(|_| vec![0.0; w * h]);
    for y in 0..h {
        for x in 0..w {
            let mut sums = [0.0_f64; 4];
            for t in 0..5 {
                for j in 0..5 {
                    let yy = (y as isize + j as isize - 2).clamp(0, h as isize - 1) as usize;
                    for i in 0..5 {
                        let xx = (x as isize + i as isize - 2).clamp(0, w as isize - 1) as usize;
                        let value = blurred(t, xx, yy);
                        sums[0] += d5[i] * p5[j] * p5[t] * value;
                        sums[1] += p5[i] * d5[j] * p5[t] * value;
                        sums[2] += p5[i] * p5[j] * d5[t] * value;
                        sums[3] += p5[i] * p5[j] * p5[t] * value;
                    }
                }
            }
            let no_data = y < RADIUS || y + RADIUS >= h || x < margin || x + margin >= w;
            for (k, o) in out.iter_mut().enumerate() {
                o[y * w + x] = if no_data && k < 3 { 0.0 } else { sums[k] };
            }
        }
    }
    out
}
