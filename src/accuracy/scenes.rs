//! The paper's Table 2 depth scenes: relative depth errors of the Kalman depth stage against the true depth map.

use super::{AccuracyError, case_err};
use crate::image::Image;
use crate::pipeline::PipelineParams;
use crate::pipeline::depth::estimate_depth;
use crate::pipeline::derivatives::compute_derivatives;
use crate::pipeline::optical_flow::{FlowMethod, compute_flow};
use crate::synth::{SceneConfig, SceneKind};

/// One row of the paper's Table 2: relative depth errors at one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DepthErrors {
    /// Frame index.
    pub frame: usize,
    /// Share (%) of pixels with relative error below 5%.
    pub below_5: f64,
    /// Share (%) with error from 5% to 15%.
    pub from_5_to_15: f64,
    /// Share (%) above 15%.
    pub above_15: f64,
    /// Mean relative error (%).
    pub mean: f64,
    /// Its standard deviation (%).
    pub sigma: f64,
    /// Pixels measured.
    pub pixels: usize,
}

/// Relative errors of `estimate` against `truth` over the pixels where `mask` holds, leaving
/// out a `border` px frame (where the filters read clamped samples) and unmeasured pixels.
#[must_use]
pub fn depth_errors(
    frame: usize,
    estimate: &Image,
    truth: &Image,
    border: usize,
    mask: impl Fn(f32) -> bool,
) -> DepthErrors {
    let (w, h) = (truth.width, truth.height);
    let mut errs = Vec::new();
    for y in border..h.saturating_sub(border) {
        for x in border..w.saturating_sub(border) {
            let (Some(z), Some(t)) = (estimate.get(x, y), truth.get(x, y)) else {
                continue;
            };
            if !(z.is_finite() && t.is_finite() && t > 0.0 && mask(t)) {
                continue;
            }
            errs.push(f64::from((z - t).abs() / t) * 100.0);
        }
    }
    let n = errs.len().max(1) as f64;
    let share = |f: &dyn Fn(f64) -> bool| errs.iter().filter(|&&e| f(e)).count() as f64 / n * 100.0;
    let mean = errs.iter().sum::<f64>() / n;
    let var = errs.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / n;
    DepthErrors {
        frame,
        below_5: share(&|e| e < 5.0),
        from_5_to_15: share(&|e| (5.0..=15.0).contains(&e)),
        above_15: share(&|e| e > 15.0),
        mean,
        sigma: var.sqrt(),
        pixels: errs.len(),
    }
}

/// One frame's Table 2 errors on a scene: on the object's pixels and on every pixel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneDepthRow {
    /// Errors on the object (pixels nearer than the background plane).
    pub object: DepthErrors,
    /// Errors on every pixel, background included.
    pub all: DepthErrors,
}

/// Table 2 on one scene: renders the frames (in memory), runs derivatives, plain Horn–Schunck
/// flow and the Kalman depth stage over the flows up to each frame of `at`, and measures the
/// relative depth error at that frame, on the object and on every pixel.
///
/// # Errors
/// A rendering or stage error, named by the scene.
pub fn scene_depth_table(
    kind: SceneKind,
    cfg: &SceneConfig,
    at: &[usize],
    params: &PipelineParams,
) -> Result<Vec<SceneDepthRow>, AccuracyError> {
    use rayon::prelude::*;
    let case = format!("{kind:?} scene");
    let last = at.iter().copied().max().unwrap_or(0);
    let cfg = SceneConfig {
        frames: (last + 4).max(cfg.frames),
        ..cfg.clone()
    };
    let geom = cfg.geometry();
    let (frames, truths): (Vec<Image>, Vec<Image>) = (0..cfg.frames)
        .into_par_iter()
        .map(|k| crate::synth::scene::render_scene_frame(kind, &cfg, k))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| case_err(&case, e))?
        .into_iter()
        .unzip();
    let derivs = compute_derivatives(&frames, geom.land_flow_px(), &params.derivatives)
        .map_err(|e| case_err(&case, e))?;
    let mut flow_params = params.flow.clone();
    if flow_params.method == FlowMethod::GrooveHornSchunck {
        // The groove constraint describes groove walls; a scene has none.
        flow_params.method = FlowMethod::HornSchunck;
    }
    // In frame order (one flow per derivative window).
    let flows = derivs
        .par_iter()
        .map(|d| compute_flow(d, geom.focal_px, None, &flow_params))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| case_err(&case, e))?;
    let plane = cfg.plane_distance_um as f32;
    let border = 8;
    let mut rows = Vec::with_capacity(at.len());
    for &k in at {
        let upto = flows.iter().take_while(|f| f.frame_index <= k).count();
        if upto == 0 || flows[upto - 1].frame_index != k {
            return Err(case_err(&case, format!("no flow field at frame {k}")));
        }
        let depth =
            estimate_depth(&flows[..upto], &geom, &params.depth).map_err(|e| case_err(&case, e))?;
        let truth = &truths[k];
        rows.push(SceneDepthRow {
            object: depth_errors(k, &depth.z_um, truth, border, |t| t < plane - 0.5),
            all: depth_errors(k, &depth.z_um, truth, border, |_| true),
        });
    }
    Ok(rows)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;

    #[test]
    fn depth_errors_bands_and_mean() {
        let truth = Image::filled(20, 20, 100.0);
        let mut est = Image::filled(20, 20, 100.0);
        // 3 of the 16 interior (border 2) pixels at 10% error, 1 at 20%, 1 NaN (skipped).
        est.data[2 * 20 + 2] = 110.0;
        est.data[2 * 20 + 3] = 90.0;
        est.data[2 * 20 + 4] = 110.0;
        est.data[3 * 20 + 2] = 120.0;
        est.data[3 * 20 + 3] = f32::NAN;
        let e = depth_errors(0, &est, &truth, 2, |_| true);
        assert_eq!(e.pixels, 16 * 16 - 1);
        let n = e.pixels as f64;
        assert!((e.from_5_to_15 - 300.0 / n).abs() < 1e-9);
        assert!((e.above_15 - 100.0 / n).abs() < 1e-9);
        assert!((e.mean - 50.0 / n).abs() < 1e-6, "{}", e.mean);
        // A mask that keeps nothing measures nothing.
        assert_eq!(depth_errors(0, &est, &truth, 2, |_| false).pixels, 0);
    }
}
