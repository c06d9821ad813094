//! Hostile inputs: regression tests for inputs that could be misread or
//! exhaust resources, and a bounded mutation run (byte mutants of programs,
//! machine files and observation files) checking that every mutant is
//! either processed or refused cleanly. The long run is `scripts/hostile`.

use std::time::{Duration, Instant};

use postproc::machine::Machine;

use crate::common::repo;

mod data;

fn machine_text(name: &str) -> String {
    std::fs::read_to_string(repo(&format!("machines/{name}.yaml"))).unwrap()
}

/// Loads machine text and returns the error message (the load must fail).
fn machine_error(text: &str) -> String {
    match Machine::from_yaml_str(text, "m.yaml") {
        Ok(_) => panic!("accepted:\n{text}"),
        Err(e) => e.to_string(),
    }
}

/// The line number (1-based) of the first line of `text` that starts with
/// `prefix` after `after` lines.
fn line_of(text: &str, prefix: &str, after: usize) -> usize {
    text.lines()
        .enumerate()
        .skip(after)
        .find(|(_, l)| l.starts_with(prefix))
        .map(|(i, _)| i + 1)
        .unwrap_or_else(|| panic!("no line `{prefix}`"))
}

#[test]
fn a_duplicate_tool_is_refused_at_its_second_line() {
    let base = machine_text("afm-r1000");
    let text = base.replace(
        "  2: { length_mm: 75.0 }\n",
        "  2: { length_mm: 75.0 }\n  1: { length_mm: 99.0 }\n",
    );
    let err = machine_error(&text);
    let line = line_of(&text, "  1: { length_mm: 99.0 }", 0);
    assert!(
        err.starts_with(&format!("m.yaml:{line}:3: tools: duplicate key `1`")),
        "{err}"
    );
}

#[test]
fn a_duplicate_work_offset_is_refused() {
    let base = machine_text("afm-r1000");
    let text = base.replace(
        "  G59: [0.0, 0.0, 0.0]\n",
        "  G59: [0.0, 0.0, 0.0]\n  G54: [1.0, 2.0, 3.0]\n",
    );
    let err = machine_error(&text);
    let line = line_of(&text, "  G54: [1.0", 0);
    assert!(
        err.starts_with(&format!(
            "m.yaml:{line}:3: work_offsets_mm: duplicate key `G54`"
        )),
        "{err}"
    );
}

#[test]
fn a_second_error_table_of_the_same_name_is_refused() {
    let base = machine_text("afm-r1000");
    let first = line_of(&base, "      EXX_um:", 0);
    let table: Vec<&str> = base.lines().skip(first - 1).take(4).collect();
    let dup = format!("{}\n", table.join("\n")).replace("2.3, 4.2", "920.0, 4.2");
    let anchor = "      EYX_um:\n";
    let text = base.replacen(anchor, &format!("{dup}{anchor}"), 1);
    let err = machine_error(&text);
    let line = line_of(&text, "      EXX_um:", first);
    assert!(
        err.starts_with(&format!(
            "m.yaml:{line}:7: axes[0].component_errors: duplicate key `EXX_um`"
        )),
        "{err}"
    );
}

#[test]
fn duplicate_keys_are_refused_at_every_level_and_in_robots() {
    let base = machine_text("afm-r1000");
    let text = format!("{base}name: again\n");
    let err = machine_error(&text);
    assert!(err.contains("duplicate key `name`"), "{err}");
    let text = base.replace(
        "  1: { length_mm: 62.5 }",
        "  1: { length_mm: 62.5, length_mm: 70 }",
    );
    let err = machine_error(&text);
    assert!(err.contains("tools.1: duplicate key `length_mm`"), "{err}");
    let robot = machine_text("abb-irb1600");
    let text = format!("{robot}kind: robot\n");
    let err = machine_error(&text);
    assert!(err.contains("duplicate key `kind`"), "{err}");
}

#[test]
fn deep_yaml_nesting_is_refused_quickly() {
    let base = machine_text("afm-r1000");
    for nest in [
        format!("x: {}{}\n", "[".repeat(40_000), "]".repeat(40_000)),
        format!("x: {}{}\n", "{a: ".repeat(20_000), "}".repeat(20_000)),
        format!("x:\n{}1\n", "- ".repeat(20_000)),
        (1..400)
            .map(|i| format!("{}a{i}:\n", " ".repeat(i)))
            .collect::<String>(),
    ] {
        let text = format!("{base}{nest}");
        let start = Instant::now();
        let err = machine_error(&text);
        assert!(
            start.elapsed() < Duration::from_secs(2),
            "{:?}",
            start.elapsed()
        );
        assert!(err.contains("nesting deeper than 32 levels"), "{err}");
    }
}

fn robot_error(from: &str, to: &str) -> String {
    let base = machine_text("abb-irb1600");
    assert!(base.contains(from), "{from}");
    let text = base.replacen(from, to, 1);
    let err = machine_error(&text);
    assert!(err.starts_with("m.yaml:"), "{err}");
    err
}

#[test]
fn robot_values_beyond_plausibility_are_refused_with_their_key_path() {
    let err = robot_error("a_mm: 699.71", "a_mm: 999.71");
    assert!(err.contains("actual[2].a_mm: 999.71 mm is 299.71"), "{err}");
    let err = robot_error("theta_offset_deg: 0.032", "theta_offset_deg: 5.0");
    assert!(err.contains("actual[2].theta_offset_deg"), "{err}");
    let err = robot_error("lb_mm: 0.10, ub_mm: 0.10", "lb_mm: 0.10, ub_mm: 90.0");
    assert!(
        err.contains("thermal.terms[0]: grows its DH length by 90 mm"),
        "{err}"
    );
    let err = robot_error("[0.0, 0.0, -9.81]", "[0.0, 0.0, -1000.0]");
    assert!(
        err.contains("gravity_m_per_s2: magnitude 1000 m/s²"),
        "{err}"
    );
    let err = robot_error("tool_load: { mass_kg: 5.0", "tool_load: { mass_kg: 50000.0");
    assert!(
        err.contains("tool_load.mass_kg: 50000 kg is outside 0..3000 kg"),
        "{err}"
    );
    // The line is that of the key.
    let base = machine_text("abb-irb1600");
    let text = base.replacen("[0.0, 0.0, -9.81]", "[0.0, 0.0, -1000.0]", 1);
    let line = line_of(&text, "gravity_m_per_s2:", 0);
    assert!(machine_error(&text).starts_with(&format!("m.yaml:{line}:")));
}

/// Writes `text` to a scratch file named `name` and runs `postproc check`
/// on it with `machine`; (exit code, stderr).
fn check_program(name: &str, text: &[u8], machine: &str, extra: &[&str]) -> (i32, String) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(name);
    std::fs::write(&path, text).unwrap();
    let out = crate::common::postproc()
        .args(["check", "--machine", machine])
        .args(extra)
        .arg(&path)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    (out.status.code().unwrap_or(-1), stderr)
}

#[test]
fn implausible_process_inputs_are_refused_at_their_block() {
    let prog = "G21 G90 G94\nG0 X0 Y0 Z10\nS1000 M3\nG1 Z0 F1000000\n";
    let (code, err) = check_program("f.nc", prog.as_bytes(), "afm-r1000", &[]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("f.nc:4:") && err.contains("feed above 100000 mm/min"),
        "{err}"
    );
    let prog =
        "G21 G90 G94\n(POSTPROC MILLING DEPTH=1000 WIDTH=5)\nG0 X0 Y0 Z10\nS1000 M3\nG1 Z0 F100\n";
    let (code, err) = check_program("d.nc", prog.as_bytes(), "afm-r1000", &[]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("d.nc:2:") && err.contains("more than 100 mm of cut"),
        "{err}"
    );
}

#[test]
fn a_line_beyond_the_limit_is_refused_at_its_line() {
    let mut prog = b"G21 G90 G94\nG0 X0 Y0 Z10\n(".to_vec();
    prog.extend(std::iter::repeat_n(
        b'A',
        postproc::limits::LINE_MAX_BYTES + 10,
    ));
    prog.extend_from_slice(b")\nG1 X1 F100\n");
    let (code, err) = check_program("long.nc", &prog, "afm-r1000", &[]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("long.nc:3:") && err.contains("line longer than 1048576 bytes"),
        "{err}"
    );
    let mut module = b"MODULE M\n  PROC main()\n    ! ".to_vec();
    module.extend(std::iter::repeat_n(
        b'A',
        postproc::limits::LINE_MAX_BYTES + 10,
    ));
    module.extend_from_slice(b"\n  ENDPROC\nENDMODULE\n");
    let (code, err) = check_program("long.mod", &module, "abb-irb1600", &[]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("long.mod:3:") && err.contains("line longer than"),
        "{err}"
    );
    let endless = std::io::Read::take(std::io::repeat(b'1'), 3 << 20);
    let err = postproc::calibrate::observations::read_observations(
        std::io::BufReader::new(endless),
        "o.csv",
    )
    .unwrap_err()
    .to_string();
    assert!(
        err.starts_with("o.csv:1:") && err.contains("line longer than"),
        "{err}"
    );
}

#[cfg(unix)]
#[test]
fn dev_zero_is_refused_in_bounded_time_and_memory() {
    use std::os::unix::fs::FileTypeExt;
    if !std::fs::metadata("/dev/zero").is_ok_and(|m| m.file_type().is_char_device()) {
        return; // not the endless device here
    }
    for machine in ["afm-r1000", "abb-irb1600"] {
        let start = Instant::now();
        let out = crate::common::postproc()
            .args(["check", "--machine", machine, "/dev/zero"])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{err}");
        assert!(
            err.contains("/dev/zero:1:") && err.contains("line longer than"),
            "{err}"
        );
        assert!(start.elapsed() < Duration::from_secs(20));
    }
    let err = postproc::process::ForceTable::load(std::path::Path::new("/dev/zero"))
        .unwrap_err()
        .to_string();
    assert!(
        err.starts_with("/dev/zero:1:") && err.contains("line longer than"),
        "{err}"
    );
}

#[test]
fn threads_are_bounded_by_the_cores() {
    let dir = tempfile::tempdir().unwrap();
    let out_path = dir.path().join("t.nc");
    let out = crate::common::postproc()
        .args([
            "compensate",
            "--machine",
            "afm-r1000",
            "--threads",
            "100000",
            "-o",
        ])
        .arg(&out_path)
        .arg(repo("samples/effects.nc"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("per core"), "{err}");
    assert!(!out_path.exists());
}

#[test]
fn emitted_decimals_are_capped() {
    let digits = "1".repeat(255);
    let prog = format!("G21 G90 G94\nG0 X0 Y0 Z10\nS1000 M3\nG1 X10.{digits} Z5 F100\n");
    let out = crate::common::postproc()
        .args(["compensate", "--machine", "afm-r1000", "-o", "-", "-"])
        .write_stdin(prog)
        .output()
        .unwrap();
    let body = crate::common::without_header(&out.stdout);
    let text = String::from_utf8_lossy(&body);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let line = text.lines().nth(3).unwrap();
    let x = line
        .split_whitespace()
        .find(|w| w.starts_with('X'))
        .unwrap();
    let decimals = x.split_once('.').map_or(0, |(_, d)| d.len());
    assert!(decimals <= postproc::limits::EMIT_MAX_DECIMALS, "{line}");
}

#[test]
fn control_characters_are_escaped_in_rapid_and_csv_errors() {
    let module =
        "MODULE M\n  PROC main()\n    MoveL p\x1b[2J, v100, z1, tool0;\n  ENDPROC\nENDMODULE\n";
    let (code, err) = check_program("c.mod", module.as_bytes(), "abb-irb1600", &[]);
    assert_eq!(code, 2, "{err}");
    assert!(!err.contains('\x1b') && err.contains("\\u{1b}"), "{err}");
    let csv = "x_mm,y_mm,z_mm,measured_x_mm,measured_y_mm,measured_z_mm\n1,2,\x07\x1b3,1,2,3\n";
    let err = postproc::calibrate::observations::parse_observations(csv, "o.csv")
        .unwrap_err()
        .to_string();
    assert!(!err.contains('\x1b') && !err.contains('\x07'), "{err}");
}

// ---------------------------------------------------------------------------
// Mutation run
// ---------------------------------------------------------------------------

/// Mutants per input kind in the test run (`HOSTILE_MUTANTS` overrides;
/// `scripts/hostile` runs many more).
const CI_MUTANTS: usize = 1000;
/// Of those, mutants per kind that also go through the binary
/// (`HOSTILE_BINARY` overrides).
const CI_BINARY: usize = 2;

/// A small deterministic generator (SplitMix64).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// Bytes that make interesting mutants of text inputs.
const INTERESTING: &[&[u8]] = &[
    b"0",
    b"-",
    b".",
    b"e",
    b"E",
    b"9",
    b":",
    b"[",
    b"]",
    b"{",
    b"}",
    b",",
    b"\n",
    b"\r",
    b" ",
    b"\t",
    b"#",
    b"(",
    b")",
    b";",
    b"!",
    b"\"",
    b"'",
    b"\0",
    b"\x1b",
    b"\xff",
    b"\xc3",
    b"G",
    b"M",
    b"X",
    b"Z",
    b"F",
    b"S",
    b"H",
    b"T",
    b"1e308",
    b"-1e308",
    b"1e-320",
    b"NaN",
    b"inf",
    b"999999999",
    b"-0",
    b"0.000001",
    b"&a",
    b"*a",
    b"<<: ",
    b"- ",
    b"? ",
    b"~",
];

/// One mutant of `seed`: one to four byte-level edits.
fn mutate(rng: &mut Rng, seed: &[u8]) -> Vec<u8> {
    let mut v = seed.to_vec();
    // Half the mutants have one edit (most of them still parse), the others
    // two to four.
    let edits = if rng.below(2) == 0 {
        1
    } else {
        2 + rng.below(3)
    };
    for _ in 0..edits {
        let at = rng.below(v.len() + 1);
        match rng.below(8) {
            7 if at < v.len() && v[at].is_ascii_digit() => {
                // Another digit: the same syntax, another value.
                v[at] = b'0' + rng.below(10) as u8;
            }
            0 if at < v.len() => v[at] = rng.next() as u8,
            1 if at < v.len() => {
                let end = (at + 1 + rng.below(8)).min(v.len());
                v.drain(at..end);
            }
            2 => {
                let piece = INTERESTING[rng.below(INTERESTING.len())];
                v.splice(at..at, piece.iter().copied());
            }
            3 if at < v.len() => {
                // Duplicate the line around `at`.
                let start = v[..at]
                    .iter()
                    .rposition(|&b| b == b'\n')
                    .map_or(0, |p| p + 1);
                let end = v[at..]
                    .iter()
                    .position(|&b| b == b'\n')
                    .map_or(v.len(), |p| at + p + 1);
                let line = v[start..end].to_vec();
                v.splice(end..end, line);
            }
            4 if at < v.len() && v[at].is_ascii_digit() => {
                let piece = INTERESTING[34 + rng.below(9)];
                v.splice(at..at + 1, piece.iter().copied());
            }
            5 if !v.is_empty() => {
                // Copy a random slice elsewhere.
                let s = rng.below(v.len());
                let e = (s + 1 + rng.below(40)).min(v.len());
                let piece = v[s..e].to_vec();
                let to = rng.below(v.len() + 1);
                v.splice(to..to, piece);
            }
            _ => {
                if let Some(b) = v.get_mut(at) {
                    *b ^= 1 << rng.below(8);
                }
            }
        }
    }
    v
}

/// Occurrences of the words a non-finite number prints as.
fn non_finite_words(b: &[u8]) -> usize {
    let t = String::from_utf8_lossy(b);
    t.matches("NaN").count() + t.matches("inf").count()
}

/// The message of an error, checked for raw control characters.
fn clean_message(e: &postproc::Error) -> Result<(), String> {
    let m = e.to_string();
    if m.chars().any(char::is_control) {
        return Err(format!("raw control character in `{m:?}`"));
    }
    if e.exit_code() != 2 {
        return Err(format!("exit code {} for `{m}`", e.exit_code()));
    }
    Ok(())
}

struct Pools {
    one: rayon::ThreadPool,
    two: rayon::ThreadPool,
}

fn pools() -> Pools {
    let p = |n| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .unwrap()
    };
    Pools {
        one: p(1),
        two: p(2),
    }
}

/// Compensates G-code `input` on `machine` with one pool; the output or the
/// error message.
fn gcode_run(
    machine: &postproc::machine::tool::MachineTool,
    input: &[u8],
    pool: &rayon::ThreadPool,
) -> Result<Vec<u8>, String> {
    use postproc::compensate::Settings;
    use postproc::emit::gcode::EmitOptions;
    use postproc::predict::{EffectSet, ToolPredictor};
    use postproc::program::interp::Setup;
    let job = postproc::pipeline::gcode::Job {
        predictor: Some(ToolPredictor::new(machine, EffectSet::default())),
        setup: Setup::for_machine(machine),
        settings: Settings {
            tolerance_mm: 0.001,
        },
        emit: EmitOptions {
            decimals_mm: None,
            decimals_deg: None,
            annotate: true,
        },
        pool: Some(pool),
        travel: None,
    };
    let mut out = Vec::new();
    match job.run(std::io::BufReader::new(input), "m.nc", Some(&mut out), None) {
        Ok(_) => Ok(out),
        Err(e) => {
            clean_message(&e)?;
            Err(format!("error: {e}"))
        }
    }
}

/// The properties of one G-code mutant: no panic, same result for 1 and 2
/// threads, no non-finite number written that the input did not have.
fn gcode_props(
    machine: &postproc::machine::tool::MachineTool,
    input: &[u8],
    pools: &Pools,
) -> Result<bool, String> {
    let one = gcode_run(machine, input, &pools.one);
    let two = gcode_run(machine, input, &pools.two);
    if one != two {
        return Err("1 and 2 threads differ".into());
    }
    match one {
        Ok(out) if non_finite_words(&out) > non_finite_words(input) => {
            Err("non-finite number in the output".into())
        }
        Ok(_) => Ok(true),
        Err(m) if m.starts_with("error: ") => Ok(false),
        Err(m) => Err(m),
    }
}

fn rapid_props(
    robot: &postproc::machine::robot::Robot,
    input: &[u8],
    pools: &Pools,
) -> Result<bool, String> {
    use postproc::pipeline::rapid::{RapidOptions, compensate_module};
    let Ok(text) = std::str::from_utf8(input) else {
        return match postproc::program::rapid::parse_module_bytes(input, "m.mod") {
            Ok(_) => Err("invalid UTF-8 accepted".into()),
            Err(e) => clean_message(&e.into()).map(|()| false),
        };
    };
    let run = |pool: &rayon::ThreadPool| {
        pool.install(
            || match compensate_module(text, "m.mod", robot, &RapidOptions::default()) {
                Ok(o) => Ok(Ok(o.text)),
                Err(e) => clean_message(&e).map(|()| Err(e.to_string())),
            },
        )
    };
    let one = run(&pools.one)?;
    let two = run(&pools.two)?;
    if one != two {
        return Err("1 and 2 threads differ".into());
    }
    match one {
        Ok(out) if non_finite_words(out.as_bytes()) > non_finite_words(input) => {
            Err("non-finite number in the output".into())
        }
        Ok(_) => Ok(true),
        Err(_) => Ok(false),
    }
}

/// A machine-file mutant: loaded or refused; one that loads compensates
/// `gcode` (machine tools) or `rapid` (robots) with the same checks.
fn machine_props(input: &[u8], gcode: &[u8], rapid: &[u8], pools: &Pools) -> Result<bool, String> {
    let Ok(text) = std::str::from_utf8(input) else {
        return Ok(false);
    };
    match Machine::from_yaml_str(text, "m.yaml") {
        Err(e) => clean_message(&e).map(|()| false),
        Ok(Machine::Tool(m)) => gcode_props(&m, gcode, pools).map(|_| true),
        Ok(Machine::Robot(r)) => rapid_props(&r, rapid, pools).map(|_| true),
    }
}

fn observation_props(input: &[u8]) -> Result<bool, String> {
    match postproc::calibrate::observations::read_observations(input, "m.csv") {
        Ok(_) => Ok(true),
        Err(e) => clean_message(&e).map(|()| false),
    }
}

/// Runs `check` (accepted or cleanly refused, else the problem) on `count`
/// mutants of the seeds; (accepted mutants, findings).
fn mutation_run(
    kind: &str,
    seeds: &[Vec<u8>],
    count: usize,
    check: impl FnMut(&[u8]) -> Result<bool, String>,
) -> (usize, Vec<String>) {
    generated_run(kind, seeds, count, mutate, check)
}

/// [`mutation_run`] with mutants made by `make` from a seed.
fn generated_run(
    kind: &str,
    seeds: &[Vec<u8>],
    count: usize,
    mut make: impl FnMut(&mut Rng, &[u8]) -> Vec<u8>,
    mut check: impl FnMut(&[u8]) -> Result<bool, String>,
) -> (usize, Vec<String>) {
    let mut rng = Rng(0x5EED ^ (kind.len() as u64 * 7919));
    let mut findings = Vec::new();
    let mut accepted = 0;
    for (k, seed) in seeds.iter().enumerate() {
        assert_eq!(check(seed), Ok(true), "{kind} seed {k} is not accepted");
    }
    for i in 0..count {
        let seed = &seeds[i % seeds.len()];
        let m = make(&mut rng, seed);
        let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| check(&m)));
        let problem = match r {
            Ok(Ok(ok)) => {
                accepted += usize::from(ok);
                continue;
            }
            Ok(Err(p)) => p,
            Err(_) => "panic".to_string(),
        };
        let dir = std::env::temp_dir().join("postproc-hostile");
        let _ = std::fs::create_dir_all(&dir);
        let path = dir.join(format!("{kind}-{i}"));
        let _ = std::fs::write(&path, &m);
        findings.push(format!("{kind} mutant {i} ({}): {problem}", path.display()));
    }
    (accepted, findings)
}

fn env_count(name: &str, default: usize) -> usize {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn read(rel: &str) -> Vec<u8> {
    std::fs::read(repo(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

fn tool(name: &str) -> postproc::machine::tool::MachineTool {
    match Machine::from_yaml_str(&machine_text(name), name) {
        Ok(Machine::Tool(m)) => m,
        _ => panic!("{name}"),
    }
}

fn robot(rel: &str) -> postproc::machine::robot::Robot {
    let text = String::from_utf8(read(rel)).unwrap();
    match Machine::from_yaml_str(&text, rel) {
        Ok(Machine::Robot(r)) => r,
        _ => panic!("{rel}"),
    }
}

/// Reports the figures of one kind's run (stderr, shown with --nocapture).
fn report(kind: &str, count: usize, start: Instant, (accepted, findings): &(usize, Vec<String>)) {
    eprintln!(
        "\nhostile {kind}: {count} mutants ({accepted} accepted, {} refused) in {:.1} s, {} findings",
        count - accepted - findings.len(),
        start.elapsed().as_secs_f64(),
        findings.len()
    );
    for f in findings.iter().take(20) {
        eprintln!("  {f}");
    }
    assert!(findings.is_empty(), "{findings:#?}");
}

#[test]
fn mutants_of_gcode_programs_are_processed_or_refused_cleanly() {
    let count = env_count("HOSTILE_MUTANTS", CI_MUTANTS);
    let m = tool("afm-r1000");
    let pools = pools();
    let seeds = [
        read("samples/effects.nc"),
        read("samples/part.nc"),
        read("samples/gcode/mastercam_haas.nc"),
    ];
    let start = Instant::now();
    let run = mutation_run("gcode", &seeds, count, |b| gcode_props(&m, b, &pools));
    report("gcode", count, start, &run);
}

#[test]
fn mutants_of_rapid_modules_are_processed_or_refused_cleanly() {
    let count = env_count("HOSTILE_MUTANTS", CI_MUTANTS);
    let r = robot("machines/abb-irb1600.yaml");
    let pools = pools();
    let seeds = [read("samples/drilling.mod"), read("samples/milling.mod")];
    let start = Instant::now();
    let run = mutation_run("rapid", &seeds, count, |b| rapid_props(&r, b, &pools));
    report("rapid", count, start, &run);
}

#[test]
fn mutants_of_machine_files_are_loaded_or_refused_cleanly() {
    let count = env_count("HOSTILE_MUTANTS", CI_MUTANTS);
    let pools = pools();
    let probe = read("samples/effects.nc");
    let module = read("samples/drilling.mod");
    let seeds: Vec<Vec<u8>> = ["afm-r1000", "five-axis-ac", "abb-irb1600", "staubli-tx200"]
        .iter()
        .map(|n| read(&format!("machines/{n}.yaml")))
        .collect();
    let start = Instant::now();
    let run = mutation_run("machine", &seeds, count, |b| {
        machine_props(b, &probe, &module, &pools)
    });
    report("machine", count, start, &run);
}

#[test]
fn mutants_of_observation_files_are_read_or_refused_cleanly() {
    let count = env_count("HOSTILE_MUTANTS", CI_MUTANTS);
    let seeds = [
        read("samples/observations/afm-r1000-grid-measured.csv"),
        read("samples/observations/irb1600-kinematic-measured.csv"),
        read("samples/observations/irb1600-thermal-measured.csv"),
    ];
    let start = Instant::now();
    let run = mutation_run("observations", &seeds, count, observation_props);
    report("observations", count, start, &run);
}

/// A few mutants through the binary: exit code 0, 1 or 2 only, no panic,
/// no output file left on an error, same bytes for 1 and 2 threads.
#[test]
fn mutants_through_the_binary_exit_cleanly() {
    let count = env_count("HOSTILE_BINARY", CI_BINARY);
    let mut rng = Rng(0xB1A2);
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&str, &str, &str); 2] = [
        ("samples/part.nc", "afm-r1000", "p.nc"),
        ("samples/drilling.mod", "abb-irb1600", "p.mod"),
    ];
    let mut findings = Vec::new();
    for (seed, machine, name) in cases {
        let seed = read(seed);
        for i in 0..count {
            let input = dir.path().join(name);
            std::fs::write(&input, mutate(&mut rng, &seed)).unwrap();
            let mut outputs = Vec::new();
            for threads in ["1", "2"] {
                let out_path = dir.path().join(format!("out-{threads}-{name}"));
                let _ = std::fs::remove_file(&out_path);
                let out = crate::common::postproc()
                    .args([
                        "compensate",
                        "--machine",
                        machine,
                        "--threads",
                        threads,
                        "-o",
                    ])
                    .arg(&out_path)
                    .arg(&input)
                    .output()
                    .unwrap();
                let code = out.status.code();
                let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
                if !matches!(code, Some(0..=2)) || stderr.contains("panicked") {
                    findings.push(format!("{name} {i}: exit {code:?}: {stderr}"));
                }
                if code == Some(2) && out_path.exists() {
                    findings.push(format!("{name} {i}: output left after an error"));
                }
                outputs.push((code, std::fs::read(&out_path).ok()));
            }
            if outputs[0] != outputs[1] {
                findings.push(format!("{name} {i}: 1 and 2 threads differ"));
            }
        }
    }
    assert!(findings.is_empty(), "{findings:#?}");
}

#[test]
fn a_compensation_that_flips_the_wrist_near_the_singularity_is_refused() {
    use postproc::machine::robot::{IkSelect, JOINT_JUMP_MAX_DEG, Model, RobotError};
    use postproc::predict::EffectSet;
    let r = robot("machines/abb-irb1600.yaml");
    let allowing = r.clone().allowing_reconfiguration(true);
    let mut refused = 0;
    // Wrist nearly straight (q5 of ±0.1°): a sub-millimetre correction
    // turns q4 and q6 by more than 10° each way.
    for q5 in [0.002, -0.002] {
        let q = [0.0, 0.5, 0.2, 1.0, q5, -0.3];
        let programmed = r.tcp_pose(Model::Nominal, &q);
        let sel = IkSelect::Conf(r.confdata(&q));
        let Ok(free) =
            allowing.compensate(&allowing.file_context(), &programmed, &sel, EffectSet::ALL)
        else {
            // No solution at all this close to the singularity.
            assert!(
                r.compensate(&r.file_context(), &programmed, &sel, EffectSet::ALL)
                    .is_err()
            );
            continue;
        };
        let jump = free
            .q_compensated
            .iter()
            .zip(&free.q_programmed)
            .map(|(a, b)| (a - b).to_degrees().abs())
            .fold(0.0, f64::max);
        match r.compensate(&r.file_context(), &programmed, &sel, EffectSet::ALL) {
            Err(e @ RobotError::Reconfiguration { .. }) => {
                refused += 1;
                assert!(
                    jump > JOINT_JUMP_MAX_DEG || free.conf.cfx != r.confdata(&q).cfx,
                    "{e}"
                );
                let m = e.to_string();
                assert!(
                    m.contains("joint deltas [") && m.contains("--allow-reconfiguration"),
                    "{m}"
                );
            }
            Ok(c) => assert!(jump <= JOINT_JUMP_MAX_DEG, "{:?}", c.q_compensated),
            Err(e) => panic!("{e}"),
        }
    }
    assert_eq!(refused, 2, "targets near the singularity were accepted");
    // Farther from the singularity the same kind of target is compensated.
    let q = [0.0, 0.5, 0.2, 1.0, 0.02, -0.3];
    let programmed = r.tcp_pose(Model::Nominal, &q);
    r.compensate(
        &r.file_context(),
        &programmed,
        &IkSelect::Conf(r.confdata(&q)),
        EffectSet::ALL,
    )
    .expect("regular target");
}

#[test]
fn an_observation_file_beyond_the_row_limit_is_refused_with_the_limit() {
    use postproc::limits::OBSERVATION_MAX_ROWS;
    let mut csv = String::from("x_mm,y_mm,z_mm,X_mm,Y_mm,Z_mm\n");
    for i in 0..=OBSERVATION_MAX_ROWS {
        csv.push_str(&format!("{i},1,2,{i},1,2\n"));
    }
    let err = postproc::calibrate::observations::parse_observations(&csv, "o.csv")
        .unwrap_err()
        .to_string();
    let line = OBSERVATION_MAX_ROWS + 2;
    assert!(
        err.starts_with(&format!(
            "o.csv:{line}:1: more than {OBSERVATION_MAX_ROWS} data rows"
        )),
        "{err}"
    );
    // At the limit the file is read.
    let at_limit: String = csv
        .lines()
        .take(OBSERVATION_MAX_ROWS + 1)
        .map(|l| format!("{l}\n"))
        .collect();
    let obs = postproc::calibrate::observations::parse_observations(&at_limit, "o.csv").unwrap();
    assert_eq!(obs.rows.len(), OBSERVATION_MAX_ROWS);
}

// ---------------------------------------------------------------------------
// Signals, links and dwell (issue 43)
// ---------------------------------------------------------------------------

/// A program long enough that the run is still writing its output when a
/// signal arrives.
#[cfg(unix)]
fn long_program(dir: &std::path::Path) -> std::path::PathBuf {
    let program = dir.join("big.nc");
    let mut text = String::from("G90 G17 G21 G54\nT1 M6\nG43 H1 G0 X0 Y0 Z20\nG1 Z0 F2000\n");
    for k in 0..400_000 {
        let x = if k % 2 == 0 { 400 } else { 0 };
        text.push_str(&format!("X{x} Y{:.4}\n", k as f64 * 0.0005));
    }
    std::fs::write(&program, text).unwrap();
    program
}

/// Starts `compensate` of `program` into `out_dir`, waits for its
/// temporary file, sends `signal` (a `kill` name); (the run was
/// interrupted while writing, the files left in `out_dir`).
#[cfg(unix)]
fn interrupted_run(
    program: &std::path::Path,
    out_dir: &std::path::Path,
    signal: &str,
    ignore_hup: bool,
) -> (bool, Option<i32>, Vec<String>) {
    use std::os::unix::process::{CommandExt, ExitStatusExt};
    let mut cmd = std::process::Command::new(assert_cmd::cargo::cargo_bin("postproc"));
    cmd.args(["compensate", "--machine", "afm-r1000", "-o"])
        .arg(out_dir.join("o.nc"))
        .arg(program)
        // A core dump (QUIT, XFSZ, …) goes nowhere near the repository.
        .current_dir(out_dir.parent().unwrap())
        .stderr(std::process::Stdio::null());
    if ignore_hup {
        // SAFETY: only async-signal-safe calls between fork and exec.
        unsafe {
            cmd.pre_exec(|| {
                libc::signal(libc::SIGHUP, libc::SIG_IGN);
                Ok(())
            });
        }
    }
    let mut child = cmd.spawn().unwrap();
    let mut seen = false;
    for _ in 0..2000 {
        if std::fs::read_dir(out_dir).unwrap().next().is_some() {
            seen = true;
            break;
        }
        if child.try_wait().unwrap().is_some() {
            break;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    let killed = std::process::Command::new("kill")
        .arg(format!("-{signal}"))
        .arg(child.id().to_string())
        .status()
        .unwrap();
    let status = child.wait().unwrap();
    let mut left: Vec<String> = std::fs::read_dir(out_dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    left.sort();
    (seen && killed.success(), status.signal(), left)
}

/// Every signal that ends the process (not only INT, TERM and HUP) leaves
/// no partial `.postproc-*` file beside the output: each ends the run as
/// its default action would (by that signal), after the temporary file is
/// removed.
#[cfg(unix)]
#[test]
fn every_terminating_signal_leaves_no_temporary_file() {
    let dir = tempfile::tempdir().unwrap();
    let program = long_program(dir.path());
    let out_dir = dir.path().join("out");
    let mut interrupted = 0;
    for (signal, number) in [
        ("QUIT", libc::SIGQUIT),
        ("USR1", libc::SIGUSR1),
        ("USR2", libc::SIGUSR2),
        ("ALRM", libc::SIGALRM),
        ("XFSZ", libc::SIGXFSZ),
        ("XCPU", libc::SIGXCPU),
        ("VTALRM", libc::SIGVTALRM),
        ("PROF", libc::SIGPROF),
        ("HUP", libc::SIGHUP),
        ("ABRT", libc::SIGABRT),
    ] {
        let _ = std::fs::remove_dir_all(&out_dir);
        std::fs::create_dir(&out_dir).unwrap();
        let (sent, by, left) = interrupted_run(&program, &out_dir, signal, false);
        if sent && by.is_some() {
            interrupted += 1;
            assert_eq!(by, Some(number), "{signal}: ended by another signal");
            assert!(left.is_empty(), "{signal}: left {left:?}");
        } else {
            assert!(left.iter().all(|f| f == "o.nc"), "{signal}: left {left:?}");
        }
    }
    assert!(interrupted >= 5, "only {interrupted} runs were interrupted");
}

/// A signal the run was started with ignored (`nohup`) stays ignored: the
/// run goes on and writes its output.
#[cfg(unix)]
#[test]
fn an_ignored_hangup_does_not_end_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let program = long_program(dir.path());
    let out_dir = dir.path().join("out");
    std::fs::create_dir(&out_dir).unwrap();
    let (_, by, left) = interrupted_run(&program, &out_dir, "HUP", true);
    assert_eq!(by, None, "ended by a signal it was started ignoring");
    assert_eq!(left, ["o.nc"]);
}

/// The temporary file of a run that was killed (SIGKILL cannot be caught)
/// is removed by the next run writing into the same folder; one of a live
/// process is left alone.
#[cfg(unix)]
#[test]
fn the_next_run_removes_the_temporary_file_of_a_killed_run() {
    let dir = tempfile::tempdir().unwrap();
    let out_dir = dir.path().join("out");
    std::fs::create_dir(&out_dir).unwrap();
    let mut gone = std::process::Command::new("true").spawn().unwrap();
    let dead = gone.id();
    gone.wait().unwrap();
    let stale = out_dir.join(format!(".postproc-{dead}-0-0badf00d"));
    let live = out_dir.join(format!(".postproc-{}-0-0badf00d", std::process::id()));
    let unrelated = out_dir.join(".postproc-notes");
    for f in [&stale, &live, &unrelated] {
        std::fs::write(f, "partial").unwrap();
    }
    let out = crate::common::postproc()
        .args(["compensate", "--machine", "afm-r1000", "-o"])
        .arg(out_dir.join("o.nc"))
        .arg(repo("samples/part.nc"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0));
    assert!(!stale.exists(), "the killed run's file is left");
    assert!(live.exists() && unrelated.exists());
}

/// `batch` of a folder does not follow a link inside it that leads out of
/// it (a folder or a file elsewhere): it is skipped with a warning.
#[cfg(unix)]
#[test]
fn batch_does_not_leave_its_input_folder_through_a_link() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let input = d.join("in");
    let outside = d.join("elsewhere");
    std::fs::create_dir_all(input.join("sub")).unwrap();
    std::fs::create_dir_all(&outside).unwrap();
    std::fs::copy(repo("samples/part.nc"), input.join("sub/part.nc")).unwrap();
    std::fs::copy(repo("samples/effects.nc"), outside.join("secret.nc")).unwrap();
    std::os::unix::fs::symlink(&outside, input.join("linked")).unwrap();
    std::os::unix::fs::symlink(outside.join("secret.nc"), input.join("one.nc")).unwrap();
    // A link that stays inside the folder is followed as before.
    std::os::unix::fs::symlink(input.join("sub"), input.join("again")).unwrap();
    let out_dir = d.join("out");
    let run = crate::common::postproc()
        .args(["batch", "--machine", "afm-r1000", "--out-dir"])
        .arg(&out_dir)
        .arg(&input)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(0), "{err}");
    for link in ["linked", "one.nc"] {
        assert!(
            err.contains(&format!("{link}: a link out of the input folder")),
            "{link}: {err}"
        );
    }
    let summary = std::fs::read_to_string(out_dir.join("batch-summary.json")).unwrap();
    assert!(!summary.contains("secret"), "{summary}");
    assert!(
        summary.contains("a link out of the input folder"),
        "{summary}"
    );
    let mut outputs: Vec<String> = walk_names(&out_dir);
    outputs.sort();
    assert!(outputs.iter().all(|f| !f.contains("secret")), "{outputs:?}");
    assert!(
        outputs.iter().any(|f| f.ends_with("part.nc")),
        "{outputs:?}"
    );
}

/// File names under `dir`, recursively, relative to it.
fn walk_names(dir: &std::path::Path) -> Vec<String> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push(p.strip_prefix(dir).unwrap().display().to_string());
            }
        }
    }
    out
}

/// A negative dwell at the bottom of a canned cycle (`G82 … P-1`) is
/// refused at its word, as `G4 P-1` is.
#[test]
fn a_negative_cycle_dwell_is_refused_at_its_word() {
    let prog = "G21 G90 G94 G17\nT1 M6\nG43 H1 G0 X0. Y0. Z20.\nS1000 M3\nG98 G82 X10. Y10. Z-5. R2. P-1 F100.\nG80\nM30\n";
    let (code, err) = check_program("dwell.nc", prog.as_bytes(), "afm-r1000", &[]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("dwell.nc:5:28: negative dwell time: `P-1`"),
        "{err}"
    );
    let prog = prog.replace("P-1", "P500");
    let (code, err) = check_program("dwell.nc", prog.as_bytes(), "afm-r1000", &[]);
    assert!(code == 0 || code == 1, "{err}");
}

// ---------------------------------------------------------------------------
// Implausible models (issue 43)
// ---------------------------------------------------------------------------

/// Writes machine text `machine` and runs `check` of `program` (a sample)
/// with it; (exit code, stderr).
fn check_with_machine(machine: &str, program: &str) -> (i32, String) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.yaml");
    std::fs::write(&path, machine).unwrap();
    let out = crate::common::postproc()
        .current_dir(dir.path())
        .args(["check", "--machine", "m.yaml"])
        .arg(repo(program))
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// `base` with `from` replaced by `to` (once; `from` must be there).
fn edited(base: &str, from: &str, to: &str) -> String {
    assert!(base.contains(from), "{from}");
    base.replacen(from, to, 1)
}

/// The refusal of an implausible model through the binary: exit 2, the
/// file, line and column of the key, the key path and the range.
fn refused_at(machine: &str, program: &str, key_line: &str, want: &str) {
    let (code, err) = check_with_machine(machine, program);
    assert_eq!(code, 2, "{err}");
    let line = line_of(machine, key_line, 0);
    assert!(
        err.contains(&format!("m.yaml:{line}:")),
        "line {line}: {err}"
    );
    assert!(err.contains(want), "{err}");
    assert!(err.contains(": off }"), "no override named: {err}");
}

#[test]
fn robot_joint_stiffness_divided_by_100_is_refused() {
    let base = machine_text("abb-irb1600");
    let text = edited(
        &base,
        "k_nm_per_rad: [270990.0, 430040.0, 140940.0, 11280.0, 9550.0, 5330.0]",
        "k_nm_per_rad: [270990.0, 430040.0, 1409.4, 112.8, 95.5, 53.3]",
    );
    refused_at(
        &text,
        "samples/drilling.mod",
        "k_nm_per_rad:",
        "k_nm_per_rad[2]: 1409.4 N·m/rad is outside 11800..11800000 N·m/rad, the plausible range of a main joint's (1–3) stiffness on an arm of 196 kg and 2000 mm reach",
    );
    // Only the wrist joints: the first of them is named.
    let text = edited(&base, "11280.0, 9550.0, 5330.0]", "112.8, 95.5, 53.3]");
    refused_at(
        &text,
        "samples/drilling.mod",
        "k_nm_per_rad:",
        "k_nm_per_rad[3]: 112.8 N·m/rad is outside 588..1960000 N·m/rad",
    );
}

#[test]
fn machine_tool_stiffness_off_by_a_thousand_is_refused() {
    let base = machine_text("five-axis-ac");
    let stiffness = "k_n_per_um: { x_pos: 12.0, x_neg: 12.5, y_pos: 10.0, y_neg: 11.0, z_pos: 18.0, z_neg: 15.0 }";
    for (to, want) in [
        (
            "k_n_per_um: { x_pos: 0.012, x_neg: 0.0125, y_pos: 0.01, y_neg: 0.011, z_pos: 0.018, z_neg: 0.015 }",
            "stiffness.k_n_per_um.x_pos: 0.012 N/µm is outside 1..1000 N/µm, the plausible range of a machine tool's static stiffness",
        ),
        (
            "k_n_per_um: { x_pos: 12000, x_neg: 12500, y_pos: 10000, y_neg: 11000, z_pos: 18000, z_neg: 15000 }",
            "stiffness.k_n_per_um.x_pos: 12000 N/µm is outside 1..1000 N/µm",
        ),
    ] {
        let text = edited(&base, stiffness, to);
        refused_at(&text, "samples/part.nc", "  k_n_per_um:", want);
    }
    // A grid value of the AFM file.
    let base = machine_text("afm-r1000");
    let text = edited(&base, "[[18.0, 20.0, 18.0]", "[[18.0, 0.02, 18.0]");
    refused_at(
        &text,
        "samples/part.nc",
        "    x_pos:",
        "stiffness.k_n_per_um.x_pos: 0.02 N/µm is outside 1..1000 N/µm",
    );
}

#[test]
fn a_tool_longer_than_the_travel_allows_is_refused() {
    let base = machine_text("afm-r1000");
    let text = edited(&base, "1: { length_mm: 62.5 }", "1: { length_mm: 62500 }");
    refused_at(
        &text,
        "samples/part.nc",
        "  1: { length_mm: 62500 }",
        "tools.1.length_mm: 62500 mm is outside 0..1000 mm, the plausible range of a tool length (the Z travel of 500 mm plus 500 mm",
    );
    // At the Z travel plus 500 mm it is a (long) tool.
    let text = edited(&base, "1: { length_mm: 62.5 }", "1: { length_mm: 1000 }");
    let (code, err) = check_with_machine(&text, "samples/part.nc");
    assert!(code == 0 || code == 1, "{err}");
}

#[test]
fn a_heavy_flange_link_is_refused() {
    let base = machine_text("abb-irb1600");
    let text = edited(
        &base,
        "{ mass_kg: 1.0,  com_mm: [0.0, 0.0, -10.0] }",
        "{ mass_kg: 1000.0,  com_mm: [0.0, 0.0, -10.0] }",
    );
    refused_at(
        &text,
        "samples/drilling.mod",
        "  - { mass_kg: 1000.0",
        "links[5].mass_kg: 1000 kg is outside 0..100 kg, the plausible range of the flange's (link 6) mass",
    );
    let text = edited(
        &base,
        "{ mass_kg: 15.0, com_mm: [0.0, 0.0, -250.0] }",
        "{ mass_kg: 15000.0, com_mm: [0.0, 0.0, -250.0] }",
    );
    refused_at(
        &text,
        "samples/drilling.mod",
        "  - { mass_kg: 15000.0",
        "links[3].mass_kg: 15000 kg is outside 0..1000 kg",
    );
}

#[test]
fn drill_diameters_are_bounded() {
    let base = machine_text("abb-irb1600");
    let text = edited(&base, "drill_diameter_mm: 6.8", "drill_diameter_mm: 6800");
    refused_at(
        &text,
        "samples/drilling.mod",
        "  drill_diameter_mm:",
        "process_force.drill_diameter_mm: 6800 mm is outside 0.1..150 mm, the plausible range of a drill's diameter",
    );
    let base = machine_text("afm-r1000");
    let milling = "process_force:\n  model: milling\n  kt_n_per_mm2: 800.0\n  kr_n_per_mm2: 170.0\n  ka_n_per_mm2: 220.0\n  kte_n_per_mm: 28.0\n  kre_n_per_mm: 31.0\n  kae_n_per_mm: 2.0\n  tool_diameter_mm: 10.0\n  flutes: 3\n  axial_depth_mm: 2.0\n  radial_width_mm: 3.0\n";
    let text = edited(
        &base,
        milling,
        "process_force:\n  model: drilling\n  thrust_coefficient_n_per_mm2: 450.0\n  drill_diameter_mm: 680.0\n",
    );
    refused_at(
        &text,
        "samples/part.nc",
        "  drill_diameter_mm:",
        "process_force.drill_diameter_mm: 680 mm is outside 0.1..150 mm",
    );
}

#[test]
fn a_spindle_speed_off_by_a_thousand_is_refused_by_its_cutting_speed() {
    let base = machine_text("staubli-tx200");
    let text = edited(&base, "spindle_rpm: 15000.0", "spindle_rpm: 15");
    refused_at(
        &text,
        "samples/milling.mod",
        "  spindle_rpm:",
        "process_force.spindle_rpm: 15 1/min with the 12 mm cutter is a cutting speed of 0.565 m/min, outside 2..6000 m/min",
    );
}

#[test]
fn a_vanishing_modal_stiffness_is_refused_even_with_plausibility_off() {
    let base = machine_text("abb-irb1600");
    let text = edited(
        &base,
        "damping_ratio: 0.05, stiffness_n_per_um: 0.5 }",
        "damping_ratio: 0.05, stiffness_n_per_um: 5e-324 }",
    );
    let (code, err) = check_with_machine(&text, "samples/milling.mod");
    assert_eq!(code, 2, "{err}");
    let line = line_of(&text, "  - { direction: x", 0);
    assert!(
        err.contains(&format!("m.yaml:{line}:"))
            && err.contains("modal[0].stiffness_n_per_um: `5e-324` is outside 0.001..100000"),
        "{err}"
    );
    let off = format!("{text}plausibility:\n  modal: off\n");
    let (code, err) = check_with_machine(&off, "samples/milling.mod");
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("modal[0].stiffness_n_per_um: `5e-324`"),
        "{err}"
    );
    // Machine tools alike; a merely implausible one names the range.
    let base = machine_text("afm-r1000");
    let from = "x: { natural_frequency_hz: 62.0, damping_ratio: 0.04, stiffness_n_per_um: 20.0 }";
    let text = edited(&base, from, &from.replace("20.0 }", "5e-324 }"));
    let (code, err) = check_with_machine(&text, "samples/part.nc");
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("modal.x.stiffness_n_per_um: `5e-324` is outside 0.001..100000"),
        "{err}"
    );
    let text = edited(&base, from, &from.replace("20.0 }", "0.02 }"));
    refused_at(
        &text,
        "samples/part.nc",
        "  x: { natural_frequency_hz",
        "modal.x.stiffness_n_per_um: 0.02 N/µm is outside 0.5..2000 N/µm",
    );
    let text = edited(&base, from, &from.replace("0.04", "0.0005"));
    refused_at(
        &text,
        "samples/part.nc",
        "  x: { natural_frequency_hz",
        "modal.x.damping_ratio: 0.0005 is outside 0.001..0.5, the plausible range of a damping ratio",
    );
}

#[test]
fn plausibility_off_accepts_a_key_with_a_warning_and_only_that_key() {
    let base = machine_text("abb-irb1600");
    let soft = edited(&base, "11280.0, 9550.0, 5330.0]", "112.8, 95.5, 53.3]");
    let text = format!("{soft}plausibility:\n  k_nm_per_rad: off\n");
    let (code, err) = check_with_machine(&text, "samples/drilling.mod");
    assert!(code == 0 || code == 1, "{err}");
    let line = line_of(&text, "k_nm_per_rad:", 0);
    assert!(
        err.contains(&format!("m.yaml:{line}:"))
            && err.contains("k_nm_per_rad[3]: 112.8 N·m/rad is outside 588..1960000 N·m/rad")
            && err.contains("accepted because `plausibility: { k_nm_per_rad: off }`"),
        "{err}"
    );
    // One joint's key covers that joint only.
    let text = format!("{soft}plausibility:\n  k_nm_per_rad[3]: off\n");
    let (code, err) = check_with_machine(&text, "samples/drilling.mod");
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("k_nm_per_rad[4]: 95.5 N·m/rad"), "{err}");
    // Another key does not cover it; an unknown key is an error.
    let text = format!("{soft}plausibility:\n  links: off\n");
    let (code, err) = check_with_machine(&text, "samples/drilling.mod");
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("k_nm_per_rad[3]"), "{err}");
    let text = format!("{base}plausibility:\n  k_nm_per_radian: off\n");
    let (code, err) = check_with_machine(&text, "samples/drilling.mod");
    assert_eq!(code, 2, "{err}");
    let line = line_of(&text, "  k_nm_per_radian: off", 0);
    assert!(
        err.contains(&format!("m.yaml:{line}:3:"))
            && err.contains("plausibility.k_nm_per_radian: `k_nm_per_radian` is not the key path"),
        "{err}"
    );
    // Only `off` is a value; an override with nothing to accept is a warning.
    let text = format!("{base}plausibility:\n  k_nm_per_rad: on\n");
    let (code, err) = check_with_machine(&text, "samples/drilling.mod");
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("plausibility.k_nm_per_rad"), "{err}");
    let text = format!("{base}plausibility:\n  k_nm_per_rad: off\n");
    let (code, err) = check_with_machine(&text, "samples/drilling.mod");
    assert!(code == 0 || code == 1, "{err}");
    assert!(err.contains("the override can go"), "{err}");
    // Machine tools alike.
    let tool = machine_text("afm-r1000");
    let long = edited(&tool, "1: { length_mm: 62.5 }", "1: { length_mm: 1500 }");
    let text = format!("{long}plausibility:\n  tools.1: off\n");
    let (code, err) = check_with_machine(&text, "samples/part.nc");
    assert!(code == 0 || code == 1, "{err}");
    assert!(
        err.contains("tools.1.length_mm: 1500 mm is outside 0..1000 mm")
            && err.contains("accepted because `plausibility: { tools.1: off }`"),
        "{err}"
    );
}

// ---------------------------------------------------------------------------
// Scaled models: each quantity off by 10^±3 (issue 43)
// ---------------------------------------------------------------------------

/// Largest deviation a machine-tool model within every plausible range may
/// predict on the probe programs, mm (its errors are limited to 1 mm and
/// 1000 µrad each, its stiffness to at least 1 N/µm).
const TOOL_DEV_MAX_MM: f64 = 2.0;
/// The same for a robot, mm (uncalibrated arms err by 1–3 mm).
const ROBOT_DEV_MAX_MM: f64 = 10.0;

/// The numbers of a machine file's text that are values (not keys, not
/// part of a name, not in a comment): (start, end) byte offsets.
fn value_tokens(text: &str) -> Vec<(usize, usize)> {
    let b = text.as_bytes();
    let mut out = Vec::new();
    let mut line_start = 0;
    for line in text.split_inclusive('\n') {
        let body = match line.find('#') {
            Some(c) => &line[..c],
            None => line,
        };
        let lb = body.as_bytes();
        let mut i = 0;
        while i < lb.len() {
            let starts = lb[i].is_ascii_digit()
                || (matches!(lb[i], b'-' | b'.') && lb.get(i + 1).is_some_and(u8::is_ascii_digit));
            let joined =
                i > 0 && (lb[i - 1].is_ascii_alphanumeric() || matches!(lb[i - 1], b'_' | b'.'));
            if !starts || joined {
                i += 1;
                continue;
            }
            let mut j = i + 1;
            while j < lb.len()
                && (lb[j].is_ascii_digit()
                    || lb[j] == b'.'
                    || matches!(lb[j], b'e' | b'E')
                    || (matches!(lb[j], b'-' | b'+') && matches!(lb[j - 1], b'e' | b'E')))
            {
                j += 1;
            }
            let key = body[j..].trim_start().starts_with(':');
            let named = j < lb.len() && (lb[j].is_ascii_alphabetic() || lb[j] == b'_');
            if !key && !named && body[i..j].parse::<f64>().is_ok() {
                out.push((line_start + i, line_start + j));
            }
            i = j;
        }
        line_start += line.len();
    }
    debug_assert!(out.iter().all(|&(s, e)| e <= b.len() && s < e));
    out
}

/// `text` with the tokens `which` multiplied by `factor`.
fn scaled(text: &str, tokens: &[(usize, usize)], factor: f64) -> String {
    let mut out = String::with_capacity(text.len() + 16 * tokens.len());
    let mut at = 0;
    for &(s, e) in tokens {
        out.push_str(&text[at..s]);
        let v: f64 = text[s..e].parse().unwrap_or(0.0);
        out.push_str(&format!("{}", v * factor));
        at = e;
    }
    out.push_str(&text[at..]);
    out
}

/// The scaled mutants of a seed: every value alone, then every line's
/// values together (a section written in another unit), each by 10^3 and
/// 10^-3; beyond them, two values of random lines at once.
fn scaled_mutant(text: &str, tokens: &[(usize, usize)], i: usize, rng: &mut Rng) -> String {
    let factor = if i % 2 == 0 { 1e3 } else { 1e-3 };
    let k = i / 2;
    if k < tokens.len() {
        return scaled(text, &tokens[k..=k], factor);
    }
    let lines: Vec<(usize, usize)> = {
        let mut v: Vec<(usize, usize)> = Vec::new();
        let mut start = 0;
        for line in text.split_inclusive('\n') {
            v.push((start, start + line.len()));
            start += line.len();
        }
        v
    };
    let k = k - tokens.len();
    if k < lines.len() {
        let (s, e) = lines[k];
        let on: Vec<(usize, usize)> = tokens
            .iter()
            .copied()
            .filter(|&(a, b)| a >= s && b <= e)
            .collect();
        return scaled(text, &on, factor);
    }
    let mut pick = [
        tokens[rng.below(tokens.len())],
        tokens[rng.below(tokens.len())],
    ];
    pick.sort();
    if pick[0] == pick[1] {
        return scaled(text, &pick[..1], factor);
    }
    let f2 = if rng.below(2) == 0 { 1e3 } else { 1e-3 };
    let once = scaled(text, &pick[1..], f2);
    scaled(&once, &pick[..1], factor)
}

/// The largest `dev N mm` annotation of a compensated program, mm.
fn largest_dev(out: &[u8]) -> f64 {
    String::from_utf8_lossy(out)
        .split("dev ")
        .skip(1)
        .filter_map(|t| t.split_whitespace().next()?.parse::<f64>().ok())
        .fold(0.0, f64::max)
}

/// Compensates the probe with a loaded model: (largest deviation, the
/// output's non-finite words beyond the probe's) or the error.
fn probe(m: &Machine, input: &[u8], pools: &Pools) -> Result<(f64, bool), String> {
    let out = match m {
        Machine::Tool(t) => gcode_run(t, input, &pools.one)?,
        Machine::Robot(r) => {
            use postproc::pipeline::rapid::{RapidOptions, compensate_module};
            let text = std::str::from_utf8(input).unwrap_or_default();
            match compensate_module(text, "m.mod", r, &RapidOptions::default()) {
                Ok(o) => o.text.into_bytes(),
                Err(e) => {
                    clean_message(&e)?;
                    return Err(format!("error: {e}"));
                }
            }
        }
    };
    Ok((
        largest_dev(&out),
        non_finite_words(&out) > non_finite_words(input),
    ))
}

/// The key path a plausibility refusal names (`m.yaml:L:C: PATH: …`).
fn refused_key(message: &str) -> Option<String> {
    if !message.contains(": off }`)") {
        return None;
    }
    let rest = message.strip_prefix("m.yaml:")?;
    let rest = rest.splitn(3, ':').nth(2)?.trim_start();
    Some(rest.split(": ").next()?.to_string())
}

/// A scaled model: refused with a located message, or loaded and then
/// predicting at most the plausible deviation on the probe (or refusing
/// the probe cleanly). A value refused as implausible and accepted with
/// `plausibility: { KEY: off }` must still give finite numbers only.
fn scaled_props(text: &str, probe_input: &[u8], pools: &Pools) -> Result<bool, String> {
    let m = match Machine::from_yaml_str(text, "m.yaml") {
        Ok(m) => m,
        Err(e) => {
            clean_message(&e)?;
            let msg = e.to_string();
            if !msg.starts_with("m.yaml:") {
                return Err(format!("refusal without its place: {msg}"));
            }
            return overridden_props(text, &msg, probe_input, pools).map(|()| false);
        }
    };
    let limit = match m {
        Machine::Tool(_) => TOOL_DEV_MAX_MM,
        Machine::Robot(_) => ROBOT_DEV_MAX_MM,
    };
    match probe(&m, probe_input, pools) {
        Ok((_, true)) => Err("non-finite number in the output".into()),
        Ok((dev, false)) if dev > limit => Err(format!(
            "a model within every plausible range predicts {dev} mm (more than {limit} mm)"
        )),
        Ok(_) => Ok(true),
        Err(m) if m.starts_with("error: ") => Ok(true),
        Err(m) => Err(m),
    }
}

/// The model of a plausibility refusal with the refused keys turned off
/// (up to 4): loaded or refused cleanly, and no non-finite number in what
/// it writes.
fn overridden_props(
    text: &str,
    first: &str,
    probe_input: &[u8],
    pools: &Pools,
) -> Result<(), String> {
    let mut keys: Vec<String> = Vec::new();
    let mut msg = first.to_string();
    for _ in 0..4 {
        let Some(key) = refused_key(&msg) else {
            return Ok(());
        };
        if keys.contains(&key) {
            return Err(format!("`{key}: off` does not accept it: {msg}"));
        }
        keys.push(key);
        let mut with = format!("{text}\nplausibility:\n");
        for k in &keys {
            with.push_str(&format!("  {k}: off\n"));
        }
        match Machine::from_yaml_str(&with, "m.yaml") {
            Ok(m) => {
                return match probe(&m, probe_input, pools) {
                    Ok((_, true)) => {
                        Err(format!("non-finite number in the output with {keys:?} off"))
                    }
                    Ok(_) => Ok(()),
                    Err(m) if m.starts_with("error: ") => Ok(()),
                    Err(m) => Err(m),
                };
            }
            Err(e) => {
                clean_message(&e)?;
                msg = e.to_string();
            }
        }
    }
    Ok(())
}

/// A seed of the scaled-model generator: the machine text, its value
/// tokens and the probe program.
type ScaledSeed = (String, Vec<(usize, usize)>, Vec<u8>);

#[test]
fn mutants_of_scaled_models_are_refused_or_predict_plausibly() {
    let count = env_count("HOSTILE_MUTANTS", CI_MUTANTS / 4);
    let pools = pools();
    let cases = [
        ("afm-r1000", "samples/effects.nc"),
        ("five-axis-ac", "samples/five-axis.nc"),
        ("head-table-bc", "samples/head-table.nc"),
        ("abb-irb1600", "samples/milling.mod"),
        ("staubli-tx200", "samples/milling.mod"),
    ];
    let seeds: Vec<ScaledSeed> = cases
        .iter()
        .map(|(m, p)| {
            let text = machine_text(m);
            let tokens = value_tokens(&text);
            (text, tokens, read(p))
        })
        .collect();
    for (k, (text, tokens, probe_input)) in seeds.iter().enumerate() {
        assert!(tokens.len() > 20, "seed {k}: {} values", tokens.len());
        assert_eq!(
            scaled_props(text, probe_input, &pools),
            Ok(true),
            "seed {k}"
        );
    }
    let mut rng = Rng(0x5CA1E);
    let start = Instant::now();
    let mut accepted = 0;
    let mut findings = Vec::new();
    for i in 0..count {
        let (text, tokens, probe_input) = &seeds[i % seeds.len()];
        let m = scaled_mutant(text, tokens, i / seeds.len(), &mut rng);
        let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            scaled_props(&m, probe_input, &pools)
        }));
        let problem = match r {
            Ok(Ok(ok)) => {
                accepted += usize::from(ok);
                continue;
            }
            Ok(Err(p)) => p,
            Err(_) => "panic".to_string(),
        };
        let dir = std::env::temp_dir().join("postproc-hostile");
        let _ = std::fs::create_dir_all(&dir);
        let path = dir.join(format!("scaled-{i}.yaml"));
        let _ = std::fs::write(&path, &m);
        findings.push(format!("scaled mutant {i} ({}): {problem}", path.display()));
    }
    report("scaled models", count, start, &(accepted, findings));
}

#[test]
fn value_tokens_are_the_numbers_that_are_values() {
    let text = "a: 1.5 # 7\ntools:\n  12: { length_mm: -6e2 }\nname: G54.1P1 x2\nk: [1, .5]\n";
    let got: Vec<&str> = value_tokens(text)
        .iter()
        .map(|&(s, e)| &text[s..e])
        .collect();
    assert_eq!(got, ["1.5", "-6e2", "1", ".5"]);
    let toks = value_tokens(text);
    assert_eq!(
        scaled(text, &toks[1..2], 1e-3),
        text.replace("-6e2", "-0.6")
    );
}

// ---------------------------------------------------------------------------
// G-code words that are not moves, and feed modes (issue 43, second round)
// ---------------------------------------------------------------------------

/// Writes `text` to a scratch file and runs `postproc compensate` on it;
/// (exit code, written program, stderr).
fn compensate_program(name: &str, text: &[u8], machine: &str) -> (i32, Vec<u8>, String) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(name);
    let out_path = dir.path().join(format!("out-{name}"));
    std::fs::write(&path, text).unwrap();
    let out = crate::common::postproc()
        .args(["compensate", "-q", "--machine", machine])
        .arg(&path)
        .arg("-o")
        .arg(&out_path)
        .output()
        .unwrap();
    let written = std::fs::read(&out_path).unwrap_or_default();
    (
        out.status.code().unwrap_or(-1),
        written,
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// The program lines of a compensated G-code program (no header comments,
/// no annotations).
fn program_lines(written: &[u8]) -> Vec<String> {
    String::from_utf8_lossy(written)
        .lines()
        .filter(|l| !l.starts_with('('))
        .map(|l| l.split(" (").next().unwrap_or("").to_string())
        .collect()
}

/// `G50.1 X0. Y0.` (mirror cancel) names the axes whose mirror it cancels:
/// not a move, written back as it came; the next move starts at Y100.
#[test]
fn a_mirror_cancel_with_axis_words_is_not_a_move() {
    let prog = "G21 G90 G94 G17\nT1 M6\nG43 H1 G0 X0. Y0. Z20.\nS1000 M3\nG1 X0. Y100. F500.\nG50.1 X0. Y0.\nG50\nG1 X50. Y100.\nM30\n";
    let (code, err) = check_program("mirror.nc", prog.as_bytes(), "afm-r1000", &["-q"]);
    assert_eq!(code, 0, "{err}");
    let (code, written, err) = compensate_program("mirror.nc", prog.as_bytes(), "afm-r1000");
    assert_eq!(code, 0, "{err}");
    let lines = program_lines(&written);
    let at = lines
        .iter()
        .position(|l| l == "G50.1 X0. Y0.")
        .unwrap_or_else(|| panic!("mirror cancel rewritten: {lines:?}"));
    // Every move line after it stays near Y100 (no traverse to Y0).
    for l in &lines[at + 1..] {
        if let Some(y) = l.split(' ').find_map(|w| w.strip_prefix('Y')) {
            let y: f64 = y.parse().unwrap();
            assert!((y - 100.0).abs() < 0.1, "{l} in {lines:?}");
        }
    }
}

#[test]
fn scaling_and_mirroring_words_are_refused_by_name() {
    let head = "G21 G90 G94 G17\nT1 M6\nG43 H1 G0 X0. Y0. Z20.\nS1000 M3\n";
    for (line, want) in [
        ("G50 X0. Z0.", "g.nc:5:1: G50 with axis words"),
        (
            "G1 G50.1 X0. Y0. F100.",
            "g.nc:5:4: G50.1 (mirror cancel) names axes, and cannot share a block with the motion code `G1`",
        ),
        (
            "G51.1 X0.",
            "g.nc:5:1: G51.1 (programmable mirror image) cannot be compensated offline",
        ),
        (
            "G51 X0. Y0. P2",
            "g.nc:5:1: G51 (scaling/mirroring) cannot be compensated offline",
        ),
    ] {
        let prog = format!("{head}{line}\nG1 X10. F100.\nM30\n");
        let (code, err) = check_program("g.nc", prog.as_bytes(), "afm-r1000", &["-q"]);
        assert_eq!(code, 2, "{line}: {err}");
        assert!(err.contains(want), "{line}: {err}");
    }
}

/// An F given under G93 (1/min) does not carry into G94 as mm/min, nor a
/// G94 F into G95 as mm/rev: the feed move after the switch needs its F.
#[test]
fn a_feed_does_not_carry_across_a_change_of_feed_mode() {
    let head = "G21 G90 G94 G17\nT1 M6\nG43 H1 G0 X0. Y0. Z20.\nS1000 M3\n";
    for (body, want, feed) in [
        (
            "G93\nG1 X10. F2.\nG94\nG1 X60.\n",
            "f.nc:8:1: feed move without a new F after the change of feed mode to G94 (per minute): the F in force was given under G93 (inverse time)",
            "F300.",
        ),
        (
            "G1 X10. F200.\nG95\nG1 X60.\n",
            "f.nc:7:1: feed move without a new F after the change of feed mode to G95 (per revolution): the F in force was given under G94 (per minute)",
            "F0.1",
        ),
    ] {
        let prog = format!("{head}{body}M30\n");
        let (code, err) = check_program("f.nc", prog.as_bytes(), "afm-r1000", &["-q"]);
        assert_eq!(code, 2, "{body}: {err}");
        assert!(err.contains(want), "{body}: {err}");
        // With its own F (on the switch or the move) the program is read.
        let fixed = prog.replace("G1 X60.", &format!("G1 X60. {feed}"));
        let (code, err) = check_program("f.nc", fixed.as_bytes(), "afm-r1000", &["-q"]);
        assert_eq!(code, 0, "{fixed}: {err}");
    }
    let prog = format!("{head}G93\nG1 X10. F2.\nG94 F400.\nG1 X60.\nM30\n");
    let (code, err) = check_program("f.nc", prog.as_bytes(), "afm-r1000", &["-q"]);
    assert_eq!(code, 0, "{err}");
}

// ---------------------------------------------------------------------------
// Line ends (issue 43, second round)
// ---------------------------------------------------------------------------

/// `compensate --effects none` of `text`: the written bytes after the
/// header comment lines (a byte-order mark kept in front), which must be
/// the input's bytes.
fn identity_bytes(name: &str, text: &[u8]) -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(name);
    let out_path = dir.path().join("out.nc");
    std::fs::write(&path, text).unwrap();
    let out = crate::common::postproc()
        .args([
            "compensate",
            "-q",
            "--effects",
            "none",
            "--machine",
            "afm-r1000",
        ])
        .arg(&path)
        .arg("-o")
        .arg(&out_path)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{name}: {stderr}");
    let written = std::fs::read(&out_path).unwrap();
    let bom: &[u8] = b"\xEF\xBB\xBF";
    let (lead, mut rest) = match written.strip_prefix(bom) {
        Some(r) => (bom, r),
        None => (&b""[..], &written[..]),
    };
    while rest.starts_with(b"(") {
        let nl = rest.iter().position(|&b| b == b'\n').unwrap();
        rest = &rest[nl + 1..];
    }
    [lead, rest].concat()
}

#[test]
fn mixed_line_ends_a_missing_final_newline_a_bom_and_long_lines_are_written_as_they_came() {
    let long = format!("({})", "C".repeat(600_000));
    let cases: Vec<(&str, Vec<u8>)> = vec![
        (
            "mixed.nc",
            b"G21 G90 G94 G17\r\nT1 M6\r\nG0 X0. Y0. Z20.\nG1 X10. F100.\r\nG1 X20.\nM30".to_vec(),
        ),
        (
            "bom.nc",
            b"\xEF\xBB\xBFG21 G90 G94 G17\r\nG0 X0. Y0. Z20.\r\nG1 X10. F100.\r\nM30\r\n".to_vec(),
        ),
        (
            "long.nc",
            format!("G21 G90 G94 G17\n{long}\nG0 X0. Y0. Z20.\nG1 X10. F100. {long}\nM30\n")
                .into_bytes(),
        ),
    ];
    for (name, text) in cases {
        let (code, err) = check_program(name, &text, "afm-r1000", &["-q"]);
        assert_eq!(code, 0, "{name}: {err}");
        assert!(identity_bytes(name, &text) == text, "{name}: bytes differ");
    }
}

/// A carriage return without its line feed (CR-only files, or one such
/// line end among CR LF ones) is refused at its byte: read as a line end
/// it was not, a `%` or a comment would swallow the lines after it.
#[test]
fn a_carriage_return_alone_is_refused_at_its_byte() {
    let cr_only = b"%\rG21 G90 G94 G17\rG0 X0. Y0. Z20.\rG1 X10. F100.\rM30\r%\r";
    let last_cr = b"G21 G90 G94 G17\r\nG0 X0. Y0. Z20.\r\nG1 X10. F100.\r";
    let mid_cr = b"G21 G90 G94 G17\r\nG0 X0. Y0. Z20.\r\nG1 X10. F100.\rM30\r\n";
    for (text, at) in [
        (&cr_only[..], "p.nc:1:2:"),
        (&last_cr[..], "p.nc:3:14:"),
        (&mid_cr[..], "p.nc:3:14:"),
    ] {
        let (code, err) = check_program("p.nc", text, "afm-r1000", &["-q"]);
        assert_eq!(code, 2, "{err}");
        assert!(
            err.contains(&format!(
                "{at} carriage return (CR) without a line feed: lines end in LF or CR LF"
            )),
            "{err}"
        );
    }
    let module = std::fs::read_to_string(repo("samples/drilling.mod")).unwrap();
    let cr_module = module.replace('\n', "\r");
    let (code, err) = check_program("m.mod", cr_module.as_bytes(), "abb-irb1600", &["-q"]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("m.mod:1:4: carriage return (CR) without a line feed"),
        "{err}"
    );
    let crlf_module = module.replace('\n', "\r\n");
    let (code, err) = check_program("m.mod", crlf_module.as_bytes(), "abb-irb1600", &["-q"]);
    assert_eq!(code, 0, "{err}");
}

#[test]
fn a_nul_byte_is_refused_at_its_byte() {
    let text = b"G21 G90 G94 G17\nG0 X0. Y0. Z20.\nG1 X10.\0 F100.\nM30\n";
    let (code, err) = check_program("n.nc", text, "afm-r1000", &["-q"]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("n.nc:3:8: unexpected character byte 0x00"),
        "{err}"
    );
}

// ---------------------------------------------------------------------------
// RAPID resolution time (issue 43, second round)
// ---------------------------------------------------------------------------

/// A module of `n` moves going back and forth between two named targets
/// (each compensated move of a named target gets a copy of its own).
fn back_and_forth_module(n: usize) -> String {
    let conf = "[-1,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]";
    let mut m = format!(
        "MODULE Big\n  PERS tooldata tSp := [TRUE,[[0,0,150],[1,0,0,0]],[2,[0,0,60],[1,0,0,0],0,0,0]];\n  CONST robtarget pA := [[800,-100,600],[0,0,1,0],{conf}];\n  CONST robtarget pB := [[850,-50,600],[0,0,1,0],{conf}];\n  PROC main()\n"
    );
    for i in 0..n {
        m.push_str(if i % 2 == 0 {
            "    MoveL pA, v100, z1, tSp;\n"
        } else {
            "    MoveL pB, v100, z1, tSp;\n"
        });
    }
    m.push_str("  ENDPROC\nENDMODULE\n");
    m
}

/// Seconds `compensate` takes on `module`, or `None` when it runs past
/// `limit` seconds (it is then ended).
fn compensate_seconds(dir: &std::path::Path, name: &str, module: &str, limit: f64) -> Option<f64> {
    let path = dir.join(name);
    std::fs::write(&path, module).unwrap();
    let start = Instant::now();
    let mut child = std::process::Command::new(assert_cmd::cargo::cargo_bin("postproc"))
        .args(["compensate", "-q", "--machine", "abb-irb1600", "-o"])
        .arg(dir.join(format!("out-{name}")))
        .arg(&path)
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            assert!(status.success(), "{name}: {status}");
            return Some(start.elapsed().as_secs_f64());
        }
        if start.elapsed().as_secs_f64() > limit {
            child.kill().unwrap();
            child.wait().unwrap();
            return None;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Ten times the moves between two named targets take less than ten
/// times as long (the copies' names were found by trying every number
/// against every name made so far, and each move's routine-local data by
/// a walk over the whole routine: the time grew with the cube). The
/// growth order is checked, with retries; the absolute time is in
/// scripts/bench.
#[test]
fn resolution_time_grows_linearly_with_the_moves() {
    let dir = tempfile::tempdir().unwrap();
    let small = back_and_forth_module(1_000);
    let large = back_and_forth_module(10_000);
    let mut ratios = Vec::new();
    for _ in 0..3 {
        let t_small = compensate_seconds(dir.path(), "small.mod", &small, 600.0).unwrap();
        // Past 20 times the small run's time the ratio is lost: stop there.
        let limit = 20.0 * t_small + 5.0;
        let t_large = compensate_seconds(dir.path(), "large.mod", &large, limit);
        let ratio = t_large.map_or(f64::INFINITY, |t| t / t_small);
        if ratio < 10.0 {
            return;
        }
        ratios.push(ratio);
    }
    panic!("10 000 moves take more than 10× the time of 1 000: ratios {ratios:?}");
}

// ---------------------------------------------------------------------------
// Generated G-code: line ends, non-motion codes, feed modes, incremental
// cycles (issue 43, second round)
// ---------------------------------------------------------------------------

/// Lines the generator inserts: codes whose axis words are not moves,
/// feed-mode switches with and without F, incremental canned cycles.
const MODAL_LINES: &[&str] = &[
    "G50.1 X0. Y0.",
    "G50",
    "G50 X0. Z0.",
    "G51.1 X0.",
    "G1 G50.1 X0. F100.",
    "G93",
    "G94",
    "G95",
    "G94 F500.",
    "G95 F0.1",
    "G93 G1 X10. F2.",
    "G1 X5. F0.2",
    "G91",
    "G90",
    "G98",
    "G99",
    "G91 G99 G81 X10. Y0. Z-20. R-5. F100.",
    "G91 G98 G81 X5. Z-3. R-2. F80.",
    "G91 G98 G83 X-5. Z-10. R-400. Q2. F80.",
    "X10.",
    "G80",
    "G0 X10.",
    "G1 Z-1. F200.",
];

/// One generated program from `seed`: its lines with one line-end mix
/// (LF, CR LF, the two mixed, or any of LF, CR LF and CR alone), maybe a
/// byte-order mark and no final line end, and lines of [`MODAL_LINES`]
/// inserted here and there.
fn line_end_mutant(rng: &mut Rng, seed: &[u8]) -> Vec<u8> {
    let text = String::from_utf8_lossy(seed);
    let lines: Vec<&str> = text.lines().collect();
    let mut out = Vec::with_capacity(seed.len() + 256);
    if rng.below(8) == 0 {
        out.extend_from_slice(b"\xEF\xBB\xBF");
    }
    let mix = rng.below(4);
    let rate = 2 + rng.below(30);
    let eol = |rng: &mut Rng| -> &'static [u8] {
        match (mix, rng.below(3)) {
            (0, _) => b"\n",
            (1, _) => b"\r\n",
            (2, 0) => b"\n",
            (2, _) => b"\r\n",
            (_, 0) => b"\n",
            (_, 1) => b"\r\n",
            _ => b"\r",
        }
    };
    for (i, l) in lines.iter().enumerate() {
        if i > 0 && rng.below(rate) == 0 {
            out.extend_from_slice(MODAL_LINES[rng.below(MODAL_LINES.len())].as_bytes());
            let e = eol(rng);
            out.extend_from_slice(e);
        }
        out.extend_from_slice(l.as_bytes());
        if i + 1 < lines.len() || rng.below(4) != 0 {
            let e = eol(rng);
            out.extend_from_slice(e);
        }
    }
    out
}

/// The reader of `check` for `machine` (no predictor, one thread): the
/// forward pass that reads a written program back.
fn reader_job<'a>(
    machine: &postproc::machine::tool::MachineTool,
    pools: &'a Pools,
) -> postproc::pipeline::gcode::Job<'a> {
    postproc::pipeline::gcode::Job {
        predictor: None,
        setup: postproc::program::interp::Setup::for_machine(machine),
        settings: postproc::compensate::Settings {
            tolerance_mm: 0.001,
        },
        emit: postproc::emit::gcode::EmitOptions {
            decimals_mm: None,
            decimals_deg: None,
            annotate: true,
        },
        pool: Some(&pools.one),
        travel: None,
    }
}

/// [`gcode_props`], and a program written is read back by the reader of
/// `check` (its line ends and words are ones the reader takes).
fn line_end_props(
    machine: &postproc::machine::tool::MachineTool,
    input: &[u8],
    pools: &Pools,
) -> Result<bool, String> {
    if !gcode_props(machine, input, pools)? {
        return Ok(false);
    }
    let out = gcode_run(machine, input, &pools.one)?;
    let job = reader_job(machine, pools);
    job.forward(
        std::io::BufReader::new(&out[..]),
        "out.nc",
        &mut |_, _, _| {},
    )
    .map_err(|e| format!("the written program is refused by its reader: {e}"))?;
    Ok(true)
}

#[test]
fn mutants_of_line_ends_and_modal_codes_are_processed_or_refused_cleanly() {
    let count = env_count("HOSTILE_MUTANTS", CI_MUTANTS);
    let m = tool("afm-r1000");
    let pools = pools();
    let seeds = [
        read("samples/effects.nc"),
        read("samples/part.nc"),
        read("samples/gcode/mastercam_haas.nc"),
    ];
    let start = Instant::now();
    let run = generated_run("line-ends", &seeds, count, line_end_mutant, |b| {
        line_end_props(&m, b, &pools)
    });
    report("line-ends", count, start, &run);
}

/// An arc whose ends are within the travel but whose bulge leaves it (Y
/// 30 mm beyond) is refused by `check` as by `compensate`, at its line.
#[test]
fn an_arc_whose_bulge_leaves_the_travel_is_refused() {
    let prog = "G21 G90 G94 G17\nT1 M6\nG43 H1 G0 X0. Y300. Z20.\nS1000 M3\nG1 Z10. F200.\nG2 X160. Y300. I80. J0.\nM30\n";
    let (code, err) = check_program("arc.nc", prog.as_bytes(), "afm-r1000", &["-q"]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("arc.nc:6:1: machine Y = 530.0000 (work Y380.0000 + offsets 150.0000 mm) is outside the travel [0, 500] on the arc"),
        "{err}"
    );
    let (code, _, err) = compensate_program("arc.nc", prog.as_bytes(), "afm-r1000");
    assert_eq!(code, 2, "{err}");
    // The same arc the other way round bulges to Y220, within the travel.
    let inside = prog.replace("G2 X160.", "G3 X160.");
    let (code, err) = check_program("arc.nc", inside.as_bytes(), "afm-r1000", &["-q"]);
    assert_eq!(code, 0, "{err}");
}

/// `compensate` then `check` of the output with the same machine options
/// (`args`): (compensate's exit code and stderr, check's exit code and
/// stderr, the output).
fn compensate_then_check(
    name: &str,
    text: &str,
    args: &[&str],
    tolerance: &str,
) -> ((i32, String), (i32, String), String) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(name);
    let out_path = dir.path().join(format!("out-{name}"));
    std::fs::write(&path, text).unwrap();
    let run = |cmd: &[&str], file: &std::path::Path| {
        let out = crate::common::postproc()
            .args(cmd)
            .args(args)
            .arg(file)
            .output()
            .unwrap();
        (
            out.status.code().unwrap_or(-1),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    let o = out_path.to_str().unwrap();
    let compensated = run(
        &[
            "compensate",
            "-q",
            "--annotate",
            "none",
            "--tolerance",
            tolerance,
            "-o",
            o,
        ],
        &path,
    );
    let written = std::fs::read_to_string(&out_path).unwrap_or_default();
    let checked = run(&["check", "-q"], &out_path);
    (compensated, checked, written)
}

/// A TCPM rapid to the top of Z (machine Z0 of the five-axis machine) at
/// A10: the correction would cross the end by less than the tolerance
/// and is held there. Under TCPM a tip word moves the other machine axes,
/// so the rapid gets every tip word its correction needs (the corrected Y
/// left out moved machine Z 4 µm past its end), and the compensated
/// program passes its own `check`.
#[test]
fn a_tcpm_rapid_at_the_top_of_z_is_written_within_the_travel() {
    let prog = "G21 G90 G17 G94\nG54 G0 X0. Y0. A0. C0.\nG43.4 H1 G0 Z100.\nG0 X50. Y20. A10. C30.\nG0 Z200.485\nG0 Z100.\nG49\nM30\n";
    let args = ["--machine", "five-axis-ac"];
    let ((code, err), (check, check_err), out) =
        compensate_then_check("top.nc", prog, &args, "0.02");
    assert_eq!(code, 0, "{err}");
    assert_eq!(check, 0, "{check_err}\n{out}");
    // The rapid to the top writes the corrected X and Y too.
    let top = out
        .lines()
        .find(|l| l.starts_with("G0 ") && l.contains(" Z200.4"))
        .unwrap_or("");
    assert!(top.contains('X') && top.contains('Y'), "{out}");
}

/// A point held at the top of Z with a work offset of more decimals than
/// the written words (G54 Z200.00003: the end is work Z299.99997) is
/// written one unit inside (`Z299.9999`), not rounded past the end
/// (`Z300.`, machine Z500.00003, which `check` refuses).
#[test]
fn a_point_held_at_a_travel_end_is_rounded_inside_it() {
    let bundled = std::fs::read_to_string(crate::common::repo("machines/afm-r1000.yaml")).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let table = dir.path().join("table.yaml");
    std::fs::write(
        &table,
        bundled.replace("tolerance_mm: 0.003", "tolerance_mm: 0.02"),
    )
    .unwrap();
    let prog = std::fs::read_to_string(crate::common::repo("tests/shop/plasma_no_z.nc")).unwrap();
    let args = [
        "--machine",
        table.to_str().unwrap(),
        "--work-offset",
        "G54=100,50,200.00003",
    ];
    let ((code, err), (check, check_err), out) =
        compensate_then_check("plasma.nc", &prog, &args, "0.02");
    assert_eq!(code, 0, "{err}");
    assert_eq!(check, 0, "{check_err}\n{out}");
    assert!(
        out.contains(" Z299.9999") && !out.contains(" Z300."),
        "{out}"
    );
}

/// A thermal scale origin far outside its axis' travel is a coordinate of
/// another convention (machine zero at the other end, another unit): it is
/// refused at its key with the plausible range; one within the travel
/// widened by its length is read. The fixture is the AFM R-1000 counted
/// from the bottom (X travel 0..1000 mm: plausible −1000..2000 mm).
#[test]
fn a_scale_origin_far_outside_the_travel_is_refused() {
    let base = crate::common::text("tests/shop/zbottom/afm-r1000-zbottom.yaml");
    let line = "    X: { scale_ppm_per_kw: 60.0, time_constant_min: 40.0, friction_n: 300.0 }";
    let with = |origin: &str| {
        edited(
            &base,
            line,
            &format!(
                "    X: {{ scale_ppm_per_kw: 60.0, time_constant_min: 40.0, friction_n: 300.0, scale_origin_mm: {origin} }}"
            ),
        )
    };
    refused_at(
        &with("2500.0"),
        "samples/part.nc",
        "    X: { scale_ppm_per_kw",
        "thermal.axes.X.scale_origin_mm: 2500 mm is outside -1000..2000 mm, the plausible range of a scale origin (the X travel 0..1000 mm widened by its length on each side",
    );
    let (code, err) = check_with_machine(&with("1500.0"), "samples/part.nc");
    assert!(code == 0 || code == 1, "{err}");
}
