//! The measurement information J, b of each pixel's window: direct sums in f32 for narrow windows, running and prefix sums in f64 for wide ones.

use super::*;

/// Vertical window sums of one column over absolute rows Y: Σw, Σw·Y, Σw·Y², Σwm, Σwm·Y.
pub(super) type ColumnSums = [f64; 5];

/// Largest neighbourhood half-side whose window sums are taken directly in f32 (O(r) work per
/// pixel); larger windows use running sums in f64.
pub(super) const DIRECT_WINDOW_MAX_R: usize = 4;

/// The five consecutive blocks of length `n` at the start of `v`.
pub(super) fn split5(v: &mut [f32], n: usize) -> [&mut [f32]; 5] {
    let (a, rest) = v.split_at_mut(n);
    let (b, rest) = rest.split_at_mut(n);
    let (c, rest) = rest.split_at_mut(n);
    let (d, rest) = rest.split_at_mut(n);
    let (e, _) = rest.split_at_mut(n);
    [a, b, c, d, e]
}

impl Filter {
    /// Adds (`sign` = 1) or removes (−1) row `yy` of the weights to the column sums.
    #[inline(always)]
    pub(super) fn slide(&self, vs: &mut [ColumnSums], meas: &Measurements, yy: usize, sign: f64) {
        let w = self.width;
        let (Some(wr), Some(mr)) = (
            meas.w.get(yy * w..(yy + 1) * w),
            meas.wm.get(yy * w..(yy + 1) * w),
        ) else {
            return;
        };
        let yf = yy as f64;
        for ((c, &wv), &mv) in vs.iter_mut().zip(wr).zip(mr) {
            let (wv, mv) = (sign * f64::from(wv), sign * f64::from(mv));
            c[0] += wv;
            c[1] += wv * yf;
            c[2] += wv * yf * yf;
            c[3] += mv;
            c[4] += mv * yf;
        }
    }

    /// Whether the window is narrow enough (r ≤ [`DIRECT_WINDOW_MAX_R`]) to be summed directly
    /// ([`Filter::direct_info`]) rather than by running sums ([`Filter::prefix_info`]).
    pub(super) fn sums_directly(&self) -> bool {
        self.r <= DIRECT_WINDOW_MAX_R
    }

    /// The measurement information of row `y` summed directly over the (2r+1)² window in f32
    /// (r ≤ [`DIRECT_WINDOW_MAX_R`]): the vertical moments of each column relative to row y,
    /// then the horizontal sums of those relative to each pixel. Pixels outside the image
    /// weigh 0. Fills `sc.info` (zeroed by the caller).
    #[inline(always)]
    pub(super) fn direct_info(&self, y: usize, meas: &Measurements, sc: &mut SweepScratch) {
        let (w, h, r) = (self.width, self.height, self.r);
        let inv_r = (1.0 / self.noise_var) as f32;
        let padded = w + 2 * r;
        sc.moments.clear();
        sc.moments.resize(5 * padded, 0.0);
        let [m0, m1, m2, m3, m4] = split5(&mut sc.moments, padded);
        for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
            let (Some(wr), Some(mr)) = (
                meas.w.get(yy * w..(yy + 1) * w),
                meas.wm.get(yy * w..(yy + 1) * w),
            ) else {
                continue;
            };
            let dy = yy as f32 - y as f32;
            let cols = m0[r..r + w]
                .iter_mut()
                .zip(&mut m1[r..r + w])
                .zip(&mut m2[r..r + w])
                .zip(&mut m3[r..r + w])
                .zip(&mut m4[r..r + w]);
            for (((((c0, c1), c2), c3), c4), (&wv, &mv)) in cols.zip(wr.iter().zip(mr)) {
                *c0 += wv;
                *c1 += dy * wv;
                *c2 += dy * dy * wv;
                *c3 += mv;
                *c4 += dy * mv;
            }
        }
        // info block p accumulates Σ_dx weight(dx)·moment[x + dx] for its moment and dx power:
        // (αα: dx², Σw), (αβ: dx, Σw·dy), (αι: dx, Σw), (ββ: 1, Σw·dy²), (βι: 1, Σw·dy),
        // (ιι: 1, Σw), (α: dx, Σwm), (β: 1, Σwm·dy), (ι: 1, Σwm).
        let terms: [(u32, &[f32]); 9] = [
            (2, m0),
            (1, m1),
            (1, m0),
            (0, m2),
            (0, m1),
            (0, m0),
            (1, m3),
            (0, m4),
            (0, m3),
        ];
        for (out, (power, moment)) in sc.info.chunks_exact_mut(w).zip(terms) {
            for dx in 0..=2 * r {
                let d = dx as f32 - r as f32;
                let f = d.powi(power as i32);
                if let Some(src) = moment.get(dx..dx + w) {
                    for (o, &m) in out.iter_mut().zip(src) {
                        *o += f * m;
                    }
                }
            }
            for o in out.iter_mut() {
                *o *= inv_r;
            }
        }
    }

    /// The measurement information of row `y` from the column sums `vs` slid down the band
    /// (absolute rows), by prefix sums along the row in f64: for any window size. Fills
    /// `sc.info` (zeroed by the caller) where the window holds weight.
    pub(super) fn prefix_info(&self, y: usize, vs: &[ColumnSums], sc: &mut SweepScratch) {
        let (w, r) = (self.width, self.r);
        let yf = y as f64;
        let inv_r = 1.0 / self.noise_var;
        // Prefix sums along the row of the column sums taken relative to row y
        // (Σw, Σw·dy, Σw·dy², Σwm, Σwm·dy), weighted by the absolute column X and X²:
        // pre[X] = Σ_{X′<X} [c0, c0·X′, c0·X′², c1, c1·X′, c2, c3, c3·X′, c4].
        sc.prefix.clear();
        sc.prefix.reserve(w + 1);
        let mut acc = [0.0_f64; 9];
        sc.prefix.push(acc);
        for (xc, c) in vs.iter().enumerate() {
            let xf = xc as f64;
            let c1 = c[1] - yf * c[0];
            let c2 = c[2] - 2.0 * yf * c[1] + yf * yf * c[0];
            let c4 = c[4] - yf * c[3];
            let terms = [
                c[0],
                c[0] * xf,
                c[0] * xf * xf,
                c1,
                c1 * xf,
                c2,
                c[3],
                c[3] * xf,
                c4,
            ];
            for (a, v) in acc.iter_mut().zip(terms) {
                *a += v;
            }
            sc.prefix.push(acc);
        }
        // Window sums over x − r ..= x + r, moved to dx = X − x:
        // Σc·dx = T1 − x·T0, Σc·dx² = T2 − 2x·T1 + x²·T0. Then
        // J = Σ w·h·hᵀ/R packed (αα, αβ, αι, ββ, βι, ιι) and b = Σ w·m·h/R.
        for x in 0..w {
            let (Some(hi), Some(lo)) = (
                sc.prefix.get((x + r + 1).min(w)),
                sc.prefix.get(x.saturating_sub(r)),
            ) else {
                continue;
            };
            let t: [f64; 9] = std::array::from_fn(|i| hi[i] - lo[i]);
            if t[0] > 0.0 {
                let xf = x as f64;
                let v = [
                    t[2] - 2.0 * xf * t[1] + xf * xf * t[0],
                    t[4] - xf * t[3],
                    t[1] - xf * t[0],
                    t[5],
                    t[3],
                    t[0],
                    t[7] - xf * t[6],
                    t[8],
                    t[6],
                ];
                for (p, e) in v.into_iter().enumerate() {
                    if let Some(d) = sc.info.get_mut(p * w + x) {
                        *d = (e * inv_r) as f32;
                    }
                }
            }
        }
    }
}
