//! Is the expanded uncertainty U (k=2) of a predicted deviation honest?
//! Simulated calibrations, many seeds: a "true" machine is the bundled
//! model with its parameters moved at random, measured at random poses
//! with Gaussian noise; the parameters are identified by least squares
//! (`calibrate::lsq`, with its covariance); at held-out poses the error of
//! the identified model's prediction against the truth must lie within U
//! (`predict::uncertainty`, first order through the sensitivities) in
//! about 95 % of cases, for a 3-axis machine tool, a 5-axis machine tool
//! and a robot. The coverage found is printed.

use nalgebra::{DMatrix, DVector, Matrix3xX, Vector3};

use postproc::calibrate::lsq::{LsqOptions, solve_linear};
use postproc::calibrate::stats::SplitMix64;
use postproc::machine::robot::{DhField, Model, Robot, RobotParam};
use postproc::machine::tool::{LocationParam, MachineTool, ToolParam};
use postproc::machine::{Machine, MachineFile};
use postproc::predict::uncertainty::{COVERAGE_K, ParamCovariance, propagate};

/// Seeds (simulated calibrations) per machine kind.
const SEEDS: u64 = 40;
/// Poses measured per calibration.
const FIT_POSES: usize = 30;
/// Held-out poses per calibration.
const HELD_OUT: usize = 12;
/// Coverage accepted around the nominal 95 % (over about 1400 cases the
/// binomial standard deviation is 0.6 %).
const COVERAGE_RANGE: (f64, f64) = (0.92, 0.98);
/// A coordinate whose U is below this has no uncertainty to cover, mm.
const NO_UNCERTAINTY_MM: f64 = 1e-9;

/// The model with each parameter offset by the values given.
type ModelFn<'a, M> = Box<dyn Fn(&[f64]) -> M + 'a>;
/// A random pose.
type PoseFn<'a, P> = Box<dyn Fn(&mut SplitMix64) -> P + 'a>;
/// What a model predicts at a pose, mm.
type PredictFn<'a, M, P> = Box<dyn Fn(&M, &P) -> Vector3<f64> + 'a>;
/// Sensitivities at a pose.
type JacFn<'a, P> = Box<dyn Fn(&P) -> Matrix3xX<f64> + 'a>;

/// One machine kind: how to move its parameters, pick a pose, predict.
struct Case<'a, M, P> {
    name: &'a str,
    /// Prior standard deviation of each parameter's true offset.
    prior: Vec<f64>,
    /// Effect of each parameter.
    effects: Vec<&'static str>,
    /// Measurement noise per coordinate, mm.
    noise_mm: f64,
    /// The model with each parameter offset by `delta`.
    model: ModelFn<'a, M>,
    /// A random pose.
    pose: PoseFn<'a, P>,
    /// The position (or deviation) a model predicts at a pose, mm.
    predict: PredictFn<'a, M, P>,
    /// Sensitivities at a pose, mm per parameter unit.
    jac: JacFn<'a, P>,
}

/// The share of held-out coordinates whose error is within U.
fn coverage<M, P>(c: &Case<'_, M, P>) -> f64 {
    let n = c.prior.len();
    let base = (c.model)(&vec![0.0; n]);
    let (mut inside, mut total) = (0usize, 0usize);
    for seed in 1..=SEEDS {
        let mut rng = SplitMix64::new(seed);
        let delta: Vec<f64> = c.prior.iter().map(|s| s * rng.normal()).collect();
        let truth = (c.model)(&delta);
        let mut a = DMatrix::zeros(3 * FIT_POSES, n);
        let mut b = DVector::zeros(3 * FIT_POSES);
        for i in 0..FIT_POSES {
            let p = (c.pose)(&mut rng);
            let j = (c.jac)(&p);
            let measured = (c.predict)(&truth, &p).map(|v| v + c.noise_mm * rng.normal());
            let r = measured - (c.predict)(&base, &p);
            for k in 0..3 {
                a.row_mut(3 * i + k).copy_from(&j.row(k));
                b[3 * i + k] = r[k];
            }
        }
        let sol = solve_linear(&a, &b, &LsqOptions::default()).expect("fit");
        assert!(
            sol.identifiability.unidentifiable.is_empty(),
            "{}: parameters {:?} not identified",
            c.name,
            sol.identifiability.unidentifiable
        );
        let ident = (c.model)(sol.params.as_slice());
        let cov = ParamCovariance::new(c.effects.clone(), sol.covariance.expect("covariance"))
            .expect("covariance");
        for _ in 0..HELD_OUT {
            let p = (c.pose)(&mut rng);
            let err = (c.predict)(&ident, &p) - (c.predict)(&truth, &p);
            let u = propagate(&(c.jac)(&p), &cov)
                .expect("propagate")
                .expanded_xyz_mm(COVERAGE_K);
            for k in 0..3 {
                if u[k] > NO_UNCERTAINTY_MM {
                    total += 1;
                    inside += usize::from(err[k].abs() <= u[k]);
                }
            }
        }
    }
    let share = inside as f64 / total as f64;
    eprintln!(
        "{}: {inside} of {total} held-out coordinates within U (k=2): {:.1} %",
        c.name,
        100.0 * share
    );
    share
}

fn assert_coverage(name: &str, share: f64) {
    assert!(
        (COVERAGE_RANGE.0..=COVERAGE_RANGE.1).contains(&share),
        "{name}: coverage {:.1} % outside {:.0}–{:.0} %",
        100.0 * share,
        100.0 * COVERAGE_RANGE.0,
        100.0 * COVERAGE_RANGE.1
    );
}

fn tool(name: &str) -> MachineTool {
    match MachineFile::bundled(name)
        .expect("bundled")
        .load()
        .expect("loads")
    {
        Machine::Tool(t) => t,
        Machine::Robot(_) => panic!("{name} is a robot"),
    }
}

/// A machine-tool case: parameters `params` (prior σ each), random
/// commands from `pose`, a 100 mm tool, the geometric tip deviation.
fn tool_case<'a>(
    name: &'a str,
    m: &'a MachineTool,
    params: &'a [(ToolParam, f64)],
    sens: &'a postproc::predict::uncertainty::ToolSensitivity,
    pose: PoseFn<'a, [f64; 6]>,
) -> Case<'a, MachineTool, [f64; 6]> {
    const TOOL_MM: f64 = 100.0;
    Case {
        name,
        prior: params.iter().map(|p| p.1).collect(),
        effects: vec!["geometric"; params.len()],
        noise_mm: 0.001,
        model: Box::new(move |d: &[f64]| {
            let edits: Vec<(ToolParam, f64)> = params
                .iter()
                .zip(d)
                .map(|(&(p, _), dv)| (p, m.param_value(p).unwrap_or(0.0) + dv))
                .collect();
            m.with_params(&edits).expect("parameters in range")
        }),
        pose,
        predict: Box::new(|t: &MachineTool, c: &[f64; 6]| t.tip_error_mm(c, &[1; 6], TOOL_MM)),
        jac: Box::new(move |c: &[f64; 6]| sens.jacobian(c, &[1; 6], TOOL_MM)),
    }
}

#[test]
fn coverage_of_a_three_axis_machine_tool() {
    let m = tool("afm-r1000");
    let loc = |axis, error| ToolParam::Location { axis, error };
    let node = |axis, error, node| ToolParam::Component {
        axis,
        error,
        node,
        forward: true,
    };
    // Squareness (µrad, σ 20) and positioning nodes (µm, σ 3).
    let params = [
        (loc(1, LocationParam::Angle(2)), 20.0),
        (loc(2, LocationParam::Angle(0)), 20.0),
        (loc(2, LocationParam::Angle(1)), 20.0),
        (node(0, 0, 3), 3.0),
        (node(0, 0, 7), 3.0),
        (node(1, 1, 5), 3.0),
    ];
    let steps: Vec<(ToolParam, f64)> = params.iter().map(|&(p, _)| (p, 1.0)).collect();
    let sens = postproc::predict::uncertainty::ToolSensitivity::new(&m, &steps).unwrap();
    let pose = Box::new(|r: &mut SplitMix64| {
        [
            1000.0 * r.next_f64(),
            500.0 * r.next_f64(),
            500.0 * r.next_f64(),
            0.0,
            0.0,
            0.0,
        ]
    });
    let share = coverage(&tool_case("3-axis afm-r1000", &m, &params, &sens, pose));
    assert_coverage("3-axis", share);
}

#[test]
fn coverage_of_a_five_axis_machine_tool() {
    let m = tool("five-axis-ac");
    let loc = |axis, error| ToolParam::Location { axis, error };
    // Location errors of the C (slot 5) and A (slot 3) axes: mm σ 0.01,
    // µrad σ 20.
    let params = [
        (loc(5, LocationParam::Offset(0)), 0.01),
        (loc(5, LocationParam::Offset(1)), 0.01),
        (loc(5, LocationParam::Angle(0)), 20.0),
        (loc(5, LocationParam::Angle(1)), 20.0),
        (loc(3, LocationParam::Offset(1)), 0.01),
        (loc(3, LocationParam::Offset(2)), 0.01),
        (loc(3, LocationParam::Angle(1)), 20.0),
        (loc(3, LocationParam::Angle(2)), 20.0),
    ];
    let steps: Vec<(ToolParam, f64)> = params
        .iter()
        .map(|&(p, s)| (p, if s < 1.0 { 0.001 } else { 1.0 }))
        .collect();
    let sens = postproc::predict::uncertainty::ToolSensitivity::new(&m, &steps).unwrap();
    let pose = Box::new(|r: &mut SplitMix64| {
        [
            -200.0 + 400.0 * r.next_f64(),
            -200.0 + 400.0 * r.next_f64(),
            -100.0 + 200.0 * r.next_f64(),
            -90.0 + 180.0 * r.next_f64(),
            0.0,
            -180.0 + 360.0 * r.next_f64(),
        ]
    });
    let share = coverage(&tool_case("5-axis five-axis-ac", &m, &params, &sens, pose));
    assert_coverage("5-axis", share);
}

#[test]
fn coverage_of_a_robot() {
    let robot = match MachineFile::bundled("abb-irb1600").unwrap().load().unwrap() {
        Machine::Robot(r) => r,
        Machine::Tool(_) => panic!("a robot"),
    };
    let dh = |joint, field| RobotParam::Dh { joint, field };
    // DH lengths (mm, σ 0.2) and zero offsets (deg, σ 0.02).
    let params = [
        (dh(0, DhField::D), 0.2),
        (dh(1, DhField::A), 0.2),
        (dh(1, DhField::ThetaOffset), 0.02),
        (dh(2, DhField::A), 0.2),
        (dh(2, DhField::ThetaOffset), 0.02),
        (dh(3, DhField::D), 0.2),
    ];
    let steps: Vec<(RobotParam, f64)> = params
        .iter()
        .map(|&(p, s)| (p, if s < 0.1 { 0.001 } else { 0.01 }))
        .collect();
    let sens = postproc::predict::uncertainty::RobotSensitivity::new(&robot, &steps).unwrap();
    let r = &robot;
    let case = Case {
        name: "robot abb-irb1600",
        prior: params.iter().map(|p| p.1).collect(),
        effects: vec!["kinematic"; params.len()],
        noise_mm: 0.02,
        model: Box::new(move |d: &[f64]| -> Robot {
            let edits: Vec<(RobotParam, f64)> = params
                .iter()
                .zip(d)
                .map(|(&(p, _), dv)| (p, r.param_value(p).unwrap_or(0.0) + dv))
                .collect();
            r.with_params(&edits).expect("parameters in range")
        }),
        pose: Box::new(|g: &mut SplitMix64| {
            let span = [90.0, 60.0, 50.0, 90.0, 90.0, 90.0];
            let mut q = [0.0; 6];
            for (k, s) in span.iter().enumerate() {
                q[k] = (s * (2.0 * g.next_f64() - 1.0)).to_radians();
            }
            q
        }),
        predict: Box::new(|m: &Robot, q: &[f64; 6]| {
            m.tcp_pose(Model::Actual, q).translation.vector
        }),
        jac: Box::new(|q: &[f64; 6]| sens.jacobian(q)),
    };
    let share = coverage(&case);
    assert_coverage("robot", share);
}
