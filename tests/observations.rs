//! Integration tests: observations.
