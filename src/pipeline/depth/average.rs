//! Depth without the Kalman filter: the per-frame depths −f·U/u moved into the last frame's grid and averaged.

use super::*;

/// Averages the per-frame depths Z = −f·U/u, each moved into the last frame's grid; returns
/// ι̃ = Z_ref/Z̄ and Var ι̃ of the mean.
pub(super) fn average(
    flows: &[FlowField],
    width: usize,
    height: usize,
    geom: &Geometry,
    params: &DepthParams,
    warnings: &mut Vec<String>,
) -> (Vec<f32>, Vec<f32>) {
    let fu = geom.focal_px * geom.frame_step_um;
    let z_ref = geom.working_distance_um;
    let last = flows.last().map_or(0, |f| f.frame_index);
    let mut sum = vec![0.0_f64; width * height];
    let mut var_sum = vec![0.0_f64; width * height];
    let mut count = vec![0_u32; width * height];
    let noise = f64::from(params.measurement_noise_px2);
    let mut prev_index = None;
    for (k, flow) in flows.iter().enumerate() {
        let mut meas = Measurements::default();
        meas.fill(flow, -fu / z_ref, params.min_confidence);
        note_frame(k, flow, &meas, prev_index, warnings);
        prev_index = Some(flow.frame_index);
        if meas.valid == 0 {
            continue;
        }
        let steps = last.saturating_sub(flow.frame_index) as f64;
        // Per-pixel depth and its variance in this frame's grid (NaN where unusable).
        let depth_at = |i: usize| -> Option<(f64, f64)> {
            let wv = f64::from(*meas.w.get(i)?);
            let u = f64::from(*flow.u.data.get(i)?);
            (wv > 0.0 && u < 0.0).then(|| {
                let z = -fu / u;
                (z, (z / u).powi(2) * noise / wv)
            })
        };
        sum.par_chunks_mut(width)
            .zip(var_sum.par_chunks_mut(width))
            .zip(count.par_chunks_mut(width))
            .enumerate()
            .for_each(|(y, ((s, vs), c))| {
                for x in 0..width {
                    let base = y * width;
                    let Some((z_here, _)) = depth_at(base + x) else {
                        continue;
                    };
                    let xs = x as f64 + steps * fu / z_here;
                    let i0 = xs.floor();
                    if !(i0 >= 0.0 && i0 < width as f64) {
                        continue;
                    }
                    let (i, t) = (i0 as usize, xs - i0);
                    let Some((za, va)) = depth_at(base + i) else {
                        continue;
                    };
                    let (z, v) = if t > 0.0 {
                        let Some((zb, vb)) = depth_at(base + i + 1).filter(|_| i + 1 < width)
                        else {
                            continue;
                        };
                        (za * (1.0 - t) + zb * t, va * (1.0 - t) + vb * t)
                    } else {
                        (za, va)
                    };
                    if let (Some(so), Some(vo), Some(co)) =
                        (s.get_mut(x), vs.get_mut(x), c.get_mut(x))
                    {
                        *so += z;
                        *vo += v;
                        *co += 1;
                    }
                }
            });
    }
    let mut iota = vec![f32::NAN; width * height];
    let mut var = vec![f32::NAN; width * height];
    for (((o, ov), (&s, &vs)), &c) in iota
        .iter_mut()
        .zip(var.iter_mut())
        .zip(sum.iter().zip(&var_sum))
        .zip(&count)
    {
        if c > 0 {
            let n = f64::from(c);
            let z = s / n;
            let io = z_ref / z;
            *o = io as f32;
            // Var ι̃ = Var Z · (Z_ref/Z²)².
            *ov = (vs / (n * n) * (io / z).powi(2)) as f32;
        }
    }
    (iota, var)
}
