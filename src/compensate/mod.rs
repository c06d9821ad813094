//! compensate (in progress).
