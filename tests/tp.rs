//! Integration tests: the FANUC TP syntax layer (grammar/tp.md), its
//! fixtures (tests/tp/: a pick-and-place with UF/UT and PR[] and a weld
//! path with C moves), CONFIG and W, P, R on the bundled FANUC arms, and
//! the programs through the binary ([`compensate`]).

use nalgebra::Vector3;
use postproc::machine::robot::{Model, Robot};
use postproc::machine::{Machine, MachineFile};
use postproc::program::euler;
use postproc::program::tp::config::{Config, joints_to_model};
use postproc::program::tp::{Instruction, Motion, Program, parse};

use crate::common::{fenced_blocks, text};

mod compensate;

/// Every number of every position spans exactly its text.
fn numbers_span_their_text(src: &str, p: &Program) -> usize {
    let mut n = 0;
    for pos in &p.positions {
        for g in &pos.groups {
            for (_, v) in g.values.iter().chain(
                g.uf.iter()
                    .map(|u| ("UF".to_string(), u.clone()))
                    .collect::<Vec<_>>()
                    .iter(),
            ) {
                assert_eq!(src[v.span.clone()].parse::<f64>().ok(), Some(v.value));
                n += 1;
            }
        }
        assert!(src[pos.span.clone()].starts_with("P[") && src[pos.span.clone()].ends_with("};"));
    }
    n
}

#[test]
fn every_grammar_example_parses() {
    let md = text("grammar/tp.md");
    let examples = fenced_blocks(&md, "ls");
    assert_eq!(examples.len(), 5);
    let mut kinds = std::collections::BTreeSet::new();
    for (i, ex) in examples.iter().enumerate() {
        let p = parse(ex, "grammar/tp.md").unwrap_or_else(|e| panic!("example {}: {e}", i + 1));
        numbers_span_their_text(ex, &p);
        if let Some((count, _)) = &p.line_count {
            assert_eq!(*count as usize, p.mn.len(), "example {}", i + 1);
        }
        for l in &p.mn {
            kinds.insert(match &l.instruction {
                Instruction::Move { motion, target, .. } => {
                    format!("{motion:?} {}", if target.register { "PR" } else { "P" })
                }
                Instruction::UframeNum(_) => "UFRAME_NUM".into(),
                Instruction::UtoolNum(_) => "UTOOL_NUM".into(),
                Instruction::FrameNumAtRunTime { .. } => "frame number at run time".into(),
                Instruction::SetFrame { .. } => "frame set".into(),
                Instruction::Label => "label".into(),
                Instruction::Other => "other".into(),
            });
        }
        for pos in &p.positions {
            for g in &pos.groups {
                kinds.insert(if g.is_joint() {
                    "joint form".into()
                } else {
                    "cartesian form".to_string()
                });
            }
        }
        kinds.extend(p.sections.iter().map(|(s, _)| format!("/{s}")));
    }
    for want in [
        "/PROG",
        "/ATTR",
        "/APPL",
        "/MN",
        "/POS",
        "/END",
        "J P",
        "L P",
        "C P",
        "J PR",
        "UFRAME_NUM",
        "UTOOL_NUM",
        "frame number at run time",
        "frame set",
        "label",
        "joint form",
        "cartesian form",
        "other",
    ] {
        assert!(
            kinds.contains(want),
            "grammar/tp.md shows no {want}: {kinds:?}"
        );
    }
}

#[test]
fn the_pick_and_place_reads_frames_registers_and_positions() {
    let src = text("tests/tp/pick_place.ls");
    let p = parse(&src, "pick_place.ls").expect("parses");
    assert_eq!(p.name, "PICK_PLACE");
    let (count, span) = p.line_count.clone().expect("LINE_COUNT");
    assert_eq!((count as usize, &src[span]), (p.mn.len(), "17"));
    let frames: Vec<String> =
        p.mn.iter()
            .filter_map(|l| match &l.instruction {
                Instruction::UframeNum(n) => Some(format!("UF{n}")),
                Instruction::UtoolNum(n) => Some(format!("UT{n}")),
                Instruction::Move { target, .. } => Some(format!(
                    "{}{}",
                    if target.register { "PR" } else { "P" },
                    target.index
                )),
                _ => None,
            })
            .collect();
    assert_eq!(
        frames,
        [
            "UF1", "UT2", "P1", "P2", "P3", "P2", "UF3", "PR5", "P4", "P5", "P1"
        ]
    );
    let home = p.position(1).expect("P[1]");
    assert_eq!(home.comment.as_deref(), Some("\"home\""));
    assert!(home.groups[0].is_joint() && home.groups[0].config.is_none());
    assert_eq!(home.groups[0].value("J5").map(|n| n.value), Some(-90.0));
    let pick = &p.position(3).expect("P[3]").groups[0];
    let z = pick.value("Z").expect("Z");
    assert_eq!((z.value, &src[z.span.clone()]), (62.75, "62.750"));
    assert_eq!(
        (
            pick.uf.as_ref().map(|n| n.value),
            pick.ut.as_ref().map(|n| n.value)
        ),
        (Some(1.0), Some(2.0))
    );
    let (cfg, span) = pick.config.clone().expect("CONFIG");
    assert_eq!(&src[span], cfg);
    assert_eq!(Config::parse(&cfg).expect("config").cfx(), 0);
    assert_eq!(numbers_span_their_text(&src, &p), 5 * 6 + 5);
}

#[test]
fn the_weld_path_pairs_each_circle_with_its_via_and_end_points() {
    let src = text("tests/tp/weld_seam.ls");
    let p = parse(&src, "weld_seam.ls").expect("parses");
    assert_eq!(
        p.line_count.as_ref().map(|l| l.0 as usize),
        Some(p.mn.len())
    );
    let circles: Vec<(u32, u32)> =
        p.mn.iter()
            .filter_map(|l| match &l.instruction {
                Instruction::Move {
                    motion: Motion::C,
                    via: Some(v),
                    target,
                    rest,
                } => {
                    assert_eq!(src[rest.clone()].trim(), "12mm/sec CNT100");
                    Some((v.index, target.index))
                }
                _ => None,
            })
            .collect();
    assert_eq!(circles, [(3, 4), (5, 6), (7, 8), (9, 10)]);
    assert_eq!(p.positions.len(), 12);
    assert!(
        p.positions
            .iter()
            .all(|q| q.groups[0].value("W").map(|w| w.value) == Some(-145.0))
    );
}

#[test]
fn malformed_programs_are_located_errors() {
    for (src, line, col) in [
        ("MN\n", 1, 1),
        (
            "/PROG X\n/POS\nP[1]{\n   GP1:\n\tX = abc mm\n};\n/END\n",
            5,
            6,
        ),
        ("/PROG X\n/POS\nQ[1]{};\n/END\n", 3, 1),
        ("/PROG X\n/MN\n   x:J P[1] 100% FINE ;\n", 3, 1),
    ] {
        let e = parse(src, "bad.ls").expect_err(src);
        assert_eq!((e.line, e.column), (line, col), "{src}: {e}");
    }
    for path in ["tests/tp/pick_place.ls", "tests/tp/weld_seam.ls"] {
        let src = text(path);
        for end in (0..=src.len()).filter(|e| src.is_char_boundary(*e)) {
            let _ = parse(&src[..end], path);
        }
    }
}

fn fanuc(name: &str) -> Robot {
    match MachineFile::bundled(name)
        .expect("bundled")
        .load()
        .expect("loads")
    {
        Machine::Robot(r) => r,
        Machine::Tool(_) => panic!("{name} is a robot"),
    }
}

/// CONFIG of joint positions on the bundled FANUC arms as the rules of
/// grammar/tp.md give it by hand, and W, P, R of the faceplate at zero.
#[test]
fn config_and_wpr_on_the_bundled_fanuc_arms() {
    let r = fanuc("fanuc-lrmate200id");
    let cfg = |j: [f64; 6]| Config::of_joints(&r, &joints_to_model(&j)).to_string();
    // The tool pointing down in front: no flip (J5 < 0), elbow up, front.
    assert_eq!(cfg([0.0, 0.0, 0.0, 0.0, -90.0, 0.0]), "N U T, 0, 0, 0");
    // J5 positive: flip; J6 beyond 180°: turn 1; J4 below −180°: turn −1.
    assert_eq!(
        cfg([10.0, 20.0, -10.0, -200.0, 45.0, 270.0]),
        "F U T, 0, -1, 1"
    );
    // J2 back and J3 up over the top: the wrist centre behind axis 1.
    assert_eq!(&cfg([0.0, -60.0, 80.0, 0.0, -30.0, 0.0])[4..5], "B");
    // A configuration read back solves to the joints it came from.
    for j in [
        [30.0, 10.0, -20.0, 40.0, -60.0, 100.0],
        [-100.0, 50.0, 20.0, -150.0, 70.0, -250.0],
    ] {
        let q = joints_to_model(&j);
        let c = Config::of_joints(&r, &q);
        assert!(
            Config::parse(&c.to_string())
                .expect("reads")
                .matches(&r, &q)
        );
    }
    for name in ["fanuc-lrmate200id", "fanuc-m20ia", "fanuc-r2000ic-165f"] {
        let f = fanuc(name).flange_pose(Model::Nominal, &[0.0; 6]);
        // W, P, R = 180, -90, 0: R = Rz(0)·Ry(-90°)·Rx(180°).
        let want = euler::zyx_to_quaternion(0.0, -90.0, 180.0);
        assert!(f.rotation.angle_to(&want) < 1e-12, "{name}");
        let (_, p, _) = euler::quaternion_to_zyx(&f.rotation);
        assert!((p + 90.0).abs() < 1e-6, "{name}: P {p}");
        assert!(
            (f.rotation * Vector3::x() - Vector3::z()).norm() < 1e-12,
            "{name}: x up"
        );
    }
}
