//! Integration tests: machine_tool.
