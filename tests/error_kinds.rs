//! Error kinds: a representative error of each kind through the library is
//! of that kind (matched on [`ErrorKind`], not on its words), and each kind
//! leaves the binary with the exit code docs/cli.md gives it.

use std::path::Path;

use nalgebra::Isometry3;

use crate::common::{postproc, repo, text, write};
use postproc::error::{EXIT_ERROR, EXIT_INTERNAL, Error, ErrorKind, Located};
use postproc::machine::robot::{Model, Robot};
use postproc::machine::status::Calibration;
use postproc::machine::{Machine, MachineFile};
use postproc::predict::EffectSet;
use postproc::process::ForceTable;

fn kind<T: std::fmt::Debug>(r: postproc::Result<T>) -> (ErrorKind, Error) {
    let e = r.expect_err("an error");
    (e.kind(), e)
}

#[test]
fn every_bad_machine_file_is_a_machine_error_at_a_line() {
    let dir = repo("tests/bad/machines");
    let mut seen = 0;
    for entry in std::fs::read_dir(&dir).expect("corpus folder") {
        let path = entry.expect("entry").path();
        if path.extension().is_some_and(|e| e == "expect") {
            continue;
        }
        let (k, e) = kind(Machine::load(&path));
        assert_eq!(k, ErrorKind::Machine, "{}: {e}", path.display());
        let Error::Machine(at) = &e else {
            unreachable!("kind Machine is Error::Machine")
        };
        assert!(at.line >= 1 && at.column >= 1, "{}: {e}", path.display());
        seen += 1;
    }
    assert!(seen >= 10, "corpus too small: {seen}");
}

#[test]
fn a_model_value_out_of_range_is_a_machine_error_naming_its_key() {
    let robot = text("machines/abb-irb1600.yaml");
    let bad = robot.replacen("k_nm_per_rad: [", "k_nm_per_rad: [-", 1);
    assert_ne!(bad, robot, "the sample has k_nm_per_rad");
    let (k, e) = kind(Machine::from_yaml_str(&bad, "r.yaml"));
    assert_eq!(k, ErrorKind::Machine);
    let Error::Machine(at) = e else {
        unreachable!("kind Machine is Error::Machine")
    };
    assert!(at.message.starts_with("k_nm_per_rad[0]: "), "{at}");
    let line = bad
        .lines()
        .position(|l| l.contains("k_nm_per_rad"))
        .map(|i| i + 1);
    assert_eq!(Some(at.line), line);
}

/// `calibrations` as a flow list takes another entry: the writer edits the
/// file's syntax tree in any layout the loader reads, so this layout is no
/// longer an error; the record reads back after the one written before.
#[test]
fn a_flow_calibrations_list_takes_another_entry() {
    let base = text("machines/afm-r1000.yaml");
    let entry = format!(
        "{{ date: 2026-01-02, kind: geometry, observations: a.csv, observations_sha256: {}, rows: 3, fit_rms_mm: 0.001 }}",
        "0a".repeat(32)
    );
    let body: String = base
        .lines()
        .filter(|l| !l.starts_with("status:"))
        .map(|l| format!("{l}\n"))
        .collect();
    let flow = format!("{body}status: calibrated\ncalibrations: [{entry}]\n");
    Machine::from_yaml_str(&flow, "m.yaml").expect("a valid machine file");
    let calibration = Calibration {
        date: "2026-02-03".into(),
        kind: "geometry".into(),
        observations: "b.csv".into(),
        observations_sha256: "1b".repeat(32),
        rows: 4,
        fit_rms_mm: 0.002,
    };
    let edit = postproc::machine::yaml_write::Edit::Calibrated(calibration.clone());
    let out =
        postproc::machine::yaml_write::apply(&flow, "m.yaml", "test", &[edit]).expect("written");
    assert!(
        out.contains(&format!("calibrations: [{entry}, {{ date: 2026-02-03")),
        "{out}"
    );
    match postproc::machine::Status::from_yaml_str(&out, "m.yaml").expect("status") {
        postproc::machine::Status::Calibrated(list) => {
            assert_eq!(list.len(), 2);
            assert_eq!(list[1], calibration);
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn a_malformed_input_file_is_an_input_error_at_its_cell() {
    let (k, e) = kind(ForceTable::from_csv_str(
        "line,fx_n,fy_n,fz_n\n1,0,0,0\n2,0,x,0\n",
        "f.csv",
    ));
    assert_eq!(k, ErrorKind::Input, "{e}");
    let Error::Input(at) = e else {
        unreachable!("kind Input is Error::Input")
    };
    assert_eq!((at.file.as_str(), at.line), ("f.csv", 3));
}

#[test]
fn flag_values_and_machine_names_are_usage_errors() {
    let spec: postproc::machine::effects::EffectSpec = "geometric,gravity".parse().expect("names");
    let (k, e) = kind(EffectSet::from_flags(
        &spec,
        &[],
        postproc::predict::MachineKind::Tool,
    ));
    assert_eq!(k, ErrorKind::Usage, "{e}");
    let (k, e) = kind(MachineFile::open("no-such-machine-anywhere"));
    assert_eq!(k, ErrorKind::Usage, "{e}");
}

#[test]
fn an_unreadable_file_is_an_io_error_naming_it() {
    let dir = tempfile::tempdir().expect("temp dir");
    let missing = dir.path().join("absent.yaml");
    let (k, e) = kind(Machine::load(&missing));
    assert_eq!(k, ErrorKind::Io, "{e}");
    let Error::Io { path, .. } = e else {
        unreachable!("kind Io is Error::Io")
    };
    assert_eq!(path, missing);
}

#[test]
fn an_unreachable_robot_target_is_unachievable_at_its_place() {
    let r = Robot::from_yaml_str(&text("machines/abb-irb1600.yaml"), "abb-irb1600.yaml")
        .expect("valid robot");
    let q = [0.3, 0.2, 0.1, 0.4, 0.5, 0.6];
    let far = Isometry3::translation(5000.0, 0.0, 0.0) * r.tcp_pose(Model::Nominal, &q);
    let failure = r
        .ik_conf(&far, r.confdata(&q))
        .expect_err("5 m out of reach");
    let e = failure.at("m.mod", 12, 5);
    assert_eq!(e.kind(), ErrorKind::Unachievable, "{e}");
    let Error::Unachievable(at) = e else {
        unreachable!("kind Unachievable is Error::Unachievable")
    };
    assert_eq!((at.file.as_str(), at.line, at.column), ("m.mod", 12, 5));
}

#[test]
fn exit_codes_are_decided_by_kind() {
    let at = || Located::new("f", 1, 1, "m");
    let cases = [
        (Error::Input(at()), ErrorKind::Input, EXIT_ERROR),
        (Error::Machine(at()), ErrorKind::Machine, EXIT_ERROR),
        (Error::Data("m".into()), ErrorKind::Data, EXIT_ERROR),
        (Error::Usage("m".into()), ErrorKind::Usage, EXIT_ERROR),
        (
            Error::io("f", std::io::Error::from(std::io::ErrorKind::NotFound)),
            ErrorKind::Io,
            EXIT_ERROR,
        ),
        (
            Error::Unachievable(at()),
            ErrorKind::Unachievable,
            EXIT_ERROR,
        ),
        (
            Error::Internal("m".into()),
            ErrorKind::Internal,
            EXIT_INTERNAL,
        ),
    ];
    for (e, k, code) in cases {
        assert_eq!(e.kind(), k);
        assert_eq!(e.exit_code(), code, "{k:?}");
    }
    // The codes docs/cli.md documents; 1 is for findings, not errors.
    assert_eq!((EXIT_ERROR, EXIT_INTERNAL), (2, 3));
}

#[test]
fn an_edit_the_writers_never_make_is_an_internal_error_with_its_message() {
    use postproc::emit::rapid::{Edit, apply_edits};
    let src = "MoveL p10, v100;";
    let cases = [
        (
            vec![Edit::replace(5..8, "a"), Edit::replace(6..9, "b")],
            "edit 6..9 overlaps a previous edit ending at 8",
        ),
        (
            vec![Edit::replace(10..40, "c")],
            "edit 10..40 is outside the program (16 bytes)",
        ),
    ];
    for (edits, message) in cases {
        let (k, e) = kind(apply_edits(src, &edits));
        assert_eq!(k, ErrorKind::Internal, "{e}");
        assert_eq!(e.exit_code(), EXIT_INTERNAL);
        assert_eq!(e.to_string(), message);
    }
}

/// Runs `compensate` with `args`; the exit code, stderr, and whether the
/// output file exists afterwards.
fn compensate(dir: &Path, args: &[&str]) -> (Option<i32>, String, bool) {
    let out = dir.join("out.txt");
    let run = postproc()
        .arg("compensate")
        .args(args)
        .arg("-o")
        .arg(&out)
        .output()
        .expect("runs");
    (
        run.status.code(),
        String::from_utf8_lossy(&run.stderr).into_owned(),
        out.exists(),
    )
}

#[test]
fn each_kind_exits_with_its_code_through_the_binary_and_writes_nothing() {
    let dir = tempfile::tempdir().expect("temp dir");
    let d = dir.path();
    let program = write(d, "p.nc", "G90 G54 G0 X10 Y10 Z50\nG1 X20 F500\n");
    let program = program.to_str().expect("utf-8 path");
    let bad_program = write(d, "bad.nc", "G90 G0 X10\nG1 X#1 F500\n");
    let far = write(d, "far.nc", "G90 G54 G0 X10 Y10\nG0 Y350.05\n");
    let bad_machine = repo("tests/bad/machines/unknown-key.yaml");
    let missing = d.join("absent.nc");
    let cases: [(&str, Vec<&str>, &str); 5] = [
        (
            "input",
            vec![bad_program.to_str().expect("path"), "-m", "afm-r1000"],
            "bad.nc:2:",
        ),
        (
            "machine",
            vec![program, "-m", bad_machine.to_str().expect("path")],
            "unknown-key.yaml:",
        ),
        (
            "usage",
            vec![program, "-m", "afm-r1000", "--allow-reconfiguration"],
            "--allow-reconfiguration",
        ),
        (
            "io",
            vec![missing.to_str().expect("path"), "-m", "afm-r1000"],
            "absent.nc",
        ),
        (
            "unachievable",
            vec![far.to_str().expect("path"), "-m", "afm-r1000"],
            "far.nc:2:1:",
        ),
    ];
    for (what, args, names) in cases {
        let (code, stderr, written) = compensate(d, &args);
        assert_eq!(code, Some(EXIT_ERROR), "{what}: {stderr}");
        // One error line, after any warnings, naming the file.
        let errors: Vec<&str> = stderr
            .lines()
            .filter(|l| l.starts_with("error: "))
            .collect();
        assert_eq!(errors.len(), 1, "{what}: {stderr}");
        assert!(errors[0].contains(names), "{what}: {stderr}");
        assert!(!written, "{what}: an output file was written");
    }
    let (code, stderr, written) = compensate(d, &[program, "-m", "afm-r1000"]);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(written);
}

/// Too few load rows for a stiffness calibration is a data error naming
/// the observation file, not a usage error.
#[test]
fn too_few_rows_for_a_fit_is_a_data_error_naming_the_observations() {
    use postproc::calibrate::observations::load_poses;
    use postproc::calibrate::simulate::{Noise, simulate};
    use postproc::calibrate::stiffness::{Options, calibrate_stiffness};
    let truth = "samples/observations/irb1600-truth.yaml";
    let start = "machines/abb-irb1600.yaml";
    let mut poses =
        load_poses(&repo("samples/observations/irb1600-ldbb-poses.csv")).expect("poses");
    poses.rows.truncate(9);
    let m = Machine::from_yaml_str(&text(truth), truth).expect("machine");
    let noise = Noise {
        um: 15.0,
        um_per_m: 0.0,
        seed: 1,
    };
    let obs = simulate(&m, &poses, truth, &noise).expect("simulated");
    let (k, e) = kind(calibrate_stiffness(
        &text(start),
        start,
        &obs,
        "few.csv",
        &Options::default(),
    ));
    assert_eq!(k, ErrorKind::Data, "{e}");
    assert!(e.to_string().starts_with("few.csv: "), "{e}");
}

/// A robot file without thermal terms cannot be thermally calibrated: a
/// problem of the machine file, named as the whole file.
#[test]
fn thermal_calibration_of_a_file_without_terms_is_a_machine_error() {
    use postproc::calibrate::observations::load_poses;
    use postproc::calibrate::stiffness::Options;
    use postproc::calibrate::thermal::calibrate_thermal;
    let start = "machines/staubli-tx200.yaml";
    let obs = load_poses(&repo("samples/observations/irb1600-thermal-poses.csv")).expect("poses");
    let (k, e) = kind(calibrate_thermal(
        &text(start),
        start,
        &obs,
        "t.csv",
        &Options::default(),
    ));
    assert_eq!(k, ErrorKind::Machine, "{e}");
    assert!(
        e.to_string()
            .starts_with("machines/staubli-tx200.yaml: no thermal terms"),
        "{e}"
    );
}

/// A fitted joint compliance so negative that no stiffness can hold it is
/// a data error of `diagnose --write-model` (the data ask for the
/// impossible), and an effect the library never offers a robot is an
/// internal error (the library is built per machine kind).
#[test]
fn diagnose_writing_an_impossible_compliance_is_a_data_error() {
    use postproc::diagnose::{Found, Param, effects, library, write};
    let t = text("machines/abb-irb1600.yaml");
    let m = Machine::from_yaml_str(&t, "irb1600.yaml").expect("robot");
    let joint1 = library(&m, &[])
        .into_iter()
        .find(|e| e.name == "joint1_compliance")
        .expect("joint1_compliance in the robot library");
    let found = |effect: effects::Effect, value: f64| Found {
        params: vec![Param {
            name: effect.params[0].clone(),
            value,
            u: 0.1,
        }],
        effect,
        bootstrap: 1.0,
    };
    // k1 = 262 000 N·m/rad: a compliance of −1e9 µrad/(N·m) = −1000 rad/(N·m)
    // is far beyond −1/k.
    let (k, e) = kind(write::write_model(&m, &t, &[found(joint1.clone(), -1e9)]));
    assert_eq!(k, ErrorKind::Data, "{e}");
    assert!(write::write_model(&m, &t, &[found(joint1.clone(), 1.0)]).is_ok());
    let foreign = effects::Effect {
        action: effects::Action::SpindleTime,
        ..joint1
    };
    let (k, e) = kind(write::write_model(&m, &t, &[found(foreign, 1.0)]));
    assert_eq!(k, ErrorKind::Internal, "{e}");
}

/// The help lists every exit code the binary uses, internal errors (3)
/// included.
#[test]
fn help_lists_every_exit_code() {
    let out = crate::common::postproc()
        .arg("--help")
        .output()
        .expect("runs");
    let help = String::from_utf8_lossy(&out.stdout);
    for code in [
        "0 success",
        "1 completed",
        "2 bad input",
        "3 internal error",
    ] {
        assert!(help.contains(code), "{code}: {help}");
    }
}
