//! FANUC TP programs through the binary (`check`, `compensate`, `report`,
//! `batch`) on the bundled M-20iA with the cell's frames in its robot file
//! (`fanuc:`): identity runs give the input back after the header, byte
//! for byte; a compensated run changes only the numbers of the positions
//! it compensates; each written position, put in the world by its user
//! frame and solved in its written CONFIG, is checked by forward
//! kinematics (the nominal model gives the written pose back) and is
//! predicted to land on the programmed pose.

use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use postproc::machine::robot::pose::pose_error;
use postproc::machine::robot::{Model, Robot};
use postproc::machine::{Machine, MachineFile};
use postproc::predict::EffectSet;
use postproc::predict::MoveContext;
use postproc::program::tp::config::Config;
use postproc::program::tp::{Group, Program, parse};

use crate::common::{fenced_blocks, postproc, repo, text, text_without_header};

/// The arm the fixtures are written for.
const ARM: &str = "fanuc-m20ia";

/// The cell's frames: UF 1 (the bin), UF 2 (the weld fixture), UF 3 (the
/// place fixture), UT 1 (a torch), UT 2 (a gripper).
const FRAMES: &str = "
fanuc:
  user_frames:
    1: {x_mm: 700, y_mm: 0, z_mm: -400, w_deg: 0, p_deg: 0, r_deg: 0}
    2: {x_mm: 0, y_mm: 0, z_mm: -300, w_deg: 0, p_deg: 0, r_deg: 0}
    3: {x_mm: 500, y_mm: 600, z_mm: -300, w_deg: 0, p_deg: 0, r_deg: 90}
  tool_frames:
    1: {x_mm: 0, y_mm: 30, z_mm: 350, w_deg: 0, p_deg: 22, r_deg: 0}
    2: {x_mm: 0, y_mm: 0, z_mm: 180, w_deg: 0, p_deg: 0, r_deg: 0}
";

/// Position agreement, mm: positions written with 3 decimals (half a unit
/// per axis, 0.00087 mm in all).
const POS_TOL_MM: f64 = 1e-3;
/// Orientation agreement, rad: angles written with 3 decimals turn the
/// frame by at most 3 × 8.7e-6 rad.
const ROT_TOL_RAD: f64 = 3e-5;

/// The frames of [`FRAMES`], by hand: X, Y, Z, W, P, R as
/// `Trans · Rz(R) · Ry(P) · Rx(W)` (built from axis rotations, not from
/// the code under test).
fn frame(v: [f64; 6]) -> Isometry3<f64> {
    let [x, y, z, w, p, r] = v;
    let rot = UnitQuaternion::from_axis_angle(&nalgebra::Vector3::z_axis(), r.to_radians())
        * UnitQuaternion::from_axis_angle(&nalgebra::Vector3::y_axis(), p.to_radians())
        * UnitQuaternion::from_axis_angle(&nalgebra::Vector3::x_axis(), w.to_radians());
    Isometry3::from_parts(Translation3::new(x, y, z), rot)
}

fn user_frame(n: u32) -> Isometry3<f64> {
    match n {
        1 => frame([700.0, 0.0, -400.0, 0.0, 0.0, 0.0]),
        2 => frame([0.0, 0.0, -300.0, 0.0, 0.0, 0.0]),
        3 => frame([500.0, 600.0, -300.0, 0.0, 0.0, 90.0]),
        _ => panic!("UF {n}"),
    }
}

fn tool_frame(n: u32) -> Isometry3<f64> {
    match n {
        1 => frame([0.0, 30.0, 350.0, 0.0, 22.0, 0.0]),
        2 => frame([0.0, 0.0, 180.0, 0.0, 0.0, 0.0]),
        _ => panic!("UT {n}"),
    }
}

fn arm() -> Robot {
    match MachineFile::bundled(ARM)
        .expect("bundled")
        .load()
        .expect("loads")
    {
        Machine::Robot(r) => r,
        Machine::Tool(_) => panic!("{ARM} is a robot"),
    }
}

/// A scratch folder with the fixtures `names` and `cell.yaml`: the bundled
/// arm with `frames` appended.
fn scratch(names: &[&str], frames: &str) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().expect("tempdir");
    for n in names {
        std::fs::copy(repo(&format!("tests/tp/{n}")), dir.path().join(n)).expect("copy");
    }
    let cell = text(&format!("machines/{ARM}.yaml")) + frames;
    std::fs::write(dir.path().join("cell.yaml"), cell).expect("write");
    let p = dir.path().to_path_buf();
    (dir, p)
}

fn read(p: &Path) -> String {
    std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// Runs `postproc args…` in `dir`: exit code, stdout, stderr.
fn run(dir: &Path, args: &[&str]) -> (i32, String, String) {
    let out = postproc()
        .current_dir(dir)
        .args(args)
        .output()
        .expect("runs");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// `s` with every number (its sign included) and the blanks before it
/// replaced by `#`: what a compensation may not change.
fn skeleton(s: &str) -> String {
    let mut out = String::new();
    let chars: Vec<char> = s.chars().collect();
    let mut i = 0;
    while i < chars.len() {
        let c = chars[i];
        let starts =
            c.is_ascii_digit() || (c == '-' && chars.get(i + 1).is_some_and(char::is_ascii_digit));
        if starts {
            while out.ends_with(' ') {
                out.pop();
            }
            out.push('#');
            i += 1;
            while i < chars.len() && (chars[i].is_ascii_digit() || chars[i] == '.') {
                i += 1;
            }
        } else {
            out.push(c);
            i += 1;
        }
    }
    out
}

/// The bytes of `s` from `/MN` to `/POS`.
fn mn(s: &str) -> &str {
    let a = s.find("/MN").expect("/MN");
    let b = s.find("/POS").expect("/POS");
    &s[a..b]
}

fn gp1(p: &Program, index: u32) -> &Group {
    &p.position(index).expect("position").groups[0]
}

fn pose_of(g: &Group) -> Isometry3<f64> {
    let v = |k: &str| g.value(k).expect(k).value;
    frame([v("X"), v("Y"), v("Z"), v("W"), v("P"), v("R")])
}

/// The joint solutions of `pose` (world) on `r` within its limits, turns
/// of joints 1, 4 and 6 included.
fn solutions(r: &Robot, pose: &Isometry3<f64>) -> Vec<[f64; 6]> {
    let tau = std::f64::consts::TAU;
    let mut out = Vec::new();
    for q in r.ik_all(pose).expect("reachable").into_iter().flatten() {
        for k in 0..27 {
            let mut c = q;
            c[0] += tau * f64::from(k % 3 - 1);
            c[3] += tau * f64::from((k / 3) % 3 - 1);
            c[5] += tau * f64::from(k / 9 - 1);
            if r.check_limits(&c).is_ok() {
                out.push(c);
            }
        }
    }
    out
}

/// Checks the written position `index` against the programmed one: in
/// the world by its user frame, with its tool, solved in its written
/// CONFIG; the nominal forward kinematics gives the written pose back and
/// the prediction lands on the programmed pose.
fn lands(input: &Program, output: &Program, index: u32) {
    let (gi, go) = (gp1(input, index), gp1(output, index));
    let uf = user_frame(go.uf.as_ref().expect("UF").value as u32);
    let r = arm().with_tool(tool_frame(go.ut.as_ref().expect("UT").value as u32), None);
    let (p_in, p_out) = (uf * pose_of(gi), uf * pose_of(go));
    assert_ne!(
        pose_of(gi),
        pose_of(go),
        "P[{index}] is compensated (moved)"
    );
    let config = Config::parse(&go.config.as_ref().expect("CONFIG").0).expect("reads");
    let q = *solutions(&r, &p_out)
        .iter()
        .find(|q| config.matches(&r, q))
        .unwrap_or_else(|| panic!("P[{index}]: a solution in CONFIG {config}"));
    let (fp, fr) = pose_error(&r.tcp_pose(Model::Nominal, &q), &p_out);
    assert!(
        fp.norm() <= POS_TOL_MM && fr.norm() <= ROT_TOL_RAD,
        "P[{index}] FK"
    );
    let (dp, dr) = pose_error(
        &r.predict(&MoveContext::default(), &q, EffectSet::ALL),
        &p_in,
    );
    assert!(dp.norm() <= POS_TOL_MM, "P[{index}]: {dp}");
    assert!(dr.norm() <= ROT_TOL_RAD, "P[{index}]: {dr}");
}

#[test]
fn identity_runs_give_the_program_back_after_the_header() {
    let (_d, dir) = scratch(&["pick_place.ls", "weld_seam.ls"], FRAMES);
    for stem in ["pick_place", "weld_seam"] {
        let args = [
            "compensate",
            &format!("{stem}.ls"),
            "--machine",
            "cell.yaml",
            "--effects",
            "none",
            "--annotate",
            "none",
        ];
        let (code, _, err) = run(&dir, &args);
        assert_eq!(code, 0, "{stem}: {err}");
        let out = read(&dir.join(format!("{stem}.comp.ls")));
        // The header follows the `/PROG` line.
        let second = out.lines().nth(1).unwrap_or("");
        assert!(out.starts_with("/PROG"), "{stem}");
        assert!(second.starts_with("  ! postproc "), "{stem}: {second}");
        assert_eq!(
            text_without_header(&out),
            read(&dir.join(format!("{stem}.ls")))
        );
    }
}

#[test]
fn pick_and_place_compensates_every_position_known_offline() {
    let (_d, dir) = scratch(&["pick_place.ls"], FRAMES);
    let (code, _, err) = run(
        &dir,
        &["compensate", "pick_place.ls", "--machine", "cell.yaml"],
    );
    assert_eq!(code, 0, "{err}");
    // L P[2] and J P[2] are one position; J P[1] twice a joint target; PR[5]
    // and the Offset move are left as written.
    assert!(err.contains("4 moves compensated"), "{err}");
    assert!(err.contains("4 left as written"), "{err}");
    let src_in = read(&dir.join("pick_place.ls"));
    let src_out = text_without_header(&read(&dir.join("pick_place.comp.ls")));
    assert_eq!(skeleton(&src_out), skeleton(&src_in));
    assert_eq!(mn(&src_out), mn(&src_in));
    let (pin, pout) = (
        parse(&src_in, "in").expect("parses"),
        parse(&src_out, "out").expect("parses"),
    );
    for index in [2, 3, 4] {
        lands(&pin, &pout, index);
    }
    // P[1] (joints) and P[5] (Offset,PR[7]) as written.
    for index in [1, 5] {
        let span = pin.position(index).expect("P").span.clone();
        let out_span = pout.position(index).expect("P").span.clone();
        assert_eq!(src_in[span], src_out[out_span], "P[{index}]");
    }
}

#[test]
fn the_weld_path_compensates_its_circles_via_and_end_points() {
    let (_d, dir) = scratch(&["weld_seam.ls"], FRAMES);
    let (code, _, err) = run(
        &dir,
        &["compensate", "weld_seam.ls", "--machine", "cell.yaml"],
    );
    assert_eq!(code, 0, "{err}");
    let src_in = read(&dir.join("weld_seam.ls"));
    let src_out = text_without_header(&read(&dir.join("weld_seam.comp.ls")));
    assert_eq!(skeleton(&src_out), skeleton(&src_in));
    assert_eq!(mn(&src_out), mn(&src_in));
    let (pin, pout) = (
        parse(&src_in, "in").expect("parses"),
        parse(&src_out, "out").expect("parses"),
    );
    for index in 1..=12 {
        lands(&pin, &pout, index);
    }
}

#[test]
fn a_frame_the_robot_file_does_not_give_is_named() {
    let without_uf3 = FRAMES.replace(
        "    3: {x_mm: 500, y_mm: 600, z_mm: -300, w_deg: 0, p_deg: 0, r_deg: 90}\n",
        "",
    );
    let (_d, dir) = scratch(&["pick_place.ls"], &without_uf3);
    let (code, out, err) = run(&dir, &["check", "pick_place.ls", "--machine", "cell.yaml"]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(
        out.trim(),
        "pick_place.ls: FANUC TP program PICK_PLACE, 8 motions (3 targets, 2 joint targets, 3 left as written)"
    );
    let (code, _, err) = run(
        &dir,
        &[
            "check",
            "pick_place.ls",
            "--machine",
            "cell.yaml",
            "--strict",
        ],
    );
    assert_eq!(code, 2, "{err}");
    let (code, _, err) = run(
        &dir,
        &["compensate", "pick_place.ls", "--machine", "cell.yaml"],
    );
    assert_eq!(code, 0, "{err}");
    assert!(
        err.contains(
            "user frame UF 3 is in the controller: give it in the robot file (fanuc: user_frames)"
        ),
        "{err}"
    );
    assert!(err.contains("PR[5] is a position register"), "{err}");
    assert!(
        err.contains("`OFFSET` displaces the position at run time"),
        "{err}"
    );
    let src_in = read(&dir.join("pick_place.ls"));
    let src_out = text_without_header(&read(&dir.join("pick_place.comp.ls")));
    let (pin, pout) = (
        parse(&src_in, "in").expect("parses"),
        parse(&src_out, "out").expect("parses"),
    );
    let p4 = |p: &Program, s: &str| s[p.position(4).expect("P[4]").span.clone()].to_string();
    assert_eq!(p4(&pin, &src_in), p4(&pout, &src_out));
    lands(&pin, &pout, 3);
}

#[test]
fn frames_in_the_robot_file_are_strict() {
    for (frames, want) in [
        (
            "\nfanuc:\n  user_frames:\n    0: {x_mm: 0, y_mm: 0, z_mm: 0, w_deg: 0, p_deg: 0, r_deg: 0}\n",
            "fanuc.user_frames.0: frame numbers go from 1 to 61",
        ),
        (
            "\nfanuc:\n  tool_frames:\n    1: {x_mm: 0, y_mm: 0, z_mm: 0, w_deg: 0, p_deg: 0}\n",
            "r_deg",
        ),
        (
            "\nfanuc:\n  tool_frames:\n    1: {x: 0, y_mm: 0, z_mm: 0, w_deg: 0, p_deg: 0, r_deg: 0}\n",
            "unknown field `x`",
        ),
    ] {
        let (_d, dir) = scratch(&["pick_place.ls"], frames);
        let (code, _, err) = run(&dir, &["check", "pick_place.ls", "--machine", "cell.yaml"]);
        assert_eq!(code, 2, "{err}");
        assert!(err.contains("cell.yaml:"), "{err}");
        assert!(err.contains(want), "{want}: {err}");
    }
}

#[test]
fn report_and_batch_read_tp_programs() {
    let (_d, dir) = scratch(&["pick_place.ls", "weld_seam.ls"], FRAMES);
    let (code, out, err) = run(
        &dir,
        &[
            "report",
            "weld_seam.ls",
            "--machine",
            "cell.yaml",
            "--format",
            "csv",
        ],
    );
    assert_eq!(code, 0, "{err}");
    // A row per motion (nine, all Cartesian) after the header line.
    assert!(
        out.lines().filter(|l| !l.starts_with('#')).count() >= 10,
        "{out}"
    );
    std::fs::create_dir(dir.join("cell")).expect("mkdir");
    for n in ["pick_place.ls", "weld_seam.ls"] {
        std::fs::copy(dir.join(n), dir.join("cell").join(n)).expect("copy");
    }
    let (code, _, err) = run(
        &dir,
        &[
            "batch",
            "cell",
            "--machine",
            "cell.yaml",
            "--out-dir",
            "out",
        ],
    );
    assert_eq!(code, 0, "{err}");
    for n in ["pick_place", "weld_seam"] {
        let written = read(&dir.join("out").join(format!("{n}.ls")));
        assert_eq!(
            skeleton(&text_without_header(&written)),
            skeleton(&read(&dir.join(format!("{n}.ls"))))
        );
    }
}

#[test]
fn the_grammar_example_of_moves_left_as_written_names_each_reason() {
    let md = text("grammar/tp.md");
    let example = fenced_blocks(&md, "ls")
        .into_iter()
        .find(|b| b.starts_with("/PROG  LEFT"))
        .expect("the LEFT example");
    let (_d, dir) = scratch(&[], FRAMES);
    std::fs::write(dir.join("left.ls"), &example).expect("write");
    let (code, out, err) = run(&dir, &["check", "left.ls", "--machine", "cell.yaml"]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(
        out.trim(),
        "left.ls: FANUC TP program LEFT, 4 motions (1 targets, 0 joint targets, 3 left as written)"
    );
    let (code, _, err) = run(&dir, &["compensate", "left.ls", "--machine", "cell.yaml"]);
    assert_eq!(code, 0, "{err}");
    for reason in [
        "UFRAME[2] is set at line 4 at run time",
        "`TOOL_OFFSET` displaces the position at run time",
        "P[9] is not in /POS",
    ] {
        assert!(err.contains(reason), "{reason}: {err}");
    }
    let written = text_without_header(&read(&dir.join("left.comp.ls")));
    let (pin, pout) = (
        parse(&example, "in").expect("parses"),
        parse(&written, "out").expect("parses"),
    );
    lands(&pin, &pout, 1);
    let p2 = |p: &Program, s: &str| s[p.position(2).expect("P[2]").span.clone()].to_string();
    assert_eq!(p2(&pin, &example), p2(&pout, &written));
}
