//! The frames' pixel noise, and the wider band it earns a blurred border on a noisy camera.
//!
//! More rows about a blurred border average pixel noise down, but they also reach further into
//! the wall and the land, whose shading the border model does not follow. On the paper's
//! dual-focus camera a cap of ±40 px rather than ±24 px reads 8-bit scans with 1–8 grey levels of
//! noise up to 3.4 dB better, and clean scans up to 0.5 dB worse (docs/ACCURACY.md). So the cap
//! rises from `max_band_half_height_px` to `noisy_band_half_height_px` only where the reference
//! frame's pixel noise reaches `noisy_grey_levels`; sharp borders read their narrow band either
//! way.
//!
//! The noise is Immerkær's estimate (1996): the mask N = [1 −2 1; −2 4 −2; 1 −2 1] cancels planes
//! and most smooth shading, and white noise of σ gives N ∗ I a spread of 6σ, so
//! σ = √(π/2)·mean|N ∗ I| / 6. Edges and texture raise it, so it is taken per 16 × 16 block
//! (at most 256 of them, spread over the frame: a 20th of a 1280 × 1024 frame) and the estimate
//! is a low quantile of the blocks: the smoothest parts of the frame, of which a defocused one
//! has many. It reads white noise about 8 % low.

use super::EdgeParams;
use crate::image::Image;

/// Side of a block (px).
const BLOCK_PX: usize = 16;
/// The quantile of the blocks' estimates taken.
const QUANTILE: f64 = 0.05;
/// Fewest blocks for an estimate.
const MIN_BLOCKS: usize = 16;
/// Most blocks read, spread evenly over the frame: a low quantile of a few hundred is steady,
/// and each costs time in every group.
const MAX_BLOCKS: usize = 256;

/// σ of `frame`'s pixel noise in its grey units (1 = white); None when the frame holds fewer
/// than [`MIN_BLOCKS`] finite blocks.
#[must_use]
pub(super) fn pixel_noise(frame: &Image) -> Option<f64> {
    let (w, h) = (frame.width, frame.height);
    if w < BLOCK_PX + 2 || h < BLOCK_PX + 2 || frame.data.len() != w * h {
        return None;
    }
    // Blocks on the interior: the mask reaches one pixel past them.
    let (across, down) = ((w - 2) / BLOCK_PX, (h - 2) / BLOCK_PX);
    let step = ((across * down) as f64 / MAX_BLOCKS as f64)
        .sqrt()
        .ceil()
        .max(1.0) as usize;
    let row = |y: usize| &frame.data[y * w..(y + 1) * w];
    let mut estimates = Vec::new();
    for y0 in (0..down).step_by(step).map(|j| 1 + j * BLOCK_PX) {
        for x0 in (0..across).step_by(step).map(|i| 1 + i * BLOCK_PX) {
            let mut sum = 0.0_f64;
            for y in y0..y0 + BLOCK_PX {
                let (a, b, c) = (row(y - 1), row(y), row(y + 1));
                for x in x0..x0 + BLOCK_PX {
                    // [1 −2 1] along each row, the rows weighted 1, −2, 1.
                    let line = |r: &[f32]| {
                        f64::from(r[x - 1]) - 2.0 * f64::from(r[x]) + f64::from(r[x + 1])
                    };
                    sum += (line(a) - 2.0 * line(b) + line(c)).abs();
                }
            }
            let mean = sum / (BLOCK_PX * BLOCK_PX) as f64;
            if mean.is_finite() {
                estimates.push(std::f64::consts::FRAC_PI_2.sqrt() * mean / 6.0);
            }
        }
    }
    if estimates.len() < MIN_BLOCKS {
        return None;
    }
    let k = (QUANTILE * (estimates.len() - 1) as f64) as usize;
    let (_, v, _) = estimates.select_nth_unstable_by(k, f64::total_cmp);
    Some(*v)
}

/// `params` with the band cap raised to `noisy_band_half_height_px` where the pixel noise of
/// `frame` (a frame of the group, grey in `[0, 1]`) reaches `noisy_grey_levels` of 255, and that
/// noise in grey levels of 255 (None where the frame is too small to say).
#[must_use]
pub(super) fn capped_for_noise(params: &EdgeParams, frame: &Image) -> (EdgeParams, Option<f64>) {
    let levels = pixel_noise(frame).map(|s| s * 255.0);
    let mut capped = params.clone();
    if params.noisy_band_half_height_px > params.max_band_half_height_px
        && levels.is_some_and(|l| l >= params.noisy_grey_levels)
    {
        capped.max_band_half_height_px = params.noisy_band_half_height_px;
    }
    (capped, levels)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::noise::Rng;

    /// A shaded frame with a sharp bright stripe, and white noise of `sigma`.
    fn frame(sigma: f64, seed: u64) -> Image {
        let (w, h) = (320, 256);
        let mut rng = Rng::new(seed);
        let mut img = Image::zeros(w, h);
        for y in 0..h {
            for x in 0..w {
                let shade = 0.3 + 0.2 * (x as f64 / w as f64) + 0.1 * (y as f64 / h as f64).powi(2);
                let stripe = if (100..140).contains(&y) { 0.3 } else { 0.0 };
                img.data[y * w + x] = (shade + stripe + sigma * rng.gaussian()) as f32;
            }
        }
        img
    }

    #[test]
    fn reads_white_noise_through_shading_and_an_edge() {
        for (sigma, seed) in [(1.0 / 255.0, 1), (4.0 / 255.0, 2), (0.02, 3)] {
            let s = pixel_noise(&frame(sigma, seed)).unwrap();
            assert!(
                (0.8 * sigma..=1.05 * sigma).contains(&s),
                "σ {sigma}: read {s}"
            );
        }
        // No noise: shading and the stripe's edges read as none.
        assert!(pixel_noise(&frame(0.0, 4)).unwrap() < 1e-6);
        assert_eq!(pixel_noise(&Image::zeros(17, 300)), None);
    }

    #[test]
    fn the_cap_rises_on_a_noisy_frame_only() {
        let p = EdgeParams::default();
        let (clean, levels) = capped_for_noise(&p, &frame(0.3 / 255.0, 5));
        assert_eq!(clean, p);
        assert!(
            levels.is_some_and(|l| (0.24..=0.32).contains(&l)),
            "{levels:?}"
        );
        let (noisy, _) = capped_for_noise(&p, &frame(2.0 / 255.0, 6));
        assert_eq!(noisy.max_band_half_height_px, p.noisy_band_half_height_px);
        assert_eq!(
            EdgeParams {
                max_band_half_height_px: p.max_band_half_height_px,
                ..noisy
            },
            p
        );
        // A noisy cap at or below the plain one: unchanged.
        let off = EdgeParams {
            noisy_band_half_height_px: p.max_band_half_height_px,
            ..p.clone()
        };
        assert_eq!(capped_for_noise(&off, &frame(2.0 / 255.0, 6)).0, off);
    }
}
