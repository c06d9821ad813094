//! Performance-path regressions of G-code compensation: the output of a
//! program longer than one chunk, with every effect on (geometric errors,
//! milling force and static deflection, thermal drift, vibration), is the
//! same byte for byte whatever the number of worker threads.

use std::fmt::Write as _;

use crate::common::postproc;

/// A raster over several chunks (4096 lines each) that cuts with the
/// spindle on, changes engagement and feed, and mixes long feeds (that
/// cross component-table and stiffness-grid breakpoints), short steps,
/// arcs and rapids.
fn program() -> String {
    let mut p = String::from(
        "%\nO2001 (THREADS)\nG90 G17 G21 G54\nT1 M6\nG43 H1 G0 X0 Y0 Z20\nS6000 M3\n(POSTPROC MILLING DEPTH=2 WIDTH=3)\nG1 Z0 F2000\n",
    );
    let mut y = 0.0f64;
    for n in 0..7000 {
        let x = if n % 2 == 0 { 400.0 } else { 0.0 };
        let _ = writeln!(p, "X{x:.3} Y{y:.3}");
        y += 0.04;
        let _ = writeln!(p, "Y{y:.3}");
        if n % 50 == 25 {
            // A half circle back and forth, then a rapid hop.
            let _ = writeln!(p, "G2 X{x:.3} Y{:.3} I0 J5. F1500", y + 10.0);
            let _ = writeln!(p, "G3 X{x:.3} Y{y:.3} I0 J-5.");
            let _ = writeln!(p, "G0 Z5.\nG0 Z0\nG1 F2000");
        }
        if n % 1500 == 700 {
            p.push_str("(POSTPROC MILLING DEPTH=1 WIDTH=6)\nS4500 M3\n");
        }
    }
    p.push_str("M30\n%\n");
    p
}

fn run(input: &std::path::Path, threads: &str) -> Vec<u8> {
    let out = postproc()
        .args([
            "compensate",
            input.to_str().unwrap_or_default(),
            "--machine",
            "afm-r1000",
            "--effects",
            "all",
            "--thermal-start",
            "steady",
            "-o",
            "-",
            "--threads",
            threads,
        ])
        .output()
        .unwrap();
    // Every piece of the long passes is within the tolerance: no finding.
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.stdout.starts_with(b"%\n"), "a program is written");
    out.stdout
}

#[test]
fn large_program_with_every_effect_is_the_same_for_one_and_two_threads() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("threads.nc");
    let text = program();
    assert!(text.lines().count() > 3 * 4096, "must span several chunks");
    std::fs::write(&input, &text).unwrap();
    let one = run(&input, "1");
    let two = run(&input, "2");
    let out = String::from_utf8_lossy(&one);
    // Every effect shows in the annotations: the run really compensates.
    for label in ["geo", "stat", "therm"] {
        assert!(
            out.contains(label),
            "no `{label}` annotation:\n{}",
            &out[..2000.min(out.len())]
        );
    }
    assert!(out.lines().count() >= text.lines().count());
    assert_eq!(one, two);
}
