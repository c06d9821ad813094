//! Snapshot tests: the exact bytes of the compensated programs and reports of
//! every sample and of a few generated programs, compared with the expected
//! files under `tests/snapshots/`.
//!
//! A change that alters any output byte fails here, so restructuring the code
//! is proven byte-identical, and a deliberate change of output shows up as a
//! diff of the expected files in the same commit. The comparison is byte for
//! byte (CRLF and ISO-8859-1 samples included), which is why the expected
//! files are plain files rather than a snapshot crate's normalised text.
//!
//! To accept a deliberate change, run
//! `UPDATE_SNAPSHOTS=1 cargo test --test integration snapshots` and read the
//! diff of `tests/snapshots/` before committing it. On a mismatch the new
//! bytes are written to `target/snapshots-new/` for inspection.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::common::{postproc, repo};

/// One run of the binary whose standard output (or one written file) is
/// the snapshot.
struct Case {
    /// Snapshot file name under `tests/snapshots/`.
    name: String,
    /// Arguments, relative to the repository root (the working directory).
    args: Vec<String>,
    /// Snapshot a file the run writes (name within the scratch folder)
    /// instead of standard output.
    file: Option<&'static str>,
}

fn case(name: &str, args: &[&str]) -> Case {
    Case {
        name: name.to_string(),
        args: args.iter().map(|s| s.to_string()).collect(),
        file: None,
    }
}

/// Tool lengths for the sample programs that call H1–H12 without a tool
/// table in the machine file.
fn tools() -> Vec<String> {
    (1..=12)
        .flat_map(|h| ["--tool".to_string(), format!("H{h}={}", 60 + 5 * h)])
        .collect()
}

fn snapshot_dir() -> PathBuf {
    repo("tests/snapshots")
}

/// Compares `got` with the expected file `name`, or writes it when
/// `UPDATE_SNAPSHOTS` is set. Returns a description of the mismatch.
fn compare(name: &str, got: &[u8]) -> Option<String> {
    let path = snapshot_dir().join(name);
    if std::env::var_os("UPDATE_SNAPSHOTS").is_some() {
        std::fs::create_dir_all(snapshot_dir()).unwrap();
        std::fs::write(&path, got).unwrap();
        return None;
    }
    let want = match std::fs::read(&path) {
        Ok(w) => w,
        Err(e) => return Some(format!("{name}: no expected file ({e})")),
    };
    if want == got {
        return None;
    }
    let new_dir = repo("target/snapshots-new");
    std::fs::create_dir_all(&new_dir).unwrap();
    std::fs::write(new_dir.join(name), got).unwrap();
    let (w, g) = (String::from_utf8_lossy(&want), String::from_utf8_lossy(got));
    let line = w
        .split_inclusive('\n')
        .zip(g.split_inclusive('\n'))
        .position(|(a, b)| a != b)
        .unwrap_or_else(|| w.lines().count().min(g.lines().count()));
    let show = |t: &str| {
        t.split_inclusive('\n')
            .nth(line)
            .unwrap_or("<end>")
            .to_string()
    };
    Some(format!(
        "{name}: differs from line {}:\n  expected: {:?}\n  got:      {:?}",
        line + 1,
        show(&w),
        show(&g)
    ))
}

/// Runs every case (in the repository root, outputs in a scratch folder)
/// and reports every mismatch at once.
fn run_cases(cases: Vec<Case>, scratch: &Path) {
    let mut failures = Vec::new();
    for c in cases {
        let args: Vec<String> = c
            .args
            .iter()
            .map(|a| {
                a.replace(
                    "{scratch}",
                    scratch.to_str().expect("scratch path is UTF-8"),
                )
            })
            .collect();
        let out = postproc()
            .current_dir(repo(""))
            .env("RAYON_NUM_THREADS", "2")
            .args(&args)
            .output()
            .unwrap();
        let code = out.status.code();
        assert!(
            matches!(code, Some(0) | Some(1)),
            "{}: exit {code:?}\n{}",
            c.name,
            String::from_utf8_lossy(&out.stderr)
        );
        let bytes = match c.file {
            Some(f) => std::fs::read(scratch.join(f)).unwrap(),
            None => out.stdout,
        };
        if let Some(msg) = compare(&c.name, &bytes) {
            failures.push(msg);
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The machine of the shop-style samples: the AFM R-1000 example with G58 and
/// G59 set to a fixture inside the travel (the samples use them), written to
/// the scratch folder by [`write_shop_machine`].
const SHOP: &str = "{scratch}/shop.yaml";

fn write_shop_machine(scratch: &Path) {
    let text = std::fs::read_to_string(repo("machines/afm-r1000.yaml")).unwrap();
    let shop = text
        .replace("G58: [0.0, 0.0, 0.0]", "G58: [300.0, 200.0, 250.0]")
        .replace("G59: [0.0, 0.0, 0.0]", "G59: [300.0, 200.0, 250.0]");
    assert_ne!(shop, text, "the example's G58/G59 lines changed");
    std::fs::write(scratch.join("shop.yaml"), shop).unwrap();
}

/// The G-code samples with the machine each runs on.
fn gcode_samples() -> Vec<(&'static str, &'static str, bool)> {
    vec![
        ("samples/part.nc", "afm-r1000", false),
        ("samples/effects.nc", "afm-r1000", false),
        ("samples/five-axis.nc", "five-axis-ac", false),
        ("samples/gcode/block_delete.nc", SHOP, true),
        ("samples/gcode/fusion_fanuc.nc", SHOP, true),
        ("samples/gcode/inch_g20.nc", SHOP, true),
        ("samples/gcode/iso_spaced_crlf.nc", SHOP, true),
        ("samples/gcode/linuxcnc.ngc", SHOP, true),
        ("samples/gcode/mastercam_haas.nc", SHOP, true),
    ]
}

fn stem(path: &str) -> String {
    Path::new(path)
        .file_name()
        .unwrap()
        .to_string_lossy()
        .replace('.', "_")
}

#[test]
fn gcode_samples_compensated_and_reported() {
    let scratch = tempfile::tempdir().unwrap();
    write_shop_machine(scratch.path());
    let mut cases = Vec::new();
    for (program, machine, needs_tools) in gcode_samples() {
        let s = stem(program);
        let extra = if needs_tools { tools() } else { Vec::new() };
        let with = |mut v: Vec<String>| {
            v.extend(extra.iter().cloned());
            v
        };
        let base = |cmd: &str| -> Vec<String> {
            vec![
                cmd.to_string(),
                program.to_string(),
                "--machine".to_string(),
                machine.to_string(),
            ]
        };
        let mut c = base("compensate");
        c.extend(["-o".to_string(), "-".to_string()]);
        cases.push(Case {
            name: format!("{s}.compensate"),
            args: with(c),
            file: None,
        });
        for fmt in ["table", "csv", "json"] {
            let mut c = base("report");
            c.extend(["--format".to_string(), fmt.to_string()]);
            cases.push(Case {
                name: format!("{s}.report.{fmt}"),
                args: with(c),
                file: None,
            });
        }
        cases.push(Case {
            name: format!("{s}.check"),
            args: with(base("check")),
            file: None,
        });
    }
    // Options that change the output.
    cases.push(case(
        "part_nc.compensate.geometric_annotate_none",
        &[
            "compensate",
            "samples/part.nc",
            "--machine",
            "afm-r1000",
            "--effects",
            "geometric",
            "--annotate",
            "none",
            "-o",
            "-",
        ],
    ));
    cases.push(case(
        "part_nc.compensate.tolerance_0_005",
        &[
            "compensate",
            "samples/part.nc",
            "--machine",
            "afm-r1000",
            "--tolerance",
            "0.005",
            "-o",
            "-",
        ],
    ));
    cases.push(Case {
        file: Some("part.svg"),
        ..case(
            "part_nc.report.svg",
            &[
                "report",
                "samples/part.nc",
                "--machine",
                "afm-r1000",
                "--format",
                "svg",
                "-o",
                "{scratch}/part.svg",
            ],
        )
    });
    run_cases(cases, scratch.path());
}

#[test]
fn rapid_samples_compensated_and_reported() {
    let scratch = tempfile::tempdir().unwrap();
    let mut cases = Vec::new();
    for (program, machine) in [
        ("samples/drilling.mod", "abb-irb1600"),
        ("samples/milling.mod", "samples/irb1600-milling.yaml"),
        ("samples/milling.mod", "abb-irb1600"),
    ] {
        let s = format!("{}.{}", stem(program), stem(machine));
        cases.push(case(
            &format!("{s}.compensate"),
            &["compensate", program, "--machine", machine, "-o", "-"],
        ));
        for fmt in ["table", "csv", "json"] {
            cases.push(case(
                &format!("{s}.report.{fmt}"),
                &["report", program, "--machine", machine, "--format", fmt],
            ));
        }
    }
    cases.push(case(
        "drilling_mod.check",
        &["check", "samples/drilling.mod"],
    ));
    cases.push(case(
        "drilling_mod.compensate.gravity_process_annotate_none",
        &[
            "compensate",
            "samples/drilling.mod",
            "--machine",
            "abb-irb1600",
            "--effects",
            "gravity,process",
            "--annotate",
            "none",
            "-o",
            "-",
        ],
    ));
    cases.push(Case {
        file: Some("drilling.svg"),
        ..case(
            "drilling_mod.report.svg",
            &[
                "report",
                "samples/drilling.mod",
                "--machine",
                "abb-irb1600",
                "--format",
                "svg",
                "-o",
                "{scratch}/drilling.svg",
            ],
        )
    });
    run_cases(cases, scratch.path());
}

/// A raster finish of a shallow dome: many short feed moves whose Z follows
/// the surface, in the style of a CAM surfacing toolpath.
fn surfacing_program() -> String {
    let mut s = String::from(
        "%\nO4001 (GENERATED SURFACING)\nG90 G17 G21 G40 G80\nG54\nT1 M6\nS10000 M3\nG43 H1 G0 X0. Y0. Z30.\n",
    );
    let z = |x: f64, y: f64| {
        let (dx, dy) = (x - 100.0, y - 60.0);
        -2.0 + 10.0 * (-(dx * dx + dy * dy) / 4000.0).exp()
    };
    writeln!(s, "G1 Z{:.3} F1200.", z(0.0, 0.0)).unwrap();
    for row in 0..40 {
        let y = row as f64 * 3.0;
        for i in 0..=40 {
            let i = if row % 2 == 0 { i } else { 40 - i };
            let x = i as f64 * 5.0;
            writeln!(s, "X{x:.3} Y{y:.3} Z{:.3}", z(x, y)).unwrap();
        }
    }
    s.push_str("G0 Z30.\nM5\nG91 G28 Z0.\nM30\n%\n");
    s
}

/// A pocket of helical bores and arc contours: full circles with a Z lead,
/// in the style of a CAM bore-milling toolpath.
fn bores_program() -> String {
    let mut s = String::from(
        "%\nO4002 (GENERATED HELICAL BORES)\nG90 G17 G21 G40 G80\nG54\nT2 M6\nS8000 M3\nG43 H2 G0 Z30.\n",
    );
    for (n, (cx, cy)) in [(40.0, 40.0), (120.0, 40.0), (120.0, 110.0), (40.0, 110.0)]
        .iter()
        .enumerate()
    {
        let r = 6.0 + n as f64;
        writeln!(s, "G0 X{:.3} Y{cy:.3}", cx + r).unwrap();
        s.push_str("Z2.\nG1 Z0. F300.\n");
        for turn in 1..=4 {
            writeln!(
                s,
                "G3 X{:.3} Y{cy:.3} Z{:.3} I{:.3} J0.",
                cx + r,
                -2.0 * turn as f64,
                -r
            )
            .unwrap();
        }
        writeln!(s, "G3 X{:.3} Y{cy:.3} I{:.3} J0.", cx + r, -r).unwrap();
        writeln!(s, "G1 X{cx:.3}\nG0 Z30.").unwrap();
    }
    // A contour with tangent arcs around the bores.
    s.push_str("G0 X20. Y20.\nZ2.\nG1 Z-3. F400.\nX140.\nG2 X150. Y30. I0. J10.\nG1 Y120.\nG2 X140. Y130. I-10. J0.\nG1 X20.\nG2 X10. Y120. I0. J-10.\nG1 Y30.\nG2 X20. Y20. I10. J0.\nG0 Z30.\nM5\nG91 G28 Z0.\nM30\n%\n");
    s
}

/// A module of robot targets in the style of a CAM robot-milling post:
/// declared targets, a tool and a work object, moves in a routine.
fn robot_module() -> String {
    let mut s = String::from(
        "MODULE GenPath\n  PERS tooldata tMill := [TRUE,[[0,0,180],[1,0,0,0]],[3,[0,0,80],[1,0,0,0],0.01,0.01,0.006]];\n  TASK PERS wobjdata wFix := [FALSE,TRUE,\"\",[[650,50,350],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];\n",
    );
    let n = 120;
    for i in 0..n {
        let x = 20.0 + (i % 12) as f64 * 20.0;
        let y = 20.0 + (i / 12) as f64 * 25.0;
        let z = 5.0 * ((i as f64) * 0.3).sin();
        writeln!(
            s,
            "  CONST robtarget p{i} := [[{x:.2},{y:.2},{z:.3}],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];"
        )
        .unwrap();
    }
    s.push_str("  PROC main()\n    ConfL \\Off;\n");
    for i in 0..n {
        let speed = if i == 0 { "v500" } else { "v100" };
        writeln!(s, "    MoveL p{i},{speed},z1,tMill\\WObj:=wFix;").unwrap();
    }
    s.push_str("  ENDPROC\nENDMODULE\n");
    s
}

#[test]
fn generated_programs_compensated_and_reported() {
    let scratch = tempfile::tempdir().unwrap();
    let dir = scratch.path();
    std::fs::write(dir.join("surfacing.nc"), surfacing_program()).unwrap();
    std::fs::write(dir.join("bores.nc"), bores_program()).unwrap();
    std::fs::write(dir.join("robot.mod"), robot_module()).unwrap();
    let mut cases = Vec::new();
    for (file, machine, extra) in [
        ("surfacing.nc", "afm-r1000", vec!["--tool", "H1=90"]),
        ("bores.nc", "afm-r1000", vec!["--tool", "H2=75"]),
        ("robot.mod", "abb-irb1600", vec![]),
    ] {
        let s = format!("generated_{}", stem(file));
        let input = format!("{{scratch}}/{file}");
        let mut args = vec!["compensate", &input, "--machine", machine, "-o", "-"];
        args.extend(extra.iter().copied());
        cases.push(case(&format!("{s}.compensate"), &args));
        let mut args = vec!["report", &input, "--machine", machine, "--format", "csv"];
        args.extend(extra.iter().copied());
        cases.push(case(&format!("{s}.report.csv"), &args));
    }
    run_cases(cases, dir);
}
