//! Integration tests: the names and bytes a compensation adds to a program
//! are ones its controller loads. A new target is a `LOCAL CONST` of at
//! most 32 characters that takes no name of a routine, record type or
//! module of the program, so modules compensated side by side never
//! declare the same global name; a file that opens with a UTF-8
//! byte-order mark keeps it first, the provenance header after it.

use crate::common::{postproc, write};

/// A tool of the samples' kind (TCP 182.5 mm along the flange z axis).
/// A second tool, 20 mm longer: a move with it to the same target needs a
/// copy.
const TOOL: &str = "  PERS tooldata tSp := [TRUE,[[0,0,182.5],[1,0,0,0]],[2.4,[0,0,85],[1,0,0,0],0,0,0]];\n  PERS tooldata tLong := [TRUE,[[0,0,202.5],[1,0,0,0]],[2.4,[0,0,85],[1,0,0,0],0,0,0]];\n";

/// A target 700 mm in front of the IRB 1600, tool pointing down.
fn target(name: &str) -> String {
    format!(
        "  CONST robtarget {name} := [[700,0,400],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n"
    )
}

/// The identifiers a module declares at its left: `LOCAL CONST robtarget
/// NAME`, `PROC NAME(`, … (the second or third word of a declaration line).
fn declared(text: &str) -> Vec<String> {
    text.lines()
        .filter_map(|l| {
            let words: Vec<&str> = l.split_whitespace().collect();
            let w = match words.as_slice() {
                ["LOCAL", "CONST", _, n, ..] | ["CONST", _, n, ..] | ["PERS", _, n, ..] => *n,
                ["PROC", n, ..] | ["LOCAL", "PROC", n, ..] => n.split('(').next().unwrap_or(n),
                _ => return None,
            };
            Some(w.to_ascii_lowercase())
        })
        .collect()
}

#[test]
fn copies_in_two_modules_of_a_program_are_local_to_each() {
    let dir = tempfile::tempdir().expect("dir");
    write(
        dir.path(),
        "Data.mod",
        &format!("MODULE Data\n{TOOL}{}ENDMODULE\n", target("p10")),
    );
    for m in ["A", "B"] {
        write(
            dir.path(),
            &format!("{m}.mod"),
            &format!(
                "MODULE {m}\n  PROC run{m}()\n    MoveL p10, v100, fine, tSp;\n  ENDPROC\nENDMODULE\n"
            ),
        );
    }
    let out = dir.path().join("out");
    postproc()
        .current_dir(dir.path())
        .args([
            "compensate",
            "Data.mod",
            "A.mod",
            "B.mod",
            "--machine",
            "abb-irb1600",
        ])
        .arg("--out-dir")
        .arg(&out)
        .assert()
        .success();
    for m in ["A", "B"] {
        let text = std::fs::read_to_string(out.join(format!("{m}.mod"))).expect("written");
        let copies: Vec<&str> = text
            .lines()
            .filter(|l| l.contains("robtarget p10_"))
            .collect();
        assert_eq!(copies.len(), 1, "{text}");
        assert!(
            copies[0]
                .trim_start()
                .starts_with("LOCAL CONST robtarget p10_c"),
            "{text}"
        );
    }
}

#[test]
fn a_new_name_takes_no_routine_or_module_name_of_the_program() {
    let dir = tempfile::tempdir().expect("dir");
    // The module's own routine p1_c2, and another module's global routine
    // p1_o1 and module p1_c3.
    write(
        dir.path(),
        "A.mod",
        &format!(
            "MODULE A\n{TOOL}{}  PROC main()\n    MoveL p1, v100, fine, tSp;\n    MoveL p1, v100, fine, tLong;\n    MoveL Offs(p1, 0, 0, 50), v100, fine, tSp;\n    p1_c2;\n  ENDPROC\n  PROC p1_c2()\n  ENDPROC\nENDMODULE\n",
            target("p1")
        ),
    );
    write(
        dir.path(),
        "B.sys",
        "MODULE p1_c3(SYSMODULE)\n  PROC p1_o1()\n  ENDPROC\nENDMODULE\n",
    );
    let out = dir.path().join("out");
    postproc()
        .current_dir(dir.path())
        .args(["compensate", "A.mod", "B.sys", "--machine", "abb-irb1600"])
        .arg("--out-dir")
        .arg(&out)
        .assert()
        .success();
    let a = std::fs::read_to_string(out.join("A.mod")).expect("written");
    let names = declared(&a);
    let mut unique = names.clone();
    unique.sort();
    unique.dedup();
    assert_eq!(unique.len(), names.len(), "a name declared twice:\n{a}");
    for taken in ["p1_c2", "p1_c3", "p1_o1"] {
        assert!(
            !a.lines()
                .any(|l| l.contains(&format!("robtarget {taken} "))),
            "{taken} given to a target:\n{a}"
        );
    }
    // The copies exist, under the next free names.
    assert!(a.contains("LOCAL CONST robtarget p1_c4 :="), "{a}");
    assert!(a.contains("LOCAL CONST robtarget p1_o2 :="), "{a}");
}

#[test]
fn a_new_name_stays_within_32_characters() {
    let dir = tempfile::tempdir().expect("dir");
    let long = "Target_Entgraten_Kontur_Aussen_1";
    assert_eq!(long.len(), 32);
    let module = write(
        dir.path(),
        "Long.mod",
        &format!(
            "MODULE Long\n{TOOL}{}  PROC main()\n    MoveL {long}, v100, fine, tSp;\n    MoveL {long}, v100, fine, tLong;\n    MoveL Offs({long}, 0, 0, 50), v100, fine, tSp;\n  ENDPROC\nENDMODULE\n",
            target(long)
        ),
    );
    let out = postproc()
        .args(["compensate", "--machine", "abb-irb1600", "-o", "-"])
        .arg(&module)
        .assert()
        .success();
    let text = String::from_utf8(out.get_output().stdout.clone()).expect("utf-8");
    let added: Vec<String> = declared(&text)
        .into_iter()
        .filter(|n| n.starts_with("target_entgraten_kontur_aussen") && n.len() != 32)
        .collect();
    assert_eq!(added.len(), 0, "{text}");
    let new: Vec<&str> = text
        .lines()
        .filter(|l| l.trim_start().starts_with("LOCAL CONST robtarget"))
        .collect();
    assert_eq!(new.len(), 2, "a copy and an Offs value:\n{text}");
    for l in new {
        let name = l.split_whitespace().nth(3).expect("name");
        assert!(name.len() <= 32, "{name}");
        assert!(text.contains(&format!("MoveL {name},")), "{text}");
    }
}

#[test]
fn a_byte_order_mark_stays_first_in_both_languages() {
    let dir = tempfile::tempdir().expect("dir");
    let bom = "\u{feff}";
    let rapid = write(
        dir.path(),
        "Bom.mod",
        &format!(
            "{bom}MODULE Bom\r\n{TOOL}{}  PROC main()\r\n    MoveL p1, v100, fine, tSp;\r\n  ENDPROC\r\nENDMODULE\r\n",
            target("p1")
        ),
    );
    let gcode = write(
        dir.path(),
        "bom.nc",
        &format!(
            "{bom}%\r\nO1001\r\nG90 G54 G0 X100. Y100. Z50.\r\nG1 X200. F1000.\r\nM30\r\n%\r\n"
        ),
    );
    for (input, machine, first) in [
        (&rapid, "abb-irb1600", "MODULE Bom\r\n"),
        (&gcode, "afm-r1000", "%\r\nO1001\r\n"),
    ] {
        let out = postproc()
            .args(["compensate", "--machine", machine, "-o", "-"])
            .arg(input)
            .args(["--effects", "none", "--annotate", "none"])
            .assert()
            .success();
        let text = String::from_utf8(out.get_output().stdout.clone()).expect("utf-8");
        let body = text.strip_prefix(bom).expect("the mark first");
        assert!(body.starts_with(first), "{text}");
        assert!(!body.contains(bom), "{text}");
        let original = std::fs::read_to_string(input).expect("input");
        assert_eq!(
            crate::common::text_without_header(body),
            original.strip_prefix(bom).expect("mark"),
        );
    }
}
