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

fn transpose(img: &Image) -> Image {
    let (w, h) = (img.width, img.height);
    let mut out = vec![0.0f32; w * h];
    out.par_chunks_mut(h.max(1))
        .enumerate()
        .for_each(|(x, col)| {
            for (y, v) in col.iter_mut().enumerate() {
                *v = img.data[y * w + x];
            }
        });
    Image {
        width: h,
        height: w,
        data: out,
    }
}

/// Convolves every row with a symmetric kernel (clamped borders).
fn rows_kernel(img: &mut Image, kernel: &[f32]) {
    let w = img.width;
    let r = kernel.len() / 2;
    img.data.par_chunks_mut(w.max(1)).for_each_init(
        || vec![0.0f32; w + 2 * r],
        |pad, row| {
            let first = row.first().copied().unwrap_or(0.0);
            let last = row.last().copied().unwrap_or(0.0);
            pad[..r].fill(first);
            pad[r..r + w].copy_from_slice(row);
            pad[r + w..].fill(last);
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
            let first = row.first().copied().unwrap_or(0.0);
            let last = row.last().copied().unwrap_or(0.0);
            pad[..r].fill(first);
            pad[r..r + w].copy_from_slice(row);
            pad[r + w..].fill(last);
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
        let r = ((0.25 + sigma * sigma).sqrt() - 0.5).round().max(1.0) as usize;
        for _ in 0..3 {
            rows_box(img, r);
        }
    }
}

/// Gaussian blur of σ px in both directions.
#[must_use]
pub fn gaussian_blur(img: &Image, sigma: f64) -> Image {
    let mut a = img.clone();
    rows_gauss(&mut a, sigma);
    let mut t = transpose(&a);
    rows_gauss(&mut t, sigma);
    transpose(&t)
}

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

impl BlurStack {
    /// Blurs `sharp` with a per-pixel Gaussian σ (px) from `sigma`, interpolating between the
    /// levels of [`BLUR_LEVELS_PX`]. Levels above the largest σ present are skipped.
    #[must_use]
    pub fn apply(sharp: &Image, sigma: &Image) -> Image {
        let max_sigma = sigma.data.iter().fold(0.0f32, |m, &v| m.max(v));
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
            out.data
                .par_iter_mut()
                .zip(level.data.par_iter())
                .zip(sigma.data.par_iter())
                .for_each(|((o, &l), &sp)| {
                    let wgt = hat(&BLUR_LEVELS_PX, i, f64::from(sp));
                    if wgt > 0.0 {
                        *o += wgt * l;
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
