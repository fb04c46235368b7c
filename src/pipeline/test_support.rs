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
