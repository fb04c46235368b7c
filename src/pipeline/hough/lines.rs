//! Segmentation and centroid lines: each in-focus pixel labelled by the window its curve passes through, then a robust centroid row per column.

use super::*;

/// Labels every point: the index of the single window its curve passes through, else
/// [`label::DISCARDED`] (two or more) or [`label::UNASSIGNED`] (none).
pub(super) fn label_points(points: &[FocusPoint], peaks: &[Peak]) -> Vec<i8> {
    let windows: Vec<WindowTest> = peaks.iter().map(WindowTest::new).collect();
    points
        .par_iter()
        .map(|pt| {
            let (xc, y) = (f64::from(pt.xc), f64::from(pt.y));
            let mut found = label::UNASSIGNED;
            for (k, window) in windows.iter().enumerate() {
                if window.contains(xc, y) {
                    if found != label::UNASSIGNED {
                        return label::DISCARDED;
                    }
                    found = i8::try_from(k).unwrap_or(label::DISCARDED);
                }
            }
            found
        })
        .collect()
}

/// The centroid line of region `k`.
///
/// Per column, the region's rows are gathered (sorted, as the points are row-major). Pass 1 takes
/// the mean of the span of 2·gate rows holding the most of them ([`densest_run`]), with
/// gate = ½·T + [`CENTROID_GATE_MARGIN_PX`] and T the median pixel count per measured column (the
/// stripe thickness); a running median of these along x (±max(`line_smoothing_px`,
/// [`MIN_MEDIAN_HALF_PX`])) gives a reference row per column. The centroid is the mean of the
/// column's rows within ±gate of that reference (none: a void). On a clean stripe this is the plain
/// mean; stray in-focus pixels that fall in the window (which, in image space, widens toward the
/// image sides) no longer pull it. The
/// centroids are smoothed over the measured columns within ±`line_smoothing_px`; voids are taken
/// from the peak line and marked. The half-width is half the gated pixel count per column (smoothed
/// alike; voids get the mean). Depths are left unset.
pub(super) fn centroid_line(
    points: &[FocusPoint],
    labels: &[i8],
    k: usize,
    width: usize,
    peak: &Peak,
    params: &HoughParams,
) -> WallLine {
    let want = i8::try_from(k).unwrap_or(label::NONE);
    let x0 = peak.x_origin_px;
    let column_of = |pt: &FocusPoint| {
        let x = (pt.xc + x0).round();
        (x >= 0.0 && (x as usize) < width).then_some(x as usize)
    };
    // Bucket the region's rows by column (CSR layout: offsets, then rows).
    let mut offsets = vec![0usize; width + 1];
    for (pt, &l) in points.iter().zip(labels) {
        if l == want
            && let Some(x) = column_of(pt)
        {
            offsets[x + 1] += 1;
        }
    }
    for x in 0..width {
        offsets[x + 1] += offsets[x];
    }
    let mut fill = offsets.clone();
    let mut col_rows = vec![0.0_f32; offsets[width]];
    for (pt, &l) in points.iter().zip(labels) {
        if l == want
            && let Some(x) = column_of(pt)
            && let Some(slot) = col_rows.get_mut(fill[x])
        {
            *slot = pt.y;
            fill[x] += 1;
        }
    }
    let column = |x: usize| col_rows.get(offsets[x]..offsets[x + 1]).unwrap_or(&[]);

    let mut counts: Vec<usize> = (0..width)
        .map(|x| column(x).len())
        .filter(|&c| c > 0)
        .collect();
    let thickness = median_in_place(&mut counts).map_or(0.0, |c| c as f32);
    let gate = 0.5 * thickness + CENTROID_GATE_MARGIN_PX;

    // Pass 1: the densest span per column; a running median along x then removes columns where a
    // chance cluster of stray pixels outnumbered a thin stripe.
    let first: Vec<f64> = (0..width)
        .map(|x| {
            densest_run(column(x), 2.0 * gate, peak.row_at_px(x as f32)).map_or(f64::NAN, |r| r.0)
        })
        .collect();
    let reference = running_median(&first, params.line_smoothing_px.max(MIN_MEDIAN_HALF_PX));
    // Pass 2: the mean of the rows within ±gate of the reference.
    let mut raw_rows = vec![f64::NAN; width];
    let mut raw_half = vec![f64::NAN; width];
    for x in 0..width {
        let Some(&r) = reference.get(x) else {
            continue;
        };
        if !r.is_finite() {
            continue;
        }
        let (mut sum, mut n) = (0.0_f64, 0usize);
        for &y in column(x) {
            if (f64::from(y) - r).abs() <= f64::from(gate) {
                sum += f64::from(y);
                n += 1;
            }
        }
        if n > 0 {
            raw_rows[x] = sum / n as f64;
            raw_half[x] = 0.5 * n as f64;
        }
    }
    let rows_s = smooth_measured(&raw_rows, params.line_smoothing_px);
    let half_s = smooth_measured(&raw_half, params.line_smoothing_px);
    let measured: Vec<f64> = raw_half.iter().copied().filter(|v| v.is_finite()).collect();
    let mean_half = if measured.is_empty() {
        0.0
    } else {
        measured.iter().sum::<f64>() / measured.len() as f64
    };

    let mut rows = Vec::with_capacity(width);
    let mut half_width_px = Vec::with_capacity(width);
    let mut filled = Vec::with_capacity(width);
    for x in 0..width {
        let r = rows_s.get(x).copied().unwrap_or(f64::NAN);
        if r.is_finite() {
            rows.push(r as f32);
            half_width_px.push(half_s.get(x).copied().unwrap_or(mean_half) as f32);
            filled.push(false);
        } else {
            rows.push(peak.row_at_px(x as f32));
            half_width_px.push(mean_half as f32);
            filled.push(true);
        }
    }
    WallLine {
        side: WallSide::Right,
        rows,
        half_width_px,
        depth_um: None,
        projection_depth_um: None,
        filled,
    }
}

/// The span of at most `span` rows holding the most of the sorted `rows` (ties: the one whose
/// mean is closest to `prior`): returns its mean row and its pixel count; `None` when empty.
pub(super) fn densest_run(rows: &[f32], span: f32, prior: f32) -> Option<(f64, usize)> {
    let mut best: Option<(usize, f64, f64)> = None; // (count, mean, distance to prior)
    let mut j = 0;
    let mut sum = 0.0_f64;
    for (i, &start) in rows.iter().enumerate() {
        if j < i {
            j = i;
            sum = 0.0;
        }
        while let Some(&y) = rows.get(j) {
            if y - start > span {
                break;
            }
            sum += f64::from(y);
            j += 1;
        }
        let n = j - i;
        let mean = sum / n as f64;
        let dist = (mean - f64::from(prior)).abs();
        let better = match best {
            None => true,
            Some((bn, _, bd)) => n > bn || (n == bn && dist < bd),
        };
        if better {
            best = Some((n, mean, dist));
        }
        sum -= f64::from(start);
    }
    best.map(|(n, mean, _)| (mean, n))
}

/// Running median over ±`half` of the finite entries (NaN where none).
pub(super) fn running_median(values: &[f64], half: usize) -> Vec<f64> {
    let n = values.len();
    let mut window = Vec::with_capacity(2 * half + 1);
    (0..n)
        .map(|i| {
            window.clear();
            let lo = i.saturating_sub(half);
            let hi = (i + half + 1).min(n);
            window.extend(values[lo..hi].iter().copied().filter(|v| v.is_finite()));
            median_in_place(&mut window).unwrap_or(f64::NAN)
        })
        .collect()
}

/// Moving average over ±`half` of the finite entries; NaN stays NaN.
pub(super) fn smooth_measured(values: &[f64], half: usize) -> Vec<f64> {
    values
        .iter()
        .zip(crate::pipeline::finite_window_means(values, half))
        .map(|(&v, mean)| if v.is_finite() { mean } else { f64::NAN })
        .collect()
}
