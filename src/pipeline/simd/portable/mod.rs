//! The portable builds of the kernels: fixed-size lane arrays that the compiler maps onto whatever vector registers the target has.

pub(super) mod hs;
pub(super) mod irls;
pub(super) mod median;
