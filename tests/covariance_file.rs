//! The parameter covariance `calibrate` writes into the machine file: one
//! block per calibrated section with the data it came from (file name,
//! SHA-256 and rows, checked here against the observation file itself),
//! the key path of each written value and its uncertainty, which must be
//! the one the calibration table prints; a calibration kind that records
//! no covariance leaves the file without the list.

use sha2::{Digest, Sha256};

use postproc::machine::Machine;
use postproc::predict::uncertainty::read_covariance;

use crate::common::{postproc, repo, text};

const ROBOT: &str = "machines/abb-irb1600.yaml";
const ROBOT_OBS: &str = "samples/observations/irb1600-kinematic-measured.csv";
const MILL: &str = "machines/afm-r1000.yaml";
const MILL_OBS: &str = "samples/observations/afm-r1000-grid-measured.csv";

/// Runs `calibrate KIND` and returns (stdout, written file).
fn calibrate(kind: &str, machine: &std::path::Path, obs: &str, out: &std::path::Path) -> String {
    let a = postproc()
        .args(["calibrate", kind, "--machine"])
        .arg(machine)
        .arg("--observations")
        .arg(repo(obs))
        .arg("-o")
        .arg(out)
        .assert()
        .success();
    String::from_utf8_lossy(&a.get_output().stdout).into_owned()
}

/// Data rows of an observation file: neither the header nor a comment nor
/// empty.
fn data_rows(rel: &str) -> usize {
    text(rel)
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.trim_start().starts_with('#'))
        .count()
        - 1
}

fn sha256(rel: &str) -> String {
    let bytes = std::fs::read(repo(rel)).expect("read");
    Sha256::digest(&bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// The expanded uncertainty the calibration table prints for `name`
/// (its `U (k=2)` column: parameter, start, identified, u, U, …).
fn printed_u(table: &str, name: &str) -> Option<f64> {
    let line = table
        .lines()
        .find(|l| l.split_whitespace().next() == Some(name))?;
    line.split_whitespace().nth(4)?.parse().ok()
}

/// The table's name of a robot key path: `actual[J].KEY` is `jJ+1.KEY`,
/// `flange_to_tool.KEY` is `tool.KEY`.
fn robot_table_name(path: &str) -> String {
    if let Some(key) = path.strip_prefix("flange_to_tool.") {
        return format!("tool.{key}");
    }
    let rest = path.strip_prefix("actual[").expect("a DH key");
    let (j, key) = rest.split_once("].").expect("actual[J].key");
    format!("j{}.{key}", j.parse::<usize>().expect("joint") + 1)
}

#[test]
fn kinematics_writes_its_covariance_with_its_data() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("cal.yaml");
    let table = calibrate("kinematics", &repo(ROBOT), ROBOT_OBS, &out);
    let written = std::fs::read_to_string(&out).expect("written");
    Machine::from_yaml_str(&written, "cal.yaml").expect("the written file loads");
    let blocks = read_covariance(&written, "cal.yaml").expect("covariance");
    assert_eq!(blocks.len(), 1, "one block:\n{written}");
    let b = &blocks[0];
    assert_eq!(b.kind, "kinematics");
    assert_eq!(b.observations, "irb1600-kinematic-measured.csv");
    assert_eq!(b.observations_sha256, sha256(ROBOT_OBS));
    assert_eq!(b.rows, data_rows(ROBOT_OBS));
    assert!(!b.parameters.is_empty());
    for (p, u) in b.parameters.iter().zip(&b.u) {
        let name = robot_table_name(p);
        let shown = printed_u(&table, &name)
            .unwrap_or_else(|| panic!("{name} ({p}) not in the table:\n{table}"));
        // The table prints U = 2u to its decimals: agreement within half
        // of its last digit, or 1 % of the value.
        let tol = (shown.abs() * 0.01).max(0.5e-4);
        assert!(
            (2.0 * u - shown).abs() <= tol,
            "{p}: 2u = {} but the table says {shown}",
            2.0 * u
        );
    }
    let cov = b.covariance().expect("a covariance");
    assert_eq!(cov.len(), b.parameters.len());

    // Calibrating the calibrated file again replaces the block.
    let again = dir.path().join("again.yaml");
    calibrate("kinematics", &out, ROBOT_OBS, &again);
    let twice = std::fs::read_to_string(&again).expect("written");
    let blocks = read_covariance(&twice, "again.yaml").expect("covariance");
    assert_eq!(blocks.len(), 1, "replaced, not added:\n{twice}");
    assert_eq!(twice.matches("\ncovariance:").count(), 1);
}

#[test]
fn geometry_writes_its_covariance_by_key_path() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("cal.yaml");
    calibrate("geometry", &repo(MILL), MILL_OBS, &out);
    let written = std::fs::read_to_string(&out).expect("written");
    Machine::from_yaml_str(&written, "cal.yaml").expect("the written file loads");
    let blocks = read_covariance(&written, "cal.yaml").expect("covariance");
    assert_eq!(blocks.len(), 1);
    let b = &blocks[0];
    assert_eq!(b.kind, "geometry");
    assert_eq!(b.observations_sha256, sha256(MILL_OBS));
    assert_eq!(b.rows, data_rows(MILL_OBS));
    assert!(
        b.parameters
            .iter()
            .all(|p| p.starts_with("axes[") && p.contains("_errors.")),
        "{:?}",
        b.parameters
    );
    assert!(b.u.iter().all(|u| *u > 0.0), "{:?}", b.u);
}

#[test]
fn the_bundled_files_carry_no_covariance() {
    for m in [ROBOT, MILL, "machines/five-axis-ac.yaml"] {
        let blocks = read_covariance(&text(m), m).expect("reads");
        assert!(blocks.is_empty(), "{m}");
    }
}
