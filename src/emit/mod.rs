//! emit (in progress).

pub mod rapid;
