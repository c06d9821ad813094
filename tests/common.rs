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

/// Largest difference between numbers of two simulated CSV files that still
/// counts as the same data (floating-point noise of a refactored model).
pub const CSV_NOISE_TOL: f64 = 1e-9;

/// Asserts two CSV texts have the same header and text cells and numbers
/// equal within [`CSV_NOISE_TOL`].
pub fn assert_csv_close(got: &str, want: &str, what: &str) {
    let (a, b): (Vec<&str>, Vec<&str>) = (got.lines().collect(), want.lines().collect());
    assert_eq!(a.len(), b.len(), "{what}: line count");
    for (n, (la, lb)) in a.iter().zip(&b).enumerate() {
        let (ca, cb): (Vec<&str>, Vec<&str>) = (la.split(',').collect(), lb.split(',').collect());
        assert_eq!(ca.len(), cb.len(), "{what}: cells of line {}", n + 1);
        for (x, y) in ca.iter().zip(&cb) {
            match (x.parse::<f64>(), y.parse::<f64>()) {
                (Ok(x), Ok(y)) => assert!(
                    (x - y).abs() <= CSV_NOISE_TOL,
                    "{what}: line {}: {x} vs {y}",
                    n + 1
                ),
                _ => assert_eq!(x, y, "{what}: line {}", n + 1),
            }
        }
    }
}
