//! The Simoncelli window: the pre-blur folded into 7-tap temporal filters, then the separable 5-tap passes over bands of rows.

use super::*;

/// Rows per parallel work item of the separable filters.
pub(super) const BAND_ROWS: usize = 16;
/// The pre-blur convolved with a 5-tap temporal filter: one 7-tap filter over the window.
pub(super) fn fold_preblur(taps: &[f32; 5]) -> [f32; SIMONCELLI_WINDOW_FRAMES] {
    let mut out = [0.0_f32; SIMONCELLI_WINDOW_FRAMES];
    for (m, &t) in taps.iter().enumerate() {
        for (i, &b) in TEMPORAL_PREBLUR.iter().enumerate() {
            out[m + i] += t * b;
        }
    }
    out
}

/// `dst[x] = Σ_j taps[j]·src[clamp(x + j − 2)]` (a 5-tap correlation with clamped borders).
#[inline(always)]
pub(super) fn correlate_row5(src: &[f32], taps: &[f32; 5], dst: &mut [f32]) {
    let w = src.len().min(dst.len());
    if w == 0 {
        return;
    }
    let (src, dst) = (&src[..w], &mut dst[..w]);
    let last = w as isize - 1;
    let edge = |x: usize| -> f32 {
        taps.iter()
            .enumerate()
            .map(|(j, &t)| t * src[(x as isize + j as isize - 2).clamp(0, last) as usize])
            .sum()
    };
    if w <= 2 * RADIUS {
        for (x, d) in dst.iter_mut().enumerate() {
            *d = edge(x);
        }
        return;
    }
    let len = w - 2 * RADIUS;
    let [t0, t1, t2, t3, t4] = *taps;
    let (a, b, c, d, e) = (
        &src[0..len],
        &src[1..len + 1],
        &src[2..len + 2],
        &src[3..len + 3],
        &src[4..len + 4],
    );
    let out = &mut dst[RADIUS..RADIUS + len];
    for i in 0..len {
        out[i] = t0 * a[i] + t1 * b[i] + t2 * c[i] + t3 * d[i] + t4 * e[i];
    }
    for x in (0..RADIUS).chain(w - RADIUS..w) {
        dst[x] = edge(x);
    }
}

/// `dst = Σ_j taps[j]·rows[j]` over five rows of equal length.
#[inline(always)]
pub(super) fn combine_rows5(rows: [&[f32]; 5], taps: &[f32; 5], dst: &mut [f32]) {
    let len = dst.len();
    let [a, b, c, d, e] = rows.map(|r| &r[..len.min(r.len())]);
    if [a, b, c, d, e].iter().any(|r| r.len() != len) {
        return;
    }
    let [t0, t1, t2, t3, t4] = *taps;
    for i in 0..len {
        dst[i] = t0 * a[i] + t1 * b[i] + t2 * c[i] + t3 * d[i] + t4 * e[i];
    }
}

/// Rows `r..r + 5` of a buffer with row length `width`.
pub(super) fn five_rows(buf: &[f32], r: usize, width: usize) -> [&[f32]; 5] {
    std::array::from_fn(|j| row_of(buf, r + j, width))
}

/// Row `y` of a buffer with row length `width`.
pub(super) fn row_of(buf: &[f32], y: usize, width: usize) -> &[f32] {
    &buf[y * width..(y + 1) * width]
}

/// `acc = t·src` when `first`, else `acc += t·src`.
#[inline(always)]
pub(super) fn axpy(acc: &mut [f32], t: f32, src: &[f32], first: bool) {
    let len = acc.len().min(src.len());
    let (acc, src) = (&mut acc[..len], &src[..len]);
    if first {
        for i in 0..len {
            acc[i] = t * src[i];
        }
    } else {
        for i in 0..len {
            acc[i] += t * src[i];
        }
    }
}

/// Scratch rows one band of [`simoncelli_window`] works in.
pub(super) struct BandScratch {
    /// Temporally smoothed rows (band + 2·RADIUS rows).
    pub(super) p: Vec<f32>,
    /// Temporally differentiated rows (band + 2·RADIUS rows).
    pub(super) d: Vec<f32>,
    /// One pre-warped input row.
    pub(super) shifted: Vec<f32>,
    /// Vertical pass outputs for one row.
    pub(super) yp: Vec<f32>,
    pub(super) yd: Vec<f32>,
    pub(super) ypd: Vec<f32>,
}

impl BandScratch {
    pub(super) fn new(width: usize) -> Self {
        let rows = BAND_ROWS + 2 * RADIUS;
        Self {
            p: vec![0.0; rows * width],
            d: vec![0.0; rows * width],
            shifted: vec![0.0; width],
            yp: vec![0.0; width],
            yd: vec![0.0; width],
            ypd: vec![0.0; width],
        }
    }
}

/// What every band of one Simoncelli window shares.
pub(super) struct BandCtx<'a> {
    pub(super) window: &'a [Image],
    pub(super) shifts: &'a [RowShift],
    pub(super) p7: &'a [f32; SIMONCELLI_WINDOW_FRAMES],
    pub(super) d7: &'a [f32; SIMONCELLI_WINDOW_FRAMES],
    /// Left/right columns without data (see [`prewarp_margin`]).
    pub(super) margin: usize,
}

/// One band of [`simoncelli_band`], to be compiled for an instruction set.
pub(super) struct Band<'a, 'b> {
    pub(super) ctx: &'a BandCtx<'a>,
    pub(super) scratch: &'a mut BandScratch,
    pub(super) y0: usize,
    pub(super) outs: [&'b mut [f32]; 4],
}

impl Compiled for Band<'_, '_> {
    type Output = ();
    #[inline(always)]
    fn run(self) {
        simoncelli_band(self.ctx, self.scratch, self.y0, self.outs);
    }
}

/// Rows `y0..` of one window: temporal 7-tap filters (with pre-warp) into `s.p`/`s.d`, then
/// the vertical and horizontal 5-tap passes into `outs = [ix, iy, it, image]` (whole rows).
#[inline(always)]
pub(super) fn simoncelli_band(
    ctx: &BandCtx,
    s: &mut BandScratch,
    y0: usize,
    outs: [&mut [f32]; 4],
) {
    let [ix_b, iy_b, it_b, im_b] = outs;
    let (width, height) = (ctx.window[0].width, ctx.window[0].height);
    let rows = ix_b.len() / width;
    // Temporal filtering of rows y0 − 2 ..= y0 + rows + 1 (clamped).
    for r in 0..rows + 2 * RADIUS {
        let y = (y0 as isize + r as isize - RADIUS as isize).clamp(0, height as isize - 1) as usize;
        let p_row = &mut s.p[r * width..(r + 1) * width];
        let d_row = &mut s.d[r * width..(r + 1) * width];
        let mut first_d = true;
        for (k, frame) in ctx.window.iter().enumerate() {
            let src = frame.row(y);
            let row: &[f32] = if ctx.shifts[k].is_identity() {
                src
            } else {
                ctx.shifts[k].apply(src, &mut s.shifted);
                &s.shifted
            };
            axpy(p_row, ctx.p7[k], row, k == 0);
            if ctx.d7[k] != 0.0 {
                axpy(d_row, ctx.d7[k], row, first_d);
                first_d = false;
            }
        }
    }
    for r in 0..rows {
        combine_rows5(five_rows(&s.p, r, width), &P5, &mut s.yp);
        combine_rows5(five_rows(&s.p, r, width), &D5, &mut s.yd);
        combine_rows5(five_rows(&s.d, r, width), &P5, &mut s.ypd);
        let out = r * width..(r + 1) * width;
        correlate_row5(&s.yp, &D5, &mut ix_b[out.clone()]);
        correlate_row5(&s.yp, &P5, &mut im_b[out.clone()]);
        correlate_row5(&s.yd, &P5, &mut iy_b[out.clone()]);
        correlate_row5(&s.ypd, &P5, &mut it_b[out.clone()]);
        let y = y0 + r;
        let m = if y < RADIUS || y + RADIUS >= height {
            width
        } else {
            ctx.margin
        };
        blank_margins(&mut ix_b[out.clone()], m);
        blank_margins(&mut iy_b[out.clone()], m);
        blank_margins(&mut it_b[out], m);
    }
}

/// The pre-warp of each frame of a 7-frame window: frame `k` moved back by its `k − 3` frames
/// of land motion at `base_flow_px` a frame.
pub(super) fn window_shifts(base_flow_px: f64, width: usize) -> Vec<RowShift> {
    (0..SIMONCELLI_WINDOW_FRAMES)
        .map(|k| RowShift::new((k as f64 - HALF_WINDOW as f64) * base_flow_px, width))
        .collect()
}

/// One Simoncelli derivative set from a 7-frame window centred on group frame `centre`, the
/// bands compiled for `isa`.
pub(super) fn simoncelli_window(
    window: &[Image],
    centre: usize,
    base_flow_px: f64,
    isa: Isa,
) -> Derivatives {
    let (width, height) = (window[0].width, window[0].height);
    let p7 = fold_preblur(&P5);
    let d7 = fold_preblur(&D5);
    let shifts = window_shifts(base_flow_px, width);
    let margin = prewarp_margin(&shifts, RADIUS);
    let n = width * height;
    let (mut ix, mut iy, mut it, mut image) =
        (vec![0.0; n], vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    let chunk = BAND_ROWS * width;
    ix.par_chunks_mut(chunk)
        .zip(iy.par_chunks_mut(chunk))
        .zip(it.par_chunks_mut(chunk))
        .zip(image.par_chunks_mut(chunk))
        .enumerate()
        .for_each_init(
            || BandScratch::new(width),
            |s, (band, (((ix_b, iy_b), it_b), im_b))| {
                let ctx = BandCtx {
                    window,
                    shifts: &shifts,
                    p7: &p7,
                    d7: &d7,
                    margin,
                };
                isa.compiled(Band {
                    ctx: &ctx,
                    scratch: s,
                    y0: band * BAND_ROWS,
                    outs: [ix_b, iy_b, it_b, im_b],
                });
            },
        );
    Derivatives::from_planes((width, height), [ix, iy, it, image], centre, base_flow_px)
}
