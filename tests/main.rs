//! The one integration-test binary: CLI tests through the real executable,
//! goldens, property tests and regressions.

mod common;
mod diagnose;
mod gcode_cli;
mod gcode_grammar;
mod golden;
mod machine_tool;
mod observations;
mod rapid;
mod rapid_cli;
mod robot;
