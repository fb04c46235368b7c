//! Stitching: every group's samples onto one uniform grid of groove positions by cubic Lagrange interpolation, cross-faded where groups overlap.

use super::*;

/// Smallest cross-fade weight inside a group's span (its very first/last sample would get 0,
/// which would leave a point covered only there without data).
pub(super) const MIN_FADE_WEIGHT: f64 = 1e-6;
/// Largest stitched signal (samples per channel), against runaway allocations from a tiny spacing.
pub(super) const MAX_STITCH_SAMPLES: f64 = 268_435_456.0;
/// Grid points this close (in spacings) outside a group's span still count as inside it.
pub(super) const SPAN_TOL_SPACINGS: f64 = 1e-9;
/// A continuous signal on a uniform grid of groove positions.
#[derive(Clone, Debug, PartialEq)]
pub struct StitchedSignal {
    /// Position of sample 0 (µm).
    pub start_um: f64,
    /// Sample spacing (µm).
    pub spacing_um: f64,
    /// Native sample rate = Vt / spacing (Hz).
    pub native_rate_hz: f64,
    /// Channels, velocity mm/s (gaps filled with 0 and listed in `gaps`).
    pub channels: Vec<Vec<f32>>,
    /// Sample ranges where at least one channel had no data (filled with silence), merged.
    pub gaps: Vec<Range<usize>>,
}

/// Value of one group channel at `p`, which lies in segment `[pos[j], pos[j+1]]`: a cubic through
/// four consecutive finite samples around the segment (centred j−1..=j+2 where possible,
/// one-sided at a group end or next to a gap), else a quadratic, else linear. None when either
/// segment end is a gap.
pub(super) fn interpolate(pos: &[f64], val: &[f32], j: usize, p: f64) -> Option<f64> {
    let ok = |k: usize| val.get(k).is_some_and(|v| v.is_finite());
    if !ok(j) || !ok(j + 1) {
        return None;
    }
    // Candidate first nodes, most centred first, for 4 then 3 nodes.
    let window = [(4usize, 1usize), (4, 0), (4, 2), (3, 1), (3, 0), (2, 0)]
        .into_iter()
        .find_map(|(len, back)| {
            let lo = j.checked_sub(back)?;
            (lo..lo + len).all(ok).then_some((lo, len))
        });
    let (lo, len) = window.unwrap_or((j, 2));
    let mut nodes = [(0.0, 0.0); 4];
    for (node, k) in nodes.iter_mut().zip(lo..lo + len) {
        *node = (*pos.get(k)?, f64::from(*val.get(k)?));
    }
    Some(crate::pipeline::lagrange(&nodes[..len], p))
}

/// Stitches group signals onto one uniform grid from the smallest to the largest sample
/// position, cross-fading where groups overlap so seams do not click (see the module docs).
/// Grid points no group covers are 0 and listed in `gaps`. The native rate uses the mean Vt.
///
/// # Errors
/// [`StageError`] when there are no groups or samples, channel counts or lengths differ, a
/// position is NaN, or the spacing is not positive.
#[allow(clippy::too_many_lines)] // one pass: validate, size the grid, accumulate, normalise
pub fn stitch<S: GroupSignals + ?Sized>(
    groups: &S,
    spacing_um: f64,
) -> Result<StitchedSignal, StageError> {
    check_range(
        "sound.native_spacing_um",
        spacing_um,
        f64::MIN_POSITIVE,
        f64::MAX,
    )?;
    let bad = |problem: String| StageError::BadInput {
        stage: "stitch",
        problem,
    };
    let Some(first) = groups.view(0) else {
        return Err(bad("no groups".to_string()));
    };
    let n_channels = first.channel_count();
    if n_channels == 0 {
        return Err(bad(format!("group {} has no channel", first.group)));
    }
    let (mut lo_um, mut hi_um) = (f64::INFINITY, f64::NEG_INFINITY);
    let (mut vt_sum, mut vt_count) = (0.0, 0.0);
    for g in groups.views() {
        if g.channel_count() != n_channels {
            return Err(bad(format!(
                "group {} has {} channels, group {} has {n_channels}",
                g.group,
                g.channel_count(),
                first.group
            )));
        }
        if !g.lengths_agree() {
            return Err(bad(format!(
                "group {}: channel and position lengths differ",
                g.group
            )));
        }
        if g.positions_um.iter().any(|p| !p.is_finite())
            || g.positions_um.windows(2).any(|w| w[1] < w[0])
        {
            return Err(bad(format!(
                "group {}: positions must be finite and increasing",
                g.group
            )));
        }
        if let (Some(&a), Some(&b)) = (g.positions_um.first(), g.positions_um.last()) {
            lo_um = lo_um.min(a);
            hi_um = hi_um.max(b);
        }
        if g.groove_speed_mm_s.is_finite() && g.groove_speed_mm_s > 0.0 {
            vt_sum += g.groove_speed_mm_s;
            vt_count += 1.0;
        }
    }
    if !lo_um.is_finite() {
        return Err(bad("no samples in any group".to_string()));
    }
    if vt_count == 0.0 {
        return Err(bad("no group has a positive groove speed".to_string()));
    }
    let steps = ((hi_um - lo_um) / spacing_um + SPAN_TOL_SPACINGS).floor();
    if steps.is_nan() || steps >= MAX_STITCH_SAMPLES {
        return Err(StageError::InvalidParam {
            name: "sound.native_spacing_um".to_string(),
            problem: format!(
                "{spacing_um} µm over {} µm makes more than {MAX_STITCH_SAMPLES} samples",
                hi_um - lo_um
            ),
        });
    }
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // checked above
    let n = steps as usize + 1;

    // Each group's cross-fade ramp: its longest overlap with another group, at least one spacing
    // and at most half its span.
    let spans: Vec<(f64, f64)> = groups
        .views()
        .map(|g| match (g.positions_um.first(), g.positions_um.last()) {
            (Some(&a), Some(&b)) => (a, b),
            _ => (f64::NAN, f64::NAN),
        })
        .collect();
    let mut order: Vec<usize> = (0..groups.group_count())
        .filter(|&i| spans[i].0.is_finite())
        .collect();
    order.sort_by(|&a, &b| spans[a].0.total_cmp(&spans[b].0));
    let mut overlap = vec![0.0f64; groups.group_count()];
    for (k, &i) in order.iter().enumerate() {
        for &j in &order[k + 1..] {
            if spans[j].0 >= spans[i].1 {
                break;
            }
            let ov = spans[i].1.min(spans[j].1) - spans[j].0;
            overlap[i] = overlap[i].max(ov);
            overlap[j] = overlap[j].max(ov);
        }
    }

    // One channel at a time, so the accumulators are one channel long (a clip's eight
    // border tracks would otherwise need 128 bytes a grid point); every sum still adds its
    // groups in group order.
    let mut sums = vec![0.0f64; n];
    let mut weights = vec![0.0f64; n];
    let mut missing = vec![false; n];
    let mut channels = Vec::with_capacity(n_channels);
    let tol_um = SPAN_TOL_SPACINGS * spacing_um;
    for c in 0..n_channels {
        sums.fill(0.0);
        weights.fill(0.0);
        for (gi, g) in groups.views().enumerate() {
            let (a, b) = spans[gi];
            let ch = g.channel(c);
            if !a.is_finite() || g.positions_um.len() < 2 {
                // A lone sample: it lands on the nearest grid point only if it is on one.
                if let (Some(&p), true) = (g.positions_um.first(), g.positions_um.len() == 1) {
                    let k = ((p - lo_um) / spacing_um).round();
                    if ((lo_um + k * spacing_um) - p).abs() <= tol_um {
                        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                        let k = k as usize;
                        if let Some(&v) = ch.first().filter(|v| v.is_finite())
                            && k < n
                        {
                            sums[k] += MIN_FADE_WEIGHT * f64::from(v);
                            weights[k] += MIN_FADE_WEIGHT;
                        }
                    }
                }
                continue;
            }
            let ramp_um = overlap[gi]
                .max(spacing_um)
                .min(((b - a) / 2.0).max(spacing_um));
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // inside 0..n
            let k0 = ((a - lo_um - tol_um) / spacing_um).ceil().max(0.0) as usize;
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            let k1 = (((b - lo_um + tol_um) / spacing_um).floor().max(0.0) as usize).min(n - 1);
            let pos = g.positions_um;
            let mut j = 0usize;
            #[allow(clippy::cast_precision_loss)] // grid indices ≤ 2^28
            for k in k0..=k1 {
                let p = (lo_um + k as f64 * spacing_um).clamp(a, b);
                while j + 2 < pos.len() && pos[j + 1] < p {
                    j += 1;
                }
                let w = ((p - a).min(b - p) / ramp_um).clamp(MIN_FADE_WEIGHT, 1.0);
                if let Some(v) = interpolate(pos, ch, j, p) {
                    sums[k] += w * v;
                    weights[k] += w;
                }
            }
        }
        let mut out = vec![0.0f32; n];
        for k in 0..n {
            let w = weights[k];
            if w > 0.0 {
                #[allow(clippy::cast_possible_truncation)] // audio samples are f32
                {
                    out[k] = (sums[k] / w) as f32;
                }
            } else {
                missing[k] = true;
            }
        }
        channels.push(out);
    }
    drop((sums, weights));

    let mut gaps: Vec<Range<usize>> = Vec::new();
    for (k, _) in missing.iter().enumerate().filter(|(_, m)| **m) {
        match gaps.last_mut() {
            Some(r) if r.end == k => r.end = k + 1,
            _ => gaps.push(k..k + 1),
        }
    }
    let mean_vt = vt_sum / vt_count;
    Ok(StitchedSignal {
        start_um: lo_um,
        spacing_um,
        native_rate_hz: mean_vt * 1000.0 / spacing_um,
        channels,
        gaps,
    })
}
