//! Pre-warping: rows resampled along x by the known land motion (exact copies for whole pixels, Catmull–Rom cubic otherwise), and the border strips that carry no data.

/// A row resampler: `dst[x] = src(x + shift)` with clamped borders.
///
/// Integer shifts copy samples exactly; fractional ones use the Catmull–Rom cubic
/// (Keys, a = −1/2) through the four nearest samples.
#[derive(Clone, Copy, Debug)]
pub(super) struct RowShift {
    /// Integer part (floor) of the shift, limited so index arithmetic cannot overflow.
    pub(super) whole: isize,
    /// Cubic weights for samples `whole − 1 ..= whole + 2`; `None` for an integer shift.
    pub(super) weights: Option<[f32; 4]>,
}

impl RowShift {
    pub(super) fn new(shift_px: f64, width: usize) -> Self {
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

    pub(super) fn is_identity(&self) -> bool {
        self.whole == 0 && self.weights.is_none()
    }

    /// Resamples `src` into `dst` (same length).
    #[inline(always)]
    pub(super) fn apply(&self, src: &[f32], dst: &mut [f32]) {
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

/// Columns at each side whose spatial filter, or the pre-warped samples it reads, reach
/// outside the frame: `filter_radius` without pre-warping.
pub(super) fn prewarp_margin(shifts: &[RowShift], filter_radius: usize) -> usize {
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
pub(super) fn blank_margins(row: &mut [f32], margin: usize) {
    let w = row.len();
    let m = margin.min(w);
    row[..m].fill(0.0);
    row[w - m..].fill(0.0);
}
