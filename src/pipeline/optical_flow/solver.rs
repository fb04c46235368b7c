//! The Horn–Schunck system and its temporally blocked solve: blocks of iterations, the wavefront passes over row bands and the seam triangles.

use super::*;

/// A Horn–Schunck system ready to iterate: the coefficient blocks ([`CoefRow`]) of every
/// image row's even half, then those of every odd half (so a wavefront step, whose levels all
/// update one half, reads consecutive rows of one run).
pub(super) struct HsSystem {
    pub(super) lay: Layout,
    pub(super) stencil: Stencil,
    pub(super) coef: Aligned,
    /// Each half's [`HalfEdges`] (worked out once: a row update would otherwise divide twice).
    pub(super) edges: [HalfEdges; 2],
}

impl HsSystem {
    /// Fills the coefficients a row at a time: `f(y, rows)` writes coefficient k of every
    /// column of image row `y` into `rows[k]` (natural column order, so the caller's loop can
    /// vectorise); the rows are then scattered into their halves' lane-major blocks.
    pub(super) fn build_rows<const C: usize>(
        lay: &Layout,
        stencil: Stencil,
        f: impl Fn(usize, &mut [Vec<f32>; C]) + Sync,
    ) -> Self {
        let (w, h) = (lay.width, lay.height);
        let halves = [CoefRow::new(lay, 0, C), CoefRow::new(lay, 1, C)];
        // The even halves' h rows come first, then the odd halves'; both halves have m
        // blocks, so rows of the same length.
        let coef = Aligned::from_row_pairs(
            halves[0].len(),
            h,
            // The image row's C coefficients.
            || std::array::from_fn(|_| vec![0.0_f32; w]),
            |rows: &mut [Vec<f32>; C], y, even, odd| {
                f(y, rows);
                halves[0].scatter(rows, even);
                halves[1].scatter(rows, odd);
            },
        );
        Self {
            lay: *lay,
            stencil,
            coef,
            edges: [lay.half_edges(0), lay.half_edges(1)],
        }
    }

    /// Image row `y`'s coefficient blocks of half `half`.
    #[inline]
    pub(super) fn coef_row(&self, y: usize, half: usize) -> &[f32] {
        let len = CoefRow::new(&self.lay, half, self.stencil.coefs()).len();
        let at = (half * self.lay.height + y) * len;
        self.coef.get(at..at + len).unwrap_or_default()
    }

    /// The plain system.
    pub(super) fn plain(lay: &Layout, d: &Derivatives, lambda: f32) -> Self {
        let w = lay.width;
        Self::build_rows::<PLAIN_COEFS>(lay, Stencil::Plain, |y, [gx, gy, gt]| {
            let span = y * w..(y + 1) * w;
            let (Some(ix), Some(iy), Some(it)) = (
                d.ix.data.get(span.clone()),
                d.iy.data.get(span.clone()),
                d.it.data.get(span),
            ) else {
                return;
            };
            let outs = gx.iter_mut().zip(gy.iter_mut()).zip(gt.iter_mut());
            for (((a, b), c), ((&ix, &iy), &it)) in outs.zip(ix.iter().zip(iy).zip(it)) {
                let s = 1.0 / (lambda + ix * ix + iy * iy).sqrt();
                (*a, *b, *c) = (ix * s, iy * s, it * s);
            }
        })
    }

    /// The groove system, its coefficient rows built for `isa`.
    pub(super) fn groove(
        lay: &Layout,
        d: &Derivatives,
        walls: &WallSideMap,
        focal_px: f64,
        params: &FlowParams,
        isa: Isa,
    ) -> Self {
        let (w, h) = (lay.width, lay.height);
        let lambda = f64::from(params.lambda);
        let gamma = f64::from(params.groove_weight) * lambda;
        let base = f64::from(d.base_flow_px);
        Self::build_rows::<GROOVE_COEFS>(
            lay,
            Stencil::Groove {
                quarter_lambda: 0.25 * params.lambda,
            },
            |y, rows| {
                let span = y * w..(y + 1) * w;
                let (Some(ix), Some(iy), Some(it), Some(sides)) = (
                    d.ix.data.get(span.clone()),
                    d.iy.data.get(span.clone()),
                    d.it.data.get(span.clone()),
                    walls.sign.get(span),
                ) else {
                    return;
                };
                // A missing row above or below stands in as the row itself, with its edges
                // switched off, so the loop over the row is branch-free and vectorises.
                let (above, has_above) = y
                    .checked_sub(1)
                    .and_then(|yy| walls.sign.get(yy * w..(yy + 1) * w))
                    .map_or((sides, false), |r| (r, true));
                let (below, has_below) = walls
                    .sign
                    .get((y + 1) * w..(y + 2) * w)
                    .map_or((sides, false), |r| (r, true));
                let row = GrooveRow {
                    lambda: params.lambda,
                    edges: groove_row_edges(y, h, focal_px, lambda, gamma, base),
                    ix,
                    iy,
                    it,
                    sides,
                    above,
                    below,
                    has_above,
                    has_below,
                };
                isa.compiled(GrooveFill {
                    row: &row,
                    out: rows,
                });
            },
        )
    }

    /// Iterates from the state in `st`; returns (iterations, converged).
    pub(super) fn solve(&self, st: &mut SplitState, params: &FlowParams, isa: Isa) -> (u32, bool) {
        self.solve_with(st, params, isa, rayon::current_num_threads(), None)
    }

    /// [`HsSystem::solve`] with at most `max_bands` row bands and, if given, a fixed block length.
    pub(super) fn solve_with(
        &self,
        st: &mut SplitState,
        params: &FlowParams,
        isa: Isa,
        max_bands: usize,
        block_override: Option<usize>,
    ) -> (u32, bool) {
        let lay = &self.lay;
        let jacobi = params.solver == Solver::Jacobi;
        let floats_per_px = self.stencil.coefs() + if jacobi { 4 } else { 2 };
        let row_bytes = lay.width * floats_per_px * std::mem::size_of::<f32>();
        let rows_fit = (BLOCK_CACHE_BYTES / row_bytes.max(1)).max(4);
        // Levels (half-sweeps for red–black, sweeps for Jacobi) per block.
        let per_iteration = if jacobi { 1 } else { 2 };
        let block_iterations = block_override
            .unwrap_or((rows_fit - 2) / per_iteration)
            .clamp(1, MAX_BLOCK_ITERATIONS);
        let threads = max_bands.max(1);
        let mut other = if jacobi { Some(st.clone()) } else { None };
        let max = params.max_iterations as usize;
        let pixels = (lay.width * lay.height) as f64;
        let tolerance = f64::from(params.tolerance_px);
        // With τ = 0 nothing can converge: the changes are not measured at all.
        let measure = tolerance > 0.0;
        let mut done = 0;
        let mut next = block_iterations;
        let mut last: Option<(usize, f64)> = None;
        while done < max {
            let k = next.min(max - done);
            let (mid, delta) = self.block(
                isa,
                st,
                other.as_mut(),
                k,
                threads,
                params.sor_omega,
                measure,
                PASS_LEVELS,
            );
            done += k;
            let per_px = delta / pixels;
            if per_px < tolerance {
                return (u32::try_from(done).unwrap_or(u32::MAX), true);
            }
            if block_override.is_none() {
                // The decay rate from the block's middle iteration (or, for a short block, the
                // previous block's last) to its last one predicts the iterations still needed.
                let before = (k >= 2).then(|| (done - k + k / 2, mid / pixels)).or(last);
                next = before
                    .and_then(|b| iterations_to_tolerance(b, (done, per_px), tolerance))
                    .unwrap_or(block_iterations)
                    .clamp(1, block_iterations);
            }
            last = Some((done, per_px));
        }
        (u32::try_from(done).unwrap_or(u32::MAX), false)
    }

    /// Runs `k` iterations from `st` (and `other`, a Jacobi solve's second state; the result
    /// ends in `st`) as wavefront passes of at most `pass_levels` levels each. Returns
    /// Σ(|Δu| + |Δv|) over the middle iteration (the ⌊k/2⌋-th of k; 0 when k < 2) and over
    /// the last one, or zeros when not `measure`. How the iterations are cut into passes
    /// changes only the memory traffic: every cut gives the same bits, sums included.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn block(
        &self,
        isa: Isa,
        st: &mut SplitState,
        mut other: Option<&mut SplitState>,
        k: usize,
        threads: usize,
        omega: f32,
        measure: bool,
        pass_levels: usize,
    ) -> (f64, f64) {
        // Levels per iteration: two half-sweeps (red–black, one state) or one sweep (Jacobi).
        let per = if other.is_some() { 1 } else { 2 };
        let passes = k.div_ceil((pass_levels / per).max(1)).max(1);
        let mid = k / 2;
        let mut sums = (0.0, 0.0);
        let mut start = 0;
        for p in 0..passes {
            let end = k * (p + 1) / passes;
            if end == start {
                continue;
            }
            let levels = (end - start) * per;
            let bands = threads.min(self.lay.height / (2 * levels + 2)).max(1);
            // The middle iteration, counted from this pass's start, if this pass runs it.
            let mid_here =
                (measure && mid >= 1 && mid < k && mid > start && mid <= end).then(|| mid - start);
            let last_here = measure && end == k;
            // One state (red–black, relaxed by ω) or two (Jacobi, never relaxed).
            let (mut one, mut two);
            let (states, w): (&mut [&mut SplitState], f32) = match other.as_deref_mut() {
                None => {
                    one = [&mut *st];
                    (&mut one, omega)
                }
                Some(b) => {
                    two = [&mut *st, b];
                    (&mut two, 1.0)
                }
            };
            let (m, l) = self.pass(isa, states, levels, bands, w, mid_here, last_here);
            // A Jacobi pass of odd length leaves its result in the second state.
            if let Some(b) = other.as_deref_mut()
                && !levels.is_multiple_of(2)
            {
                std::mem::swap(st, b);
            }
            sums = (sums.0 + m, sums.1 + l);
            start = end;
        }
        sums
    }

    /// Runs `levels` levels (red–black half-sweeps with one state, Jacobi sweeps with two:
    /// level h reads state `h % 2` and writes the other) over the whole image, temporally
    /// blocked: each of `bands` row bands first runs the trapezoid that needs no rows of its
    /// neighbours (a wavefront, so the rows being updated stay in cache), then the inverted
    /// triangles around each band seam finish the levels. Returns Σ(|Δu| + |Δv|) over
    /// iteration `mid` (1-based, if given) and, if `last`, over the last one (zeros for what
    /// is not measured); the same bits whatever the number of bands.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn pass(
        &self,
        isa: Isa,
        states: &mut [&mut SplitState],
        levels: usize,
        bands: usize,
        omega: f32,
        mid: Option<usize>,
        last: bool,
    ) -> (f64, f64) {
        let h = self.lay.height;
        let bounds: Vec<(usize, usize)> = (0..bands)
            .map(|b| (b * h / bands, (b + 1) * h / bands))
            .collect();
        // Levels per iteration: two half-sweeps (red–black, one state) or one sweep (Jacobi).
        let per = if states.len() == 1 { 2 } else { 1 };
        let iterations = levels / per;
        let sched = Schedule {
            levels,
            measure_from: if last {
                levels.saturating_sub(per)
            } else {
                usize::MAX
            },
            mid: match mid {
                Some(m) if m >= 1 && m <= iterations => (m - 1) * per..m * per,
                _ => 0..0,
            },
            omega,
        };
        let measure = last || !sched.mid.is_empty();
        // Each row's measured changes, summed level by level in increasing order and then
        // row by row, so the totals do not depend on the bands (or the threads).
        let mut per_row = vec![(0.0_f64, 0.0_f64); if measure { h } else { 0 }];
        split_bands(&self.lay, states, &mut per_row, &bounds)
            .into_par_iter()
            .for_each(|mut ch| self.phase_one(isa, &mut ch, &sched));
        if bands > 1 {
            let reach = levels + 1;
            let zones: Vec<(usize, usize)> = bounds[1..]
                .iter()
                .map(|&(seam, _)| (seam - reach, seam + reach))
                .collect();
            split_bands(&self.lay, states, &mut per_row, &zones)
                .into_par_iter()
                .for_each(|mut ch| self.phase_two(isa, &mut ch, &sched));
        }
        per_row
            .iter()
            .fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1))
    }

    /// The band's own trapezoid: level h covers rows `[a + h + 1, b − h − 1)` (no shrink at
    /// the image top and bottom), visited as a wavefront (row s − h at step s).
    pub(super) fn phase_one(&self, isa: Isa, ch: &mut RowBand, s: &Schedule) {
        let (a, b, h_img) = (ch.y0, ch.y0 + ch.rows, self.lay.height);
        // Taken out so that a row's sum and the chunk's state can be borrowed at once.
        let sums = std::mem::take(&mut ch.sums);
        let lo = |lvl: usize| if a == 0 { 0 } else { a + lvl + 1 };
        let hi = |lvl: usize| {
            if b == h_img {
                h_img
            } else {
                b.saturating_sub(lvl + 1)
            }
        };
        let mut scratch = Vec::new();
        for step in a..b + s.levels {
            for lvl in 0..s.levels.min(step + 1) {
                let y = step - lvl;
                if y >= lo(lvl) && y < hi(lvl) {
                    s.add(lvl, sums.get_mut(y - a), |measure| {
                        self.update_row(isa, ch, y, lvl, measure, s.omega, &mut scratch)
                    });
                }
            }
        }
    }

    /// The seam's inverted triangles: level h covers rows `[seam − h − 1, seam + h + 1)`.
    pub(super) fn phase_two(&self, isa: Isa, ch: &mut RowBand, s: &Schedule) {
        let seam = ch.y0 + s.levels + 1;
        let sums = std::mem::take(&mut ch.sums);
        let mut scratch = Vec::new();
        for lvl in 0..s.levels {
            for y in seam - lvl - 1..seam + lvl + 1 {
                s.add(lvl, sums.get_mut(y - ch.y0), |measure| {
                    self.update_row(isa, ch, y, lvl, measure, s.omega, &mut scratch)
                });
            }
        }
    }

    /// Updates image row `y` at level `lvl`; returns Σ(|Δu| + |Δv|) when `measure`.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn update_row(
        &self,
        isa: Isa,
        ch: &mut RowBand,
        y: usize,
        lvl: usize,
        measure: bool,
        omega: f32,
        scratch: &mut Vec<f32>,
    ) -> f64 {
        let lay = &self.lay;
        // Top and bottom rows have no neighbour beyond the image: that slot is fed the pixel's
        // own previous value, so at the fixed point the missing edge contributes nothing (free
        // boundary). Any valid row index stands in for it when slicing.
        let (up_own, dn_own) = (y == 0, y + 1 == lay.height);
        let up = if up_own { y + 1 } else { y - 1 };
        let dn = if dn_own { y - 1 } else { y + 1 };
        let (r, r_up, r_dn) = (y - ch.y0, up - ch.y0, dn - ch.y0);
        let mut delta = 0.0;
        let stride = lay.stride();
        if ch.bufs.len() == 1 {
            // Red–black: colour lvl % 2; red = (x + y) even, i.e. half (y + colour) % 2.
            let half = (y + lvl) % 2;
            let Some((e, o)) = ch.bufs.first_mut() else {
                return 0.0;
            };
            let (same, other): (&mut [f32], &[f32]) = if half == 0 { (e, o) } else { (o, e) };
            let across = &other[r * stride..(r + 1) * stride];
            let (up_row, mid, dn_row) = rows3(same, stride, r, r_up, r_dn);
            let keep_old = measure || up_own || dn_own;
            if keep_old {
                scratch.clear();
                scratch.extend_from_slice(mid);
            }
            let up_row = if up_own { &scratch[..] } else { up_row };
            let dn_row = if dn_own { &scratch[..] } else { dn_row };
            self.run_row(isa, half, y, omega, across, up_row, dn_row, mid);
            if measure {
                delta += abs_diff_sum(lay, lay.columns_in(half), mid, scratch);
            }
        } else {
            // Jacobi: read state lvl % 2, write the other, both halves.
            let (first, second) = ch.bufs.split_at_mut(1);
            let (Some(s0), Some(s1)) = (first.first_mut(), second.first_mut()) else {
                return 0.0;
            };
            let (src, dst) = if lvl.is_multiple_of(2) {
                (s0, s1)
            } else {
                (s1, s0)
            };
            for half in 0..2 {
                let (src_same, src_other, dst_same): (&[f32], &[f32], &mut [f32]) = if half == 0 {
                    (&*src.0, &*src.1, &mut *dst.0)
                } else {
                    (&*src.1, &*src.0, &mut *dst.1)
                };
                let row = |rr: usize| rr * stride..(rr + 1) * stride;
                let across = &src_other[row(r)];
                let old = &src_same[row(r)];
                let up_row = if up_own { old } else { &src_same[row(r_up)] };
                let dn_row = if dn_own { old } else { &src_same[row(r_dn)] };
                let mid = &mut dst_same[row(r)];
                self.run_row(isa, half, y, omega, across, up_row, dn_row, mid);
                if measure {
                    delta += abs_diff_sum(lay, lay.columns_in(half), mid, old);
                }
            }
        }
        delta
    }

    /// One half-row through the selected kernel.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn run_row(
        &self,
        isa: Isa,
        half: usize,
        y: usize,
        omega: f32,
        across: &[f32],
        up: &[f32],
        dn: &[f32],
        dst: &mut [f32],
    ) {
        let coef = self.coef_row(y, half);
        let edges = self.edges[half];
        let relax = omega != 1.0;
        let k = SolveScalars {
            quarter_lambda: match self.stencil {
                Stencil::Plain => 0.0,
                Stencil::Groove { quarter_lambda } => quarter_lambda,
            },
            omega,
        };
        let rows = HalfRowInputs {
            across,
            up,
            down: dn,
            coef,
        };
        match self.stencil {
            Stencil::Plain if relax => update_half_row::<false, true>(isa, k, edges, rows, dst),
            Stencil::Plain => update_half_row::<false, false>(isa, k, edges, rows, dst),
            Stencil::Groove { .. } if relax => {
                update_half_row::<true, true>(isa, k, edges, rows, dst)
            }
            Stencil::Groove { .. } => update_half_row::<true, false>(isa, k, edges, rows, dst),
        }
    }
}
