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
