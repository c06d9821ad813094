//! The words the compensation writes: inserted axis words in the program's
//! axis order before its feed and auxiliary words, canned-cycle holes that
//! keep their words, and inch programs written with enough decimals for the
//! tolerance.

use crate::common::{postproc, repo};

/// The bundled AFM R-1000 with its `output:` block (4 decimals) removed,
/// so the decimals come from the program and the tolerance.
fn afm_without_decimals() -> String {
    let text = std::fs::read_to_string(repo("machines/afm-r1000.yaml")).unwrap();
    let plain = text.replace("output:\n  decimals_mm: 4\n", "");
    assert_ne!(plain, text);
    plain
}

/// `postproc compensate` of `program` on `machine` with `args`, its output.
fn compensate(machine: &str, program: &str, args: &[&str]) -> String {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("m.yaml"), machine).unwrap();
    std::fs::write(dir.path().join("p.nc"), program).unwrap();
    let out = postproc()
        .current_dir(dir.path())
        .args(["compensate", "p.nc", "--machine", "m.yaml", "-o", "-"])
        .args(["--effects", "geometric", "--annotate", "none"])
        .args(args)
        .assert()
        .success()
        .get_output()
        .clone();
    String::from_utf8(crate::common::without_header(&out.stdout)).unwrap()
}

/// The letters of a line's words, in order.
fn letters(line: &str) -> String {
    line.split_whitespace()
        .filter_map(|w| w.chars().next())
        .collect()
}

/// Regression: a block that programs Z and F only (`G1 Z-0.2 F50`) got
/// the X and Y words its correction needs after the feed word
/// (`Z-0.19999 F50 X1.55029 Y9.99982`). They go before Z, in axis order.
#[test]
fn regression_inserted_axis_words_keep_the_axis_order_before_the_feed() {
    let program =
        "G90 G54 G0 X100. Y80. Z80.\nG1 Z60. F500.\nZ-0.2 F50.\nX140. F200. M8\nY120. S9000\n";
    let out = compensate(&afm_without_decimals(), program, &["--tolerance", "0.001"]);
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(letters(lines[1]), "GXYZF", "{out}");
    assert_eq!(letters(lines[2]), "XYZF", "{out}");
    // Y (and Z) inserted after X, before F and M.
    assert_eq!(letters(lines[3]), "XYZFM", "{out}");
    // X before Y, Z only where its correction changes the word.
    assert!(
        ["XYS", "XYZS"].contains(&letters(lines[4]).as_str()),
        "{out}"
    );
}

/// The hole blocks of a canned cycle keep the modal Z and R, and the axis
/// they do not name, while the corrected values stay within a quarter of
/// the tolerance of them: two holes 1 mm apart need no new words.
#[test]
fn canned_cycle_holes_keep_their_words() {
    let program =
        "G90 G54 G0 X100. Y80. Z20.\nG98 G81 X100. Y80. Z-5. R2. F100.\nX101.\nX102.\nG80\n";
    let out = compensate(&afm_without_decimals(), program, &["--tolerance", "0.005"]);
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(letters(lines[2]), "X", "{out}");
    assert_eq!(letters(lines[3]), "X", "{out}");
}

/// Regression: inch programs were written with one decimal more than mm
/// ones (4 when the machine file sets none): rounding to 0.0001 in moves a
/// word by up to 1.27 µm, more than a 1 µm tolerance. The decimals now
/// grow until half a unit of the last one is within a quarter of the
/// tolerance: 5 at 1 µm (0.13 µm), 4 would exceed it.
#[test]
fn regression_inch_programs_get_decimals_within_the_tolerance() {
    let program = "G20 G90 G54 G0 X4. Y3. Z1.\nG1 X12.3456 Y7.1 F20.\nX2.5 Y9.2 Z0.5\n";
    let out = compensate(&afm_without_decimals(), program, &["--tolerance", "0.001"]);
    let mut most = 0;
    for line in out.lines().skip(1) {
        for w in line.split_whitespace() {
            if let Some(rest) = w.strip_prefix(['X', 'Y', 'Z']) {
                let decimals = rest.split('.').nth(1).map_or(0, str::len);
                assert!(decimals <= 5, "{w} in\n{out}");
                most = most.max(decimals);
            }
        }
    }
    assert_eq!(most, 5, "{out}");
    // At 3 µm, 5 decimals still (4 would round by 1.27 µm > 0.75 µm).
    let out = compensate(&afm_without_decimals(), program, &["--tolerance", "0.003"]);
    assert!(
        out.lines()
            .skip(1)
            .flat_map(|l| l.split_whitespace())
            .any(|w| w.split('.').nth(1).is_some_and(|d| d.len() == 5)),
        "{out}"
    );
}

/// Regression: a block written as several pieces (here a takeup point and
/// the move) kept its M codes and `G9` on its own line, the takeup point,
/// so `M30` ended the program before the last move, `M0`/`M1` stopped
/// before the move and `M5` stopped the spindle before the cut. Words that
/// act at the end of the motion go to the last piece; the block number,
/// feed and the coolant start `M8` stay on the first.
#[test]
fn regression_stops_and_ends_go_to_the_last_piece_of_a_block() {
    let program = "%\nO2001\nN1 G21 G90 G17\nN2 T1 M6\nN3 G54 G0 X0. Y0. S3000 M3\n\
                   N4 G43 H1 Z50.\nN5 G1 Z-1. F300.\nN6 G1 X40. F800. M8\nN7 G1 Y25. M5\n\
                   N8 G1 X0. M1\nN9 G9 G1 Y0.\nN10 G2 X20. Y0. I10. J0. F500. M0\n\
                   N11 G1 Y10. M30\n%\n";
    // All effects: the static and thermal parts make the takeup points.
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("p.nc"), program).unwrap();
    let written = postproc()
        .current_dir(dir.path())
        .args(["compensate", "p.nc", "--machine", "afm-r1000", "-o", "-"])
        .args(["--annotate", "none"])
        .assert()
        .success()
        .get_output()
        .stdout
        .clone();
    let out = String::from_utf8(crate::common::without_header(&written)).unwrap();
    // The lines of each numbered block: its own and the ones added after it.
    let mut blocks: Vec<(String, Vec<&str>)> = Vec::new();
    for line in out.lines() {
        match line.split_whitespace().next() {
            Some(n) if n.starts_with('N') => blocks.push((n.to_string(), vec![line])),
            Some("%") => blocks.push(("%".into(), vec![line])),
            _ => {
                if let Some(b) = blocks.last_mut() {
                    b.1.push(line);
                }
            }
        }
    }
    let lines = |n: &str| {
        blocks
            .iter()
            .find(|b| b.0 == n)
            .map(|b| b.1.clone())
            .unwrap_or_else(|| panic!("{n} missing:\n{out}"))
    };
    let has = |line: &str, word: &str| line.split_whitespace().any(|w| w == word);
    for (n, word) in [
        ("N7", "M5"),
        ("N8", "M1"),
        ("N9", "G9"),
        ("N10", "M0"),
        ("N11", "M30"),
    ] {
        let ls = lines(n);
        assert!(ls.len() >= 2, "{n} is not split, nothing tested:\n{out}");
        let (last, before) = ls.split_last().unwrap();
        assert!(has(last, word), "{n}: {word} not on its last line:\n{out}");
        assert!(
            before.iter().all(|l| !has(l, word)),
            "{n}: {word} before the last piece:\n{out}"
        );
    }
    // The arc after its takeup point carries the stop.
    assert!(lines("N10").last().unwrap().starts_with("G2 "), "{out}");
    // The feed and the coolant start act before the motion: first line.
    let n6 = lines("N6");
    assert!(n6.len() >= 2, "N6 is not split:\n{out}");
    assert!(has(n6[0], "M8") && has(n6[0], "F800."), "{out}");
    assert!(n6[1..].iter().all(|l| !has(l, "M8")), "{out}");
    assert!(has(lines("N9")[0], "G1"), "{out}");
}
