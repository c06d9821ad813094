//! `postproc report` through the binary, for G-code and RAPID: every format,
//! the JSON against the committed schema, the SVG as XML with the toolpath,
//! and `compensate --report` in the format of its extension.

use approx::assert_abs_diff_eq;

use crate::common::{postproc, repo};

/// Deviations are printed with 5 decimals.
const DEV_TOL_MM: f64 = 0.5e-5;
/// One row per motion block of samples/part.nc (see gcode_cli.rs).
const PART_ROWS: usize = 54;
/// Motion instructions of samples/drilling.mod, counted independently of
/// the tool: the lines of the module text that start with `Move`.
fn drilling_moves() -> usize {
    let text = std::fs::read_to_string(repo("samples/drilling.mod")).expect("sample");
    text.lines()
        .map(str::trim_start)
        .filter(|l| l.starts_with("Move"))
        .count()
}

fn run(args: &[&str]) -> String {
    let a = postproc().args(args).assert().success();
    String::from_utf8_lossy(&a.get_output().stdout).to_string()
}

fn part_report(format: &str) -> String {
    let part = repo("samples/part.nc");
    run(&[
        "report",
        part.to_str().expect("utf-8 path"),
        "--machine",
        "afm-r1000",
        "--format",
        format,
    ])
}

fn drilling_report(format: &str) -> String {
    let m = repo("samples/drilling.mod");
    run(&[
        "report",
        m.to_str().expect("utf-8 path"),
        "--machine",
        "abb-irb1600",
        "--format",
        format,
    ])
}

/// Validates a report against schemas/report.schema.json with `boon`.
fn validate(report: &str) -> serde_json::Value {
    let schema: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(repo("schemas/report.schema.json")).expect("schema file"),
    )
    .expect("schema is JSON");
    let instance: serde_json::Value = serde_json::from_str(report).expect("report is JSON");
    let mut schemas = boon::Schemas::new();
    let mut compiler = boon::Compiler::new();
    let url = "https://postproc.example/schemas/report.schema.json";
    compiler.add_resource(url, schema).expect("schema resource");
    let idx = compiler
        .compile(url, &mut schemas)
        .expect("schema compiles");
    if let Err(e) = schemas.validate(&instance, idx) {
        panic!("report does not match the schema: {e:#}");
    }
    // The schema is not vacuous: a report without its summary, or with an
    // unknown row key, is rejected.
    let mut bad = instance.clone();
    if let Some(o) = bad.as_object_mut() {
        o.remove("summary");
    }
    assert!(schemas.validate(&bad, idx).is_err());
    let mut bad = instance.clone();
    bad["rows"][0]["surprise"] = serde_json::json!(1);
    assert!(schemas.validate(&bad, idx).is_err());
    instance
}

#[test]
fn gcode_json_report_validates_and_summarises_per_effect() {
    let v = validate(&part_report("json"));
    assert_eq!(v["kind"], "gcode");
    assert_eq!(v["rows"].as_array().map(Vec::len), Some(PART_ROWS));
    let s = &v["summary"];
    // The same maximum as the table's summary line in README (line 29,
    // 0.03178 mm) and as the rows: the worst block is the largest dev_mm.
    let rows = v["rows"].as_array().expect("rows");
    let (max_line, max_dev) = rows
        .iter()
        .map(|r| {
            (
                r["line"].as_u64().unwrap_or(0),
                r["dev_mm"].as_f64().unwrap_or(0.0),
            )
        })
        .fold((0, 0.0), |a, b| if b.1 > a.1 { b } else { a });
    assert_eq!(s["max_line"].as_u64(), Some(max_line));
    assert_eq!(max_line, 29);
    assert_abs_diff_eq!(
        s["max_mm"].as_f64().unwrap_or(0.0),
        max_dev,
        epsilon = DEV_TOL_MM
    );
    // Mean recomputed from the rows (rounded to 5 decimals each).
    let mean = rows
        .iter()
        .map(|r| r["dev_mm"].as_f64().unwrap_or(0.0))
        .sum::<f64>()
        / rows.len() as f64;
    assert_abs_diff_eq!(
        s["mean_mm"].as_f64().unwrap_or(0.0),
        mean,
        epsilon = DEV_TOL_MM
    );
    // p95 of 54 values: the ceil(0.95·54) = 52nd smallest, to the 1e-5 bin.
    let mut devs: Vec<f64> = rows
        .iter()
        .map(|r| r["dev_mm"].as_f64().unwrap_or(0.0))
        .collect();
    devs.sort_by(f64::total_cmp);
    assert_abs_diff_eq!(
        s["p95_mm"].as_f64().unwrap_or(0.0),
        devs[51],
        epsilon = 2.0 * DEV_TOL_MM
    );
    // Total first, then one entry per effect; worst blocks largest first.
    let effects = s["effects"].as_array().expect("effects");
    assert_eq!(effects[0]["name"], "total");
    assert_eq!(
        effects.len(),
        1 + v["effects"].as_array().map_or(0, Vec::len)
    );
    let worst: Vec<f64> = effects[0]["worst"]
        .as_array()
        .expect("worst")
        .iter()
        .map(|w| w["dev_mm"].as_f64().unwrap_or(0.0))
        .collect();
    assert_eq!(worst.len(), 5);
    assert!(worst.windows(2).all(|w| w[0] >= w[1]));
    assert_eq!(effects[0]["worst"][0]["line"], 29);
    // Line 29 of samples/part.nc, quoted.
    assert_eq!(effects[0]["worst"][0]["source"], "N210 G54 G0 X80. Y55.");
}

#[test]
fn rapid_json_report_validates_with_the_robot_effects() {
    let v = validate(&drilling_report("json"));
    assert_eq!(v["kind"], "rapid");
    assert_eq!(
        v["effects"],
        serde_json::json!(["kinematic", "thermal", "gravity", "process", "dynamic"])
    );
    let rows = v["rows"].as_array().expect("rows");
    assert_eq!(rows.len(), drilling_moves());
    // Line 45 is `MoveAbsJ jHome…`, the first move. Its breakdown must match
    // what `compensate` annotates on that instruction (an independent
    // formatter of the same prediction, 3 decimals).
    let first = &rows[0];
    assert_eq!(first["line"], 45);
    assert_eq!(first["motion"], "MoveAbsJ");
    // (A MoveAbsJ is annotated when compensated as a Cartesian pose.)
    let compensated = run(&[
        "compensate",
        "--machine",
        "abb-irb1600",
        "--compensate-joint-targets",
        "-o",
        "-",
        repo("samples/drilling.mod").to_str().unwrap(),
    ]);
    let note = compensated
        .lines()
        .find(|l| l.trim_start().starts_with("MoveAbsJ jHome"))
        .and_then(|l| l.split_once("! dev "))
        .map(|(_, n)| n.to_string())
        .expect("annotated first move");
    let value_after = |key: &str| -> f64 {
        note.split(key)
            .nth(1)
            .and_then(|r| r.split_whitespace().next())
            .and_then(|v| v.trim_end_matches(')').parse().ok())
            .unwrap_or_else(|| panic!("`{key}` in `{note}`"))
    };
    const ANNOTATION_TOL_MM: f64 = 0.0005;
    assert_abs_diff_eq!(
        first["dev_mm"].as_f64().unwrap_or(0.0),
        note.split_whitespace()
            .next()
            .and_then(|v| v.parse::<f64>().ok())
            .expect("dev value"),
        epsilon = ANNOTATION_TOL_MM
    );
    assert_abs_diff_eq!(
        first["effects_mm"]["kinematic"].as_f64().unwrap_or(0.0),
        value_after("kin "),
        epsilon = ANNOTATION_TOL_MM
    );
    assert_abs_diff_eq!(
        first["effects_mm"]["gravity"].as_f64().unwrap_or(0.0),
        value_after("grav "),
        epsilon = ANNOTATION_TOL_MM
    );
    assert!(first["effects_mm"]["gravity"].as_f64().unwrap_or(0.0) > 0.1);
    assert!(first.get("residual_mm").is_none());
}

#[test]
fn table_and_csv_reports_for_gcode_and_rapid() {
    let table = part_report("table");
    let rows = table
        .lines()
        .filter(|l| {
            l.split_whitespace()
                .next()
                .is_some_and(|w| w.parse::<usize>().is_ok())
        })
        .count();
    assert_eq!(rows, PART_ROWS);
    assert!(table.contains("summary: 54 rows"), "{table}");
    let total = table
        .lines()
        .find(|l| l.starts_with("total "))
        .expect("per-effect total line");
    // The total line's worst block is the row with the largest dev_mm,
    // read back from the rows themselves.
    let header: Vec<&str> = table
        .lines()
        .next()
        .unwrap_or("")
        .split_whitespace()
        .collect();
    let dev_col = header
        .iter()
        .position(|h| *h == "dev_mm")
        .expect("dev_mm column");
    let (worst_line, worst_dev) = table
        .lines()
        .skip(1)
        .take(PART_ROWS)
        .filter_map(|l| {
            let cells: Vec<&str> = l.split_whitespace().collect();
            Some((
                cells.first()?.parse::<usize>().ok()?,
                cells.get(dev_col)?.parse::<f64>().ok()?,
            ))
        })
        .fold((0, f64::MIN), |a, b| if b.1 > a.1 { b } else { a });
    assert_eq!(worst_line, 29, "{table}");
    assert!(total.contains(&format!("29 ({worst_dev:.5})")), "{total}");
    assert!(table.lines().any(|l| l.starts_with("geometric ")));
    assert!(
        table
            .lines()
            .any(|l| l.starts_with("  line 29 ") && l.ends_with("rapid     N210 G54 G0 X80. Y55.")),
        "{table}"
    );
    // Aligned: every row line has the header's length.
    let header_len = table.lines().next().map_or(0, str::len);
    assert!(
        table
            .lines()
            .skip(1)
            .take(PART_ROWS)
            .all(|l| l.len() == header_len)
    );

    let csv = drilling_report("csv");
    let mut lines = csv.lines();
    let header = lines.next().expect("header");
    assert_eq!(
        header,
        "line,motion,X_mm,Y_mm,Z_mm,dx_mm,dy_mm,dz_mm,dev_mm,kinematic_mm,thermal_mm,gravity_mm,process_mm,dynamic_mm,orient_urad"
    );
    let data: Vec<&str> = csv
        .lines()
        .skip(1)
        .filter(|l| !l.starts_with('#'))
        .collect();
    assert_eq!(data.len(), drilling_moves());
    for row in &data {
        assert_eq!(row.split(',').count(), 15, "{row}");
    }
    // The process-move headline (a drilling program: the moves under
    // thrust), the summary and the provenance comment lines.
    let tail: Vec<&str> = csv.lines().rev().take(3).collect();
    assert!(tail[2].starts_with("# process moves ("), "{csv}");
    assert!(tail[1].starts_with("# summary:"), "{csv}");
    assert!(
        tail[0].starts_with("# provenance: postproc ") && tail[0].contains("abb-irb1600.yaml"),
        "{csv}"
    );

    let rapid_table = drilling_report("table");
    for effect in ["total", "kinematic", "gravity", "process"] {
        assert!(
            rapid_table
                .lines()
                .any(|l| l.starts_with(&format!("{effect} "))),
            "{effect}: {rapid_table}"
        );
    }
}

/// Points of the `points` attribute of a polyline.
fn polyline_points(n: &roxmltree::Node) -> usize {
    n.attribute("points")
        .map_or(0, |p| p.split_whitespace().count())
}

#[test]
fn svg_report_is_xml_with_the_toolpath_and_is_deterministic() {
    let svg = part_report("svg");
    let doc = roxmltree::Document::parse(&svg).expect("SVG parses as XML");
    assert_eq!(doc.root_element().tag_name().name(), "svg");
    let polylines: Vec<roxmltree::Node> = doc
        .descendants()
        .filter(|n| n.tag_name().name() == "polyline")
        .collect();
    assert!(!polylines.is_empty());
    // The toolpath is drawn twice (plan and side view) from the 54 rows:
    // 53 segments each, plus the 54-point deviation curve.
    let points: usize = polylines.iter().map(polyline_points).sum();
    assert!(points >= 2 * 54 + 54, "{points} polyline points");
    let text: String = svg_texts(doc.root_element());
    for label in [
        "Plan view (XY)",
        "Side view (XZ)",
        "X (mm)",
        "Z (mm)",
        "source line",
        "max, line 29",
    ] {
        assert!(text.contains(label), "{label} missing in {text}");
    }
    // The worst cutting block (not a rapid or G28 move) is circled and
    // named: found independently from the JSON rows.
    let v: serde_json::Value = serde_json::from_str(&part_report("json")).expect("JSON");
    let cut = v["rows"]
        .as_array()
        .expect("rows")
        .iter()
        .filter(|r| !matches!(r["motion"].as_str(), Some("rapid" | "fixed")))
        .map(|r| {
            (
                r["line"].as_u64().unwrap_or(0),
                r["dev_mm"].as_f64().unwrap_or(0.0),
            )
        })
        .fold((0, 0.0), |a, b| if b.1 > a.1 { b } else { a });
    assert!(
        text.contains(&format!("max cutting, line {}", cut.0)),
        "{text}"
    );
    // Same bytes on a second run.
    assert_eq!(svg, part_report("svg"));

    // RAPID too, written with -o.
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("drilling.svg");
    let m = repo("samples/drilling.mod");
    run(&[
        "report",
        m.to_str().expect("utf-8 path"),
        "--machine",
        "abb-irb1600",
        "--format",
        "svg",
        "-o",
        out.to_str().expect("utf-8 path"),
    ]);
    let svg = std::fs::read_to_string(&out).expect("svg written");
    let doc = roxmltree::Document::parse(&svg).expect("SVG parses as XML");
    assert!(doc.descendants().any(|n| n.tag_name().name() == "polyline"));
}

#[test]
fn svg_of_a_long_program_is_decimated() {
    // 20 000 feed moves: the picture keeps at most 2 × 4000 points per view,
    // so the SVG stays far below one polyline point per block × 3 views.
    let dir = tempfile::tempdir().expect("temp dir");
    let p = dir.path().join("long.nc");
    let mut text = String::from("G90 G54 G0 X10 Y10 Z150\nG1 F1000\n");
    for i in 0..20_000 {
        let x = 10.0 + (i % 200) as f64;
        let y = 10.0 + (i / 200) as f64;
        text.push_str(&format!("X{x} Y{y}\n"));
    }
    std::fs::write(&p, text).expect("write program");
    let svg = run(&[
        "report",
        p.to_str().expect("utf-8 path"),
        "--machine",
        "afm-r1000",
        "--format",
        "svg",
        "--effects",
        "none",
    ]);
    let doc = roxmltree::Document::parse(&svg).expect("SVG parses as XML");
    let points: usize = doc
        .descendants()
        .filter(|n| n.tag_name().name() == "polyline")
        .map(|n| polyline_points(&n))
        .sum();
    assert!(points > 1000, "{points}");
    // Five series of at most 2 × 4001 kept points: plan and side view,
    // the deviation along the program, and the before/after panel's two.
    assert!(points <= 5 * 2 * 4001 + 200, "{points}");
}

#[test]
fn compensate_report_format_follows_the_extension() {
    let dir = tempfile::tempdir().expect("temp dir");
    let d = |n: &str| dir.path().join(n).to_str().expect("utf-8 path").to_string();
    let part = repo("samples/part.nc");
    run(&[
        "compensate",
        part.to_str().expect("utf-8 path"),
        "--machine",
        "afm-r1000",
        "-o",
        &d("part.comp.nc"),
        "--report",
        &d("part.json"),
    ]);
    validate(&std::fs::read_to_string(dir.path().join("part.json")).expect("json report"));
    // --report-format overrides the extension.
    run(&[
        "compensate",
        part.to_str().expect("utf-8 path"),
        "--machine",
        "afm-r1000",
        "-o",
        &d("part2.comp.nc"),
        "--report",
        &d("part.rep"),
        "--report-format",
        "table",
    ]);
    let table = std::fs::read_to_string(dir.path().join("part.rep")).expect("table report");
    assert!(table.contains("summary: 54 rows"));
    // RAPID: the report is written beside the compensated module.
    let m = repo("samples/drilling.mod");
    run(&[
        "compensate",
        m.to_str().expect("utf-8 path"),
        "--machine",
        "abb-irb1600",
        "-o",
        &d("drilling.comp.mod"),
        "--report",
        &d("drilling.svg"),
    ]);
    assert!(dir.path().join("drilling.comp.mod").exists());
    let svg = std::fs::read_to_string(dir.path().join("drilling.svg")).expect("svg report");
    roxmltree::Document::parse(&svg).expect("SVG parses as XML");
}

#[test]
fn rapid_report_rejects_gcode_options() {
    let m = repo("samples/drilling.mod");
    postproc()
        .args(["report"])
        .arg(m)
        .args(["--machine", "abb-irb1600", "--tool", "H1=100"])
        .assert()
        .code(2);
}

#[test]
fn compensate_refuses_a_report_path_that_would_replace_a_program() {
    let dir = tempfile::tempdir().expect("temp dir");
    let input = dir.path().join("p.nc");
    std::fs::copy(repo("samples/part.nc"), &input).expect("copy sample");
    let before = std::fs::read(&input).expect("read");
    let out = dir.path().join("p.comp.nc");
    for report in [&input, &out] {
        postproc()
            .arg("compensate")
            .arg(&input)
            .args(["--machine", "afm-r1000", "-o"])
            .arg(&out)
            .arg("--report")
            .arg(report)
            .assert()
            .code(2);
    }
    assert_eq!(std::fs::read(&input).expect("read"), before);
    assert!(!out.exists());
}

/// Widest line of the text report, characters.
const TABLE_COLUMNS: usize = 120;

fn report_of(program: &str, machine: &str, format: &str) -> String {
    let p = repo(program);
    run(&[
        "report",
        p.to_str().expect("utf-8 path"),
        "--machine",
        machine,
        "--format",
        format,
    ])
}

#[test]
fn text_report_fits_120_columns_and_csv_json_keep_every_column() {
    // The five-axis machines have the widest tables (two rotary columns).
    for (program, machine) in [
        ("samples/five-axis.nc", "five-axis-ac"),
        ("samples/head-table.nc", "head-table-bc"),
    ] {
        for l in report_of(program, machine, "table").lines() {
            assert!(
                l.chars().count() <= TABLE_COLUMNS,
                "{program}: {} characters: {l}",
                l.chars().count()
            );
        }
    }
    for (program, machine) in [
        ("samples/part.nc", "afm-r1000"),
        ("samples/drilling.mod", "abb-irb1600"),
        ("samples/milling.mod", "abb-irb1600"),
    ] {
        let table = report_of(program, machine, "table");
        for l in table.lines() {
            assert!(
                l.chars().count() <= TABLE_COLUMNS,
                "{program}: {} characters: {l}",
                l.chars().count()
            );
        }
        // Every table column is a CSV column of the same name, and the
        // values agree row by row.
        let csv = report_of(program, machine, "csv");
        let csv_header: Vec<&str> = csv.lines().next().unwrap_or("").split(',').collect();
        let table_header: Vec<&str> = table
            .lines()
            .next()
            .unwrap_or("")
            .split_whitespace()
            .collect();
        for h in &table_header {
            assert!(csv_header.contains(h), "{program}: {h} not in CSV");
        }
        let csv_rows: Vec<Vec<&str>> = csv
            .lines()
            .skip(1)
            .filter(|l| !l.starts_with('#'))
            .map(|l| l.split(',').collect())
            .collect();
        let table_rows: Vec<Vec<&str>> = table
            .lines()
            .skip(1)
            .take(csv_rows.len())
            .map(|l| l.split_whitespace().collect())
            .collect();
        assert_eq!(table_rows.len(), csv_rows.len(), "{program}");
        let dev_t = table_header
            .iter()
            .position(|h| *h == "dev_mm")
            .expect("dev_mm");
        let dev_c = csv_header
            .iter()
            .position(|h| *h == "dev_mm")
            .expect("dev_mm");
        for (t, c) in table_rows.iter().zip(&csv_rows) {
            assert_eq!(t.first(), c.first(), "{program}: same line");
            assert_eq!(t.get(dev_t), c.get(dev_c), "{program}: same dev_mm");
        }
        // The columns left out of the table are in CSV and JSON.
        let json: serde_json::Value =
            serde_json::from_str(&report_of(program, machine, "json")).expect("JSON report");
        let row = &json["rows"][0];
        for col in ["dx_mm", "dy_mm", "dz_mm", "orient_urad"] {
            assert!(csv_header.contains(&col), "{program}: {col} not in CSV");
            assert!(
                !table_header.contains(&col),
                "{program}: {col} in the table"
            );
        }
        assert_eq!(row["deviation_mm"].as_array().map(Vec::len), Some(3));
        assert!(row["orient_urad"].is_number(), "{row}");
        if program.ends_with(".nc") {
            assert!(csv_header.contains(&"residual_mm"));
            assert!(!table_header.contains(&"residual_mm"));
            assert!(row["residual_mm"].is_number(), "{row}");
        }
        // Every format says what the positions are.
        let (frame, label) = if program.ends_with(".nc") {
            ("machine", "positions: machine coordinates")
        } else {
            ("world", "positions: programmed TCP, world frame")
        };
        assert_eq!(json["positions"], frame, "{program}");
        assert!(table.lines().any(|l| l.starts_with(label)), "{table}");
        assert!(
            csv.lines().any(|l| l.starts_with(&format!("# {label}"))),
            "{csv}"
        );
        // The provenance is a block of `key: value` lines.
        assert!(table.lines().any(|l| l == "provenance:"), "{table}");
        assert!(
            table
                .lines()
                .any(|l| l.starts_with("  machine sha256: ") && l.len() == 18 + 64),
            "{table}"
        );
    }
}

/// Points `(x, y)` of the polyline of the SVG group with this id.
fn series(doc: &roxmltree::Document, id: &str) -> Option<Vec<(f64, f64)>> {
    let g = doc.descendants().find(|n| n.attribute("id") == Some(id))?;
    let line = g.children().find(|n| n.tag_name().name() == "polyline")?;
    line.attribute("points")?
        .split_whitespace()
        .map(|p| {
            let (x, y) = p.split_once(',')?;
            Some((x.parse().ok()?, y.parse().ok()?))
        })
        .collect()
}

/// The CSV rows of a report as maps from column name to cell.
fn csv_rows(csv: &str) -> Vec<std::collections::HashMap<String, String>> {
    let mut lines = csv.lines().filter(|l| !l.starts_with('#'));
    let header: Vec<&str> = lines.next().unwrap_or("").split(',').collect();
    lines
        .map(|l| {
            header
                .iter()
                .zip(l.split(','))
                .map(|(h, c)| (h.to_string(), c.to_string()))
                .collect()
        })
        .collect()
}

/// A cutting move: neither a rapid, a move to a machine-defined place nor
/// a robot joint move.
fn cutting(motion: &str) -> bool {
    !matches!(motion, "rapid" | "fixed" | "MoveJ" | "MoveAbsJ")
}

/// Pixels the before/after points may be off the common scale: the
/// CSV's 5-decimal rounding and the SVG's 1-decimal coordinates.
const PIXEL_TOL: f64 = 0.5;

/// Floor of the before/after panel's logarithmic axis, mm (1 nm).
const LOG_FLOOR_MM: f64 = 1e-6;

#[test]
fn svg_before_after_panel_has_a_point_per_cutting_move_on_one_scale() {
    let svg = part_report("svg");
    let doc = roxmltree::Document::parse(&svg).expect("SVG parses as XML");
    let panel = doc
        .descendants()
        .find(|n| n.attribute("id") == Some("before-after"))
        .expect("before/after panel");
    let legend: String = svg_texts(panel);
    assert!(legend.contains("before compensation"), "{legend}");
    assert!(legend.contains("after compensation"), "{legend}");
    let text: String = svg_texts(doc.root_element());
    for label in [
        "before and after compensation",
        "deviation (mm)",
        "source line (cutting moves)",
    ] {
        assert!(text.contains(label), "{label} missing in {text}");
    }
    let before = series(&doc, "before-after-before").expect("before series");
    let after = series(&doc, "before-after-after").expect("after series");
    // The cutting moves of the same run, from its CSV report.
    let rows: Vec<_> = csv_rows(&part_report("csv"))
        .into_iter()
        .filter(|r| cutting(&r["motion"]))
        .collect();
    let value = |r: &std::collections::HashMap<String, String>, k: &str| -> f64 {
        r[k].parse().expect("number")
    };
    assert_eq!(before.len(), rows.len());
    assert_eq!(after.len(), rows.len());
    // One logarithmic scale (1 nm and below on its floor): pixel height
    // is linear in log10 of the deviation, fitted on the before series'
    // smallest and largest values, and holds for both.
    let lg = |v: f64| v.max(LOG_FLOOR_MM).log10();
    let (lo, hi) =
        rows.iter()
            .zip(&before)
            .fold(((f64::MAX, 0.0), (f64::MIN, 0.0)), |(lo, hi), (r, p)| {
                let d = lg(value(r, "dev_mm"));
                (
                    if d < lo.0 { (d, p.1) } else { lo },
                    if d > hi.0 { (d, p.1) } else { hi },
                )
            });
    assert!(hi.0 > lo.0, "deviations vary");
    let per_mm = (hi.1 - lo.1) / (hi.0 - lo.0);
    let y_of = |v: f64| lo.1 + (v - lo.0) * per_mm;
    assert!(per_mm < 0.0, "larger deviations are higher up");
    let mut helped = 0;
    for ((r, b), a) in rows.iter().zip(&before).zip(&after) {
        let (dev, residual) = (value(r, "dev_mm"), value(r, "residual_mm"));
        assert_eq!(a.0, b.0, "line {}: same abscissa", r["line"]);
        assert!(
            (b.1 - y_of(lg(dev))).abs() <= PIXEL_TOL,
            "line {}",
            r["line"]
        );
        // A residual printed with fewer than two significant digits is too
        // coarse for a logarithmic check, except zero (on the floor).
        // The fit's error grows with the distance extrapolated beyond the
        // before series' range (its ends' coordinates are rounded).
        if residual == 0.0 || residual >= 1e-4 {
            let reach = 1.0 + (lg(residual) - lo.0).abs() / (hi.0 - lo.0);
            assert!(
                (a.1 - y_of(lg(residual))).abs() <= PIXEL_TOL * reach,
                "line {}: {} vs {}",
                r["line"],
                a.1,
                y_of(lg(residual))
            );
        }
        // Where the compensation is expected to help (residual clearly
        // below the deviation), the after point is lower on the page.
        if residual < dev / 2.0 {
            helped += 1;
            assert!(a.1 > b.1, "line {}: {a:?} not below {b:?}", r["line"]);
        }
    }
    assert!(helped > rows.len() / 2, "{helped} of {}", rows.len());
    // Program order along the x axis.
    assert!(before.windows(2).all(|w| w[0].0 < w[1].0));

    // A robot program: the before series only (no residual is reported).
    let svg = drilling_report("svg");
    let doc = roxmltree::Document::parse(&svg).expect("SVG parses as XML");
    let cuts = csv_rows(&drilling_report("csv"))
        .iter()
        .filter(|r| cutting(&r["motion"]))
        .count();
    assert_eq!(
        series(&doc, "before-after-before").map(|s| s.len()),
        Some(cuts)
    );
    assert!(series(&doc, "before-after-after").is_none());
    // In its place each robot effect's part along the program.
    for effect in ["kinematic", "thermal", "gravity", "process", "dynamic"] {
        assert_eq!(
            series(&doc, &format!("before-after-part-{effect}")).map(|s| s.len()),
            Some(cuts),
            "{effect}"
        );
    }
}

/// The texts under `node` of an SVG, joined with `|`.
fn svg_texts(node: roxmltree::Node) -> String {
    node.descendants()
        .filter(|n| n.tag_name().name() == "text")
        .filter_map(|n| n.text())
        .collect::<Vec<_>>()
        .join("|")
}

/// The joint-interpolated instructions of the motion table (`MoveJDO`,
/// `MoveJSync`, `TriggJ`, …) are positioning moves in the report's groups,
/// as `MoveJ` is; the linear ones (`MoveLDO`, `ArcL`) are cutting moves.
#[test]
fn joint_moves_of_every_spelling_are_grouped_as_positioning() {
    let dir = tempfile::tempdir().expect("tempdir");
    let module = "MODULE Cell\n\
  PERS tooldata tG := [TRUE,[[0,0,150],[1,0,0,0]],[1,[0,0,60],[1,0,0,0],0,0,0]];\n\
  CONST robtarget pA := [[700,-100,600],[0,0,1,0],[-1,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n\
  CONST robtarget pB := [[760,80,520],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n\
  CONST robtarget pC := [[820,40,480],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n\
  PROC main()\n\
    MoveJDO pA, v1000, z50, tG, doGrip, 1;\n\
    MoveLDO pB, v100, fine, tG, doGrip, 0;\n\
    MoveJ pC, v1000, z50, tG;\n\
    MoveL pA, v100, fine, tG;\n\
  ENDPROC\n\
ENDMODULE\n";
    let path = crate::common::write(dir.path(), "cell.mod", module);
    let v = validate(&run(&[
        "report",
        path.to_str().expect("utf-8 path"),
        "--machine",
        "abb-irb1600",
        "--format",
        "json",
    ]));
    let s = &v["summary"];
    let lines = |group: &str| -> Vec<u64> {
        s[group]["worst"]
            .as_array()
            .expect("worst list")
            .iter()
            .map(|w| w["line"].as_u64().expect("line"))
            .collect::<std::collections::BTreeSet<u64>>()
            .into_iter()
            .collect()
    };
    assert_eq!(s["positioning"]["moves"], 2, "{s}");
    assert_eq!(s["cutting"]["moves"], 2, "{s}");
    assert_eq!(lines("positioning"), [7, 9], "{s}");
    assert_eq!(lines("cutting"), [8, 10], "{s}");
}

/// The report schema's `motion` values name every instruction of the
/// motion table, so a report of any module that parses validates.
#[test]
fn the_report_schema_knows_every_motion_instruction() {
    use postproc::program::rapid::instructions::MOTION_INSTRUCTIONS;
    let schema: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(repo("schemas/report.schema.json")).expect("schema file"),
    )
    .expect("schema is JSON");
    let motions: Vec<&str> = schema["$defs"]["row"]["properties"]["motion"]["enum"]
        .as_array()
        .expect("motion enum")
        .iter()
        .filter_map(|m| m.as_str())
        .collect();
    for m in MOTION_INSTRUCTIONS {
        assert!(motions.contains(&m.name), "{} not in the schema", m.name);
    }
}

/// The JSON report of a program of several modules (the controller-backup
/// sample) validates, and its rows, worst blocks and maxima name their
/// module file.
#[test]
fn a_program_report_in_json_names_the_module_of_every_line() {
    let o = postproc()
        .args(["report", "--machine"])
        .arg(repo("machines/abb-irb1600.yaml"))
        .args(["--effects", "kinematic", "--format", "json"])
        .arg(repo("samples/cell-backup/RAPID/TASK1"))
        .output()
        .expect("run");
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let v = validate(&String::from_utf8(o.stdout).expect("utf-8"));
    let rows = v["rows"].as_array().expect("rows");
    assert!(!rows.is_empty());
    for row in rows {
        let file = row["file"].as_str().expect("file");
        assert!(file.ends_with(".mod"), "{row}");
    }
    let cutting = &v["summary"]["cutting"];
    let max_file = cutting["max_file"].as_str().expect("max_file");
    let first = &cutting["worst"][0];
    assert_eq!(first["file"].as_str(), Some(max_file));
    assert_eq!(first["line"], cutting["max_line"]);
    // The quoted source is the text of that line of that file.
    let text = std::fs::read_to_string(max_file).expect("module");
    let line = first["line"].as_u64().expect("line") as usize;
    let at = text.lines().nth(line - 1).expect("line").trim();
    assert_eq!(first["source"].as_str(), Some(at));
}

/// A controller backup in a batch with reports: the task folder's report
/// lands beside the task's output folder (`out/RAPID/TASK1.report.csv`),
/// whose parent the batch makes, in every report format.
#[test]
fn batch_of_a_backup_writes_the_task_report() {
    for (format, ext) in [("csv", "csv"), ("svg", "svg"), ("html", "html")] {
        let dir = tempfile::tempdir().expect("tempdir");
        let out = dir.path().join("out");
        let a = postproc()
            .args(["batch", "--machine", "abb-irb1600", "--out-dir"])
            .arg(&out)
            .arg(repo("samples/cell-backup"))
            .args(["--report-format", format])
            .assert();
        let o = a.get_output();
        assert_eq!(
            o.status.code(),
            Some(0),
            "{format}: {}",
            String::from_utf8_lossy(&o.stdout)
        );
        let report = out.join(format!("RAPID/TASK1.report.{ext}"));
        let text = std::fs::read_to_string(&report)
            .unwrap_or_else(|e| panic!("{format}: no report {} ({e})", report.display()));
        assert!(text.contains("MainModule.mod"), "{format}: {text:.200}");
        assert!(out.join("RAPID/TASK1/PROGMOD/MainModule.mod").is_file());
    }
}
