//! Integration tests: files in robot and control languages postproc does
//! not read (FANUC TP other than a `.ls`, Yaskawa JBI, URScript, Stäubli
//! VAL3, native Siemens 840D, Heidenhain conversational; KUKA KRL other
//! than a `.src`) get one
//! message naming their language at `check`, `compensate`, `report` and
//! `batch`, exit 2; a KRL `DEF MAIN()` is never taken for Siemens 840D, and
//! a KRL `.src` is read. The programs are
//! written here in the style of each language's real files.

use std::path::Path;

use crate::common::{postproc, write};

/// One program per language: file name, text, the language the message
/// names, and the line it quotes (`None`: told by the extension).
const PROGRAMS: &[(&str, &str, &str, Option<&str>)] = &[
    (
        "pallet.dat",
        "&ACCESS RVP\r\n&REL 12\r\nDEFDAT  pallet\r\nDECL E6POS XP1={X 812.5,Y -140.0,Z 655.0,A 180.0,B 0.0,C 180.0,S 2,T 35,E1 0.0}\r\nENDDAT\r\n",
        "KUKA KRL",
        Some("&ACCESS RVP"),
    ),
    (
        "WELD01.JBI",
        "/JOB\r\n//NAME WELD01\r\n//POS\r\n///NPOS 2,0,0,0,0,0\r\n///TOOL 0\r\n///POSTYPE PULSE\r\n///PULSE\r\nC00000=0,0,0,0,0,0\r\nC00001=1200,-3400,2100,0,-1500,0\r\n//INST\r\n///DATE 2024/05/14 09:30\r\n///ATTR SC,RW\r\n///GROUP1 RB1\r\nNOP\r\nMOVJ C00000 VJ=20.00\r\nMOVL C00001 V=80.0\r\nEND\r\n",
        "Yaskawa JBI",
        Some("/JOB"),
    ),
    (
        "pick.script",
        "def pick_part():\n  set_tcp(p[0.0, 0.0, 0.145, 0.0, 0.0, 0.0])\n  movej([0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0], a=1.4, v=1.05)\n  movel(p[0.42, -0.11, 0.23, 0.0, 3.1416, 0.0], a=1.2, v=0.25)\nend\n",
        "Universal Robots URScript",
        Some("def pick_part():"),
    ),
    (
        "start.pgx",
        "<?xml version=\"1.0\" encoding=\"utf-8\"?>\r\n<Programs xmlns:xsi=\"http://www.w3.org/2001/XMLSchema-instance\" xmlns=\"http://www.staubli.com/robotics/VAL3/Program/2\">\r\n  <Program name=\"start\">\r\n    <Code><![CDATA[begin\r\n  movej(jApproach, tGripper, mFast)\r\n  waitEndMove()\r\nend]]></Code>\r\n  </Program>\r\n</Programs>\r\n",
        "Stäubli VAL3",
        Some("<?xml version=\"1.0\" encoding=\"utf-8\"?>"),
    ),
    (
        "POCKET.MPF",
        "; pocket, 840D sl\nN10 G17 G90 G54\nN20 T=\"CUTTER_10\" M6\nN30 DEF REAL DEPTH=-5\nN40 G0 X0 Y0 Z50\nN50 M30\n",
        "Siemens 840D",
        Some("N30 DEF REAL DEPTH=-5"),
    ),
    (
        "contour.spf",
        "PROC CONTOUR(REAL DEPTH)\nN10 G1 Z=DEPTH F200\nN20 X40 Y0\nRET\n",
        "Siemens 840D",
        Some("PROC CONTOUR(REAL DEPTH)"),
    ),
    (
        "PLATE.H",
        "0 BEGIN PGM PLATE MM\n1 BLK FORM 0.1 Z X+0 Y+0 Z-20\n2 BLK FORM 0.2 X+100 Y+100 Z+0\n3 TOOL CALL 1 Z S5000\n4 L Z+100 R0 FMAX M3\n5 L X+10 Y+10 R0 FMAX\n6 END PGM PLATE MM\n",
        "Heidenhain conversational",
        Some("0 BEGIN PGM PLATE MM"),
    ),
    // Named by the extension alone: a binary TP program.
    ("drop.tp", "\u{1}\u{0}\u{7f}TPBIN", "FANUC TP", None),
];

/// Runs `postproc args…`: exit code, standard output, standard error.
fn run(args: &[&str]) -> (i32, String, String) {
    let out = postproc().args(args).output().expect("runs");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Checks the message of `path` names `lang` (and quotes `line`), on one
/// line, as `file:line:1: …` or `file: …`.
fn assert_named(err: &str, path: &Path, lang: &str, line: Option<&str>, what: &str) {
    let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(lines.len(), 1, "{what}: one message, got {err}");
    let msg = lines[0];
    assert!(msg.contains(&path.display().to_string()), "{what}: {msg}");
    assert!(msg.contains(lang), "{what}: names {lang}: {msg}");
    let told = if lang == "KUKA KRL" {
        "postproc reads a KRL program from its .src"
    } else if lang == "FANUC TP" {
        "postproc reads a TP program in its ASCII form, a .ls file"
    } else {
        "a language postproc does not read"
    };
    assert!(msg.contains(told), "{what}: {msg}");
    match line {
        Some(l) => assert!(
            msg.contains(&format!("(`{l}`)")),
            "{what}: quotes {l}: {msg}"
        ),
        None => assert!(msg.contains("file)"), "{what}: by its extension: {msg}"),
    }
}

#[test]
fn check_compensate_and_report_name_each_unread_language() {
    let dir = tempfile::tempdir().unwrap();
    for (name, text, lang, line) in PROGRAMS {
        let path = write(dir.path(), name, text);
        let p = path.to_str().unwrap();
        let out = dir.path().join(format!("{name}.out"));
        let o = out.to_str().unwrap();
        // A robot and a machine tool: the language is told before either.
        for machine in ["abb-irb4600-2.05", "afm-r1000"] {
            for args in [
                vec!["check", p, "--machine", machine],
                vec!["compensate", p, "--machine", machine, "-o", o],
                vec!["report", p, "--machine", machine],
            ] {
                let (code, stdout, err) = run(&args);
                let what = format!("{} {name} on {machine}", args[0]);
                assert_eq!(code, 2, "{what}: {err}");
                assert_eq!(stdout, "", "{what}");
                assert_named(&err, &path, lang, *line, &what);
                assert!(!out.exists(), "{what}: no output written");
            }
        }
        // Without a machine file too.
        let (code, _, err) = run(&["check", p]);
        assert_eq!(code, 2, "check {name}: {err}");
        assert_named(&err, &path, lang, *line, &format!("check {name}"));
    }
}

/// The two `DEF MAIN()` files of the issue: KUKA KRL, never Siemens 840D,
/// whatever their extension; a Siemens `DEF REAL` is Siemens.
#[test]
fn a_krl_def_main_is_never_taken_for_siemens() {
    let dir = tempfile::tempdir().unwrap();
    let krl = "DEF MAIN()\n  INI\n  PTP HOME Vel=100 % DEFAULT\nEND\n";
    // A `.src` is read as KRL.
    let path = write(dir.path(), "main.src", krl);
    let (code, out, err) = run(&["check", path.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    assert!(
        out.contains("KRL program, 1 motion (0 targets, 0 joint targets, 1 left as written)"),
        "{out}"
    );
    assert!(!err.contains("Siemens"), "{err}");
    for name in ["MAIN", "main.txt", "main.nc", "main.mpf"] {
        let path = write(dir.path(), name, krl);
        let (code, _, err) = run(&["check", path.to_str().unwrap(), "--machine", "afm-r1000"]);
        assert_eq!(code, 2, "{name}: {err}");
        assert_named(&err, &path, "KUKA KRL", Some("DEF MAIN()"), name);
        assert!(!err.contains("Siemens"), "{name}: {err}");
    }
    // A `DEF MAIN()` further down a G-code file: the G-code reader names
    // KRL at that line.
    let path = write(dir.path(), "late.nc", "G0 X0 Y0\nDEF MAIN()\n");
    let (code, _, err) = run(&["check", path.to_str().unwrap(), "--machine", "afm-r1000"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains(":2:") && err.contains("KUKA KRL"), "{err}");
    assert!(!err.contains("Siemens"), "{err}");
    let path = write(dir.path(), "depth.txt", "DEF REAL DEPTH=5\nG0 X0\n");
    let (code, _, err) = run(&["check", path.to_str().unwrap(), "--machine", "afm-r1000"]);
    assert_eq!(code, 2, "{err}");
    assert_named(
        &err,
        &path,
        "Siemens 840D",
        Some("DEF REAL DEPTH=5"),
        "depth.txt",
    );
}

/// A plain ISO `.mpf` is G-code and is read as such.
#[test]
fn a_siemens_file_in_plain_iso_gcode_is_read() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(
        dir.path(),
        "plain.mpf",
        "; plain ISO\nN10 G21 G90 G17\nN20 G0 X10 Y10 Z50\nN30 G1 Z20 F500\nN40 X60\nN50 M30\n",
    );
    let (code, _, err) = run(&["check", path.to_str().unwrap(), "--machine", "afm-r1000"]);
    assert!(code == 0 || code == 1, "{err}");
}

/// A batch over a folder of programs in every unread language beside one
/// G-code program: one `unread` line per such file, the G-code program
/// compensated, none of them counted as failed, exit 2.
#[test]
fn batch_names_each_unread_file_on_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in");
    std::fs::create_dir(&input).unwrap();
    for (name, text, _, _) in PROGRAMS {
        write(&input, name, text);
    }
    write(
        &input,
        "part.nc",
        "%\nO1000\nG21 G90 G17\nG54 G0 X20. Y20. Z50.\nG43 H1 Z10.\nG1 Z2. F300.\nX80.\nG0 Z50.\nM30\n%\n",
    );
    // A note that is no program stays skipped.
    write(&input, "notes.txt", "cell 4: costs $5, see R1=3\n");
    let out = dir.path().join("out");
    let (code, stdout, err) = run(&[
        "batch",
        "--machine",
        "afm-r1000",
        "--out-dir",
        out.to_str().unwrap(),
        input.to_str().unwrap(),
    ]);
    assert_eq!(code, 2, "{stdout}{err}");
    for (name, _, lang, _) in PROGRAMS {
        let lines: Vec<&str> = stdout
            .lines()
            .filter(|l| l.contains(&format!("/{name}")))
            .collect();
        assert_eq!(lines.len(), 1, "{name}: {stdout}");
        assert!(lines[0].starts_with("unread    "), "{name}: {}", lines[0]);
        assert!(lines[0].contains(lang), "{name}: {}", lines[0]);
    }
    let n = PROGRAMS.len();
    assert!(
        stdout.contains(&format!(
            "batch: {} programs: 1 compensated (0 with findings, 0 empty), 0 failed, {n} in a language not read; 1 skipped",
            n + 1
        )),
        "{stdout}"
    );
    assert!(out.join("part.nc").is_file());
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("batch-summary.json")).unwrap()).unwrap();
    assert_eq!(summary["failed"], 0);
    assert_eq!(summary["exit_code"], 2);
    let results = summary["results"].as_array().unwrap();
    let unread: Vec<_> = results.iter().filter(|r| r["status"] == "unread").collect();
    assert_eq!(unread.len(), n);
    assert!(unread.iter().all(|r| r["output"].is_null()));
    // A file given by name is told the same way.
    let ls = input.join("WELD01.JBI");
    let (code, stdout, _) = run(&[
        "batch",
        "--machine",
        "abb-irb4600-2.05",
        "--out-dir",
        dir.path().join("out2").to_str().unwrap(),
        ls.to_str().unwrap(),
    ]);
    assert_eq!(code, 2, "{stdout}");
    assert!(
        stdout
            .lines()
            .any(|l| l.starts_with("unread    ") && l.contains("Yaskawa JBI")),
        "{stdout}"
    );
    assert!(
        stdout.contains("0 failed, 1 in a language not read"),
        "{stdout}"
    );
}
