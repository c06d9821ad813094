//! `postproc batch` through the binary: many generated programs with a few
//! broken ones, exit codes, the summary file, and identical bytes for any
//! thread count.

use std::path::{Path, PathBuf};

use crate::common::{postproc, repo};

/// Programs generated; these indices are broken (one parse error, one
/// `#` parameter, one arc without a centre).
const PROGRAMS: usize = 50;
const BROKEN: [usize; 3] = [7, 23, 41];

/// A small, valid three-axis program: a square pocket pass at a depth that
/// varies with `i`.
fn program(i: usize) -> String {
    let z = 2.0 + (i % 5) as f64;
    let x0 = 20.0 + i as f64;
    format!(
        "%\nO{:04}\nG21 G90 G17\nG54 G0 X{x0} Y20. Z50.\nG43 H1 Z10.\nG1 Z{z} F300.\nX{} Y20.\nY80.\nX{x0}\nY20.\nG0 Z50.\nM30\n%\n",
        1000 + i,
        x0 + 60.0
    )
}

fn broken(i: usize) -> String {
    match i {
        7 => "G0 X10 Y10 Z50\nG1 X@5 F100\n".to_string(),
        23 => "G0 X10 Y10 Z50\nG1 X#1 F100\n".to_string(),
        _ => "G0 X10 Y10 Z50\nG2 X20 Y20 F100\n".to_string(),
    }
}

fn name(i: usize) -> String {
    // Mixed extensions, one sub-folder.
    let ext = ["nc", "ngc", "tap", "gcode", "cnc"][i % 5];
    if i % 10 == 9 {
        format!("sub/p{i:02}.{ext}")
    } else {
        format!("p{i:02}.{ext}")
    }
}

fn make_inputs(dir: &Path) {
    std::fs::create_dir_all(dir.join("sub")).expect("mkdir");
    for i in 0..PROGRAMS {
        let text = if BROKEN.contains(&i) {
            broken(i)
        } else {
            program(i)
        };
        std::fs::write(dir.join(name(i)), text).expect("write program");
    }
    // Not a program: ignored.
    std::fs::write(dir.join("notes.txt"), "not a program\n").expect("write notes");
}

fn batch(input: &Path, out: &Path, threads: &str) -> (i32, String) {
    let a = postproc()
        .args([
            "batch",
            "--machine",
            "afm-r1000",
            "--threads",
            threads,
            "--out-dir",
        ])
        .arg(out)
        .arg(input)
        .output()
        .expect("run batch");
    // stderr is a pipe here: no progress bar (no carriage returns, no bar).
    let stderr = String::from_utf8_lossy(&a.stderr);
    assert!(
        !stderr.contains('\r') && !stderr.contains("programs "),
        "{stderr}"
    );
    (
        a.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&a.stdout).to_string(),
    )
}

/// Every file below `dir`, relative, with its bytes, sorted.
fn tree(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    fn walk(root: &Path, dir: &Path, out: &mut Vec<(PathBuf, Vec<u8>)>) {
        for e in std::fs::read_dir(dir).expect("read dir") {
            let p = e.expect("entry").path();
            if p.is_dir() {
                walk(root, &p, out);
            } else {
                let rel = p.strip_prefix(root).expect("below root").to_path_buf();
                out.push((rel, std::fs::read(&p).expect("read file")));
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, dir, &mut out);
    out.sort();
    out
}

/// Validates a summary against schemas/batch-summary.schema.json.
fn validate(summary: &serde_json::Value) {
    let schema: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(repo("schemas/batch-summary.schema.json")).expect("schema"),
    )
    .expect("schema is JSON");
    let mut schemas = boon::Schemas::new();
    let mut compiler = boon::Compiler::new();
    let url = "https://postproc.example/schemas/batch-summary.schema.json";
    compiler.add_resource(url, schema).expect("schema resource");
    // The provenance object is defined in the report schema.
    let report: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(repo("schemas/report.schema.json")).expect("report schema"),
    )
    .expect("report schema is JSON");
    compiler
        .add_resource(
            "https://postproc.example/schemas/report.schema.json",
            report,
        )
        .expect("report schema resource");
    let idx = compiler
        .compile(url, &mut schemas)
        .expect("schema compiles");
    if let Err(e) = schemas.validate(summary, idx) {
        panic!("summary does not match the schema: {e:#}");
    }
}

#[test]
fn batch_of_fifty_reports_exactly_the_broken_ones_and_is_thread_independent() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let input = tmp.path().join("in");
    make_inputs(&input);
    let (out1, out2) = (tmp.path().join("out1"), tmp.path().join("out2"));
    let (code1, stdout1) = batch(&input, &out1, "1");
    let (code2, _) = batch(&input, &out2, "2");
    // A failed program makes the exit code 2; the others are still written.
    assert_eq!(code1, 2, "{stdout1}");
    assert_eq!(code2, 2);

    let summary: serde_json::Value = serde_json::from_slice(
        &std::fs::read(out1.join("batch-summary.json")).expect("summary written"),
    )
    .expect("summary is JSON");
    validate(&summary);
    assert_eq!(summary["exit_code"], 2);
    assert_eq!(summary["programs"], PROGRAMS);
    assert_eq!(summary["failed"], BROKEN.len());
    assert_eq!(summary["ok"], PROGRAMS - BROKEN.len());
    let results = summary["results"].as_array().expect("results");
    assert_eq!(results.len(), PROGRAMS);
    let mut failed: Vec<String> = results
        .iter()
        .filter(|r| r["status"] == "failed")
        .map(|r| {
            assert!(r["output"].is_null());
            assert!(r["error"].as_str().is_some_and(|e| !e.is_empty()));
            // A failed program has no deviation (not 0).
            assert!(r["max_deviation_mm"].is_null() && r["max_deviation_line"].is_null());
            r["input"].as_str().unwrap_or("").to_string()
        })
        .collect();
    failed.sort();
    let mut expected: Vec<String> = BROKEN
        .iter()
        .map(|&i| input.join(name(i)).display().to_string())
        .collect();
    expected.sort();
    assert_eq!(failed, expected);
    // Sorted by input path.
    let inputs: Vec<&str> = results.iter().filter_map(|r| r["input"].as_str()).collect();
    let mut sorted = inputs.clone();
    sorted.sort();
    assert_eq!(inputs, sorted);
    // The stdout summary names the broken files and counts.
    for f in &expected {
        assert!(stdout1.contains(f.as_str()), "{stdout1}");
    }
    assert!(
        stdout1.contains(
            "batch: 50 programs: 47 compensated (0 with findings, 0 empty), 3 failed; 1 skipped"
        ),
        "{stdout1}"
    );
    // The file that is not a program is listed as skipped.
    let notes = input.join("notes.txt").display().to_string();
    assert_eq!(summary["skipped"][0]["path"], notes.as_str());
    assert!(stdout1.contains(&format!(
        "skipped   {notes}: not a program (by its extension or its first block)"
    )));

    // 47 compensated programs (same relative names) + the summary; no
    // partial or temporary files for the broken ones.
    let files = tree(&out1);
    assert_eq!(files.len(), PROGRAMS - BROKEN.len() + 1);
    for i in (0..PROGRAMS).filter(|i| !BROKEN.contains(i)) {
        let out = std::fs::read_to_string(out1.join(name(i))).expect("compensated program");
        // Compensated: the annotation comment is on the cutting moves.
        assert!(out.contains("(dev "), "{}", name(i));
    }
    // Identical bytes whatever the thread count (summary paths differ only
    // by the output folder name).
    let files2 = tree(&out2);
    assert_eq!(files.len(), files2.len());
    for ((p1, b1), (p2, b2)) in files.iter().zip(&files2) {
        assert_eq!(p1, p2);
        if p1 == Path::new("batch-summary.json") {
            let s1 = String::from_utf8_lossy(b1).replace("out1", "outN");
            let s2 = String::from_utf8_lossy(b2).replace("out2", "outN");
            assert_eq!(s1, s2);
        } else {
            assert_eq!(b1, b2, "{}", p1.display());
        }
    }
}

#[test]
fn batch_exit_codes_success_and_usage() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let input = tmp.path().join("ok.nc");
    std::fs::write(&input, program(1)).expect("write");
    let out = tmp.path().join("out");
    let (code, stdout) = batch(&input, &out, "2");
    assert_eq!(code, 0, "{stdout}");
    assert!(out.join("ok.nc").exists());
    // RAPID modules with a robot.
    let rout = tmp.path().join("rout");
    let a = postproc()
        .args(["batch", "--machine", "abb-irb1600", "--out-dir"])
        .arg(&rout)
        .arg(repo("samples/drilling.mod"))
        .output()
        .expect("run batch");
    assert_eq!(a.status.code(), Some(0));
    assert!(rout.join("drilling.mod").exists());
    // --report-format: a report beside each output, named in the summary.
    let gout = tmp.path().join("gout");
    postproc()
        .args([
            "batch",
            "--machine",
            "afm-r1000",
            "--report-format",
            "json",
            "--out-dir",
        ])
        .arg(&gout)
        .arg(&input)
        .assert()
        .code(0);
    let report = gout.join("ok.nc.report.json");
    let v: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&report).expect("report written")).expect("JSON");
    // program(1) has 8 motion blocks: G0 X Y Z50., G43 H1 Z10., G1 Z, the
    // four sides X, Y, X, Y, and G0 Z50.
    assert_eq!(v["rows"].as_array().map(Vec::len), Some(8));
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(gout.join("batch-summary.json")).expect("summary"))
            .expect("JSON");
    validate(&summary);
    assert_eq!(
        summary["results"][0]["report"],
        report.display().to_string()
    );
    // Usage: no inputs, unknown machine.
    postproc()
        .args(["batch", "--machine", "afm-r1000", "--out-dir"])
        .arg(&out)
        .assert()
        .code(2);
    postproc()
        .args(["batch", "--machine", "no-such-machine", "--out-dir"])
        .arg(&out)
        .arg(&input)
        .assert()
        .code(2);
    // --help lists the exit codes.
    let help = postproc().args(["batch", "--help"]).output().expect("help");
    assert!(String::from_utf8_lossy(&help.stdout).contains("Exit codes: 0"));
}

fn run_batch(args: &[&str]) -> (i32, String, String) {
    let out = postproc().args(args).output().expect("runs");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn summary_of(dir: &Path) -> serde_json::Value {
    let v: serde_json::Value = serde_json::from_slice(
        &std::fs::read(dir.join("batch-summary.json")).expect("summary written"),
    )
    .expect("JSON");
    validate(&v);
    v
}

#[test]
fn shards_cover_every_program_once_and_merge_into_the_whole_batch_summary() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let input = tmp.path().join("in");
    make_inputs(&input);
    let inp = input.to_str().unwrap();
    let whole = tmp.path().join("whole");
    let (code, _, err) = run_batch(&[
        "-q",
        "batch",
        "--machine",
        "afm-r1000",
        "--tool",
        "H1=100",
        "--out-dir",
        whole.to_str().unwrap(),
        inp,
    ]);
    assert_eq!(code, 2, "{err}");
    let mut shard_summaries = Vec::new();
    let mut seen = Vec::new();
    for k in 1..=3 {
        let out = tmp.path().join(format!("shard{k}"));
        let (code, _, err) = run_batch(&[
            "-q",
            "batch",
            "--machine",
            "afm-r1000",
            "--tool",
            "H1=100",
            "--shard",
            &format!("{k}/3"),
            "--out-dir",
            out.to_str().unwrap(),
            inp,
        ]);
        assert!(code == 0 || code == 2, "{err}");
        let s = summary_of(&out);
        assert_eq!(s["shard"]["index"], k);
        for r in s["results"].as_array().unwrap() {
            seen.push(r["input"].as_str().unwrap().to_string());
        }
        shard_summaries.push(out.join("batch-summary.json"));
    }
    // Every program in exactly one shard.
    seen.sort();
    let before = seen.len();
    seen.dedup();
    assert_eq!((before, seen.len()), (PROGRAMS, PROGRAMS));
    // Merged, the shards' summaries are the whole batch's (apart from the
    // output folder names and the list of merged shards).
    let merged = tmp.path().join("merged");
    let mut args = vec![
        "batch",
        "--merge-summaries",
        "--out-dir",
        merged.to_str().unwrap(),
    ];
    let paths: Vec<String> = shard_summaries
        .iter()
        .map(|p| p.display().to_string())
        .collect();
    args.extend(paths.iter().map(String::as_str));
    let (code, stdout, err) = run_batch(&args);
    assert_eq!(code, 2, "{err}");
    assert!(
        stdout.contains("batch: 50 programs: 47 compensated"),
        "{stdout}"
    );
    let mut m = summary_of(&merged);
    let mut w = summary_of(&whole);
    assert_eq!(m["merged"].as_array().unwrap().len(), 3);
    m["merged"] = serde_json::Value::Null;
    w["merged"] = serde_json::Value::Null;
    let strip = |v: &serde_json::Value| {
        let text = v.to_string();
        let mut t = text.clone();
        for k in 1..=3 {
            t = t.replace(&format!("shard{k}"), "OUT");
        }
        t.replace("whole", "OUT")
    };
    assert_eq!(strip(&m), strip(&w));
    // A shard given twice is refused.
    let (code, _, err) = run_batch(&[
        "batch",
        "--merge-summaries",
        "--out-dir",
        merged.to_str().unwrap(),
        &paths[0],
        &paths[0],
    ]);
    assert_eq!(code, 2);
    assert!(err.contains("given twice"), "{err}");
    // A bad shard spec is a usage error.
    let (code, _, err) = run_batch(&[
        "batch",
        "--machine",
        "afm-r1000",
        "--shard",
        "4/3",
        "--out-dir",
        merged.to_str().unwrap(),
        inp,
    ]);
    assert_eq!(code, 2);
    assert!(err.contains("for '--shard <K/N|auto[/N]>': `4/3`"), "{err}");
}

#[test]
fn batch_flags_empty_and_compensated_programs_and_lists_each_file_once() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let input = tmp.path().join("in");
    std::fs::create_dir_all(&input).unwrap();
    std::fs::write(input.join("a.nc"), program(1)).unwrap();
    std::fs::write(input.join("empty.nc"), "").unwrap();
    std::fs::write(input.join(".hidden.nc"), program(2)).unwrap();
    // A program compensated before.
    let once = tmp.path().join("once.nc");
    let (code, _, err) = run_batch(&[
        "-q",
        "compensate",
        input.join("a.nc").to_str().unwrap(),
        "-m",
        "afm-r1000",
        "--tool",
        "H1=100",
        "-o",
        once.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    std::fs::copy(&once, input.join("b.nc")).unwrap();
    let out = tmp.path().join("out");
    let a_twice = format!("{}/./a.nc", input.display());
    let (code, stdout, err) = run_batch(&[
        "-q",
        "batch",
        "--machine",
        "afm-r1000",
        "--tool",
        "H1=100",
        "--out-dir",
        out.to_str().unwrap(),
        input.to_str().unwrap(),
        &a_twice,
    ]);
    assert_eq!(code, 2, "{err}");
    let s = summary_of(&out);
    let results = s["results"].as_array().unwrap();
    // a.nc once although named twice; b.nc refused; empty.nc flagged.
    let status: Vec<(String, String)> = results
        .iter()
        .map(|r| {
            let p = r["input"].as_str().unwrap();
            let name = Path::new(p)
                .file_name()
                .unwrap()
                .to_string_lossy()
                .into_owned();
            (name, r["status"].as_str().unwrap().to_string())
        })
        .collect();
    assert_eq!(
        status,
        [
            ("a.nc".to_string(), "ok".to_string()),
            ("b.nc".to_string(), "failed".to_string()),
            ("empty.nc".to_string(), "empty".to_string()),
        ],
        "{s:#}"
    );
    assert!(
        results[1]["error"]
            .as_str()
            .unwrap()
            .contains("compensated by postproc"),
        "{s:#}"
    );
    assert_eq!(s["empty"], 1);
    assert!(stdout.contains("empty     "), "{stdout}");
    assert_eq!(s["skipped"][0]["reason"], "hidden");
    assert!(s["provenance"]["machine"]["sha256"].is_string());
    // With --recompensate b.nc is taken.
    let out2 = tmp.path().join("out2");
    let (code, _, err) = run_batch(&[
        "-q",
        "batch",
        "--machine",
        "afm-r1000",
        "--tool",
        "H1=100",
        "--recompensate",
        "--out-dir",
        out2.to_str().unwrap(),
        input.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
}

/// A controller-backup task folder given to `batch` is one program: its
/// changed modules are written into the output folder under the task's
/// name, the others not at all, with one summary entry and one report of
/// every module's moves.
#[test]
fn batch_of_a_task_folder_is_one_program() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("out");
    let task = repo("samples/cell-backup/RAPID/TASK1");
    let m = repo("machines/abb-irb1600.yaml");
    let (code, _, err) = run_batch(&[
        "batch",
        "--machine",
        m.to_str().unwrap(),
        "--effects",
        "kinematic",
        "--annotate",
        "none",
        "--report-format",
        "csv",
        "--out-dir",
        out.to_str().unwrap(),
        task.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let summary = summary_of(&out);
    let files = summary["results"].as_array().expect("results");
    assert_eq!(files.len(), 1, "{summary}");
    let entry = &files[0];
    assert_eq!(entry["input"].as_str(), Some(task.to_str().unwrap()));
    assert_eq!(entry["status"].as_str(), Some("ok"), "{entry}");
    // Only the main module holds moves; the calibration data and the
    // system module are not written.
    let written: Vec<PathBuf> = tree(&out).into_iter().map(|(p, _)| p).collect();
    let main = out.join("TASK1/PROGMOD/MainModule.mod");
    let report = out.join("TASK1.report.csv");
    assert_eq!(
        written,
        [
            PathBuf::from("TASK1/PROGMOD/MainModule.mod"),
            PathBuf::from("TASK1.report.csv"),
            PathBuf::from("batch-summary.json"),
        ],
        "{written:?}"
    );
    // One row per move compensated, each in the main module.
    let rows: Vec<String> = std::fs::read_to_string(&report)
        .expect("report")
        .lines()
        .filter(|l| !l.starts_with('#'))
        .skip(1)
        .map(str::to_string)
        .collect();
    assert_eq!(Some(rows.len() as u64), entry["moves"].as_u64(), "{rows:?}");
    assert!(!rows.is_empty());
    for row in &rows {
        assert!(row.contains("PROGMOD/MainModule.mod,"), "{row}");
    }
    // The written module is a RAPID module of the same name.
    let text = std::fs::read_to_string(&main).expect("main");
    assert!(text.contains("MODULE MainModule"), "{text}");
}

/// A controller backup given whole: each task folder below it is one
/// program, and an earlier compensated output beside a module is passed
/// over.
#[test]
fn batch_of_a_backup_takes_each_task_folder_as_one_program() {
    let dir = tempfile::tempdir().expect("tempdir");
    let backup = dir.path().join("backup");
    let task = backup.join("RAPID/TASK1");
    for sub in ["PROGMOD", "SYSMOD"] {
        std::fs::create_dir_all(task.join(sub)).expect("folders");
        for e in
            std::fs::read_dir(repo("samples/cell-backup/RAPID/TASK1").join(sub)).expect("sample")
        {
            let e = e.expect("entry");
            std::fs::copy(e.path(), task.join(sub).join(e.file_name())).expect("copy");
        }
    }
    std::fs::copy(
        task.join("PROGMOD/MainModule.mod"),
        task.join("PROGMOD/MainModule.comp.mod"),
    )
    .expect("an earlier output");
    let out = dir.path().join("out");
    let m = repo("machines/abb-irb1600.yaml");
    let (code, _, err) = run_batch(&[
        "batch",
        "--machine",
        m.to_str().unwrap(),
        "--out-dir",
        out.to_str().unwrap(),
        backup.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let summary = summary_of(&out);
    let files = summary["results"].as_array().expect("results");
    assert_eq!(files.len(), 1, "{summary}");
    assert_eq!(files[0]["input"].as_str(), Some(task.to_str().unwrap()));
    assert_eq!(files[0]["status"].as_str(), Some("ok"), "{summary}");
    assert!(out.join("RAPID/TASK1/PROGMOD/MainModule.mod").is_file());
}

/// A shop's program memory copied off a control: files named by their
/// program number, without an extension, are G-code by their first block;
/// a note and a compensated output are passed over.
#[test]
fn batch_takes_programs_without_an_extension_by_their_first_block() {
    let dir = tempfile::tempdir().expect("tempdir");
    let input = dir.path().join("memory");
    std::fs::create_dir_all(&input).expect("folder");
    let program = "%\nO1001 (PLATE)\nG21 G90 G54 G0 X10. Y10. Z50.\nG43 H1 Z5.\nG1 Z-1. F200.\nX60.\nG0 Z50.\nM30\n%\n";
    std::fs::write(input.join("O1001"), program).expect("program");
    std::fs::write(input.join("notes"), "Clamp the plate at both ends.\n").expect("note");
    std::fs::write(input.join("O1001.comp.nc"), program).expect("an earlier output");
    let out = dir.path().join("out");
    let m = repo("machines/afm-r1000.yaml");
    let (code, stdout, err) = run_batch(&[
        "batch",
        "--machine",
        m.to_str().unwrap(),
        "--out-dir",
        out.to_str().unwrap(),
        input.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let summary = summary_of(&out);
    let files = summary["results"].as_array().expect("results");
    assert_eq!(files.len(), 1, "{summary}");
    assert_eq!(
        files[0]["input"].as_str(),
        Some(input.join("O1001").to_str().unwrap())
    );
    assert!(out.join("O1001").is_file());
    let skipped = summary["skipped"].as_array().expect("skipped");
    assert_eq!(skipped.len(), 2, "{summary}");
    assert!(
        stdout.contains("a compensated program (*.comp.*)"),
        "{stdout}"
    );
    assert!(
        stdout.contains("not a program (by its extension or its first block)"),
        "{stdout}"
    );
}
