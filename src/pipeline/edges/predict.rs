//! The coarse borders' prediction between samples: a Catmull–Rom interpolant over their grid.

/// The first index of `points` (sorted by `s`) whose `s` exceeds `s`, as
/// `partition_point(|p| p.0 <= s)` gives it: guessed from the points' mean step (they are the
/// coarse samples' grid, with gaps) and walked to the exact place.
pub(super) fn first_after(points: &[(f64, f64)], s: f64, s0: f64, step: f64) -> usize {
    let n = points.len();
    let guess = (s - s0) / step + 1.0;
    let mut i = if guess >= 0.0 {
        (guess as usize).min(n)
    } else {
        0
    };
    // Back while the point before is not at or below `s` (above it, or `s` is NaN).
    while i > 0
        && points[i - 1]
            .0
            .partial_cmp(&s)
            .is_none_or(|o| o == std::cmp::Ordering::Greater)
    {
        i -= 1;
    }
    while i < n && points[i].0 <= s {
        i += 1;
    }
    i
}

/// A Catmull–Rom interpolant through `(s, y)` points sorted by `s` (constant beyond the ends).
pub(super) fn interpolant(points: Vec<(f64, f64)>) -> impl Fn(f64) -> f64 {
    let s0 = points.first().map_or(0.0, |p| p.0);
    let step = match (points.first(), points.last()) {
        (Some(a), Some(b)) if points.len() > 1 => (b.0 - a.0) / (points.len() - 1) as f64,
        _ => 1.0,
    };
    move |s: f64| {
        let n = points.len();
        if n == 0 {
            return f64::NAN;
        }
        let i = first_after(&points, s, s0, step);
        if i == 0 {
            return points[0].1;
        }
        if i >= n {
            return points[n - 1].1;
        }
        let (p1, p2) = (points[i - 1], points[i]);
        let p0 = if i >= 2 { points[i - 2] } else { p1 };
        let p3 = points.get(i + 1).copied().unwrap_or(p2);
        let h = p2.0 - p1.0;
        if h <= 0.0 {
            return p1.1;
        }
        let t = (s - p1.0) / h;
        // Tangents by finite differences over the neighbours (non-uniform spacing allowed).
        let m1 = if p2.0 > p0.0 {
            (p2.1 - p0.1) / (p2.0 - p0.0) * h
        } else {
            p2.1 - p1.1
        };
        let m2 = if p3.0 > p1.0 {
            (p3.1 - p1.1) / (p3.0 - p1.0) * h
        } else {
            p2.1 - p1.1
        };
        let (t2, t3) = (t * t, t * t * t);
        (2.0 * t3 - 3.0 * t2 + 1.0) * p1.1
            + (t3 - 2.0 * t2 + t) * m1
            + (-2.0 * t3 + 3.0 * t2) * p2.1
            + (t3 - t2) * m2
    }
}
