//! Integration tests of the process effects through the binary: static
//! deflection under a process force, thermal drift on the program's time
//! line, vibration at the tooth-passing frequency, the milling directive,
//! effect switches and gains. Every machine file is written for the test,
//! error-free unless the test needs geometric errors, so each expected value
//! can be derived by hand (derivations in the comments).

use std::path::{Path, PathBuf};

use approx::assert_abs_diff_eq;

use crate::common::{postproc, repo, text_without_header, write};

/// Compensated coordinates are written with 6 decimals.
const POS_TOL_MM: f64 = 1e-6;
/// The report prints deviations with 5 decimals.
const REPORT_TOL_MM: f64 = 1e-5;

const AXES: &str = "kind: machine_tool
name: effects test
units_default: mm
axes:
  - { name: X, type: linear, side: workpiece, travel_mm: [-500, 500], rapid_mm_per_min: 60000 }
  - { name: Y, type: linear, side: workpiece, travel_mm: [-500, 500], rapid_mm_per_min: 60000 }
  - { name: Z, type: linear, side: tool, travel_mm: [-500, 500], rapid_mm_per_min: 60000 }
";

const STIFF_20: &str = "stiffness:
  k_n_per_um: { x_pos: 20, x_neg: 20, y_pos: 20, y_neg: 20, z_pos: 20, z_neg: 40 }
";

/// Runs `compensate … -o - --decimals 6` and returns stdout.
fn compensate(machine: &Path, program: &Path, extra: &[&str]) -> String {
    let out = postproc()
        .arg("compensate")
        .arg(program)
        .arg("-m")
        .arg(machine)
        .args(["-o", "-", "--decimals", "6"])
        .args(extra)
        .output()
        .expect("run postproc");
    assert!(
        out.status.success(),
        "compensate failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    text_without_header(&String::from_utf8(out.stdout).expect("utf-8 output"))
}

/// The value of `letter` in the `n`-th (1-based) output line.
fn word(out: &str, n: usize, letter: char) -> f64 {
    let line = out.lines().nth(n - 1).expect("line exists");
    let code = line.split('(').next().unwrap_or("");
    code.split_whitespace()
        .find_map(|w| w.strip_prefix(letter))
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no {letter} word in `{line}`"))
}

/// The value of `letter` where the block on output line `n` (1-based)
/// ends: a block that starts with a takeup point or is split goes on over
/// the added lines after it (up to the next annotated block), and an added
/// line carries only the axes that move.
fn end_word(out: &str, n: usize, letter: char) -> f64 {
    let lines: Vec<&str> = out.lines().collect();
    let own = 1 + lines[n..]
        .iter()
        .take_while(|l| !l.contains("(dev "))
        .count();
    let block = lines[n - 1..n - 1 + own].to_vec();
    block
        .iter()
        .rev()
        .find_map(|line| {
            let code = line.split('(').next().unwrap_or("");
            code.split_whitespace()
                .find_map(|w| w.strip_prefix(letter))
                .and_then(|v| v.parse().ok())
        })
        .unwrap_or_else(|| panic!("no {letter} word in `{block:?}`"))
}

/// `report --format csv` rows as (header, rows of fields).
fn report(machine: &Path, program: &Path, extra: &[&str]) -> (Vec<String>, Vec<Vec<String>>) {
    let out = postproc()
        .arg("report")
        .arg(program)
        .arg("-m")
        .arg(machine)
        .args(["--format", "csv"])
        .args(extra)
        .output()
        .expect("run postproc");
    assert!(
        out.status.success(),
        "report failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).expect("utf-8 output");
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header = lines
        .next()
        .expect("header")
        .split(',')
        .map(String::from)
        .collect();
    let rows = lines
        .map(|l| l.split(',').map(String::from).collect())
        .collect();
    (header, rows)
}

fn col(header: &[String], row: &[String], name: &str) -> f64 {
    let i = header
        .iter()
        .position(|h| h == name)
        .unwrap_or_else(|| panic!("no column {name} in {header:?}"));
    row[i].parse().expect("number")
}

#[test]
fn constant_200_n_against_20_n_per_um_gives_a_10_um_correction() {
    let dir = tempfile::tempdir().expect("tempdir");
    let m = write(
        dir.path(),
        "m.yaml",
        &format!("{AXES}{STIFF_20}process_force:\n  model: constant\n  force_n: [0, 0, 200]\n"),
    );
    let p = write(dir.path(), "p.nc", "G0 X0 Y0 Z0\nG1 X10 F100\n");
    // 200 N on the tool along +Z (the workpiece pushes the tool up); k_z+ =
    // 20 N/µm: the tip gives way by +200/20 = +10 µm, so the program is
    // moved down by 10 µm. Rapids carry no process force.
    let out = compensate(&m, &p, &[]);
    assert_abs_diff_eq!(word(&out, 2, 'Z'), -0.010, epsilon = POS_TOL_MM);
    assert!(
        out.lines().nth(1).unwrap_or("").contains("stat 0.0100"),
        "{out}"
    );
    assert!(!out.lines().next().unwrap_or("").contains("stat"), "{out}");
    // Load sign: −200 N meets k_z− = 40 N/µm: −5 µm, corrected by +5 µm.
    // Given on the command line in the tool frame (tool along +Z).
    let out = compensate(&m, &p, &["--force", "constant:0,0,-200@tool"]);
    assert_abs_diff_eq!(word(&out, 2, 'Z'), 0.005, epsilon = POS_TOL_MM);
    // Feed frame: tangential 200 N along the travel (+X): +10 µm in X.
    // The rapid ended unloaded at X0; under the load the start gives way by
    // the same 10 µm, so the block first takes up X0 − 0.010, then cuts.
    let out = compensate(&m, &p, &["--force", "constant:200,0,0@feed"]);
    assert!(out.lines().nth(1).unwrap_or("").contains("takeup"), "{out}");
    assert_abs_diff_eq!(word(&out, 2, 'X'), -0.010, epsilon = POS_TOL_MM);
    assert_abs_diff_eq!(end_word(&out, 2, 'X'), 10.0 - 0.010, epsilon = POS_TOL_MM);
    // `--force none` switches the machine file's force off.
    let out = compensate(&m, &p, &["--force", "none"]);
    assert!(!out.contains("stat"), "{out}");
}

#[test]
fn milling_forces_from_the_directive_deflect_the_tool() {
    let dir = tempfile::tempdir().expect("tempdir");
    let m = write(
        dir.path(),
        "m.yaml",
        &format!(
            "{AXES}{STIFF_20}process_force:\n  model: milling\n  kt_n_per_mm2: 2000\n  kr_n_per_mm2: 800\n  tool_diameter_mm: 10\n  flutes: 2\n  axial_depth_mm: 1\n  radial_width_mm: 1\n"
        ),
    );
    let p = write(
        dir.path(),
        "p.nc",
        "G0 X0 Y0 Z0\nS1000 M3\n(POSTPROC MILLING DEPTH=2 WIDTH=10)\nG1 X10 F400\n",
    );
    // Slot (width = diameter), a = 2 mm, N = 2, c = F/(S·N) = 400/2000 =
    // 0.2 mm. Mean forces on the tool (feed frame, no edge coefficients):
    //   tangential Fx = −N a c Kr/4 = −2·2·0.2·800/4 = −160 N
    //   normal     Fy =  N a c Kt/4 =  2·2·0.2·2000/4 = 400 N
    // Travel +X with the tool along +Z: feed x = +X, normal y = z × x = +Y.
    // Deflection (−160/20, 400/20) µm = (−8, +20) µm → corrections (+8, −20).
    let out = compensate(&m, &p, &[]);
    assert_abs_diff_eq!(end_word(&out, 4, 'X'), 10.008, epsilon = POS_TOL_MM);
    assert_abs_diff_eq!(end_word(&out, 4, 'Y'), -0.020, epsilon = POS_TOL_MM);
    // Without the directive the command line sets the engagement.
    let p2 = write(dir.path(), "p2.nc", "G0 X0 Y0 Z0\nS1000 M3\nG1 X10 F400\n");
    let out = compensate(&m, &p2, &["--milling-depth", "2", "--milling-width", "10"]);
    assert_abs_diff_eq!(end_word(&out, 3, 'Y'), -0.020, epsilon = POS_TOL_MM);
    // Spindle stopped (no M3): no cutting force.
    let p3 = write(dir.path(), "p3.nc", "G0 X0 Y0 Z0\nS1000\nG1 X10 F400\n");
    let out = compensate(&m, &p3, &[]);
    assert!(!out.contains("stat"), "{out}");
}

#[test]
fn the_grammar_directive_example_runs_and_bad_directives_are_located() {
    let dir = tempfile::tempdir().expect("tempdir");
    let m = write(dir.path(), "m.yaml", AXES);
    // The example of grammar/gcode.md.
    let p = write(
        dir.path(),
        "p.nc",
        "G0 X0 Y0 Z0\n(POSTPROC MILLING DEPTH=2 WIDTH=4)\nS8000 M3\nG1 X50 F1200\n",
    );
    postproc()
        .args(["check"])
        .arg(&p)
        .arg("-m")
        .arg(&m)
        .assert()
        .success();
    let bad = write(
        dir.path(),
        "bad.nc",
        "G0 X0 Y0 Z0\nG1 X1 F100 (POSTPROC MILLING DEPTH=2 SPEED=4)\n",
    );
    let out = postproc()
        .args(["check"])
        .arg(&bad)
        .arg("-m")
        .arg(&m)
        .output()
        .expect("run");
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("bad.nc:2:38: unknown key `SPEED`"), "{err}");
    let bad = write(dir.path(), "bad2.nc", "(POSTPROC MILLING DEPTH=-2)\n");
    let out = postproc()
        .args(["check"])
        .arg(&bad)
        .arg("-m")
        .arg(&m)
        .output()
        .expect("run");
    assert_eq!(out.status.code(), Some(2));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("bad2.nc:1:19: `DEPTH=-2`"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn drilling_thrust_in_a_canned_cycle() {
    let dir = tempfile::tempdir().expect("tempdir");
    let m = write(
        dir.path(),
        "m.yaml",
        &format!(
            "{AXES}{STIFF_20}process_force:\n  model: drilling\n  thrust_coefficient_n_per_mm2: 1500\n  drill_diameter_mm: 8\n"
        ),
    );
    let p = write(
        dir.path(),
        "p.nc",
        "G0 X0 Y0 Z10\nS1000 M3\nG81 X5 Y5 Z-10 R2 F200\nG80\n",
    );
    // f_rev = 200/1000 = 0.2 mm; thrust 1500 · 8/2 · 0.2 = 1200 N on the
    // drill along +Z; k_z+ = 20 N/µm → +60 µm; the hole bottom moves down
    // by 60 µm.
    let (h, rows) = report(&m, &p, &[]);
    let hole = rows.iter().find(|r| r[1] == "cycle").expect("cycle row");
    assert_abs_diff_eq!(col(&h, hole, "static_mm"), 0.060, epsilon = REPORT_TOL_MM);
    let out = compensate(&m, &p, &[]);
    assert_abs_diff_eq!(word(&out, 3, 'Z'), -10.060, epsilon = POS_TOL_MM);
}

#[test]
fn force_table_by_line_and_located_csv_errors() {
    let dir = tempfile::tempdir().expect("tempdir");
    let m = write(dir.path(), "m.yaml", &format!("{AXES}{STIFF_20}"));
    let p = write(dir.path(), "p.nc", "G0 X0 Y0 Z0\nG1 X10 F100\nG1 X20\n");
    let t = write(dir.path(), "f.csv", "line,fx_n,fy_n,fz_n\n3,100,0,0\n");
    // Line 3 only: 100 N along +X at 20 N/µm = +5 µm, corrected by −5 µm.
    let out = compensate(&m, &p, &["--force-table", t.to_str().unwrap_or("")]);
    assert!(!out.lines().nth(1).unwrap_or("").contains("stat"), "{out}");
    assert_abs_diff_eq!(end_word(&out, 3, 'X'), 20.0 - 0.005, epsilon = POS_TOL_MM);
    let bad = write(dir.path(), "bad.csv", "line,fx_n,fy_n,fz_n\n3,100,zero,0\n");
    let out = postproc()
        .arg("report")
        .arg(&p)
        .arg("-m")
        .arg(&m)
        .arg("--force-table")
        .arg(&bad)
        .output()
        .expect("run");
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("bad.csv:2:7: fy_n: `zero`"), "{err}");
}

fn thermal_machine(dir: &Path) -> PathBuf {
    write(
        dir,
        "t.yaml",
        &format!(
            "{AXES}thermal:\n  spindle: {{ idle_w_per_rpm: 1.0, growth_um_per_kw: 10.0, time_constant_min: 1.0 }}\n"
        ),
    )
}

#[test]
fn constant_spindle_power_for_one_time_constant_gives_63_percent_of_the_steady_growth() {
    let dir = tempfile::tempdir().expect("tempdir");
    let m = thermal_machine(dir.path());
    // The spindle starts with the cut: 1 W/rpm · 1000 rpm = 1 kW, steady
    // growth 10 µm/kW · 1 kW = 10 µm. The feed move lasts 60 mm / 60 mm/min
    // = 1 min = τ, so at its end the growth is 10 (1 − e⁻¹) = 6.3212 µm; the
    // spindle grows towards the table (tip down), the program moves up.
    let p = write(dir.path(), "p.nc", "G0 X0 Y0 Z0\nG1 X60 F60 S1000 M3\n");
    let out = compensate(&m, &p, &[]);
    let growth_mm = 0.010 * (1.0 - (-1.0f64).exp());
    assert_abs_diff_eq!(word(&out, 2, 'Z'), growth_mm, epsilon = POS_TOL_MM);
    // Warm start: 1 min of warm-up at the program's mean power. The rapid
    // from the home position (Z 500 → 0 at 60000 mm/min) takes 0.5 s with
    // the spindle off, so P_mean = 1000 · 60/60.5 W and
    //   g0 = 10 · (60/60.5) · (1 − e⁻¹)          (after the warm-up)
    //   g1 = g0 · e^(−0.5/60)                      (end of the rapid)
    //   g2 = 10 + (g1 − 10) · e⁻¹                  (end of the cut)
    let out = compensate(&m, &p, &["--thermal-start", "1"]);
    let g0 = 10.0 * (60.0 / 60.5) * (1.0 - (-1.0f64).exp());
    let g1 = g0 * (-0.5f64 / 60.0).exp();
    let g2 = 10.0 + (g1 - 10.0) * (-1.0f64).exp();
    assert_abs_diff_eq!(word(&out, 1, 'Z'), g1 * 1e-3, epsilon = POS_TOL_MM);
    assert_abs_diff_eq!(word(&out, 2, 'Z'), g2 * 1e-3, epsilon = POS_TOL_MM);
    // Steady start: g0 = 10 · 60/60.5.
    let out = compensate(&m, &p, &["--thermal-start", "steady"]);
    let g1 = 10.0 * (60.0 / 60.5) * (-0.5f64 / 60.0).exp();
    assert_abs_diff_eq!(word(&out, 1, 'Z'), g1 * 1e-3, epsilon = POS_TOL_MM);
    // A dwell heats too: G4 P60000 = 60 s at 1 kW after the cut.
    let p = write(
        dir.path(),
        "dwell.nc",
        "G0 X0 Y0 Z0\nS1000 M3\nG4 P60000\nG1 X1 F6000\n",
    );
    // The cut lasts 1 mm / 6000 mm/min = 0.01 s: g = 10 (1 − e^(−60.01/60)).
    let out = compensate(&m, &p, &[]);
    assert_abs_diff_eq!(
        word(&out, 4, 'Z'),
        0.010 * (1.0 - (-60.01f64 / 60.0).exp()),
        epsilon = POS_TOL_MM
    );
}

#[test]
fn tooth_passing_at_the_natural_frequency_warns_with_a_suggested_speed() {
    let dir = tempfile::tempdir().expect("tempdir");
    let m = write(
        dir.path(),
        "m.yaml",
        &format!(
            "{AXES}process_force:\n  model: milling\n  kt_n_per_mm2: 2000\n  kr_n_per_mm2: 800\n  tool_diameter_mm: 10\n  flutes: 2\n  axial_depth_mm: 2\n  radial_width_mm: 5\nmodal:\n  x: {{ natural_frequency_hz: 60, damping_ratio: 0.05, stiffness_n_per_um: 20 }}\n"
        ),
    );
    // 1800 rpm × 2 flutes / 60 = 60 Hz = the X natural frequency. Suggested:
    // 0.7 · 60 Hz · 60 / 2 = 1260 rpm (1.3 → 2340 rpm is as far from 1800
    // rpm; the slower one is proposed). Both cutting moves resonate: one
    // warning, at the first (line 3), with the larger vibration.
    let p = write(
        dir.path(),
        "p.nc",
        "G0 X0 Y0 Z0\nS1800 M3\nG1 X60 F360\nG1 X0\n",
    );
    let out = postproc()
        .arg("compensate")
        .arg(&p)
        .arg("-m")
        .arg(&m)
        .args(["-o", "-"])
        .output()
        .expect("run");
    assert!(out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("p.nc:3: tooth-passing frequency 60.00 Hz (1800 rpm x 2 teeth / 60)"),
        "{err}"
    );
    assert!(
        err.contains("at 1260 rpm the tooth passing (42.00 Hz) is clear of every mode"),
        "{err}"
    );
    assert_eq!(
        err.matches("tooth-passing").count(),
        1,
        "once per speed: {err}"
    );
    // The vibration is reported, not compensated: the program is unchanged
    // apart from the annotation.
    let text = text_without_header(&String::from_utf8_lossy(&out.stdout));
    assert!(
        text.lines()
            .nth(2)
            .unwrap_or("")
            .starts_with("G1 X60 F360 (dev 0.0000 mm vib "),
        "{text}"
    );
    // 3000 rpm → 100 Hz, far from 60 Hz: no warning.
    let p = write(dir.path(), "q.nc", "G0 X0 Y0 Z0\nS3000 M3\nG1 X60 F600\n");
    let out = postproc()
        .arg("report")
        .arg(&p)
        .arg("-m")
        .arg(&m)
        .output()
        .expect("run");
    assert!(!String::from_utf8_lossy(&out.stderr).contains("tooth-passing"));
}

/// A machine with every effect: a geometric error, stiffness, a thermal
/// spindle and X mode, and a constant-then-milling force.
fn full_machine(dir: &Path) -> PathBuf {
    let text = "kind: machine_tool
name: all effects
units_default: mm
axes:
  - name: X
    type: linear
    side: workpiece
    travel_mm: [-500, 500]
    rapid_mm_per_min: 60000
    component_errors:
      EXX_um: { positions_mm: [-500, 500], forward: [-5, 5] }
  - { name: Y, type: linear, side: workpiece, travel_mm: [-500, 500], rapid_mm_per_min: 60000 }
  - { name: Z, type: linear, side: tool, travel_mm: [-500, 500], rapid_mm_per_min: 60000 }
process_force:
  model: milling
  kt_n_per_mm2: 2000
  kr_n_per_mm2: 800
  tool_diameter_mm: 10
  flutes: 2
  axial_depth_mm: 2
  radial_width_mm: 10
stiffness:
  k_n_per_um: { x_pos: 20, x_neg: 20, y_pos: 20, y_neg: 20, z_pos: 20, z_neg: 20 }
thermal:
  spindle: { idle_w_per_rpm: 1.0, growth_um_per_kw: 10.0, time_constant_min: 1.0 }
modal:
  x: { natural_frequency_hz: 60, damping_ratio: 0.05, stiffness_n_per_um: 20 }
";
    write(dir, "all.yaml", text)
}

#[test]
fn toggling_an_effect_removes_exactly_its_share_and_gains_scale_it() {
    let dir = tempfile::tempdir().expect("tempdir");
    let m = full_machine(dir.path());
    let p = write(
        dir.path(),
        "p.nc",
        "G0 X0 Y0 Z0\nS1000 M3\nG1 X100 F400\nG1 Y50\n",
    );
    let parts = ["geometric_mm", "static_mm", "thermal_mm", "dynamic_mm"];
    let (h, all) = report(&m, &p, &[]);
    let feed_rows: Vec<&Vec<String>> = all.iter().filter(|r| r[1] == "feed").collect();
    assert_eq!(feed_rows.len(), 2);
    for r in &feed_rows {
        for part in parts {
            assert!(col(&h, r, part) > 1e-4, "{part} is active: {r:?}");
        }
    }
    for (i, off) in ["geometric", "static", "thermal", "dynamic"]
        .iter()
        .enumerate()
    {
        let on: Vec<&str> = ["geometric", "static", "thermal", "dynamic"]
            .into_iter()
            .filter(|e| e != off)
            .collect();
        let (h2, rows) = report(&m, &p, &["--effects", &on.join(",")]);
        for (a, b) in all.iter().zip(&rows) {
            for (j, part) in parts.iter().enumerate() {
                let want = if i == j { 0.0 } else { col(&h, a, part) };
                assert_abs_diff_eq!(col(&h2, b, part), want, epsilon = REPORT_TOL_MM);
            }
            // The total loses exactly the switched-off vector (dynamic is
            // not part of the total): check dz, where geometric (EXX) adds
            // nothing, static and thermal add.
            if *off == "thermal" {
                // Thermal acts along −Z only here: dz drops by its size.
                assert_abs_diff_eq!(
                    col(&h2, b, "dz_mm"),
                    col(&h, a, "dz_mm") + col(&h, a, "thermal_mm"),
                    epsilon = 2.0 * REPORT_TOL_MM
                );
            }
            if *off == "dynamic" {
                assert_abs_diff_eq!(
                    col(&h2, b, "dev_mm"),
                    col(&h, a, "dev_mm"),
                    epsilon = REPORT_TOL_MM
                );
            }
        }
        // Gains scale the part linearly.
        let (h3, rows) = report(&m, &p, &["--gain", &format!("{off}=0.5")]);
        for (a, b) in all.iter().zip(&rows) {
            for (j, part) in parts.iter().enumerate() {
                let want = col(&h, a, part) * if i == j { 0.5 } else { 1.0 };
                assert_abs_diff_eq!(col(&h3, b, part), want, epsilon = REPORT_TOL_MM);
            }
        }
    }
}

#[test]
fn bundled_machine_with_every_section_runs_the_sample() {
    let out = postproc()
        .arg("report")
        .arg(repo("samples/effects.nc"))
        .args(["-m", "afm-r1000", "--format", "csv"])
        .output()
        .expect("run");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    let (h, rows) = {
        let mut lines = text.lines().filter(|l| !l.starts_with('#'));
        let h: Vec<String> = lines
            .next()
            .unwrap_or("")
            .split(',')
            .map(String::from)
            .collect();
        let rows: Vec<Vec<String>> = lines
            .map(|l| l.split(',').map(String::from).collect())
            .collect();
        (h, rows)
    };
    // Every effect shows up somewhere in the sample.
    for part in ["geometric_mm", "static_mm", "thermal_mm", "dynamic_mm"] {
        assert!(
            rows.iter().any(|r| col(&h, r, part) > 0.0),
            "{part} never non-zero"
        );
    }
}

#[test]
fn machine_file_sections_are_validated_with_key_paths() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = write(dir.path(), "p.nc", "G0 X0\n");
    for (section, needle) in [
        (
            "process_force:\n  model: milling\n  kt_n_per_mm2: 2000\n",
            "process_force: the `milling` model needs",
        ),
        (
            "process_force:\n  model: constant\n  force_n: [0, 0, 1]\n  flutes: 2\n",
            "process_force.flutes: `flutes` is not used by the `constant` model",
        ),
        (
            "stiffness:\n  k_n_per_um: { x_pos: 0, x_neg: 20, y_pos: 20, y_neg: 20, z_pos: 20, z_neg: 20 }\n",
            "stiffness.k_n_per_um.x_pos",
        ),
        (
            "thermal:\n  spindle:\n    growth_um_per_kw: 10\n    time_constant_min: -1\n",
            "thermal.spindle.time_constant_min",
        ),
        (
            "modal:\n  x:\n    natural_frequency_hz: 60\n    damping_ratio: 2\n    stiffness_n_per_um: 20\n",
            "modal.x.damping_ratio",
        ),
    ] {
        let m = write(dir.path(), "bad.yaml", &format!("{AXES}{section}"));
        let out = postproc()
            .arg("check")
            .arg(&p)
            .arg("-m")
            .arg(&m)
            .output()
            .expect("run");
        assert_eq!(out.status.code(), Some(2), "{section}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains("bad.yaml:") && err.contains(needle), "{err}");
    }
}

#[test]
fn bad_process_flags_are_usage_errors() {
    let dir = tempfile::tempdir().expect("tempdir");
    let m = thermal_machine(dir.path());
    let p = write(dir.path(), "p.nc", "G0 X0 Y0 Z0\n");
    for (args, needle) in [
        (
            vec!["--force", "constant:1,2"],
            "for '--force <SPEC>': `constant:1,2`",
        ),
        (
            vec!["--force", "constant:1,2,3@wrist"],
            "for '--force <SPEC>': `constant:1,2,3@wrist`",
        ),
        (
            vec!["--thermal-start", "warm"],
            "for '--thermal-start <START>': `warm` is not cold, steady",
        ),
        (vec!["--milling-depth=-1"], "--milling-depth -1"),
        (vec!["--gain", "vibration=2"], "unknown effect `vibration`"),
    ] {
        let out = postproc()
            .arg("report")
            .arg(&p)
            .arg("-m")
            .arg(&m)
            .args(&args)
            .output()
            .expect("run");
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(needle), "{args:?}: {err}");
    }
    // A warm start reads the program twice: not from standard input.
    let out = postproc()
        .args(["report", "-", "-m"])
        .arg(&m)
        .args(["--thermal-start", "steady"])
        .write_stdin("G0 X0 Y0 Z0\n")
        .output()
        .expect("run");
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("not standard input"));
}

#[test]
fn feed_drive_heat_scales_the_axis_and_the_stiffness_map_is_position_dependent() {
    let dir = tempfile::tempdir().expect("tempdir");
    let m = write(
        dir.path(),
        "m.yaml",
        &format!(
            "{AXES}thermal:\n  axes:\n    X: {{ scale_ppm_per_kw: 1000, time_constant_min: 1, friction_n: 1000 }}\n"
        ),
    );
    let p = write(dir.path(), "p.nc", "G0 X0 Y0 Z0\nG1 X100 F6000\n");
    // X drive: 1000 N friction × 0.1 m/s = 100 W during the 1 s feed; the
    // 0.5 s rapid from Z500 does not move X. Mean X power 100 · 1/1.5 W.
    //   steady start y0 = 1000 ppm/kW · 0.0666… kW = 66.67 ppm
    //   after the rapid  y1 = y0 · e^(−0.5/60)
    //   after the feed   y2 = 100 + (y1 − 100) · e^(−1/60)   (steady 100 ppm)
    // The axis reaches c (1 + y2·10⁻⁶), so the command for X100 is
    // 100 / (1 + y2·10⁻⁶).
    let y0 = 1000.0 * (100.0 / 1.5) / 1000.0;
    let y1 = y0 * (-0.5f64 / 60.0).exp();
    let y2 = 100.0 + (y1 - 100.0) * (-1.0f64 / 60.0).exp();
    let out = compensate(&m, &p, &["--thermal-start", "steady"]);
    assert_abs_diff_eq!(
        word(&out, 2, 'X'),
        100.0 / (1.0 + y2 * 1e-6),
        epsilon = POS_TOL_MM
    );

    // Stiffness along X from 10 N/µm at X0 to 30 N/µm at X100 (uniform in
    // Y and Z): at X50, k = 20 N/µm, so 300 N along +X gives 15 µm. The
    // solve evaluates k where the corrected command lies (X49.985, k =
    // 19.997 N/µm): the command is 50 − 300/k(c) µm, solved by
    // c = 50 − 0.3/(10 + 0.2 c), c ≈ 49.984998.
    let m = write(
        dir.path(),
        "k.yaml",
        &format!(
            "{AXES}stiffness:\n  grid_mm: {{ x: [0, 100], y: [0], z: [0] }}\n  k_n_per_um:\n    x_pos: [[[10, 30]]]\n    x_neg: 20\n    y_pos: 20\n    y_neg: 20\n    z_pos: 20\n    z_neg: 20\n"
        ),
    );
    let p = write(dir.path(), "k.nc", "G0 X0 Y0 Z0\nG1 X50 F100\n");
    // The deflection changes along the move (30 µm at X0), so the move is
    // split; its end point is the last line.
    let out = compensate(&m, &p, &["--force", "constant:300,0,0"]);
    let last = out.lines().count();
    assert!(last > 2, "{out}");
    let mut c: f64 = 50.0;
    for _ in 0..50 {
        c = 50.0 - 0.3 / (10.0 + 0.2 * c);
    }
    assert_abs_diff_eq!(word(&out, last, 'X'), c, epsilon = POS_TOL_MM);
    assert_abs_diff_eq!(c, 49.985, epsilon = 1e-5);
}
