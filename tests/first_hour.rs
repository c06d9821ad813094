//! Rough edges a newcomer meets in the first hour, each pinned: a closed
//! pipe ends a command quietly with exit 0, the release profile strips
//! debug information while a profiling profile keeps line tables, the
//! travel is checked with any effects, and the others below.

use std::io::Read;
use std::process::{Command, Stdio};

use crate::common::{postproc, repo};

/// `postproc calibrate … | head -1`: the reader closes the pipe before the
/// report is written; the run ends with exit 0 and says nothing.
#[test]
fn a_closed_pipe_ends_the_run_quietly_with_exit_0() {
    let dir = tempfile::tempdir().expect("temp dir");
    let bin = postproc().get_program().to_owned();
    let mut child = Command::new(bin)
        .args(["calibrate", "stiffness", "--machine"])
        .arg(repo("machines/abb-irb1600.yaml"))
        .arg("--observations")
        .arg(repo("samples/observations/irb1600-ldbb-measured.csv"))
        .arg("-o")
        .arg(dir.path().join("c.yaml"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("runs");
    // Closed before the calibration (a fraction of a second) prints.
    drop(child.stdout.take());
    let mut err = String::new();
    child
        .stderr
        .take()
        .expect("stderr")
        .read_to_string(&mut err)
        .expect("stderr text");
    let status = child.wait().expect("exits");
    assert_eq!(status.code(), Some(0), "{err}");
    assert!(!err.contains("error"), "{err}");
    assert!(!err.contains("Broken pipe"), "{err}");
}

#[test]
fn release_builds_strip_debug_information_and_profiling_keeps_it() {
    let manifest: toml_like::Profiles =
        toml_like::profiles(&std::fs::read_to_string(repo("Cargo.toml")).expect("Cargo.toml"));
    let release = manifest.get("release").expect("a release profile");
    assert_eq!(release.get("debug").map(String::as_str), Some("false"));
    assert_eq!(
        release.get("strip").map(String::as_str),
        Some("\"debuginfo\"")
    );
    let profiling = manifest.get("profiling").expect("a profiling profile");
    assert_eq!(
        profiling.get("inherits").map(String::as_str),
        Some("\"release\"")
    );
    assert_eq!(profiling.get("debug").map(String::as_str), Some("1"));
}

/// The `[profile.NAME]` tables of a Cargo manifest as key → raw value.
mod toml_like {
    use std::collections::BTreeMap;

    pub type Profiles = BTreeMap<String, BTreeMap<String, String>>;

    pub fn profiles(text: &str) -> Profiles {
        let mut out = Profiles::new();
        let mut current: Option<String> = None;
        for line in text.lines().map(str::trim) {
            if line.starts_with('[') {
                current = line
                    .strip_prefix("[profile.")
                    .and_then(|l| l.strip_suffix(']'))
                    .map(str::to_string);
                continue;
            }
            if let (Some(p), Some((k, v))) = (&current, line.split_once('=')) {
                if !line.starts_with('#') {
                    out.entry(p.clone())
                        .or_default()
                        .insert(k.trim().to_string(), v.trim().to_string());
                }
            }
        }
        out
    }
}

/// A G-code program given a robot's machine file is named as such, for
/// every command that takes a program (the RAPID parser's "expected
/// `MODULE name`" was the message).
#[test]
fn a_gcode_program_on_a_robot_is_named_as_a_language_mismatch() {
    let part = repo("samples/part.nc");
    for args in [
        vec!["report", "--machine", "abb-irb1600"],
        vec!["check", "--machine", "abb-irb1600"],
        vec!["compensate", "--machine", "abb-irb1600", "-o", "never.nc"],
    ] {
        let a = postproc().args(&args).arg(&part).assert().code(2);
        let err = String::from_utf8_lossy(&a.get_output().stderr).to_string();
        assert!(
            err.contains("part.nc: is a G-code program")
                && err.contains("abb-irb1600.yaml (bundled) is a robot"),
            "{args:?}: {err}"
        );
        assert!(!err.contains("MODULE"), "{err}");
    }
}

/// Every subcommand's `--help` says how to call it with what it needs
/// (`--machine` where the run needs one) and lists its exit codes.
#[test]
fn every_help_has_its_usage_and_exit_codes() {
    let needs_machine = [
        "compensate",
        "report",
        "batch",
        "simulate",
        "calibrate",
        "diagnose",
    ];
    let all = [
        "check",
        "compensate",
        "report",
        "batch",
        "simulate",
        "calibrate",
        "diagnose",
        "machines",
        "completions",
        "man",
    ];
    for sub in all {
        let a = postproc().args([sub, "--help"]).assert().success();
        let help = String::from_utf8_lossy(&a.get_output().stdout).to_string();
        let usage = help
            .lines()
            .find(|l| l.starts_with("Usage: "))
            .unwrap_or_else(|| panic!("{sub}: no usage line in {help}"));
        assert!(usage.contains(&format!("postproc {sub}")), "{usage}");
        if needs_machine.contains(&sub) {
            assert!(usage.contains("--machine <MACHINE>"), "{sub}: {usage}");
        }
        assert!(
            help.contains("Exit codes: 0 "),
            "{sub}: no exit codes in\n{help}"
        );
    }
}

/// `postproc completions SHELL` and `postproc man` print what the shells
/// and `man` read, generated from the flags themselves.
#[test]
fn completions_and_man_page_are_generated_from_the_flags() {
    let a = postproc().args(["completions", "bash"]).assert().success();
    let bash = String::from_utf8_lossy(&a.get_output().stdout).to_string();
    assert!(bash.contains("_postproc()"), "{bash:.200}");
    for flag in ["--machine", "--report-format", "--merge-summaries"] {
        assert!(bash.contains(flag), "bash completion lacks {flag}");
    }
    let a = postproc().args(["completions", "zsh"]).assert().success();
    assert!(String::from_utf8_lossy(&a.get_output().stdout).starts_with("#compdef postproc"));
    postproc().args(["completions", "tcsh"]).assert().code(2);
    let a = postproc().arg("man").assert().success();
    let man = String::from_utf8_lossy(&a.get_output().stdout).to_string();
    assert!(man.contains(".TH postproc 1"), "{man:.200}");
    assert!(
        man.contains(".TH postproc-compensate 1"),
        "a page per subcommand"
    );
    assert!(man.contains("\\-\\-machine"), "flags are listed");
}

/// `--effects none` still checks every programmed position against the
/// travel (nothing is solved, so the solver's check does not run): X1150
/// on a 0–1000 axis is refused with exit 2 and no output file.
#[test]
fn the_travel_is_checked_with_every_effect_off() {
    let dir = tempfile::tempdir().expect("temp dir");
    let program = crate::common::write(
        dir.path(),
        "far.nc",
        "G21 G90 G54\nG0 X0. Y0. Z50.\nG1 X1150. F1000.\nM30\n",
    );
    for effects in ["none", "all", "thermal"] {
        let out = dir.path().join(format!("far-{effects}.nc"));
        let a = postproc()
            .args(["compensate", "--machine", "afm-r1000", "--effects", effects])
            .arg(&program)
            .arg("-o")
            .arg(&out)
            .assert()
            .code(2);
        let err = String::from_utf8_lossy(&a.get_output().stderr).to_string();
        assert!(
            err.contains("far.nc:3:1:") && err.contains("is outside the travel [0, 1000]"),
            "--effects {effects}: {err}"
        );
        assert!(!out.exists(), "--effects {effects}: output written");
    }
}

/// `calibrate geometry` on an example machine marks the geometry section
/// calibrated and no other: the file's `status` names each section, the
/// name and the header comment it owns say what changed, and every run
/// with the file still warns of the stiffness, thermal and process-force
/// example values.
#[test]
fn one_calibration_marks_its_section_and_the_warning_names_the_others() {
    let dir = tempfile::tempdir().expect("temp dir");
    let cal = dir.path().join("cal.yaml");
    postproc()
        .env("SOURCE_DATE_EPOCH", "1764028800") // 2025-11-25
        .args([
            "calibrate",
            "geometry",
            "--machine",
            "afm-r1000",
            "--observations",
        ])
        .arg(repo("samples/observations/afm-r1000-grid-measured.csv"))
        .arg("-o")
        .arg(&cal)
        .assert()
        .code(0);
    let text = std::fs::read_to_string(&cal).expect("written");
    assert!(
        text.contains(
            "\nstatus: { geometry: calibrated, stiffness: example, thermal: example, process_force: example }"
        ),
        "{text}"
    );
    assert!(
        text.contains("\nname: AFM R-1000 (example values in stiffness, thermal, process force)\n"),
        "{text}"
    );
    assert!(
        text.starts_with("# AFM R-1000")
            && text.contains(
                "\n# GEOMETRY CALIBRATED 2025-11-25 FROM afm-r1000-grid-measured.csv (the notes below describe the example values it replaced)."
            ),
        "{text}"
    );
    // The process-force comment stays: that section is still an example.
    assert!(
        text.contains("\n# Process effects — EXAMPLE CALIBRATION, NOT MEASURED DATA"),
        "{text}"
    );
    let a = postproc()
        .args(["check", "--machine"])
        .arg(&cal)
        .arg(repo("samples/part.nc"))
        .assert()
        .code(0);
    let err = String::from_utf8_lossy(&a.get_output().stderr).to_string();
    assert!(
        err.contains(
            "cal.yaml: stiffness, thermal, process force still example values, not measured data (geometry calibrated 2025-11-25 from afm-r1000-grid-measured.csv)"
        ),
        "{err}"
    );
}

/// The `postproc` binary's folder, for scripts that call `postproc`.
fn path_with_postproc() -> String {
    let bin = postproc().get_program().to_owned();
    let dir = std::path::Path::new(&bin)
        .parent()
        .expect("bin dir")
        .to_owned();
    format!(
        "{}:{}",
        dir.display(),
        std::env::var("PATH").unwrap_or_default()
    )
}

/// A shared folder as docs/batch.md's cluster examples expect it:
/// `machines/mill-7.yaml` and three programs in `programs/`.
fn cluster_folder() -> tempfile::TempDir {
    let dir = tempfile::tempdir().expect("temp dir");
    std::fs::create_dir_all(dir.path().join("machines")).expect("machines");
    std::fs::create_dir_all(dir.path().join("programs")).expect("programs");
    std::fs::copy(
        repo("machines/afm-r1000.yaml"),
        dir.path().join("machines/mill-7.yaml"),
    )
    .expect("machine");
    for p in [
        "samples/part.nc",
        "samples/gcode/fusion_fanuc.nc",
        "samples/gcode/linuxcnc.ngc",
    ] {
        let name = std::path::Path::new(p).file_name().expect("name");
        std::fs::copy(repo(p), dir.path().join("programs").join(name)).expect("program");
    }
    dir
}

/// Merges the shards' summaries in `dir` as docs/batch.md does and checks
/// that every program was compensated in exactly one shard.
fn merged_covers_every_program(dir: &std::path::Path, merge: &str) {
    let run = Command::new("bash")
        .arg("-c")
        .arg(merge)
        .current_dir(dir)
        .env("PATH", path_with_postproc())
        .output()
        .expect("merge runs");
    let out =
        String::from_utf8_lossy(&run.stdout).to_string() + &String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(0), "{merge}: {out}");
    assert!(
        out.contains("batch: 3 programs: 3 compensated (0 with findings, 0 empty), 0 failed"),
        "{out}"
    );
    for name in ["part.nc", "fusion_fanuc.nc", "linuxcnc.ngc"] {
        let shards = (1..=8)
            .filter(|k| dir.join(format!("out/shard-{k}/{name}")).exists())
            .count();
        assert_eq!(shards, 1, "{name} in {shards} shards");
    }
}

/// docs/batch.md's Slurm array script, run as each of its 8 tasks with
/// the variables Slurm sets (`--array=1-8`), then the merge of its
/// dependent job: `--shard auto` shares the programs out once.
#[test]
fn the_slurm_array_script_of_the_docs_shards_from_the_array_variables() {
    let md = crate::common::text("docs/batch.md");
    let blocks = crate::common::fenced_blocks(&md, "bash");
    let script = blocks
        .iter()
        .find(|b| b.contains("#SBATCH --array=1-8") && b.contains("--shard auto"))
        .expect("the Slurm script in docs/batch.md");
    let submit = blocks
        .iter()
        .find(|b| b.contains("sbatch --dependency"))
        .expect("the submission in docs/batch.md");
    let merge = submit.split('\'').nth(1).expect("the merge command");
    let dir = cluster_folder();
    std::fs::write(dir.path().join("postproc-array.sh"), script).expect("script");
    for k in 1..=8 {
        let run = Command::new("bash")
            .arg("postproc-array.sh")
            .current_dir(dir.path())
            .env("PATH", path_with_postproc())
            .env("SLURM_ARRAY_TASK_ID", k.to_string())
            .env("SLURM_ARRAY_TASK_COUNT", "8")
            .env("SLURM_ARRAY_TASK_MIN", "1")
            .env("SLURM_ARRAY_TASK_MAX", "8")
            .env("SLURM_CPUS_PER_TASK", "1")
            .env_remove("JOB_COMPLETION_INDEX")
            .output()
            .expect("task runs");
        assert_eq!(
            run.status.code(),
            Some(0),
            "task {k}: {}",
            String::from_utf8_lossy(&run.stderr)
        );
    }
    merged_covers_every_program(dir.path(), merge);
}

/// docs/batch.md's Kubernetes indexed Job: the container's command of the
/// manifest, run in its working folder for every index of its
/// `completions`, then the merge.
#[test]
fn the_kubernetes_indexed_job_of_the_docs_shards_from_the_completion_index() {
    let md = crate::common::text("docs/batch.md");
    let manifest = crate::common::fenced_blocks(&md, "yaml")
        .into_iter()
        .find(|b| b.contains("completionMode: Indexed"))
        .expect("the Job in docs/batch.md");
    let job: serde_yaml::Value = serde_yaml::from_str(&manifest).expect("the manifest reads");
    let completions = job["spec"]["completions"].as_u64().expect("completions");
    let container = &job["spec"]["template"]["spec"]["containers"][0];
    assert_eq!(container["workingDir"].as_str(), Some("/data"));
    let command: Vec<&str> = container["command"]
        .as_sequence()
        .expect("command")
        .iter()
        .filter_map(|v| v.as_str())
        .collect();
    assert_eq!(command, ["/bin/sh", "-c"]);
    let args = container["args"][0].as_str().expect("args");
    assert!(
        args.contains(&format!("--shard auto/{completions}")),
        "{args}"
    );
    let dir = cluster_folder();
    for i in 0..completions {
        let run = Command::new(command[0])
            .arg(command[1])
            .arg(args)
            .current_dir(dir.path())
            .env("PATH", path_with_postproc())
            .env("JOB_COMPLETION_INDEX", i.to_string())
            .env_remove("SLURM_ARRAY_TASK_ID")
            .output()
            .expect("pod runs");
        assert_eq!(
            run.status.code(),
            Some(0),
            "index {i}: {}",
            String::from_utf8_lossy(&run.stderr)
        );
    }
    merged_covers_every_program(
        dir.path(),
        "postproc batch --merge-summaries --out-dir out/merged out/shard-*/batch-summary.json",
    );
}

/// The robot report's headline is on the process moves: in
/// `samples/drilling.mod` the moves under drilling thrust, not the
/// `MoveL` approaches and retracts in air (the approach to 2 mm above
/// hole 9 was its "max cutting"); the moves in air join the positioning
/// moves. Without the process effect the linear moves are the headline.
#[test]
fn the_robot_headline_is_on_the_process_moves() {
    let run = postproc()
        .args(["report", "-m", "abb-irb1600", "--format", "json"])
        .arg(repo("samples/drilling.mod"))
        .output()
        .expect("runs");
    let v: serde_json::Value = serde_json::from_slice(&run.stdout).expect("json");
    let rows = v["rows"].as_array().expect("rows");
    let positioning = |m: &str| matches!(m, "MoveJ" | "MoveAbsJ");
    let process = |r: &serde_json::Value| {
        !positioning(r["motion"].as_str().expect("motion"))
            && r["effects_mm"]["process"].as_f64().expect("process part") > 0.0
    };
    let group_max = |under_force: bool| {
        rows.iter()
            .filter(|r| process(r) == under_force)
            .map(|r| {
                (
                    r["dev_mm"].as_f64().expect("dev"),
                    r["line"].as_u64().expect("line"),
                )
            })
            .fold((0.0, 0), |a, b| if b.0 > a.0 { b } else { a })
    };
    let processed = rows.iter().filter(|r| process(r)).count();
    assert!(processed >= 12, "{processed} process moves");
    let (cut_max, cut_line) = group_max(true);
    let (air_max, air_line) = group_max(false);
    let s = &v["summary"];
    assert_eq!(s["cutting"]["max_line"].as_u64(), Some(cut_line));
    assert_eq!(s["cutting"]["max_mm"].as_f64(), Some(cut_max));
    assert_eq!(s["positioning"]["max_line"].as_u64(), Some(air_line));
    assert_eq!(s["positioning"]["max_mm"].as_f64(), Some(air_max));
    let table = postproc()
        .args(["report", "-m", "abb-irb1600"])
        .arg(repo("samples/drilling.mod"))
        .output()
        .expect("runs");
    let text = String::from_utf8_lossy(&table.stdout);
    assert!(
        text.contains(&format!("\nprocess moves ({processed}): "))
            && text.contains(&format!(
                "\npositioning moves and moves in air ({}): ",
                rows.len() - processed
            ))
            && text.contains("\nworst process blocks:\n"),
        "{text}"
    );
    let no_process = postproc()
        .args([
            "report",
            "-m",
            "abb-irb1600",
            "--effects",
            "kinematic,gravity",
        ])
        .arg(repo("samples/drilling.mod"))
        .output()
        .expect("runs");
    let text = String::from_utf8_lossy(&no_process.stdout);
    assert!(text.contains("\ncutting moves ("), "{text}");
}

/// A batch over a folder of both languages compensates the programs of
/// the machine's language and skips each of the others with one line
/// (they were failures, each naming its path twice); a program of the
/// other language named on its own still fails, its path said once.
#[test]
fn a_batch_over_a_mixed_folder_skips_the_other_language_with_one_line() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mixed = dir.path().join("cell");
    std::fs::create_dir_all(&mixed).expect("folder");
    for p in [
        "samples/drilling.mod",
        "samples/part.nc",
        "samples/gcode/linuxcnc.ngc",
    ] {
        let name = std::path::Path::new(p).file_name().expect("name");
        std::fs::copy(repo(p), mixed.join(name)).expect("copy");
    }
    let cases = [
        (
            "abb-irb1600",
            "a G-code program, and the machine is a robot",
            ["linuxcnc.ngc", "part.nc"].as_slice(),
            "batch: 1 programs: 1 compensated",
        ),
        (
            "afm-r1000",
            "a RAPID module, and the machine is a machine tool",
            ["drilling.mod"].as_slice(),
            "batch: 2 programs: 2 compensated",
        ),
    ];
    for (machine, reason, others, totals) in cases {
        let out = dir.path().join(format!("out-{machine}"));
        let a = postproc()
            .args(["batch", "--machine", machine, "--out-dir"])
            .arg(&out)
            .arg(&mixed)
            .assert()
            .code(0);
        let stdout = String::from_utf8_lossy(&a.get_output().stdout).to_string();
        for name in others {
            let line = format!("skipped   {}: {reason}\n", mixed.join(name).display());
            assert_eq!(stdout.matches(&line).count(), 1, "{stdout}");
        }
        assert!(!stdout.contains("failed "), "{stdout}");
        assert!(
            stdout.contains(&format!(
                "{totals} (0 with findings, 0 empty), 0 failed; {} skipped",
                others.len()
            )),
            "{stdout}"
        );
    }
    let part = mixed.join("part.nc");
    let a = postproc()
        .args(["batch", "--machine", "abb-irb1600", "--out-dir"])
        .arg(dir.path().join("out-named"))
        .arg(&part)
        .assert()
        .code(2);
    let stdout = String::from_utf8_lossy(&a.get_output().stdout).to_string();
    assert_eq!(
        stdout.matches(&part.display().to_string()).count(),
        1,
        "{stdout}"
    );
}

/// A compensated robot target written with another confdata than the
/// programmed one is noted with its target and line: the module of
/// tests/conf_off.rs, whose targets under `ConfL \Off` carry a wrong
/// confdata (joints 4 and 6 half a turn off), gets one warning per such
/// target; the last move (`\On`, true confdata) none.
#[test]
fn a_changed_confdata_is_noted_with_its_target_and_line() {
    use postproc::machine::robot::Robot;
    let dir = tempfile::tempdir().expect("temp dir");
    let (name, text) = crate::conf_off::robots()[0].clone();
    let machine = crate::common::write(dir.path(), &format!("{name}.yaml"), &text);
    let robot = crate::conf_off::with_spindle(Robot::from_yaml_str(&text, name).expect("valid"));
    let (src, [ca, cb]) = crate::conf_off::module(&robot, true);
    let input = crate::common::write(dir.path(), "free.mod", &src);
    let a = postproc()
        .args(["compensate", "--effects", "kinematic,gravity", "--machine"])
        .arg(&machine)
        .arg(&input)
        .arg("-o")
        .arg(dir.path().join("free.out.mod"))
        .assert()
        .code(0);
    let err = String::from_utf8_lossy(&a.get_output().stderr).to_string();
    let line_of = |needle: &str| src.lines().position(|l| l.contains(needle)).expect("move") + 1;
    for (target, mv, right) in [("pA", "MoveJ", ca), ("pB", "MoveL", cb)] {
        let at = line_of(&format!("{mv} {target},"));
        let wrong = postproc::machine::robot::ConfData {
            cf4: right.cf4 + 2,
            cf6: right.cf6 - 2,
            ..right
        };
        let want = format!(
            "free.mod:{at}:5: target `{target}` of {mv}: written with confdata {right}, programmed {wrong} (configuration monitoring off"
        );
        assert!(err.contains(&want), "{want}\n{err}");
    }
    assert!(!err.contains("target `pA2`"), "{err}");
}

/// The most decimals of the rewritten linear (X Y Z) and rotary (A C)
/// words of `program` compensated on the five-axis sample machine with
/// `args`, and the compensated text.
fn five_axis_decimals(program: &[u8], args: &[&str]) -> ([usize; 2], String) {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("rot.nc");
    std::fs::write(&input, program).unwrap();
    let a = postproc()
        .args([
            "compensate",
            "--machine",
            "five-axis-ac",
            "--annotate",
            "none",
            "-o",
            "-",
        ])
        .args(args)
        .arg(&input)
        .assert()
        .code(0);
    let out = String::from_utf8_lossy(&a.get_output().stdout).to_string();
    let mut most = [0usize; 2];
    for line in out.lines().filter(|l| !l.starts_with('(')) {
        for word in line.split_whitespace() {
            let Some(letter) = word.chars().next() else {
                continue;
            };
            let Some((_, frac)) = word.split_once('.') else {
                continue;
            };
            let slot = match letter {
                'X' | 'Y' | 'Z' => 0,
                'A' | 'C' => 1,
                _ => continue,
            };
            most[slot] = most[slot].max(frac.len());
        }
    }
    (most, out)
}

/// `--decimals` sets the decimals of the rewritten rotary words too; the
/// sample's own rotary words (`A15.`, `C30.`) are rewritten with the
/// fewest decimals whose rounding (half a unit, at a 500 mm lever arm)
/// stays within a quarter of the tolerance: 0.00005° is 0.44 µm ≤ 0.75 µm
/// at 0.003 mm, 0.0005° would be 4.4 µm; at 0.001 mm (0.25 µm) 4 decimals
/// round by 0.44 µm, 5 by 0.044 µm.
#[test]
fn decimals_sets_the_rotary_words_too() {
    let sample = std::fs::read(repo("samples/five-axis.nc")).unwrap();
    assert_eq!(five_axis_decimals(&sample, &[]).0, [4, 4]);
    assert_eq!(five_axis_decimals(&sample, &["--decimals", "5"]).0, [5, 5]);
    assert_eq!(five_axis_decimals(&sample, &["--decimals", "4"]).0, [4, 4]);
    assert_eq!(
        five_axis_decimals(&sample, &["--tolerance", "0.001"]).0[1],
        5
    );
}

/// Rotary words follow the program's own decimal style: a program
/// writing `A12.5` and `C-90.` gets its corrected rotary words with the
/// trailing zeros dropped and no more decimals than the tolerance needs
/// (not the six of a fixed count), and one writing five decimals keeps
/// its five.
#[test]
fn rotary_words_follow_the_program_s_decimals() {
    let short = b"G21 G90 G17 G94\nG54 G0 X0. Y0. Z100. A0. C0.\nG1 X-40. Y-20. Z40. A12.5 C-90. F1500.\nX40. Y20. A20. C-45.\nM30\n";
    let (most, out) = five_axis_decimals(short, &[]);
    assert_eq!(most[1], 4, "{out}");
    let rotary: Vec<&str> = out
        .lines()
        .filter(|l| !l.starts_with('('))
        .flat_map(|l| l.split_whitespace())
        .filter(|w| w.starts_with('A') || w.starts_with('C'))
        .collect();
    assert!(rotary.len() >= 4, "{out}");
    for w in &rotary {
        // Trailing zeros are dropped (the program's style), never `A12.5000`.
        assert!(!w.ends_with('0') || !w.contains('.'), "{w} in\n{out}");
    }
    // A word the correction moves is rewritten (its value changes).
    assert!(
        !out.contains(" A12.5 ") && !out.contains(" C-90. "),
        "{out}"
    );
    let long = String::from_utf8_lossy(short)
        .replace("A12.5 C-90.", "A12.50000 C-90.00000")
        .into_bytes();
    let (most, out) = five_axis_decimals(&long, &[]);
    assert_eq!(most[1], 5, "{out}");
}

/// `check` lists every error of a program as a compiler does (each bad
/// line is read as blank and the checking goes on), up to a limit, then
/// the warnings; exit 2 when there is any error.
#[test]
fn check_lists_every_error_then_the_warnings() {
    let dir = tempfile::tempdir().expect("temp dir");
    let program = crate::common::write(
        dir.path(),
        "three.nc",
        "G21 G90 G54\nG0 X0. Y0. Z50.\nG1 Z40. F1000.\nG1 X1150.\nG1 X10. ,C2.\nG2 X20. Y10.\nG1 X30. Y5\nM30\n",
    );
    let a = postproc()
        .args(["check", "--machine", "afm-r1000"])
        .arg(&program)
        .assert()
        .code(2);
    let err = String::from_utf8_lossy(&a.get_output().stderr).to_string();
    let out = String::from_utf8_lossy(&a.get_output().stdout).to_string();
    let errors: Vec<&str> = err.lines().filter(|l| l.starts_with("error: ")).collect();
    assert_eq!(errors.len(), 3, "{err}");
    for (e, line) in errors.iter().zip([4, 5, 6]) {
        assert!(
            e.starts_with(&format!("error: {}:{line}:", program.display())),
            "{err}"
        );
    }
    assert!(errors[0].contains("outside the travel"), "{err}");
    assert!(out.contains("\nerrors: 3\n"), "{out}");
    let warnings = out.split("\nwarnings: ").nth(1).expect("warnings");
    assert!(warnings.contains("line 7: "), "{out}");
    // More than the limit: the first 20, and the rest not checked.
    let many: String = (0..25).map(|_| "G1 X10. ,C2.\n").collect();
    let program = crate::common::write(dir.path(), "many.nc", &format!("G21 G90 G54\n{many}M30\n"));
    let a = postproc()
        .args(["check", "--machine", "afm-r1000"])
        .arg(&program)
        .assert()
        .code(2);
    let err = String::from_utf8_lossy(&a.get_output().stderr).to_string();
    assert_eq!(
        err.lines().filter(|l| l.contains(",C")).count(),
        20,
        "{err}"
    );
    assert!(
        err.contains("20 errors shown; the rest of the program is not checked"),
        "{err}"
    );
}

/// The log lines of a run on a terminal (util-linux `script` gives it one),
/// with `NO_COLOR` set to `no_color` or unset.
fn terminal_log(no_color: Option<&str>) -> String {
    let dir = tempfile::tempdir().unwrap();
    let bin = postproc().get_program().to_owned();
    let command = format!(
        "'{}' compensate '{}' --machine afm-r1000 -o '{}'",
        std::path::Path::new(&bin).display(),
        repo("samples/part.nc").display(),
        dir.path().join("part.comp.nc").display()
    );
    let mut run = Command::new("script");
    run.args(["-qec", &command, "/dev/null"])
        .current_dir(dir.path())
        .env_remove("RUST_LOG")
        .env_remove("NO_COLOR");
    if let Some(v) = no_color {
        run.env("NO_COLOR", v);
    }
    let out = run
        .output()
        .expect("util-linux `script` runs the program on a terminal");
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn no_color_turns_the_terminal_s_colours_off() {
    // On a terminal the bundled file's example-values warning is coloured…
    let coloured = terminal_log(None);
    assert!(
        coloured.contains("WARN") && coloured.contains('\u{1b}'),
        "a terminal run colours its warning:\n{coloured}"
    );
    // …and with NO_COLOR set (to anything but empty) it is plain.
    let plain = terminal_log(Some("1"));
    assert!(
        plain.contains("WARN") && !plain.contains('\u{1b}'),
        "NO_COLOR=1 leaves no escape sequence:\n{plain}"
    );
    // An empty NO_COLOR does not count, as no-color.org defines it.
    assert!(terminal_log(Some("")).contains('\u{1b}'));
}
