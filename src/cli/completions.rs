//! `postproc completions SHELL` and `postproc man`: the shell completion
//! script and the manual page, generated from the command-line definition
//! itself (clap_complete, clap_mangen), so they cannot drift from it.

use std::io::Write;

use clap::CommandFactory;

use crate::error::{Error, Result};

/// Writes `bytes` to standard output.
fn print(bytes: &[u8]) -> Result<i32> {
    let mut out = std::io::stdout().lock();
    out.write_all(bytes)
        .and_then(|()| out.flush())
        .map_err(|e| Error::io("stdout", e))?;
    Ok(0)
}

/// The completion script of `shell` for every subcommand and flag.
pub fn completions(shell: clap_complete::Shell) -> Result<i32> {
    let mut cmd = super::Cli::command();
    let mut buf = Vec::new();
    clap_complete::generate(shell, &mut cmd, "postproc", &mut buf);
    print(&buf)
}

/// The manual page: the top-level page, then one section per subcommand.
pub fn man() -> Result<i32> {
    let cmd = super::Cli::command();
    let mut buf = Vec::new();
    clap_mangen::Man::new(cmd.clone())
        .render(&mut buf)
        .map_err(|e| Error::io("man page", e))?;
    for sub in cmd.get_subcommands() {
        clap_mangen::Man::new(sub.clone())
            .title(format!("postproc-{}", sub.get_name()))
            .render(&mut buf)
            .map_err(|e| Error::io("man page", e))?;
    }
    print(&buf)
}
