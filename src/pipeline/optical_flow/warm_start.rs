//! The warm start of a group's later flow windows: each starts from the previous window's flow moved with the content, and groove Horn–Schunck reuses the first window's wall sides.

use rayon::prelude::*;

use super::{
    FlowField, FlowMethod, FlowParams, WallSideMap, compute_flow, compute_flow_from,
    estimate_wall_sides,
};
use crate::image::{Image, zeros_par};
use crate::pipeline::StageError;
use crate::pipeline::derivatives::Derivatives;

/// Flow of every derivative window of a group (the depth path), using the group's temporal coherence:
/// the first window runs the full solve (for groove Horn–Schunck: plain solve, wall sides
/// estimated from it, groove solve); each later window starts from the previous result moved
/// with the content (the land flow toward −x) and, for groove Horn–Schunck, reuses the first
/// window's wall sides moved the same way, so it skips the plain pre-solve. Each window still
/// iterates to the same tolerance and cap; only the starting point changes.
///
/// # Errors
/// The first window's [`StageError`].
pub fn flows_of_group(
    derivs: &[Derivatives],
    focal_px: f64,
    land_flow_px: f64,
    params: &FlowParams,
) -> Result<Vec<FlowField>, StageError> {
    let Some((first, rest)) = derivs.split_first() else {
        return Ok(Vec::new());
    };
    let flow0 = compute_flow(first, focal_px, None, params)?;
    let walls0 = match params.method {
        FlowMethod::GrooveHornSchunck => Some(estimate_wall_sides(&flow0, focal_px)?),
        _ => None,
    };
    let mut flows = Vec::with_capacity(derivs.len());
    flows.push(flow0);
    for d in rest {
        let Some(prev) = flows.last() else {
            break;
        };
        let step = d.frame_index.saturating_sub(prev.frame_index) as f64 * land_flow_px.abs();
        let init = shift_flow(prev, step);
        let from_first = d.frame_index.saturating_sub(first.frame_index) as f64;
        let walls = walls0
            .as_ref()
            .map(|w| shift_walls(w, from_first * land_flow_px.abs()));
        flows.push(compute_flow_from(
            d,
            focal_px,
            walls.as_ref(),
            Some(&init),
            params,
        )?);
    }
    Ok(flows)
}

/// A flow field whose content moved by `shift_px` toward −x: column x takes the (linearly
/// interpolated) value at x + shift; beyond the right edge the last column repeats.
fn shift_flow(flow: &FlowField, shift_px: f64) -> FlowField {
    let s = if shift_px.is_finite() { shift_px } else { 0.0 };
    // Column x reads x + s = x + whole + t: the same fraction t for every column.
    let whole = s.floor();
    let t = (s - whole) as f32;
    let shift = |im: &Image| {
        let w = im.width.max(1);
        let mut out = zeros_par(im.data.len());
        out.par_chunks_mut(w)
            .zip(im.data.par_chunks(w))
            .for_each(|(dst, row)| {
                let last = row.len().saturating_sub(1);
                let (Some(&first), Some(&end)) = (row.first(), row.last()) else {
                    return;
                };
                // Column x reads i = x + whole: before the row, the first value; from the last
                // column on, the last; in between, a + (b − a)·t of columns i and i + 1.
                let n = dst.len().min(row.len());
                let (lo, hi) = if whole >= 0.0 {
                    let k = (whole as usize).min(n);
                    (0, last.saturating_sub(k).min(n))
                } else {
                    let k = ((-whole) as usize).min(n);
                    (k, n)
                };
                let k0 = (lo as f64 + whole) as usize;
                let (head, rest) = dst.split_at_mut(lo);
                let (mid, tail) = rest.split_at_mut(hi.max(lo) - lo);
                head.fill(first);
                tail.fill(end);
                if let (Some(a), Some(b)) = (
                    row.get(k0..k0 + mid.len()),
                    row.get(k0 + 1..k0 + 1 + mid.len()),
                ) {
                    for ((d, &a), &b) in mid.iter_mut().zip(a).zip(b) {
                        *d = a + (b - a) * t;
                    }
                }
            });
        Image {
            width: im.width,
            height: im.height,
            data: out,
        }
    };
    FlowField {
        u: shift(&flow.u),
        v: shift(&flow.v),
        confidence: Image::zeros(0, 0),
        iterations: 0,
        converged: false,
        frame_index: flow.frame_index,
    }
}

/// The wall-side map of content that moved by `shift_px` toward −x: column x takes the side
/// found at x + shift (rounded; beyond the right edge the last column repeats).
fn shift_walls(walls: &WallSideMap, shift_px: f64) -> WallSideMap {
    let w = walls.width;
    let s = if shift_px.is_finite() {
        shift_px.round().max(0.0) as usize
    } else {
        0
    };
    let mut sign = Vec::with_capacity(walls.sign.len());
    for row in walls.sign.chunks(w.max(1)) {
        sign.extend((0..w).map(|x| {
            row.get((x + s).min(w.saturating_sub(1)))
                .copied()
                .unwrap_or(0)
        }));
    }
    WallSideMap {
        width: w,
        height: walls.height,
        sign,
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests fail loudly on purpose
mod tests {
    use super::*;
    use crate::pipeline::PipelineParams;
    use crate::pipeline::derivatives::compute_derivatives;

    #[test]
    fn shifted_flow_and_walls_follow_the_content() {
        let u = Image::from_fn(6, 2, |x, y| x as f32 + 10.0 * y as f32);
        let f = FlowField {
            u: u.clone(),
            v: u,
            confidence: Image::zeros(6, 2),
            iterations: 0,
            converged: true,
            frame_index: 3,
        };
        let s = shift_flow(&f, 1.5);
        assert_eq!(s.u.data[..6], [1.5, 2.5, 3.5, 4.5, 5.0, 5.0]);
        assert_eq!(s.v.data[6..], [11.5, 12.5, 13.5, 14.5, 15.0, 15.0]);
        let walls = WallSideMap {
            width: 4,
            height: 1,
            sign: vec![0, 1, -1, 0],
        };
        assert_eq!(shift_walls(&walls, 1.2).sign, [1, -1, 0, 0]);
    }

    #[test]
    fn warm_started_windows_match_cold_ones() {
        // A textured pattern translating by 1.3 px/frame, 12 frames: every window's flow from
        // the depth-path loop (warm starts, shared walls) against each window solved from zero.
        let fr: Vec<Image> = (0..12)
            .map(|k| {
                Image::from_fn(64, 48, |x, y| {
                    let t = x as f32 + 1.3 * k as f32;
                    (0.37 * t).sin() * (0.23 * y as f32 + 0.1 * t).cos() + 0.3 * (0.11 * t).cos()
                })
            })
            .collect();
        let mut params = PipelineParams::default();
        params.flow.method = FlowMethod::HornSchunck;
        params.flow.max_iterations = 400;
        // Converged solves: the same fixed point from either start.
        params.flow.tolerance_px = 1e-5;
        let d = compute_derivatives(&fr, -1.0, &params.derivatives).unwrap();
        let warm = flows_of_group(&d, 10_000.0, -1.0, &params.flow).unwrap();
        assert_eq!(warm.len(), d.len());
        let diffs: Vec<f64> = warm
            .iter()
            .zip(&d)
            .map(|(w, di)| {
                assert_eq!(w.frame_index, di.frame_index);
                let cold = compute_flow(di, 10_000.0, None, &params.flow).unwrap();
                w.u.data
                    .iter()
                    .zip(&cold.u.data)
                    .map(|(a, b)| f64::from((a - b).abs()))
                    .sum::<f64>()
                    / cold.u.data.len() as f64
            })
            .collect();
        assert!(
            diffs.iter().all(|&x| x < 1e-4),
            "mean |Δu| per window {diffs:?}"
        );
    }
}
