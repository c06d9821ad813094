//! `postproc verify` through the binary: the figures of the samples in
//! samples/verify/ against values derived by hand (docs/verify.md), limits
//! from the command line and the machine file, exit codes, located errors,
//! the JSON schema, and ISO 230-2 predicted by a model.

use serde_json::Value;

use crate::common::{postproc, repo, write};

/// Figures agree to a nanometre (the JSON report rounds to 1e-6 mm).
const NM: f64 = 1.001e-6;

/// Runs `postproc verify ARGS --format json`; (exit code, report, stderr).
fn verify_json(args: &[&str]) -> (i32, Value, String) {
    let out = postproc()
        .current_dir(repo(""))
        .arg("verify")
        .args(args)
        .args(["--format", "json"])
        .output()
        .expect("run");
    let code = out.status.code().expect("exit code");
    let stderr = String::from_utf8_lossy(&out.stderr).to_string();
    let report = if code <= 1 {
        let r: Value = serde_json::from_slice(&out.stdout).expect("JSON report");
        validate(&r);
        r
    } else {
        Value::Null
    };
    (code, report, stderr)
}

/// Runs `postproc verify ARGS` (table); (exit code, stdout, stderr).
fn verify(args: &[&str]) -> (i32, String, String) {
    let out = postproc()
        .current_dir(repo(""))
        .arg("verify")
        .args(args)
        .output()
        .expect("run");
    (
        out.status.code().expect("exit code"),
        String::from_utf8_lossy(&out.stdout).to_string(),
        String::from_utf8_lossy(&out.stderr).to_string(),
    )
}

/// Validates a report against schemas/verify.schema.json, and checks that
/// the schema is not vacuous.
fn validate(report: &Value) {
    let schema: Value = serde_json::from_str(
        &std::fs::read_to_string(repo("schemas/verify.schema.json")).expect("schema file"),
    )
    .expect("schema is JSON");
    let mut schemas = boon::Schemas::new();
    let mut compiler = boon::Compiler::new();
    let url = "https://postproc.example/schemas/verify.schema.json";
    compiler.add_resource(url, schema).expect("schema resource");
    let idx = compiler
        .compile(url, &mut schemas)
        .expect("schema compiles");
    if let Err(e) = schemas.validate(report, idx) {
        panic!("report does not match the schema: {e:#}");
    }
    let mut bad = report.clone();
    bad["groups"][0]["figures"]["Q_mm"] = serde_json::json!(1.0);
    assert!(
        schemas.validate(&bad, idx).is_err(),
        "unknown figure accepted"
    );
    let mut bad = report.clone();
    if let Some(o) = bad.as_object_mut() {
        o.remove("verdict");
    }
    assert!(
        schemas.validate(&bad, idx).is_err(),
        "report without verdict accepted"
    );
}

/// The figure `name` of group `group`, mm.
fn figure(r: &Value, group: &str, name: &str) -> f64 {
    r["groups"]
        .as_array()
        .expect("groups")
        .iter()
        .find(|g| g["name"] == group)
        .unwrap_or_else(|| panic!("group {group}"))["figures"][format!("{name}_mm")]
    .as_f64()
    .unwrap_or_else(|| panic!("figure {name}"))
}

/// Asserts the figures of a group equal hand-derived values.
fn assert_figures(r: &Value, group: &str, want: &[(&str, f64)]) {
    for &(name, w) in want {
        let got = figure(r, group, name);
        assert!((got - w).abs() <= NM, "{group} {name}: {got} vs {w}");
    }
}

/// ISO 230-2 of samples/verify/iso230-2-x.csv, derived by hand in
/// docs/verify.md: means and s per target, then the axis figures.
const X_AXIS: [(&str, f64); 12] = [
    ("E_up", 0.006),
    ("E_down", 0.005),
    ("E", 0.008),
    ("M", 0.0055),
    ("A_up", 0.011),
    ("A_down", 0.011),
    ("A", 0.013),
    ("R_up", 0.008),
    ("R_down", 0.008),
    ("R", 0.009),
    ("B", 0.004),
    ("B_mean", 0.0028),
];

#[test]
fn iso230_2_reproduces_the_hand_derived_figures() {
    let (code, r, _) = verify_json(&["iso230-2", "samples/verify/iso230-2-x.csv"]);
    assert_eq!(code, 0);
    assert_eq!(r["standard"], "ISO 230-2");
    assert_eq!(r["verdict"], "no limits");
    assert_figures(&r, "X", &X_AXIS);
    let t = &r["detail"]["axes"][0]["targets"][2];
    assert_eq!(t["target_mm"], 200.0);
    assert_eq!(t["runs_up"], 5);
    assert!((t["s_up_mm"].as_f64().unwrap() - 0.002).abs() <= NM);
    assert!((t["repeatability_mm"].as_f64().unwrap() - 0.009).abs() <= NM);
}

#[test]
fn iso230_2_exits_1_when_a_limit_is_exceeded() {
    let file = "samples/verify/iso230-2-x.csv";
    let (code, out, _) = verify(&["iso230-2", file, "--limit", "A=0.012"]);
    assert_eq!(code, 1, "{out}");
    assert!(
        out.contains("  X        A           0.0130 >      0.0120  FAIL  (command line)"),
        "{out}"
    );
    assert!(out.ends_with("verdict: fail\n"), "{out}");
    let (code, r, _) = verify_json(&[
        "iso230-2",
        file,
        "--limit",
        "A=0.014",
        "--limit",
        "X.R=0.0095",
    ]);
    assert_eq!(code, 0);
    assert_eq!(r["verdict"], "pass");
    assert_eq!(r["checks"].as_array().unwrap().len(), 2);
    // Exactly at the limit passes.
    let (code, _, _) = verify(&["iso230-2", file, "--limit", "B=0.004"]);
    assert_eq!(code, 0);
}

#[test]
fn limits_come_from_the_machine_file_and_the_command_line_replaces_them() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(repo("machines/afm-r1000.yaml")).unwrap();
    let m = write(
        dir.path(),
        "m.yaml",
        &format!(
            "{text}acceptance:\n  iso230_2:\n    X: {{ A_mm: 0.010, R_mm: 0.010 }}\n  iso230_4: {{ H_mm: 0.0005 }}\n"
        ),
    );
    let m = m.to_str().unwrap();
    // The file still loads for every other command.
    let (code, _, err) = verify(&[
        "iso230-2",
        "--predict",
        "--machine",
        m,
        "--targets",
        "0,250,500,750,1000",
    ]);
    assert_ne!(code, 2, "{err}");
    let file = "samples/verify/iso230-2-x.csv";
    let (code, r, _) = verify_json(&["iso230-2", file, "--machine", m]);
    assert_eq!(code, 1);
    let checks = r["checks"].as_array().unwrap();
    assert_eq!(checks.len(), 2);
    assert_eq!(checks[0]["figure"], "A");
    assert_eq!(checks[0]["source"], "machine file");
    assert_eq!(checks[0]["pass"], false);
    assert_eq!(checks[1]["pass"], true);
    let (code, r, _) = verify_json(&["iso230-2", file, "--machine", m, "--limit", "A=0.02"]);
    assert_eq!(code, 0);
    assert_eq!(r["checks"][0]["source"], "command line");
    let (code, _, _) = verify(&["iso230-4", "samples/verify/iso230-4-xy.csv", "--machine", m]);
    assert_eq!(code, 1);
}

#[test]
fn iso230_4_reproduces_the_hand_derived_figures() {
    // Radial deviations: ccw 2,0,2,0,… µm and cw 3,1,2,1,… µm at every
    // 45°, both plus a centre offset (3, 1.5) µm and 0.5 µm of radius.
    let file = "samples/verify/iso230-4-xy.csv";
    let (code, r, _) = verify_json(&["iso230-4", file]);
    assert_eq!(code, 0);
    assert_figures(
        &r,
        "circle",
        &[
            ("G_ccw", 0.002),
            ("G_cw", 0.002),
            ("G", 0.002),
            ("G_b", 0.003),
            ("H", 0.001),
        ],
    );
    assert!((r["detail"]["circle_both"]["centre_x_mm"].as_f64().unwrap() - 0.003).abs() <= NM);
    assert!((r["detail"]["circle_both"]["centre_y_mm"].as_f64().unwrap() - 0.0015).abs() <= NM);
    let (code, out, _) = verify(&[
        "iso230-4",
        file,
        "--limit",
        "G_b=0.0025",
        "--limit",
        "H=0.001",
    ]);
    assert_eq!(code, 1);
    assert!(
        out.contains("circle   G_b         0.0030 >      0.0025  FAIL"),
        "{out}"
    );
    assert!(
        out.contains("circle   H           0.0010 <=     0.0010  pass"),
        "{out}"
    );
}

#[test]
fn iso9283_reproduces_the_hand_derived_figures() {
    // Each pose: 30 visits at +a, −a in x, +a, −a in y and 0 about the
    // barycentre, so l̄ = 0.8 a and S_l = a·sqrt(4.8/29) = 0.4068381 a;
    // RP = a·(0.8 + 3·0.4068381) = 2.0205143 a. P5 has a = 0.06 mm.
    // The path's points: 10 runs, the same pattern, S_l = b·sqrt(1.6/9).
    let (code, r, _) = verify_json(&[
        "iso9283",
        "samples/verify/iso9283-poses.csv",
        "--path",
        "samples/verify/iso9283-path.csv",
    ]);
    assert_eq!(code, 0);
    assert_figures(&r, "poses", &[("AP", 1.0), ("RP", 0.121_231)]);
    assert_figures(&r, "path", &[("AT", 0.25), ("RT", 0.061_947)]);
    let p1 = &r["detail"]["poses"][0];
    assert_eq!(p1["label"], "P1");
    assert_eq!(p1["visits"], 30);
    assert!((p1["ap_mm"].as_f64().unwrap() - 0.5).abs() <= NM);
    assert!((p1["ap_y_mm"].as_f64().unwrap() + 0.4).abs() <= NM);
    assert!((p1["l_mean_mm"].as_f64().unwrap() - 0.04).abs() <= NM);
    assert!((p1["rp_mm"].as_f64().unwrap() - 0.101_026).abs() <= NM);
    let (code, out, _) = verify(&[
        "iso9283",
        "samples/verify/iso9283-poses.csv",
        "--limit",
        "RP=0.1",
    ]);
    assert_eq!(code, 1);
    assert!(
        out.contains("poses    RP          0.1212 >      0.1000  FAIL"),
        "{out}"
    );
    // Without path data there are no AT and RT, and a limit on them is refused.
    let (code, _, err) = verify(&[
        "iso9283",
        "samples/verify/iso9283-poses.csv",
        "--limit",
        "path.AT=1",
    ]);
    assert_eq!(code, 2);
    assert!(err.contains("no `path` in the data"), "{err}");
}

#[test]
fn iso9283_orientation_reproduces_the_hand_derived_figures() {
    // samples/verify/iso9283-orientation.csv: 10 cycles of P1 … P5; at
    // each pose every angle is its command + an offset + (−s five times,
    // +s five times), so the mean difference is the offset and
    // S = s·sqrt(10/9) = 1.0540926 s, RP = 3 S = 3.1622777 s. Offsets and
    // s (deg): P1 (0.01, −0.02, 0.005), (0.002, 0.001, 0.003); P2 (−0.03,
    // 0.01, 0), (0.001, 0.004, 0.001); P3 (0, 0, 0.02), (0.003, 0.002,
    // 0.002) with c commanded at 179.99° and attained across ±180°; P4
    // (0.015, 0.025, −0.01), (0.002, 0.002, 0.005); P5 (0.005, −0.005, 0),
    // (0.001, 0.001, 0.001). Largest magnitudes: APa = −0.03 (P2),
    // APb = 0.025 (P4), APc = 0.02 (P3); RPa = 3.1622777·0.003 = 0.009487
    // (P3), RPb = 3.1622777·0.004 = 0.012649 (P2), RPc = 3.1622777·0.005
    // = 0.015811 (P4).
    let want = [
        ("APa", -0.03),
        ("APb", 0.025),
        ("APc", 0.02),
        ("RPa", 0.009_487),
        ("RPb", 0.012_649),
        ("RPc", 0.015_811),
    ];
    let (code, r, _) = verify_json(&["iso9283", "samples/verify/iso9283-orientation.csv"]);
    assert_eq!(code, 0);
    let group = r["groups"]
        .as_array()
        .expect("groups")
        .iter()
        .find(|g| g["name"] == "orientation")
        .expect("an orientation group")
        .clone();
    for (name, w) in want {
        let got = group["figures"][format!("{name}_deg")]
            .as_f64()
            .unwrap_or_else(|| panic!("{name}_deg"));
        // 1e-6 of rounding in the report, and the sample's six decimals.
        assert!((got - w).abs() <= 1.5e-6, "{name}: {got} vs {w}");
    }
    let p3 = &r["detail"]["poses"][2];
    assert!((p3["ap_c_deg"].as_f64().unwrap() - 0.02).abs() <= 1.5e-6);
    // Position: every visit 0.1 mm off in x, no scatter.
    assert_figures(&r, "poses", &[("AP", 0.1), ("RP", 0.0)]);
    let (code, out, _) = verify(&[
        "iso9283",
        "samples/verify/iso9283-orientation.csv",
        "--limit",
        "RPc=0.015",
        "--limit",
        "APa=0.05",
    ]);
    assert_eq!(code, 1, "{out}");
    assert!(
        out.contains("RPc         0.0158 >      0.0150  FAIL"),
        "{out}"
    );
    assert!(
        out.contains("APa        -0.0300 <=     0.0500  pass"),
        "{out}"
    );
    assert!(out.contains("(mm; APa … RPc: deg)"), "{out}");
    // A row with part of an orientation is refused at its line.
    let dir = tempfile::tempdir().expect("tempdir");
    let text = std::fs::read_to_string(repo("samples/verify/iso9283-orientation.csv")).unwrap();
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    lines[4] = lines[4].rsplit_once(',').unwrap().0.to_string() + ",";
    let bad = write(dir.path(), "bad.csv", &(lines.join("\n") + "\n"));
    let (code, _, err) = verify(&["iso9283", bad.to_str().unwrap()]);
    assert_eq!(code, 2);
    assert!(
        err.contains("bad.csv:5:") && err.contains("`c_deg` not given"),
        "{err}"
    );
}

#[test]
fn bad_input_exits_2_with_a_located_error_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("r.json");
    let out_s = out.to_str().unwrap();
    let bad = write(
        dir.path(),
        "x.csv",
        "axis,run,dir,target_mm,actual_mmm\nX,1,+1,0,0\n",
    );
    let (code, _, err) = verify(&["iso230-2", bad.to_str().unwrap(), "-o", out_s]);
    assert_eq!(code, 2);
    assert!(
        err.contains("x.csv:1:24: unknown column `actual_mmm`"),
        "{err}"
    );
    assert!(!out.exists());
    let bad = write(
        dir.path(),
        "c.csv",
        "dir,angle_deg,dr_mm\n+1,0,0.001\ncw,45,0\n",
    );
    let (code, _, err) = verify(&["iso230-4", bad.to_str().unwrap()]);
    assert_eq!(code, 2);
    assert!(
        err.contains("c.csv:3:1: column `dir`: expected +1 or -1, found `cw`"),
        "{err}"
    );
    let bad = write(
        dir.path(),
        "p.csv",
        "pose,xc_mm,yc_mm,zc_mm,x_mm,y_mm,z_mm\nP1,0,0,0,0,,0\n",
    );
    let (code, _, err) = verify(&["iso9283", bad.to_str().unwrap()]);
    assert_eq!(code, 2);
    assert!(err.contains("p.csv:2:1: empty `y_mm`"), "{err}");
    let (code, _, err) = verify(&[
        "iso230-2",
        "samples/verify/iso230-2-x.csv",
        "--limit",
        "G=1",
    ]);
    assert_eq!(code, 2);
    assert!(err.contains("ISO 230-2 has no figure `G`"), "{err}");
    let (code, _, _) = verify(&[
        "iso230-2",
        "samples/verify/iso230-2-x.csv",
        "--limit",
        "A=-1",
    ]);
    assert_eq!(code, 2);
    let (code, _, err) = verify(&["iso230-2", "no-such-file.csv"]);
    assert_eq!(code, 2);
    assert!(err.contains("no-such-file.csv"), "{err}");
}

/// A machine whose only error is the X positioning EXX(x): forward and
/// reverse tables at 0, 100, … 400 mm, the mean deviations of the sample.
fn exx_machine(dir: &std::path::Path) -> String {
    let m = write(
        dir,
        "exx.yaml",
        "kind: machine_tool
name: EXX only
axes:
  - name: X
    type: linear
    side: workpiece
    travel_mm: [0, 400]
    rapid_mm_per_min: 20000
    component_errors:
      EXX_um:
        positions_mm: [0, 100, 200, 300, 400]
        forward: [0, 3, 5, 4, 6]
        reverse: [-2, 1, 2, 0, 3]
  - name: Y
    type: linear
    side: workpiece
    travel_mm: [0, 300]
    rapid_mm_per_min: 20000
  - name: Z
    type: linear
    side: tool
    travel_mm: [0, 300]
    rapid_mm_per_min: 20000
",
    );
    m.to_str().unwrap().to_string()
}

#[test]
fn iso230_2_predicted_from_a_model() {
    let dir = tempfile::tempdir().unwrap();
    let m = exx_machine(dir.path());
    let (code, r, err) = verify_json(&[
        "iso230-2",
        "--predict",
        "--machine",
        &m,
        "--axis",
        "X",
        "--targets",
        "0,100,200,300,400",
    ]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(r["source"]["kind"], "predicted");
    // The sample's means without scatter: A = E, R_up = R_down = 0 and
    // R = B = max |B_i|.
    assert_figures(
        &r,
        "X",
        &[
            ("E_up", 0.006),
            ("E_down", 0.005),
            ("E", 0.008),
            ("M", 0.0055),
            ("A_up", 0.006),
            ("A_down", 0.005),
            ("A", 0.008),
            ("R_up", 0.0),
            ("R_down", 0.0),
            ("R", 0.004),
            ("B", 0.004),
            ("B_mean", 0.0028),
        ],
    );
    let (code, _, err) = verify(&[
        "iso230-2",
        "--predict",
        "--machine",
        &m,
        "--targets",
        "0,100,200,300,500",
    ]);
    assert_eq!(code, 2);
    assert!(err.contains("500 mm is outside the travel of X"), "{err}");
    let (code, _, err) = verify(&[
        "iso230-2",
        "--predict",
        "--machine",
        &m,
        "--targets",
        "0,100",
    ]);
    assert_eq!(code, 2);
    assert!(err.contains("at least 5"), "{err}");
}

#[test]
fn iso230_2_after_compensation_keeps_the_scatter_only() {
    let dir = tempfile::tempdir().unwrap();
    let m = exx_machine(dir.path());
    let (code, r, err) = verify_json(&[
        "iso230-2",
        "samples/verify/iso230-2-x.csv",
        "--compensated",
        "--machine",
        &m,
    ]);
    assert_eq!(code, 0, "{err}");
    // The model is the sample's means: what remains is s (1 or 2 µm):
    // A_up = 2·0.002 + 2·0.002, R_i = max(2 s↑ + 2 s↓, 4 s↑, 4 s↓).
    assert_figures(
        &r,
        "X",
        &[
            ("E", 0.0),
            ("M", 0.0),
            ("B", 0.0),
            ("A_up", 0.008),
            ("A_down", 0.008),
            ("A", 0.008),
            ("R_up", 0.008),
            ("R_down", 0.008),
            ("R", 0.008),
        ],
    );
}

/// The examples of docs/verify.md: each ```text block whose first line is
/// `$ postproc verify …` shows that command's output (stdout and stderr),
/// run in the repository.
#[test]
fn the_examples_of_docs_verify_md_show_real_output() {
    let doc = std::fs::read_to_string(repo("docs/verify.md")).expect("docs/verify.md");
    let mut examples = 0;
    for block in doc.split("```text\n").skip(1) {
        let body = block.split("```").next().unwrap_or_default();
        let mut lines = body.lines();
        let Some(cmd) = lines.next().and_then(|l| l.strip_prefix("$ postproc ")) else {
            continue;
        };
        let shown: Vec<&str> = lines.map(str::trim_end).collect();
        let out = postproc()
            .current_dir(repo(""))
            .args(cmd.split_whitespace())
            .output()
            .expect("run");
        let mut got = String::from_utf8_lossy(&out.stdout).to_string();
        got.push_str(&String::from_utf8_lossy(&out.stderr));
        let got: Vec<&str> = got.lines().map(str::trim_end).collect();
        assert_eq!(got, shown, "docs/verify.md: `{cmd}`");
        examples += 1;
    }
    assert_eq!(examples, 4, "examples of docs/verify.md");
}

/// A machine whose only error is a scale error of X, EXX = 0.05 µm/mm,
/// with a reversal of `reversal_um` in the reverse column.
fn scale_machine(dir: &std::path::Path, reversal_um: f64) -> String {
    let m = write(
        dir,
        &format!("scale{reversal_um}.yaml"),
        &format!(
            "kind: machine_tool
name: X scale
axes:
  - name: X
    type: linear
    side: workpiece
    travel_mm: [0, 400]
    rapid_mm_per_min: 20000
    component_errors:
      EXX_um: {{ positions_mm: [0, 400], forward: [0, 20], reverse: [{reversal_um}, {}] }}
  - name: Y
    type: linear
    side: workpiece
    travel_mm: [0, 300]
    rapid_mm_per_min: 20000
  - name: Z
    type: linear
    side: tool
    travel_mm: [0, 300]
    rapid_mm_per_min: 20000
",
            20.0 + reversal_um
        ),
    );
    m.to_str().unwrap().to_string()
}

#[test]
fn iso230_4_predicted_from_a_model() {
    let dir = tempfile::tempdir().unwrap();
    // A scale error k = 5e-5 on a circle of R = 100 mm about X = 200:
    // dr = k (200 + R cos θ) cos θ = k·200 cos θ + kR/2 + kR/2 cos 2θ;
    // the least-squares circle takes the first two terms, the range of
    // the third is kR = 0.005 mm in both directions, without hysteresis.
    let m = scale_machine(dir.path(), 0.0);
    let args = [
        "iso230-4",
        "--predict",
        "--machine",
        &m,
        "--radius",
        "100",
        "--at",
        "X=200,Y=150",
    ];
    let (code, r, err) = verify_json(&args);
    assert_eq!(code, 0, "{err}");
    assert_figures(
        &r,
        "circle",
        &[
            ("G_ccw", 0.005),
            ("G_cw", 0.005),
            ("G_b", 0.005),
            ("H", 0.0),
        ],
    );
    // A reversal of 2 µm: X moves in − on 0° < θ < 180° counter-clockwise
    // and on 180° < θ < 360° clockwise, so at 1° (and 179°, 181°, 359°)
    // one path holds 2 µm·cos 1° more than the other: H = 0.0019997 mm.
    let m = scale_machine(dir.path(), 2.0);
    let args = [
        "iso230-4",
        "--predict",
        "--machine",
        &m,
        "--radius",
        "100",
        "--at",
        "X=200,Y=150",
    ];
    let (code, r, err) = verify_json(&args);
    assert_eq!(code, 0, "{err}");
    assert_figures(&r, "circle", &[("H", 0.002 * 1f64.to_radians().cos())]);
    let (code, _, err) = verify(&["iso230-4", "--predict", "--machine", &m, "--radius", "250"]);
    assert_eq!(code, 2);
    assert!(err.contains("the circle leaves the travel of X"), "{err}");
    let (code, _, err) = verify(&[
        "iso230-4",
        "--predict",
        "--machine",
        &m,
        "--radius",
        "10",
        "--plane",
        "XX",
    ]);
    assert_eq!(code, 2);
    assert!(err.contains("--plane XX"), "{err}");
}

/// The EXX-only machine of [`exx_machine`] with the tables `forward` and
/// `reverse` (µm) and a covariance of two of its values: forward[4] (400
/// mm, u = [`U_F4_UM`]) and reverse[0] (0 mm, u = [`U_R0_UM`]),
/// correlated by [`RHO`].
fn exx_machine_with_covariance(dir: &std::path::Path, forward: &str, reverse: &str) -> String {
    let text = std::fs::read_to_string(exx_machine(dir)).expect("machine");
    let text = text
        .replace("forward: [0, 3, 5, 4, 6]", &format!("forward: {forward}"))
        .replace("reverse: [-2, 1, 2, 0, 3]", &format!("reverse: {reverse}"));
    let m = write(
        dir,
        "exx-cov.yaml",
        &format!(
            "{text}covariance:\n  - kind: geometry\n    observations: \"hand.csv\"\n    observations_sha256: 00\n    rows: 10\n    parameters: [\"axes[X].component_errors.EXX_um.forward[4]\", \"axes[X].component_errors.EXX_um.reverse[0]\"]\n    u: [{U_F4_UM}, {U_R0_UM}]\n    correlation:\n      - [1.0, {RHO}]\n      - [{RHO}, 1.0]\n"
        ),
    );
    m.to_str().unwrap().to_string()
}

const U_F4_UM: f64 = 2.0;
const U_R0_UM: f64 = 1.0;
const RHO: f64 = 0.5;

/// The U (k=2) of figure `name` of group `group`, mm.
fn figure_u(r: &Value, group: &str, name: &str) -> f64 {
    let g = r["groups"]
        .as_array()
        .expect("groups")
        .iter()
        .find(|g| g["name"] == group)
        .unwrap_or_else(|| panic!("group {group}"));
    assert_eq!(g["uncertainty"]["k"], 2.0);
    g["uncertainty"]["figures"][format!("{name}_mm")]
        .as_f64()
        .unwrap_or_else(|| panic!("U of {name}"))
}

/// Each ISO 230-2 figure's U (k=2) from the model's covariance, derived
/// by hand. The model's X deviation at 400 mm approached in + is
/// forward[4] (1e-3 mm per µm; a = u of it) and at 0 mm approached in −
/// is reverse[0] (b); no other prediction is uncertain, and cov(400↑, 0↓)
/// = ρ a b. A figure moves with the means of the targets that attain its
/// extremes (after compensation each mean is the measured one less the
/// prediction; predicted, the prediction itself), so with
/// w = 1e-3 √(a² + b² − 2ρab) (E's two ends move against each other):
/// - after compensation of the sample (model 0: the figures are the
///   sample's): E = x̄↑(400) − x̄↓(0) → U = 2w; E↑ = x̄↑(400) − x̄↑(0)
///   → 2·1e-3 a; E↓ = x̄↓(400) − x̄↓(0) → 2·1e-3 b; M = x̄(400) − x̄(0),
///   each half a direction → w; A↑ = 9 (200↑) − (−2) (0↑) → 0;
///   A↓ = 7 (400↓) − (−4) (0↓) → 2·1e-3 b; A = 9 (200↑) − (−4) (0↓) →
///   2·1e-3 b; R↑, R↓ are scatter → 0; B = |B(300)| → 0;
///   B̄ = mean B_i, B(400) with −x̄↑(400), B(0) with +x̄↓(0) → 2w/5;
///   R = 9 at 200 and at 400 (2 s↑ + 2 s↓ + |B(400)| = 2 + 4 + 3), a
///   tie: R(400) grows as the prediction at 400↑ falls, so the larger
///   one-sided U is 2·1e-3 a;
/// - predicted by the model with the sample's means as tables (s = 0):
///   E, A → 2w, E↑, A↑ → 2·1e-3 a, E↓, A↓ → 2·1e-3 b, M → w, B̄ → 2w/5,
///   R = B = |B(300)| → 0, R↑ = R↓ = 0 → 0.
#[test]
fn iso230_2_figures_carry_u_from_the_covariance() {
    let (a, b) = (U_F4_UM, U_R0_UM);
    let w = 1e-3 * (a * a + b * b - 2.0 * RHO * a * b).sqrt();
    let ua = 2e-3 * a;
    let ub = 2e-3 * b;
    let dir = tempfile::tempdir().unwrap();
    let zero = exx_machine_with_covariance(dir.path(), "[0, 0, 0, 0, 0]", "[0, 0, 0, 0, 0]");
    let (code, r, err) = verify_json(&[
        "iso230-2",
        "samples/verify/iso230-2-x.csv",
        "--compensated",
        "--machine",
        &zero,
    ]);
    assert_eq!(code, 0, "{err}");
    assert_figures(&r, "X", &X_AXIS);
    let after = [
        ("E_up", ua),
        ("E_down", ub),
        ("E", 2.0 * w),
        ("M", w),
        ("A_up", 0.0),
        ("A_down", ub),
        ("A", ub),
        ("R_up", 0.0),
        ("R_down", 0.0),
        ("R", ua),
        ("B", 0.0),
        ("B_mean", 2.0 * w / 5.0),
    ];
    for (name, want) in after {
        let got = figure_u(&r, "X", name);
        assert!(
            (got - want).abs() <= NM,
            "after: U of {name} {got}, by hand {want}"
        );
    }
    assert!(
        r["source"]["note"].as_str().is_some_and(
            |n| n.contains("U (k=2) from the parameter covariance of geometry (hand.csv)")
        ),
        "{}",
        r["source"]
    );

    let means = exx_machine_with_covariance(dir.path(), "[0, 3, 5, 4, 6]", "[-2, 1, 2, 0, 3]");
    let (code, r, err) = verify_json(&[
        "iso230-2",
        "--predict",
        "--machine",
        &means,
        "--targets",
        "0,100,200,300,400",
    ]);
    assert_eq!(code, 0, "{err}");
    let predicted = [
        ("E_up", ua),
        ("E_down", ub),
        ("E", 2.0 * w),
        ("M", w),
        ("A_up", ua),
        ("A_down", ub),
        ("A", 2.0 * w),
        ("R_up", 0.0),
        ("R_down", 0.0),
        ("R", 0.0),
        ("B", 0.0),
        ("B_mean", 2.0 * w / 5.0),
    ];
    for (name, want) in predicted {
        let got = figure_u(&r, "X", name);
        assert!(
            (got - want).abs() <= NM,
            "predicted: U of {name} {got}, by hand {want}"
        );
    }
    // The table shows value ± U.
    let (code, table, _) = verify(&[
        "iso230-2",
        "--predict",
        "--machine",
        &means,
        "--targets",
        "0,100,200,300,400",
    ]);
    assert_eq!(code, 0);
    assert!(table.contains("(mm; value ± U, k=2)"), "{table}");
    assert!(
        table.contains(&format!("0.0080 ± {:.4}", 2.0 * w)),
        "{table}"
    );
}
