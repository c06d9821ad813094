//! Hostile inputs of issue 43's second round, as generators: observation
//! sets with near-copies of their poses, observation files written in
//! another unit, and RAPID modules read a window at a time against read
//! whole. Each runs `HOSTILE_MUTANTS` inputs (`scripts/hostile`: 10 000 per
//! kind) with the same reporting as the byte mutants of [`super`].

use std::time::Instant;

use postproc::calibrate::observations::{Observations, read_observations};
use postproc::calibrate::screen::{
    NEAR_DEG, NEAR_MM, check_units, distinct_poses, grouped_split, pose_groups,
};
use postproc::machine::Machine;

use super::{CI_BINARY, CI_MUTANTS, Rng, env_count, generated_run, mutate, read, report};
use crate::common::repo;

/// A uniform number in `[lo, hi)`.
fn uniform(rng: &mut Rng, lo: f64, hi: f64) -> f64 {
    lo + (hi - lo) * (rng.next() >> 11) as f64 / (1u64 << 53) as f64
}

/// The header line's index and its column names.
fn header(lines: &[&str]) -> Option<(usize, Vec<String>)> {
    let at = lines
        .iter()
        .position(|l| !l.starts_with('#') && !l.trim().is_empty())?;
    Some((
        at,
        lines[at].split(',').map(|s| s.trim().to_string()).collect(),
    ))
}

fn observations(bytes: &[u8]) -> Result<Observations, String> {
    read_observations(bytes, "m.csv").map_err(|e| e.to_string())
}

/// The tolerance within which a pose column's values are one pose
/// (joint and rotary angles, linear axes), `None` for other columns.
fn pose_tolerance(name: &str) -> Option<f64> {
    if name.ends_with("_deg") {
        Some(NEAR_DEG)
    } else if matches!(name, "X_mm" | "Y_mm" | "Z_mm") {
        Some(NEAR_MM)
    } else {
        None
    }
}

/// One observation set with near-copies: rows that are the first of
/// their pose in `seed` measured again one to five times, each pose value
/// moved by up to 0.45 of the pose tolerance and each measured coordinate
/// by up to 5 µm of noise; a copy's id is `<id>~<k>`. Copies go at random
/// places after their original.
fn near_copy_mutant(rng: &mut Rng, seed: &[u8]) -> Vec<u8> {
    let text = String::from_utf8_lossy(seed);
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let refs: Vec<&str> = lines.iter().map(String::as_str).collect();
    let Some((h, names)) = header(&refs) else {
        return seed.to_vec();
    };
    let Ok(obs) = observations(seed) else {
        return seed.to_vec();
    };
    let (of_row, _) = pose_groups(&obs);
    let firsts: Vec<usize> = (0..of_row.len())
        .filter(|&i| of_row[..i].iter().all(|&g| g != of_row[i]))
        .collect();
    // Copies made from the seed's lines, inserted afterwards from the
    // last position up so the positions stay those of the seed.
    let mut inserts: Vec<(usize, String)> = Vec::new();
    for c in 0..1 + rng.below(12) {
        let r = firsts[rng.below(firsts.len())];
        let line = h + 1 + r;
        let moved: Vec<String> = lines[line]
            .split(',')
            .zip(&names)
            .map(|(v, name)| {
                if name == "id" {
                    return format!("{v}~{c}");
                }
                let Ok(x) = v.trim().parse::<f64>() else {
                    return v.to_string();
                };
                match (pose_tolerance(name), name.as_str()) {
                    (Some(tol), _) => format!("{:.6}", x + uniform(rng, -0.45, 0.45) * tol),
                    (None, "x_mm" | "y_mm" | "z_mm") => {
                        format!("{:.6}", x + uniform(rng, -0.005, 0.005))
                    }
                    _ => v.to_string(),
                }
            })
            .collect();
        let at = line + 1 + rng.below(lines.len() - line);
        inserts.push((at, moved.join(",")));
    }
    inserts.sort_by_key(|b| std::cmp::Reverse(b.0));
    for (at, l) in inserts {
        lines.insert(at, l);
    }
    let mut out = lines.join("\n");
    out.push('\n');
    out.into_bytes()
}

/// A near-copy mutant's rows count as their originals' poses: as many
/// distinct poses as the seed, each copy in its original's pose group, and
/// on the same side of every held-out split.
fn near_copy_props(seed_poses: usize, input: &[u8]) -> Result<bool, String> {
    let obs = observations(input)?;
    let (of_row, n) = pose_groups(&obs);
    if n != seed_poses {
        return Err(format!("{n} pose groups where the seed has {seed_poses}"));
    }
    let all: Vec<usize> = (0..obs.rows.len()).collect();
    if distinct_poses(&obs, &all) != seed_poses {
        return Err("distinct_poses counts near-copies as poses".into());
    }
    let original = |i: usize| -> Option<usize> {
        let id = obs.rows[i].id.split('~').next()?;
        obs.rows.iter().position(|r| r.id == id)
    };
    for seed in [1, 7, 42] {
        let (fit, _) = grouped_split(&obs, 0.25, seed);
        for i in 0..obs.rows.len() {
            let Some(o) = original(i) else { continue };
            if of_row[i] != of_row[o] {
                return Err(format!(
                    "row {} is not in its original's pose",
                    obs.rows[i].id
                ));
            }
            if fit.contains(&i) != fit.contains(&o) {
                return Err(format!(
                    "split {seed} puts row {} apart from its original",
                    obs.rows[i].id
                ));
            }
        }
    }
    Ok(true)
}

#[test]
fn mutants_of_observation_sets_with_near_copies_count_each_pose_once() {
    let count = env_count("HOSTILE_MUTANTS", CI_MUTANTS);
    let seeds = [
        read("samples/observations/afm-r1000-grid-measured.csv"),
        read("samples/observations/irb1600-kinematic-measured.csv"),
        read("samples/observations/irb1600-thermal-measured.csv"),
        read("samples/observations/irb1600-ldbb-measured.csv"),
    ];
    let poses: Vec<usize> = seeds
        .iter()
        .map(|s| pose_groups(&observations(s).expect("seed")).1)
        .collect();
    let start = Instant::now();
    // The generator walks the seeds in turn: the mutant of call `i` is of
    // seed `i % 4`, which tells its pose count.
    let mut checked = 0usize;
    let run = generated_run("near-copies", &seeds, count, near_copy_mutant, |b| {
        // The first calls check the seeds themselves, in order.
        let k = checked % seeds.len();
        checked += 1;
        near_copy_props(poses[k], b)
    });
    report("near-copies", count, start, &run);
}

/// Units position columns are often written in by mistake: the factor
/// from mm to the unit and its name in the refusal.
const UNITS: [(f64, &str); 5] = [
    (1.0 / 25.4, "inch"),
    (1e-3, "m"),
    (0.1, "cm"),
    (1e3, "µm"),
    (0.01, "dm"),
];

/// The measured-position columns of `seed` multiplied by `factor` and
/// shifted by `offset` (an instrument's origin, in the file's unit).
fn scaled_positions(seed: &[u8], factor: f64, offset: [f64; 3]) -> Vec<u8> {
    let text = String::from_utf8_lossy(seed);
    let lines: Vec<&str> = text.lines().collect();
    let Some((h, names)) = header(&lines) else {
        return seed.to_vec();
    };
    let mut out = String::with_capacity(seed.len() + 64);
    for (i, l) in lines.iter().enumerate() {
        if i <= h {
            out.push_str(l);
        } else {
            let fields: Vec<String> = l
                .split(',')
                .zip(&names)
                .map(|(v, name)| {
                    let axis = ["x_mm", "y_mm", "z_mm"].iter().position(|c| c == name);
                    match (axis, v.trim().parse::<f64>()) {
                        (Some(a), Ok(x)) => format!("{:.9}", x * factor + offset[a]),
                        _ => v.to_string(),
                    }
                })
                .collect();
            out.push_str(&fields.join(","));
        }
        out.push('\n');
    }
    out.into_bytes()
}

/// One observation file in a unit: the first byte says which (0..5 a unit
/// of [`UNITS`], 5 mm with a factor within 10 %, 6 a factor between two
/// units), the rest is the file.
fn unit_mutant(rng: &mut Rng, seed: &[u8]) -> Vec<u8> {
    let which = rng.below(7);
    let factor = match which {
        0..=4 => UNITS[which].0,
        5 => uniform(rng, 0.9, 1.1),
        // Between two units (a mistake no unit explains): 2.5–7 or 1/7–1/2.5.
        _ => {
            let f = uniform(rng, 2.5, 7.0);
            if rng.below(2) == 0 { f } else { 1.0 / f }
        }
    };
    let spread = 3000.0 * factor;
    let offset = [0, 1, 2].map(|_| uniform(rng, -spread, spread));
    let mut out = vec![which as u8];
    out.extend(scaled_positions(seed, factor, offset));
    out
}

/// A unit mutant on `machine`: a file in a unit of [`UNITS`] is refused
/// naming it, one in mm (within 10 %) is taken, one between two units is
/// refused.
fn unit_props(machine: &Machine, input: &[u8]) -> Result<bool, String> {
    let (&which, file) = input.split_first().ok_or("empty")?;
    let obs = observations(file)?;
    match (which, check_units(machine, &obs, "m.csv")) {
        (5, Ok(())) => Ok(true),
        (5, Err(e)) => Err(format!("positions in mm refused: {e}")),
        (w, Ok(())) => Err(format!("positions scaled ({w}) taken as mm")),
        (w @ 0..=4, Err(e)) => {
            let m = e.to_string();
            let unit = UNITS[usize::from(w)].1;
            if m.contains(&format!("look like {unit},")) {
                Ok(false)
            } else {
                Err(format!("{unit} not named: {m}"))
            }
        }
        (_, Err(e)) if e.exit_code() == 2 => Ok(false),
        (_, Err(e)) => Err(format!("exit code {}: {e}", e.exit_code())),
    }
}

fn machine(rel: &str) -> Machine {
    let text = String::from_utf8(read(rel)).expect("utf-8");
    Machine::from_yaml_str(&text, rel).expect("machine")
}

#[test]
fn mutants_of_observations_in_another_unit_are_refused_naming_it() {
    let count = env_count("HOSTILE_MUTANTS", CI_MUTANTS);
    let cases = [
        (
            "machines/afm-r1000.yaml",
            "samples/observations/afm-r1000-grid-measured.csv",
        ),
        (
            "machines/abb-irb1600.yaml",
            "samples/observations/irb1600-kinematic-measured.csv",
        ),
        (
            "machines/abb-irb1600.yaml",
            "samples/observations/irb1600-tracker-measured.csv",
        ),
    ];
    let start = Instant::now();
    let mut accepted = 0;
    let mut findings = Vec::new();
    for (k, (m, obs)) in cases.iter().enumerate() {
        let m = machine(m);
        let mut seed = vec![5u8];
        seed.extend(read(obs));
        let n = count / cases.len() + usize::from(k < count % cases.len());
        let (a, f) = generated_run(&format!("units-{k}"), &[seed], n, unit_mutant_of, |b| {
            unit_props(&m, b)
        });
        accepted += a;
        findings.extend(f);
    }
    report("units", count, start, &(accepted, findings));
}

/// [`unit_mutant`] of a seed that carries its unit byte.
fn unit_mutant_of(rng: &mut Rng, seed: &[u8]) -> Vec<u8> {
    unit_mutant(rng, &seed[1..])
}

/// Through the binary: `calibrate kinematics` and `diagnose` of positions
/// in another unit exit 2 naming it, and leave no model written.
#[test]
fn observations_in_another_unit_are_refused_by_calibrate_and_diagnose() {
    let count = env_count("HOSTILE_BINARY", CI_BINARY).max(UNITS.len());
    let dir = tempfile::tempdir().expect("tmp");
    let seed = read("samples/observations/irb1600-kinematic-measured.csv");
    let mut rng = Rng(0x0417);
    for i in 0..count {
        let (factor, unit) = UNITS[i % UNITS.len()];
        let offset = [0, 1, 2].map(|_| uniform(&mut rng, -1000.0, 1000.0) * factor);
        let obs = dir.path().join(format!("m{i}.csv"));
        std::fs::write(&obs, scaled_positions(&seed, factor, offset)).expect("write");
        let model = dir.path().join(format!("m{i}.yaml"));
        for args in [
            &["calibrate", "kinematics", "-o"][..],
            &["diagnose", "--write-model"][..],
        ] {
            let out = crate::common::postproc()
                .args(args)
                .arg(&model)
                .args(["--machine"])
                .arg(repo("machines/abb-irb1600.yaml"))
                .arg("--observations")
                .arg(&obs)
                .output()
                .expect("run");
            let err = String::from_utf8_lossy(&out.stderr);
            assert_eq!(out.status.code(), Some(2), "{args:?} {unit}: {err}");
            assert!(err.contains(&format!("look like {unit},")), "{unit}: {err}");
            assert!(!model.exists(), "{args:?} {unit}: a model was written");
        }
    }
}

/// RAPID lines that change how later moves are read (configuration
/// monitoring, singularity handling) or repeat a move.
const RAPID_LINES: [&str; 6] = [
    "        ConfL\\Off;",
    "        ConfL\\On;",
    "        ConfJ\\Off;",
    "        SingArea\\Wrist;",
    "        SingArea\\Off;",
    "        WaitTime 0.1;",
];

/// One RAPID module mutant: byte edits (half of them) or lines of
/// [`RAPID_LINES`] and copies of move lines inserted inside routines.
fn window_mutant(rng: &mut Rng, seed: &[u8]) -> Vec<u8> {
    if rng.below(2) == 0 {
        return mutate(rng, seed);
    }
    let text = String::from_utf8_lossy(seed);
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let moves: Vec<usize> = (0..lines.len())
        .filter(|&i| lines[i].trim_start().starts_with("Move"))
        .collect();
    if moves.is_empty() {
        return seed.to_vec();
    }
    for _ in 0..1 + rng.below(4) {
        let at = moves[rng.below(moves.len())] + rng.below(2);
        let line = if rng.below(3) == 0 {
            lines[moves[rng.below(moves.len())]].clone()
        } else {
            RAPID_LINES[rng.below(RAPID_LINES.len())].to_string()
        };
        lines.insert(at.min(lines.len()), line);
    }
    let mut out = lines.join("\n");
    out.push('\n');
    out.into_bytes()
}

/// `compensate` of `input` in process, with `extra` flags: the bytes
/// written, or the error.
fn compensate_in_process(
    dir: &std::path::Path,
    out: &str,
    extra: &[&str],
) -> Result<Vec<u8>, String> {
    use clap::Parser;
    let out = dir.join(out);
    let _ = std::fs::remove_file(&out);
    let input = dir.join("m.mod");
    let mut args = vec![
        "postproc".to_string(),
        "-q".into(),
        "compensate".into(),
        "--machine".into(),
        "abb-irb1600".into(),
        "-o".into(),
        out.display().to_string(),
        input.display().to_string(),
    ];
    args.extend(extra.iter().map(|s| s.to_string()));
    let cli = postproc::cli::Cli::try_parse_from(&args).map_err(|e| e.to_string())?;
    match postproc::cli::run(cli) {
        Ok(_) => std::fs::read(&out).map_err(|e| format!("no output: {e}")),
        Err(e) => {
            if out.exists() {
                return Err(format!("output left after an error: {e}"));
            }
            Err(format!("error: {e}"))
        }
    }
}

/// `report` of a written module in process (to a file): the module's
/// own reading, which refuses a target out of reach, takes it or not.
fn read_back_in_process(dir: &std::path::Path, path: &std::path::Path) -> Result<(), String> {
    use clap::Parser;
    let args = [
        "postproc".to_string(),
        "-q".into(),
        "report".into(),
        "--machine".into(),
        "abb-irb1600".into(),
        "-o".into(),
        dir.join("report.txt").display().to_string(),
        path.display().to_string(),
    ];
    let cli = postproc::cli::Cli::try_parse_from(&args).map_err(|e| e.to_string())?;
    postproc::cli::run(cli)
        .map(|_| ())
        .map_err(|e| e.to_string())
}

/// A module compensated read whole and read a window of 1–64 lines at a
/// time gives the same bytes (or the same error), and what it writes its
/// own reading takes.
fn window_props(dir: &std::path::Path, rng: &mut Rng, input: &[u8]) -> Result<bool, String> {
    std::fs::write(dir.join("m.mod"), input).map_err(|e| e.to_string())?;
    let lines = (1 + rng.below(64)).to_string();
    let whole = compensate_in_process(dir, "whole.mod", &[]);
    let windowed = compensate_in_process(dir, "win.mod", &["--rapid-window-lines", &lines]);
    if whole != windowed {
        let say = |r: &Result<Vec<u8>, String>| match r {
            Ok(b) => format!("{} bytes", b.len()),
            Err(e) => e.clone(),
        };
        return Err(format!(
            "read whole: {}; in windows of {lines} lines: {}",
            say(&whole),
            say(&windowed)
        ));
    }
    match whole {
        Ok(_) => read_back_in_process(dir, &dir.join("whole.mod"))
            .map(|()| true)
            .map_err(|e| format!("the written module is refused by its reading: {e}")),
        Err(e) if e.starts_with("error: ") => Ok(false),
        Err(e) => Err(e),
    }
}

#[test]
fn mutants_of_rapid_modules_read_in_windows_give_the_bytes_read_whole() {
    let count = env_count("HOSTILE_MUTANTS", CI_MUTANTS / 10);
    let dir = tempfile::tempdir().expect("tmp");
    let milling = String::from_utf8(read("samples/milling.mod")).expect("utf-8");
    let conf_off = milling.replacen("\n    MoveL", "\n    ConfL\\Off;\n    MoveL", 1);
    assert_ne!(conf_off, milling, "the ConfL\\Off seed differs");
    let seeds = [
        read("samples/drilling.mod"),
        milling.into_bytes(),
        conf_off.into_bytes(),
    ];
    let mut pick = Rng(0x3D0);
    let start = Instant::now();
    let run = generated_run("rapid-windows", &seeds, count, window_mutant, |b| {
        window_props(dir.path(), &mut pick, b)
    });
    report("rapid-windows", count, start, &run);
}

/// Incremental canned cycles and what surrounds them: levels, repeats,
/// cancels and the moves after a cycle.
const CYCLE_LINES: &[&str] = &[
    "G91",
    "G90",
    "G98",
    "G99",
    "G91 G99 G81 X10. Y0. Z-20. R-5. F100.",
    "G91 G98 G81 X5. Z-3. R-2. F80.",
    "G91 G98 G83 X-5. Z-10. R-400. Q2. F80.",
    "G91 G99 G73 X6. Z-12. R-3. Q3. F120.",
    "G91 G98 G82 X-8. Z-4. R-1. P200 F90.",
    "G91 G81 X10. Z-5. R-2. K3 F100.",
    "G91 G81 X-10. Z-5. R-2. L2 F100.",
    "G90 G98 G81 X20. Y20. Z-2. R2. F100.",
    "X10.",
    "Y-5.",
    "G80",
    "G0 X10.",
    "G1 Z-1. F200.",
];

/// Codes whose axis words are not moves, and codes without motion: none
/// of them, where the program is taken, may add or change a move.
const NON_MOTION_LINES: &[&str] = &[
    "G50.1 X0. Y0.",
    "G50.1 X0.",
    "G50",
    "G50 X0. Z0.",
    "G4 X1.",
    "G4 X0.5",
    "G4 P500",
    "G04 P1.",
    "M5",
    "M9",
    "G15",
    "G69",
];

/// Feed-mode switches, with and without F, and moves right after them.
const FEED_MODE_LINES: &[&str] = &[
    "G93",
    "G94",
    "G95",
    "G94 F500.",
    "G95 F0.1",
    "G93 G1 X10. F2.",
    "G93 G2 X10. Y0. I5. J0. F4.",
    "G1 X5. F0.2",
    "G1 X-5.",
    "F300.",
];

/// `seed`'s lines with one to eight lines of `inserted` put among them
/// (LF line ends; what the line-end generator of [`super`] varies is
/// left alone here, so each kind attacks one thing).
fn inserted_mutant(rng: &mut Rng, seed: &[u8], inserted: &[&str]) -> Vec<u8> {
    let text = String::from_utf8_lossy(seed);
    let mut lines: Vec<&str> = text.lines().collect();
    for _ in 0..1 + rng.below(8) {
        // Not before the first line (a `%` or the program number).
        let at = 1 + rng.below(lines.len().max(1));
        lines.insert(at.min(lines.len()), inserted[rng.below(inserted.len())]);
    }
    let mut out = lines.join("\n");
    out.push('\n');
    out.into_bytes()
}

/// The end point of every move of length of a program, in order, as its
/// reader (the forward pass of `report` and `compensate`) sees them.
fn move_ends(
    machine: &postproc::machine::tool::MachineTool,
    program: &[u8],
    pools: &super::Pools,
) -> Result<Vec<[f64; 6]>, String> {
    let job = super::reader_job(machine, pools);
    let mut ends = Vec::new();
    job.forward(
        std::io::BufReader::new(program),
        "m.nc",
        &mut |_, plan, _| {
            if let Some(mv) = &plan.mv {
                let (s, e) = (mv.start, mv.end);
                if (0..6).any(|i| s[i] != e[i]) {
                    ends.push([0, 1, 2, 3, 4, 5].map(|i| e[i]));
                }
            }
        },
    )
    .map_err(|e| e.to_string())?;
    Ok(ends)
}

/// The properties of [`super::line_end_props`] (no panic, the same
/// bytes or error for 1 and 2 threads, nothing non-finite written, the
/// written program read back by its reader), and for non-motion lines: a
/// program taken with them has the moves of the program without them.
fn inserted_props(
    machine: &postproc::machine::tool::MachineTool,
    input: &[u8],
    pools: &super::Pools,
    no_moves: Option<&[&str]>,
) -> Result<bool, String> {
    let one = super::gcode_run(machine, input, &pools.one);
    if one != super::gcode_run(machine, input, &pools.two) {
        return Err("1 and 2 threads differ".into());
    }
    let out = match one {
        Ok(out) => out,
        Err(m) if m.starts_with("error: ") => return Ok(false),
        Err(m) => return Err(m),
    };
    if super::non_finite_words(&out) > super::non_finite_words(input) {
        return Err("non-finite number in the output".into());
    }
    move_ends(machine, &out, pools)
        .map_err(|e| format!("the written program is refused by its reader: {e}"))?;
    let Some(codes) = no_moves else {
        return Ok(true);
    };
    let text = String::from_utf8_lossy(input);
    let mut without: String = text
        .lines()
        .filter(|l| !codes.contains(l))
        .collect::<Vec<_>>()
        .join("\n");
    without.push('\n');
    let (a, b) = (
        move_ends(machine, input, pools)?,
        move_ends(machine, without.as_bytes(), pools)?,
    );
    if a != b {
        let at = a.iter().zip(&b).position(|(x, y)| x != y);
        return Err(format!(
            "non-motion lines change the moves: {} moves against {} without them, first \
             difference at move {at:?}",
            a.len(),
            b.len()
        ));
    }
    Ok(true)
}

/// One generated G-code kind: `inserted` lines among the sample programs'.
fn inserted_run(kind: &str, inserted: &[&str], no_moves: bool) {
    let count = env_count("HOSTILE_MUTANTS", CI_MUTANTS / 10);
    let m = super::tool("afm-r1000");
    let pools = super::pools();
    let seeds = [
        read("samples/effects.nc"),
        read("samples/part.nc"),
        read("samples/gcode/mastercam_haas.nc"),
    ];
    let start = Instant::now();
    let run = generated_run(
        kind,
        &seeds,
        count,
        |rng, seed| inserted_mutant(rng, seed, inserted),
        |b| inserted_props(&m, b, &pools, no_moves.then_some(inserted)),
    );
    report(kind, count, start, &run);
}

#[test]
fn mutants_with_incremental_cycles_are_processed_or_refused_cleanly() {
    inserted_run("incremental-cycles", CYCLE_LINES, false);
}

#[test]
fn mutants_with_non_motion_codes_keep_the_moves_of_the_program() {
    inserted_run("non-motion-codes", NON_MOTION_LINES, true);
}

#[test]
fn mutants_with_feed_mode_switches_are_processed_or_refused_cleanly() {
    inserted_run("feed-modes", FEED_MODE_LINES, false);
}
