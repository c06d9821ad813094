//! The one integration-test binary: CLI tests through the real executable,
//! goldens, property tests and regressions.

mod alloc;
mod bad_corpus;
mod batch_cli;
mod calibrate_cli;
mod common;
mod compact;
mod compensate_props;
mod conf_off;
mod configurations;
mod diagnose;
mod diagnose_matrix;
mod effects;
mod engine_flags;
mod error_kinds;
mod frames;
mod function_size;
mod gcode_cli;
mod gcode_grammar;
mod golden;
mod gperf;
mod honesty_cli;
mod hostile;
mod layers;
mod machine_tool;
mod mounts;
mod observations;
mod output_words;
mod paper_b;
mod peers;
mod posts;
mod provenance_cli;
mod rapid;
mod rapid_cli;
mod rapid_programs;
mod rapid_stream;
#[cfg(unix)] // links the inputs into a scratch folder, runs bash
mod readme;
mod regression;
mod report_cli;
mod repredict;
mod robot;
mod robot_process;
mod robot_samples;
mod snapshots;
