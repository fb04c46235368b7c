//! Two-frame derivatives: central differences averaged over a frame pair, and their difference in time.

use super::*;

/// One two-frame derivative set: central differences in x and y averaged over both frames,
/// `It` = difference of the frames (the second pre-warped by `base_flow_px`).
pub(super) fn two_frame(a: &Image, b: &Image, index: usize, base_flow_px: f64) -> Derivatives {
    let (width, height) = (a.width, a.height);
    let shift = RowShift::new(base_flow_px, width);
    let margin = prewarp_margin(&[shift], 1);
    let warped: Vec<f32> = if shift.is_identity() {
        b.data.clone()
    } else {
        let mut out = vec![0.0; width * height];
        out.par_chunks_mut(width)
            .zip(b.data.par_chunks(width))
            .for_each(|(dst, src)| shift.apply(src, dst));
        out
    };
    let n = width * height;
    let (mut ix, mut iy, mut it, mut image) =
        (vec![0.0; n], vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    let last_x = width - 1;
    ix.par_chunks_mut(width)
        .zip(iy.par_chunks_mut(width))
        .zip(it.par_chunks_mut(width))
        .zip(image.par_chunks_mut(width))
        .enumerate()
        .for_each(|(y, (((ix_r, iy_r), it_r), im_r))| {
            let up = y.saturating_sub(1);
            let dn = (y + 1).min(height - 1);
            let (a0, a_up, a_dn) = (
                row_of(&a.data, y, width),
                row_of(&a.data, up, width),
                row_of(&a.data, dn, width),
            );
            let (b0, b_up, b_dn) = (
                row_of(&warped, y, width),
                row_of(&warped, up, width),
                row_of(&warped, dn, width),
            );
            for x in 0..width {
                let (l, r) = (x.saturating_sub(1), (x + 1).min(last_x));
                ix_r[x] = 0.25 * ((a0[r] - a0[l]) + (b0[r] - b0[l]));
                iy_r[x] = 0.25 * ((a_dn[x] - a_up[x]) + (b_dn[x] - b_up[x]));
                it_r[x] = b0[x] - a0[x];
                im_r[x] = 0.5 * (a0[x] + b0[x]);
            }
            let m = if y == 0 || y + 1 == height {
                width
            } else {
                margin
            };
            blank_margins(ix_r, m);
            blank_margins(iy_r, m);
            blank_margins(it_r, m);
        });
    Derivatives::from_planes((width, height), [ix, iy, it, image], index, base_flow_px)
}
