//! Integration tests: the RAPID front end (grammar examples, spans, errors)
//! and the byte-faithful rewriter.

use crate::common::{fenced_blocks, repo};
use approx::assert_abs_diff_eq;
use postproc::emit::rapid::{
    Edit, Format, annotate, apply_edits, decl_copy, format_fixed, format_quaternion,
    insert_after_decl, line_ending, robtarget_edits, robtarget_literal,
};
use postproc::program::rapid::{
    DataType, DataValue, Module, MoveKind, RobTarget, Scope, Stmt, Storage, Target, parse_module,
    parse_module_bytes,
};
use proptest::prelude::*;

/// Tolerance on values read back from literals (they are parsed exactly).
const VALUE_TOL: f64 = 1e-12;

fn grammar() -> String {
    std::fs::read_to_string(repo("grammar/rapid.md")).expect("grammar/rapid.md readable")
}

fn sample() -> String {
    std::fs::read_to_string(repo("samples/drilling.mod")).expect("samples/drilling.mod readable")
}

fn parse(src: &str) -> Module {
    match parse_module(src, "t.mod") {
        Ok(m) => m,
        Err(e) => panic!("parse failed: {e}\n{src}"),
    }
}

fn parse_err(src: &str) -> String {
    match parse_module(src, "t.mod") {
        Ok(_) => panic!("expected a parse error for:\n{src}"),
        Err(e) => e.to_string(),
    }
}

fn robtarget<'m>(m: &'m Module, name: &str) -> &'m RobTarget {
    match m.decl(name).and_then(|d| d.value.as_ref()) {
        Some(DataValue::RobTarget(r)) => r,
        other => panic!("{name} is not a robtarget: {other:?}"),
    }
}

/// Every number of a robtarget slices back to text that parses to its
/// value, or to the name of a `CONST num` of the module declared with it.
fn check_spans(src: &str, rt: &RobTarget) {
    let all = rt
        .trans
        .iter()
        .chain(&rt.rot)
        .chain(&rt.robconf)
        .chain(&rt.extax);
    for n in all {
        let text = &src[n.span.clone()];
        let v: f64 = match text.parse() {
            Ok(v) => v,
            Err(_) => {
                // `CONST num NAME := VALUE;` in the same text.
                let decl = format!("CONST num {text} := ");
                let at = src.find(&decl).expect("span is a number or a constant") + decl.len();
                let value = &src[at..];
                value[..value.find(';').expect("value")]
                    .trim()
                    .parse()
                    .expect("a literal")
            }
        };
        assert_abs_diff_eq!(v, n.value, epsilon = VALUE_TOL);
    }
    assert!(src[rt.span.clone()].starts_with("[["));
    assert!(src[rt.span.clone()].ends_with("]]"));
}

fn all_robtargets(m: &Module) -> Vec<&RobTarget> {
    fn walk<'a>(v: &'a DataValue, out: &mut Vec<&'a RobTarget>) {
        match v {
            DataValue::RobTarget(r) => out.push(r),
            DataValue::Array { items, .. } => items.iter().for_each(|i| walk(i, out)),
            _ => {}
        }
    }
    let mut out = Vec::new();
    for d in &m.decls {
        if let Some(v) = &d.value {
            walk(v, &mut out);
        }
    }
    for mv in m.moves() {
        if let Target::Inline(r) = &mv.target {
            out.push(r);
        }
    }
    out
}

#[test]
fn grammar_examples_parse_and_rejects_fail() {
    let md = grammar();
    let good = fenced_blocks(&md, "rapid");
    let bad = fenced_blocks(&md, "rapid-reject");
    assert!(good.len() >= 3, "grammar has {} rapid examples", good.len());
    assert!(bad.len() >= 3, "grammar has {} reject examples", bad.len());
    for src in &good {
        let m = parse(src);
        for rt in all_robtargets(&m) {
            check_spans(src, rt);
        }
        assert_eq!(apply_edits(src, &[]).expect("no edits"), *src);
    }
    for src in &bad {
        let e = parse_err(src);
        assert!(e.starts_with("t.mod:"), "{e}");
    }
}

/// Every source file the grammar names (`src/….rs` in backquotes) exists.
#[test]
fn grammar_names_existing_source_files() {
    let md = grammar();
    let named: Vec<&str> = md
        .match_indices("`src/")
        .filter_map(|(k, _)| md[k + 1..].split('`').next())
        .filter(|t| t.ends_with(".rs"))
        .collect();
    assert!(!named.is_empty());
    for path in named {
        assert!(repo(path).is_file(), "grammar/rapid.md names {path}");
    }
}

#[test]
fn sample_module_structure() {
    let src = sample();
    let m = parse_module(&src, "samples/drilling.mod").expect("sample parses");
    assert_eq!(m.name, "Drilling");
    assert!(m.header.is_some());
    assert_eq!(m.decls.len(), 11);
    assert_eq!(m.procs.len(), 1);
    // 2 MoveAbsJ + 2 MoveJ pClear + 12 holes × 4 moves.
    assert_eq!(m.moves().count(), 52);
    let holes = m.decl("HOLES").expect("case-insensitive lookup");
    assert_eq!(
        holes.dims.iter().map(|d| d.value).collect::<Vec<_>>(),
        vec![Some(12)]
    );
    assert_eq!(holes.data_type, DataType::RobTarget);
    let Some(DataValue::Array { items, .. }) = &holes.value else {
        panic!("holes is an array");
    };
    assert_eq!(items.len(), 12);
    // Hole 6 is row 2 (x = 175), column 2 (y = 150), written [[175,150,0],…].
    let DataValue::RobTarget(h6) = &items[5] else {
        panic!("robtarget element");
    };
    assert_eq!(&src[h6.trans[0].span.clone()], "175");
    assert_eq!(&src[h6.trans[1].span.clone()], "150");
    assert_abs_diff_eq!(h6.rot[2].value, 1.0, epsilon = VALUE_TOL);
    assert!(h6.extax.iter().all(|n| n.is_unused_axis()));
    for rt in all_robtargets(&m) {
        check_spans(&src, rt);
    }
    // The tool: 2.4 kg, centre of gravity 85 mm along z, TCP at z 182.5.
    let Some(DataValue::ToolData(t)) = &m.decl("tDrill").and_then(|d| d.value.clone()) else {
        panic!("tooldata");
    };
    assert!(t.robhold);
    assert_abs_diff_eq!(t.mass.value, 2.4, epsilon = VALUE_TOL);
    assert_abs_diff_eq!(t.cog[2].value, 85.0, epsilon = VALUE_TOL);
    assert_abs_diff_eq!(t.tframe.trans[2].value, 182.5, epsilon = VALUE_TOL);
    let Some(DataValue::WobjData(w)) = &m.decl("wPlate").and_then(|d| d.value.clone()) else {
        panic!("wobjdata");
    };
    assert!(w.ufprog && !w.robhold);
    assert_abs_diff_eq!(w.uframe.trans[0].value, 600.0, epsilon = VALUE_TOL);
    let pclear = robtarget(&m, "pClear");
    assert_eq!(&src[pclear.extax[0].span.clone()], "9E+09");
    assert_eq!(m.decl("depth").map(|d| d.storage), Some(Storage::Const));
    // The drilling move of hole 1: MoveL Offs(holes{1},0,0,-12), vDrill, fine, tDrill\WObj:=wPlate;
    let drill = m.moves().nth(4).expect("fifth move");
    assert_eq!(drill.kind, MoveKind::MoveL);
    assert_eq!(&*drill.speed.text, "vDrill");
    assert_eq!(&*drill.zone.as_ref().unwrap().text, "fine");
    assert_eq!(&*drill.tool.text, "tDrill");
    assert_eq!(drill.wobj.as_ref().map(|a| &*a.text), Some("wPlate"));
    let Target::Offs { base, offsets, .. } = &drill.target else {
        panic!("Offs target: {:?}", drill.target);
    };
    let Target::Named { name, index, .. } = base.as_ref() else {
        panic!("named base");
    };
    assert_eq!(name, "holes");
    assert_eq!(index.as_ref().and_then(|i| i.value), Some(1));
    assert_eq!(offsets[2].value, Some(-12.0));
    assert_eq!(&src[offsets[2].span.clone()], "-12");
    assert_eq!(
        &src[drill.span.clone()],
        "MoveL Offs(holes{1},0,0,-12), vDrill, fine, tDrill\\WObj:=wPlate;"
    );
    let line = src.lines().nth(drill.line - 1).expect("line exists");
    assert!(line.contains("holes{1},0,0,-12"), "{line}");
    assert_eq!(apply_edits(&src, &[]).expect("no edits"), src);
}

#[test]
fn keywords_are_case_insensitive() {
    let upper = "MODULE M\nCONST ROBTARGET P := [[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\nPROC MAIN()\nMOVEL P, V100, Z10, TOOL0\\WOBJ:=W;\nENDPROC\nENDMODULE\n";
    let lower = upper.to_lowercase();
    for src in [upper.to_string(), lower] {
        let m = parse(&src);
        assert_eq!(m.decls[0].data_type, DataType::RobTarget);
        assert_eq!(m.decls[0].scope, Scope::Global);
        let mv = m.moves().next().expect("one move");
        assert_eq!(mv.kind, MoveKind::MoveL);
        assert_eq!(
            mv.wobj.as_ref().map(|a| a.text.to_lowercase()),
            Some("w".to_string())
        );
    }
}

#[test]
fn optional_arguments_with_and_without_comma() {
    let src = "MODULE M\nPROC main()\n  MoveL p1, v100\\V:=150, z10, tool1\\WObj:=wobj1\\TLoad:=load1;\n  MoveL p1, v100, \\V:=150, z10, tool1, \\WObj:=wobj1, \\TLoad:=load1;\n  MoveJ \\Conc, p1, v100, z10, tool1;\n  MoveJ\\Conc,p1,v100,z10,tool1;\nENDPROC\nENDMODULE\n";
    let m = parse(src);
    let moves: Vec<_> = m.moves().collect();
    assert_eq!(moves.len(), 4);
    for mv in &moves[..2] {
        assert_eq!(&*mv.speed.text, "v100");
        assert_eq!(&*mv.zone.as_ref().unwrap().text, "z10");
        assert_eq!(&*mv.tool.text, "tool1");
        assert_eq!(mv.wobj.as_ref().map(|a| &*a.text), Some("wobj1"));
        assert_eq!(mv.tload.as_ref().map(|a| &*a.text), Some("load1"));
        let v = mv
            .opt("v")
            .and_then(|o| o.value.as_ref())
            .expect("\\V given");
        assert_eq!(&*v.text, "150");
        assert!(!mv.conc);
    }
    for mv in &moves[2..] {
        assert!(mv.conc);
        assert!(matches!(&mv.target, Target::Named { name, .. } if name == "p1"));
        assert_eq!(&*mv.tool.text, "tool1");
    }
}

#[test]
fn reltool_movec_inline_and_numbers() {
    let src = "MODULE M\nPROC main()\n  MoveJ RelTool(p10,0,0,-50\\Rz:=45), v500, z20, tool0;\n  MoveC p1, p2, v100, z1, tool0;\n  MoveL [[800,-0.5,4.5e+2],[-1.5e-3,0,1,0],[0,0,-1,1],[9E9,9E9,9E9,9E9,9E9,9E9]], v100, fine, tool0;\nENDPROC\nENDMODULE\n";
    let m = parse(src);
    let mv: Vec<_> = m.moves().collect();
    let Target::RelTool {
        offsets, rz, rx, ..
    } = &mv[0].target
    else {
        panic!("RelTool");
    };
    assert_eq!(offsets[2].value, Some(-50.0));
    assert_eq!(rz.as_ref().and_then(|s| s.value), Some(45.0));
    assert!(rx.is_none());
    assert_eq!(mv[1].kind, MoveKind::MoveC);
    assert!(matches!(mv[1].via.as_deref(), Some(Target::Named { name, .. }) if name == "p1"));
    assert!(matches!(&mv[1].target, Target::Named { name, .. } if name == "p2"));
    let Target::Inline(rt) = &mv[2].target else {
        panic!("inline");
    };
    // 4.5e+2 = 450; -1.5e-3 = -0.0015.
    assert_eq!(&src[rt.trans[2].span.clone()], "4.5e+2");
    assert_abs_diff_eq!(rt.trans[2].value, 450.0, epsilon = VALUE_TOL);
    assert_eq!(&src[rt.rot[0].span.clone()], "-1.5e-3");
    assert_abs_diff_eq!(rt.rot[0].value, -0.0015, epsilon = VALUE_TOL);
    assert_eq!(mv[2].line, 5);
}

#[test]
fn control_and_opaque_statements_keep_spans() {
    let src = "MODULE M\nPROC main()\n  IF a > 1 THEN\n    TPWrite \"x;y\";\n  ENDIF\n  FOR i FROM 1 TO 3 DO\n    MoveL p{i}, v10, z1, tool0;\n  ENDFOR\nENDPROC\nENDMODULE\n";
    let m = parse(src);
    let body = &m.procs[0].body;
    assert_eq!(body.len(), 6);
    assert!(matches!(&body[0], Stmt::Control { keyword, .. } if keyword == "IF"));
    assert_eq!(&src[body[1].span()], "TPWrite \"x;y\";");
    let Stmt::Move(mv) = &body[4] else {
        panic!("move in loop");
    };
    let Target::Named { index, .. } = &mv.target else {
        panic!("named");
    };
    let index = index.as_ref().expect("index");
    assert_eq!(index.text, "i");
    assert_eq!(index.value, None);
}

#[test]
fn crlf_input() {
    let lf = sample();
    let crlf = lf.replace('\n', "\r\n");
    let a = parse(&lf);
    let b = parse(&crlf);
    assert_eq!(a.moves().count(), b.moves().count());
    for (x, y) in a.moves().zip(b.moves()) {
        assert_eq!(x.line, y.line);
    }
    for rt in all_robtargets(&b) {
        check_spans(&crlf, rt);
    }
    assert_eq!(apply_edits(&crlf, &[]).expect("no edits"), crlf);
    assert_eq!(line_ending(&crlf), "\r\n");
    assert_eq!(line_ending(&lf), "\n");
    // A malformed CRLF file reports the same line and column as with LF.
    let bad = "MODULE Bad\r\n  PROC main()\r\n    MoveL p10, v100, z10, tool0\r\n    MoveL p20, v100, z10, tool0;\r\n  ENDPROC\r\nENDMODULE\r\n";
    assert!(
        parse_err(bad).starts_with("t.mod:3:32:"),
        "{}",
        parse_err(bad)
    );
}

#[test]
fn malformed_inputs_are_located() {
    // Unterminated MODULE: reported at the MODULE keyword.
    let e = parse_err("MODULE Bad\n  PROC main()\n  ENDPROC\n");
    assert!(e.starts_with("t.mod:1:1: unterminated MODULE Bad"), "{e}");
    // Rotation with 3 numbers; in `  CONST robtarget p := [[750,0,500],[0,1,0],…` the
    // second inner `[` is at byte column 37 (2 + 5 + 1 + 9 + 1 + 1 + 1 + 2 + 1 = 23
    // characters before the outer `[` at 24, then `[750,0,500],` is 12 more → 37).
    let e = parse_err(
        "MODULE Bad\n  CONST robtarget p := [[750,0,500],[0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\nENDMODULE\n",
    );
    assert!(e.starts_with("t.mod:2:37: robtarget must be"), "{e}");
    assert!(e.contains("has 3 values, expected 4"), "{e}");
    assert!(e.contains("`[0,1,0]"), "{e}");
    // Missing `;`: right after `    MoveL p10, v100, z10, tool0` (31 bytes) → column 32.
    let e = parse_err(
        "MODULE Bad\n  PROC main()\n    MoveL p10, v100, z10, tool0\n    MoveL p20, v100, z10, tool0;\n  ENDPROC\nENDMODULE\n",
    );
    assert!(e.starts_with("t.mod:3:32: missing `;`"), "{e}");
    assert!(e.contains("tool0`"), "{e}");
    // Missing `;` after a declaration: `  VAR num n := 3` is 16 bytes → column 17.
    let e = parse_err("MODULE Bad\n  VAR num n := 3\n  VAR num m := 4;\nENDMODULE\n");
    assert!(e.starts_with("t.mod:2:17:"), "{e}");
    // Garbage at module level and inside a routine.
    let e = parse_err("MODULE M\n  @@@ junk\nENDMODULE\n");
    assert!(e.starts_with("t.mod:2:3: expected a declaration"), "{e}");
    assert!(e.contains("`@@@ junk`"), "{e}");
    let e = parse_err(
        "MODULE M\nPROC main()\n  MoveL p1, v100, z10, tool0;\n  )))\nENDPROC\nENDMODULE\n",
    );
    assert!(e.starts_with("t.mod:4:3:"), "{e}");
    // Wrong argument count.
    let e = parse_err("MODULE M\nPROC main()\n  MoveL p1, v100, tool0;\nENDPROC\nENDMODULE\n");
    assert!(e.starts_with("t.mod:3:3: MoveL takes 4 arguments"), "{e}");
    // Missing ENDPROC.
    let e = parse_err("MODULE M\nPROC main()\n  WaitTime 1;\nENDMODULE\n");
    assert!(e.starts_with("t.mod:4:1: expected ENDPROC"), "{e}");
    // Text after ENDMODULE, empty input.
    let e = parse_err("MODULE M\nENDMODULE\nxyz\n");
    assert!(e.starts_with("t.mod:3:1:"), "{e}");
    let e = parse_err("");
    assert!(e.starts_with("t.mod:1:1:"), "{e}");
    // Array size mismatch.
    let e = parse_err("MODULE M\nCONST num a{3} := [1,2];\nENDMODULE\n");
    assert!(
        e.starts_with("t.mod:2:19: array declared with 3 elements has 2"),
        "{e}"
    );
}

#[test]
fn deep_nesting_is_an_error_not_a_crash() {
    let deep = format!(
        "MODULE M\nCONST num a := {}1{};\nENDMODULE\n",
        "[".repeat(100_000),
        "]".repeat(100_000)
    );
    assert!(parse_err(&deep).contains("nested too deeply"));
    let offs = format!(
        "MODULE M\nPROC main()\nMoveL {}p{}, v1, z1, t;\nENDPROC\nENDMODULE\n",
        "Offs(".repeat(100_000),
        ",0,0,0)".repeat(100_000)
    );
    assert!(parse_err(&offs).contains("nested too deeply"));
}

#[test]
fn invalid_utf8_is_located() {
    // `  ! caf` is 7 bytes, so the bad byte is at column 8 of line 2.
    let e = parse_module_bytes(b"MODULE M\n  ! caf\xff\nENDMODULE\n", "b.mod").unwrap_err();
    assert_eq!((e.line, e.column), (2, 8));
    assert!(e.to_string().starts_with("b.mod:2:8: invalid UTF-8"), "{e}");
    let ok = parse_module_bytes(sample().as_bytes(), "s.mod").expect("valid");
    assert_eq!(ok.name, "Drilling");
}

#[test]
fn rewrite_robtarget_numbers() {
    let src = "MODULE M\r\n  CONST robtarget p10 := [[750,0,500],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\r\n  PROC main()\r\n    MoveL p10, v100, z10, tool0;\r\n  ENDPROC\r\nENDMODULE\r\n";
    let m = parse(src);
    let rt = robtarget(&m, "p10");
    let fmt = Format::default();
    // Position: 750.1234 → 750.123; -0.0001 → "-0.000" → "0.000"; 499.9996 → 500.000.
    // Quaternion [0, 0.001, -1, 0] has norm sqrt(1 + 1e-6); normalised it is
    // [0, 0.0009999995, -0.9999995, 0]; its dot with the input [0,0,1,0] is
    // negative, so it is negated: [0, -0.001000, 1.000000, 0] at 6 decimals.
    let edits = robtarget_edits(
        rt,
        &[750.1234, -0.0001, 499.9996],
        Some(&[0.0, 0.001, -1.0, 0.0]),
        &fmt,
    )
    .expect("finite");
    assert_eq!(edits.len(), 7);
    let out = apply_edits(src, &edits).expect("apply");
    let expected = src.replace(
        "[[750,0,500],[0,0,1,0],",
        "[[750.123,0.000,500.000],[0.000000,-0.001000,1.000000,0.000000],",
    );
    assert_eq!(out, expected);
    // A materialised copy inserted after p10, indented and CRLF-terminated,
    // and an annotation at the end of the move's line.
    let lit = robtarget_literal(src, rt, &[751.0, 0.0, 500.0], None, &fmt).expect("literal");
    assert_eq!(
        lit,
        "[[751.000,0.000,500.000],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]"
    );
    let decl = m.decl("p10").expect("p10");
    let copy = decl_copy(src, decl, "p10_c1", &lit).expect("copy");
    assert_eq!(copy, format!("CONST robtarget p10_c1 := {lit};"));
    let mv = m.moves().next().expect("move");
    let edits = [
        insert_after_decl(src, &decl.span, &copy),
        annotate(src, &mv.span, "compensated: p10_c1"),
        Edit::replace(mv.target.span(), "p10_c1"),
    ];
    let out = apply_edits(src, &edits).expect("apply");
    let expected = format!(
        "MODULE M\r\n  CONST robtarget p10 := [[750,0,500],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\r\n  {copy}\r\n  PROC main()\r\n    MoveL p10_c1, v100, z10, tool0; ! compensated: p10_c1\r\n  ENDPROC\r\nENDMODULE\r\n"
    );
    assert_eq!(out, expected);
    // The output parses again.
    parse(&out);
}

#[test]
fn rewriter_rejects_bad_edits() {
    let src = "abcdef";
    let overlap = [Edit::replace(1..3, "x"), Edit::replace(2..4, "y")];
    assert!(apply_edits(src, &overlap).is_err());
    assert!(apply_edits(src, &[Edit::replace(4..9, "x")]).is_err());
    assert!(apply_edits("é", &[Edit::replace(1..2, "x")]).is_err());
    // Order of the list does not matter; insertions at one point keep their order.
    let edits = [
        Edit::replace(4..5, "E"),
        Edit::insert(0, "<"),
        Edit::insert(0, "["),
        Edit::replace(0..1, "A"),
    ];
    assert_eq!(apply_edits(src, &edits).expect("ok"), "<[AbcdEf");
}

#[test]
fn number_formatting() {
    assert_eq!(format_fixed(1e-7, 3).as_deref(), Some("0.000"));
    assert_eq!(format_fixed(-1e-7, 3).as_deref(), Some("0.000"));
    assert_eq!(format_fixed(-2.5, 3).as_deref(), Some("-2.500"));
    assert_eq!(
        format_fixed(1e20, 1).as_deref(),
        Some("100000000000000000000.0")
    );
    assert_eq!(format_fixed(0.12345, 4).as_deref(), Some("0.1235"));
    assert_eq!(format_fixed(f64::NAN, 3), None);
    // No reference: q1 ≥ 0. [-2,0,0,0] normalises to [-1,0,0,0], negated to [1,0,0,0].
    let q = format_quaternion(&[-2.0, 0.0, 0.0, 0.0], None, &Format::default()).expect("ok");
    assert_eq!(q, ["1.000000", "0.000000", "0.000000", "0.000000"]);
    // [1,1,1,1]/2 = 0.5 each.
    let q = format_quaternion(&[1.0, 1.0, 1.0, 1.0], None, &Format::default()).expect("ok");
    assert_eq!(q, ["0.500000", "0.500000", "0.500000", "0.500000"]);
    assert!(format_quaternion(&[0.0; 4], None, &Format::default()).is_err());
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]

    #[test]
    fn arbitrary_text_never_panics(s in "\\PC{0,200}") {
        let _ = parse_module(&s, "p.mod");
        let wrapped = format!("MODULE M\nPROC main()\n{s}\nENDPROC\nENDMODULE\n");
        let _ = parse_module(&wrapped, "p.mod");
    }

    #[test]
    fn rapid_like_text_never_panics(s in "[A-Za-z0-9 \\[\\]{}(),;:=\\\\!\"%.+\\-\n\r]{0,300}") {
        let _ = parse_module(&s, "p.mod");
        let wrapped = format!("MODULE M\nPROC main()\nMoveL {s}\nENDPROC\nENDMODULE\n");
        let _ = parse_module(&wrapped, "p.mod");
    }

    #[test]
    fn mutated_sample_never_panics(edits in proptest::collection::vec((any::<usize>(), any::<u8>(), 0u8..3), 1..8)) {
        let mut bytes = sample().into_bytes();
        for (pos, byte, op) in edits {
            let len = bytes.len();
            if len == 0 { break; }
            let p = pos % len;
            match op {
                0 => bytes[p] = byte,
                1 => { bytes.remove(p); }
                _ => bytes.insert(p, byte),
            }
        }
        if let Ok(m) = parse_module_bytes(&bytes, "m.mod") {
            let text = std::str::from_utf8(&bytes).unwrap_or_default();
            let same = apply_edits(text, &[]).ok();
            prop_assert_eq!(same.as_deref(), Some(text));
            for rt in all_robtargets(&m) {
                prop_assert!(text.get(rt.span.clone()).is_some());
            }
        }
    }
}

/// Angle (rad) between the rotation of a written quaternion (parsed back and
/// normalised, as the controller does) and the exact unit quaternion `n`.
fn written_angle(text: &[String; 4], n: &[f64; 4]) -> f64 {
    let c: Vec<f64> = text
        .iter()
        .map(|t| t.parse::<f64>().expect("number"))
        .collect();
    let norm = c.iter().map(|x| x * x).sum::<f64>().sqrt();
    let dot: f64 = c.iter().zip(n).map(|(a, b)| a * b).sum();
    let s = if dot < 0.0 { -1.0 } else { 1.0 };
    // Unit quaternions a rotation φ apart are a chord 2·sin(φ/4) apart in
    // R⁴: φ = 4·asin(chord/2), stable near zero.
    let chord = c
        .iter()
        .zip(n)
        .map(|(a, b)| (s * a / norm - b).powi(2))
        .sum::<f64>()
        .sqrt();
    4.0 * (chord / 2.0).asin()
}

/// Written-orientation bound at 7 decimals, rad: each component off by
/// ≤ 5e-8, |δq| ≤ 1e-7, rotation ≤ 2·|δq| = 2e-7 rad (< 1 µrad).
const Q7_ROT_TOL_RAD: f64 = 2e-7;

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, ..ProptestConfig::default() })]
    #[test]
    fn written_quaternions_meet_one_microradian(
        w in -1.0f64..1.0, x in -1.0f64..1.0, y in -1.0f64..1.0, z in -1.0f64..1.0
    ) {
        let norm = (w * w + x * x + y * y + z * z).sqrt();
        prop_assume!(norm > 0.1);
        let n = [w / norm, x / norm, y / norm, z / norm];
        let f7 = Format { position_decimals: 3, quaternion_decimals: 7 };
        let t7 = format_quaternion(&n, Some(&n), &f7).expect("ok");
        prop_assert!(written_angle(&t7, &n) <= Q7_ROT_TOL_RAD, "{t7:?}");
        // At 6 decimals the best of the 16 roundings is never worse than
        // rounding each component to nearest.
        let f6 = Format::default();
        let t6 = format_quaternion(&n, Some(&n), &f6).expect("ok");
        let plain: [String; 4] = n.map(|c| format_fixed(c, 6).expect("finite"));
        prop_assert!(written_angle(&t6, &n) <= written_angle(&plain, &n) + 1e-15);
    }
}

/// A module shaped like a controller backup's data module: a `%%%`
/// header, record types (one LOCAL) with their fields, a record declared
/// with one, and arrays sized by constants.
const CELL_DATA: &str = "%%%\r\n  VERSION:1\r\n  LANGUAGE:ENGLISH\r\n%%%\r\n\r\nMODULE CellData\r\n  CONST num MAX_BUFFER := 16;\r\n  CONST num nRows := 3;\r\n  CONST num nCols := 2;\r\n  RECORD partdata\r\n    robtarget pPick;\r\n    ! where the part goes\r\n    robtarget pPlace;\r\n    num nHeight;\r\n  ENDRECORD\r\n  LOCAL RECORD counters\r\n    num nGood; num nBad;\r\n  ENDRECORD\r\n  PERS partdata part1 := [[[612,-85,240],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],[[300,410,120],[0,0,1,0],[1,0,1,0],[9E9,9E9,9E9,9E9,9E9,9E9]],35];\r\n  VAR robtarget buf{MAX_BUFFER};\r\n  CONST num slots{nRows * nCols, nCols DIV 2 + (1 - 1)} := [[1],[2],[3],[4],[5],[6]];\r\n  VAR num tbl{nRows+1} := [0,0,0,0];\r\n  VAR num other{nUnknown};\r\n  PROC main()\r\n    VAR num local{nRows};\r\n    MoveL part1.pPick, v500, z10, tool0;\r\n  ENDPROC\r\nENDMODULE\r\n";

#[test]
fn records_and_constant_array_sizes_are_read() {
    let m = parse(CELL_DATA);
    let header = m.header.clone().expect("header");
    assert_eq!(
        &CELL_DATA[header],
        "%%%\r\n  VERSION:1\r\n  LANGUAGE:ENGLISH\r\n%%%"
    );
    assert_eq!(m.name, "CellData");
    assert_eq!(m.records.len(), 2);
    let part = m.record("PARTDATA").expect("record by name, any case");
    assert_eq!(part.scope, Scope::Global);
    let fields: Vec<(&str, &str)> = part
        .fields
        .iter()
        .map(|f| (f.type_name.as_str(), f.name.as_str()))
        .collect();
    assert_eq!(
        fields,
        vec![
            ("robtarget", "pPick"),
            ("robtarget", "pPlace"),
            ("num", "nHeight")
        ]
    );
    assert_eq!(part.fields[1].data_type, DataType::RobTarget);
    assert_eq!(part.field("pplace").map(|(k, _)| k), Some(1));
    assert_eq!(&CELL_DATA[part.fields[2].span.clone()], "num nHeight;");
    assert!(CELL_DATA[part.span.clone()].starts_with("RECORD partdata"));
    assert!(CELL_DATA[part.span.clone()].ends_with("ENDRECORD"));
    assert_eq!(part.line, 10);
    let counters = m.record("counters").expect("local record");
    assert_eq!(counters.scope, Scope::Local);
    assert_eq!(counters.fields.len(), 2);
    // A declaration of a record type keeps its value as written.
    let part1 = m.decl("part1").expect("part1");
    assert_eq!(part1.type_name, "partdata");
    assert!(matches!(part1.value, Some(DataValue::Other { .. })));
    let dims = |name: &str| -> Vec<(String, Option<usize>)> {
        m.decl(name)
            .expect(name)
            .dims
            .iter()
            .map(|d| (CELL_DATA[d.span.clone()].to_string(), d.value))
            .collect()
    };
    assert_eq!(dims("buf"), vec![("MAX_BUFFER".to_string(), Some(16))]);
    assert_eq!(
        dims("slots"),
        vec![
            ("nRows * nCols".to_string(), Some(6)),
            ("nCols DIV 2 + (1 - 1)".to_string(), Some(1))
        ]
    );
    assert_eq!(dims("tbl"), vec![("nRows+1".to_string(), Some(4))]);
    // A constant of another module: the size is not known here.
    assert_eq!(dims("other"), vec![("nUnknown".to_string(), None)]);
    assert_eq!(m.moves().count(), 1);
    assert_eq!(apply_edits(CELL_DATA, &[]).expect("no edits"), CELL_DATA);
}

#[test]
fn constant_array_sizes_are_checked_and_errors_located() {
    let e = parse_err("MODULE M\nCONST num N := 2;\nCONST num a{N*2} := [1,2,3];\nENDMODULE\n");
    assert!(
        e.starts_with("t.mod:3:21: array declared with 4 elements has 3"),
        "{e}"
    );
    // A size that is not a constant integer: no value, no check.
    for size in ["N/2", "M", "N+", "2.5", "PERS_N"] {
        let src = format!(
            "MODULE M\nCONST num N := 2;\nPERS num PERS_N := 2;\nCONST num a{{{size}}} := [1,2,3];\nENDMODULE\n"
        );
        let m = parse(&src);
        assert_eq!(m.decl("a").expect("a").dims[0].value, None, "{size}");
    }
    let e = parse_err("MODULE M\nCONST num a{0} := [];\nENDMODULE\n");
    assert!(
        e.starts_with("t.mod:2:13: array size must be at least 1"),
        "{e}"
    );
    // A constant expression that gives a size below 1 is the same error.
    for size in ["N-2", "0-N", "N - 2 * N"] {
        let e = parse_err(&format!(
            "MODULE M\nCONST num N := 2;\nCONST num a{{{size}}} := [1,2,3];\nENDMODULE\n"
        ));
        assert!(
            e.starts_with("t.mod:3:13: array size must be at least 1"),
            "{size}: {e}"
        );
    }
    // Every sub-array has the size its constant gives, not only the first.
    let e =
        parse_err("MODULE M\nCONST num N := 3;\nVAR num g{2, N} := [[1,2,3],[1,2]];\nENDMODULE\n");
    assert!(
        e.starts_with("t.mod:3:29: array declared with 3 elements has 2"),
        "{e}"
    );
    let m =
        parse("MODULE M\nCONST num N := 3;\nVAR num g{2, N} := [[1,2,3],[4,5,6]];\nENDMODULE\n");
    let dims: Vec<Option<usize>> = m
        .decl("g")
        .expect("g")
        .dims
        .iter()
        .map(|d| d.value)
        .collect();
    assert_eq!(dims, vec![Some(2), Some(3)]);
    let e = parse_err("MODULE M\nVAR num a{};\nENDMODULE\n");
    assert!(e.starts_with("t.mod:2:11: expected an array size"), "{e}");
    let e = parse_err("MODULE M\nVAR num a{2;\nENDMODULE\n");
    assert!(e.starts_with("t.mod:2:"), "{e}");
    // Records: a missing ENDRECORD and a field without its `;`.
    let e = parse_err("MODULE M\nRECORD r\n  num a;\nPROC main()\nENDPROC\nENDMODULE\n");
    assert!(
        e.starts_with("t.mod:2:1: unterminated RECORD r: expected ENDRECORD"),
        "{e}"
    );
    let e = parse_err("MODULE M\nRECORD r\n  num a\n  num b;\nENDRECORD\nENDMODULE\n");
    assert!(
        e.starts_with("t.mod:3:8: expected `;` to end the field a"),
        "{e}"
    );
    let e = parse_err("MODULE M\nRECORD\nENDRECORD\nENDMODULE\n");
    assert!(e.starts_with("t.mod:3:1: expected a record name"), "{e}");
}

/// An error handler for a list of error numbers, and compact `IF`s with
/// their statement on the same line or the next, in a socket loop.
#[test]
fn error_lists_and_compact_ifs_are_read() {
    let src = "MODULE PcLink\n  VAR socketdev sock;\n  VAR string msg;\n  PROC serve(bool bHome)\n    WHILE TRUE DO\n      SocketReceive sock \\Str:=msg \\Time:=10;\n      IF msg = \"home\"\n        MoveJ pHome, v1000, fine, tool0;\n      IF bHome AND (msg <> \"\") ! the same, checked twice\n        TPWrite \"home\";\n      IF msg = \"quit\" RETURN;\n    ENDWHILE\n  ERROR (ERR_SOCK_TIMEOUT,\n         ERR_SOCK_CLOSED)\n    SocketClose sock;\n    RETRY;\n  ENDPROC\n  TRAP stop\n    StopMove;\n  ERROR\n    RETURN;\n  ENDTRAP\nENDMODULE\n";
    let m = parse(src);
    let body = &m.procs[0].body;
    let texts: Vec<&str> = body.iter().map(|s| &src[s.span()]).collect();
    assert_eq!(
        texts,
        vec![
            "WHILE TRUE DO",
            "SocketReceive sock \\Str:=msg \\Time:=10;",
            "IF msg = \"home\"\n        MoveJ pHome, v1000, fine, tool0;",
            "IF bHome AND (msg <> \"\") ! the same, checked twice\n        TPWrite \"home\";",
            "IF msg = \"quit\" RETURN;",
            "ENDWHILE",
            "ERROR (ERR_SOCK_TIMEOUT,\n         ERR_SOCK_CLOSED)",
            "SocketClose sock;",
            "RETRY;",
        ]
    );
    // The move of a compact IF is a move, its `IF cond` kept as written.
    let Stmt::Move(mv) = &body[2] else {
        panic!("a move: {:?}", body[2])
    };
    assert_eq!(
        (mv.line, &src[mv.span.clone()]),
        (8, "MoveJ pHome, v1000, fine, tool0;")
    );
    assert_eq!(
        mv.condition.clone().map(|c| &src[c]),
        Some("IF msg = \"home\"")
    );
    assert!(matches!(&body[3], Stmt::Opaque { line: 9, .. }));
    assert_eq!(
        mv.target.span(),
        src.find("pHome").map(|k| k..k + 5).expect("pHome")
    );
    assert_eq!(mv.zone.as_ref().unwrap().text.as_ref(), "fine");
    assert!(matches!(&body[6], Stmt::Control { keyword, line: 13, .. } if keyword == "ERROR"));
    let trap = &m.procs[1].body;
    assert!(matches!(&trap[1], Stmt::Control { keyword, .. } if keyword == "ERROR"));
    // On the IF's line, and under two compact IFs, as well.
    let src = "MODULE M\nPROC a()\n  IF b MoveL p1, v100, z10, tool0;\n  IF x > \"MoveL\" ! MoveL\n    IF y MoveC p2, p3, v100, z10, tool0;\n  IF c TPWrite \"MoveL p\";\nENDPROC\nENDMODULE\n";
    let m = parse(src);
    let moves: Vec<(&str, &str, usize)> = m
        .moves()
        .map(|mv| {
            let cond = mv.condition.clone().expect("in a compact IF");
            (&src[cond], &src[mv.span.clone()], mv.line)
        })
        .collect();
    assert_eq!(
        moves,
        vec![
            ("IF b", "MoveL p1, v100, z10, tool0;", 3),
            (
                "IF x > \"MoveL\" ! MoveL\n    IF y",
                "MoveC p2, p3, v100, z10, tool0;",
                5
            ),
        ]
    );
    assert!(matches!(&m.procs[0].body[2], Stmt::Opaque { line: 6, .. }));
    // A move with too few arguments is an error there too, unless it is
    // unfinished (an editor placeholder).
    let e = parse_err("MODULE M\nPROC a()\n  IF b MoveL p1, v100;\nENDPROC\nENDMODULE\n");
    assert!(e.starts_with("t.mod:3:8: MoveL takes 4 arguments"), "{e}");
    let m = parse("MODULE M\nPROC a()\n  IF b MoveL <ARG>;\nENDPROC\nENDMODULE\n");
    assert!(matches!(&m.procs[0].body[0], Stmt::Opaque { .. }));
    // A compact IF whose next line is not a statement of its own is an error.
    for bad in [
        "MODULE M\nPROC a()\n  IF x\n  ENDPROC\nENDMODULE\n",
        "MODULE M\nPROC a()\n  IF x\n    IF y THEN\n  ENDIF\nENDPROC\nENDMODULE\n",
        "MODULE M\nPROC a()\n  IF x\n    MoveL p, v1, z1;\nENDPROC\nENDMODULE\n",
        "MODULE M\nPROC a()\n  ERROR (ERR_A\nENDPROC\nENDMODULE\n",
    ] {
        let e = parse_err(bad);
        assert!(e.starts_with("t.mod:"), "{e}");
    }
    // The ERROR list is names or integers separated by commas, at least one.
    for (list, at) in [
        ("()", "t.mod:3:10: expected an error number"),
        ("( )", "t.mod:3:11: expected an error number"),
        ("(A B)", "t.mod:3:12: expected `,` or `)` in the ERROR list"),
        ("(A,)", "t.mod:3:12: expected an error number"),
        ("(1A)", "t.mod:3:10: expected an error number"),
        ("(\"A\")", "t.mod:3:10: expected an error number"),
    ] {
        let e = parse_err(&format!(
            "MODULE M\nPROC a()\n  ERROR {list}\n    RETURN;\nENDPROC\nENDMODULE\n"
        ));
        assert!(e.starts_with(at), "{list}: {e}");
    }
    let m = parse("MODULE M\nPROC a()\n  ERROR (41, ERR_A , 7)\n    RETURN;\nENDPROC\nENDMODULE\n");
    assert!(matches!(&m.procs[0].body[0], Stmt::Control { keyword, .. } if keyword == "ERROR"));
    // A `;` in a string of the condition is not the end of the IF.
    let src = "MODULE M\nPROC a()\n  IF msg = \"a;b\"\n    MoveL p1, v100, z10, tool0;\n  RETURN;\nENDPROC\nENDMODULE\n";
    let m = parse(src);
    let texts: Vec<&str> = m.procs[0].body.iter().map(|s| &src[s.span()]).collect();
    assert_eq!(
        texts,
        vec![
            "IF msg = \"a;b\"\n    MoveL p1, v100, z10, tool0;",
            "RETURN;"
        ]
    );
}

/// Editor placeholders are kept byte for byte; a routine holding one is
/// marked and gives no moves; the others are as without it.
#[test]
fn editor_placeholders_mark_their_routine() {
    let md = grammar();
    let src = fenced_blocks(&md, "rapid")
        .into_iter()
        .find(|b| b.contains("MODULE Unfinished"))
        .expect("the placeholder example");
    let m = parse(&src);
    let marked: Vec<(&str, bool)> = m
        .procs
        .iter()
        .map(|p| (p.name.as_str(), p.placeholder))
        .collect();
    assert_eq!(
        marked,
        vec![("pick", true), ("place", false), ("<ID>", true)]
    );
    assert_eq!(m.placeholders.len(), 1);
    assert_eq!(&src[m.placeholders[0].clone()], "<DDN>");
    assert_eq!(m.decl("<ID>").map(|d| d.type_name.as_str()), Some("num"));
    // Only the finished routine's move is a move to compensate.
    let moves: Vec<&str> = m.moves().map(|mv| &src[mv.span.clone()]).collect();
    assert_eq!(moves, vec!["MoveL pPlace, v500, fine, tool0;"]);
    let pick = &m.procs[0].body;
    let texts: Vec<&str> = pick.iter().map(|s| &src[s.span()]).collect();
    assert_eq!(
        texts,
        vec![
            "MoveL pApproach, v500, z10, tool0;",
            "<SMT>",
            "IF <EXP> THEN",
            "<SMT>",
            "<EIT>",
            "ENDIF",
            "MoveL <EXP>, v100, fine, tool0;",
        ]
    );
    // The moves are still in the tree of the marked routine.
    assert_eq!(
        pick.iter().filter(|s| matches!(s, Stmt::Move(_))).count(),
        2
    );
    // A placeholder in a comment or a string is text, not a placeholder;
    // an unfinished move with too few arguments is kept as written.
    let src = "MODULE M\n  PROC a()\n    ! <SMT> still to do\n    TPWrite \"<EXP>\";\n    MoveL p1, v100, z10, tool0;\n  ENDPROC\n  PROC b()\n    MoveL <ARG>;\n    <SMT>;\n  ENDPROC\nENDMODULE\n";
    let m = parse(src);
    assert!(!m.procs[0].placeholder);
    assert!(m.procs[1].placeholder);
    assert_eq!(m.moves().count(), 1);
    assert_eq!(&src[m.procs[1].body[0].span()], "MoveL <ARG>;");
    assert_eq!(&src[m.procs[1].body[1].span()], "<SMT>;");
    // A function whose type and name are still to be given.
    let m = parse("MODULE M\n  FUNC <ID> <ID>(<PAR>)\n    RETURN <EXP>;\n  ENDFUNC\nENDMODULE\n");
    assert!(m.procs[0].placeholder);
    // Not placeholders: lower case, unknown names; an unfinished move
    // without one is still an error.
    let e = parse_err("MODULE M\nPROC a()\n  <smt>\nENDPROC\nENDMODULE\n");
    assert!(e.starts_with("t.mod:3:"), "{e}");
    let e = parse_err("MODULE M\nPROC a()\n  MoveL p1;\nENDPROC\nENDMODULE\n");
    assert!(e.starts_with("t.mod:3:3: MoveL takes 4 arguments"), "{e}");
}

/// Deep chains of compact IFs, and long runs of signs or parentheses in
/// array sizes, are errors or unknown sizes, not a crash.
#[test]
fn deep_compact_ifs_and_sizes_do_not_crash() {
    let ifs = format!(
        "MODULE M\nPROC main()\n{}  MoveL p1, v100, z10, tool0;\nENDPROC\nENDMODULE\n",
        "  IF a\n".repeat(100_000)
    );
    assert!(parse_err(&ifs).starts_with("t.mod:"));
    let two = "MODULE M\nPROC main()\n  IF a\n  IF b\n  MoveL p1, v100, z10, tool0;\nENDPROC\nENDMODULE\n";
    assert_eq!(parse(two).procs[0].body.len(), 1);
    for size in [
        "-".repeat(100_000) + "1",
        "(".repeat(100_000) + "1" + &")".repeat(100_000),
    ] {
        let src = format!("MODULE M\nVAR num a{{{size}}};\nENDMODULE\n");
        match parse_module(&src, "t.mod") {
            Ok(m) => assert_eq!(m.decls[0].dims[0].value, None),
            Err(e) => assert!(e.to_string().starts_with("t.mod:2:"), "{e}"),
        }
    }
}

/// One call of each motion instruction of the table, its arguments named
/// after their roles, with the role names it must parse to.
#[test]
fn every_motion_instruction_of_the_table_parses_its_roles() {
    use postproc::program::rapid::instructions::{MOTION_INSTRUCTIONS, Role};
    for instr in MOTION_INSTRUCTIONS {
        let args: Vec<String> = instr
            .args
            .iter()
            .enumerate()
            .map(|(k, r)| match r {
                Role::CirPoint => "pCir".to_string(),
                Role::ToPoint => "pTo".to_string(),
                Role::Speed => "vS".to_string(),
                Role::Zone => "zZ".to_string(),
                Role::Tool => "tT".to_string(),
                Role::Other(_) => format!("other{k}"),
            })
            .collect();
        let call = format!("{} {}\\WObj:=wW;", instr.name, args.join(", "));
        let src = format!("MODULE M\nPROC main()\n  {call}\nENDPROC\nENDMODULE\n");
        let m = parse(&src);
        let mv = m.moves().next().unwrap_or_else(|| panic!("{call}: a move"));
        assert_eq!(mv.name, instr.name);
        assert_eq!(mv.kind, instr.kind, "{call}");
        assert_eq!(&src[mv.span.clone()], call);
        let named = |t: &Target| match t {
            Target::Named { name, .. } => name.clone(),
            other => panic!("{call}: {other:?}"),
        };
        assert_eq!(named(&mv.target), "pTo", "{call}");
        assert_eq!(
            mv.via.as_deref().map(named),
            instr.position(Role::CirPoint).map(|_| "pCir".to_string())
        );
        assert_eq!(&*mv.speed.text, "vS", "{call}");
        assert_eq!(&*mv.tool.text, "tT", "{call}");
        let zone = mv.zone.as_ref().map(|z| z.text.to_string());
        let want = instr.position(Role::Zone).map(|_| "zZ".to_string());
        assert_eq!(zone, want, "{call}");
        assert_eq!(mv.wobj.as_ref().map(|a| &*a.text), Some("wW"));
        // Lower case is the same instruction.
        let lower = src.to_lowercase();
        let m = parse(&lower);
        let mv = m.moves().next().expect("a move");
        assert_eq!(mv.name, instr.name);
        // One positional argument short is an error naming the signature;
        // for an instruction written otherwise by other versions of its
        // process package, an opaque statement named as not compensated.
        let short = format!(
            "MODULE M\nCONST robtarget pTo := {RT};\nPROC main()\n  {} {};\nENDPROC\nENDMODULE\n",
            instr.name,
            args[..args.len() - 1].join(", ")
        );
        if instr.other_forms {
            let m = parse(&short);
            assert_eq!(m.moves().count(), 0, "{short}");
            let named: Vec<_> = m
                .unknown_motions(&short)
                .into_iter()
                .map(|u| (u.name, u.line))
                .collect();
            assert_eq!(named, [(instr.name.to_string(), 4)], "{short}");
        } else {
            let said = parse_err(&short);
            assert!(said.contains(&instr.signature()), "{said}");
        }
    }
}

/// A robtarget literal for the declarations of the tests of this file.
const RT: &str = "[[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]";

#[test]
fn motion_instructions_keep_their_name_and_move_like_their_kind() {
    let src = "MODULE M\nPROC main()\n  MoveLDO p1, v100, z1, tool1, do1, 1;\n  TriggL p2, v100, trOn \\T2:=trOff, z1, tool1;\n  TriggC \\Conc, c3, p3, v100, trOn, fine, tool1;\n  SearchL \\Stop, diTouch, pFound, p4, v20, tool1;\n  SearchC \\SStop, diTouch, pFound, c5, p5, v20, tool1;\n  ArcLStart p6, v100, seam1, weld1\\Weave:=weave1, fine, tool1;\n  ArcC c7, p7, v100, seam1, weld1, z1, tool1;\n  MoveJSync p8, v100, z1, tool1, \"proc1\";\n  IF bOn MoveCDO c9, p9, v100, z1, tool1, do1, 0;\nENDPROC\nENDMODULE\n";
    let m = parse(src);
    let got: Vec<(&str, MoveKind, String, Option<String>)> = m
        .moves()
        .map(|mv| {
            let name = |t: &Target| src[t.span()].to_string();
            (
                mv.name,
                mv.kind,
                name(&mv.target),
                mv.via.as_deref().map(name),
            )
        })
        .collect();
    let c = |s: &str| Some(s.to_string());
    let want = vec![
        ("MoveLDO", MoveKind::MoveL, "p1".to_string(), None),
        ("TriggL", MoveKind::MoveL, "p2".to_string(), None),
        ("TriggC", MoveKind::MoveC, "p3".to_string(), c("c3")),
        ("SearchL", MoveKind::MoveL, "p4".to_string(), None),
        ("SearchC", MoveKind::MoveC, "p5".to_string(), c("c5")),
        ("ArcLStart", MoveKind::MoveL, "p6".to_string(), None),
        ("ArcC", MoveKind::MoveC, "p7".to_string(), c("c7")),
        ("MoveJSync", MoveKind::MoveJ, "p8".to_string(), None),
        ("MoveCDO", MoveKind::MoveC, "p9".to_string(), c("c9")),
    ];
    assert_eq!(got, want);
    let moves: Vec<_> = m.moves().collect();
    assert!(moves[1].opt("T2").is_some());
    assert!(moves[2].conc);
    assert!(moves[5].opt("Weave").is_some());
    assert!(moves[8].condition.is_some());
    // Words that only start like a motion instruction stay opaque.
    let other = "MODULE M\nPROC main()\n  MoveLDOx p1, v100, z1, tool1;\n  ArcLStartup;\nENDPROC\nENDMODULE\n";
    assert_eq!(parse(other).moves().count(), 0);
}

/// The motion instruction table of grammar/rapid.md is the parser's, row
/// for row, and its example parses to the moves it describes.
#[test]
fn grammar_motion_table_is_the_parsers() {
    use postproc::program::rapid::instructions::MOTION_INSTRUCTIONS;
    let md = grammar();
    let rows: Vec<&str> = md
        .lines()
        .skip_while(|l| !l.starts_with("### Motion instructions"))
        .filter(|l| l.starts_with("| `"))
        .take_while(|l| l.contains("` | "))
        .collect();
    assert_eq!(rows.len(), MOTION_INSTRUCTIONS.len(), "{rows:#?}");
    for (row, instr) in rows.iter().zip(MOTION_INSTRUCTIONS) {
        let kind = match instr.kind {
            MoveKind::MoveL => "linear",
            MoveKind::MoveJ => "joint",
            MoveKind::MoveC => "circular",
            MoveKind::MoveAbsJ => "absolute-joint",
        };
        let want = format!("| `{}` | {kind} | `{}` |", instr.name, instr.signature());
        assert_eq!(*row, want);
    }
    let example = fenced_blocks(&md, "rapid")
        .into_iter()
        .find(|b| b.contains("MODULE Process"))
        .expect("the process example");
    let m = parse(&example);
    let got: Vec<_> = m
        .moves()
        .map(|mv| {
            let zone = mv.zone.as_ref().map(|z| z.text.to_string());
            let via = mv.via.as_deref().map(|t| example[t.span()].to_string());
            (
                mv.name,
                mv.kind,
                example[mv.target.span()].to_string(),
                via,
                zone,
            )
        })
        .collect();
    let s = |x: &str| Some(x.to_string());
    let want = vec![
        ("MoveLDO", MoveKind::MoveL, "p10".into(), None, s("z5")),
        ("TriggL", MoveKind::MoveL, "p20".into(), None, s("z1")),
        ("ArcLStart", MoveKind::MoveL, "p30".into(), None, s("fine")),
        ("ArcC", MoveKind::MoveC, "p40".into(), s("p35"), s("z1")),
        ("ArcLEnd", MoveKind::MoveL, "p50".into(), None, s("fine")),
        ("SearchL", MoveKind::MoveL, "p60".into(), None, None),
        ("MoveJSync", MoveKind::MoveJ, "p70".into(), None, s("z50")),
    ];
    assert_eq!(got, want);
    let first = m.moves().next().expect("a move");
    assert_eq!((&*first.speed.text, &*first.tool.text), ("v200", "tool1"));
}

/// The spot-welding example of grammar/rapid.md parses to the moves it
/// describes; the older form of `SpotL` and the `PaintL` stay opaque.
#[test]
fn grammar_spot_example_is_the_parsers() {
    let md = grammar();
    let example = fenced_blocks(&md, "rapid")
        .into_iter()
        .find(|b| b.contains("MODULE Spot"))
        .expect("the spot example");
    let m = parse(&example);
    let got: Vec<_> = m
        .moves()
        .map(|mv| {
            let zone = mv.zone.as_ref().map(|z| z.text.to_string());
            let target = example[mv.target.span()].to_string();
            (mv.name, mv.kind, target, zone, mv.tool.text.to_string())
        })
        .collect();
    let s = |x: &str| x.to_string();
    let want = vec![
        (
            "MoveJ",
            MoveKind::MoveJ,
            s("pApp"),
            Some(s("z50")),
            s("tGun"),
        ),
        ("SpotL", MoveKind::MoveL, s("pWeld1"), None, s("tGun")),
        ("SpotJ", MoveKind::MoveJ, s("pWeld2"), None, s("tGun")),
        (
            "MoveL",
            MoveKind::MoveL,
            s("pApp"),
            Some(s("fine")),
            s("tGun"),
        ),
    ];
    assert_eq!(got, want);
    let spot = m.moves().nth(1).expect("SpotL");
    assert_eq!(&*spot.speed.text, "vmax");
    assert_eq!(
        spot.opt("GunD")
            .and_then(|o| o.value.as_ref())
            .map(|a| &*a.text),
        Some("gunData1")
    );
    assert_eq!(spot.wobj.as_ref().map(|a| &*a.text), Some("wCar"));
    let opaque: Vec<&str> = m.procs[0]
        .body
        .iter()
        .filter_map(|st| match st {
            Stmt::Opaque { span, .. } => {
                Some(example[span.clone()].split(' ').next().unwrap_or(""))
            }
            _ => None,
        })
        .collect();
    assert_eq!(opaque, ["SpotL", "PaintL"]);
}

/// `SpotL` and `SpotJ` parse their roles as the row of the table says —
/// the gun data (with `\GunD`) and the spot data kept as written, no zone
/// — in any case, with `\Conc` first, inline targets and `Offs`; a form
/// with other positional arguments stays opaque, in a compact `IF` too.
#[test]
fn spot_instructions_parse_the_roles_of_their_row() {
    let src = format!(
        "MODULE M\n  CONST robtarget p10 := {RT};\n  PROC main()\n    SpotL p10, vmax, gun1\\GunD:=gd1, spot10, tGun\\WObj:=wCar;\n    spotj \\Conc, Offs(p10, 0, 0, 5), v1500, gun1, spot20, tGun;\n    SPOTL {RT}, v200, gun2, spot30, tGun\\WObj:=wCar\\TLoad:=load1;\n    SpotL p10, vmax, spot10\\InPos\\NoConc, tGun;\n    IF bWeld SpotJ p10, vmax, spot10, tGun;\n    IF bWeld SpotJ p10, vmax, gun1, spot10, tGun;\n  ENDPROC\nENDMODULE\n"
    );
    let m = parse(&src);
    let moves: Vec<_> = m.moves().collect();
    let got: Vec<_> = moves
        .iter()
        .map(|mv| {
            (
                mv.name,
                mv.kind,
                src[mv.target.span()].to_string(),
                mv.speed.text.to_string(),
                mv.zone.is_some(),
                mv.tool.text.to_string(),
                mv.line,
            )
        })
        .collect();
    let s = |x: &str| x.to_string();
    let want = vec![
        (
            "SpotL",
            MoveKind::MoveL,
            s("p10"),
            s("vmax"),
            false,
            s("tGun"),
            4,
        ),
        (
            "SpotJ",
            MoveKind::MoveJ,
            s("Offs(p10, 0, 0, 5)"),
            s("v1500"),
            false,
            s("tGun"),
            5,
        ),
        (
            "SpotL",
            MoveKind::MoveL,
            s(RT),
            s("v200"),
            false,
            s("tGun"),
            6,
        ),
        (
            "SpotJ",
            MoveKind::MoveJ,
            s("p10"),
            s("vmax"),
            false,
            s("tGun"),
            9,
        ),
    ];
    assert_eq!(got, want);
    assert!(moves[0].opt("GunD").is_some());
    assert!(moves[1].conc);
    assert_eq!(moves[2].tload.as_ref().map(|a| &*a.text), Some("load1"));
    assert!(moves[3].condition.is_some());
    assert!(matches!(m.procs[0].body[3], Stmt::Opaque { line: 7, .. }));
    assert!(matches!(m.procs[0].body[4], Stmt::Opaque { line: 8, .. }));
    let named: Vec<_> = m
        .unknown_motions(&src)
        .into_iter()
        .map(|u| (u.name, u.line))
        .collect();
    assert_eq!(named, [(s("SpotL"), 7)]);
    // A malformed call of the row's form is still an error.
    let bad = "MODULE M\nPROC main()\n  SpotL p10, vmax, gun1, spot10, tGun\nENDPROC\nENDMODULE\n";
    assert!(parse_err(bad).starts_with("t.mod:"), "{}", parse_err(bad));
}

#[test]
fn motion_like_statements_to_declared_robtargets_are_listed() {
    let src = "MODULE M\n  CONST robtarget p10 := [[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n  PROC main()\n    VAR robtarget pLocal;\n    CapL p10, v100, cd1, ws1, wv1, z1, tool1;\n    PaintL pLocal, v100, z1, tool1;\n    DispL pOther, v100, bead1, z1, tool1;\n    MoveL p10, v100, z1, tool1;\n    MoveExtJ jt1, v100, fine;\n    TPWrite \"PaintL p10\";\n    MoveLx := p10;\n    SearchJ \\Stop, di1, pLocal, p10, v100, tool1;\n    SpotL p10, vmax, gun1, spot1, tool1;\n    SpotL p10, vmax, spot1, tool1;\n    dispL \\On, p10, v100, bead1, z1, tool1;\n  ENDPROC\nENDMODULE\n";
    let m = parse(src);
    let got: Vec<(String, usize)> = m
        .unknown_motions(src)
        .into_iter()
        .map(|u| (u.name, u.line))
        .collect();
    // The SpotL of its table row (line 13) is a move, the older form
    // (line 14) is named.
    let want = [
        ("CapL", 5),
        ("PaintL", 6),
        ("SearchJ", 12),
        ("SpotL", 14),
        ("dispL", 15),
    ]
    .map(|(n, l)| (n.to_string(), l));
    assert_eq!(got, want);
    let moves: Vec<_> = m.moves().map(|mv| (mv.name, mv.line)).collect();
    assert_eq!(moves, [("MoveL", 8), ("SpotL", 13)]);
    // The modules of the grammar examples and the samples hold none.
    for name in ["samples/drilling.mod", "samples/milling.mod"] {
        let text = std::fs::read_to_string(repo(name)).expect("sample");
        assert!(parse(&text).unknown_motions(&text).is_empty(), "{name}");
    }
}

/// Assignments are typed statements: the name, an index or a component,
/// and the value read as a target expression; one inside a compact `IF`
/// stays opaque, and the text is kept byte for byte.
#[test]
fn assignments_are_typed_statements() {
    let src = "MODULE A\n  PROC main()\n    pV := Offs(pBase, 0, 0, nLift);\n    buf{i} := CRobT(\\Tool:=tool1);\n    pV.trans.z := 5;\n    bOk := StrToVal(sData, pRecv);\n    n := n + 1;\n    pV := [[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n    IF bOk pV := pBase;\n  ENDPROC\nENDMODULE\n";
    let m = parse(src);
    let body = &m.procs[0].body;
    let assigns: Vec<_> = body
        .iter()
        .filter_map(|s| match s {
            Stmt::Assign(a) => Some(a.as_ref()),
            _ => None,
        })
        .collect();
    assert_eq!(assigns.len(), 6);
    assert!(matches!(body[6], Stmt::Opaque { line: 9, .. }));
    let a = assigns[0];
    assert_eq!((a.name.as_str(), a.line, a.component), ("pV", 3, false));
    let Target::Offs { base, offsets, .. } = &a.value else {
        panic!("{:?}", a.value)
    };
    assert!(matches!(base.as_ref(), Target::Named { name, .. } if name == "pBase"));
    assert_eq!(offsets[2].text, "nLift");
    let b = assigns[1];
    assert_eq!(b.index.as_ref().map(|i| i.text.as_str()), Some("i"));
    assert!(matches!(&b.value, Target::Other { text, .. } if text == "CRobT(\\Tool:=tool1)"));
    assert!(assigns[2].component);
    assert!(
        matches!(&assigns[3].value, Target::Other { text, .. } if text.starts_with("StrToVal("))
    );
    assert!(matches!(&assigns[4].value, Target::Other { text, .. } if text == "n + 1"));
    assert!(matches!(&assigns[5].value, Target::Inline(_)));
    for s in body {
        let span = s.span();
        assert_eq!(src.as_bytes()[span.end - 1], b';', "{:?}", &src[span]);
    }
}
