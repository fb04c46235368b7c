//! Which wall each pixel lies on (c = ±1 or 0), estimated from the parallax of a plain flow field.

use super::*;

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
pub(super) fn box_mean(im: &Image, rx: usize, ry: usize) -> Vec<f64> {
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
