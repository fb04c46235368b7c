//! The IRLS pass of the robust plane fit on whole chunks of 4 points, portable (fixed 4-lane arrays the compiler vectorises).

use crate::pipeline::simd::irls::{
    IRLS_LANES as LANES, IRLS_SUMS as N_SUMS, PassInputs, point_terms,
};

/// See [`crate::pipeline::simd::irls::accumulate_chunks`].
pub(in crate::pipeline::simd) fn chunks(
    pass: PassInputs<'_>,
    w_new: &mut [f64],
    acc: &mut [[f64; LANES]; N_SUMS],
) {
    let ([a, b, c], k) = (pass.plane, pass.k);
    let chunks = pass
        .x
        .chunks_exact(LANES)
        .zip(pass.y.chunks_exact(LANES))
        .zip(pass.z.chunks_exact(LANES))
        .zip(pass.w_old.chunks_exact(LANES))
        .zip(w_new.chunks_exact_mut(LANES));
    for ((((xc, yc), zc), woc), wnc) in chunks {
        let (Ok(xc), Ok(yc), Ok(zc), Ok(woc), Ok(wnc)) = (
            <&[f64; LANES]>::try_from(xc),
            <&[f64; LANES]>::try_from(yc),
            <&[f64; LANES]>::try_from(zc),
            <&[f64; LANES]>::try_from(woc),
            <&mut [f64; LANES]>::try_from(wnc),
        ) else {
            continue;
        };
        // Lane-wise arithmetic on fixed-size arrays (the compiler maps it onto SIMD registers).
        let r: [f64; LANES] = std::array::from_fn(|l| zc[l] - a * xc[l] - b * yc[l] - c);
        let w: [f64; LANES] = std::array::from_fn(|l| 1.0 / (1.0 + r[l] * r[l] * k));
        *wnc = w;
        for l in 0..LANES {
            let terms = point_terms([xc[l], yc[l], zc[l], woc[l]], r[l], w[l]);
            for (s, t) in acc.iter_mut().zip(terms) {
                s[l] += t;
            }
        }
    }
}
