//! The expanded uncertainty U (k=2) of a robot target's predicted
//! deviation through the binary: a KUKA KR 210 file whose `covariance`
//! list is written here by hand, one kinematics parameter, the height d of
//! joint 1 (`actual[0].d_mm`, u = 0.05 mm). That length lies along the
//! base's z axis before any joint turns, so every target's TCP moves by it
//! one to one along z: U of the deviation's length is
//! 2 u |dz| / |dev|, derived here from the deviation the report gives.
//! The KRL annotations carry the same U; `--gain-auto` is refused by name.

use std::path::PathBuf;

use crate::common::run_in as run;
use crate::common::{repo, text};

const U_D1_MM: f64 = 0.05;
/// The report writes U with 5 decimals.
const REPORT_U_TOL_MM: f64 = 0.6e-5;
/// Annotations write U with 3 decimals.
const ANNOTATION_U_TOL_MM: f64 = 0.6e-3;

fn scratch() -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().expect("tempdir");
    for n in ["palletise.src", "palletise.dat", "$config.dat"] {
        std::fs::copy(repo(&format!("tests/krl/{n}")), dir.path().join(n)).expect("copy");
    }
    let mut m = text("machines/kuka-kr210-r2700-2.yaml");
    if !m.ends_with('\n') {
        m.push('\n');
    }
    m.push_str(&format!(
        "covariance:\n  - kind: kinematics\n    observations: \"hand.csv\"\n    observations_sha256: 00\n    rows: 30\n    parameters: [\"actual[0].d_mm\"]\n    u: [{U_D1_MM}]\n    correlation:\n      - [1.0]\n"
    ));
    std::fs::write(dir.path().join("arm.yaml"), m).expect("write");
    let p = dir.path().to_path_buf();
    (dir, p)
}

#[test]
fn robot_report_and_krl_annotations_carry_u_from_the_kinematics_covariance() {
    let (_d, dir) = scratch();
    let (code, out, err) = run(
        &dir,
        &[
            "report",
            "palletise.src",
            "--machine",
            "arm.yaml",
            "--format",
            "json",
        ],
    );
    assert_eq!(code, 0, "{err}");
    let json: serde_json::Value = serde_json::from_str(&out).expect("JSON");
    let rows = json["rows"].as_array().expect("rows");
    let mut hand = Vec::new();
    for r in rows.iter().filter(|r| r.get("u_mm").is_some()) {
        let dz = r["deviation_mm"][2].as_f64().expect("dz");
        let dev = r["dev_mm"].as_f64().expect("dev");
        let want = 2.0 * U_D1_MM * dz.abs() / dev;
        let u = r["u_mm"].as_f64().expect("u");
        assert!(
            (u - want).abs() <= REPORT_U_TOL_MM,
            "line {}: U {u} but {want} by hand",
            r["line"]
        );
        hand.push(want);
    }
    assert!(
        hand.iter().filter(|u| **u > ANNOTATION_U_TOL_MM).count() >= 2,
        "the test exercises U: {hand:?}"
    );
    assert_eq!(
        json["provenance"]["uncertainty"]["covariance_of"][0],
        "kinematics (hand.csv)"
    );

    let (code, _, err) = run(
        &dir,
        &["compensate", "palletise.src", "--machine", "arm.yaml"],
    );
    assert_eq!(code, 0, "{err}");
    let src = std::fs::read_to_string(dir.join("palletise.comp.src")).expect("written");
    let us: Vec<f64> = src
        .lines()
        .filter(|l| l.contains("; dev "))
        .filter_map(|l| l.split(" U ").nth(1))
        .map(|u| u.trim().parse().expect("a number after U"))
        .collect();
    // The compensated moves are the report's rows with a target (two).
    assert!(us.len() >= 2, "{src}");
    for u in &us {
        assert!(
            hand.iter().any(|h| (h - u).abs() <= ANNOTATION_U_TOL_MM),
            "annotation U {u} is none of the report's {hand:?}"
        );
    }
}

#[test]
fn without_a_covariance_robot_runs_state_no_u() {
    let (_d, dir) = scratch();
    let arm = "kuka-kr210-r2700-2";
    let (code, out, err) = run(
        &dir,
        &[
            "report",
            "palletise.src",
            "--machine",
            arm,
            "--format",
            "json",
        ],
    );
    assert_eq!(code, 0, "{err}");
    assert!(!out.contains("u_mm"), "{out}");
    let (code, _, err) = run(&dir, &["compensate", "palletise.src", "--machine", arm]);
    assert_eq!(code, 0, "{err}");
    let src = std::fs::read_to_string(dir.join("palletise.comp.src")).expect("written");
    assert!(src.contains("; dev "), "{src}");
    assert!(!src.contains(" U "), "{src}");
}

#[test]
fn gain_auto_is_refused_by_name_for_krl_and_tp() {
    let (_d, dir) = scratch();
    std::fs::copy(repo("tests/tp/pick_place.ls"), dir.join("p.ls")).expect("copy");
    for (program, machine) in [("palletise.src", "arm.yaml"), ("p.ls", "fanuc-lrmate200id")] {
        for command in ["compensate", "report"] {
            let (code, _, err) = run(
                &dir,
                &[command, program, "--machine", machine, "--gain-auto"],
            );
            assert_eq!(code, 2, "{command} {program}: {err}");
            assert!(err.contains("--gain-auto is a G-code option"), "{err}");
        }
    }
}

/// The cell frames of tests/tp/compensate.rs: UF 2 (the weld fixture)
/// and UT 1 (a torch) of `weld_seam.ls`.
const TP_FRAMES: &str = "
fanuc:
  user_frames:
    2: {x_mm: 0, y_mm: 0, z_mm: -300, w_deg: 0, p_deg: 0, r_deg: 0}
  tool_frames:
    1: {x_mm: 0, y_mm: 30, z_mm: 350, w_deg: 0, p_deg: 22, r_deg: 0}
";

/// The numbers after ` U ` in `text` (U of a remark; ` U =` of a note and
/// `'N U T'` of a configuration are not numbers).
fn numbers_after_u(text: &str) -> Vec<f64> {
    text.split(" U ")
        .skip(1)
        .filter_map(|s| {
            let n: String = s
                .chars()
                .take_while(|c| c.is_ascii_digit() || *c == '.')
                .collect();
            n.parse().ok()
        })
        .collect()
}

/// FANUC TP: the report's U of each target derived by hand as for KRL
/// (joint 1's height d moves the TCP along z one to one), and the `!`
/// remark lines of the compensated program carry the same U; without the
/// covariance they carry none.
#[test]
fn tp_remarks_carry_u_from_the_kinematics_covariance() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let dir = tmp.path();
    std::fs::copy(repo("tests/tp/weld_seam.ls"), dir.join("w.ls")).expect("copy");
    let mut m = text("machines/fanuc-m20ia.yaml");
    if !m.ends_with('\n') {
        m.push('\n');
    }
    m.push_str(TP_FRAMES);
    std::fs::write(dir.join("plain.yaml"), &m).expect("write");
    m.push_str(&format!(
        "covariance:\n  - kind: kinematics\n    observations: \"hand.csv\"\n    observations_sha256: 00\n    rows: 30\n    parameters: [\"actual[0].d_mm\"]\n    u: [{U_D1_MM}]\n    correlation:\n      - [1.0]\n"
    ));
    std::fs::write(dir.join("arm.yaml"), m).expect("write");
    let (code, out, err) = run(
        dir,
        &[
            "report",
            "w.ls",
            "--machine",
            "arm.yaml",
            "--format",
            "json",
        ],
    );
    assert_eq!(code, 0, "{err}");
    let json: serde_json::Value = serde_json::from_str(&out).expect("JSON");
    let mut hand = Vec::new();
    for r in json["rows"]
        .as_array()
        .expect("rows")
        .iter()
        .filter(|r| r.get("u_mm").is_some())
    {
        let dz = r["deviation_mm"][2].as_f64().expect("dz");
        let dev = r["dev_mm"].as_f64().expect("dev");
        let want = 2.0 * U_D1_MM * dz.abs() / dev;
        let u = r["u_mm"].as_f64().expect("u");
        assert!(
            (u - want).abs() <= REPORT_U_TOL_MM,
            "line {}: U {u} but {want} by hand",
            r["line"]
        );
        hand.push(want);
    }
    assert!(
        hand.iter().filter(|u| **u > ANNOTATION_U_TOL_MM).count() >= 2,
        "the test exercises U: {hand:?}"
    );
    let (code, _, err) = run(dir, &["compensate", "w.ls", "--machine", "arm.yaml"]);
    assert_eq!(code, 0, "{err}");
    let ls = std::fs::read_to_string(dir.join("w.comp.ls")).expect("written");
    let remarks: Vec<&str> = ls.lines().filter(|l| l.contains('!')).collect();
    let us = numbers_after_u(&remarks.join(" "));
    assert!(us.len() >= 2, "{ls}");
    for u in &us {
        assert!(
            hand.iter().any(|h| (h - u).abs() <= ANNOTATION_U_TOL_MM),
            "remark U {u} is none of the report's {hand:?}"
        );
    }
    let (code, _, err) = run(
        dir,
        &[
            "compensate",
            "w.ls",
            "--machine",
            "plain.yaml",
            "-o",
            "p.ls",
        ],
    );
    assert_eq!(code, 0, "{err}");
    let plain = std::fs::read_to_string(dir.join("p.ls")).expect("written");
    let remarks: Vec<&str> = plain.lines().filter(|l| l.contains('!')).collect();
    assert!(remarks.iter().any(|l| l.contains("! dev ")), "{plain}");
    assert!(numbers_after_u(&remarks.join(" ")).is_empty(), "{plain}");
}
