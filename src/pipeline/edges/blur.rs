//! The band a border's fine fits read, sized to that border's blur in the group.
//!
//! The border model fits a level on each side of the edge, so its band must reach past the
//! edge's spread on both sides, and its width bound must admit the true spread. With a band of
//! ±8 px and σ ≤ 4 px on a defocused border (the small dual-focus camera's are σ ≈ 8 and 17 px,
//! the paper's dual-focus camera's 15–35 px), the position trades against the levels: the fit
//! settles near wherever the band was centred, the predicted row, and moves by pixels for
//! inputs that differ in the eighth decimal (docs/ACCURACY.md).
//!
//! So when the coarse strips read a border wider than a third of `band_half_height_px`, a few
//! pilot fits on the reference frame, with a wide band, measure the group's edge spread σ, and
//! every fit of the border then reads `band_sigmas`·σ on each side (never less than
//! `band_half_height_px`, never more than `max_band_half_height_px`, which bounds the cost,
//! nor half the way to the next border), with the width bound raised to twice σ. A sharp border
//! keeps the knobs as they are, and its fits are unchanged.

use super::EdgeParams;

/// Pilot fits per border and group, spread over its samples.
const PILOT_SAMPLES: usize = 9;
/// Widest band a pilot reads (px on each side).
const PILOT_BAND_PX: f64 = 32.0;

/// `params` with the band and the width bound sized to the border's blur. `strip_widths` are
/// the edge spreads σ (px) of its coarse strips (they read a moving border wider than it is, so
/// when their median times `band_sigmas` is within the band, the border is sharp enough and no
/// pilot runs), `samples` the border's sample count, `gap_px` the rows to the nearest other
/// border of the groove (NaN: unknown), and `width_at(i, pilot)` the σ that sample `i` fits
/// with the pilot's knobs (None where it fits none).
pub(super) fn sized_to_blur(
    params: &EdgeParams,
    strip_widths: &[f64],
    samples: usize,
    gap_px: f64,
    width_at: &dyn Fn(usize, &EdgeParams) -> Option<f64>,
) -> EdgeParams {
    let sharp = super::finite_median(strip_widths.to_vec())
        .is_some_and(|w| params.band_sigmas * w <= params.band_half_height_px);
    if params.band_sigmas <= 0.0 || samples == 0 || sharp {
        return params.clone();
    }
    // Half the way to the next border.
    let gap_limit = if gap_px.is_finite() && gap_px > 0.0 {
        0.5 * gap_px
    } else {
        PILOT_BAND_PX
    }
    .max(params.band_half_height_px);
    let mut pilot = params.clone();
    pilot.band_half_height_px = PILOT_BAND_PX.min(gap_limit);
    pilot.border.max_width_px = params
        .border
        .max_width_px
        .max(0.5 * pilot.band_half_height_px);
    let picks = PILOT_SAMPLES.min(samples);
    let widths: Vec<f64> = (0..picks)
        .filter_map(|k| {
            // Evenly spread, both ends included.
            let i = if picks > 1 {
                k * (samples - 1) / (picks - 1)
            } else {
                samples / 2
            };
            width_at(i, &pilot)
        })
        .collect();
    let Some(sigma) = super::finite_median(widths) else {
        return params.clone();
    };
    let mut sized = params.clone();
    let limit = gap_limit
        .min(params.max_band_half_height_px)
        .max(params.band_half_height_px);
    sized.band_half_height_px =
        (params.band_sigmas * sigma).clamp(params.band_half_height_px, limit);
    // Twice the measured σ: a band capped below three σ still fits the edge's true spread
    // rather than a narrower one that would pull the position toward the band's centre.
    sized.border.max_width_px = params
        .border
        .max_width_px
        .max(0.5 * sized.band_half_height_px)
        .max(2.0 * sigma);
    sized
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_band_follows_the_blur_within_its_limits() {
        let params = EdgeParams::default();
        let sized = |sigma: f64, gap: f64| {
            sized_to_blur(&params, &[4.0], 100, gap, &|_, pilot: &EdgeParams| {
                Some(sigma.min(pilot.border.max_width_px))
            })
        };
        // Sharp: the knobs as they are.
        assert_eq!(sized(0.3, 200.0), params);
        // Sharp enough in the coarse strips: no pilot.
        let first = [0.3, 0.31, 2.5];
        let kept = sized_to_blur(&params, &first, 100, 200.0, &|_, _| panic!("no pilot"));
        assert_eq!(kept, params);
        // σ 6 px: 3σ on each side, the width free to twice σ.
        let s = sized(6.0, 200.0);
        assert_eq!(s.band_half_height_px, 18.0);
        assert_eq!(s.border.max_width_px, 12.0);
        // Never past max_band_half_height_px (24) …
        let s = sized(10.0, 200.0);
        assert_eq!(s.band_half_height_px, 24.0);
        assert_eq!(s.border.max_width_px, 20.0);
        // … nor half the way to the next border.
        let s = sized(6.0, 30.0);
        assert_eq!(s.band_half_height_px, 15.0);
        // A pilot that finds nothing, or a band_sigmas of 0: unchanged.
        assert_eq!(
            sized_to_blur(&params, &[4.0], 100, 200.0, &|_, _| None),
            params
        );
        let off = EdgeParams {
            band_sigmas: 0.0,
            ..EdgeParams::default()
        };
        assert_eq!(
            sized_to_blur(&off, &[4.0], 100, 200.0, &|_, _| panic!(
                "no pilot when off"
            )),
            off
        );
    }

    #[test]
    fn the_pilots_spread_over_the_samples() {
        let seen = std::cell::RefCell::new(Vec::new());
        let _ = sized_to_blur(&EdgeParams::default(), &[], 17, f64::NAN, &|i, _| {
            seen.borrow_mut().push(i);
            Some(1.0)
        });
        assert_eq!(*seen.borrow(), vec![0, 2, 4, 6, 8, 10, 12, 14, 16]);
    }
}
