//! rapid (in progress).
