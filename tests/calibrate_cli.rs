//! Integration tests: `postproc simulate` and `postproc calibrate` — every
//! kind of identification recovers the parameters of a "true" machine file
//! from simulated measurements within its reported uncertainty (several
//! seeds), the held-out residual falls to the noise level, badly
//! conditioned data sets are reported as such, and bad input exits with 2.
//!
//! Pass criterion: |identified − true| ≤ 3 u (k = 3 instead of the k = 2 the
//! report prints, so that a test with dozens of parameters does not fail on
//! the ≈5 % of honest 2u outliers; with k = 3 a normal parameter fails with
//! probability 0.27 %).

use postproc::calibrate::geometry::calibrate_geometry;
use postproc::calibrate::kinematics::calibrate_kinematics;
use postproc::calibrate::observations::{Observations, load_observations, load_poses};
use postproc::calibrate::report::Calibration;
use postproc::calibrate::simulate::{Noise, simulate};
use postproc::calibrate::stiffness::{Options, calibrate_stiffness};
use postproc::machine::Machine;

use crate::common::{postproc, repo, text, write};

/// Coverage factor of the recovery test (see the module doc).
const K_TEST: f64 = 3.0;
/// Agreement of a value written to a model file with the fitted one: the
/// writer keeps at least 5 decimals of a gain.
const WRITTEN_TOL: f64 = 1e-5;

/// Mean norm of a 3-D isotropic normal error with standard deviation σ per
/// coordinate: σ·√(8/π) ≈ 1.596 σ (Maxwell distribution mean).
const MAXWELL_MEAN: f64 = 1.596;

fn machine(rel: &str) -> Machine {
    Machine::from_yaml_str(&text(rel), rel).expect("machine file")
}

fn simulated(truth: &str, poses: &str, noise: Noise) -> Observations {
    let p = load_poses(&repo(poses)).expect("poses");
    simulate(&machine(truth), &p, poses, &noise).expect("simulate")
}

fn param<'a>(cal: &'a Calibration, name: &str) -> &'a postproc::calibrate::report::Estimate {
    cal.params
        .iter()
        .find(|p| p.name == name)
        .unwrap_or_else(|| panic!("parameter {name} in the report"))
}

fn assert_recovered(cal: &Calibration, name: &str, truth: f64) {
    let p = param(cal, name);
    let u = p.u.unwrap_or_else(|| panic!("{name} has an uncertainty"));
    assert!(
        (p.value - truth).abs() <= K_TEST * u,
        "{name}: identified {} ± {u}, true {truth} (more than {K_TEST} u apart)",
        p.value
    );
}

const TRUTH_ROBOT: &str = "samples/observations/irb1600-truth.yaml";
const START_ROBOT: &str = "machines/abb-irb1600.yaml";
/// True joint stiffness of irb1600-truth.yaml, N·m/rad (its `k_nm_per_rad`).
const TRUE_K: [f64; 6] = [262000.0, 447000.0, 134500.0, 11900.0, 9050.0, 5650.0];

/// Laser tracker noise of the data sets: 15 µm + 6 µm/m (docs/physics.md).
fn tracker(seed: u64) -> Noise {
    Noise {
        um: 15.0,
        um_per_m: 6.0,
        seed,
    }
}

/// Paper C–style LDBB data (19 configurations × 5 points × unloaded and two
/// loads of 310–360 N): joints 1–3 within 3 % and within 3u of the truth for
/// three seeds, the wrist with a larger relative uncertainty than joints
/// 1–3 (as Paper C Table 6), the held-out deflection residual at the noise
/// level (pair differences: σ√2 per coordinate, σ ≈ 15 + 6·1.2 ≈ 22 µm).
#[test]
fn stiffness_recovers_paper_c_style_truth() {
    for seed in [11, 12, 13] {
        let obs = simulated(
            TRUTH_ROBOT,
            "samples/observations/irb1600-ldbb-poses.csv",
            tracker(seed),
        );
        let cal = calibrate_stiffness(
            &text(START_ROBOT),
            START_ROBOT,
            &obs,
            "ldbb.csv",
            &Options {
                holdout: 0.3,
                seed,
                ..Options::default()
            },
        )
        .expect("stiffness identified");
        for (i, &k) in TRUE_K.iter().enumerate() {
            assert_recovered(&cal, &format!("k{}", i + 1), k);
        }
        let rel = |i: usize| {
            let p = param(&cal, &format!("k{}", i + 1));
            p.u.unwrap_or(f64::INFINITY) / p.value
        };
        for (i, &k) in TRUE_K.iter().enumerate().take(3) {
            let p = param(&cal, &format!("k{}", i + 1));
            assert!((p.value - k).abs() < 0.03 * k, "k{} off by > 3 %", i + 1);
        }
        let worst_arm = rel(0).max(rel(1)).max(rel(2));
        let best_wrist = rel(3).min(rel(4)).min(rel(5));
        assert!(best_wrist > worst_arm, "wrist less certain than joints 1-3");
        let v = cal.validation.expect("held-out pairs");
        let sigma_pair_mm = 0.022 * std::f64::consts::SQRT_2;
        assert!(
            v.after_mean_mm < 1.3 * MAXWELL_MEAN * sigma_pair_mm,
            "{v:?}"
        );
        assert!(v.after_mean_mm <= v.before_mean_mm, "{v:?}");
        let reloaded = Machine::from_yaml_str(&cal.yaml, "out.yaml").expect("valid file");
        let Machine::Robot(r) = reloaded else {
            panic!("robot")
        };
        // The file stores N·m/rad with one decimal; the model N·mm/rad.
        assert!((r.k_nm_per_rad()[0] - param(&cal, "k1").value).abs() <= 0.05);
    }
}

/// Kinematics: the start file is the truth with every DH row changed to the
/// example calibration of machines/abb-irb1600.yaml, except the parameters
/// that these poses cannot identify (they are kept at the start value, so
/// they must equal the truth for a fair comparison). Every identified
/// parameter is within 3u of the truth, the held-out residual drops from
/// > 1 mm to the noise level.
#[test]
fn kinematics_recovers_truth() {
    let truth = text(TRUTH_ROBOT);
    // Rows of machines/abb-irb1600.yaml's `actual`, with the truth's j3.d,
    // j5.theta, j6.alpha, j6.theta (the redundant ones) and the truth's TCP
    // z; the TCP x/y start at 0 (truth 0.3, -0.2).
    let start = truth
        .replace(
            "  - { a_mm: 150.42, alpha_deg: -90.05, d_mm: 0.06,   theta_offset_deg: -90.061 }",
            "  - { a_mm: 150.27, alpha_deg: -90.03, d_mm: 0.18,   theta_offset_deg: -90.034 }",
        )
        .replace(
            "  - { a_mm: 699.83, alpha_deg: 0.012,  d_mm: -0.27,  theta_offset_deg: 0.018 }",
            "  - { a_mm: 699.61, alpha_deg: 0.025,  d_mm: -0.27,  theta_offset_deg: 0.042 }",
        )
        .replace(
            "  - { a_mm: -0.08,  alpha_deg: 90.02,  d_mm: 0.21,   theta_offset_deg: 0.051 }",
            "  - { a_mm: -0.14,  alpha_deg: 90.04,  d_mm: 0.09,   theta_offset_deg: 0.051 }",
        )
        .replace(
            "x_mm: 0.3, y_mm: -0.2, z_mm: 150.0",
            "x_mm: 0.0, y_mm: 0.0, z_mm: 150.0",
        );
    assert_ne!(start, truth);
    // True values (irb1600-truth.yaml `actual`, flange_to_tool).
    let expect = [
        ("j1.d_mm", 486.31),
        ("j2.a_mm", 150.42),
        ("j2.alpha_deg", -90.05),
        ("j2.d_mm", 0.06),
        ("j2.theta_offset_deg", -90.061),
        ("j3.a_mm", 699.83),
        ("j3.alpha_deg", 0.012),
        ("j3.theta_offset_deg", 0.018),
        ("j4.a_mm", 0.35),
        ("j4.d_mm", 600.12),
        ("j5.a_mm", -0.08),
        ("j5.alpha_deg", 90.02),
        ("j5.d_mm", 0.21),
        ("j6.a_mm", 0.19),
        ("j6.d_mm", 65.02),
        ("tool.x_mm", 0.3),
        ("tool.y_mm", -0.2),
    ];
    for seed in [21, 22] {
        let obs = simulated(
            TRUTH_ROBOT,
            "samples/observations/irb1600-kinematic-poses.csv",
            tracker(seed),
        );
        let cal = calibrate_kinematics(
            &start,
            "start.yaml",
            &obs,
            "k.csv",
            &Options {
                holdout: 0.3,
                seed,
                ..Options::default()
            },
        )
        .expect("kinematics identified");
        let fixed = cal.fixed();
        for name in [
            "j3.d_mm",
            "j5.theta_offset_deg",
            "j6.alpha_deg",
            "j6.theta_offset_deg",
            "tool.z_mm",
        ] {
            assert!(
                fixed.contains(&name),
                "{name} reported unidentifiable: {fixed:?}"
            );
        }
        for (name, v) in expect {
            assert_recovered(&cal, name, v);
        }
        let v = cal.validation.expect("held-out rows");
        assert!(v.before_mean_mm > 0.5, "{v:?}");
        // σ ≈ 22 µm per coordinate; allow 1.5× for the parameter uncertainty.
        assert!(v.after_mean_mm < 1.5 * MAXWELL_MEAN * 0.022, "{v:?}");
        Machine::from_yaml_str(&cal.yaml, "out.yaml").expect("valid file");
    }
}

/// All poses with joint 1 at the same angle: the first link's offsets
/// (j2.a, j2.alpha) can no longer be told from a shift and tilt of the
/// measuring frame (j1.a, j1.alpha), although varied poses identify them.
/// Fitting the rest would push their errors into the neighbours with small
/// uncertainties (j1.a came out 0.48 ± 0.007 mm against a true 0), so the
/// data set is refused as badly conditioned, naming them and the cause.
#[test]
fn kinematics_refuses_fixed_joint_one_as_badly_conditioned() {
    let obs = simulated(
        TRUTH_ROBOT,
        "samples/observations/irb1600-q1fixed-poses.csv",
        tracker(5),
    );
    let err = calibrate_kinematics(
        &text(START_ROBOT),
        START_ROBOT,
        &obs,
        "q1.csv",
        &Options::default(),
    )
    .expect_err("a badly conditioned data set is refused");
    let msg = err.to_string();
    assert!(msg.contains("badly conditioned"), "{msg}");
    assert!(
        msg.contains("j2.a_mm") && msg.contains("j2.alpha_deg"),
        "{msg}"
    );
    assert!(
        msg.contains("every row has joint 1 at the same angle"),
        "{msg}"
    );
    assert_eq!(err.exit_code(), 2);
}

/// Geometry on the AFM R-1000 grid data (1 µm noise): every identified
/// table value and the three squareness errors within 3u of the truth
/// file's values at the targets; held-out residual at the noise level.
#[test]
fn geometry_recovers_truth_tables_and_squareness() {
    let truth = machine("samples/observations/afm-r1000-truth.yaml");
    let Machine::Tool(tt) = &truth else {
        panic!("machine tool")
    };
    for seed in [31, 32] {
        let obs = simulated(
            "samples/observations/afm-r1000-truth.yaml",
            "samples/observations/afm-r1000-grid-poses.csv",
            Noise {
                um: 1.0,
                um_per_m: 0.0,
                seed,
            },
        );
        let cal = calibrate_geometry(
            &text("machines/afm-r1000.yaml"),
            "machines/afm-r1000.yaml",
            &obs,
            "g.csv",
            &Options {
                holdout: 0.3,
                seed,
                ..Options::default()
            },
        )
        .expect("geometry identified");
        // Squareness of the truth file (hand-edited values).
        assert_recovered(&cal, "EC0Y_urad", 28.0);
        assert_recovered(&cal, "EA0Z_urad", -18.0);
        assert_recovered(&cal, "EB0Z_urad", 47.0);
        // Table values: `E<err><axis>@<pos><dir>` against the truth tables
        // (read from the truth file: positions are table nodes there too).
        let letters = ['X', 'Y', 'Z'];
        let mut checked = 0;
        for p in cal.params.iter().filter(|p| p.name.contains('@')) {
            let b = p.name.as_bytes();
            let err = letters
                .iter()
                .position(|&c| c as u8 == b[1])
                .expect("letter");
            let axis = letters
                .iter()
                .position(|&c| c as u8 == b[2])
                .expect("letter");
            let pos: f64 = p.name[4..p.name.len() - 1].parse().expect("position");
            let dir = if p.name.ends_with('+') { 1 } else { -1 };
            let table = tt
                .axis(axis)
                .and_then(|a| a.components.tables[err].as_ref());
            let want = table.map_or(0.0, |t| t.lookup(pos, dir).value * 1000.0);
            assert_recovered(&cal, &p.name, want);
            checked += 1;
        }
        // 6 targets per axis, forward and reverse: positioning 12 values;
        // straightness 11 (first forward is the datum), 10 for EXY, EXZ,
        // EYZ (end-point line): X 12+11+11, Y 12+10+11, Z 12+10+10 = 99.
        assert_eq!(checked, 99);
        let v = cal.validation.expect("held-out rows");
        assert!(v.after_mean_mm < 1.5 * MAXWELL_MEAN * 0.001, "{v:?}");
        assert!(v.before_mean_mm > 3.0 * v.after_mean_mm, "{v:?}");
    }
}

/// Through the binary: simulate writes a file that calibrate reads; the
/// table, O1, condition number, validation and the output path go to stdout;
/// the written machine file keeps the original comments.
#[test]
fn binary_simulate_then_calibrate_stiffness() {
    let dir = tempfile::tempdir().expect("tempdir");
    let meas = dir.path().join("m.csv");
    let out = dir.path().join("cal.yaml");
    postproc()
        .args(["simulate", "--machine"])
        .arg(repo(TRUTH_ROBOT))
        .arg("--observations")
        .arg(repo("samples/observations/irb1600-ldbb-poses.csv"))
        .args([
            "--noise-um",
            "15",
            "--noise-um-per-m",
            "6",
            "--seed",
            "3",
            "-o",
        ])
        .arg(&meas)
        .assert()
        .success();
    let again = dir.path().join("m2.csv");
    postproc()
        .args(["simulate", "--machine"])
        .arg(repo(TRUTH_ROBOT))
        .arg("--observations")
        .arg(repo("samples/observations/irb1600-ldbb-poses.csv"))
        .args([
            "--noise-um",
            "15",
            "--noise-um-per-m",
            "6",
            "--seed",
            "3",
            "-o",
        ])
        .arg(&again)
        .assert()
        .success();
    assert_eq!(
        std::fs::read(&meas).ok(),
        std::fs::read(&again).ok(),
        "same seed, same data"
    );
    let obs = load_observations(&meas).expect("simulate output is a valid observation file");
    assert_eq!(obs.rows.len(), 19 * 5 * 3);
    let a = postproc()
        .args(["calibrate", "stiffness", "--machine"])
        .arg(repo(START_ROBOT))
        .arg("--observations")
        .arg(&meas)
        .arg("-o")
        .arg(&out)
        .assert()
        .success();
    let stdout = String::from_utf8_lossy(&a.get_output().stdout).to_string();
    for want in [
        "O1 = ",
        "condition number = ",
        "k1 ",
        "k6 ",
        "held-out validation (",
        "U (k=2)",
    ] {
        assert!(stdout.contains(want), "stdout lacks {want:?}:\n{stdout}");
    }
    let written = std::fs::read_to_string(&out).expect("output");
    assert!(
        written.contains("# Paper C Table 6: [2.7099"),
        "comments kept"
    );
    Machine::from_yaml_str(&written, "cal.yaml").expect("valid machine file");
}

/// Sample data, badly conditioned: every load vertical. A vertical force
/// has no moment about the vertical joint-1 axis, so k1 cannot be
/// identified; the run is refused with exit 2 and says why.
#[test]
fn binary_refuses_badly_conditioned_stiffness_data() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut poses = String::from("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,fz_n\n");
    for q in [
        "10,20,-10,30,40,50",
        "-40,5,20,-60,30,10",
        "90,-20,30,0,60,-90",
        "150,10,-40,45,-30,20",
        "-120,30,-60,90,45,0",
        "60,-10,10,-30,-60,120",
    ] {
        poses.push_str(&format!("{q},0\n{q},-335\n{q},-250\n"));
    }
    let p = write(dir.path(), "p.csv", &poses);
    let meas = dir.path().join("m.csv");
    postproc()
        .args(["simulate", "--machine"])
        .arg(repo(TRUTH_ROBOT))
        .arg("--observations")
        .arg(&p)
        .args(["--noise-um", "15", "-o"])
        .arg(&meas)
        .assert()
        .success();
    let a = postproc()
        .args(["calibrate", "stiffness", "--holdout", "0", "--machine"])
        .arg(repo(START_ROBOT))
        .arg("--observations")
        .arg(&meas)
        .arg("-o")
        .arg(dir.path().join("o.yaml"))
        .assert()
        .code(2);
    let stderr = String::from_utf8_lossy(&a.get_output().stderr).to_string();
    assert!(
        stderr.contains("badly conditioned") && stderr.contains("k1"),
        "{stderr}"
    );
    assert!(!dir.path().join("o.yaml").exists(), "nothing written");
}

/// Force signs flipped (the force applied BY the robot instead of ON it):
/// the compliances come out negative and the run is refused with the usual
/// causes named.
#[test]
fn binary_refuses_negative_stiffness() {
    let dir = tempfile::tempdir().expect("tempdir");
    let obs = simulated(
        TRUTH_ROBOT,
        "samples/observations/irb1600-ldbb-poses.csv",
        tracker(9),
    );
    let mut flipped = obs.clone();
    for r in &mut flipped.rows {
        r.force_n = -r.force_n;
    }
    let mut buf = Vec::new();
    postproc::calibrate::observations::write_observations(&mut buf, &flipped).expect("write");
    let meas = write(dir.path(), "m.csv", &String::from_utf8_lossy(&buf));
    let a = postproc()
        .args(["calibrate", "stiffness", "--machine"])
        .arg(repo(START_ROBOT))
        .arg("--observations")
        .arg(&meas)
        .arg("-o")
        .arg(dir.path().join("o.yaml"))
        .assert()
        .code(2);
    let stderr = String::from_utf8_lossy(&a.get_output().stderr).to_string();
    assert!(
        stderr.contains("non-positive") && stderr.contains("sign"),
        "{stderr}"
    );
}

/// Bad input exits with 2 and a message: loaded rows without an unloaded
/// partner; a robot data set for a machine tool; a bad --holdout; a
/// negative noise.
#[test]
fn binary_bad_input() {
    let dir = tempfile::tempdir().expect("tempdir");
    let orphan = write(
        dir.path(),
        "o.csv",
        "id,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,x_mm,y_mm,z_mm,fz_n\nL1,0,0,0,0,0,0,1,2,3,-300\n",
    );
    let out = dir.path().join("x.yaml");
    let a = postproc()
        .args(["calibrate", "stiffness", "--machine"])
        .arg(repo(START_ROBOT))
        .arg("--observations")
        .arg(&orphan)
        .arg("-o")
        .arg(&out)
        .assert()
        .code(2);
    assert!(String::from_utf8_lossy(&a.get_output().stderr).contains("L1 (line 2)"));
    let a = postproc()
        .args(["calibrate", "geometry", "--machine"])
        .arg(repo("machines/afm-r1000.yaml"))
        .arg("--observations")
        .arg(&orphan)
        .arg("-o")
        .arg(&out)
        .assert()
        .code(2);
    assert!(String::from_utf8_lossy(&a.get_output().stderr).contains("describes a machine tool"));
    postproc()
        .args(["calibrate", "kinematics", "--holdout", "1.5", "--machine"])
        .arg(repo(START_ROBOT))
        .arg("--observations")
        .arg(&orphan)
        .arg("-o")
        .arg(&out)
        .assert()
        .code(2);
    postproc()
        .args(["simulate", "--noise-um", "-1", "--machine"])
        .arg(repo(START_ROBOT))
        .arg("--observations")
        .arg(&orphan)
        .arg("-o")
        .arg(&out)
        .assert()
        .code(2);
    assert!(!out.exists());
}

/// The seeded noise has the requested standard deviation: 100 rows × 3
/// coordinates of (noisy − noise-free) with --noise-um 15 give a sample
/// standard deviation within 15 % of 15 µm (the relative standard error of
/// a sample SD of 300 values is 1/√600 ≈ 4 %).
#[test]
fn simulate_noise_has_requested_sd() {
    let poses =
        load_poses(&repo("samples/observations/irb1600-kinematic-poses.csv")).expect("poses");
    let m = machine(START_ROBOT);
    let clean = simulate(&m, &poses, "p", &Noise::default()).expect("clean");
    let noisy = simulate(
        &m,
        &poses,
        "p",
        &Noise {
            um: 15.0,
            um_per_m: 0.0,
            seed: 99,
        },
    )
    .expect("noisy");
    let d: Vec<f64> = clean
        .rows
        .iter()
        .zip(&noisy.rows)
        .flat_map(|(a, b)| {
            (b.measured_mm - a.measured_mm)
                .iter()
                .copied()
                .collect::<Vec<_>>()
        })
        .collect();
    let n = d.len() as f64;
    let mean = d.iter().sum::<f64>() / n;
    let sd_um = 1000.0 * (d.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    assert!((sd_um - 15.0).abs() < 0.15 * 15.0, "sample sd {sd_um} µm");
}

/// A poses file with deviation columns left empty: simulate fills the
/// deviations; kinematics on deviations leaves the TCP translation out (a
/// deviation of one point barely depends on where the point is) and still
/// identifies the arm (j2.a within 3u of the truth, 150.42 mm).
#[test]
fn binary_deviation_files() {
    let dir = tempfile::tempdir().expect("tempdir");
    let poses = text("samples/observations/irb1600-kinematic-poses.csv");
    let mut body = String::from("id,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,dx_mm,dy_mm,dz_mm\n");
    for l in poses.lines().filter(|l| l.starts_with('K')) {
        body.push_str(&format!("{l},,,\n"));
    }
    let p = write(dir.path(), "p.csv", &body);
    let meas = dir.path().join("m.csv");
    postproc()
        .args(["simulate", "--noise-um", "15", "--seed", "8", "--machine"])
        .arg(repo(TRUTH_ROBOT))
        .arg("--observations")
        .arg(&p)
        .arg("-o")
        .arg(&meas)
        .assert()
        .success();
    let obs = load_observations(&meas).expect("deviation file");
    assert_eq!(
        obs.measured,
        postproc::calibrate::observations::MeasuredKind::Deviation
    );
    let cal = calibrate_kinematics(
        &text(START_ROBOT),
        START_ROBOT,
        &obs,
        "m.csv",
        &Options {
            holdout: 0.0,
            seed: 1,
            ..Options::default()
        },
    )
    .expect("identified");
    assert!(cal.params.iter().all(|p| !p.name.starts_with("tool.")));
    assert!(cal.validation.is_none());
    assert_recovered(&cal, "j2.a_mm", 150.42);
}

/// Five-axis AC trunnion (X on the tool side, tables that do not follow the
/// conventions, squareness on X): with the rotary axes fixed, noise-free data
/// are reproduced exactly (the conventions only re-parameterise the truth);
/// with a moving A axis the run is refused.
#[test]
fn geometry_on_a_five_axis_machine() {
    let mut body = String::from("X_mm,Y_mm,Z_mm,A_deg,C_deg,dirX,dirY,dirZ\n");
    // A deterministic 3×3×3 grid, each point approached + and −, plus mixed
    // directions (x+ y− z+, x− y+ z−) so that reverse tables separate.
    for x in [-100, 0, 100] {
        for y in [-100, 0, 100] {
            for z in [-200, -100, 0] {
                for d in ["1,1,1", "-1,-1,-1", "1,-1,1", "-1,1,-1"] {
                    body.push_str(&format!("{x},{y},{z},0,0,{d}\n"));
                }
            }
        }
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let p = write(dir.path(), "p.csv", &body);
    let poses = load_poses(&p).expect("poses");
    let m = machine("machines/five-axis-ac.yaml");
    let obs = simulate(&m, &poses, "p.csv", &Noise::default()).expect("simulate");
    let cal = calibrate_geometry(
        &text("machines/five-axis-ac.yaml"),
        "five-axis-ac.yaml",
        &obs,
        "p.csv",
        &Options {
            holdout: 0.0,
            seed: 1,
            ..Options::default()
        },
    )
    .expect("identified");
    // Noise-free: residual at rounding level of the written tables (0.01 µm).
    assert!(cal.rms_fit_mm < 1e-4, "fit RMS {} mm", cal.rms_fit_mm);
    let moving = body.replacen("-100,-100,-200,0,0", "-100,-100,-200,30,0", 1);
    let p2 = write(dir.path(), "p2.csv", &moving);
    let meas = dir.path().join("m2.csv");
    postproc()
        .args(["simulate", "--machine"])
        .arg(repo("machines/five-axis-ac.yaml"))
        .arg("--observations")
        .arg(&p2)
        .arg("-o")
        .arg(&meas)
        .assert()
        .success();
    let a = postproc()
        .args(["calibrate", "geometry", "--machine"])
        .arg(repo("machines/five-axis-ac.yaml"))
        .arg("--observations")
        .arg(&meas)
        .arg("-o")
        .arg(dir.path().join("o.yaml"))
        .assert()
        .code(2);
    assert!(
        String::from_utf8_lossy(&a.get_output().stderr)
            .contains("the A axis takes 2 different positions")
    );
}

/// Thermal (Paper B): the three terms of `irb1600-thermal-truth.yaml`
/// (a2 ← P1: lb = ub = 0.08 mm, ts = 0.022 1/W; a3 ← P2: 0.07, 0.07, 0.015;
/// d4 ← P3: 0.04, 0.04, 0.04) are recovered from the start file (all
/// 0.1/0.1/0.02) on the sample poses (40 poses × 3 steady states at the
/// Paper B power levels, joints varied independently), two seeds, 5 µm noise;
/// the held-out mean residual falls to the noise level (Maxwell mean ×
/// 1.25 for the fit uncertainty and sampling). The calibrated file carries
/// the identified values in the `thermal.terms` lines.
#[test]
fn thermal_recovers_paper_b_terms() {
    let truth = [
        ("a2←P1", 0.08, 0.08, 0.022),
        ("a3←P2", 0.07, 0.07, 0.015),
        ("d4←P3", 0.04, 0.04, 0.040),
    ];
    const NOISE_MM: f64 = 0.005;
    for seed in [11, 13] {
        let obs = simulated(
            "samples/observations/irb1600-thermal-truth.yaml",
            "samples/observations/irb1600-thermal-poses.csv",
            Noise {
                um: NOISE_MM * 1000.0,
                um_per_m: 0.0,
                seed,
            },
        );
        let start = text("samples/observations/irb1600-thermal-start.yaml");
        let cal = postproc::calibrate::thermal::calibrate_thermal(
            &start,
            "start.yaml",
            &obs,
            "obs.csv",
            &Options {
                holdout: 0.3,
                seed,
                ..Options::default()
            },
        )
        .expect("thermal calibration");
        assert!(cal.fixed().is_empty(), "{cal}");
        for (name, lb, ub, ts) in truth {
            assert_recovered(&cal, &format!("{name}.lb"), lb);
            assert_recovered(&cal, &format!("{name}.ub"), ub);
            assert_recovered(&cal, &format!("{name}.ts"), ts);
        }
        let v = cal.validation.expect("held-out rows");
        assert!(
            v.after_mean_mm <= 1.25 * MAXWELL_MEAN * NOISE_MM,
            "held-out mean {} mm after\n{cal}",
            v.after_mean_mm
        );
        assert!(v.after_mean_mm < v.before_mean_mm, "{cal}");
        assert!(cal.observability_o1 > 0.0 && cal.condition_number < 1e4);
        let m = Machine::from_yaml_str(&cal.yaml, "cal.yaml").expect("calibrated file loads");
        let Machine::Robot(r) = m else {
            panic!("robot")
        };
        let t = r.thermal().expect("thermal section");
        let a2 = param(&cal, "a2←P1.ts").value;
        assert!((t.terms[0].ts_per_w - a2).abs() <= 1e-6 * a2.abs().max(1.0));
        assert!(cal.yaml.contains("# THERMAL TRUTH") || cal.yaml.contains("# START file"));
    }
}

/// A term whose joint power never varies in the data is fixed and listed;
/// a file without thermal terms is refused with an explanation.
#[test]
fn thermal_constant_power_term_is_fixed() {
    let mut obs = simulated(
        "samples/observations/irb1600-thermal-truth.yaml",
        "samples/observations/irb1600-thermal-poses.csv",
        Noise {
            um: 5.0,
            um_per_m: 0.0,
            seed: 3,
        },
    );
    // Joint 3 always at 20 W: d4 ← P3 cannot be identified.
    for r in &mut obs.rows {
        if let postproc::calibrate::observations::Pose::Robot(rp) = &mut r.pose {
            rp.p_w[2] = Some(20.0);
        }
    }
    let start = text("samples/observations/irb1600-thermal-start.yaml");
    let opts = Options {
        holdout: 0.3,
        seed: 3,
        ..Options::default()
    };
    let cal = postproc::calibrate::thermal::calibrate_thermal(&start, "s", &obs, "o", &opts)
        .expect("calibration runs");
    for k in ["lb", "ub", "ts"] {
        assert!(param(&cal, &format!("d4←P3.{k}")).fixed, "{cal}");
    }
    assert!(
        cal.notes
            .iter()
            .any(|n| n.contains("d4←P3") && n.contains("never varies")),
        "{cal}"
    );
    let err = postproc::calibrate::thermal::calibrate_thermal(
        &text("machines/staubli-tx200.yaml"),
        "tx200",
        &obs,
        "o",
        &opts,
    );
    assert!(err.is_err());
}

/// Machine-tool thermal gains at steady state: the truth is
/// `machines/afm-r1000.yaml` with spindle growth 11 instead of 3 µm/kW and
/// X scale 90 instead of 60 ppm/kW; the grid poses get a spindle power of
/// 0…8 kW and an X drive power of 0…400 W per row (simulated, 1 µm noise).
/// Both gains are recovered within 3u and written into the `thermal:` lines;
/// Y and Z (no power columns) are left alone.
#[test]
fn thermal_machine_tool_gains() {
    let model = text("machines/afm-r1000.yaml");
    let truth = model
        .replacen("growth_um_per_kw: 3.0", "growth_um_per_kw: 11.0", 1)
        .replacen(
            "X: { scale_ppm_per_kw: 60.0,",
            "X: { scale_ppm_per_kw: 90.0,",
            1,
        );
    assert_ne!(truth, model);
    let mut poses =
        load_poses(&repo("samples/observations/afm-r1000-grid-poses.csv")).expect("poses");
    let mut rng = postproc::calibrate::stats::SplitMix64::new(7);
    for r in &mut poses.rows {
        if let postproc::calibrate::observations::Pose::Tool(tp) = &mut r.pose {
            tp.spindle_w = Some(8000.0 * rng.next_f64());
            tp.p_w[0] = Some(400.0 * rng.next_f64());
        }
    }
    let truth_m = Machine::from_yaml_str(&truth, "truth").expect("truth");
    const NOISE_MM: f64 = 0.001;
    let obs = simulate(
        &truth_m,
        &poses,
        "poses",
        &Noise {
            um: 1.0,
            um_per_m: 0.0,
            seed: 8,
        },
    )
    .expect("simulate");
    let cal = postproc::calibrate::thermal::calibrate_thermal(
        &model,
        "afm.yaml",
        &obs,
        "obs.csv",
        &Options {
            holdout: 0.3,
            seed: 8,
            ..Options::default()
        },
    )
    .expect("calibration");
    assert_recovered(&cal, "spindle.growth", 11.0);
    assert_recovered(&cal, "X.scale", 90.0);
    assert_eq!(cal.params.len(), 2, "{cal}");
    let v = cal.validation.expect("held out");
    assert!(v.after_mean_mm <= 1.25 * MAXWELL_MEAN * NOISE_MM, "{cal}");
    let Machine::Tool(t) = Machine::from_yaml_str(&cal.yaml, "cal").expect("loads") else {
        panic!("tool")
    };
    let th = t.thermal().expect("thermal");
    let g = th.spindle.map_or(0.0, |s| s.gain_per_kw);
    assert!((g - param(&cal, "spindle.growth").value).abs() < WRITTEN_TOL);
    assert!(
        cal.yaml.contains("# Dominant mode per direction"),
        "comments kept"
    );
}

/// The committed thermal sample through the binary: the sample's
/// measured file is exactly what `simulate` makes from the truth file with
/// the recorded command, and `calibrate thermal` on it prints the table and
/// writes a loadable file with the identified terms.
#[test]
fn binary_calibrate_thermal_sample() {
    let dir = tempfile::tempdir().expect("tempdir");
    let meas = dir.path().join("m.csv");
    postproc()
        .args(["simulate", "--machine"])
        .arg(repo("samples/observations/irb1600-thermal-truth.yaml"))
        .arg("--observations")
        .arg(repo("samples/observations/irb1600-thermal-poses.csv"))
        .args([
            "--noise-um",
            "15",
            "--noise-um-per-m",
            "6",
            "--seed",
            "5",
            "-o",
        ])
        .arg(&meas)
        .assert()
        .success();
    crate::common::assert_csv_close(
        &std::fs::read_to_string(&meas).expect("simulated"),
        &text("samples/observations/irb1600-thermal-measured.csv"),
        "the sample is made by the recorded command",
    );
    let out = dir.path().join("cal.yaml");
    let a = postproc()
        .args(["calibrate", "thermal", "--machine"])
        .arg(repo("samples/observations/irb1600-thermal-start.yaml"))
        .arg("--observations")
        .arg(repo("samples/observations/irb1600-thermal-measured.csv"))
        .arg("-o")
        .arg(&out)
        .assert()
        .success();
    let stdout = String::from_utf8_lossy(&a.get_output().stdout).to_string();
    assert!(
        stdout.starts_with("calibrate thermal: 84 items"),
        "{stdout}"
    );
    assert!(stdout.contains("a2←P1.ts"), "{stdout}");
    let written = std::fs::read_to_string(&out).expect("written");
    let m = Machine::from_yaml_str(&written, "cal.yaml").expect("loads");
    assert!(matches!(m, Machine::Robot(_)));
    assert!(written.contains("# START file"), "comments kept");
}

/// Data that support no correction of a file (the file already fits them
/// within their large noise): the kinematic calibration still runs and
/// prints its table instead of failing on an empty fit.
#[test]
fn kinematics_with_no_significant_correction_runs() {
    let dir = tempfile::tempdir().expect("tempdir");
    let calibrated = dir.path().join("cal.yaml");
    postproc()
        .args(["calibrate", "kinematics", "--machine"])
        .arg(repo(START_ROBOT))
        .arg("--observations")
        .arg(repo("samples/observations/irb1600-kinematic-measured.csv"))
        .arg("-o")
        .arg(&calibrated)
        .assert()
        .success();
    let noisy = dir.path().join("noisy.csv");
    postproc()
        .args(["simulate", "--machine"])
        .arg(repo(TRUTH_ROBOT))
        .arg("--observations")
        .arg(repo("samples/observations/irb1600-kinematic-poses.csv"))
        .args(["--noise-um", "300", "--seed", "2", "-o"])
        .arg(&noisy)
        .assert()
        .success();
    let a = postproc()
        .args(["calibrate", "kinematics", "--holdout", "0", "--machine"])
        .arg(&calibrated)
        .arg("--observations")
        .arg(&noisy)
        .arg("-o")
        .arg(dir.path().join("again.yaml"))
        .assert()
        .success();
    let stdout = String::from_utf8_lossy(&a.get_output().stdout).to_string();
    assert!(
        stdout.contains("not significant on the fit rows"),
        "{stdout}"
    );
}

/// A machine-tool grid whose rows carry a measured orientation: geometry
/// calibration fits the positions and says in one line that the
/// orientations are not used (the machine-tool model predicts the tool
/// tip's position only); without orientation columns no such line.
#[test]
fn geometry_says_it_leaves_measured_orientations_out() {
    let dir = tempfile::tempdir().expect("tempdir");
    let grid = std::fs::read_to_string(repo("samples/observations/afm-r1000-grid-measured.csv"))
        .expect("grid");
    let oriented: String = grid
        .lines()
        .map(|l| {
            if l.starts_with('#') {
                format!("{l}\n")
            } else if l.starts_with("id,") {
                format!("{l},qw,qx,qy,qz\n")
            } else {
                format!("{l},1,0,0,0\n")
            }
        })
        .collect();
    let obs = write(dir.path(), "oriented.csv", &oriented);
    let run = |obs: &std::path::Path, out: &str| -> String {
        let a = postproc()
            .args(["calibrate", "geometry", "-q", "--machine"])
            .arg(repo("machines/afm-r1000.yaml"))
            .arg("--observations")
            .arg(obs)
            .arg("-o")
            .arg(dir.path().join(out))
            .assert()
            .success();
        String::from_utf8_lossy(&a.get_output().stdout).to_string()
    };
    let with = run(&obs, "a.yaml");
    let plain = run(
        &repo("samples/observations/afm-r1000-grid-measured.csv"),
        "b.yaml",
    );
    let note = "not used: the machine-tool model predicts the tool tip's position only";
    assert_eq!(with.matches(note).count(), 1, "{with}");
    assert!(!plain.contains("measured orientation"), "{plain}");
    // Everything else is the same.
    let without_note: String = with
        .lines()
        .filter(|l| !l.contains(note) && !l.starts_with("wrote "))
        .map(|l| format!("{l}\n"))
        .collect();
    let plain: String = plain
        .lines()
        .filter(|l| !l.starts_with("wrote "))
        .map(|l| format!("{l}\n"))
        .collect();
    assert_eq!(without_note, plain);
}

/// `calibrate kinematics --holdout 0` (nothing held out) is judged by
/// 5-fold cross-validation by pose: 25 poses of a correct model measured
/// with 0.3 mm noise give a model that predicts the rows it did not fit
/// worse — not written (exit 1) unless `--force`; 60 poses of a model with
/// two lengths 0.4 mm off give one that is better, written.
#[test]
fn holdout_zero_is_judged_by_cross_validation() {
    let dir = tempfile::tempdir().expect("tmp");
    let mut rng = postproc::calibrate::stats::SplitMix64::new(11);
    let mut poses = |n: usize| {
        let mut s = String::from("id,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n");
        for i in 0..n {
            let mut u = |lo: f64, hi: f64| lo + (hi - lo) * rng.next_f64();
            let q = [
                u(-90.0, 90.0),
                u(-30.0, 60.0),
                u(-60.0, 30.0),
                u(-120.0, 120.0),
                u(-90.0, 90.0),
                u(-180.0, 180.0),
            ];
            let q: Vec<String> = q.iter().map(|v| format!("{v:.3}")).collect();
            s.push_str(&format!("{},{}\n", i + 1, q.join(",")));
        }
        s
    };
    let model = repo("machines/abb-irb1600.yaml");
    let truth = text("machines/abb-irb1600.yaml")
        .replacen(
            "a_mm: 149.95, alpha_deg: -90.022",
            "a_mm: 150.35, alpha_deg: -90.022",
            1,
        )
        .replacen("d_mm: 600.26", "d_mm: 600.66", 1);
    let truth = write(dir.path(), "truth.yaml", &truth);
    for (name, n, machine, noise, worse) in [
        ("few", 25, model.clone(), "300", true),
        ("many", 60, truth, "15", false),
    ] {
        let p = write(dir.path(), &format!("{name}.csv"), &poses(n));
        let meas = dir.path().join(format!("{name}-measured.csv"));
        postproc()
            .args(["simulate", "--machine"])
            .arg(&machine)
            .arg("--observations")
            .arg(&p)
            .arg("-o")
            .arg(&meas)
            .args(["--noise-um", noise, "--seed", "3"])
            .assert()
            .success();
        for force in [false, true] {
            let out = dir.path().join(format!("{name}-{force}.yaml"));
            let mut cmd = postproc();
            cmd.args(["calibrate", "kinematics", "--holdout", "0", "--machine"])
                .arg(&model)
                .arg("--observations")
                .arg(&meas)
                .arg("-o")
                .arg(&out);
            if force {
                cmd.arg("--force");
            }
            let a = cmd.assert();
            let o = a.get_output();
            let s = String::from_utf8_lossy(&o.stdout).into_owned();
            assert!(s.contains("cross-validation (5 folds by pose"), "{s}");
            let before = s
                .split("RMS per point ")
                .nth(1)
                .and_then(|t| t.split(" mm").next())
                .and_then(|v| v.parse::<f64>().ok())
                .expect("before");
            let after = s
                .split("mm before, ")
                .nth(1)
                .and_then(|t| t.split(" mm").next())
                .and_then(|v| v.parse::<f64>().ok())
                .expect("after");
            assert_eq!(after > before, worse, "{name}: {s}");
            let written = !worse || force;
            assert_eq!(
                o.status.code(),
                Some(if written { 0 } else { 1 }),
                "{name}: {s}"
            );
            assert_eq!(out.exists(), written, "{name} force={force}");
            assert_eq!(s.contains("not written"), !written, "{s}");
        }
    }
}

/// 8 poses measured 12 times each with a jitter of ±0.002° of the joints
/// (near-copies): they count as 8 poses — `calibrate kinematics` refuses
/// to fit 27 parameters to them instead of claiming a held-out error
/// measured on copies of its fit rows, and `diagnose` holds out whole
/// poses (all 12 rows of each).
#[test]
fn near_copies_count_as_one_pose() {
    let dir = tempfile::tempdir().expect("tmp");
    let mut rng = postproc::calibrate::stats::SplitMix64::new(2);
    let mut u = |lo: f64, hi: f64| lo + (hi - lo) * rng.next_f64();
    let base: Vec<[f64; 6]> = (0..8)
        .map(|_| {
            [
                u(-90.0, 90.0),
                u(-30.0, 60.0),
                u(-60.0, 30.0),
                u(-120.0, 120.0),
                u(-90.0, 90.0),
                u(-180.0, 180.0),
            ]
        })
        .collect();
    let mut s = String::from("id,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n");
    for k in 0..96 {
        let q: Vec<String> = base[k % 8]
            .iter()
            .map(|v| format!("{:.5}", v + u(-0.002, 0.002)))
            .collect();
        s.push_str(&format!("{},{}\n", k + 1, q.join(",")));
    }
    let poses = write(dir.path(), "poses.csv", &s);
    let meas = dir.path().join("measured.csv");
    postproc()
        .args(["simulate", "--machine"])
        .arg(repo("machines/abb-irb1600.yaml"))
        .arg("--observations")
        .arg(&poses)
        .arg("-o")
        .arg(&meas)
        .args(["--noise-um", "15", "--seed", "3"])
        .assert()
        .success();
    let out = dir.path().join("out.yaml");
    postproc()
        .args(["calibrate", "kinematics", "--machine"])
        .arg(repo("machines/abb-irb1600.yaml"))
        .arg("--observations")
        .arg(&meas)
        .arg("-o")
        .arg(&out)
        .assert()
        .code(2)
        .stderr(predicates::str::contains("distinct poses left for the fit"));
    assert!(!out.exists());
    let a = postproc()
        .args([
            "diagnose",
            "--format",
            "json",
            "--bootstrap",
            "3",
            "--machine",
        ])
        .arg(repo("machines/abb-irb1600.yaml"))
        .arg("--observations")
        .arg(&meas)
        .assert()
        .success();
    let d: serde_json::Value = serde_json::from_slice(&a.get_output().stdout).expect("json");
    let held = d["holdout_rows"].as_u64().expect("held out");
    assert!(held > 0 && held % 12 == 0, "{held} held-out rows");
}

/// `calibrate geometry` writes the machine file back with the keys it does
/// not identify as they were: a thermal scale origin
/// (`thermal.axes.<axis>.scale_origin_mm`) stays, and the written file
/// loads with it.
#[test]
fn calibrate_geometry_keeps_the_thermal_scale_origin() {
    let dir = tempfile::tempdir().expect("tempdir");
    let base = text("tests/shop/zbottom/afm-r1000-zbottom.yaml");
    let line = "    X: { scale_ppm_per_kw: 60.0, time_constant_min: 40.0, friction_n: 300.0 }";
    assert!(base.contains(line), "fixture line changed");
    let with_origin = base.replace(
        line,
        "    X: { scale_ppm_per_kw: 60.0, time_constant_min: 40.0, friction_n: 300.0, scale_origin_mm: 12.5 }",
    );
    let m = write(dir.path(), "m.yaml", &with_origin);
    let out = dir.path().join("cal.yaml");
    postproc()
        .args(["calibrate", "geometry", "--machine"])
        .arg(&m)
        .arg("--observations")
        .arg(repo("samples/observations/afm-r1000-grid-measured.csv"))
        .arg("--output")
        .arg(&out)
        .assert()
        .success();
    let written = std::fs::read_to_string(&out).expect("written file");
    assert!(
        written.contains("friction_n: 300.0, scale_origin_mm: 12.5 }"),
        "scale origin lost: {}",
        written
            .lines()
            .filter(|l| l.contains("X: { scale"))
            .collect::<Vec<_>>()
            .join("\n")
    );
    let loaded = Machine::load(&out).expect("the written file loads");
    assert!(matches!(loaded, Machine::Tool(_)), "a machine tool");
}
