//! Spatially varying defocus blur: a stack of ever more Gaussian-blurred copies of the sharp
//! frame, blended per pixel by its σ (hat weights between neighbouring levels).

use rayon::prelude::*;

use crate::image::Image;

/// The blur levels (Gaussian σ, px) of the stack; larger σ is clamped to the last level.
pub const BLUR_LEVELS_PX: [f64; 13] = [
    0.0, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0, 12.0, 16.0, 24.0, 32.0,
];
/// Increments up to this σ use an exact Gaussian kernel; larger ones three box passes.
const EXACT_GAUSS_MAX_SIGMA_PX: f64 = 3.0;

/// Namespace of the blur-stack renderer.
pub struct BlurStack;

/// Copies `row` into `pad` from index `r` on, and fills the rest of `pad` on either side with
/// the row's end values (clamped borders).
fn pad_clamped(pad: &mut [f32], row: &[f32], r: usize) {
    let first = row.first().copied().unwrap_or(0.0);
    let last = row.last().copied().unwrap_or(0.0);
    pad[..r].fill(first);
    pad[r..r + row.len()].copy_from_slice(row);
    pad[r + row.len()..].fill(last);
}

/// Convolves every row with a symmetric kernel (clamped borders).
fn rows_kernel(img: &mut Image, kernel: &[f32]) {
    let w = img.width;
    let r = kernel.len() / 2;
    img.data.par_chunks_mut(w.max(1)).for_each_init(
        || vec![0.0f32; w + 2 * r],
        |pad, row| {
            pad_clamped(pad, row, r);
            for (x, v) in row.iter_mut().enumerate() {
                *v = pad[x..x + kernel.len()]
                    .iter()
                    .zip(kernel)
                    .map(|(a, b)| a * b)
                    .sum();
            }
        },
    );
}

/// Running-mean box filter of half-width `r` along every row (clamped borders).
fn rows_box(img: &mut Image, r: usize) {
    let w = img.width;
    let norm = 1.0 / (2 * r + 1) as f64;
    img.data.par_chunks_mut(w.max(1)).for_each_init(
        || vec![0.0f32; w + 2 * r + 1],
        |pad, row| {
            pad_clamped(pad, row, r);
            let mut acc: f64 = pad[..2 * r + 1].iter().map(|&v| f64::from(v)).sum();
            for x in 0..w {
                row[x] = (acc * norm) as f32;
                acc += f64::from(pad[x + 2 * r + 1]) - f64::from(pad[x]);
            }
        },
    );
}

fn gauss_kernel(sigma: f64) -> Vec<f32> {
    let r = (3.0 * sigma).ceil().max(1.0) as usize;
    let mut k: Vec<f64> = (0..=2 * r)
        .map(|i| {
            let d = i as f64 - r as f64;
            (-0.5 * d * d / (sigma * sigma)).exp()
        })
        .collect();
    let sum: f64 = k.iter().sum();
    for v in &mut k {
        *v /= sum;
    }
    k.into_iter().map(|v| v as f32).collect()
}

/// Blurs rows by σ: exact Gaussian when small, else three boxes of matching variance.
fn rows_gauss(img: &mut Image, sigma: f64) {
    if sigma <= 0.0 {
        return;
    }
    if sigma <= EXACT_GAUSS_MAX_SIGMA_PX {
        rows_kernel(img, &gauss_kernel(sigma));
    } else {
        // Three boxes of half-width r have variance 3·((2r+1)² − 1)/12 = r(r+1).
        let r = box_radius(sigma);
        for _ in 0..3 {
            rows_box(img, r);
        }
    }
}

/// Convolves every column with a symmetric kernel (clamped borders), whole rows at a time.
fn cols_kernel(img: &Image, kernel: &[f32]) -> Image {
    let (w, h) = (img.width, img.height);
    let r = kernel.len() / 2;
    let mut out = Image::zeros(w, h);
    out.data
        .par_chunks_mut(w.max(1))
        .enumerate()
        .for_each(|(y, orow)| {
            for (k, &wk) in kernel.iter().enumerate() {
                let src = (y + k).saturating_sub(r).min(h - 1);
                for (o, &v) in orow.iter_mut().zip(img.row(src)) {
                    *o += wk * v;
                }
            }
        });
    out
}

/// Box filter of half-width `r` along every column (clamped borders): a running sum of whole
/// rows, down the image.
fn cols_box(img: &Image, r: usize) -> Image {
    let (w, h) = (img.width, img.height);
    let row = |y: isize| img.row(y.clamp(0, h as isize - 1) as usize);
    let mut acc = vec![0.0f64; w];
    for k in -(r as isize)..=(r as isize) {
        for (a, &v) in acc.iter_mut().zip(row(k)) {
            *a += f64::from(v);
        }
    }
    let norm = 1.0 / (2 * r + 1) as f64;
    let mut out = Image::zeros(w, h);
    for (y, orow) in out.data.chunks_mut(w.max(1)).enumerate() {
        let (add, sub) = (
            row(y as isize + r as isize + 1),
            row(y as isize - r as isize),
        );
        for (((o, a), &p), &m) in orow.iter_mut().zip(acc.iter_mut()).zip(add).zip(sub) {
            *o = (*a * norm) as f32;
            *a += f64::from(p) - f64::from(m);
        }
    }
    out
}

/// Blurs columns by σ: exact Gaussian when small, else three boxes of matching variance.
fn cols_gauss(img: &Image, sigma: f64) -> Image {
    if sigma <= 0.0 {
        return img.clone();
    }
    if sigma <= EXACT_GAUSS_MAX_SIGMA_PX {
        cols_kernel(img, &gauss_kernel(sigma))
    } else {
        let r = box_radius(sigma);
        let a = cols_box(img, r);
        let b = cols_box(&a, r);
        cols_box(&b, r)
    }
}

/// Half-width of three boxes with the variance of a Gaussian of σ: r(r+1) = σ².
fn box_radius(sigma: f64) -> usize {
    ((0.25 + sigma * sigma).sqrt() - 0.5).round().max(1.0) as usize
}

/// Gaussian blur of σ px in both directions (clamped borders).
#[must_use]
pub fn gaussian_blur(img: &Image, sigma: f64) -> Image {
    if img.data.is_empty() {
        return img.clone();
    }
    let mut a = img.clone();
    rows_gauss(&mut a, sigma);
    cols_gauss(&a, sigma)
}

#[cfg(test)]
fn hat(levels: &[f64], i: usize, s: f64) -> f32 {
    let c = levels[i];
    let last = levels.len() - 1;
    let w = if s >= c {
        if i == last {
            1.0
        } else {
            1.0 - (s - c) / (levels[i + 1] - c)
        }
    } else if i == 0 {
        0.0
    } else {
        1.0 - (c - s) / (c - levels[i - 1])
    };
    w.clamp(0.0, 1.0) as f32
}

/// Level index below σ and the weight of the level above (hat interpolation).
fn level_of(sigma: f64) -> (u8, f32) {
    let last = BLUR_LEVELS_PX.len() - 1;
    if sigma.is_nan() || sigma <= 0.0 {
        return (0, 0.0);
    }
    if sigma >= BLUR_LEVELS_PX[last] {
        return (last as u8, 0.0);
    }
    let i = BLUR_LEVELS_PX.partition_point(|&l| l <= sigma) - 1;
    let f = (sigma - BLUR_LEVELS_PX[i]) / (BLUR_LEVELS_PX[i + 1] - BLUR_LEVELS_PX[i]);
    (i as u8, f as f32)
}

impl BlurStack {
    /// Blurs `sharp` with a per-pixel Gaussian σ (px) from `sigma`, interpolating between the
    /// levels of [`BLUR_LEVELS_PX`]. Levels above the largest σ present are skipped.
    #[must_use]
    pub fn apply(sharp: &Image, sigma: &Image) -> Image {
        let max_sigma = sigma.data.iter().fold(0.0f32, |m, &v| m.max(v));
        let slots: Vec<(u8, f32)> = sigma
            .data
            .par_iter()
            .map(|&s| level_of(f64::from(s)))
            .collect();
        let mut out = Image::zeros(sharp.width, sharp.height);
        let mut level = sharp.clone();
        let mut prev_sigma = 0.0;
        for (i, &s) in BLUR_LEVELS_PX.iter().enumerate() {
            if i > 0 {
                if BLUR_LEVELS_PX[i - 1] > f64::from(max_sigma) {
                    break;
                }
                let inc = (s * s - prev_sigma * prev_sigma).sqrt();
                level = gaussian_blur(&level, inc);
            }
            prev_sigma = s;
            let i = i as u8;
            out.data
                .par_iter_mut()
                .zip(level.data.par_iter())
                .zip(slots.par_iter())
                .for_each(|((o, &l), &(k, f))| {
                    if k == i {
                        *o += (1.0 - f) * l;
                    } else if k.wrapping_add(1) == i {
                        *o += f * l;
                    }
                });
        }
        out
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may panic
mod tests {
    use super::*;

    #[test]
    fn level_slots_match_the_hat_weights() {
        for s in [0.0, 0.3, 1.0, 2.7, 9.0, 31.0, 40.0] {
            let (k, f) = level_of(s);
            for i in 0..BLUR_LEVELS_PX.len() {
                let want = hat(&BLUR_LEVELS_PX, i, s);
                let got = if i == usize::from(k) {
                    1.0 - f
                } else if i == usize::from(k) + 1 {
                    f
                } else {
                    0.0
                };
                assert!((got - want).abs() < 1e-6, "{s} level {i}: {got} {want}");
            }
        }
    }

    #[test]
    fn hat_weights_sum_to_one() {
        for s in [0.0, 0.3, 1.0, 2.7, 9.0, 31.0, 40.0] {
            let total: f32 = (0..BLUR_LEVELS_PX.len())
                .map(|i| hat(&BLUR_LEVELS_PX, i, s))
                .sum();
            assert!((total - 1.0).abs() < 1e-6, "{s}: {total}");
        }
    }

    #[test]
    fn blur_keeps_the_mean_and_has_the_right_width() {
        let mut img = Image::zeros(101, 101);
        img.data[50 * 101 + 50] = 1.0;
        for sigma in [1.5, 6.0] {
            let b = gaussian_blur(&img, sigma);
            let total: f32 = b.data.iter().sum();
            assert!((total - 1.0).abs() < 1e-3, "{total}");
            let var: f64 = (0..101)
                .map(|x| f64::from(b.data[50 * 101 + x]) * ((x as f64 - 50.0).powi(2)))
                .sum::<f64>()
                / (0..101)
                    .map(|x| f64::from(b.data[50 * 101 + x]))
                    .sum::<f64>();
            assert!(
                (var.sqrt() - sigma).abs() < 0.15 * sigma,
                "{sigma}: {}",
                var.sqrt()
            );
        }
    }

    #[test]
    fn zero_sigma_keeps_the_image_and_large_sigma_flattens_it() {
        let img = Image::from_fn(64, 48, |x, y| ((x * 7 + y * 3) % 5) as f32 / 4.0);
        let sharp = BlurStack::apply(&img, &Image::zeros(64, 48));
        assert_eq!(sharp, img);
        let flat = BlurStack::apply(&img, &Image::filled(64, 48, 24.0));
        let (lo, hi) = flat.finite_range().unwrap();
        assert!(hi - lo < 0.05, "{lo} {hi}");
    }
}
