//! Integration tests: the KRL syntax layer (grammar/krl.md), its fixtures
//! (tests/krl/: a palletising `.src`/`.dat` pair with folds and inline
//! forms, a CAM milling program of 10 000 `LIN`s and a `$config.dat`), and
//! Status/Turn and A, B, C on the bundled KUKA arms.

use nalgebra::Vector3;
use postproc::machine::robot::{Model, Robot};
use postproc::machine::{Machine, MachineFile};
use postproc::program::euler;
use postproc::program::krl::config::{StatusTurn, axes_to_model, model_to_axes};
use postproc::program::krl::{Aggregate, File, Kind, Motion, Target, Value, parse};

use crate::common::{fenced_blocks, text};

/// Every number of an aggregate (nested ones too) spans exactly its text.
fn numbers_span_their_text(src: &str, a: &Aggregate) -> usize {
    let mut n = 0;
    for (_, v) in &a.fields {
        match v {
            Value::Number(x) => {
                let text = &src[x.span.clone()];
                assert_eq!(text.parse::<f64>().ok(), Some(x.value), "{text}");
                n += 1;
            }
            Value::Aggregate(inner) => n += numbers_span_their_text(src, inner),
            _ => {}
        }
    }
    assert!(src[a.span.clone()].starts_with('{') && src[a.span.clone()].ends_with('}'));
    n
}

fn aggregates(f: &File) -> impl Iterator<Item = &Aggregate> {
    f.lines.iter().filter_map(|l| match &l.kind {
        Kind::Decl { value: Some(a), .. } | Kind::Assign(_, Some(a), _) => Some(a),
        Kind::Move {
            target: Target::Aggregate(a),
            ..
        } => Some(a),
        _ => None,
    })
}

#[test]
fn every_grammar_example_parses_and_every_construct_is_shown() {
    let md = text("grammar/krl.md");
    let examples = fenced_blocks(&md, "krl");
    assert!(examples.len() >= 7, "{} examples", examples.len());
    let mut seen = std::collections::BTreeSet::new();
    for (i, ex) in examples.iter().enumerate() {
        let f = parse(ex, &format!("grammar/krl.md example {}", i + 1))
            .unwrap_or_else(|e| panic!("example {}: {e}", i + 1));
        for l in &f.lines {
            let tag = match &l.kind {
                Kind::Header(..) => "header".to_string(),
                Kind::Def(_) => "def".into(),
                Kind::End => "end".into(),
                Kind::DefDat(_) => "defdat".into(),
                Kind::EndDat => "enddat".into(),
                Kind::Fold(_, Some(form)) => format!("inline {:?}", form.motion),
                Kind::Fold(_, None) => "fold".into(),
                Kind::EndFold => "endfold".into(),
                Kind::Decl { type_name, .. } => format!("decl {type_name}"),
                Kind::Move { motion, .. } => format!("move {motion:?}"),
                Kind::Assign(lhs, ..) => format!("assign {}", lhs.split('[').next().unwrap_or("")),
                Kind::Blank | Kind::Other => continue,
            };
            seen.insert(tag);
        }
        for a in aggregates(&f) {
            numbers_span_their_text(ex, a);
        }
    }
    for want in [
        "header",
        "def",
        "end",
        "defdat",
        "enddat",
        "fold",
        "endfold",
        "inline Ptp",
        "inline Lin",
        "inline Circ",
        "move Ptp",
        "move Lin",
        "move Circ",
        "move Sptp",
        "move Slin",
        "move Scirc",
        "decl E6POS",
        "decl POS",
        "decl FRAME",
        "decl E6AXIS",
        "decl AXIS",
        "decl PDAT",
        "decl LDAT",
        "decl FDAT",
        "assign $BASE",
        "assign $TOOL",
        "assign TOOL_DATA",
        "assign BASE_DATA",
    ] {
        assert!(
            seen.contains(want),
            "grammar/krl.md shows no {want}: {seen:?}"
        );
    }
}

#[test]
fn inline_forms_read_their_points_speed_data_tool_and_base() {
    let src = ";FOLD PTP P1 CONT Vel=100 % PDAT1 Tool[1] Base[2];%{PE}%R 8.3.38\n\
               ;FOLD LIN P2 Vel=0.5 m/s CPDAT1 Tool[3]:GRIPPER Base[0];%{PE}\n\
               ;FOLD CIRC P3 P4 Vel=0.2 m/s CPDAT2 Tool[1] Base[2]\n";
    let f = parse(src, "t").expect("parses");
    let forms: Vec<_> = f
        .lines
        .iter()
        .filter_map(|l| match &l.kind {
            Kind::Fold(_, Some(form)) => Some(form),
            _ => None,
        })
        .collect();
    assert_eq!(forms.len(), 3);
    let (p, l, c) = (forms[0], forms[1], forms[2]);
    assert_eq!(
        (p.motion, p.points.as_slice(), p.cont),
        (Motion::Ptp, &["P1".to_string()][..], true)
    );
    let (vel, unit) = p.vel.as_ref().expect("Vel");
    assert_eq!(
        (vel.value, unit.as_str(), &src[vel.span.clone()]),
        (100.0, "%", "100")
    );
    assert_eq!(
        (p.data.as_deref(), p.tool, p.base),
        (Some("PDAT1"), Some(1), Some(2))
    );
    let (vel, unit) = l.vel.as_ref().expect("Vel");
    assert_eq!(
        (vel.value, unit.as_str(), &src[vel.span.clone()]),
        (0.5, "m/s", "0.5")
    );
    assert_eq!(
        (l.cont, l.data.as_deref(), l.tool, l.base),
        (false, Some("CPDAT1"), Some(3), Some(0))
    );
    assert_eq!(c.points, ["P3", "P4"]);
}

#[test]
fn the_palletising_pair_parses_with_its_folds_inline_forms_and_data() {
    let src = text("tests/krl/palletise.src");
    let f = parse(&src, "palletise.src").expect("the .src parses");
    // CRLF: spans leave the line ends out.
    assert!(f.lines.iter().all(|l| !src[l.span.clone()].ends_with('\r')));
    let folds = f
        .lines
        .iter()
        .filter(|l| matches!(l.kind, Kind::Fold(..)))
        .count();
    let ends = f
        .lines
        .iter()
        .filter(|l| matches!(l.kind, Kind::EndFold))
        .count();
    assert_eq!((folds, ends), (6, 6));
    let inline: Vec<_> = f
        .lines
        .iter()
        .filter_map(|l| match &l.kind {
            Kind::Fold(_, Some(form)) => Some((form.motion, form.points[0].clone())),
            _ => None,
        })
        .collect();
    assert_eq!(
        inline,
        [
            (Motion::Sptp, "HOME".to_string()),
            (Motion::Ptp, "PICK_ABOVE".to_string()),
            (Motion::Lin, "PICK".to_string())
        ]
    );
    let moves: Vec<String> = f
        .lines
        .iter()
        .filter_map(|l| match &l.kind {
            Kind::Move { motion, target, .. } => Some(match target {
                Target::Named(n, _) => format!("{motion:?} {n}"),
                Target::Aggregate(a) => format!("{motion:?} {{{}}}", a.fields.len()),
            }),
            _ => None,
        })
        .collect();
    assert_eq!(
        moves,
        [
            "Sptp XHOME",
            "Ptp XPICK_ABOVE",
            "Lin XPICK",
            "Ptp place",
            "Lin {6}",
            "Ptp {6}"
        ]
    );
    let assigns: Vec<&str> = f
        .lines
        .iter()
        .filter_map(|l| match &l.kind {
            Kind::Assign(lhs, ..) => Some(lhs.as_str()),
            _ => None,
        })
        .collect();
    for want in ["$BASE", "$TOOL", "place", "place.X", "PDAT_ACT"] {
        assert!(assigns.contains(&want), "{want} in {assigns:?}");
    }

    let dat = text("tests/krl/palletise.dat");
    let d = parse(&dat, "palletise.dat").expect("the .dat parses");
    let decl = |name: &str| {
        d.lines
            .iter()
            .find_map(|l| match &l.kind {
                Kind::Decl {
                    name: n,
                    value: Some(a),
                    type_name,
                } if n.eq_ignore_ascii_case(name) => Some((type_name.clone(), a.clone())),
                _ => None,
            })
            .unwrap_or_else(|| panic!("{name} declared"))
    };
    let (t, p) = decl("XPICK");
    assert_eq!(t, "E6POS");
    let z = p.number("Z").expect("Z");
    assert_eq!((z.value, &dat[z.span.clone()]), (265.0, "265.000"));
    assert_eq!((p.bits("S"), p.bits("T")), (Some(2), Some(35)));
    let (t, o) = decl("XPLACE_ORIGIN");
    assert_eq!(
        (t.as_str(), o.bits("S"), o.bits("T")),
        ("POS", Some(0b010), Some(0b100011))
    );
    let (_, ld) = decl("LCPDAT1");
    assert_eq!(ld.number("VEL").map(|n| n.value), Some(0.5));
    assert!(matches!(ld.get("ORI_TYP"), Some(Value::Word(w)) if &dat[w.clone()] == "#VAR"));
    let (_, fd) = decl("FPICK");
    assert_eq!(fd.number("BASE_NO").map(|n| n.value), Some(1.0));
    let mut numbers = 0;
    for a in aggregates(&d) {
        numbers += numbers_span_their_text(&dat, a);
    }
    assert!(numbers > 60, "{numbers}");
}

#[test]
fn config_dat_holds_tool_and_base_frames() {
    let src = text("tests/krl/$config.dat");
    let f = parse(&src, "$config.dat").expect("parses");
    let frames: Vec<(String, f64)> = f
        .lines
        .iter()
        .filter_map(|l| match &l.kind {
            Kind::Assign(lhs, Some(a), _) => Some((lhs.clone(), a.number("Z")?.value)),
            _ => None,
        })
        .collect();
    assert_eq!(
        frames,
        [
            ("TOOL_DATA[1]".to_string(), 185.5),
            ("TOOL_DATA[2]".to_string(), 242.8),
            ("BASE_DATA[1]".to_string(), 310.0),
            ("BASE_DATA[2]".to_string(), 0.0)
        ]
    );
}

#[test]
fn the_cam_program_has_ten_thousand_lins_with_their_numbers() {
    let src = text("tests/krl/pocket_mill.src");
    let f = parse(&src, "pocket_mill.src").expect("parses");
    let mut lins = 0;
    for l in &f.lines {
        if let Kind::Move {
            motion: Motion::Lin,
            target: Target::Aggregate(a),
            ..
        } = &l.kind
        {
            assert_eq!(numbers_span_their_text(&src, a), 6, "line {}", l.number);
            lins += 1;
        }
    }
    assert_eq!(lins, 10_000);
    let scirc = f
        .lines
        .iter()
        .find_map(|l| match &l.kind {
            Kind::Move {
                motion: Motion::Scirc,
                aux: Some(Target::Aggregate(aux)),
                target: Target::Aggregate(end),
                ..
            } => Some((aux.number("X")?.value, end.number("X")?.value)),
            _ => None,
        })
        .expect("an SCIRC with two points");
    assert_eq!(scirc, (140.0, 160.0));
}

#[test]
fn malformed_aggregates_are_located_errors() {
    for (src, col) in [
        ("DECL E6POS XP1={X 1.0,Y 2.0\n", 28),
        ("LIN {X 1.0 Y 2.0}\n", 12),
        ("DECL POS XP1={X 'B01\n", 17),
    ] {
        let e = parse(src, "bad.src").expect_err(src);
        assert_eq!((e.line, e.column), (1, col), "{src}: {e}");
        assert!(e.to_string().contains(src.trim()), "{e}");
    }
}

fn kuka(name: &str) -> Robot {
    match MachineFile::bundled(name)
        .expect("bundled")
        .load()
        .expect("loads")
    {
        Machine::Robot(r) => r,
        Machine::Tool(_) => panic!("{name} is a robot"),
    }
}

/// Status and Turn of joint positions on the bundled KUKA arms against
/// the definitions worked by hand, and the model's inverse kinematics in
/// the configuration they name lands on the same joints.
#[test]
fn status_and_turn_on_the_bundled_kuka_arms() {
    let r = kuka("kuka-kr16-2");
    // HOME: basic area, elbow up (A3 = 90° beyond φ), A5 = 0 positive: S 2;
    // only A2 is negative: T 2.
    let home = axes_to_model(&[0.0, -90.0, 90.0, 0.0, 0.0, 0.0]);
    assert_eq!(
        StatusTurn::of_joints(&r, &home),
        StatusTurn { status: 2, turn: 2 }
    );
    // A5 negative sets S bit 2 and T bit 4; A1 and A6 negative T bits 0, 5.
    let q = axes_to_model(&[-30.0, -80.0, 100.0, 10.0, -45.0, -200.0]);
    assert_eq!(
        StatusTurn::of_joints(&r, &q),
        StatusTurn {
            status: 6,
            turn: 0b110011
        }
    );
    // Reaching over the shoulder (A2 −150°, A3 = 60°): the wrist root point
    // is behind A1, the overhead area, S bit 0.
    let over = axes_to_model(&[0.0, -150.0, 60.0, 0.0, 30.0, 0.0]);
    assert_eq!(StatusTurn::of_joints(&r, &over).status & 1, 1);
    // Elbow below φ: A3 = −20° with the KR 16's offset below the forearm.
    let down = axes_to_model(&[0.0, -60.0, -20.0, 0.0, 40.0, 0.0]);
    assert_eq!(StatusTurn::of_joints(&r, &down).status & 2, 0);
    // Every configuration the IK gives back is the one asked for.
    for a in [
        [20.0, -70.0, 80.0, 30.0, 50.0, 60.0],
        [-120.0, -100.0, 110.0, -150.0, -60.0, 250.0],
        [170.0, -40.0, 140.0, 100.0, 20.0, -300.0],
    ] {
        let q = axes_to_model(&a);
        let st = StatusTurn::of_joints(&r, &q);
        assert!(st.matches(&r, &q));
        let back = model_to_axes(&q);
        for (x, y) in back.iter().zip(a) {
            assert!((x - y).abs() < 1e-9);
        }
    }
}

/// The flange of the bundled KUKA arms at HOME, read as A, B, C, is
/// `A 0, B 90, C 0`: KUKA's $FLANGE z axis points along $ROBROOT x.
#[test]
fn the_flange_at_home_reads_b_90() {
    for name in ["kuka-kr6-r900-sixx", "kuka-kr16-2", "kuka-kr210-r2700-2"] {
        let r = kuka(name);
        let f = r.flange_pose(
            Model::Nominal,
            &axes_to_model(&[0.0, -90.0, 90.0, 0.0, 0.0, 0.0]),
        );
        let (a, b, c) = euler::quaternion_to_zyx(&f.rotation);
        assert!(
            a.abs() < 1e-9 && (b - 90.0).abs() < 1e-6 && c.abs() < 1e-9,
            "{name}: {a} {b} {c}"
        );
        assert!((f.rotation * Vector3::z() - Vector3::x()).norm() < 1e-12);
    }
}

/// No input makes the parser panic: every prefix of the fixtures (a file
/// cut anywhere) parses or is a located error.
#[test]
fn cut_files_never_panic() {
    for path in ["tests/krl/palletise.src", "tests/krl/palletise.dat"] {
        let src = text(path);
        for end in (0..=src.len()).filter(|e| src.is_char_boundary(*e)) {
            let _ = parse(&src[..end], path);
        }
    }
}
