//! Lucas–Kanade flow with the smallest-eigenvalue confidence.

use super::*;

/// Lucas–Kanade: per pixel, least squares over a square window of the structure tensor.
pub(super) fn lucas_kanade(d: &Derivatives, params: &FlowParams) -> FlowField {
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
