//! The Hough transform of the in-focus pixels: the accumulator, peaks and their windows, and the votes.

use super::*;

/// The Hough vote array: `votes[t * rho_bins + r]` for θ bin t and ρ bin r.
///
/// θ bin t is centred on `thetas_rad[t]`; ρ bin r is centred on `rho_min_px + r·rho_step_px` and
/// covers half a step either side. A pixel (x, y) votes in θ bin t for the ρ bin holding
/// ρ = −(x − x_origin_px)·sin θ + y·cos θ (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct Accumulator {
    /// θ of each bin (radians): the line angle from the x axis.
    pub thetas_rad: Vec<f32>,
    /// ρ of bin 0 (px).
    pub rho_min_px: f32,
    /// ρ bin width (px).
    pub rho_step_px: f32,
    /// Number of ρ bins.
    pub rho_bins: usize,
    /// Votes.
    pub votes: Vec<u32>,
    /// Column the ρ origin sits on, (width − 1)/2 (px).
    pub x_origin_px: f32,
    /// Every `vote_stride`-th in-focus pixel voted (1 = all).
    pub vote_stride: usize,
}

impl Accumulator {
    /// Number of θ bins.
    #[must_use]
    pub fn theta_bins(&self) -> usize {
        self.thetas_rad.len()
    }

    /// Votes at θ bin `t`, ρ bin `r` (0 outside).
    #[must_use]
    pub fn get(&self, t: usize, r: usize) -> u32 {
        if r >= self.rho_bins {
            return 0;
        }
        self.votes.get(t * self.rho_bins + r).copied().unwrap_or(0)
    }

    /// Centre of ρ bin `r` (px).
    #[must_use]
    pub fn rho_of_bin(&self, r: usize) -> f32 {
        self.rho_min_px + r as f32 * self.rho_step_px
    }

    /// Fractional θ bin of an angle (bin centres are integers).
    #[must_use]
    pub fn theta_bin_f(&self, theta_rad: f32) -> f32 {
        let (Some(first), Some(second)) = (self.thetas_rad.first(), self.thetas_rad.get(1)) else {
            return 0.0;
        };
        (theta_rad - first) / (second - first)
    }

    /// Fractional ρ bin of an offset (bin centres are integers).
    #[must_use]
    pub fn rho_bin_f(&self, rho_px: f32) -> f32 {
        (rho_px - self.rho_min_px) / self.rho_step_px
    }
}

/// One accumulator peak and its window: the line −(x − x₀)·sin θ + y·cos θ = ρ with x₀ = `x_origin_px`.
///
/// The window is θ ∈ [θ − window_theta_rad, θ + window_theta_rad] × ρ ∈ [ρ − window_rho_px, ρ + window_rho_px].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Peak {
    /// Line angle from the x axis (radians); the centre of the winning θ bin.
    pub theta_rad: f32,
    /// Line offset (px): about the row at the centre column. Refined below the bin width by the
    /// vote-weighted centroid of the bins at the peak's θ holding at least half its votes.
    pub rho_px: f32,
    /// Votes at the peak.
    pub votes: u32,
    /// Column of the ρ origin (px).
    pub x_origin_px: f32,
    /// Half-width of the window in θ (radians).
    pub window_theta_rad: f32,
    /// Half-width of the window in ρ (px).
    pub window_rho_px: f32,
}

impl Peak {
    /// Row of the peak line at column `x` (px).
    #[must_use]
    pub fn row_at_px(&self, x: f32) -> f32 {
        let (s, c) = self.theta_rad.sin_cos();
        (self.rho_px + (x - self.x_origin_px) * s) / c
    }

    /// True when the (θ, ρ) curve of pixel (x, y) passes through this peak's window, i.e. some θ
    /// in the window gives a ρ in the window.
    #[must_use]
    pub fn window_contains_curve_of(&self, x: f32, y: f32) -> bool {
        WindowTest::new(self).contains(f64::from(x - self.x_origin_px), f64::from(y))
    }
}

/// A peak's window with its θ ends' sines and cosines precomputed, for the per-pixel test.
#[derive(Clone, Copy, Debug)]
pub(super) struct WindowTest {
    /// sin, cos of θ − wθ.
    pub(super) sa: f64,
    pub(super) ca: f64,
    /// sin, cos of θ + wθ.
    pub(super) sb: f64,
    pub(super) cb: f64,
    pub(super) rho_lo: f64,
    pub(super) rho_hi: f64,
}

impl WindowTest {
    pub(super) fn new(p: &Peak) -> Self {
        let (sa, ca) = f64::from(p.theta_rad - p.window_theta_rad).sin_cos();
        let (sb, cb) = f64::from(p.theta_rad + p.window_theta_rad).sin_cos();
        let rho = f64::from(p.rho_px);
        let w = f64::from(p.window_rho_px);
        Self {
            sa,
            ca,
            sb,
            cb,
            rho_lo: rho - w,
            rho_hi: rho + w,
        }
    }

    /// Range of ρ(θ) = −xc·sin θ + y·cos θ over the window's θ interval (shorter than π).
    ///
    /// ρ(θ) = r·cos(θ − θ*) has its maximum r where dρ/dθ = −xc·cos θ − y·sin θ turns from
    /// positive to negative and its minimum −r where it turns the other way; an interval shorter
    /// than π holds at most one of them, found from the derivative's signs at the two ends.
    pub(super) fn rho_range(&self, xc: f64, y: f64) -> (f64, f64) {
        let ra = -xc * self.sa + y * self.ca;
        let rb = -xc * self.sb + y * self.cb;
        let da = -xc * self.ca - y * self.sa;
        let db = -xc * self.cb - y * self.sb;
        let mut lo = ra.min(rb);
        let mut hi = ra.max(rb);
        if da > 0.0 && db < 0.0 {
            hi = xc.hypot(y);
        } else if da < 0.0 && db > 0.0 {
            lo = -xc.hypot(y);
        }
        (lo, hi)
    }

    /// True when the curve of the pixel at centred column `xc`, row `y` meets the window.
    pub(super) fn contains(&self, xc: f64, y: f64) -> bool {
        let (lo, hi) = self.rho_range(xc, y);
        hi >= self.rho_lo && lo <= self.rho_hi
    }
}
/// An in-focus pixel: centred column x − x₀, row y, and its row-major index.
#[derive(Clone, Copy, Debug)]
pub(super) struct FocusPoint {
    pub(super) xc: f32,
    pub(super) y: f32,
    pub(super) index: u32,
}

/// The in-focus map, its points, the Hough accumulator and its peaks of one derivative set.
pub(super) struct Votes {
    pub(super) in_focus: Image,
    pub(super) points: Vec<FocusPoint>,
    pub(super) accumulator: Accumulator,
    pub(super) min_votes: u32,
    pub(super) peaks: Vec<Peak>,
}

/// Checks the inputs, finds the in-focus pixels, votes and finds the peaks (the first half of
/// [`segment_stripes`]).
pub(super) fn votes_and_peaks(
    derivs: &Derivatives,
    flow: &FlowField,
    params: &HoughParams,
) -> Result<Votes, StageError> {
    params.validate()?;
    let (w, h) = (derivs.ix.width, derivs.ix.height);
    if w == 0 || h == 0 {
        return Err(bad_input("empty image".into()));
    }
    if !derivs.ix.same_size(&derivs.iy) || !derivs.ix.same_size(&flow.confidence) {
        return Err(bad_input(format!(
            "sizes differ: Ix {}×{}, Iy {}×{}, flow confidence {}×{}",
            w, h, derivs.iy.width, derivs.iy.height, flow.confidence.width, flow.confidence.height
        )));
    }
    if w > usize::from(u16::MAX) || h > usize::from(u16::MAX) {
        return Err(bad_input(format!("image {w}×{h} is too large")));
    }
    let cells = accumulator_cells(params, h);
    if cells > MAX_ACCUMULATOR_CELLS {
        return Err(StageError::invalid(
            "hough.theta_step_deg",
            format!(
                "the accumulator would have {cells} cells (at most {MAX_ACCUMULATOR_CELLS}); use coarser θ or ρ steps"
            ),
        ));
    }
    let (in_focus, points) = in_focus_points(&derivs.ix, &derivs.iy, &flow.confidence, params);
    let stride = vote_stride(points.len(), params.max_vote_points);
    let accumulator = vote(&points, stride, w, h, params);
    let min_votes = min_peak_votes(w, stride, params);
    let peaks = find_peaks(&accumulator, params, min_votes);
    Ok(Votes {
        in_focus,
        points,
        accumulator,
        min_votes,
        peaks,
    })
}
/// Builds the in-focus map and the list of in-focus pixels (row-major order).
pub(super) fn in_focus_points(
    ix: &Image,
    iy: &Image,
    confidence: &Image,
    params: &HoughParams,
) -> (Image, Vec<FocusPoint>) {
    let (w, h) = (ix.width, ix.height);
    let x0 = (w as f32 - 1.0) * 0.5;
    let thr2 = params.gradient_threshold * params.gradient_threshold;
    let mut map = Image::zeros(w, h);
    let rows: Vec<Vec<FocusPoint>> = map
        .data
        .par_chunks_mut(w)
        .enumerate()
        .map(|(y, out)| {
            let mut pts = Vec::new();
            let gx = ix.row(y);
            let gy = iy.row(y);
            let cf = confidence.row(y);
            for (x, (((o, &a), &b), &c)) in out.iter_mut().zip(gx).zip(gy).zip(cf).enumerate() {
                if a * a + b * b > thr2 && c > 0.0 {
                    *o = 1.0;
                    pts.push(FocusPoint {
                        xc: x as f32 - x0,
                        y: y as f32,
                        index: (y * w + x) as u32,
                    });
                }
            }
            pts
        })
        .collect();
    let points = rows.into_iter().flatten().collect();
    (map, points)
}

pub(super) fn vote_stride(n_points: usize, max_points: usize) -> usize {
    if max_points == 0 || n_points <= max_points {
        1
    } else {
        n_points.div_ceil(max_points)
    }
}

pub(super) fn min_peak_votes(width: usize, stride: usize, p: &HoughParams) -> u32 {
    let v = (p.min_votes_per_column * width as f32 / stride as f32).ceil();
    (v as u32).max(1)
}

/// Votes the points (every `stride`-th) into a fresh accumulator, one θ row per rayon task.
pub(super) fn vote(
    points: &[FocusPoint],
    stride: usize,
    width: usize,
    height: usize,
    p: &HoughParams,
) -> Accumulator {
    let nt = theta_count(p);
    let nr = rho_count(height, p);
    let thetas_rad: Vec<f32> = (0..nt)
        .map(|t| (p.theta_min_deg + t as f32 * p.theta_step_deg).to_radians())
        .collect();
    let rho_min_px = 0.0_f32;
    let inv_step = 1.0 / p.rho_step_px;
    let mut votes = vec![0u32; nt * nr];
    let positions: Vec<[f32; 2]> = points
        .iter()
        .step_by(stride)
        .map(|pt| [pt.xc, pt.y])
        .collect();
    votes
        .par_chunks_mut(nr)
        .zip(thetas_rad.par_iter())
        .for_each(|(row, &theta)| {
            let (s, c) = theta.sin_cos();
            // ρ bin = round((ρ − ρ_min)/step) = floor(a·xc + b·y + off), with the rounding 0.5
            // and a further +1 folded into `off` so that truncation toward zero acts as floor for
            // every bin ≥ −1; the 1 is taken off after the cast and negative bins wrap to huge
            // u32 values that fall outside the row.
            let a = -s * inv_step;
            let b = c * inv_step;
            let off = -rho_min_px * inv_step + 0.5 + 1.0;
            let bin = |p: &[f32; 2]| ((p[0] * a + p[1] * b + off) as i32).wrapping_sub(1) as u32;
            let mut chunks = positions.chunks_exact(VOTE_BATCH);
            for batch in &mut chunks {
                // Bins first (vectorises), then the scattered increments.
                let mut ks = [0u32; VOTE_BATCH];
                for (k, p) in ks.iter_mut().zip(batch) {
                    *k = bin(p);
                }
                for &k in &ks {
                    if let Some(v) = row.get_mut(k as usize) {
                        *v += 1;
                    }
                }
            }
            for p in chunks.remainder() {
                if let Some(v) = row.get_mut(bin(p) as usize) {
                    *v += 1;
                }
            }
        });
    Accumulator {
        thetas_rad,
        rho_min_px,
        rho_step_px: p.rho_step_px,
        rho_bins: nr,
        votes,
        x_origin_px: (width as f32 - 1.0) * 0.5,
        vote_stride: stride,
    }
}
