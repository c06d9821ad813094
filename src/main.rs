//! The `postproc` binary: parses flags, runs the command, prints the error
//! chain once and maps its kind to the exit code (0 ok, 1 findings, 2 an
//! error of the input, machine file, data, usage, I/O or an unachievable
//! target, 3 an internal error; docs/cli.md).

use clap::Parser;

fn main() {
    postproc::cli::memory::keep_freed_memory();
    let cli = postproc::cli::Cli::parse();
    match postproc::cli::run(cli) {
        Ok(code) => std::process::exit(code),
        // `postproc … | head`: the reader closed the pipe; nothing to say.
        Err(err) if postproc::cli::is_broken_pipe(&err) => std::process::exit(0),
        Err(err) => {
            let mut msg = format!("error: {err}");
            let mut src = std::error::Error::source(&err);
            while let Some(s) = src {
                msg.push_str(&format!(": {s}"));
                src = s.source();
            }
            eprintln!("{msg}");
            std::process::exit(err.exit_code());
        }
    }
}
