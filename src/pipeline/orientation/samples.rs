//! One fit per sample column and wall: the gathered points, gaps, the wall-slope check and the assembled orientation.

use super::*;

/// A sample with no fit (a gap).
pub(super) fn gap(x_px: f32) -> OrientationSample {
    OrientationSample {
        x_px,
        tan_theta: f64::NAN,
        fit: None,
    }
}

/// Columns `x` with |x − x_s| ≤ n/2 inside `0..width` (empty for a non-finite centre).
pub(super) fn window_columns(x_s: f32, n: usize, width: usize) -> std::ops::Range<usize> {
    let half = n as f64 / 2.0;
    let x_s = f64::from(x_s);
    if !x_s.is_finite() || width == 0 {
        return 0..0;
    }
    let lo = (x_s - half).ceil().max(0.0);
    let hi = (x_s + half).floor().min(width as f64 - 1.0);
    if hi < lo {
        return 0..0;
    }
    // Both bounds lie in [0, width − 1] here.
    lo as usize..hi as usize + 1
}

/// One fit's result with the pixels it used (row-major indices) and their final weights.
pub(super) struct SampleResult {
    pub(super) wall: usize,
    pub(super) sample: OrientationSample,
    pub(super) pixels: Vec<u32>,
    pub(super) weights: Vec<f32>,
}

/// Per-thread buffers of the sample fits.
#[derive(Default)]
pub(super) struct Workspace {
    pub(super) set: PointSet,
    pub(super) scratch: FitScratch,
    pub(super) pixels: Vec<u32>,
}

impl Workspace {
    /// Fits the gathered points; a gap when there are too few or they are degenerate.
    pub(super) fn fit_gathered(
        &mut self,
        wall: usize,
        x_px: f32,
        min_points: usize,
        params: &OrientationParams,
    ) -> SampleResult {
        let empty = |sample| SampleResult {
            wall,
            sample,
            pixels: Vec::new(),
            weights: Vec::new(),
        };
        if self.set.len() < min_points {
            return empty(gap(x_px));
        }
        self.set.centre();
        let Ok(fit) = fit_set(&self.set, params, &mut self.scratch) else {
            return empty(gap(x_px));
        };
        SampleResult {
            wall,
            sample: OrientationSample {
                x_px,
                tan_theta: tan_theta(&fit),
                fit: Some(fit),
            },
            pixels: self.pixels.clone(),
            weights: self
                .scratch
                .final_weights()
                .iter()
                .map(|&w| w as f32)
                .collect(),
        }
    }
}

/// The orientation of the walls `sides`: [`fit_samples`] with `gather`, then [`assemble`] on a
/// `width` × `height` weight map.
pub(super) fn fit_walls(
    sides: &[WallSide],
    sample_columns: &[f32],
    width: usize,
    height: usize,
    params: &OrientationParams,
    gather: impl Fn(&mut Workspace, usize, f32) -> usize + Sync,
) -> Orientation {
    let results = fit_samples(sides.len(), sample_columns, params, gather);
    assemble(sides, sample_columns.len(), results, width, height, params)
}

/// One fit per (wall, sample column), in parallel, in wall-then-column order: `gather(ws,
/// wall, x_s)` fills the workspace's points and pixels for the sample at column `x_s` and
/// returns the fewest points its fit needs (`usize::MAX`: a gap).
fn fit_samples(
    walls: usize,
    sample_columns: &[f32],
    params: &OrientationParams,
    gather: impl Fn(&mut Workspace, usize, f32) -> usize + Sync,
) -> Vec<SampleResult> {
    let jobs: Vec<(usize, usize)> = (0..walls)
        .flat_map(|w| (0..sample_columns.len()).map(move |s| (w, s)))
        .collect();
    jobs.par_iter()
        .map_init(Workspace::default, |ws, &(wi, si)| {
            let x_s = sample_columns.get(si).copied().unwrap_or(f32::NAN);
            ws.set.clear();
            ws.pixels.clear();
            let min_points = gather(ws, wi, x_s);
            ws.fit_gathered(wi, x_s, min_points, params)
        })
        .collect()
}

/// Median |b| (cross-groove wall slope) of the fits in `samples`; None with fewer than 3 fits.
#[must_use]
pub fn median_wall_slope(samples: &[OrientationSample]) -> Option<f64> {
    let slopes: Vec<f64> = samples
        .iter()
        .filter_map(|s| s.fit.as_ref().map(|f| f.b.abs()))
        .filter(|b| b.is_finite())
        .collect();
    if slopes.len() < 3 {
        return None;
    }
    crate::pipeline::median(slopes)
}

/// Turns the fits of `samples` whose |b| strays from `reference` by more than
/// `max_change`·reference into gaps; returns how many it rejected. The stage uses the group's
/// own median as the reference; the engine also applies the median of the groups before, which
/// catches a group whose fits are mostly wrong (a long flaked chunk).
pub fn reject_slopes_against(
    samples: &mut [OrientationSample],
    reference: f64,
    max_change: f64,
) -> usize {
    if max_change <= 0.0 || !(reference.is_finite() && reference > 0.0) {
        return 0;
    }
    let mut rejected = 0;
    for s in samples.iter_mut() {
        let Some(b) = s.fit.as_ref().map(|f| f.b.abs()) else {
            continue;
        };
        if !b.is_finite() || (b - reference).abs() > max_change * reference {
            *s = gap(s.x_px);
            rejected += 1;
        }
    }
    rejected
}

/// [`reject_slopes_against`] the median of `samples` themselves.
pub(super) fn reject_implausible_slopes(
    samples: &mut [OrientationSample],
    max_change: f64,
) -> usize {
    median_wall_slope(samples).map_or(0, |m| reject_slopes_against(samples, m, max_change))
}

/// A converged fit with slopes `a`, `b` (tests of the slope checks here and in the engine).
#[cfg(test)]
pub(crate) fn test_fit(a: f64, b: f64) -> PlaneFit {
    PlaneFit {
        a,
        b,
        c: 0.0,
        iterations: 1,
        outlier_fraction: 0.0,
        residual_um: 0.0,
        stop: StopReason::Converged,
    }
}

/// Assembles the per-wall sample lists, the weight map and the mean outlier share; rejects
/// fits with implausible wall slopes ([`OrientationParams::max_wall_slope_change`]).
fn assemble(
    sides: &[WallSide],
    n_samples: usize,
    results: Vec<SampleResult>,
    width: usize,
    height: usize,
    params: &OrientationParams,
) -> Orientation {
    let mut weight_map = Image::filled(width, height, f32::NAN);
    let mut walls: Vec<WallOrientation> = sides
        .iter()
        .map(|&side| WallOrientation {
            side,
            samples: Vec::with_capacity(n_samples),
        })
        .collect();
    let (mut outlier_sum, mut fits) = (0.0, 0_usize);
    for r in results {
        for (&p, &w) in r.pixels.iter().zip(&r.weights) {
            if let Some(m) = weight_map.data.get_mut(p as usize) {
                *m = if m.is_nan() { w } else { m.max(w) };
            }
        }
        if let Some(fit) = r.sample.fit {
            outlier_sum += fit.outlier_fraction;
            fits += 1;
        }
        if let Some(w) = walls.get_mut(r.wall) {
            w.samples.push(r.sample);
        }
    }
    let rejected_fits = walls
        .iter_mut()
        .map(|w| reject_implausible_slopes(&mut w.samples, params.max_wall_slope_change))
        .sum();
    Orientation {
        rejected_fits,
        walls,
        weight_map,
        outlier_fraction: if fits > 0 {
            outlier_sum / fits as f64
        } else {
            f64::NAN
        },
    }
}
/// Checks that every line has one row and one half-width per column.
pub(super) fn check_lines(lines: &[WallLine], width: usize) -> Result<(), StageError> {
    for (i, line) in lines.iter().enumerate() {
        if line.rows.len() != width || line.half_width_px.len() != width {
            return Err(StageError::BadInput {
                stage: STAGE,
                problem: format!(
                    "wall line {i} has {} rows and {} half-widths for {width} columns",
                    line.rows.len(),
                    line.half_width_px.len()
                ),
            });
        }
    }
    Ok(())
}

/// Number of distinct values among `depths` (µm).
pub(super) fn distinct_depths(mut depths: Vec<f64>) -> usize {
    depths.sort_by(f64::total_cmp);
    depths.dedup_by(|a, b| (*a - *b).abs() < DISTINCT_DEPTH_UM);
    depths.len()
}
