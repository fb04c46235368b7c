//! The edge decoder: sub-pixel borders between the walls and the land and bottom, read as groove displacement.
//!
//! The border model ([`border`]) is public on its own so that other decoders (the still-image
//! decoder) fit the same edge-spread profile.

pub mod border;
