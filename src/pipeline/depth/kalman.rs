//! The Barron–Ngai–Spies Kalman filter over a group's flows: row bands through every frame, prediction and information-form update on lanes of 8 pixels.

use super::*;

/// One pixel's state: α̃, β̃, ι̃, then the covariance P00 P01 P02 P11 P12 P22.
pub(super) type Cell = [f32; PLANES];

/// Fixed quantities of one filter run.
pub(super) struct Filter {
    pub(super) width: usize,
    pub(super) height: usize,
    /// Neighbourhood half-side.
    pub(super) r: usize,
    /// |u_land| = f·U/Z_ref: the land flow in px/frame (positive).
    pub(super) land_shift_px: f64,
    /// Measurement noise variance of m = u/u_land for weight 1.
    pub(super) noise_var: f64,
    /// Process noise per frame: [α̃, β̃, ι̃] variances.
    pub(super) q: [f64; 3],
    /// Prior covariance diagonal.
    pub(super) p0: [f64; 3],
    /// Instruction set the row bands are compiled for.
    pub(super) isa: Isa,
}

/// Rows per parallel work item of the filter (the vertical window sums slide down a band).
pub(super) const BAND_ROWS: usize = 32;

/// Runs the Kalman filter over the flows; returns ι̃ (NaN where never measured) and Var ι̃.
pub(super) fn kalman(
    flows: &[FlowField],
    filter: &Filter,
    min_confidence: f32,
    u_land: f64,
    warnings: &mut Vec<String>,
) -> (Vec<f32>, Vec<f32>) {
    let (w, h) = (filter.width, filter.height);
    let mut prev_index: Option<usize> = None;
    let frames: Vec<FrameInput> = flows
        .iter()
        .enumerate()
        .map(|(k, flow)| {
            let mut meas = Measurements::default();
            meas.fill(flow, u_land, min_confidence);
            note_frame(k, flow, &meas, prev_index, warnings);
            let steps = prev_index.map(|p| flow.frame_index.saturating_sub(p) as f64);
            prev_index = Some(flow.frame_index);
            FrameInput { meas, steps }
        })
        .collect();
    let mut iota = zeros_par(w * h);
    let mut var = zeros_par(w * h);
    let diverged = iota
        .par_chunks_mut(BAND_ROWS * w)
        .zip(var.par_chunks_mut(BAND_ROWS * w))
        .enumerate()
        .map_init(SweepScratch::default, |sc, (band, out)| {
            filter.band(band * BAND_ROWS, &frames, out, sc)
        })
        .sum::<usize>();
    if diverged > 0 {
        warnings.push(format!(
            "{diverged} pixel predictions diverged (plane scale 1 − f·U·α < {MIN_PLANE_SCALE}) and restarted from the prior"
        ));
    }
    (iota, var)
}

impl Filter {
    /// The prior state of one pixel.
    pub(super) fn prior(&self) -> Cell {
        let p0 = self.p0.map(|v| v as f32);
        [0.0, 0.0, 1.0, p0[0], 0.0, 0.0, p0[1], 0.0, p0[2]]
    }

    /// One row of frame `f`: prediction from the previous frame (when `f.steps` is Some) fused
    /// with the measurement update from the window about row `y` (`vs`: that frame's column
    /// sums, read only for windows too wide to sum directly). Returns the number of diverged
    /// predictions.
    ///
    /// `row` holds the row's state planar: one block of w values per state term.
    ///
    /// Phase A: each pixel's information J and b ([`Filter::direct_info`] or
    /// [`Filter::prefix_info`]), and from the old state its source position
    /// x + f·U·ι·steps. Phase B then predicts and updates [`LANES`] pixels at a time in f32
    /// lanes; it overwrites the state in place, which is safe because content moves toward −x:
    /// a pixel's sources lie at or right of it and are read before its block is written.
    #[inline(always)]
    pub(super) fn sweep_row(
        &self,
        y: usize,
        row: &mut [f32],
        f: &FrameInput,
        vs: &[ColumnSums],
        sc: &mut SweepScratch,
    ) -> usize {
        let w = self.width;
        let (steps, measured) = (f.steps, f.measured());
        let k = self.land_shift_px * steps.unwrap_or(0.0);
        // Phase A.
        sc.info.clear();
        sc.info.resize(9 * w, 0.0);
        if measured && self.sums_directly() {
            self.direct_info(y, &f.meas, sc);
        } else if measured {
            self.prefix_info(y, vs, sc);
        }
        sc.src.clear();
        if steps.is_some() {
            let iotas = row.get(IOTA * w..(IOTA + 1) * w).unwrap_or_default();
            for x in 0..w {
                let iota = iotas.get(x).map_or(f64::NAN, |&v| f64::from(v));
                let xs = x as f64 + k * iota;
                let i0 = xs.floor();
                // The source lies at or right of x; anything else (new content entering at the
                // right edge, a broken state) restarts from the prior.
                let ok = i0 >= x as f64 && i0 + 1.0 < w as f64;
                sc.src.push(if ok {
                    (i0 as u32, (xs - i0) as f32)
                } else {
                    (u32::MAX, 0.0)
                });
            }
        }
        // Phase B.
        let prior = self.prior();
        let mut diverged = 0;
        let mut x0 = 0;
        while x0 < w {
            let n = LANES.min(w - x0);
            let mut st: [Lane; PLANES] = std::array::from_fn(|p| [prior[p]; LANES]);
            let mut info = [[0.0_f32; LANES]; 9];
            let mut fresh = [true; LANES];
            if steps.is_some() {
                let srcs = sc.src.get(x0..x0 + n).unwrap_or_default();
                // Usually every lane reads the same offset d: cells x0 + d + l and the next.
                let d = srcs
                    .first()
                    .map_or(w, |&(i, _)| (i as usize).saturating_sub(x0));
                let uniform = n == LANES
                    && x0.saturating_add(d).saturating_add(LANES) < w
                    && srcs
                        .iter()
                        .enumerate()
                        .all(|(l, &(i, _))| i as usize == x0 + d + l);
                if uniform {
                    let t: Lane = std::array::from_fn(|l| srcs.get(l).map_or(0.0, |s| s.1));
                    for (p, s) in st.iter_mut().enumerate() {
                        let at = p * w + x0 + d;
                        if let (Some(a), Some(b)) =
                            (row.get(at..at + LANES), row.get(at + 1..at + 1 + LANES))
                        {
                            *s = lanes(|l| a[l] + (b[l] - a[l]) * t[l]);
                        }
                    }
                    fresh = [false; LANES];
                } else {
                    for (l, &(i, tt)) in srcs.iter().enumerate() {
                        let i = i as usize;
                        if i == u32::MAX as usize || i + 1 >= w {
                            continue;
                        }
                        for (p, s) in st.iter_mut().enumerate() {
                            if let (Some(&a), Some(&b)) =
                                (row.get(p * w + i), row.get(p * w + i + 1))
                            {
                                s[l] = a + (b - a) * tt;
                            }
                        }
                        fresh[l] = false;
                    }
                }
            } else {
                for (p, s) in st.iter_mut().enumerate() {
                    if let Some(src) = row.get(p * w + x0..p * w + x0 + n) {
                        s[..n].copy_from_slice(src);
                    }
                }
                fresh[..n].fill(false);
            }
            for (p, d) in info.iter_mut().enumerate() {
                if let Some(src) = sc.info.get(p * w + x0..p * w + x0 + n) {
                    d[..n].copy_from_slice(src);
                }
            }
            if let Some(steps) = steps {
                diverged += predict_lanes(
                    &mut st,
                    &fresh,
                    k as f32,
                    self.q.map(|q| (q * steps) as f32),
                    &prior,
                );
            }
            if measured {
                update_lanes(&mut st, &info);
            }
            for (p, s) in st.iter().enumerate() {
                if let Some(dst) = row.get_mut(p * w + x0..p * w + x0 + n) {
                    dst.copy_from_slice(&s[..n]);
                }
            }
            x0 += LANES;
        }
        diverged
    }

    /// A band of rows starting at `y0` through every frame: row by row, the row's state runs
    /// through the frames in order (for wide windows, each frame's column sums slide down the
    /// band with it), so only one row of state is kept and it stays in cache. Rows never
    /// exchange state (content moves along x only), so this is the same arithmetic, in the same
    /// order per row and frame, as sweeping the whole image one frame at a time. Writes ι̃ and
    /// Var ι̃ of the band (NaN where never measured) and returns the number of diverged
    /// predictions. Runs the AVX2 build of the same code where the CPU has it (no FMA, so the
    /// results are identical).
    pub(super) fn band(
        &self,
        y0: usize,
        frames: &[FrameInput],
        out: (&mut [f32], &mut [f32]),
        sc: &mut SweepScratch,
    ) -> usize {
        self.isa.compiled(BandRun {
            filter: self,
            y0,
            frames,
            out,
            sc,
        })
    }

    /// See [`Filter::band`].
    #[inline(always)]
    pub(super) fn band_impl(
        &self,
        y0: usize,
        frames: &[FrameInput],
        (iota, var): (&mut [f32], &mut [f32]),
        sc: &mut SweepScratch,
    ) -> usize {
        let (w, h, r) = (self.width, self.height, self.r);
        // Column sums slid down the band: only for windows too wide to sum directly.
        let slid = |f: &FrameInput| f.measured() && !self.sums_directly();
        let mut vs = std::mem::take(&mut sc.vs);
        vs.resize_with(frames.len(), Vec::new);
        for (sums, f) in vs.iter_mut().zip(frames) {
            sums.clear();
            if slid(f) {
                sums.resize(w, [0.0; 5]);
                for yy in y0.saturating_sub(r)..(y0 + r).min(h) {
                    self.slide(sums, &f.meas, yy, 1.0);
                }
            }
        }
        let prior = self.prior();
        let mut row = std::mem::take(&mut sc.row);
        let limit = (UNMEASURED_SHARE * INITIAL_VARIANCE) as f32;
        let mut diverged = 0;
        for (i, (io_row, var_row)) in iota.chunks_mut(w).zip(var.chunks_mut(w)).enumerate() {
            let y = y0 + i;
            row.clear();
            for &p in &prior {
                row.resize(row.len() + w, p);
            }
            for (sums, f) in vs.iter_mut().zip(frames) {
                if slid(f) {
                    if y + r < h {
                        self.slide(sums, &f.meas, y + r, 1.0);
                    }
                    if i > 0 && y > r {
                        self.slide(sums, &f.meas, y - r - 1, -1.0);
                    }
                }
                diverged += self.sweep_row(y, &mut row, f, sums, sc);
            }
            let (Some(is), Some(vs)) = (
                row.get(IOTA * w..(IOTA + 1) * w),
                row.get(VAR_IOTA * w..(VAR_IOTA + 1) * w),
            ) else {
                continue;
            };
            for (((o, ov), &i), &v) in io_row.iter_mut().zip(var_row.iter_mut()).zip(is).zip(vs) {
                (*o, *ov) = if v.is_finite() && v < limit && i.is_finite() {
                    (i, v)
                } else {
                    (f32::NAN, f32::NAN)
                };
            }
        }
        sc.vs = vs;
        sc.row = row;
        diverged
    }
}

/// One call of [`Filter::band_impl`], to be compiled for an instruction set.
pub(super) struct BandRun<'a, 'b> {
    pub(super) filter: &'a Filter,
    pub(super) y0: usize,
    pub(super) frames: &'a [FrameInput],
    pub(super) out: (&'b mut [f32], &'b mut [f32]),
    pub(super) sc: &'a mut SweepScratch,
}

impl Compiled for BandRun<'_, '_> {
    type Output = usize;
    #[inline(always)]
    fn run(self) -> usize {
        self.filter
            .band_impl(self.y0, self.frames, self.out, self.sc)
    }
}

/// Pixels predicted and updated together (f32 lanes the compiler maps onto SIMD registers).
pub(super) const LANES: usize = 8;
/// One value for each pixel of a block.
pub(super) type Lane = [f32; LANES];

/// Per-thread buffers of the row sweeps.
#[derive(Default)]
pub(super) struct SweepScratch {
    /// Per frame: vertical window sums per column (wide windows only).
    pub(super) vs: Vec<Vec<ColumnSums>>,
    /// The state of the row being filtered, planar.
    pub(super) row: Vec<f32>,
    /// J (αα, αβ, αι, ββ, βι, ιι) and b (α, β, ι) of this frame, one block of the row's
    /// pixels each.
    pub(super) info: Vec<f32>,
    /// Per column (padded by r zero columns each side): the window's vertical moments
    /// Σw, Σw·dy, Σw·dy², Σwm, Σwm·dy, one block each (direct window sums).
    pub(super) moments: Vec<f32>,
    /// Per pixel: source cell and interpolation weight of the prediction (u32::MAX: prior).
    pub(super) src: Vec<(u32, f32)>,
    /// Prefix sums along the row of the window moments.
    pub(super) prefix: Vec<[f64; 9]>,
}

/// A lane-wise map: `f` applied to every lane index (written so the compiler emits SIMD).
#[inline(always)]
pub(super) fn lanes(f: impl Fn(usize) -> f32) -> Lane {
    std::array::from_fn(f)
}

/// The plane transform and process noise on a block of interpolated states (module docs):
/// α′ = s·α, β′ = s·β, ι′ = ι with s = 1/(1 − k·α), P′ = F·P·Fᵀ + Q. Lanes marked `fresh` hold
/// the prior and are left alone; diverged lanes (1 − k·α < `MIN_PLANE_SCALE`) are reset to the
/// prior. Returns the number of diverged lanes.
#[inline(always)]
pub(super) fn predict_lanes(
    st: &mut [Lane; PLANES],
    fresh: &[bool; LANES],
    k: f32,
    q: [f32; 3],
    prior: &Cell,
) -> usize {
    let [al, be, io, p00, p01, p02, p11, p12, p22] = *st;
    let den = lanes(|l| 1.0 - k * al[l]);
    let s = lanes(|l| 1.0 / den[l]);
    let s2 = lanes(|l| s[l] * s[l]);
    let c = lanes(|l| be[l] * k * s2[l]);
    let new: [Lane; PLANES] = [
        lanes(|l| s[l] * al[l]),
        lanes(|l| s[l] * be[l]),
        io,
        lanes(|l| s2[l] * s2[l] * p00[l] + q[0]),
        lanes(|l| s2[l] * (c[l] * p00[l] + s[l] * p01[l])),
        lanes(|l| s2[l] * p02[l]),
        lanes(|l| c[l] * c[l] * p00[l] + 2.0 * c[l] * s[l] * p01[l] + s2[l] * p11[l] + q[1]),
        lanes(|l| c[l] * p02[l] + s[l] * p12[l]),
        lanes(|l| p22[l] + q[2]),
    ];
    let ok: [bool; LANES] = std::array::from_fn(|l| den[l] >= MIN_PLANE_SCALE as f32);
    for ((dst, nw), &pr) in st.iter_mut().zip(&new).zip(prior) {
        *dst = lanes(|l| {
            if fresh[l] {
                dst[l]
            } else if ok[l] {
                nw[l]
            } else {
                pr
            }
        });
    }
    (0..LANES).filter(|&l| !ok[l] && !fresh[l]).count()
}

/// Inverse of packed symmetric 3×3 matrices, lane-wise, scaled by the trace so that f32 copes
/// with any magnitude; zero (and a false flag) where the matrix is not invertible.
#[inline(always)]
pub(super) fn inv_sym3_lanes(m: &[Lane; 6]) -> ([Lane; 6], [bool; LANES]) {
    let sc = lanes(|l| 1.0 / (m[0][l] + m[3][l] + m[5][l]));
    let a = lanes(|l| m[0][l] * sc[l]);
    let b = lanes(|l| m[1][l] * sc[l]);
    let c = lanes(|l| m[2][l] * sc[l]);
    let d = lanes(|l| m[3][l] * sc[l]);
    let e = lanes(|l| m[4][l] * sc[l]);
    let f = lanes(|l| m[5][l] * sc[l]);
    let c00 = lanes(|l| d[l] * f[l] - e[l] * e[l]);
    let c01 = lanes(|l| c[l] * e[l] - b[l] * f[l]);
    let c02 = lanes(|l| b[l] * e[l] - c[l] * d[l]);
    let det = lanes(|l| a[l] * c00[l] + b[l] * c01[l] + c[l] * c02[l]);
    let ok: [bool; LANES] = std::array::from_fn(|l| det[l] > 0.0 && det[l] < f32::INFINITY);
    let g = lanes(|l| if ok[l] { sc[l] / det[l] } else { 0.0 });
    let inv = [
        lanes(|l| c00[l] * g[l]),
        lanes(|l| c01[l] * g[l]),
        lanes(|l| c02[l] * g[l]),
        lanes(|l| (a[l] * f[l] - c[l] * c[l]) * g[l]),
        lanes(|l| (b[l] * c[l] - a[l] * e[l]) * g[l]),
        lanes(|l| (a[l] * d[l] - b[l] * b[l]) * g[l]),
    ];
    (inv, ok)
}

/// Packed symmetric 3×3 times a vector, lane-wise.
#[inline(always)]
pub(super) fn mul_sym3_lanes(m: &[Lane; 6], v: &[Lane; 3]) -> [Lane; 3] {
    let [x, y, z] = v;
    [
        lanes(|l| m[0][l] * x[l] + m[1][l] * y[l] + m[2][l] * z[l]),
        lanes(|l| m[1][l] * x[l] + m[3][l] * y[l] + m[4][l] * z[l]),
        lanes(|l| m[2][l] * x[l] + m[4][l] * y[l] + m[5][l] * z[l]),
    ]
}

/// The information-form measurement update on a block: Λ⁺ = P⁻¹ + J,
/// µ⁺ = (Λ⁺)⁻¹·(P⁻¹·µ + b). Lanes without a measurement (J_ιι = 0) or with a singular
/// posterior keep their prior; a non-finite prior carries no information.
#[inline(always)]
pub(super) fn update_lanes(st: &mut [Lane; PLANES], info: &[Lane; 9]) {
    let [a0, a1, a2, p0, p1, p2, p3, p4, p5] = *st;
    let fin = lanes(|l| {
        if a0[l].is_finite() && a1[l].is_finite() && a2[l].is_finite() {
            1.0
        } else {
            0.0
        }
    });
    let mu = [
        lanes(|l| if fin[l] > 0.0 { a0[l] } else { 0.0 }),
        lanes(|l| if fin[l] > 0.0 { a1[l] } else { 0.0 }),
        lanes(|l| if fin[l] > 0.0 { a2[l] } else { 0.0 }),
    ];
    // A non-finite prior carries no information (its Λ is zeroed).
    let (lam, _) = inv_sym3_lanes(&[p0, p1, p2, p3, p4, p5]);
    let mut post = lam;
    for (pr, jr) in post.iter_mut().zip(info) {
        *pr = lanes(|l| pr[l] * fin[l] + jr[l]);
    }
    let mut lmu = mul_sym3_lanes(&lam, &mu);
    for (lr, br) in lmu.iter_mut().zip(&info[6..]) {
        *lr = lanes(|l| lr[l] * fin[l] + br[l]);
    }
    let (p_post, ok) = inv_sym3_lanes(&post);
    let mu_post = mul_sym3_lanes(&p_post, &lmu);
    let take: [bool; LANES] = std::array::from_fn(|l| ok[l] && info[5][l] > 0.0);
    for (dst, nw) in st.iter_mut().zip(mu_post.iter().chain(&p_post)) {
        *dst = lanes(|l| if take[l] { nw[l] } else { dst[l] });
    }
}
