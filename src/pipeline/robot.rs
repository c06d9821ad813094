//! The robot pipeline over the language-neutral move stream
//! ([`crate::program::robot_moves`]): every [`RobotTarget`] is put in the
//! world frame (work object · target, with its tool), its programmed
//! joints chosen by its language's configuration rule, and compensated with
//! [`Robot::compensate`]; every joint target is reported; what is left as
//! written is counted on the warnings. The outcome is one result per step
//! (for the language's writer), the [`Summary`] and the report [`Row`]s.
//!
//! The moves are planned in order (a configuration may follow the move
//! before), then solved on the thread pool, each independent of the
//! others: the results do not depend on the thread count.
//!
//! Between planning and solving, the planned moves are put on the robot
//! time line ([`time_line`]), the one of every robot language: each move is
//! predicted with its process wrench and the thermal power at its end.

pub mod time_line;

use std::collections::HashMap;

use nalgebra::Isometry3;
use rayon::prelude::*;

use crate::compensate::outcome::{DevStats, RobotMove, Row, Summary};
use crate::compensate::robot::{Compensation, Seed};
use crate::error::{Error, Located, Result};
use crate::machine::robot::{IkSelect, Model, Robot, RobotError};
use crate::predict::MoveContext;
use crate::predict::{Breakdown, EffectSet};
use crate::process::CutSettings;
use crate::program::interp::Warning;
use crate::program::robot_moves::{
    Configuration, JOINT_TARGET, JointMove, LeftAsWritten, PathKind, RobotStep, RobotTarget,
    ToolUse,
};
use time_line::{Asked, FALLBACK_TCP_SPEED, Refusal, StreamMove, Timed};

/// Options of a robot compensation run, for every robot language.
#[derive(Debug, Clone)]
pub struct RobotOptions {
    /// Effects to predict and compensate.
    pub effects: EffectSet,
    /// Append a `! dev …` comment to every compensated move.
    pub annotate: bool,
    /// Number formatting of rewritten robtargets.
    pub format: crate::emit::rapid::Format,
    /// Initial thermal state of the program's time line.
    pub thermal_start: crate::machine::ThermalStart,
    /// Keep a report [`Row`] per move in the outcome (for a report); without
    /// a report they are not needed, and for a large module they are a good
    /// part of the memory.
    pub records: bool,
    /// Refuse the module when a move is left as written
    /// ([`refuse_left_as_written`]).
    pub strict: bool,
    /// Compensate `MoveAbsJ` targets as Cartesian poses (joints moved so
    /// that the TCP reaches the nominal pose of the programmed joints);
    /// otherwise each is reported (its predicted deviation) and left as
    /// written ([`JOINT_TARGET`]).
    pub joint_cartesian: bool,
    /// Per-move forces by line of a `table` process force
    /// (`--force-table`, work-object frame).
    pub force_table: Option<std::sync::Arc<crate::process::ForceTable>>,
    /// The parameter covariance of the robot file
    /// ([`crate::predict::uncertainty::BlockUncertainty`]): the annotation
    /// of each compensated target of a language written by the pipeline
    /// (RAPID) carries its U (k = 2); `None` for a file without one.
    pub uncertainty: Option<std::sync::Arc<crate::predict::uncertainty::BlockUncertainty>>,
}

impl Default for RobotOptions {
    /// All effects, annotated, default formatting, cold start, move records.
    fn default() -> Self {
        RobotOptions {
            effects: EffectSet::ALL,
            annotate: true,
            format: crate::emit::rapid::Format::default(),
            thermal_start: crate::machine::ThermalStart::Cold,
            records: true,
            strict: false,
            joint_cartesian: false,
            force_table: None,
            uncertainty: None,
        }
    }
}

impl RobotOptions {
    /// The defaults with the number formatting of the robot file's
    /// `output:` section (quaternions with 7 decimals unless it says
    /// otherwise).
    pub fn for_robot(robot: &Robot) -> Self {
        let d = robot.output_decimals();
        RobotOptions {
            format: crate::emit::rapid::Format {
                position_decimals: d.mm,
                quaternion_decimals: d.quaternion,
            },
            ..RobotOptions::default()
        }
    }
}

/// With `opts.strict`, a program with a move left as written is an input
/// error (exit code 2) that names the first one: `file:line:col: MoveL left
/// as written (CRobT); --strict …`.
pub fn refuse_left_as_written(warnings: &[Warning], file: &str, opts: &RobotOptions) -> Result<()> {
    // A reported joint target is not one known at run time only.
    let left: Vec<(usize, &LeftAsWritten)> = warnings
        .iter()
        .filter_map(|w| w.left.as_ref().map(|a| (w.line, a)))
        .filter(|(_, a)| a.reason != JOINT_TARGET)
        .collect();
    match left.first() {
        Some(&(line, a)) if opts.strict => Err(Error::Input(Located::new(
            file,
            line,
            a.column,
            format!(
                "{} left as written ({}); --strict refuses a module with a move left as written ({} in all)",
                a.instruction,
                a.reason,
                left.len()
            ),
        ))),
        _ => Ok(()),
    }
}

/// What the pipeline found for one step of the stream.
#[derive(Debug, Clone, PartialEq)]
pub enum StepResult {
    /// A compensated target: its compensation and that of its auxiliary
    /// point (world frame poses; `pose` is what to program).
    Compensated {
        /// The target's.
        target: Box<Compensation>,
        /// The auxiliary point's, for a circular move.
        via: Option<Box<Compensation>>,
    },
    /// A joint target's predicted deviation (left as written).
    Reported(Box<Breakdown>),
    /// Nothing (a move left as written).
    None,
}

/// The outcome of a run over a stream.
#[derive(Debug, Clone, Default)]
pub struct RobotRun {
    /// One result per step, in stream order.
    pub results: Vec<StepResult>,
    /// What the run did.
    pub summary: Summary,
    /// One report row per compensated or reported move.
    pub records: Vec<Row>,
}

impl RobotRun {
    /// Each step's compensation as the writers take it, in stream order.
    pub fn solved(&self) -> Vec<crate::compensate::robot::Solved<'_>> {
        self.results
            .iter()
            .map(|r| match r {
                StepResult::Compensated { target, via } => Some((&**target, via.as_deref())),
                _ => None,
            })
            .collect()
    }
}

/// A planned compensation: the robot view, the programmed pose (world),
/// the selection and the programmed joints.
struct Job {
    view: usize,
    pose: Isometry3<f64>,
    q: [f64; 6],
}

/// One compensation to solve, the unit of the solve stage of every robot
/// language ([`solve_jobs`]): the robot view (an index into the run's
/// views), the programmed TCP pose (world frame), the inverse-kinematics
/// selection, the move's context and what planning found of its
/// programmed joints.
pub(crate) struct SolveJob {
    /// Index of the robot view (tool mounted).
    pub(crate) view: usize,
    /// Programmed TCP pose, world frame.
    pub(crate) pose: Isometry3<f64>,
    /// Which joint solution is programmed.
    pub(crate) sel: IkSelect,
    /// The move's context (process wrench, joint powers, tooth frequency).
    pub(crate) ctx: MoveContext,
    /// What planning found of the programmed pose.
    pub(crate) seed: Seed,
}

/// The solved compensation of one [`SolveJob`].
pub(crate) type Solution = std::result::Result<Compensation, RobotError>;

/// Solves `jobs` on the pool (rayon keeps the input order in `collect`;
/// every job is independent of the others, so the results do not depend on
/// the thread count).
pub(crate) fn solve_jobs(views: &[Robot], jobs: &[SolveJob], fx: EffectSet) -> Vec<Solution> {
    jobs.par_iter()
        .map(|j| match views.get(j.view) {
            Some(r) => r.compensate_seeded(&j.ctx, &j.pose, &j.sel, fx, &j.seed),
            None => Err(RobotError::Unreachable("no robot view".into())),
        })
        .collect()
}

/// What planning gave a step.
enum Plan {
    /// Jobs of the target and of its auxiliary point.
    Target(Job, Option<Job>),
    /// A joint target: its view and joints.
    Joints(usize, [f64; 6]),
    /// Nothing to do.
    Left,
}

/// The robot views of a run: a copy of the robot per tool, with the tool
/// mounted, made on a tool's first use and shared by every move that names
/// it (a view per move would cost a copy of the robot per target). The
/// views are shared with the solve stage ([`solve_jobs`]) behind an `Arc`:
/// a view made while no solve holds them copies nothing.
#[derive(Default)]
pub(crate) struct Views {
    /// The views, by index.
    pub(crate) robots: std::sync::Arc<Vec<Robot>>,
    /// The key of each view (what names its tool).
    keys: Vec<String>,
    of: HashMap<String, usize>,
    /// The view used last: consecutive moves mostly share their tool, and
    /// a comparison is cheaper than a hash.
    last: Option<usize>,
}

impl Views {
    /// The index of the view of the tool named `key`, made by `make` on
    /// the key's first use.
    pub(crate) fn index(&mut self, key: &str, make: impl FnOnce() -> Robot) -> usize {
        if let Some(i) = self
            .last
            .filter(|&i| self.keys.get(i).is_some_and(|k| k == key))
        {
            return i;
        }
        let i = match self.of.get(key) {
            Some(&i) => i,
            None => {
                let robots = std::sync::Arc::make_mut(&mut self.robots);
                robots.push(make());
                let i = robots.len() - 1;
                self.keys.push(key.to_string());
                self.of.insert(key.to_string(), i);
                i
            }
        };
        self.last = Some(i);
        i
    }

    fn get(&mut self, robot: &Robot, tool: &ToolUse) -> usize {
        self.index(&tool.key, || robot.with_tool(tool.flange_to_tcp, tool.load))
    }
}

/// The programmed joints of `pose` (world) on `view` by `rule`, after the
/// joints `prev` of the target before, with the closed-form branch of the
/// solution when the rule gives one (a seed of the compensation). A
/// refusal of [`Configuration::Conf`] does not list the configurations
/// that reach the pose ([`Robot::with_reaching_configurations`], a search
/// the caller makes for the refusal it reports).
pub(crate) fn programmed_joints(
    view: &Robot,
    pose: &Isometry3<f64>,
    rule: &Configuration,
    prev: Option<&[f64; 6]>,
) -> std::result::Result<([f64; 6], Option<usize>), RobotError> {
    match rule {
        Configuration::Conf(c) => view.ik_conf_indexed(pose, *c).map(|(q, k)| (q, Some(k))),
        Configuration::Previous => match prev {
            Some(p) => view.ik_nearest(pose, p).map(|(q, k)| (q, Some(k))),
            None => Err(RobotError::Unreachable(
                "no target before gives its configuration (it is the robot's at run time)".into(),
            )),
        },
        Configuration::Admits(admits, text) => {
            let mut best: Option<(f64, [f64; 6])> = None;
            let turns = [0.0, -std::f64::consts::TAU, std::f64::consts::TAU];
            for q in view.ik_all(pose)?.into_iter().flatten() {
                for t1 in turns {
                    for t4 in turns {
                        for t6 in turns {
                            let mut c = q;
                            c[0] += t1;
                            c[3] += t4;
                            c[5] += t6;
                            if !admits(view, &c) || view.check_limits(&c).is_err() {
                                continue;
                            }
                            let d = prev
                                .map_or(0.0, |p| c.iter().zip(p).map(|(a, b)| (a - b).abs()).sum());
                            if best.is_none_or(|(b, _)| d < b) {
                                best = Some((d, c));
                            }
                        }
                    }
                }
            }
            best.map(|(_, q)| (q, None)).ok_or_else(|| {
                RobotError::Unreachable(format!("no joint solution within the limits has {text}"))
            })
        }
    }
}

/// A target's refusal at its line and column.
fn refused(file: &str, line: usize, column: usize, what: &str, e: RobotError) -> Error {
    Error::Unachievable(Located::new(file, line, column, format!("{what}: {e}")))
}

/// Plans the steps in order: views, programmed poses and joints.
fn plan(
    robot: &Robot,
    steps: &[RobotStep],
    views: &mut Views,
    file: &str,
) -> Result<(Vec<Plan>, Vec<Warning>)> {
    let mut plans = Vec::with_capacity(steps.len());
    let mut warnings = Vec::new();
    let mut prev: Option<[f64; 6]> = None;
    for step in steps {
        match step {
            RobotStep::Target(t) => {
                let view = views.get(robot, &t.tool);
                let r = &views.robots[view];
                let pose = t.work * t.pose;
                // The message is made only for a refusal.
                let what = || format!("target of {} at line {}", t.instruction, t.line);
                let q = programmed_joints(r, &pose, &t.configuration, prev.as_ref());
                let q = match q {
                    Ok((q, _)) => q,
                    Err(e)
                        if matches!(t.configuration, Configuration::Previous) && prev.is_none() =>
                    {
                        warnings.push(LeftAsWritten::warning(
                            t.line,
                            t.column,
                            t.instruction,
                            &e.to_string(),
                        ));
                        plans.push(Plan::Left);
                        continue;
                    }
                    Err(e) => {
                        let e = match t.configuration {
                            Configuration::Conf(_) => r.with_reaching_configurations(&pose, e),
                            _ => e,
                        };
                        return Err(refused(file, t.line, t.column, &what(), e));
                    }
                };
                let via = match &t.via {
                    Some((v, _)) => {
                        let vpose = t.work * v;
                        let qv = r
                            .ik_nearest(&vpose, &q)
                            .map_err(|e| refused(file, t.line, t.column, &what(), e))?
                            .0;
                        Some(Job {
                            view,
                            pose: vpose,
                            q: qv,
                        })
                    }
                    None => None,
                };
                prev = Some(q);
                plans.push(Plan::Target(Job { view, pose, q }, via));
            }
            RobotStep::Joints(j) => match &j.tool {
                Some(tool) => {
                    let view = views.get(robot, tool);
                    views.robots[view]
                        .check_limits(&j.q)
                        .map_err(|e| refused(file, j.line, j.column, "joint target", e))?;
                    prev = Some(j.q);
                    warnings.push(LeftAsWritten::warning(
                        j.line,
                        j.column,
                        j.instruction,
                        JOINT_TARGET,
                    ));
                    plans.push(Plan::Joints(view, j.q));
                }
                None => {
                    prev = Some(j.q);
                    warnings.push(LeftAsWritten::warning(
                        j.line,
                        j.column,
                        j.instruction,
                        "joint target before any tool is set: not predicted",
                    ));
                    plans.push(Plan::Left);
                }
            },
            RobotStep::Left(w) => {
                warnings.push(w.clone());
                plans.push(Plan::Left);
            }
        }
    }
    Ok((plans, warnings))
}

/// The time line of the planned steps ([`time_line::put`]): one
/// entry per step (the default, a cold context, for a step left as
/// written), or all defaults for a robot with neither a thermal model nor a
/// process force.
fn timed_steps(
    robot: &Robot,
    steps: &[RobotStep],
    plans: &[Plan],
    views: &Views,
    opts: &RobotOptions,
    file: &str,
) -> Result<Vec<Timed>> {
    let mut out = vec![Timed::default(); steps.len()];
    if robot.thermal().is_none() && robot.process_force().is_none() {
        return Ok(out);
    }
    let fx = opts.effects;
    let need = fx.process != 0.0 || robot.thermal().is_some_and(|_| fx.thermal != 0.0);
    let mut moves = Vec::with_capacity(steps.len());
    let mut index = Vec::with_capacity(steps.len());
    let mut fallen_back = Vec::new();
    for (i, (step, plan)) in steps.iter().zip(plans).enumerate() {
        let m = match (step, plan) {
            (RobotStep::Target(t), Plan::Target(j, via)) => {
                let feed = t.path != PathKind::Joint;
                // A straight or circular move without a speed is taken at
                // the fallback speed (said in a warning).
                let fallback = need && feed && t.speed_mm_s.is_none();
                if fallback {
                    fallen_back.push(moves.len());
                }
                StreamMove {
                    view: &views.robots[j.view],
                    key: &t.tool.key,
                    pose: j.pose,
                    via: via.as_ref().map(|v| v.pose.translation.vector),
                    q: Some(j.q),
                    wobj: t.work,
                    feed,
                    linear: t.path == PathKind::Linear,
                    v_tcp: if fallback {
                        Some(FALLBACK_TCP_SPEED)
                    } else {
                        t.speed_mm_s
                    },
                    fallback,
                    line: t.line,
                    set: CutSettings::default(),
                }
            }
            (RobotStep::Joints(jm), Plan::Joints(view, q)) => {
                let key = jm.tool.as_ref().map_or("", |t| t.key.as_str());
                let view = &views.robots[*view];
                StreamMove {
                    view,
                    key,
                    pose: view.tcp_pose(Model::Nominal, q),
                    via: None,
                    q: Some(*q),
                    wobj: Isometry3::identity(),
                    feed: false,
                    linear: false,
                    v_tcp: None,
                    fallback: false,
                    line: jm.line,
                    set: CutSettings::default(),
                }
            }
            _ => continue,
        };
        moves.push(m);
        index.push(i);
    }
    let asked = Asked {
        process: fx.process != 0.0,
        thermal: fx.thermal != 0.0,
        start: opts.thermal_start,
        x0: None,
        effective: true,
        power: need,
        flanges: false,
        table: opts.force_table.as_deref(),
    };
    let at = |k: usize| match index.get(k).and_then(|&i| steps.get(i)) {
        Some(RobotStep::Target(t)) => (t.line, t.column, t.instruction),
        Some(RobotStep::Joints(j)) => (j.line, j.column, j.instruction),
        _ => (0, 0, "move"),
    };
    let timed = time_line::put(robot, &moves, 0, &asked, &mut None).map_err(|(k, why)| {
        let (line, column, instruction) = at(k);
        let what = match why {
            Refusal::NeedsSpeed(what) => what,
            Refusal::NoDuration => "thermal time line",
        };
        Error::Input(Located::new(
            file,
            line,
            column,
            format!(
                "the TCP speed of {instruction} cannot be resolved offline; the {what} needs it"
            ),
        ))
    })?;
    if let Some(&k) = fallen_back.first() {
        let (line, _, instruction) = at(k);
        tracing::warn!(
            "{}:{line}: the TCP speed of {instruction} (and of {} straight or circular move(s) in all) cannot be resolved offline; the time line takes it as {FALLBACK_TCP_SPEED} mm/s, and a drilling move with it has no thrust",
            crate::error::Escaped(file),
            fallen_back.len()
        );
    }
    for (i, t) in index.into_iter().zip(timed) {
        out[i] = t;
    }
    Ok(out)
}

/// Runs the pipeline over `steps` on `robot` (`file` names the program in
/// messages): plans the steps in order, puts them on the robot time line
/// (process wrench and thermal drift of every move, [`time_line`]) and
/// solves them on the pool. Errors: [`Error::Unachievable`] at the first
/// target that cannot be reached in its configuration or compensated;
/// [`Error::Input`] at a move whose process force needs a TCP speed known
/// at run time only.
pub fn run(
    robot: &Robot,
    steps: &[RobotStep],
    opts: &RobotOptions,
    file: &str,
) -> Result<RobotRun> {
    let mut views = Views::default();
    let (plans, warnings) = plan(robot, steps, &mut views, file)?;
    let timed = timed_steps(robot, steps, &plans, &views, opts, file)?;
    let fx = opts.effects;
    // The targets' and circle points' compensations, solved together;
    // the joint targets' predictions beside them.
    let job = |j: &Job, ctx: &MoveContext| {
        let r = &views.robots[j.view];
        SolveJob {
            view: j.view,
            pose: j.pose,
            sel: IkSelect::Conf(r.confdata(&j.q)),
            ctx: *ctx,
            seed: Seed {
                q: Some(j.q),
                ..Seed::default()
            },
        }
    };
    let mut jobs = Vec::with_capacity(plans.len());
    for (p, t) in plans.iter().zip(&timed) {
        if let Plan::Target(j, v) = p {
            jobs.push(job(j, &t.ctx));
            jobs.extend(v.as_ref().map(|v| job(v, &t.ctx)));
        }
    }
    let mut solutions = solve_jobs(&views.robots, &jobs, fx).into_iter();
    drop(jobs);
    let reported: Vec<Option<Breakdown>> = plans
        .par_iter()
        .zip(timed.par_iter())
        .map(|(p, t)| match p {
            Plan::Joints(view, q) => Some(views.robots[*view].predict_at_joints(&t.ctx, q, fx)),
            _ => None,
        })
        .collect();
    let mut next = || {
        solutions
            .next()
            .unwrap_or_else(|| Err(RobotError::Unreachable("no solution".into())))
    };
    let solved: Vec<std::result::Result<StepResult, RobotError>> = plans
        .iter()
        .zip(reported)
        .map(|(p, dev)| match (p, dev) {
            (Plan::Target(_, v), _) => {
                let target = next();
                let via = v.as_ref().map(|_| next());
                Ok(StepResult::Compensated {
                    target: Box::new(target?),
                    via: via.transpose()?.map(Box::new),
                })
            }
            (Plan::Joints(..), Some(dev)) => Ok(StepResult::Reported(Box::new(dev))),
            _ => Ok(StepResult::None),
        })
        .collect();
    let mut out = RobotRun::default();
    let mut deviation = DevStats::default();
    let mut moves = 0;
    for ((step, r), t) in steps.iter().zip(solved).zip(&timed) {
        let r = r.map_err(|e| match step {
            RobotStep::Target(t) => refused(
                file,
                t.line,
                t.column,
                &format!("target of {} at line {}", t.instruction, t.line),
                e,
            ),
            _ => Error::Internal(format!("{e}")),
        })?;
        match (&r, step) {
            (StepResult::Compensated { target, .. }, RobotStep::Target(s)) => {
                moves += 1;
                deviation.add(target.deviation.total.pos_mm.norm(), s.line);
                if opts.records {
                    out.records.push(with_time(row(s, target), t));
                }
            }
            (StepResult::Reported(dev), RobotStep::Joints(j)) if opts.records => {
                out.records.push(with_time(joint_row(robot, j, dev), t));
            }
            _ => {}
        }
        out.results.push(r);
    }
    out.summary = Summary {
        moves,
        deviation,
        warnings,
        ..Summary::default()
    };
    Ok(out)
}

/// A row with its move's time line: wrench, duration and powers.
fn with_time(mut row: Row, t: &Timed) -> Row {
    if let Some(r) = row.robot.as_mut() {
        r.wrench = t.ctx.wrench;
        r.duration_s = t.duration_s;
        r.power_w = t.power_w;
        r.thermal_power_w = t.ctx.joint_powers_w();
    }
    row
}

/// The report row of a compensated target.
fn row(t: &RobotTarget, c: &Compensation) -> Row {
    let p = (t.work * t.pose).translation.vector;
    let via = t
        .via
        .as_ref()
        .map(|(v, _)| (t.work * v).translation.vector.into());
    robot_row(
        (t.line, t.instruction),
        p.into(),
        via,
        c.deviation,
        Some(c.q_programmed),
    )
}

/// The report row of a reported joint target.
fn joint_row(robot: &Robot, j: &JointMove, dev: &Breakdown) -> Row {
    // The model is copied only for a move with its own tool.
    let pose = match &j.tool {
        Some(t) => robot
            .with_tool(t.flange_to_tcp, t.load)
            .tcp_pose(Model::Nominal, &j.q),
        None => robot.tcp_pose(Model::Nominal, &j.q),
    };
    let p = pose.translation.vector;
    robot_row((j.line, j.instruction), p.into(), None, *dev, Some(j.q))
}

/// A robot move's report row, the one of every robot language: its line
/// and instruction, the programmed TCP position, the circle point of a
/// circular move, the deviation and the programmed joints when the
/// language reports them (its place on the time line is added after).
pub(crate) fn robot_row(
    (line, motion): (usize, &'static str),
    p: [f64; 3],
    via_mm: Option<[f64; 3]>,
    deviation: Breakdown,
    q: Option<[f64; 6]>,
) -> Row {
    Row {
        line,
        motion,
        start: [0.0; 6],
        commanded: [p[0], p[1], p[2], 0.0, 0.0, 0.0],
        arc: None,
        compensated: [0.0; 6],
        result: crate::compensate::BlockResult::default(),
        robot: Some(RobotMove {
            via_mm,
            deviation,
            wrench: None,
            duration_s: 0.0,
            power_w: [0.0; 6],
            thermal_power_w: [0.0; 6],
            q_rad: q,
        }),
    }
}
