//! U (k=2) in the annotations of a compensated RAPID module through the
//! binary: the ABB IRB 1600 file with the hand-written `covariance` of the
//! KRL test (tests/uncertainty_robot.rs), one kinematics parameter, the
//! height d of joint 1 (`actual[0].d_mm`, u = 0.05 mm). That length moves
//! every TCP one to one along the base's z axis, so U of a target's
//! deviation length is 2 u |dz| / |dev|, derived here from the deviation
//! the report gives. Read whole or a window at a time, the module is the
//! same bytes; without the covariance no annotation carries U.

use crate::common::run_in as run;
use crate::common::{repo, text};

const U_D1_MM: f64 = 0.05;
/// Annotations write U with 3 decimals; the report's deviation has 5.
const ANNOTATION_U_TOL_MM: f64 = 0.6e-3;
/// The report writes U with 5 decimals.
const REPORT_U_TOL_MM: f64 = 0.6e-5;

/// The U of each `! dev` annotation of `module`, `None` for one without.
fn annotation_us(module: &str) -> Vec<Option<f64>> {
    module
        .lines()
        .filter(|l| l.contains("! dev "))
        .map(|l| {
            l.split(" U ")
                .nth(1)
                .map(|u| u.trim().parse().expect("a number after U"))
        })
        .collect()
}

/// A folder with `m.mod` (samples/milling.mod), `plain.yaml` (the
/// bundled ABB IRB 1600) and `arm.yaml` (the same with the covariance of
/// one parameter, the height d of joint 1).
fn fixture() -> tempfile::TempDir {
    let tmp = tempfile::tempdir().expect("tempdir");
    let dir = tmp.path();
    std::fs::copy(repo("samples/milling.mod"), dir.join("m.mod")).expect("copy");
    let mut m = text("machines/abb-irb1600.yaml");
    if !m.ends_with('\n') {
        m.push('\n');
    }
    std::fs::write(dir.join("plain.yaml"), &m).expect("write");
    m.push_str(&format!(
        "covariance:\n  - kind: kinematics\n    observations: \"hand.csv\"\n    observations_sha256: 00\n    rows: 30\n    parameters: [\"actual[0].d_mm\"]\n    u: [{U_D1_MM}]\n    correlation:\n      - [1.0]\n"
    ));
    std::fs::write(dir.join("arm.yaml"), m).expect("write");

    tmp
}

/// 2 u |dz| / |dev| of each row of a JSON report: the U (k=2) of the
/// deviation's length when d of joint 1 alone is uncertain.
fn hand_u(json: &serde_json::Value) -> Vec<f64> {
    json["rows"]
        .as_array()
        .expect("rows")
        .iter()
        .map(|r| {
            let dz = r["deviation_mm"][2].as_f64().expect("dz");
            let dev = r["dev_mm"].as_f64().expect("dev");
            2.0 * U_D1_MM * dz.abs() / dev
        })
        .collect()
}

/// The JSON report of `m.mod` in `dir` against `machine`.
fn report_json(dir: &std::path::Path, machine: &str) -> serde_json::Value {
    let (code, out, err) = run(
        dir,
        &["report", "m.mod", "--machine", machine, "--format", "json"],
    );
    assert_eq!(code, 0, "{err}");
    serde_json::from_str(&out).expect("JSON")
}

#[test]
fn rapid_annotations_carry_u_from_the_kinematics_covariance_whole_and_windowed() {
    let tmp = fixture();
    let dir = tmp.path();
    let json = report_json(dir, "arm.yaml");
    let hand = hand_u(&json);

    let (code, _, err) = run(dir, &["compensate", "m.mod", "--machine", "arm.yaml"]);
    assert_eq!(code, 0, "{err}");
    let whole = std::fs::read_to_string(dir.join("m.comp.mod")).expect("written");
    let us = annotation_us(&whole);
    assert!(us.len() >= 10, "{whole}");
    for u in &us {
        let u = u.unwrap_or_else(|| panic!("every compensated target carries U: {whole}"));
        assert!(u > ANNOTATION_U_TOL_MM, "the test exercises U: {u}");
        assert!(
            hand.iter().any(|h| (h - u).abs() <= ANNOTATION_U_TOL_MM),
            "annotation U {u} is none of the hand-derived {hand:?}"
        );
    }

    let (code, _, err) = run(
        dir,
        &[
            "compensate",
            "m.mod",
            "--machine",
            "arm.yaml",
            "--rapid-window-lines",
            "1",
            "-o",
            "w.mod",
        ],
    );
    assert_eq!(code, 0, "{err}");
    let windowed = std::fs::read_to_string(dir.join("w.mod")).expect("written");
    assert_eq!(windowed, whole, "a window at a time gives the same bytes");

    let (code, _, err) = run(
        dir,
        &[
            "compensate",
            "m.mod",
            "--machine",
            "plain.yaml",
            "-o",
            "p.mod",
        ],
    );
    assert_eq!(code, 0, "{err}");
    let plain = std::fs::read_to_string(dir.join("p.mod")).expect("written");
    let us = annotation_us(&plain);
    assert_eq!(us.len(), annotation_us(&whole).len(), "{plain}");
    assert!(us.iter().all(Option::is_none), "{plain}");

    // --gain-auto stays refused by name for RAPID, as for KRL and TP.
    let (code, _, err) = run(
        dir,
        &[
            "compensate",
            "m.mod",
            "--machine",
            "arm.yaml",
            "--gain-auto",
        ],
    );
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--gain-auto is a G-code option"), "{err}");
}

/// The rows of a RAPID report carry U, each the hand value of its own row;
/// `batch` writes the same annotations as `compensate`.
#[test]
fn rapid_report_rows_and_batch_carry_u() {
    let tmp = fixture();
    let dir = tmp.path();
    let json = report_json(dir, "arm.yaml");
    let hand = hand_u(&json);
    let rows = json["rows"].as_array().expect("rows");
    assert!(rows.len() >= 10, "{json}");
    // A `MoveAbsJ` is reported as written, without U.
    for (r, h) in rows
        .iter()
        .zip(&hand)
        .filter(|(r, _)| r["motion"] != "MoveAbsJ")
    {
        let u = r["u_mm"]
            .as_f64()
            .unwrap_or_else(|| panic!("row without u_mm: {r}"));
        // The report's dz and |dev| are rounded to 5 decimals (0.5e-5
        // each): the hand value 2u|dz|/|dev| is off by at most
        // 2u (0.5e-5 + 0.5e-5 |dz|/|dev|) / |dev| ≤ 2u·1e-5/|dev|.
        let dev = r["dev_mm"].as_f64().expect("dev");
        let tol = REPORT_U_TOL_MM + 2.0 * U_D1_MM * 1e-5 / dev;
        assert!(
            (u - h).abs() <= tol,
            "line {}: U {u}, by hand {h}",
            r["line"]
        );
    }
    assert!(
        json["summary"]["uncertainty"]["cutting_max_u_mm"]
            .as_f64()
            .is_some(),
        "{}",
        json["summary"]
    );
    // Without the covariance the rows state none.
    let plain = report_json(dir, "plain.yaml");
    assert!(
        plain["rows"]
            .as_array()
            .expect("rows")
            .iter()
            .all(|r| r["u_mm"].is_null()),
        "{plain}"
    );

    let (code, _, err) = run(dir, &["compensate", "m.mod", "--machine", "arm.yaml"]);
    assert_eq!(code, 0, "{err}");
    let single = std::fs::read_to_string(dir.join("m.comp.mod")).expect("written");
    let (code, _, err) = run(
        dir,
        &[
            "batch",
            "--machine",
            "arm.yaml",
            "--out-dir",
            "out",
            "m.mod",
        ],
    );
    assert_eq!(code, 0, "{err}");
    let batch = std::fs::read_to_string(dir.join("out").join("m.mod")).expect("batch output");
    let us = annotation_us(&batch);
    assert!(us.iter().all(Option::is_some), "{batch}");
    assert_eq!(
        us,
        annotation_us(&single),
        "batch and compensate annotate alike"
    );
}
