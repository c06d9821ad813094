//! The one integration-test binary: CLI tests through the real executable,
//! goldens, property tests and regressions.

mod common;
mod gcode_cli;
mod gcode_grammar;
mod diagnose;
mod golden;
mod machine_tool;
mod observations;
mod rapid;
mod rapid_cli;
mod robot;
