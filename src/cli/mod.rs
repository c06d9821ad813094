//! Command line: raw flags → validated run configuration → engine calls.
//! Nothing else in the crate parses flags.

use clap::Parser;

/// postproc — offline compensation post-processor for CNC machine tools and robots.
#[derive(Debug, Parser)]
#[command(name = "postproc", version)]
pub struct Cli {}

/// Runs a parsed command line; returns the process exit code.
pub fn run(_cli: Cli) -> crate::Result<i32> {
    Ok(0)
}
