//! Checks shared by the unit tests of several stages.

use std::fmt::Debug;

use super::StageError;

/// Each edit of `P`'s defaults must make `run` fail with [`StageError::InvalidParam`].
pub(crate) fn assert_each_edit_is_refused<P: Default + Debug, T>(
    edits: &[fn(&mut P)],
    run: impl Fn(&P) -> Result<T, StageError>,
) {
    for edit in edits {
        let mut p = P::default();
        edit(&mut p);
        assert!(
            matches!(run(&p), Err(StageError::InvalidParam { .. })),
            "{p:?}"
        );
    }
}

/// The least-squares gains `(a, b)` of `y ≈ a·p + b·q` over the samples `((p, q), y)`, from the
/// 2×2 normal equations.
pub(crate) fn two_gains(samples: impl IntoIterator<Item = ((f64, f64), f64)>) -> (f64, f64) {
    let (mut pp, mut pq, mut qq, mut py, mut qy) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for ((p, q), y) in samples {
        pp += p * p;
        pq += p * q;
        qq += q * q;
        py += p * y;
        qy += q * y;
    }
    let det = pp * qq - pq * pq;
    ((py * qq - qy * pq) / det, (qy * pp - py * pq) / det)
}
