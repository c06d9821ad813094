//! emit (in progress).
