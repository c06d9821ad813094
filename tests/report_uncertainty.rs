//! The expanded uncertainty U (k=2) of each block's predicted deviation in
//! `report` (JSON, CSV, table) and `compensate --gain-auto`, from a
//! machine file whose `covariance` list is written here by hand: two
//! nodes of afm-r1000's EXX forward table (300 and 400 mm) with u = 5 µm
//! and 4 µm and correlation 0.5. Only X's position error moves the tip
//! along X with those nodes, by the table's linear interpolation weights
//! (1e-3 mm per µm), on moves in +X; the reverse column is not in the
//! covariance, so moves in −X have U = 0. The expected U is derived here
//! from those weights: var_x = (w3 u3)² + (w4 u4)² + 2 ρ w3 w4 u3 u4, and
//! U of |dev| = 2 sqrt(var_x) |dx| / |dev|.

use crate::common::{postproc, repo, text, write};

/// U is printed with 5 decimals.
const U_TOL_MM: f64 = 0.6e-5;

const U3: f64 = 5.0;
const U4: f64 = 4.0;
const RHO: f64 = 0.5;

pub(crate) fn machine_with_covariance(dir: &std::path::Path) -> std::path::PathBuf {
    let mut m = text("machines/afm-r1000.yaml");
    if !m.ends_with('\n') {
        m.push('\n');
    }
    m.push_str(&format!(
        "covariance:\n  - kind: geometry\n    observations: \"hand.csv\"\n    observations_sha256: 00\n    rows: 40\n    parameters: [\"axes[X].component_errors.EXX_um.forward[3]\", \"axes[X].component_errors.EXX_um.forward[4]\"]\n    u: [{U3}, {U4}]\n    correlation:\n      - [1.0, {RHO}]\n      - [{RHO}, 1.0]\n"
    ));
    write(dir, "mill.yaml", &m)
}

pub(crate) const PROGRAM: &str =
    "G90 G54 G0 X-200 Y0 Z50\nG1 X50 F1000\nG1 X100\nG1 X120\nG1 X20\nM30\n";

/// The hand-derived U of a block at machine X `x` moving in `dir_plus`
/// with deviation (dx, |dev|).
fn expected_u(x: f64, plus: bool, dx: f64, dev: f64) -> f64 {
    if !plus || dev == 0.0 {
        return 0.0;
    }
    // Weights of the nodes at 300 and 400 mm (linear interpolation).
    let (w3, w4) = if (200.0..=300.0).contains(&x) {
        ((x - 200.0) / 100.0, 0.0)
    } else if (300.0..=400.0).contains(&x) {
        ((400.0 - x) / 100.0, (x - 300.0) / 100.0)
    } else if (400.0..=500.0).contains(&x) {
        (0.0, (500.0 - x) / 100.0)
    } else {
        (0.0, 0.0)
    };
    let var_um2 = (w3 * U3).powi(2) + (w4 * U4).powi(2) + 2.0 * RHO * w3 * w4 * U3 * U4;
    2.0 * var_um2.sqrt() * 1e-3 * dx.abs() / dev
}

fn report(machine: &std::path::Path, program: &std::path::Path, format: &str) -> String {
    let a = postproc()
        .arg("report")
        .arg(program)
        .arg("--machine")
        .arg(machine)
        .args(["--effects", "geometric", "--format", format])
        .assert()
        .success();
    String::from_utf8_lossy(&a.get_output().stdout).into_owned()
}

#[test]
fn report_gives_each_block_its_u_from_the_covariance() {
    let dir = tempfile::tempdir().expect("tempdir");
    let machine = machine_with_covariance(dir.path());
    let program = write(dir.path(), "p.nc", PROGRAM);
    let json: serde_json::Value =
        serde_json::from_str(&report(&machine, &program, "json")).expect("JSON");
    let rows = json["rows"].as_array().expect("rows");
    // Machine X (program X + G54's 250 mm) and direction of the feed
    // moves, by hand.
    let moves = [(300.0, true), (350.0, true), (370.0, true), (270.0, false)];
    let feeds: Vec<&serde_json::Value> = rows.iter().filter(|r| r["motion"] == "feed").collect();
    assert_eq!(feeds.len(), moves.len());
    let mut worst: f64 = 0.0;
    let mut nonzero = 0;
    for (r, (x, plus)) in feeds.iter().zip(moves) {
        let cx = r["commanded"]["X"].as_f64().expect("X");
        assert!((cx - x).abs() < 1e-9, "X {cx}, not {x}");
        let dx = r["deviation_mm"][0].as_f64().expect("dx");
        let dev = r["dev_mm"].as_f64().expect("dev");
        let u = r["u_mm"].as_f64().expect("u_mm");
        let want = expected_u(x, plus, dx, dev);
        assert!(
            (u - want).abs() <= U_TOL_MM,
            "line {}: U {u} but {want} by hand",
            r["line"]
        );
        let ug = r["u_effects_mm"]["geometric"].as_f64().expect("per effect");
        assert!((ug - u).abs() <= U_TOL_MM, "one effect: its U is the total");
        if want > U_TOL_MM {
            nonzero += 1;
        }
        worst = worst.max(want);
    }
    assert!(nonzero >= 3, "the test exercises U");
    let s = &json["summary"]["uncertainty"];
    assert_eq!(s["k"], 2.0);
    let got = s["cutting_max_u_mm"].as_f64().expect("worst U");
    assert!((got - worst).abs() <= U_TOL_MM, "{got} vs {worst}");
    assert_eq!(
        json["provenance"]["uncertainty"]["covariance_of"][0],
        "geometry (hand.csv)"
    );

    // CSV: a u_mm column after dev_mm and one per effect; table: U_mm.
    let csv = report(&machine, &program, "csv");
    let header: Vec<&str> = csv.lines().next().expect("header").split(',').collect();
    let dev_at = header.iter().position(|c| *c == "dev_mm").expect("dev_mm");
    assert_eq!(header[dev_at + 1], "u_mm");
    assert!(header.contains(&"u_geometric_mm"), "{header:?}");
    let table = report(&machine, &program, "table");
    assert!(table.lines().next().expect("header").contains("U_mm"));
    assert!(
        table.contains("uncertainty U(k=2) of cutting moves: max"),
        "{table}"
    );
}

#[test]
fn without_a_covariance_the_report_states_no_u() {
    let dir = tempfile::tempdir().expect("tempdir");
    let program = write(dir.path(), "p.nc", PROGRAM);
    let out = report(&repo("machines/afm-r1000.yaml"), &program, "json");
    assert!(
        !out.contains("u_mm") && !out.contains("uncertainty"),
        "{out}"
    );
    let csv = report(&repo("machines/afm-r1000.yaml"), &program, "csv");
    assert!(!csv.contains("u_mm"));
}

#[test]
fn gain_auto_scales_the_correction_by_how_well_it_is_known() {
    let dir = tempfile::tempdir().expect("tempdir");
    let machine = machine_with_covariance(dir.path());
    let program = write(dir.path(), "p.nc", PROGRAM);
    let out = dir.path().join("out.nc");
    postproc()
        .arg("compensate")
        .arg(&program)
        .arg("--machine")
        .arg(&machine)
        .args(["--effects", "geometric", "--gain-auto", "-o"])
        .arg(&out)
        .assert()
        .success();
    let written = std::fs::read_to_string(&out).expect("written");
    // The file's EXX forward values at 300 and 400 mm are 5.6 and 6.5 µm:
    // Σ (c/u)² = (5.6/5)² + (6.5/4)² = 1.2544 + 2.640625 = 3.895025, so
    // g = 1 − 2/3.895025 = 0.486524…, written to three decimals.
    assert!(
        written.contains("gain auto geometric x0.487 (by the parameter covariance)"),
        "{written}"
    );
    assert!(written.contains("effects geometric 0.487"), "{written}");
    // A file without a covariance is refused.
    let a = postproc()
        .arg("compensate")
        .arg(&program)
        .args(["--machine", "afm-r1000", "--gain-auto", "-o"])
        .arg(dir.path().join("o2.nc"))
        .assert()
        .code(2);
    let err = String::from_utf8_lossy(&a.get_output().stderr);
    assert!(err.contains("carries no parameter covariance"), "{err}");
}

/// The compensated program of `machine` (annotated, the default).
fn compensated(machine: &std::path::Path, program: &std::path::Path) -> String {
    let out = program.with_extension("comp.nc");
    postproc()
        .arg("compensate")
        .arg(program)
        .arg("--machine")
        .arg(machine)
        .args(["--effects", "geometric", "-o"])
        .arg(&out)
        .assert()
        .success();
    std::fs::read_to_string(&out).expect("written")
}

/// The number after `word ` in a block's annotation.
fn annotated(line: &str, word: &str) -> Option<f64> {
    let note = &line[line.find("(dev ")?..];
    let mut it = note.trim_end_matches(')').split(' ');
    it.find(|w| *w == word)?;
    it.next()?.parse().ok()
}

/// Annotations print U with 4 decimals (mm).
const ANNOTATION_U_TOL_MM: f64 = 0.6e-4;

/// Checks the U of each annotated feed block of `written` (a compensated
/// PROGRAM) against the hand-derived U of the report's row.
fn assert_annotated_u(machine: &std::path::Path, program: &std::path::Path, written: &str) {
    let json: serde_json::Value =
        serde_json::from_str(&report(machine, program, "json")).expect("JSON");
    let moves = [(300.0, true), (350.0, true), (370.0, true), (270.0, false)];
    let feeds: Vec<&serde_json::Value> = json["rows"]
        .as_array()
        .expect("rows")
        .iter()
        .filter(|r| r["motion"] == "feed")
        .collect();
    // The annotated feed blocks, in order (the program's four G1 blocks).
    let blocks: Vec<&str> = written
        .lines()
        .filter(|l| l.starts_with("G1") && l.contains("(dev "))
        .collect();
    assert_eq!(blocks.len(), feeds.len(), "{written}");
    let mut seen = 0;
    for ((r, (x, plus)), text) in feeds.iter().zip(moves).zip(blocks) {
        let dx = r["deviation_mm"][0].as_f64().expect("dx");
        let dev = r["dev_mm"].as_f64().expect("dev");
        let want = expected_u(x, plus, dx, dev);
        let u = annotated(text, "U").unwrap_or_else(|| panic!("no U in {text}"));
        assert!(
            (u - want).abs() <= ANNOTATION_U_TOL_MM,
            "{text}: U {u} but {want} by hand"
        );
        // U follows the deviation, before the parts.
        assert!(text.contains(" mm U "), "{text}");
        seen += usize::from(want > ANNOTATION_U_TOL_MM);
    }
    assert!(seen >= 3, "the test exercises U");
}

#[test]
fn compensated_blocks_carry_their_u_from_the_covariance() {
    let dir = tempfile::tempdir().expect("tempdir");
    let machine = machine_with_covariance(dir.path());
    let program = write(dir.path(), "p.nc", PROGRAM);
    let written = compensated(&machine, &program);
    assert_annotated_u(&machine, &program, &written);
}

/// `batch` writes the same annotations, U included, as `compensate`.
#[test]
fn batch_annotations_carry_their_u_from_the_covariance() {
    let dir = tempfile::tempdir().expect("tempdir");
    let machine = machine_with_covariance(dir.path());
    let input = dir.path().join("in");
    std::fs::create_dir_all(&input).expect("input folder");
    let program = write(&input, "p.nc", PROGRAM);
    let out = dir.path().join("out");
    postproc()
        .arg("batch")
        .arg("--machine")
        .arg(&machine)
        .args(["--effects", "geometric", "--out-dir"])
        .arg(&out)
        .arg(&input)
        .assert()
        .success();
    let written = std::fs::read_to_string(out.join("p.nc")).expect("batch output p.nc");
    assert_annotated_u(&machine, &program, &written);
}

#[test]
fn without_a_covariance_annotations_state_no_u() {
    let dir = tempfile::tempdir().expect("tempdir");
    let program = write(dir.path(), "p.nc", PROGRAM);
    let written = compensated(&repo("machines/afm-r1000.yaml"), &program);
    assert!(written.contains("(dev "), "{written}");
    assert!(!written.contains(" U "), "{written}");
}

/// The SVG picture and the HTML page state U where the machine file
/// carries a covariance: the page's data hold each drawn row's U (in
/// 0.1 µm, as its deviations) equal to the JSON report's, and the marks
/// of the SVG picture are labelled with theirs; without a covariance
/// neither does.
#[test]
fn pictures_carry_u_from_the_covariance() {
    let dir = tempfile::tempdir().expect("tempdir");
    let machine = machine_with_covariance(dir.path());
    let program = write(dir.path(), "p.nc", PROGRAM);
    let json: serde_json::Value =
        serde_json::from_str(&report(&machine, &program, "json")).expect("JSON");
    let rows = json["rows"].as_array().expect("rows");
    let html = report(&machine, &program, "html");
    let data = html
        .split("id=\"report-data\">")
        .nth(1)
        .and_then(|s| s.split("</script>").next())
        .expect("the page's data");
    let data: serde_json::Value = serde_json::from_str(data).expect("data JSON");
    let per_mm = data["units"]["dev_per_mm"].as_f64().expect("units");
    let u = data["u"].as_object().expect("U of the rows");
    assert_eq!(data["rows"].as_array().map(Vec::len), Some(rows.len()));
    let mut stated = 0;
    for (i, r) in rows.iter().enumerate() {
        let want = r["u_mm"].as_f64().expect("u_mm");
        let got = u
            .get(&i.to_string())
            .and_then(serde_json::Value::as_f64)
            .map(|v| v / per_mm);
        let got = got.unwrap_or_else(|| panic!("row {i} has no U in the page"));
        assert!(
            (got - want).abs() <= 0.51 / per_mm,
            "row {i}: {got} vs {want}"
        );
        stated += usize::from(want > 0.0);
    }
    assert!(stated >= 3, "the test exercises U");
    let marks = data["marks"].as_array().expect("marks");
    assert!(!marks.is_empty());
    for m in marks {
        let line = m["line"].as_u64().expect("line");
        let row = rows
            .iter()
            .find(|r| r["line"].as_u64() == Some(line))
            .expect("the mark's row");
        let want = row["u_mm"].as_f64().expect("u_mm");
        let got = m["u"].as_f64().expect("the mark's U");
        assert!(
            (got - want).abs() <= 1e-6,
            "mark line {line}: {got} vs {want}"
        );
    }

    let svg = report(&machine, &program, "svg");
    for m in marks {
        let label = format!(
            "line {} ({:.4} mm, U {:.4})",
            m["line"],
            m["dev"].as_f64().expect("dev"),
            m["u"].as_f64().expect("u")
        );
        assert!(svg.contains(&label), "no `{label}` in the SVG picture");
    }

    let plain = report(&repo("machines/afm-r1000.yaml"), &program, "html");
    assert!(!plain.contains(",\"u\":"), "no U without a covariance");
    let plain = report(&repo("machines/afm-r1000.yaml"), &program, "svg");
    assert!(!plain.contains(" mm, U "));
}
