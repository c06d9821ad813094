//! Integration tests: the G-code commands through the real binary.
