//! Peaks of the accumulator: global maxima with window suppression, and their sub-bin ρ.

use super::*;

/// Finds up to `params.peak_count` global maxima with at least `min_votes` votes (and at least
/// `params.min_peak_ratio` of the first peak's votes), suppressing
/// each peak's window (±window_theta_deg, ±window_rho_px) before looking for the next, and
/// returns them sorted top to bottom (by row at the centre column). A maximum whose line crosses
/// a chosen peak's line inside the frame, or comes within a window half-width of it, is another
/// tangent of the same (curved) stripe and is skipped.
#[must_use]
pub fn find_peaks(acc: &Accumulator, params: &HoughParams, min_votes: u32) -> Vec<Peak> {
    let nr = acc.rho_bins;
    let nt = acc.theta_bins();
    if nr == 0 || nt == 0 {
        return Vec::new();
    }
    let wt = (params.window_theta_deg / params.theta_step_deg).round() as usize;
    let wr = (params.window_rho_px / acc.rho_step_px).round() as usize;
    let band = (params.peak_rho_band_px / acc.rho_step_px).round() as usize;
    let mut work = if band == 0 {
        acc.votes.clone()
    } else {
        band_sums(acc, band)
    };
    let mut peaks: Vec<Peak> = Vec::with_capacity(params.peak_count);
    'next_peak: while peaks.len() < params.peak_count {
        let Some((best, &votes)) = work
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(&a.0)))
        else {
            break;
        };
        let ratio_floor = peaks
            .first()
            .map_or(0.0, |p: &Peak| p.votes as f32 * params.min_peak_ratio);
        if votes < min_votes || votes == 0 || (votes as f32) < ratio_floor {
            break;
        }
        let (t, r) = (best / nr, best % nr);
        for tt in t.saturating_sub(wt)..=(t + wt).min(nt - 1) {
            let row = tt * nr;
            for rr in r.saturating_sub(wr)..=(r + wr).min(nr - 1) {
                if let Some(v) = work.get_mut(row + rr) {
                    *v = 0;
                }
            }
        }
        let theta_rad = acc.thetas_rad.get(t).copied().unwrap_or(0.0);
        let peak = Peak {
            theta_rad,
            rho_px: if band == 0 {
                refine_rho(acc, t, r, wr)
            } else {
                band_centroid(acc, t, r, band)
            },
            votes,
            x_origin_px: acc.x_origin_px,
            window_theta_rad: params.window_theta_deg.to_radians(),
            window_rho_px: params.window_rho_px,
        };
        // Distinct stripes never cross: a maximum whose line crosses, or comes within a window
        // half-width of, a chosen line inside the frame is another part of that stripe (a curved
        // stripe votes for several tangents), not a new one.
        if peaks.iter().any(|p| same_stripe(p, &peak)) {
            continue 'next_peak;
        }
        peaks.push(peak);
    }
    let x0 = acc.x_origin_px;
    peaks.sort_by(|a, b| a.row_at_px(x0).total_cmp(&b.row_at_px(x0)));
    peaks
}

/// True when the lines of `a` and `b` cross inside the frame (columns 0..=2·x₀) or come closer
/// than `a`'s window half-width in ρ there.
pub(super) fn same_stripe(a: &Peak, b: &Peak) -> bool {
    let right = 2.0 * a.x_origin_px;
    let d0 = a.row_at_px(0.0) - b.row_at_px(0.0);
    let d1 = a.row_at_px(right) - b.row_at_px(right);
    !(d0.is_finite() && d1.is_finite())
        || d0.signum() != d1.signum()
        || d0.abs().min(d1.abs()) < a.window_rho_px
}

/// Each θ row's votes summed over ±`band` ρ bins (clipped at the ends).
pub(super) fn band_sums(acc: &Accumulator, band: usize) -> Vec<u32> {
    let nr = acc.rho_bins;
    let mut out = vec![0u32; acc.votes.len()];
    out.par_chunks_mut(nr)
        .zip(acc.votes.par_chunks(nr))
        .for_each(|(o, row)| {
            let mut prefix = Vec::with_capacity(nr + 1);
            prefix.push(0u64);
            let mut total = 0u64;
            for &v in row {
                total += u64::from(v);
                prefix.push(total);
            }
            for (r, slot) in o.iter_mut().enumerate() {
                let lo = r.saturating_sub(band);
                let hi = (r + band + 1).min(nr);
                let sum =
                    prefix.get(hi).copied().unwrap_or(0) - prefix.get(lo).copied().unwrap_or(0);
                *slot = u32::try_from(sum).unwrap_or(u32::MAX);
            }
        });
    out
}

/// Vote-weighted mean ρ of the bins within ±`band` of bin `r` at θ bin `t` (the centre of a
/// wiggling stripe's votes).
pub(super) fn band_centroid(acc: &Accumulator, t: usize, r: usize, band: usize) -> f32 {
    let mut sum = 0.0_f64;
    let mut weight = 0.0_f64;
    for rr in r.saturating_sub(band)..=(r + band).min(acc.rho_bins.saturating_sub(1)) {
        let v = f64::from(acc.get(t, rr));
        sum += v * rr as f64;
        weight += v;
    }
    let bin = if weight > 0.0 { sum / weight } else { r as f64 };
    acc.rho_min_px + bin as f32 * acc.rho_step_px
}

/// Vote-weighted centroid of the contiguous ρ bins (within ±`wr`) around peak bin `r` at θ bin `t`
/// that hold at least [`RHO_REFINE_FRACTION`] of its votes: the centre of a thick stripe.
pub(super) fn refine_rho(acc: &Accumulator, t: usize, r: usize, wr: usize) -> f32 {
    let peak = acc.get(t, r) as f32;
    let floor = peak * RHO_REFINE_FRACTION;
    let mut sum = 0.0_f64;
    let mut weight = 0.0_f64;
    let mut add = |rr: usize| {
        let v = acc.get(t, rr) as f32;
        if v >= floor && v > 0.0 {
            sum += f64::from(v) * rr as f64;
            weight += f64::from(v);
            true
        } else {
            false
        }
    };
    add(r);
    for rr in (r + 1)..=(r + wr).min(acc.rho_bins.saturating_sub(1)) {
        if !add(rr) {
            break;
        }
    }
    for rr in (r.saturating_sub(wr)..r).rev() {
        if !add(rr) {
            break;
        }
    }
    let bin = if weight > 0.0 {
        (sum / weight) as f32
    } else {
        r as f32
    };
    acc.rho_min_px + bin * acc.rho_step_px
}
