//! Integration tests: robot process forces from the machine-independent
//! models of `src/process` (milling, table, feed-frame constant) through the
//! real binary, with hand-derived goldens.

use std::f64::consts::FRAC_PI_2;
use std::path::Path;

use approx::assert_abs_diff_eq;
use nalgebra::{Isometry3, Vector3};
use postproc::machine::robot::process::travel_direction;
use postproc::machine::robot::{ForceModel, IkSelect, Model, Robot};
use postproc::process::CutSettings;
use postproc::process::MillingCache;
use postproc::program::rapid::directives::Directives;

use crate::common::{postproc, repo, write};

/// Force tolerance, N: closed-form expressions, rounding only.
const FORCE_TOL_N: f64 = 1e-9;
/// Deflection tolerance, mm. The hand value is first order (J Kθ⁻¹ Jᵀ W);
/// the prediction uses FK(q + Δq). The largest joint deflection is
/// Δq4 ≈ 8.8e-4 rad on a 247.5 mm lever: second-order term
/// ≈ 247.5·(8.8e-4)²/2 ≈ 1e-4 mm. The CSV report writes 4 decimals
/// (±5e-5 mm). So 3e-4 mm.
const DEFLECTION_TOL_MM: f64 = 3e-4;
/// Geometry of the hand-derived pose (FK exact to rounding), mm.
const GEOM_TOL_MM: f64 = 1e-9;

/// The slot of `tests/effects.rs` (Kt 2000, Kr 800 N/mm², D 10 mm, 2
/// flutes, slot width 10 mm) at axial depth 0.2 mm and 6000 rpm on the
/// IRB 1600 (its drilling force replaced).
const MILLING: &str = "process_force:
  model: milling
  kt_n_per_mm2: 2000
  kr_n_per_mm2: 800
  tool_diameter_mm: 10
  flutes: 2
  axial_depth_mm: 0.2
  radial_width_mm: 10
  spindle_rpm: 6000
";

/// The IRB 1600 file with `block` instead of its `process_force:` section.
fn irb1600_with(block: &str) -> String {
    let text = std::fs::read_to_string(repo("machines/abb-irb1600.yaml")).expect("machine file");
    let start = text.find("process_force:\n").expect("process_force");
    let end = start + text[start..].find("\n#").expect("comment after") + 1;
    format!("{}{block}{}", &text[..start], &text[end..])
}

/// The spindle tool of the programs: TCP 182.5 mm along flange z, no load.
fn spindle() -> Isometry3<f64> {
    Isometry3::translation(0.0, 0.0, 182.5)
}

/// A robtarget literal for `pose` (world = wobj0) with the confdata of the
/// joints `q` (input construction, not an expected value).
fn literal(r: &Robot, pose: &Isometry3<f64>, q: &[f64; 6]) -> String {
    let t = pose.translation.vector;
    let o = pose.rotation.quaternion();
    let c = r.confdata(q);
    format!(
        "[[{:.6},{:.6},{:.6}],[{:.9},{:.9},{:.9},{:.9}],[{},{},{},{}],[9E9,9E9,9E9,9E9,9E9,9E9]]",
        t.x, t.y, t.z, o.w, o.i, o.j, o.k, c.cf1, c.cf4, c.cf6, c.cfx
    )
}

/// A module with two `MoveL` at `v40` with the spindle tool: from 10 mm
/// behind the simple pose (along −X) to the simple pose
/// q = (0, 0, 0, 0, 90°, 0). `directive` is a line before the moves.
fn slot_program(r: &Robot, directive: &str) -> String {
    let view = r.with_tool(spindle(), None);
    let q1 = [0.0, 0.0, 0.0, 0.0, FRAC_PI_2, 0.0];
    let p1 = view.tcp_pose(Model::Nominal, &q1);
    let p0 = Isometry3::from_parts(
        (p1.translation.vector - Vector3::new(10.0, 0.0, 0.0)).into(),
        p1.rotation,
    );
    let q0 = view
        .ik_nominal(&p0, &IkSelect::Near(q1))
        .expect("reachable");
    format!(
        "MODULE Slot
  PERS tooldata tSpindle := [TRUE,[[0,0,182.5],[1,0,0,0]],[0,[0,0,0],[1,0,0,0],0,0,0]];
  CONST robtarget p0 := {};
  CONST robtarget p1 := {};
  PROC main()
    {directive}
    MoveL p0, v40, fine, tSpindle;
    MoveL p1, v40, fine, tSpindle;
  ENDPROC
ENDMODULE
",
        literal(&view, &p0, &q0),
        literal(&view, &p1, &q1)
    )
}

/// Rows of a RAPID CSV report: (line, dx, dy, dz, process_mm, dynamic_mm).
fn report_rows(machine: &Path, program: &Path, extra: &[&str]) -> Vec<(usize, [f64; 5])> {
    let out = postproc()
        .args(["report", "--format", "csv", "--effects", "process,dynamic"])
        .arg(program)
        .arg("-m")
        .arg(machine)
        .args(extra)
        .output()
        .expect("run");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout).to_string();
    text.lines()
        .skip(1)
        .filter(|l| !l.starts_with('#'))
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            let num = |i: usize| f[i].parse::<f64>().expect("number");
            (
                f[0].parse().expect("line"),
                [num(5), num(6), num(7), num(12), num(13)],
            )
        })
        .collect()
}

#[test]
fn milling_slot_force_and_deflection_are_hand_derived() {
    let r = Robot::from_yaml_str(&irb1600_with(MILLING), "m.yaml").expect("valid");
    // Geometry of the simple pose, by hand: q = (0, 0, 0, 0, 90°, 0); wrist
    // centre (150 + 600, 0, 486.5 + 700) = (750, 0, 1186.5); axis 5 turns
    // the flange (65 mm) and tool (182.5 mm) to point straight down:
    // TCP P = (750, 0, 1186.5 − 247.5) = (750, 0, 939), tool z = −Z.
    let view = r.with_tool(spindle(), None);
    let q1 = [0.0, 0.0, 0.0, 0.0, FRAC_PI_2, 0.0];
    let p1 = view.tcp_pose(Model::Nominal, &q1);
    assert_abs_diff_eq!(
        p1.translation.vector,
        Vector3::new(750.0, 0.0, 939.0),
        epsilon = GEOM_TOL_MM
    );
    assert_abs_diff_eq!(p1.rotation * Vector3::z(), -Vector3::z(), epsilon = 1e-12);

    // Mean force (the numbers of tests/effects.rs at a = 0.2 mm): slot,
    // N = 2, c = v·60/(rpm·N) = 40·60/12000 = 0.2 mm:
    //   tangential −N a c Kr/4 = −2·0.2·0.2·800/4 = −16 N
    //   normal      N a c Kt/4 =  2·0.2·0.2·2000/4 = 40 N
    // Travel +X, tool axis tip→flange = +Z: normal = Z × X = +Y, so
    // F = (−16, 40, 0) N on the tool (world = base frame).
    let pf = r.process_force().copied().expect("milling");
    assert!(matches!(pf.model, ForceModel::Milling(_)));
    let load = pf
        .milling_force(
            &Vector3::x(),
            &-Vector3::z(),
            40.0,
            &CutSettings::default(),
            &mut MillingCache::default(),
        )
        .expect("cuts");
    assert_abs_diff_eq!(
        load.force_n,
        Vector3::new(-16.0, 40.0, 0.0),
        epsilon = FORCE_TOL_N
    );
    // Tooth passing 6000·2/60 = 200 Hz.
    assert_abs_diff_eq!(load.tooth_hz, 200.0, epsilon = FORCE_TOL_N);

    // Deflection Δp = Σ_i (a_i·(r_i × F)) / k_i · (a_i × r_i) (J Kθ⁻¹ Jᵀ W
    // for a pure force), axes at the pose (k in N·mm/rad):
    //  1: z through 0, r = (750, 0, 939): τ = 40·750 = 30000;
    //     a×r = (0, 750, 0) → Δy = 30000·750/2.7099e8 = 0.0830289
    //  2: y through (150, 0, 486.5), r = (600, 0, 452.5): τ = −16·452.5 =
    //     −7240; a×r = (452.5, 0, −600) → (−0.0076181, 0, +0.0101014)
    //  3: y through (150, 0, 1186.5), r = (600, 0, −247.5): τ = 3960;
    //     a×r = (−247.5, 0, −600) → (−0.0069540, 0, −0.0168582)
    //  4: x through (750, 0, 1186.5), r = (0, 0, −247.5): τ = 40·247.5 =
    //     9900; a×r = (0, 247.5, 0) → Δy = 9900·247.5/1.128e7 = 0.2172207
    //  5: y through (750, 0, 1186.5), same r: τ = 3960; a×r = (−247.5, 0, 0)
    //     → Δx = −3960·247.5/9.55e6 = −0.1026283
    //  6: along the tool through P: no moment.
    // Total (−0.1172005, 0.3002496, −0.0067569) mm.
    let expected = Vector3::new(-0.1172005, 0.3002496, -0.0067569);
    let dir = tempfile::tempdir().expect("tempdir");
    let m = write(dir.path(), "m.yaml", &irb1600_with(MILLING));
    let p = write(dir.path(), "slot.mod", &slot_program(&r, ""));
    let rows = report_rows(&m, &p, &[]);
    assert_eq!(rows.len(), 2);
    // The first move has no known start: no force.
    assert_abs_diff_eq!(rows[0].1[3], 0.0, epsilon = DEFLECTION_TOL_MM);
    let d = rows[1].1;
    assert_abs_diff_eq!(
        Vector3::new(d[0], d[1], d[2]),
        expected,
        epsilon = DEFLECTION_TOL_MM
    );

    // The same slot set by the directive over a file depth of 0.2 mm at
    // 12000 rpm: DEPTH=0.4 RPM=12000 halves c (0.1 mm) and doubles a, the
    // same mean force.
    let p2 = write(
        dir.path(),
        "slot2.mod",
        &slot_program(&r, "! POSTPROC MILLING DEPTH=0.4 RPM=12000"),
    );
    let rows2 = report_rows(&m, &p2, &[]);
    assert_abs_diff_eq!(
        Vector3::new(rows2[1].1[0], rows2[1].1[1], rows2[1].1[2]),
        expected,
        epsilon = DEFLECTION_TOL_MM
    );
    // --milling-depth 0.4 doubles a at c = 0.2 mm: twice the force and,
    // to first order, twice the deflection (tolerance doubled).
    let rows3 = report_rows(&m, &p, &["--milling-depth", "0.4"]);
    assert_abs_diff_eq!(
        Vector3::new(rows3[1].1[0], rows3[1].1[1], rows3[1].1[2]),
        expected * 2.0,
        epsilon = 2.0 * DEFLECTION_TOL_MM + 4e-4
    );
}

#[test]
fn a_table_force_acts_only_on_its_line() {
    let r = Robot::from_yaml_str(&irb1600_with(MILLING), "m.yaml").expect("valid");
    let dir = tempfile::tempdir().expect("tempdir");
    let m = write(dir.path(), "m.yaml", &irb1600_with(MILLING));
    let p = write(dir.path(), "slot.mod", &slot_program(&r, ""));
    // The moves are on lines 7 and 8 (line 6 is the empty directive line).
    // A row for line 8 with the milling force of the test above, work
    // object wobj0 = world: the same deflection; line 7 stays unloaded.
    let t = write(
        dir.path(),
        "f.csv",
        "line,fx_n,fy_n,fz_n\n8,-16,40,0\n99,1000,0,0\n",
    );
    let rows = report_rows(&m, &p, &["--force-table", t.to_str().expect("utf8")]);
    assert_eq!(rows[0].0, 7);
    assert_eq!(rows[1].0, 8);
    assert_abs_diff_eq!(rows[0].1[3], 0.0, epsilon = 1e-12);
    assert_abs_diff_eq!(
        Vector3::new(rows[1].1[0], rows[1].1[1], rows[1].1[2]),
        Vector3::new(-0.1172005, 0.3002496, -0.0067569),
        epsilon = DEFLECTION_TOL_MM
    );
    // The row on line 7 only: now the first move is loaded, the second not.
    let t2 = write(dir.path(), "g.csv", "line,fx_n,fy_n,fz_n\n7,0,0,200\n");
    let rows = report_rows(&m, &p, &["--force-table", t2.to_str().expect("utf8")]);
    assert!(rows[0].1[3] > 0.01, "{rows:?}");
    assert_abs_diff_eq!(rows[1].1[3], 0.0, epsilon = 1e-12);
    // Milling flags need a milling model.
    let out = postproc()
        .args(["report", "--force-table"])
        .arg(&t2)
        .args(["--milling-depth", "1"])
        .arg(&p)
        .arg("-m")
        .arg(&m)
        .output()
        .expect("run");
    assert_eq!(out.status.code(), Some(2));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("not `milling`"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn directives_are_parsed_and_bad_ones_located() {
    let src = "MODULE M\n  ! POSTPROC MILLING DEPTH=2 WIDTH=4 RPM=12000\n  TPWrite \"! POSTPROC MILLING X=1\";\n  ! postproc milling width=6 ! trailing\n  ! POSTPROC other text\nENDMODULE\n";
    // The `!` inside the string does not start a comment. In the
    // directive of line 4 the second `!` is a word that is not KEY=VALUE:
    // refused at its column, 2 + `! postproc milling width=6 `.len() + 1 = 30.
    let e = Directives::parse(src, "m.mod").unwrap_err().to_string();
    assert!(e.starts_with("m.mod:4:30: `!`"), "{e}");
    let src = "MODULE M\n  ! POSTPROC MILLING DEPTH=2 WIDTH=4 RPM=12000\n  TPWrite \"! POSTPROC MILLING X=1\";\n  ! postproc milling width=6\n  ! POSTPROC other text\nENDMODULE\n";
    let d = Directives::parse(src, "m.mod").expect("valid");
    assert_eq!(d.at(1), CutSettings::default());
    assert_eq!(
        d.at(3),
        CutSettings {
            depth_mm: Some(2.0),
            width_mm: Some(4.0),
            spindle_rpm: Some(12000.0)
        }
    );
    assert_eq!(d.at(9).width_mm, Some(6.0));
    assert_eq!(d.at(9).depth_mm, Some(2.0));
    for (bad, msg) in [
        (
            "! POSTPROC MILLING DEPTH=2 SPEED=4",
            "m.mod:1:28: unknown key `SPEED`",
        ),
        (
            "! POSTPROC MILLING",
            "m.mod:1:1: POSTPROC MILLING directive without a key",
        ),
        (
            "! POSTPROC MILLING DEPTH=-1",
            "m.mod:1:20: `DEPTH=-1`: must be a length",
        ),
        (
            "! POSTPROC MILLING RPM=0",
            "m.mod:1:20: `RPM=0`: must be a spindle speed",
        ),
        (
            "! POSTPROC MILLING WIDTH=x",
            "m.mod:1:20: `WIDTH=x`: `x` is not a number",
        ),
    ] {
        let e = Directives::parse(bad, "m.mod").unwrap_err().to_string();
        assert!(e.starts_with(msg), "{e}");
    }
}

#[test]
fn arc_end_tangent_is_hand_derived() {
    // Quarter circle about the origin in the XY plane: (1,0) → (0,1) →
    // (−1,0), counter-clockwise; at (−1,0) the travel is −Y.
    let t = travel_direction(
        &Vector3::new(1.0, 0.0, 0.0),
        Some(&Vector3::new(0.0, 1.0, 0.0)),
        &Vector3::new(-1.0, 0.0, 0.0),
    );
    assert_abs_diff_eq!(t.normalize(), -Vector3::y(), epsilon = 1e-12);
    // Straight: the chord.
    let t = travel_direction(&Vector3::zeros(), None, &Vector3::new(0.0, 3.0, 0.0));
    assert_abs_diff_eq!(t, Vector3::new(0.0, 3.0, 0.0), epsilon = 1e-12);
}

#[test]
fn a_feed_frame_constant_force_equals_the_same_milling_force() {
    // Travel +X with the tool pointing down: feed frame x = +X, axial z =
    // +Z (tip → flange), normal y = Z × X = +Y. The constant (−16, 40, 0)
    // in the feed frame is the world force (−16, 40, 0) of the milling test,
    // so the deflection is the same hand-derived vector; in the work-object
    // frame (wobj0 = world) too.
    let r = Robot::from_yaml_str(&irb1600_with(MILLING), "m.yaml").expect("valid");
    let dir = tempfile::tempdir().expect("tempdir");
    let m = write(dir.path(), "m.yaml", &irb1600_with(MILLING));
    let p = write(dir.path(), "slot.mod", &slot_program(&r, ""));
    let expected = Vector3::new(-0.1172005, 0.3002496, -0.0067569);
    for spec in ["constant:-16,40,0@feed", "constant:-16,40,0@workpiece"] {
        let rows = report_rows(&m, &p, &["--force", spec]);
        let d = rows[1].1;
        assert_abs_diff_eq!(
            Vector3::new(d[0], d[1], d[2]),
            expected,
            epsilon = DEFLECTION_TOL_MM
        );
    }
    // `--force none`: no process deviation anywhere.
    let rows = report_rows(&m, &p, &["--force", "none"]);
    assert!(rows.iter().all(|(_, d)| d[3] == 0.0), "{rows:?}");
}

#[test]
fn milling_sample_loads_only_the_side_moves_and_warns_at_a_mode() {
    let sample = repo("samples/milling.mod");
    let machine = repo("samples/irb1600-milling.yaml");
    let rows = report_rows(&machine, &sample, &[]);
    // Side moves (MoveL across the tool axis): lines 45-48 and 52-55.
    // Plunges (44, 51), the retract (56) and the air moves carry no force.
    for (line, d) in &rows {
        let side = (45..=48).contains(line) || (52..=55).contains(line);
        assert_eq!(d[3] > 0.0, side, "line {line}: {d:?}");
    }
    // At 18000 rpm the tooth passes at 600 Hz, far above the modes (7.5-9.5
    // Hz): no warning. At 255 rpm, 255·2/60 = 8.5 Hz = the x mode: the
    // roughing lap (no RPM directive) triggers the warning.
    let run = |m: &Path| {
        postproc()
            .args(["report", "--format", "csv", "--effects", "dynamic"])
            .arg(&sample)
            .arg("-m")
            .arg(m)
            .output()
            .expect("run")
    };
    let out = run(&machine);
    assert!(out.status.success());
    assert!(!String::from_utf8_lossy(&out.stderr).contains("natural frequency"));
    let dir = tempfile::tempdir().expect("tempdir");
    let text = std::fs::read_to_string(&machine).expect("machine");
    assert!(text.contains("spindle_rpm: 18000.0"));
    let slow = write(
        dir.path(),
        "slow.yaml",
        &text.replace("spindle_rpm: 18000.0", "spindle_rpm: 255.0"),
    );
    let out = run(&slow);
    assert!(out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("tooth-passing frequency 8.50 Hz (255 rpm x 2 teeth / 60)")
            && err.contains("X natural frequency 8.50 Hz"),
        "{err}"
    );
    // The finishing lap runs at its directive's 20000 rpm (667 Hz): the
    // largest vibration is on a roughing side move.
    assert!(err.contains("(line 4"), "{err}");
}

#[test]
fn milling_yaml_is_validated_with_key_paths() {
    for (block, msg) in [
        (
            MILLING.replace("  spindle_rpm: 6000\n", ""),
            "model `milling` needs `spindle_rpm`",
        ),
        (
            MILLING.replace("  flutes: 2\n", ""),
            "model `milling` needs `flutes`",
        ),
        (
            MILLING.replace("  kt_n_per_mm2: 2000\n", ""),
            "model `milling` needs `kt_n_per_mm2`",
        ),
        (
            MILLING.replace("radial_width_mm: 10", "radial_width_mm: 11"),
            "process_force.radial_width_mm: `11` is outside 0..10",
        ),
        (
            format!("{MILLING}  drill_diameter_mm: 6\n"),
            "process_force.drill_diameter_mm: `drill_diameter_mm` does not apply to model `milling`",
        ),
        (
            "process_force: { model: drilling, thrust_coefficient_n_per_mm2: 450, drill_diameter_mm: 6.8, spindle_rpm: 3000, kt_n_per_mm2: 1 }\n".to_string(),
            "process_force.kt_n_per_mm2: `kt_n_per_mm2` does not apply to model `drilling`",
        ),
        (
            "process_force: { model: table }\n".to_string(),
            "process_force.model: a force table is given per run with --force-table FILE",
        ),
    ] {
        let e = Robot::from_yaml_str(&irb1600_with(&block), "m.yaml")
            .unwrap_err()
            .to_string();
        assert!(e.contains(msg), "{msg}: {e}");
        assert!(e.starts_with("m.yaml:"), "{e}");
    }
}

#[test]
fn the_grammar_directive_example_runs() {
    let doc = std::fs::read_to_string(repo("grammar/rapid.md")).expect("grammar");
    let start = doc.find("```rapid\nMODULE Wall").expect("example") + "```rapid\n".len();
    let end = start + doc[start..].find("```").expect("closed");
    let example = &doc[start..end];
    // Lines: 5 the directive, 6 `MoveL a`, 7 `MoveL b` with its own
    // directive at the end of the line.
    let d = Directives::parse(example, "wall.mod").expect("valid");
    assert_eq!(
        d.at(6),
        CutSettings {
            depth_mm: Some(5.0),
            width_mm: Some(2.0),
            spindle_rpm: None
        }
    );
    assert_eq!(d.at(7).spindle_rpm, Some(20000.0));
    assert_eq!(d.at(7).depth_mm, Some(5.0));
    // Through the binary: the second move (travel +X, tool down) is cut.
    let dir = tempfile::tempdir().expect("tempdir");
    let p = write(dir.path(), "wall.mod", example);
    let rows = report_rows(&repo("samples/irb1600-milling.yaml"), &p, &[]);
    assert_eq!(rows.len(), 2);
    assert_eq!(rows[0].1[3], 0.0);
    assert!(rows[1].1[3] > 0.01, "{rows:?}");
}
