//! Provenance through the binary: the header of compensated programs and
//! reports, the refusal of a program compensated before, the summary line
//! on standard error, the machine files bundled in the binary, and the
//! `status` that `calibrate` records.

use std::path::Path;

use crate::common::{postproc, repo, without_header};

/// SHA-256 of a file as `sha256sum` prints it, computed here with the
/// `sha2` crate rather than by the code under test.
fn sha256(path: &Path) -> String {
    use sha2::Digest;
    let digest = sha2::Sha256::digest(std::fs::read(path).expect("read"));
    digest.iter().map(|b| format!("{b:02x}")).collect()
}

fn compensate(args: &[&str]) -> std::process::Output {
    postproc()
        .arg("compensate")
        .args(args)
        .output()
        .expect("runs")
}

#[test]
fn compensated_program_carries_the_provenance_header_after_percent_and_o_number() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("part.comp.nc");
    let part = repo("samples/part.nc");
    let run = compensate(&[
        part.to_str().unwrap(),
        "--machine",
        "afm-r1000",
        "--gain",
        "thermal=0.5",
        "--tolerance",
        "0.002",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert_eq!(
        run.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let text = std::fs::read_to_string(&out).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    // `%` and the O-number line stay first; the header follows.
    assert_eq!(lines[0], "%");
    assert_eq!(lines[1], "O1001 (POSTPROC SAMPLE - POCKET PLATE)");
    assert_eq!(
        lines[2],
        format!(
            "(postproc {} compensated program - do not compensate it again)",
            env!("CARGO_PKG_VERSION")
        )
    );
    assert_eq!(lines[3], "(machine afm-r1000.yaml - bundled with postproc)");
    assert_eq!(
        lines[4],
        format!("(sha256 {})", sha256(&repo("machines/afm-r1000.yaml")))
    );
    assert!(
        lines[5].starts_with("(machine status example"),
        "{}",
        lines[5]
    );
    assert_eq!(
        lines[6],
        "(effects geometric 1, static 1, thermal 0.5, dynamic 1 reported only)"
    );
    assert_eq!(lines[7], "(tolerance 0.002 mm)");
    assert!(lines[8].starts_with("(note: dev = deviation predicted without compensation"));
    assert!(lines[9].starts_with("(note: takeup = "));
    // Then the program's own third line.
    assert_eq!(lines[10], "(MATERIAL - AL 6061, STOCK 160 X 110 X 25)");
    // The example machine is warned about, after the run's summary line.
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(err.contains("example values, not measured data"), "{err}");
}

#[test]
fn semicolon_programs_get_a_semicolon_header_and_crlf_is_kept() {
    let dir = tempfile::tempdir().unwrap();
    let program = repo("samples/gcode/iso_spaced_crlf.nc");
    let run = compensate(&[
        program.to_str().unwrap(),
        "--machine",
        "afm-r1000",
        "--effects",
        "none",
        "-o",
        "-",
    ]);
    assert_eq!(
        run.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let out = run.stdout;
    let text = String::from_utf8_lossy(&out);
    let lines: Vec<&str> = text.split("\r\n").collect();
    assert!(lines[1].starts_with("O 0815"), "{text}");
    assert!(lines[2].starts_with("; postproc "), "{text}");
    assert!(!text.replace("\r\n", "").contains('\n'), "CRLF kept");
    // Nothing else differs from the input.
    assert_eq!(without_header(&out), std::fs::read(&program).unwrap());
    let _ = dir;
}

#[test]
fn a_compensated_program_is_refused_unless_recompensate() {
    let dir = tempfile::tempdir().unwrap();
    let once = dir.path().join("once.nc");
    let twice = dir.path().join("twice.nc");
    let part = repo("samples/part.nc");
    let run = compensate(&[
        part.to_str().unwrap(),
        "-m",
        "afm-r1000",
        "-o",
        once.to_str().unwrap(),
    ]);
    assert_eq!(run.status.code(), Some(0));
    let run = compensate(&[
        once.to_str().unwrap(),
        "-m",
        "afm-r1000",
        "-o",
        twice.to_str().unwrap(),
    ]);
    assert_eq!(run.status.code(), Some(2));
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(
        err.contains("once.nc:3:1: this program was compensated by postproc")
            && err.contains("--recompensate"),
        "{err}"
    );
    assert!(!twice.exists(), "nothing written");
    // Standard input is looked at too.
    let stdin = postproc()
        .args(["compensate", "-", "-m", "afm-r1000", "-o", "-"])
        .write_stdin(std::fs::read(&once).unwrap())
        .output()
        .unwrap();
    assert_eq!(stdin.status.code(), Some(2));
    assert!(stdin.stdout.is_empty());
    // With --recompensate it is compensated again: a second header first.
    let run = compensate(&[
        once.to_str().unwrap(),
        "-m",
        "afm-r1000",
        "--recompensate",
        "-o",
        twice.to_str().unwrap(),
    ]);
    assert_eq!(
        run.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let text = std::fs::read_to_string(&twice).unwrap();
    assert_eq!(
        text.matches("compensated program - do not compensate")
            .count(),
        2
    );
}

#[test]
fn a_compensated_rapid_module_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let once = dir.path().join("once.mod");
    let module = repo("samples/drilling.mod");
    let run = compensate(&[
        module.to_str().unwrap(),
        "-m",
        "abb-irb1600",
        "-o",
        once.to_str().unwrap(),
    ]);
    assert_eq!(
        run.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let text = std::fs::read_to_string(&once).unwrap();
    let module_line = text.lines().position(|l| l.starts_with("MODULE ")).unwrap();
    assert!(
        text.lines()
            .nth(module_line + 1)
            .unwrap()
            .starts_with("  ! postproc "),
        "{text}"
    );
    for window in [None, Some("3")] {
        let mut cmd = postproc();
        cmd.args(["compensate", "-m", "abb-irb1600", "-o", "-"]);
        if let Some(w) = window {
            cmd.args(["--rapid-window-lines", w]);
        }
        let run = cmd.arg(&once).output().unwrap();
        assert_eq!(run.status.code(), Some(2));
        assert!(
            String::from_utf8_lossy(&run.stderr).contains("compensated by postproc"),
            "{}",
            String::from_utf8_lossy(&run.stderr)
        );
    }
}

#[test]
fn summary_line_on_stderr_unless_quiet() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("p.nc");
    let part = repo("samples/part.nc");
    let run = compensate(&[
        part.to_str().unwrap(),
        "-m",
        "afm-r1000",
        "-o",
        out.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&run.stderr);
    let line = err
        .lines()
        .find(|l| l.contains(" → "))
        .unwrap_or_else(|| panic!("{err}"));
    assert!(
        line.starts_with(&format!("{} → {}: ", part.display(), out.display())),
        "{line}"
    );
    // The counts agree with the written program: lines added.
    let lines_out = std::fs::read_to_string(&out).unwrap().lines().count();
    let lines_in = std::fs::read_to_string(&part).unwrap().lines().count();
    let header = lines_out
        - without_header(&std::fs::read(&out).unwrap())
            .split(|&b| b == b'\n')
            .filter(|l| !l.is_empty())
            .count();
    let added = lines_out - header - lines_in;
    let added_text = added.to_string();
    // Groups of three digits are separated by a space.
    let grouped = if added >= 1000 {
        format!(
            "{} {}",
            &added_text[..added_text.len() - 3],
            &added_text[added_text.len() - 3..]
        )
    } else {
        added_text
    };
    assert!(line.contains(&format!(" {grouped} lines added")), "{line}");
    assert!(
        line.contains("predicted deviation of cutting moves max "),
        "{line}"
    );
    // -q: nothing on stderr.
    let quiet = postproc()
        .args(["-q", "compensate"])
        .arg(&part)
        .args(["-m", "afm-r1000", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(quiet.status.code(), Some(0));
    assert!(
        quiet.stderr.is_empty(),
        "{}",
        String::from_utf8_lossy(&quiet.stderr)
    );
}

#[test]
fn an_installed_binary_run_from_tmp_uses_the_bundled_machine() {
    // The binary copied away from the build tree, run from a folder with
    // no machines/ beside it.
    let bin_dir = tempfile::tempdir().unwrap();
    let work = tempfile::tempdir().unwrap();
    let bin = bin_dir.path().join("postproc");
    std::fs::copy(assert_cmd::cargo::cargo_bin("postproc"), &bin).unwrap();
    std::fs::copy(repo("samples/part.nc"), work.path().join("part.nc")).unwrap();
    let run = std::process::Command::new(&bin)
        .current_dir(work.path())
        .args(["compensate", "part.nc", "--machine", "afm-r1000"])
        .output()
        .unwrap();
    assert_eq!(
        run.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let written = std::fs::read_to_string(work.path().join("part.comp.nc")).unwrap();
    assert!(written.contains("(machine afm-r1000.yaml - bundled with postproc)"));
    // The same bytes as the build tree's run with the machine file's path
    // apart from the header's machine line.
    let from_file = postproc()
        .args(["compensate", "-o", "-", "--machine"])
        .arg(repo("machines/afm-r1000.yaml"))
        .arg(repo("samples/part.nc"))
        .output()
        .unwrap();
    assert_eq!(
        without_header(&from_file.stdout),
        without_header(written.as_bytes())
    );
    // `postproc machines` lists the four with their status.
    let list = std::process::Command::new(&bin)
        .current_dir(work.path())
        .arg("machines")
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&list.stdout);
    for name in ["abb-irb1600", "afm-r1000", "five-axis-ac", "staubli-tx200"] {
        assert!(
            text.lines()
                .any(|l| l.trim_start().starts_with(name) && l.contains(" example ")),
            "{text}"
        );
    }
    // A file path still wins over a bundled name.
    std::fs::write(work.path().join("afm-r1000"), "kind: robot\n").unwrap();
    let run = std::process::Command::new(&bin)
        .current_dir(work.path())
        .args(["check", "part.nc", "--machine", "afm-r1000"])
        .output()
        .unwrap();
    assert_eq!(run.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&run.stderr).contains("afm-r1000:"));
}

#[test]
fn reports_carry_the_provenance() {
    let part = repo("samples/part.nc");
    let run = postproc()
        .args(["report", "--format", "json", "-m", "afm-r1000"])
        .arg(&part)
        .output()
        .unwrap();
    assert_eq!(run.status.code(), Some(0));
    let v: serde_json::Value = serde_json::from_slice(&run.stdout).unwrap();
    let p = &v["provenance"];
    assert_eq!(p["postproc"], env!("CARGO_PKG_VERSION"));
    assert_eq!(p["machine"]["file"], "afm-r1000.yaml");
    assert_eq!(p["machine"]["bundled"], true);
    assert_eq!(p["machine"]["status"], "example");
    assert_eq!(
        p["machine"]["sha256"],
        sha256(&repo("machines/afm-r1000.yaml")).as_str()
    );
    assert_eq!(p["effects"][0]["effect"], "geometric");
    assert!(p["tolerance_mm"].is_null());
}

#[test]
fn calibrate_records_a_calibrated_status_that_programs_then_carry() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cal.yaml");
    let obs = repo("samples/observations/afm-r1000-grid-measured.csv");
    let run = postproc()
        .env("SOURCE_DATE_EPOCH", "1764028800") // 2025-11-25 00:00 UTC
        .args([
            "calibrate",
            "geometry",
            "--machine",
            "afm-r1000",
            "--observations",
        ])
        .arg(&obs)
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(
        run.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let text = std::fs::read_to_string(&out).unwrap();
    // Geometry only: the other sections stay example values.
    assert!(
        text.contains("\nstatus: { geometry: calibrated, stiffness: example, thermal: example, process_force: example }"),
        "{text}"
    );
    let rows = std::fs::read_to_string(&obs)
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .count()
        - 1;
    let entry = text
        .lines()
        .find(|l| l.starts_with("  - { date: 2025-11-25, kind: geometry"))
        .unwrap_or_else(|| panic!("{text}"));
    assert!(
        entry.contains(&format!("observations_sha256: {}", sha256(&obs)))
            && entry.contains(&format!("rows: {rows},"))
            && entry.contains("observations: afm-r1000-grid-measured.csv"),
        "{entry}"
    );
    // A program compensated with it says so; the warning names the
    // sections still at example values, no longer the whole file.
    let run = compensate(&[
        repo("samples/part.nc").to_str().unwrap(),
        "-m",
        out.to_str().unwrap(),
        "-o",
        "-",
    ]);
    assert_eq!(
        run.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let program = String::from_utf8_lossy(&run.stdout);
    assert!(
        program.contains("(machine status calibrated 2025-11-25 - geometry, "),
        "{program}"
    );
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(
        err.contains("stiffness, thermal, process force still example values")
            && !err.contains("`status: example`"),
        "{err}"
    );
}

#[test]
fn report_headline_is_about_the_cutting_moves_with_positioning_moves_apart() {
    let part = repo("samples/part.nc");
    let run = postproc()
        .args(["report", "-m", "afm-r1000", "--format", "json"])
        .arg(&part)
        .output()
        .unwrap();
    let v: serde_json::Value = serde_json::from_slice(&run.stdout).unwrap();
    // Counted from the rows themselves: which are cutting moves, and the
    // largest deviation of each group.
    let rows = v["rows"].as_array().unwrap();
    let positioning = |m: &str| matches!(m, "rapid" | "fixed");
    let group_max = |cut: bool| {
        rows.iter()
            .filter(|r| positioning(r["motion"].as_str().unwrap()) != cut)
            .map(|r| (r["dev_mm"].as_f64().unwrap(), r["line"].as_u64().unwrap()))
            .fold((0.0, 0), |a, b| if b.0 > a.0 { b } else { a })
    };
    let (cut_max, cut_line) = group_max(true);
    let (pos_max, pos_line) = group_max(false);
    let s = &v["summary"];
    assert_eq!(s["cutting"]["max_line"].as_u64().unwrap(), cut_line);
    assert_eq!(s["cutting"]["max_mm"].as_f64().unwrap(), cut_max);
    assert_eq!(s["positioning"]["max_line"].as_u64().unwrap(), pos_line);
    assert_eq!(s["positioning"]["max_mm"].as_f64().unwrap(), pos_max);
    assert!(
        s["cutting"]["worst"]
            .as_array()
            .unwrap()
            .iter()
            .all(|w| !positioning(w["motion"].as_str().unwrap()))
    );
    // The table leads with the same headline and labels the positions.
    let table = postproc()
        .args(["report", "-m", "afm-r1000"])
        .arg(&part)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&table.stdout);
    let lines: Vec<&str> = text.lines().collect();
    let at = lines
        .iter()
        .position(|l| l.starts_with("cutting moves ("))
        .unwrap_or_else(|| panic!("{text}"));
    let headline = lines[at];
    assert!(
        headline.contains(&format!("(line {cut_line}),")) && !headline.contains("rapid"),
        "{headline}"
    );
    // The rapids and machine-defined moves on their own line, next.
    let positioning = lines.get(at + 1).copied().unwrap_or("");
    assert!(
        positioning.starts_with("rapids and machine-defined moves (")
            && positioning.ends_with(&format!("(line {pos_line})")),
        "{positioning}"
    );
    // The worst cutting blocks come before the positioning moves' and
    // hold no positioning move.
    let cut_at = lines.iter().position(|l| *l == "worst cutting blocks:");
    let pos_at = lines
        .iter()
        .position(|l| *l == "worst rapids and machine-defined moves:");
    let (Some(cut_at), Some(pos_at)) = (cut_at, pos_at) else {
        panic!("{text}");
    };
    assert!(cut_at < pos_at, "{text}");
    let listed = &lines[cut_at + 1..pos_at];
    assert!(!listed.is_empty());
    assert!(
        listed
            .iter()
            .all(|l| l.starts_with("  line ") && !l.contains(" rapid ") && !l.contains(" fixed ")),
        "{text}"
    );
    assert!(
        listed[0].starts_with(&format!("  line {cut_line} ")),
        "{text}"
    );
    assert!(text.contains("\npositions: machine coordinates"), "{text}");
}
