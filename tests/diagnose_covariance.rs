//! `diagnose --write-model` writes the covariance of what it identified,
//! and `report` on the written model gives each block its U from it.
//!
//! The case is built so that the fit's covariance is derived by hand
//! whatever rows the hold-out split keeps: the "measured" positions are
//! afm-r1000's own predictions plus an X positioning error linear over
//! the travel, p·u with u = (X − 500)/500 mm and p = 20 µm, and ±δ along
//! z alone (the sign alternating row by row). Every row is at one end of
//! X (X = 0 or 1000 mm, u = ∓1), so the candidate `EXX_lin` has
//! sensitivity (±1, 0, 0) µm per µm at every row: on the m fitted rows its
//! estimate is exactly ±p, the fit's residual is the ±δ in z of each row,
//! RSS = m δ² with 3m − 1 degrees of freedom, and its variance is
//! σ² / Σ s² = δ² / (3m − 1) µm². The written table value at position q
//! moves by ((q − 500)/500) p, so the file holds u_p |q − 500|/500 µm for
//! it, correlated ±1 with the others; and a block of the report at
//! machine X = x whose deviation along x is dx of |dev| has
//! U = 2 · 10⁻³ u_p |x − 500|/500 · |dx| / |dev| (the tables interpolate
//! a linear function exactly).

use std::path::Path;

use postproc::calibrate::forward;
use postproc::calibrate::observations::Pose;

use crate::common::{postproc, text, write};
use crate::diagnose::{machine, tool_rows};

/// The ±z "noise" of every row, µm.
const DELTA_UM: f64 = 5.0;
/// The X positioning error at the + end of travel, µm.
const P_UM: f64 = 20.0;
/// Middle and half length of X's travel, mm.
const MID_MM: f64 = 500.0;
/// Relative agreement of u with the hand value: what the file's rounding
/// of the positions to 9 decimals (e ≤ 5e-10 mm = 5e-7 µm per coordinate)
/// explains. The commands are predicted as written, so the rounding is the
/// only residual besides ±δ; in z it moves each row's residual to ±δ + e,
/// the RSS by at most Σ 2δ|e| = 2mδe over m δ² to first order (e² terms
/// are 1e-14 of it, the difference quotient's 1e-12 in Σ s² less), and
/// u = √(RSS / (3m − 1) / Σ s²) by half that: |Δu/u| ≤ e/δ = 1e-7.
const U_RTOL: f64 = 1e-7;
/// Fitted value within this of the truth, µm (noise-free in x).
const VALUE_TOL_UM: f64 = 1e-4;
/// U is printed with 5 decimals in the report's JSON.
const REPORT_U_TOL_MM: f64 = 0.6e-5;

/// The observation file: commanded machine positions (X at an end of
/// travel), directions and the model's attained positions plus the linear
/// X error and ±δ in z.
fn observations(model_text: &str) -> String {
    let model = machine(model_text);
    let mut s = String::from("id,t_s,X_mm,Y_mm,Z_mm,dirX,dirY,dirZ,x_mm,y_mm,z_mm\n");
    for (i, mut row) in tool_rows(120, 7).into_iter().enumerate() {
        let Pose::Tool(tp) = &mut row.pose else {
            panic!("tool rows")
        };
        tp.xyz_mm[0] = if (i / 2) % 2 == 0 { 0.0 } else { 2.0 * MID_MM };
        // The file holds the commands to 6 decimals: predict at those, so
        // the diagnosis predicts at the very commands the positions came
        // from.
        for v in tp.xyz_mm.iter_mut() {
            *v = as_written(*v);
        }
        let u = (tp.xyz_mm[0] - MID_MM) / MID_MM;
        let xyz = tp.xyz_mm;
        let d: Vec<i8> = tp.dir.iter().take(3).map(|d| d.unwrap_or(1)).collect();
        let p = forward::predict(&model, &row, "model")
            .expect("prediction")
            .attained_mm;
        let z = if i % 2 == 0 { DELTA_UM } else { -DELTA_UM } * 1e-3;
        s.push_str(&format!(
            "{},{},{:.6},{:.6},{:.6},{},{},{},{:.9},{:.9},{:.9}\n",
            row.id,
            row.t_s.unwrap_or(0.0),
            xyz[0],
            xyz[1],
            xyz[2],
            d[0],
            d[1],
            d[2],
            p[0] + P_UM * 1e-3 * u,
            p[1],
            p[2] + z
        ));
    }
    s
}

/// `v` as the file writes it, 6 decimals, read back.
fn as_written(v: f64) -> f64 {
    format!("{v:.6}").parse().unwrap_or(v)
}

fn covariance_list(model: &Path) -> Vec<serde_yaml::Value> {
    let v: serde_yaml::Value =
        serde_yaml::from_str(&std::fs::read_to_string(model).expect("written")).expect("YAML");
    v["covariance"].as_sequence().cloned().unwrap_or_default()
}

/// The factor of the written table value at `q` mm: (q − 500)/500.
fn factor(q: f64) -> f64 {
    (q - MID_MM) / MID_MM
}

#[test]
fn diagnose_writes_the_fit_covariance_and_report_gives_u_from_it() {
    let dir = tempfile::tempdir().expect("tempdir");
    let model_text = text("machines/afm-r1000.yaml");
    let model = write(dir.path(), "model.yaml", &model_text);
    let obs = write(dir.path(), "obs.csv", &observations(&model_text));
    let out = dir.path().join("fixed.yaml");
    let a = postproc()
        .arg("diagnose")
        .arg("--machine")
        .arg(&model)
        .arg("--observations")
        .arg(&obs)
        .arg("--write-model")
        .arg(&out)
        .args(["--format", "json"])
        .assert()
        .success();
    let d: serde_json::Value =
        serde_json::from_slice(&a.get_output().stdout).expect("diagnosis JSON");
    let found = d["found"].as_array().expect("found");
    assert_eq!(found.len(), 1, "{d}");
    assert_eq!(found[0]["effect"]["name"], "EXX_lin");
    assert_eq!(d["outliers"]["rows"].as_array().map(Vec::len), Some(0));
    let m = d["train_rows"].as_u64().expect("train_rows") as f64;
    let p = &found[0]["params"][0];
    let value = p["value"].as_f64().expect("value");
    assert!((value.abs() - P_UM).abs() <= VALUE_TOL_UM, "{value}");
    // By hand: u² = δ² / (3m − 1) µm².
    let u_p = DELTA_UM / (3.0 * m - 1.0).sqrt();
    let u_fit = p["u"].as_f64().expect("u");
    assert!(
        (u_fit - u_p).abs() <= U_RTOL * u_p,
        "fit u {u_fit} µm, by hand {u_p}"
    );

    // The written block: the data it came from, every table value the
    // effect moved with u_p |q − 500|/500 and correlations ±1.
    let written: serde_yaml::Value =
        serde_yaml::from_str(&std::fs::read_to_string(&out).expect("written")).expect("YAML");
    let positions: Vec<f64> = written["axes"]
        .as_sequence()
        .expect("axes")
        .iter()
        .find(|a| a["name"] == "X")
        .expect("X")["component_errors"]["EXX_um"]["positions_mm"]
        .as_sequence()
        .expect("positions")
        .iter()
        .filter_map(serde_yaml::Value::as_f64)
        .collect();
    let blocks = covariance_list(&out);
    assert_eq!(blocks.len(), 1, "{blocks:?}");
    let b = &blocks[0];
    assert_eq!(b["kind"], "diagnose");
    assert_eq!(b["observations"], "obs.csv");
    assert_eq!(b["rows"].as_u64(), Some(m as u64));
    assert_eq!(b["observations_sha256"].as_str().map(str::len), Some(64));
    let params: Vec<String> = b["parameters"]
        .as_sequence()
        .expect("parameters")
        .iter()
        .filter_map(|v| v.as_str().map(String::from))
        .collect();
    // The node of each parameter, by hand from its key path.
    let node = |path: &str| -> (bool, f64) {
        let rest = path
            .strip_prefix("axes[X].component_errors.EXX_um.")
            .unwrap_or_else(|| panic!("{path}"));
        let (column, k) = rest.split_once('[').expect("index");
        let k: usize = k.trim_end_matches(']').parse().expect("node");
        (column == "forward", positions[k])
    };
    let nonzero = positions.iter().filter(|q| factor(**q) != 0.0).count();
    assert_eq!(params.len(), 2 * nonzero, "{params:?}");
    let us: Vec<f64> = b["u"]
        .as_sequence()
        .expect("u")
        .iter()
        .filter_map(serde_yaml::Value::as_f64)
        .collect();
    for (i, path) in params.iter().enumerate() {
        let (_, q) = node(path);
        let want = u_p * factor(q).abs();
        assert!(
            (us[i] - want).abs() <= U_RTOL * u_p,
            "{path}: u {} by hand {want}",
            us[i]
        );
        for (j, other) in params.iter().enumerate() {
            let (_, r) = node(other);
            let rho = b["correlation"][i][j].as_f64().expect("correlation");
            assert_eq!(rho, (factor(q) * factor(r)).signum(), "{path} {other}");
        }
    }

    // report on the written model: U = 2 · 1e-3 u_p |x − 500|/500 · |dx|/|dev|.
    let program = write(
        dir.path(),
        "p.nc",
        "G90 G54 G0 X-200 Y0 Z50\nG1 X350 F1000\nG1 Y300\nG1 X-100 Y150\nG1 X650\nM30\n",
    );
    let a = postproc()
        .arg("report")
        .arg(&program)
        .arg("--machine")
        .arg(&out)
        .args(["--effects", "geometric", "--format", "json"])
        .assert()
        .success();
    let r: serde_json::Value = serde_json::from_slice(&a.get_output().stdout).expect("JSON");
    let mut checked = 0;
    for row in r["rows"].as_array().expect("rows") {
        let (Some(x), Some(dx), Some(dev), Some(u)) = (
            row["commanded"]["X"].as_f64(),
            row["deviation_mm"][0].as_f64(),
            row["dev_mm"].as_f64(),
            row["u_mm"].as_f64(),
        ) else {
            continue;
        };
        let want = if dev > 0.0 {
            2.0 * 1e-3 * u_p * factor(x).abs() * dx.abs() / dev
        } else {
            0.0
        };
        assert!(
            (u - want).abs() <= REPORT_U_TOL_MM,
            "line {}: U {u}, by hand {want}",
            row["line"]
        );
        if want > REPORT_U_TOL_MM {
            checked += 1;
        }
    }
    assert!(checked >= 3, "{r}");
    assert_eq!(
        r["provenance"]["uncertainty"]["covariance_of"][0],
        "diagnose (obs.csv)"
    );
}

/// `calibrate geometry` writes a geometry block on the nodes of the tables
/// it identified; `diagnose --write-model` then adds a linear X error on
/// a regular grid merged with those nodes (EXX re-gridded), so the
/// geometry block's `EXX_um.forward[k]` would name another position: the
/// written file drops that block with a warning naming it and why, keeps
/// the diagnosis's own block, loads, and `report` gives U from what is
/// left.
#[test]
fn a_regridded_table_drops_the_stale_geometry_block() {
    let dir = tempfile::tempdir().expect("tempdir");
    let calibrated = dir.path().join("calibrated.yaml");
    postproc()
        .args(["calibrate", "geometry", "--machine"])
        .arg(crate::common::repo("machines/afm-r1000.yaml"))
        .arg("--observations")
        .arg(crate::common::repo(
            "samples/observations/afm-r1000-grid-measured.csv",
        ))
        .arg("-o")
        .arg(&calibrated)
        .assert()
        .success();
    let before = covariance_list(&calibrated);
    let geometry: Vec<&serde_yaml::Value> =
        before.iter().filter(|b| b["kind"] == "geometry").collect();
    assert_eq!(geometry.len(), 1, "{before:?}");
    let names_exx = |b: &serde_yaml::Value| {
        b["parameters"].as_sequence().is_some_and(|ps| {
            ps.iter().any(|p| {
                p.as_str()
                    .is_some_and(|p| p.starts_with("axes[X].component_errors.EXX_um."))
            })
        })
    };
    assert!(names_exx(geometry[0]), "{:?}", geometry[0]);
    let cal_text = std::fs::read_to_string(&calibrated).expect("calibrated");
    let obs = write(dir.path(), "obs.csv", &observations(&cal_text));
    let out = dir.path().join("fixed.yaml");
    let a = postproc()
        .arg("diagnose")
        .arg("--machine")
        .arg(&calibrated)
        .arg("--observations")
        .arg(&obs)
        .arg("--write-model")
        .arg(&out)
        .assert()
        .success();
    let o = a.get_output();
    let stdout = String::from_utf8_lossy(&o.stdout);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(stdout.contains("added EXX_lin"), "{stdout}\n{stderr}");
    assert!(
        stderr.contains("covariance[0] (kind geometry, from ")
            && stderr
                .contains("dropped: the table `axes[X].component_errors.EXX_um` was re-gridded"),
        "{stderr}"
    );
    let after = covariance_list(&out);
    assert!(
        after.iter().all(|b| b["kind"] != "geometry"),
        "stale geometry block kept: {after:?}"
    );
    assert!(
        after
            .iter()
            .any(|b| b["kind"] == "diagnose" && names_exx(b)),
        "{after:?}"
    );
    assert!(postproc::machine::Machine::load(&out).is_ok());
    let program = write(
        dir.path(),
        "p.nc",
        "G90 G54 G0 X-200 Y0 Z50\nG1 X350 F1000\nG1 Y300\nM30\n",
    );
    let r = postproc()
        .arg("report")
        .arg(&program)
        .arg("--machine")
        .arg(&out)
        .args(["--effects", "geometric", "--format", "json"])
        .assert()
        .success();
    let r: serde_json::Value = serde_json::from_slice(&r.get_output().stdout).expect("JSON");
    let rows = r["rows"].as_array().expect("rows");
    assert!(rows.iter().any(|row| row["u_mm"].as_f64().is_some()), "{r}");
}

/// A covariance block naming a value the machine file does not have (here
/// a table the file never had, as a hand edit or an older file would
/// leave it) is an error of `report` naming the block and the parameter's
/// place in it, never a silent skip.
#[test]
fn a_block_naming_an_unknown_value_is_an_error_with_its_key_path() {
    let dir = tempfile::tempdir().expect("tempdir");
    let calibrated = dir.path().join("calibrated.yaml");
    postproc()
        .args(["calibrate", "geometry", "--machine"])
        .arg(crate::common::repo("machines/afm-r1000.yaml"))
        .arg("--observations")
        .arg(crate::common::repo(
            "samples/observations/afm-r1000-grid-measured.csv",
        ))
        .arg("-o")
        .arg(&calibrated)
        .assert()
        .success();
    let list = covariance_list(&calibrated);
    let geometry = list
        .iter()
        .position(|b| b["kind"] == "geometry")
        .expect("geometry block");
    let first = list[geometry]["parameters"][0]
        .as_str()
        .expect("a parameter")
        .to_string();
    let bogus = "axes[X].component_errors.EQQ_um.forward[0]";
    let cal_text = std::fs::read_to_string(&calibrated).expect("calibrated");
    assert!(!cal_text.contains("EQQ_um"), "{cal_text}");
    // The writer quotes each parameter (`parameters: ["axes[X]…", …]`).
    let edited = cal_text.replacen(
        &format!("parameters: [\"{first}\""),
        &format!("parameters: [\"{bogus}\""),
        1,
    );
    assert_ne!(edited, cal_text, "parameter list not found as written");
    let model = write(dir.path(), "edited.yaml", &edited);
    let program = write(
        dir.path(),
        "p.nc",
        "G90 G54 G0 X-200 Y0 Z50\nG1 X350 F1000\nG1 Y300\nM30\n",
    );
    let r = postproc()
        .arg("report")
        .arg(&program)
        .arg("--machine")
        .arg(&model)
        .args(["--effects", "geometric", "--format", "json"])
        .assert()
        .failure();
    let stderr = String::from_utf8_lossy(&r.get_output().stderr);
    assert!(
        stderr.contains(&format!("covariance[{geometry}].parameters[0]: `{bogus}`")),
        "{stderr}"
    );
}
