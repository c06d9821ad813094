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

use crate::common::run_in as run;
use crate::common::{fenced_blocks, repo, text, text_without_header};

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
        &[
            "compensate",
            "pick_place.ls",
            "--machine",
            "cell.yaml",
            "--annotate",
            "none",
        ],
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
        &[
            "compensate",
            "weld_seam.ls",
            "--machine",
            "cell.yaml",
            "--annotate",
            "none",
        ],
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
            "--annotate",
            "none",
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
        "left.ls: FANUC TP program LEFT, 5 motions (1 targets, 0 joint targets, 4 left as written)"
    );
    let (code, _, err) = run(&dir, &["compensate", "left.ls", "--machine", "cell.yaml"]);
    assert_eq!(code, 0, "{err}");
    // Each reason of a motion left as written is named, with the line
    // of the file (`/MN` line n is file line n + 2) that sets or selects
    // the frame.
    for reason in [
        "UFRAME[2] is set by the program at line 3, at run time",
        "`TOOL_OFFSET` displaces the position at run time",
        "P[9] is not in /POS",
        "UFRAME_NUM is set from a register at line 14: the user frame of the motion is known at run time only",
    ] {
        assert!(err.contains(reason), "{reason}: {err}");
    }
    // Line 8 (file line 10) shares P[1] with the compensated line 4.
    assert!(
        err.contains("line 10: the motion is left as written but its position P[1] is compensated for the move at line 6"),
        "{err}"
    );
    let written = text_without_header(&read(&dir.join("left.comp.ls")));
    let (pin, pout) = (
        parse(&example, "in").expect("parses"),
        parse(&written, "out").expect("parses"),
    );
    lands(&pin, &pout, 1);
    for index in [2, 3] {
        let p = |p: &Program, s: &str| s[p.position(index).expect("P").span.clone()].to_string();
        assert_eq!(p(&pin, &example), p(&pout, &written), "P[{index}]");
    }
}

/// A program of `mn` (the `/MN` lines) and the positions of the LEFT
/// example of grammar/tp.md (P[1], P[3] in UF 1, P[2] in UF 2).
fn with_positions(mn: &str) -> String {
    let md = text("grammar/tp.md");
    let left = fenced_blocks(&md, "ls")
        .into_iter()
        .find(|b| b.starts_with("/PROG  LEFT"))
        .expect("the LEFT example");
    let pos = &left[left.find("/POS").expect("/POS")..];
    format!("/PROG  FRAMES\n/MN\n{mn}{pos}")
}

#[test]
fn frames_the_program_sets_or_selects_by_register_leave_their_motions() {
    // (the /MN lines, the motions compensated, the reasons named).
    let cases: [(&str, usize, &[&str]); 5] = [
        // A frame set after the motion: the value outlives the program.
        (
            "   1:  UTOOL_NUM=2 ;\n   2:  UFRAME_NUM=1 ;\n   3:L P[1] 250mm/sec FINE    ;\n   4:  UFRAME[1]=PR[3] ;\n",
            0,
            &["UFRAME[1] is set by the program at line 6, at run time"],
        ),
        // A tool frame set: every motion with UT 2.
        (
            "   1:  UTOOL[2]=PR[1] ;\n   2:  UFRAME_NUM=1 ;\n   3:L P[1] 250mm/sec FINE    ;\n   4:L P[3] 250mm/sec FINE    ;\n",
            0,
            &["UTOOL[2] is set by the program at line 3, at run time"],
        ),
        // A register selection after a motion in a program without
        // labels and with UFRAME_NUM=1 before it: only the motion after.
        (
            "   1:  UTOOL_NUM=2 ;\n   2:  UFRAME_NUM=1 ;\n   3:L P[1] 250mm/sec FINE    ;\n   4:  UFRAME_NUM=R[2] ;\n   5:L P[3] 250mm/sec FINE    ;\n",
            1,
            &["UFRAME_NUM is set from a register at line 6"],
        ),
        // Before the first UFRAME_NUM=n, the register's frame may be in
        // force (the program ran before).
        (
            "   1:  UTOOL_NUM=2 ;\n   2:L P[1] 250mm/sec FINE    ;\n   3:  UFRAME_NUM=R[2] ;\n   4:  UFRAME_NUM=1 ;\n   5:L P[3] 250mm/sec FINE    ;\n",
            1,
            &["UFRAME_NUM is set from a register at line 5"],
        ),
        // A tool number from a register.
        (
            "   1:  UTOOL_NUM=R[7] ;\n   2:  UFRAME_NUM=1 ;\n   3:L P[1] 250mm/sec FINE    ;\n",
            0,
            &[
                "UTOOL_NUM is set from a register at line 3: the tool frame of the motion is known at run time only",
            ],
        ),
    ];
    for (mn, compensated, reasons) in cases {
        let (_d, dir) = scratch(&[], FRAMES);
        std::fs::write(dir.join("f.ls"), with_positions(mn)).expect("write");
        let (code, _, err) = run(&dir, &["compensate", "f.ls", "--machine", "cell.yaml"]);
        assert_eq!(code, 0, "{mn}: {err}");
        let moves = if compensated == 1 { "move" } else { "moves" };
        assert!(
            err.contains(&format!("{compensated} {moves} compensated")),
            "{mn}: {err}"
        );
        for r in reasons {
            assert!(err.contains(r), "{mn}: {r}: {err}");
        }
        let (code, _, err) = run(
            &dir,
            &["check", "f.ls", "--machine", "cell.yaml", "--strict"],
        );
        assert_eq!(code, 2, "{mn}: --strict refuses: {err}");
    }
}

/// The remark lines `! …` of `/MN` that are not in `input`, in order.
fn remarks(mn: &str) -> Vec<(u32, String)> {
    mn.lines()
        .filter_map(|l| {
            let (n, rest) = l.split_once(':')?;
            let r = rest.trim().strip_prefix("! ")?.strip_suffix(" ;")?;
            Some((n.trim().parse().ok()?, r.to_string()))
        })
        .collect()
}

#[test]
fn annotations_are_remark_lines_numbered_and_counted() {
    let (_d, dir) = scratch(&["pick_place.ls", "weld_seam.ls"], FRAMES);
    for (stem, motions) in [("pick_place", 4), ("weld_seam", 9)] {
        let (code, _, err) = run(
            &dir,
            &[
                "compensate",
                &format!("{stem}.ls"),
                "--machine",
                "cell.yaml",
            ],
        );
        assert_eq!(code, 0, "{err}");
        let src_in = read(&dir.join(format!("{stem}.ls")));
        let src_out = text_without_header(&read(&dir.join(format!("{stem}.comp.ls"))));
        let (pin, pout) = (
            parse(&src_in, "in").expect("parses"),
            parse(&src_out, "out").expect("parses"),
        );
        // LINE_COUNT counts the lines, numbered 1, 2, … in order.
        let (count, _) = pout.line_count.clone().expect("LINE_COUNT");
        assert_eq!(count as usize, pout.mn.len(), "{stem}");
        let numbers: Vec<u32> = pout.mn.iter().map(|l| l.number).collect();
        assert_eq!(numbers, (1..=count).collect::<Vec<_>>(), "{stem}");
        // The remarks added: three per compensated motion, each at most 32
        // characters, together the words of a RAPID annotation.
        let before: Vec<String> = remarks(mn(&src_in)).into_iter().map(|(_, r)| r).collect();
        let added: Vec<(u32, String)> = remarks(mn(&src_out))
            .into_iter()
            .filter(|(_, r)| !before.contains(r))
            .collect();
        assert_eq!(added.len(), 3 * motions, "{stem}: {added:?}");
        assert_eq!(count as usize, pin.mn.len() + added.len(), "{stem}");
        for chunk in added.chunks(3) {
            for (_, r) in chunk {
                assert!(r.chars().count() <= 32, "{stem}: {r}");
            }
            let text: Vec<&str> = chunk.iter().map(|(_, r)| r.as_str()).collect();
            let joined = text.join(" ");
            let shape: Vec<&str> = joined
                .split(' ')
                .filter(|w| !w.starts_with(|c: char| c.is_ascii_digit()))
                .collect();
            assert_eq!(
                shape,
                ["dev", "mm", "(kin", "therm", "grav", "proc", "vib"],
                "{stem}: {joined}"
            );
            let value = |w: &str| -> String {
                let at = joined.find(w).expect(w) + w.len() + 1;
                joined[at..]
                    .split(' ')
                    .next()
                    .unwrap_or("")
                    .trim_end_matches(')')
                    .to_string()
            };
            assert_eq!(value("dev").split('.').nth(1).map(str::len), Some(3));
            assert_eq!(value("vib").split('.').nth(1).map(str::len), Some(4));
        }
        // Without the remarks and their numbers the /MN is the input's.
        let strip = |s: &str| -> Vec<String> {
            s.lines()
                .filter(|l| remarks(l).first().is_none_or(|(_, r)| before.contains(r)))
                .map(|l| l.split_once(':').map_or(l, |(_, r)| r).to_string())
                .collect()
        };
        assert_eq!(strip(mn(&src_out)), strip(mn(&src_in)), "{stem}");
        // The remarks follow the motion they annotate: the line before a
        // first remark ends a motion (for a circle, its end point line).
        let lines: Vec<&str> = mn(&src_out).lines().collect();
        for (i, l) in lines.iter().enumerate() {
            let first = remarks(l)
                .first()
                .is_some_and(|(_, r)| r.starts_with("dev "));
            if first {
                let prev = lines[i - 1];
                assert!(
                    prev.contains("P[") && prev.trim_end().ends_with(';'),
                    "{stem}: {prev}"
                );
            }
        }
    }
}

#[test]
fn annotations_give_the_reports_deviation() {
    let (_d, dir) = scratch(&["weld_seam.ls"], FRAMES);
    let (code, _, err) = run(
        &dir,
        &[
            "compensate",
            "weld_seam.ls",
            "--machine",
            "cell.yaml",
            "--report",
            "r.json",
        ],
    );
    assert_eq!(code, 0, "{err}");
    let out = read(&dir.join("weld_seam.comp.ls"));
    let devs: Vec<f64> = remarks(mn(&out))
        .iter()
        .filter_map(|(_, r)| r.strip_prefix("dev ")?.split(' ').next()?.parse().ok())
        .collect();
    assert_eq!(devs.len(), 9);
    let report: serde_json::Value = serde_json::from_str(&read(&dir.join("r.json"))).expect("json");
    let max = report
        .pointer("/summary/max_mm")
        .and_then(serde_json::Value::as_f64)
        .expect("the report's largest deviation");
    let largest = devs.iter().copied().fold(0.0, f64::max);
    // The report rounds to 5 decimals, the remark to 3.
    assert!((largest - max).abs() <= ROUNDING_MM, "{largest} vs {max}");
}

/// Half a unit of the remark's third decimal plus the report's rounding.
const ROUNDING_MM: f64 = 0.0005 + 0.000005;
