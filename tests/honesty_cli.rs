//! Integration tests: the honesty rule of `postproc calibrate`
//! (docs/calibration.md, "Uncertain parameters") through the binary, for
//! every kind. A poorly identified data set (large noise) lists its
//! uncertain parameters and the written file keeps their input values;
//! with `--write-uncertain` the identified values are written; a
//! well-identified data set lists nothing and writes every identified
//! value. `diagnose --write-model` leaves uncertain parameters of an
//! accepted effect out the same way.
//!
//! What a file holds is read back through the binary: calibrating the
//! written file again (from the other data set of the kind, so that the
//! run has corrections to make) prints its values in the `start` column.

use std::path::{Path, PathBuf};

use crate::common::{postproc, repo};

/// A written value equals the printed one when they differ by less than
/// this fraction of the parameter's expanded uncertainty (the files and
/// the table round far below U).
const SAME_IN_U: f64 = 0.02;
/// Agreement of an added TCP offset with the simulated 0.3 mm: a tenth of it.
const ADDED_OFFSET_TOL_MM: f64 = 0.03;

/// One row of the printed table.
#[derive(Debug, Clone)]
struct Row {
    name: String,
    start: f64,
    value: f64,
    big_u: Option<f64>,
}

/// The parameter table of a calibration's standard output.
fn table(stdout: &str) -> Vec<Row> {
    stdout
        .lines()
        .skip_while(|l| !l.starts_with("parameter "))
        .skip(1)
        .map_while(|l| {
            let t: Vec<&str> = l.split_whitespace().collect();
            Some(Row {
                name: t.first()?.to_string(),
                start: t.get(1)?.parse().ok()?,
                value: t.get(2)?.parse().ok()?,
                big_u: t.get(4).and_then(|v| v.parse().ok()),
            })
        })
        .collect()
}

/// Names in the "uncertain (…)" list of a calibration's standard output.
fn uncertain(stdout: &str) -> Vec<String> {
    stdout
        .lines()
        .skip_while(|l| !l.starts_with("uncertain ("))
        .skip(1)
        .map_while(|l| l.strip_prefix("  "))
        .filter_map(|l| l.split(':').next().map(str::to_string))
        .collect()
}

/// Runs `postproc calibrate KIND` and returns its standard output; `out`
/// must be written.
fn calibrate(kind: &str, machine: &Path, obs: &Path, out: &Path, extra: &[&str]) -> String {
    let a = postproc()
        .args(["calibrate", kind, "--machine"])
        .arg(machine)
        .arg("--observations")
        .arg(obs)
        .arg("-o")
        .arg(out)
        .args(extra)
        .assert()
        .success();
    assert!(out.exists(), "{} written", out.display());
    String::from_utf8_lossy(&a.get_output().stdout).into_owned()
}

/// The values the machine file `file` holds for the parameters of a
/// calibration of `kind` (the `start` column of a run from `obs`).
fn held(kind: &str, file: &Path, obs: &Path, dir: &Path) -> Vec<Row> {
    let again = dir.join("again.yaml");
    let a = postproc()
        .args(["calibrate", kind, "--holdout", "0", "--machine"])
        .arg(file)
        .arg("--observations")
        .arg(obs)
        .arg("-o")
        .arg(&again)
        .assert();
    let rows = table(&String::from_utf8_lossy(&a.get_output().stdout));
    assert!(
        !rows.is_empty(),
        "a table from {}: {}",
        file.display(),
        String::from_utf8_lossy(&a.get_output().stderr)
    );
    rows
}

fn start_of(rows: &[Row], name: &str) -> f64 {
    rows.iter()
        .find(|r| r.name == name)
        .unwrap_or_else(|| panic!("{name} in the table"))
        .start
}

/// `got` is `want` within [`SAME_IN_U`] of the expanded uncertainty.
fn same(got: f64, want: f64, big_u: f64) -> bool {
    (got - want).abs() <= SAME_IN_U * big_u + 1e-9 * want.abs()
}

/// The poorly identified case of one kind: some parameters are listed as
/// uncertain and keep their input values; with --write-uncertain they are
/// listed too and written; every other identified value is written either
/// way.
/// `probe`: the data set of the read-back runs.
fn check_poor(kind: &str, machine: &Path, obs: &Path, probe: &Path) {
    let dir = tempfile::tempdir().expect("tempdir");
    let kept_file = dir.path().join("kept.yaml");
    let stdout = calibrate(kind, machine, obs, &kept_file, &["--holdout", "0"]);
    let rows = table(&stdout);
    let listed = uncertain(&stdout);
    assert!(
        !listed.is_empty(),
        "{kind}: uncertain parameters listed:\n{stdout}"
    );
    assert!(
        stdout.contains("NOT written (the file's value is kept"),
        "{stdout}"
    );
    let all_file = dir.path().join("all.yaml");
    let stdout_all = calibrate(
        kind,
        machine,
        obs,
        &all_file,
        &["--holdout", "0", "--write-uncertain"],
    );
    assert_eq!(uncertain(&stdout_all), listed, "{stdout_all}");
    assert!(stdout_all.contains("written because of --write-uncertain"));
    let kept = held(kind, &kept_file, probe, dir.path());
    let all = held(kind, &all_file, probe, dir.path());
    let mut moved = 0;
    for r in &rows {
        let Some(big_u) = r.big_u else { continue };
        let in_kept = start_of(&kept, &r.name);
        let in_all = start_of(&all, &r.name);
        assert!(
            same(in_all, r.value, big_u),
            "{kind}: {} written with --write-uncertain: {in_all} vs {}",
            r.name,
            r.value
        );
        if listed.contains(&r.name) {
            assert!(
                same(in_kept, r.start, big_u),
                "{kind}: uncertain {} keeps the input value {}: {in_kept}",
                r.name,
                r.start
            );
            if !same(r.value, r.start, 4.0 * big_u) {
                moved += 1;
            }
        } else {
            assert!(
                same(in_kept, r.value, big_u),
                "{kind}: {} written: {in_kept} vs {}",
                r.name,
                r.value
            );
        }
    }
    assert!(
        moved > 0,
        "{kind}: an uncertain value differs from its input value (the test bites)"
    );
}

/// The well-identified case: nothing listed, every identified value written.
/// `probe`: the data set of the read-back run.
fn check_good(kind: &str, machine: &Path, obs: &Path, probe: &Path) {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("cal.yaml");
    let stdout = calibrate(kind, machine, obs, &out, &[]);
    assert!(uncertain(&stdout).is_empty(), "{kind}:\n{stdout}");
    assert!(!stdout.contains("uncertain ("), "{stdout}");
    let rows = table(&stdout);
    let written = held(kind, &out, probe, dir.path());
    let mut identified = 0;
    for r in &rows {
        let Some(big_u) = r.big_u else { continue };
        identified += 1;
        let got = start_of(&written, &r.name);
        assert!(
            same(got, r.value, big_u),
            "{kind}: {} written: {got} vs {}",
            r.name,
            r.value
        );
    }
    assert!(identified > 0, "{kind}: identified values in\n{stdout}");
}

/// `postproc simulate` of `poses` from `truth` with `noise_um` per coordinate.
fn simulated(truth: &Path, poses: &Path, noise_um: &str, seed: &str, dir: &Path) -> PathBuf {
    let out = dir.join("measured.csv");
    postproc()
        .args(["simulate", "--machine"])
        .arg(truth)
        .arg("--observations")
        .arg(poses)
        .args(["--noise-um", noise_um, "--seed", seed, "-o"])
        .arg(&out)
        .assert()
        .success();
    out
}

const OBS: &str = "samples/observations";

#[test]
fn stiffness_uncertain_joints_keep_the_file_value() {
    let dir = tempfile::tempdir().expect("tempdir");
    let machine = repo("machines/abb-irb1600.yaml");
    // 100 µm noise: the wrist stiffness k6 is not determined.
    let noisy = simulated(
        &repo(&format!("{OBS}/irb1600-truth.yaml")),
        &repo(&format!("{OBS}/irb1600-ldbb-poses.csv")),
        "100",
        "1",
        dir.path(),
    );
    let good = repo(&format!("{OBS}/irb1600-ldbb-measured.csv"));
    check_poor("stiffness", &machine, &noisy, &good);
    check_good("stiffness", &machine, &good, &noisy);
}

#[test]
fn kinematics_uncertain_parameters_keep_the_file_value() {
    let dir = tempfile::tempdir().expect("tempdir");
    let machine = repo("machines/abb-irb1600.yaml");
    let noisy = simulated(
        &repo(&format!("{OBS}/irb1600-truth.yaml")),
        &repo(&format!("{OBS}/irb1600-kinematic-poses.csv")),
        "300",
        "2",
        dir.path(),
    );
    let good = repo(&format!("{OBS}/irb1600-kinematic-measured.csv"));
    check_poor("kinematics", &machine, &noisy, &good);
    check_good("kinematics", &machine, &good, &noisy);
}

#[test]
fn geometry_uncertain_table_values_keep_the_file_value() {
    let dir = tempfile::tempdir().expect("tempdir");
    let machine = repo("machines/afm-r1000.yaml");
    // 10 µm noise against errors of a few µm.
    let noisy = simulated(
        &repo(&format!("{OBS}/afm-r1000-truth.yaml")),
        &repo(&format!("{OBS}/afm-r1000-grid-poses.csv")),
        "10",
        "3",
        dir.path(),
    );
    let good = repo(&format!("{OBS}/afm-r1000-grid-measured.csv"));
    check_poor("geometry", &machine, &noisy, &good);
    // The 1 µm sample: entries near zero are known to within the length
    // floor and written.
    check_good("geometry", &machine, &good, &noisy);
}

#[test]
fn robot_thermal_uncertain_terms_keep_the_file_value() {
    let dir = tempfile::tempdir().expect("tempdir");
    let start = repo(&format!("{OBS}/irb1600-thermal-start.yaml"));
    let clean = simulated(
        &repo(&format!("{OBS}/irb1600-thermal-truth.yaml")),
        &repo(&format!("{OBS}/irb1600-thermal-poses.csv")),
        "1",
        "5",
        dir.path(),
    );
    // The sample (laser tracker noise against growths of tens of µm).
    let sample = repo(&format!("{OBS}/irb1600-thermal-measured.csv"));
    check_poor("thermal", &start, &sample, &clean);
    check_good("thermal", &start, &clean, &sample);
}

/// The grid poses with a spindle power of 0…8 kW and an X drive power of
/// 0…400 W per row (a fixed pattern), as an observation file in `dir`.
fn powered_poses(dir: &Path) -> PathBuf {
    let text =
        std::fs::read_to_string(repo(&format!("{OBS}/afm-r1000-grid-poses.csv"))).expect("poses");
    let mut out = String::new();
    let mut header = true;
    let mut k = 0u32;
    for line in text.lines() {
        if line.trim_start().starts_with('#') || line.trim().is_empty() {
            out.push_str(line);
        } else if header {
            header = false;
            out.push_str(&format!("{line},spindle_w,pX_w"));
        } else {
            k += 1;
            let spindle = f64::from((k * 37) % 17) * 500.0;
            let x = f64::from((k * 11) % 9) * 50.0;
            out.push_str(&format!("{line},{spindle},{x}"));
        }
        out.push('\n');
    }
    let p = dir.join("powered-poses.csv");
    std::fs::write(&p, out).expect("write poses");
    p
}

#[test]
fn machine_tool_thermal_uncertain_gains_keep_the_file_value() {
    let dir = tempfile::tempdir().expect("tempdir");
    let machine = repo("machines/afm-r1000.yaml");
    let model = std::fs::read_to_string(&machine).expect("machine file");
    let truth_text = model
        .replacen("growth_um_per_kw: 3.0", "growth_um_per_kw: 11.0", 1)
        .replacen(
            "X: { scale_ppm_per_kw: 60.0,",
            "X: { scale_ppm_per_kw: 90.0,",
            1,
        );
    assert_ne!(truth_text, model);
    let truth = dir.path().join("truth.yaml");
    std::fs::write(&truth, truth_text).expect("write truth");
    let poses = powered_poses(dir.path());
    let noisy_dir = dir.path().join("noisy");
    std::fs::create_dir(&noisy_dir).expect("mkdir");
    let noisy = simulated(&truth, &poses, "300", "8", &noisy_dir);
    let clean = simulated(&truth, &poses, "1", "8", dir.path());
    check_poor("thermal", &machine, &noisy, &clean);
    check_good("thermal", &machine, &clean, &noisy);
}

/// The threshold is the user's: a lax one lists nothing, a strict one
/// more; a threshold that is not a positive fraction is refused (exit 2).
#[test]
fn uncertain_above_sets_the_threshold() {
    let dir = tempfile::tempdir().expect("tempdir");
    let start = repo(&format!("{OBS}/irb1600-thermal-start.yaml"));
    let obs = repo(&format!("{OBS}/irb1600-thermal-measured.csv"));
    let out = dir.path().join("cal.yaml");
    let default = uncertain(&calibrate("thermal", &start, &obs, &out, &[]));
    let lax = calibrate("thermal", &start, &obs, &out, &["--uncertain-above", "3"]);
    assert!(uncertain(&lax).is_empty(), "{lax}");
    let strict = calibrate("thermal", &start, &obs, &out, &["--uncertain-above", "0.1"]);
    let strict = uncertain(&strict);
    assert!(strict.len() > default.len(), "{strict:?} vs {default:?}");
    assert!(default.iter().all(|n| strict.contains(n)));
    for bad in ["0", "-0.5", "nan", "1000"] {
        postproc()
            .args(["calibrate", "thermal", "--machine"])
            .arg(&start)
            .arg("--observations")
            .arg(&obs)
            .arg("-o")
            .arg(dir.path().join("bad.yaml"))
            .args([&format!("--uncertain-above={bad}")])
            .assert()
            .code(2)
            .stderr(predicates::str::contains("--uncertain-above"));
    }
    assert!(!dir.path().join("bad.yaml").exists());
}

/// The TCP of the flange, mm, of the robot machine file at `path`.
fn tcp_mm(path: &Path) -> [f64; 3] {
    let text = std::fs::read_to_string(path).expect("written model");
    match postproc::machine::Machine::from_yaml_str(&text, "model.yaml").expect("loads") {
        postproc::machine::Machine::Robot(r) => r.flange_to_tool().translation.vector.into(),
        postproc::machine::Machine::Tool(_) => panic!("a robot"),
    }
}

/// `diagnose --write-model` adds an accepted effect's parameters under the
/// same rule: a hidden TCP offset of 0.3 mm in x (none in y, z) is found;
/// its y and z components are uncertain and not added (listed as not
/// written) unless --write-uncertain.
#[test]
fn diagnose_write_model_leaves_uncertain_parameters_out() {
    let dir = tempfile::tempdir().expect("tempdir");
    let model = repo("samples/diagnose/model.yaml");
    let text = std::fs::read_to_string(&model).expect("model");
    let from = "flange_to_tool: { x_mm: 0.0, y_mm: 0.0, z_mm: 150.0";
    assert!(text.contains(from));
    let truth = dir.path().join("true.yaml");
    std::fs::write(
        &truth,
        text.replacen(
            from,
            "flange_to_tool: { x_mm: 0.3, y_mm: 0.0, z_mm: 150.0",
            1,
        ),
    )
    .expect("write truth");
    let measured = dir.path().join("measured.csv");
    postproc()
        .args(["simulate", "--machine"])
        .arg(&truth)
        .arg("--observations")
        .arg(repo("samples/diagnose/measured.csv"))
        .args([
            "--noise-um",
            "15",
            "--noise-um-per-m",
            "6",
            "--seed",
            "4",
            "-o",
        ])
        .arg(&measured)
        .assert()
        .success();
    let run = |out: &Path, extra: &[&str]| -> String {
        let a = postproc()
            .args(["diagnose", "--machine"])
            .arg(&model)
            .arg("--observations")
            .arg(&measured)
            .arg("--write-model")
            .arg(out)
            .args(extra)
            .assert()
            .success();
        String::from_utf8_lossy(&a.get_output().stdout).into_owned()
    };
    let kept = dir.path().join("kept.yaml");
    let stdout = run(&kept, &[]);
    assert!(stdout.contains("added tcp_offset"), "{stdout}");
    for c in ["dy", "dz"] {
        assert!(
            stdout.contains(&format!("not written: tcp_offset: {c} [µm] = ")),
            "{c} listed:\n{stdout}"
        );
    }
    assert!(!stdout.contains("tcp_offset: dx"), "{stdout}");
    let t = tcp_mm(&kept);
    assert!((t[0] - 0.3).abs() < ADDED_OFFSET_TOL_MM, "x added: {t:?}");
    assert_eq!([t[1], t[2]], [0.0, 150.0], "y, z keep the file's values");
    let all = dir.path().join("all.yaml");
    let stdout = run(&all, &["--write-uncertain"]);
    assert!(!stdout.contains("not written: tcp_offset"), "{stdout}");
    let t_all = tcp_mm(&all);
    assert_eq!(t_all[0], t[0]);
    assert!(
        t_all[1] != 0.0 && t_all[2] != 150.0,
        "y, z added: {t_all:?}"
    );
}
