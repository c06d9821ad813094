//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::path::PathBuf;

/// Path of a file in the repository.
pub fn repo(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(rel)
}

/// The `postproc` binary under test.
pub fn postproc() -> assert_cmd::Command {
    assert_cmd::Command::cargo_bin("postproc").expect("binary built")
}
