//! Compensation of an ABB RAPID module against a robot model.
//!
//! Every motion instruction is resolved to a programmed TCP pose in the world
//! frame (target · tooldata · wobjdata), compensated with
//! [`Robot::compensate`] for the tool and process phase of that move, and
//! written back in the target's own frame by byte-faithful edits
//! ([`crate::emit::rapid`]). The rewriting rules (in-place edits, `_cN`
//! copies of named targets used under different loads, `_oN` materialised
//! `Offs`/`RelTool` targets, joint-space `MoveAbsJ`) are documented in
//! `grammar/rapid.md`, section "Compensation rewriting".

pub mod program;
pub mod stream;

use std::collections::{HashMap, HashSet};
use std::rc::Rc;
use std::sync::Arc;

use rayon::prelude::*;

use nalgebra::Isometry3;

use crate::compensate::outcome::{Compensated, DevStats, Row, Summary};
use crate::compensate::robot::Seed;
use crate::emit::rapid::{
    EditList, TakenNames, fresh_name, insert_after_decl, joint_text, push_annotation,
    robtarget_in_place, robtarget_text, write_dev_comment,
};
use crate::error::{Error, Located, Result};
use crate::machine::robot::thermal::{Segment, ThermalTotals};
use crate::machine::robot::{ConfData, IkSelect, Model, Robot, RobotError};
use crate::pipeline::resonance::ResonanceWatch;
use crate::pipeline::robot::time_line::{
    self, Asked, FALLBACK_TCP_SPEED, LastEnd, Refusal, StreamMove, Timed, WrenchBits, wrench_bits,
};
use crate::pipeline::robot::{Solution, SolveJob, Views, programmed_joints, robot_row, solve_jobs};
use crate::predict::robot::Breakdown;
use crate::predict::robot_uncertainty::{push_u, target_u_mm};
use crate::predict::{MoveContext, ThermalInput, Wrench};
use crate::process::CutSettings;
use crate::program::interp::Warning;
use crate::program::rapid::directives::Directives;
use crate::program::rapid::flow::{At, Flow, Left};
use crate::program::rapid::instructions::motion_instruction;
use crate::program::rapid::resolve::{
    CartUse, Origin, ToolView, input_err, line_col, named_value, resolve_cart, resolve_tool,
    resolve_wobj, tcp_speed,
};
use crate::program::rapid::{
    ConfMonitoring, DataValue, Module, Move, MoveKind, Target, column_of, parse_module,
};
use crate::program::robot_moves::{Configuration, LeftAsWritten};

/// The options of a RAPID run: those of the robot pipeline, the one of
/// every robot language.
pub use crate::pipeline::robot::RobotOptions as RapidOptions;

/// Why a `MoveAbsJ` is left as written by default: its joints are what the
/// controller goes to, not a pose it solves (`grammar/rapid.md`, "Joint
/// targets"); the same reason for every robot language.
pub use crate::program::robot_moves::JOINT_TARGET;

/// The `--strict` rule of every robot language.
pub use crate::pipeline::robot::refuse_left_as_written;

/// Tool and work object of one move, its process wrench and its thermal
/// state (as bit patterns): moves with equal keys share a robot view and a
/// compensated target.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
struct LoadKey {
    /// Tool name in lower case (shared by the moves with the same tool).
    tool: Rc<str>,
    /// Work object name in lower case (shared, as `tool`).
    wobj: Rc<str>,
    wrench: Option<WrenchBits>,
    power: Option<[u64; 6]>,
    rpm: Option<u64>,
}

impl LoadKey {
    /// The owner of a declaration that keeps its value as written (no
    /// move has an empty tool name).
    fn as_written() -> LoadKey {
        LoadKey {
            tool: Rc::from(""),
            wobj: Rc::from(""),
            wrench: None,
            power: None,
            rpm: None,
        }
    }
}

/// Mutable state of one run: edits, new declarations, caches.
struct Rewriter<'m> {
    module: &'m Module,
    src: &'m str,
    file: &'m str,
    robot: &'m Robot,
    opts: RapidOptions,
    edits: EditList,
    /// New declaration lines per module declaration index.
    inserts: Vec<(usize, String)>,
    taken: TakenNames,
    /// Names new data may not take (lower case): [`Carry::reserved`].
    reserved: HashSet<String>,
    /// Robot views (one per tool; the process wrench and the thermal
    /// state of a move go with its job).
    views: Views,
    /// Collecting the compensation jobs, or applying their results.
    phase: Phase,
    /// Load key that owns the in-place value of a target origin.
    owner: HashMap<Origin, LoadKey>,
    /// Names of copies / materialised targets already made.
    made: HashMap<(Origin, String, LoadKey), String>,
    /// Counter of `_oN` names per origin.
    derived_count: HashMap<Origin, usize>,
    added: usize,
    /// Process wrench and thermal power of the move being rewritten.
    state: MoveState,
    /// Programmed TCP position (world, mm) of the last target compensated.
    last_tcp: [f64; 3],
    /// Programmed joints (rad) of the last target compensated: where its
    /// annotation's U is propagated.
    last_q: [f64; 6],
    /// Declarations from this index on are another module's.
    foreign_from: usize,
    /// Start of the move annotated last (a `FOR` loop's move is met once
    /// per element and annotated once, with its first element).
    last_annotated: Option<usize>,
}

/// The two walks over the moves, interleaved a chunk at a time: the first
/// collects the compensations of the chunk's moves as [`SolveJob`]s; they are
/// solved on the pool (each job independent of the others and of the
/// thread count) while the second walk writes back the results of the chunk
/// before, in source order.
enum Phase {
    /// Collecting the jobs of a chunk.
    Collect(Vec<SolveJob>),
    /// The results of the chunk being written back, in job order.
    Apply(std::vec::IntoIter<Solution>),
}

/// Jobs per chunk (a chunk ends at the move that reaches it): the jobs and
/// results of two chunks at a time live while the move records grow, never
/// those of all the moves.
const JOB_CHUNK: usize = 4096;

/// Per-move load state applied to the robot view.
#[derive(Debug, Clone, Copy, Default)]
struct MoveState {
    wrench: Option<Wrench>,
    power: Option<[f64; 6]>,
    /// Spindle speed of a `! POSTPROC MILLING RPM=` directive, 1/min.
    rpm: Option<f64>,
}

impl Rewriter<'_> {
    fn active(&self) -> bool {
        self.opts.effects.compensates()
    }

    /// Index of the robot view of a load key (made on first use).
    fn view(&mut self, key: &LoadKey, tool: &ToolView) -> usize {
        let robot = self.robot;
        // Walk 1 makes the views while no chunk is being solved (the list
        // is not shared then, so nothing is copied); walk 2 meets only the
        // keys walk 1 saw.
        self.views
            .index(&key.tool, || robot.with_tool(tool.tframe, tool.load))
    }

    /// The context of the move being rewritten: its process wrench, its
    /// effective joint powers (cold without), the spindle speed and tooth
    /// frequency of the robot's process force at its speed directive.
    fn context(&self) -> MoveContext {
        let pf = self
            .robot
            .process_force()
            .map(|p| p.with_rpm(self.state.rpm));
        MoveContext {
            wrench: self.state.wrench,
            thermal: self
                .state
                .power
                .map_or(ThermalInput::Cold, ThermalInput::JointPowers),
            spindle_rpm: pf.and_then(|p| p.spindle_rpm).unwrap_or(0.0),
            tooth_hz: pf.and_then(|p| p.excitation_hz()).unwrap_or(0.0),
            ..MoveContext::default()
        }
    }

    /// The compensation of one target: recorded as a job while collecting
    /// (`None`), the next solved result while applying.
    fn solve(
        &mut self,
        view: usize,
        pose: Isometry3<f64>,
        sel: IkSelect,
        seed: Seed,
    ) -> Option<Solution> {
        let ctx = self.context();
        match &mut self.phase {
            Phase::Collect(jobs) => {
                jobs.push(SolveJob {
                    view,
                    pose,
                    sel,
                    ctx,
                    seed,
                });
                None
            }
            // The results run out only for the moves after a collection
            // that stopped at an error, which this walk meets first; solve
            // directly anyway.
            Phase::Apply(results) => {
                Some(
                    results
                        .next()
                        .unwrap_or_else(|| match self.views.robots.get(view) {
                            Some(r) => {
                                r.compensate_seeded(&ctx, &pose, &sel, self.opts.effects, &seed)
                            }
                            None => Err(RobotError::Unreachable("no robot view".into())),
                        }),
                )
            }
        }
    }

    fn locate(&self, at: usize, e: crate::machine::robot::RobotError, what: &str) -> Error {
        let (l, c) = line_col(self.src, at);
        Error::Unachievable(Located::new(self.file, l, c, format!("{what}: {e}")))
    }

    /// Notes a compensated target written with another confdata than the
    /// programmed one: a warning under configuration monitoring off (the
    /// joints nearest the previous move's, another configuration than the
    /// programmed one), else (a joint moved across a quadrant boundary by
    /// the compensation, the same arm posture) with `-v`.
    fn note_confdata(
        &self,
        mv: &Move,
        target: &Target,
        programmed: ConfData,
        written: ConfData,
        free: bool,
    ) {
        // Formatted only when it is shown: no allocation per target otherwise.
        let shown = if free {
            tracing::enabled!(tracing::Level::WARN)
        } else {
            tracing::enabled!(tracing::Level::INFO)
        };
        if !shown {
            return;
        }
        let (ml, mc) = line_col(self.src, mv.span.start);
        let what = format!(
            "{}:{ml}:{mc}: target `{}` of {}: written with confdata {written}, programmed {programmed}",
            self.file,
            self.src.get(target.span()).unwrap_or("?"),
            mv.name,
        );
        if free {
            tracing::warn!(
                "{what} (configuration monitoring off: the joints nearest the previous move's)"
            );
        } else {
            tracing::info!("{what} (the compensation moves a joint across a quadrant boundary)");
        }
    }

    fn decl_text(&self, name: &str, kind: &str, value: &str) -> String {
        format!("LOCAL CONST {kind} {name} := {value};")
    }

    /// Compensates one robtarget use; returns the comment source.
    #[allow(clippy::too_many_arguments)]
    fn cart(
        &mut self,
        mv: &Move,
        (target, u, looped): (&Target, &CartUse, bool),
        key: &LoadKey,
        tool: &ToolView,
        wobj: &Isometry3<f64>,
        seed: Seed,
    ) -> Result<Option<Breakdown>> {
        let view = self.view(key, tool);
        let programmed = wobj * u.pose_obj;
        self.last_tcp = programmed.translation.vector.into();
        // Errors point at the literal's declaration for a plain named target
        // (where the numbers to fix are), else at the move's expression.
        let at = match (&u.origin, u.derived) {
            (Origin::Decl { .. }, false) => u.rt.span.start,
            _ => target.span().start,
        };
        // The message (and its line, a scan of the source) is built only on
        // failure: scanning per move would make a run quadratic.
        let what = || {
            let (ml, _) = line_col(self.src, mv.span.start);
            format!(
                "target `{}` of {} at line {ml}",
                self.src.get(target.span()).unwrap_or("?"),
                mv.name
            )
        };
        let sel = IkSelect::Conf(seed.conf.unwrap_or(u.conf));
        let Some(comp) = self.solve(view, programmed, sel, seed) else {
            return Ok(None);
        };
        // Only the refusal reported lists the configurations that reach
        // its target (a search per configuration on a robot solved
        // numerically; the module is refused at its first).
        let comp = comp.map_err(|e| {
            let e = match self.views.robots.get(view) {
                Some(r) => r.with_reaching_configurations(&programmed, e),
                None => e,
            };
            self.locate(at, e, &what())
        })?;
        self.last_q = comp.q_programmed;
        if !self.active() {
            return Ok(Some(comp.deviation));
        }
        if comp.conf != u.conf {
            self.note_confdata(mv, target, u.conf, comp.conf, seed.conf.is_some());
        }
        let new_obj = wobj.inverse() * comp.pose;
        let fmt = self.opts.format;
        match (u.origin, u.derived) {
            (Origin::Inline, false) => {
                robtarget_in_place(
                    &mut self.edits,
                    self.src,
                    u.rt,
                    &new_obj,
                    u.conf,
                    comp.conf,
                    &fmt,
                )?;
            }
            (Origin::Inline, true) => {
                let text = robtarget_text(self.src, u.rt, &new_obj, comp.conf, &fmt)?;
                self.edits.push_str(target.span(), &text);
            }
            (origin @ Origin::Decl { decl, .. }, false) => match self.in_place(origin, key) {
                InPlace::Write => robtarget_in_place(
                    &mut self.edits,
                    self.src,
                    u.rt,
                    &new_obj,
                    u.conf,
                    comp.conf,
                    &fmt,
                )?,
                InPlace::Written => {}
                InPlace::Copy if looped => {
                    return Err(Error::Internal(format!(
                        "the element `{}` of a FOR loop's move is owned by another move",
                        u.stem
                    )));
                }
                InPlace::Copy => {
                    let text = robtarget_text(self.src, u.rt, &new_obj, comp.conf, &fmt)?;
                    let name = self.copy_name(
                        origin,
                        decl,
                        String::new(),
                        key,
                        &u.stem,
                        "c",
                        2,
                        text,
                        "robtarget",
                    )?;
                    self.edits.push_str(target.span(), &name);
                }
            },
            (origin @ Origin::Decl { decl, .. }, true) => {
                let n = self.derived_count.get(&origin).copied().unwrap_or(0) + 1;
                let text = robtarget_text(self.src, u.rt, &new_obj, comp.conf, &fmt)?;
                let name = self.copy_name(
                    origin,
                    decl,
                    u.derived_key.clone(),
                    key,
                    &u.stem,
                    "o",
                    n,
                    text,
                    "robtarget",
                )?;
                self.edits.push_str(target.span(), &name);
            }
        }
        Ok(Some(comp.deviation))
    }

    /// The name of the copy of `origin` for (`ident`, `key`), declaring it
    /// (after declaration `decl`) when it is new.
    #[allow(clippy::too_many_arguments)]
    fn copy_name(
        &mut self,
        origin: Origin,
        decl: usize,
        ident: String,
        key: &LoadKey,
        stem: &str,
        tag: &str,
        from: usize,
        value: String,
        kind: &str,
    ) -> Result<String> {
        let k = (origin, ident, key.clone());
        if let Some(n) = self.made.get(&k) {
            return Ok(n.clone());
        }
        let module = self.module;
        let name = fresh_name(
            |n| crate::program::rapid::resolve::lookup(module, n).is_some(),
            &mut self.taken,
            &self.reserved,
            stem,
            tag,
            from,
        );
        if tag == "o" {
            *self.derived_count.entry(origin).or_insert(0) += 1;
        }
        let line = self.decl_text(&name, kind, &value);
        self.inserts.push((decl, line));
        self.added += 1;
        self.made.insert(k, name.clone());
        Ok(name)
    }

    /// Compensates a MoveAbsJ in joint space.
    fn joint(&mut self, mv: &Move, key: &LoadKey, tool: &ToolView) -> Result<Option<Breakdown>> {
        let target = &mv.target;
        let (jt, origin, stem) = match target {
            Target::InlineJoint(jt) => (jt, Origin::Inline, String::new()),
            Target::Named { .. } => {
                let (v, origin, stem) = named_value(self.module, self.src, self.file, target)?;
                let DataValue::JointTarget(jt) = v else {
                    return Err(input_err(
                        self.src,
                        self.file,
                        target.span().start,
                        "MoveAbsJ needs a jointtarget",
                    ));
                };
                (jt, origin, stem)
            }
            _ => {
                return Err(input_err(
                    self.src,
                    self.file,
                    target.span().start,
                    "MoveAbsJ target must be a jointtarget name or literal",
                ));
            }
        };
        let q_deg = jt.robax.each_ref().map(|n| n.value);
        let q = q_deg.map(f64::to_radians);
        let view = self.view(key, tool);
        let at = match origin {
            Origin::Decl { .. } => jt.span.start,
            Origin::Inline => target.span().start,
        };
        let what = || {
            let (ml, _) = line_col(self.src, mv.span.start);
            format!(
                "jointtarget `{}` of MoveAbsJ at line {ml}",
                self.src.get(target.span()).unwrap_or("?")
            )
        };
        let Some(r) = self.views.robots.get(view) else {
            return Err(Error::Internal("robot view missing".into()));
        };
        r.check_limits(&q)
            .map_err(|e| self.locate(at, e, &what()))?;
        let goal = r.tcp_pose(Model::Nominal, &q);
        self.last_tcp = goal.translation.vector.into();
        if !self.opts.joint_cartesian {
            return Ok(Some(r.predict_at_joints(
                &self.context(),
                &q,
                self.opts.effects,
            )));
        }
        let Some(comp) = self.solve(view, goal, IkSelect::Near(q), Seed::default()) else {
            return Ok(None);
        };
        let comp = comp.map_err(|e| self.locate(at, e, &what()))?;
        self.last_q = comp.q_programmed;
        if !self.active() {
            return Ok(Some(comp.deviation));
        }
        let new_deg = comp.q_compensated.map(f64::to_degrees);
        match origin {
            Origin::Inline => {
                for (n, v) in jt.robax.iter().zip(new_deg) {
                    let t = crate::emit::rapid::joint_word(v, self.src, self.file, n.span.start)?;
                    self.edits.push_str(n.span.clone(), &t);
                }
            }
            Origin::Decl { decl, .. } => match self.in_place(origin, key) {
                InPlace::Write => {
                    for (n, v) in jt.robax.iter().zip(new_deg) {
                        let t =
                            crate::emit::rapid::joint_word(v, self.src, self.file, n.span.start)?;
                        self.edits.push_str(n.span.clone(), &t);
                    }
                }
                InPlace::Written => {}
                InPlace::Copy => {
                    let text = joint_text(self.src, self.file, jt, &new_deg)?;
                    let name = self.copy_name(
                        origin,
                        decl,
                        String::new(),
                        key,
                        &stem,
                        "c",
                        2,
                        text,
                        "jointtarget",
                    )?;
                    self.edits.push_str(target.span(), &name);
                }
            },
        }
        Ok(Some(comp.deviation))
    }
}

/// Where the compensated value of a declared target goes for one move.
enum InPlace {
    /// Into the declaration: the first move of the load key that owns it.
    Write,
    /// Nowhere new: the declaration already holds it for this load key.
    Written,
    /// Into a copy: another load key (or the as-written owner) owns the
    /// declaration.
    Copy,
}

impl Rewriter<'_> {
    /// Whether the move with `key` writes its compensated target into the
    /// declaration `origin` (the first load key to come owns it), finds it
    /// there already, or needs a copy.
    fn in_place(&mut self, origin: Origin, key: &LoadKey) -> InPlace {
        // Another module's declaration is never edited.
        if matches!(origin, Origin::Decl { decl, .. } if decl >= self.foreign_from) {
            return InPlace::Copy;
        }
        let owner = self.owner.entry(origin).or_insert_with(|| key.clone());
        if owner != key {
            return InPlace::Copy;
        }
        let first = self
            .made
            .insert((origin, String::new(), key.clone()), String::new())
            .is_none();
        if first {
            InPlace::Write
        } else {
            InPlace::Written
        }
    }
}

/// What the time line and the process model need of one move.
struct Planned {
    tool: ToolView,
    wobj: Isometry3<f64>,
    /// Programmed TCP pose (world frame).
    pose: Isometry3<f64>,
    /// Programmed circle point of a MoveC (world frame).
    via: Option<Isometry3<f64>>,
    /// Controller joints, when the target is reachable.
    q: Option<[f64; 6]>,
    /// Closed-form branch of `q` (a Cartesian target's).
    branch: Option<usize>,
    /// Configuration of `q` where configuration monitoring is off for the
    /// move ([`free_configurations`]).
    free_conf: Option<ConfData>,
    /// TCP speed, mm/s, when it can be resolved (or its fallback).
    v_tcp: Option<f64>,
    /// `v_tcp` is [`FALLBACK_TCP_SPEED`]: the move's speed is known at run
    /// time only.
    speed_fallback: bool,
}

/// Plans one move: its tool and work object, its programmed pose and, by
/// the configuration rule of its confdata ([`programmed_joints`]), its
/// programmed joints and their branch when the pose is reachable.
fn plan_move(
    module: &Module,
    src: &str,
    file: &str,
    robot: &Robot,
    views: &mut Views,
    (mv, res): (&Move, &Resolved),
) -> Result<Planned> {
    let tool = resolve_tool(module, src, file, mv)?;
    let wobj = resolve_wobj(module, src, file, mv)?;
    // The tool is resolved from its name alone: equal names, equal views.
    let i = views.index(&mv.tool.text, || robot.with_tool(tool.tframe, tool.load));
    let Some(view) = views.robots.get(i) else {
        return Err(Error::Internal("robot view missing".into()));
    };
    let (pose, q, branch) = if mv.kind == MoveKind::MoveAbsJ {
        let jt = match &mv.target {
            Target::InlineJoint(jt) => Some(jt),
            t @ Target::Named { .. } => match named_value(module, src, file, t)?.0 {
                DataValue::JointTarget(jt) => Some(jt),
                _ => None,
            },
            _ => None,
        };
        let Some(jt) = jt else {
            return Err(input_err(
                src,
                file,
                mv.target.span().start,
                "MoveAbsJ target must be a jointtarget name or literal",
            ));
        };
        let q = jt.robax.each_ref().map(|n| n.value.to_radians());
        (view.tcp_pose(Model::Nominal, &q), Some(q), None)
    } else {
        let Some(u) = &res.target else {
            return Err(Error::Internal("move target not resolved".into()));
        };
        let pose = wobj * u.pose_obj;
        match programmed_joints(view, &pose, &Configuration::Conf(u.conf), None) {
            Ok((q, k)) => (pose, Some(q), k),
            Err(_) => (pose, None, None),
        }
    };
    let via = res.via.as_ref().map(|v| wobj * v.pose_obj);
    Ok(Planned {
        tool,
        wobj,
        pose,
        via,
        q,
        branch,
        free_conf: None,
        v_tcp: tcp_speed(module, mv),
        speed_fallback: false,
    })
}

/// Moves with configuration monitoring off (`ConfL \Off`, `ConfJ \Off`;
/// span starts in `free`, sorted): their joints become the solution
/// nearest the previous move's (`plans[i + o - 1]`), whatever their
/// confdata says, and their configuration is the one written with the
/// compensated target. A first move with no move before keeps its confdata.
fn free_configurations(
    robot: &Robot,
    moves: &[&Move],
    plans: &mut [Planned],
    o: usize,
    free: &[usize],
) {
    let mut views = Views::default();
    for (i, mv) in moves.iter().enumerate() {
        if free.binary_search(&mv.span.start).is_err() {
            continue;
        }
        let Some(prev) = (i + o).checked_sub(1).and_then(|k| plans.get(k)?.q) else {
            continue;
        };
        let Some(plan) = plans.get_mut(i + o) else {
            continue;
        };
        let v = views.index(&mv.tool.text, || {
            robot.with_tool(plan.tool.tframe, plan.tool.load)
        });
        let Some(view) = views.robots.get(v) else {
            continue;
        };
        let rule = Configuration::Previous;
        if let Ok((q, k)) = programmed_joints(view, &plan.pose, &rule, Some(&prev)) {
            plan.free_conf = Some(view.confdata(&q));
            plan.q = Some(q);
            plan.branch = k;
        }
    }
}

/// Parses and compensates a RAPID module. Moves are processed in source
/// order, routine by routine. Errors: [`Error::Input`] for what cannot be
/// resolved offline, [`Error::Unachievable`] (`file:line:col` of the target)
/// for unreachable targets, confdata without solution and joint limits.
pub fn compensate_module(
    src: &str,
    file: &str,
    robot: &Robot,
    opts: &RapidOptions,
) -> Result<Compensated> {
    compensate_parsed(parse_module(src, file)?, src, file, robot, opts)
}

/// [`compensate_module`] of `module`, parsed from `src` by the caller
/// (taken, so that it is freed before the output text is built).
pub fn compensate_parsed(
    module: Module,
    src: &str,
    file: &str,
    robot: &Robot,
    opts: &RapidOptions,
) -> Result<Compensated> {
    compensate_carried(module, (src, file), robot, opts, Carry::default())
}

/// [`compensate_parsed`] from the state `carry` (a module of a program).
pub(crate) fn compensate_carried(
    module: Module,
    (src, file): (&str, &str),
    robot: &Robot,
    opts: &RapidOptions,
    mut carry: Carry,
) -> Result<Compensated> {
    let text = ModuleText {
        module: &module,
        src,
        file,
    };
    carry.keep_unfinished_targets(&module, src, file);
    carry.reserve_names_of(&module);
    let mut edits = compensate_window(text, robot, opts, &mut carry, None, 0)?;
    carry.leave_unfinished(&module, src, file);
    carry.leave_unknown(&module, src, file);
    let spans: Vec<_> = module.decls.iter().map(|d| d.span.clone()).collect();
    // Free the parsed module before the output text is built (the peak).
    drop(module);
    carry.push_inserts(src, &spans, &mut edits);
    let mut outcome = carry.outcome(robot, file);
    refuse_left_as_written(&outcome.summary.warnings, file, opts)?;
    outcome.text = edits.apply(src)?;
    Ok(outcome)
}

/// The moves of `module` (parsed from `src`) that a compensation leaves as
/// written, with their reasons, in line order (warned about as a
/// compensation warns): no robot is needed to find them.
pub fn left_as_written(module: &Module, src: &str, file: &str) -> Result<Vec<Warning>> {
    left_as_written_carried(module, src, file, Carry::default())
}

/// [`left_as_written`] with what the module carries in (the scope of a
/// program of several modules).
pub(crate) fn left_as_written_carried(
    module: &Module,
    src: &str,
    file: &str,
    mut carry: Carry,
) -> Result<Vec<Warning>> {
    carry.resolve(ModuleText { module, src, file })?;
    carry.leave_unfinished(module, src, file);
    carry.leave_unknown(module, src, file);
    Ok(std::mem::take(&mut carry.warnings))
}

/// Why a move of a routine holding an editor placeholder is left as written.
pub const UNFINISHED_ROUTINE: &str = "its routine holds an editor placeholder";

/// Why a statement that looks like a motion instruction to a robtarget is
/// left as written.
pub const UNKNOWN_MOTION: &str =
    "not a motion instruction postproc knows (its robtarget is not compensated)";

/// Why a process instruction of the table written with other positional
/// arguments (another software version's form: `SpotL p10, vmax, spot1,
/// tool1;`) is left as written.
pub const OTHER_FORM: &str = "positional arguments not those of its row of the motion table (its robtarget is not compensated)";

/// What the compensation of one window of a module hands to the next: a
/// module read a window at a time ([`stream`]) is compensated as if whole,
/// and a module compensated whole is one window.
#[derive(Default)]
pub(crate) struct Carry {
    /// Plan of the last move of the windows before (the one before the
    /// next window's first move).
    prev_plan: Option<Planned>,
    /// Load torques at the end of that move ([`time_line::put`]).
    last_end: LastEnd,
    /// Effective thermal power at the end of the windows before (the
    /// start asked for when none).
    pub(crate) thermal_x: Option<[f64; 6]>,
    /// A first pass over the module that only adds up its thermal time
    /// line (a start from the program's own mean power needs the whole of
    /// it before the first move): nothing is compensated or written.
    pub(crate) time_line: Option<ThermalTotals>,
    /// Edits of the text before the window's part (the module's
    /// declarations), for a module read a window at a time.
    pub(crate) before: EditList,
    inserts: Vec<(usize, String)>,
    taken: TakenNames,
    /// Names new data may not take, lower case: the routines, record types
    /// and module names of the module (of the whole program, for a module
    /// of several): a data object may not share its name with them.
    pub(crate) reserved: HashSet<String>,
    owner: HashMap<Origin, LoadKey>,
    made: HashMap<(Origin, String, LoadKey), String>,
    derived_count: HashMap<Origin, usize>,
    added: usize,
    last_tcp: [f64; 3],
    moves: usize,
    /// The predicted deviation of the moves compensated.
    deviation: DevStats,
    resonance: ResonanceWatch,
    records: Vec<Row>,
    /// What the windows found to warn about: the moves left as written,
    /// with their reasons, in line order, then the resonances.
    warnings: Vec<Warning>,
    /// Why the module cannot be read a window at a time, found while
    /// compensating a window.
    pub(crate) unsupported: Option<&'static str>,
    /// The module's place in a program of several modules.
    pub(crate) scope: Option<ProgramScope>,
    /// Module data written by the windows so far ([`Flow::module_data_written`]).
    module_written: std::collections::HashSet<String>,
    /// Module data read by the moves of the windows so far.
    module_read: std::collections::HashSet<String>,
    /// Speed names (lower case) taken as [`FALLBACK_TCP_SPEED`] so far.
    speeds_fallen_back: HashSet<String>,
    /// `MoveAbsJ` moves are reported and left as written
    /// ([`RapidOptions::joint_cartesian`] off).
    joints_reported: bool,
    /// Configuration monitoring at the start of the next window, when it
    /// continues the routine of the window before ([`stream`] sets it; a
    /// window that starts a routine starts with monitoring on).
    pub(crate) conf_continued: Option<ConfMonitoring>,
    /// Configuration monitoring at the end of the last window.
    pub(crate) conf_end: ConfMonitoring,
}

impl Carry {
    /// Reserves the names of `module` that new data may not take: its own
    /// name, its routines' and its record types'.
    pub(crate) fn reserve_names_of(&mut self, module: &Module) {
        let names = std::iter::once(&module.name)
            .chain(module.procs.iter().map(|p| &p.name))
            .chain(module.records.iter().map(|r| &r.name));
        self.reserved.extend(names.map(|n| n.to_ascii_lowercase()));
    }

    /// The new declarations (`_cN` copies, `_oN` targets) as edits of
    /// `src`, whose module declarations have the spans `decls`: one
    /// insertion per original declaration, in order.
    pub(crate) fn push_inserts(
        &mut self,
        src: &str,
        decls: &[crate::program::rapid::Span],
        edits: &mut EditList,
    ) {
        let mut by_decl: Vec<(usize, Vec<String>)> = Vec::new();
        // New declarations for another module's go after the own ones.
        let (from, anchor) = match &self.scope {
            Some(s) => (s.from, Some(s.anchor.clone())),
            None => (usize::MAX, None),
        };
        for (d, line) in std::mem::take(&mut self.inserts) {
            let d = if d >= from {
                from.checked_sub(1).unwrap_or(usize::MAX)
            } else {
                d
            };
            match by_decl.iter_mut().find(|(k, _)| *k == d) {
                Some((_, v)) => v.push(line),
                None => by_decl.push((d, vec![line])),
            }
        }
        for (d, lines) in by_decl {
            let span = match (decls.get(d), &anchor) {
                (Some(span), _) => span,
                (None, Some(anchor)) => anchor,
                (None, None) => continue,
            };
            edits.push(&insert_after_decl(src, span, &lines.join("\n")));
        }
    }

    /// The robtarget declarations that moves of unfinished routines go to
    /// keep their values as written: a compensated move to one of them
    /// gets a copy (`_cN`) instead of the declaration edited in place.
    fn keep_unfinished_targets(&mut self, module: &Module, src: &str, file: &str) {
        for m in module.unfinished_moves() {
            for target in std::iter::once(&m.target).chain(m.via.as_deref()) {
                // A target that does not resolve (a placeholder in it) is
                // not a declaration another move could share.
                if let Ok(u) = resolve_cart(module, src, file, target)
                    && !u.derived
                    && matches!(u.origin, Origin::Decl { .. })
                {
                    self.owner.insert(u.origin, LoadKey::as_written());
                }
            }
        }
    }

    /// Leaves the moves of the module's unfinished routines (an editor
    /// placeholder in them) as written: each is warned about with its
    /// place and listed in the outcome.
    fn leave_unfinished(&mut self, module: &Module, src: &str, file: &str) {
        for m in module.unfinished_moves() {
            tracing::warn!(
                "{}:{}: {} left as written: {}",
                crate::error::Escaped(file),
                m.line,
                m.name,
                UNFINISHED_ROUTINE
            );
            self.warnings.push(LeftAsWritten::warning(
                m.line,
                column_of(src, m.span.start),
                m.name,
                UNFINISHED_ROUTINE,
            ));
        }
        self.warnings.sort_by_key(|a| a.line);
    }

    /// Names the statements that look like motion instructions to a
    /// declared robtarget but are not moves of the table of motion
    /// instructions (`PaintL p10, …`, or `SpotL` in another version's
    /// form): they are left as written, warned about with their place and
    /// listed in the outcome.
    pub(crate) fn leave_unknown(&mut self, module: &Module, src: &str, file: &str) {
        if self.time_line.is_some() {
            return;
        }
        for u in module.unknown_motions(src) {
            let reason = match motion_instruction(&u.name) {
                Some(_) => OTHER_FORM,
                None => UNKNOWN_MOTION,
            };
            tracing::warn!(
                "{}:{}: {} left as written: {}",
                crate::error::Escaped(file),
                u.line,
                crate::error::Escaped(&u.name),
                reason
            );
            self.warnings
                .push(LeftAsWritten::warning(u.line, u.column, &u.name, reason));
        }
        self.warnings.sort_by_key(|a| a.line);
    }

    /// The outcome of the windows compensated (without the text), after
    /// the resonance warnings of the whole module.
    pub(crate) fn outcome(&mut self, robot: &Robot, file: &str) -> Compensated {
        if let Some(modal) = robot.modal() {
            let resonances = self.resonance.warnings(modal, file);
            self.warnings.extend(resonances);
        }
        Compensated {
            text: String::new(),
            summary: Summary {
                moves: self.moves,
                added: self.added,
                deviation: std::mem::take(&mut self.deviation),
                warnings: std::mem::take(&mut self.warnings),
                ..Summary::default()
            },
            records: std::mem::take(&mut self.records),
        }
    }
}

/// A module of a program of several modules, resolved with the
/// declarations of the others after its own
/// ([`crate::program::rapid::program::scoped`]).
#[derive(Debug, Clone)]
pub(crate) struct ProgramScope {
    /// Its own declarations are the first `from` of the module's; the
    /// others belong to other modules and are never edited.
    pub(crate) from: usize,
    /// New declarations for those of the other modules go after this span
    /// (its last declaration, or its `MODULE` keyword).
    pub(crate) anchor: crate::program::rapid::Span,
    /// The data names the other modules' routines write.
    pub(crate) writes: Vec<String>,
    /// The procedures the other modules declare (global ones).
    pub(crate) procedures: crate::program::rapid::flow::calls::Procedures,
}

/// The robtargets a move goes to, resolved before run time: its target
/// and circle point (none for a `MoveAbsJ`, compensated in joint space).
#[derive(Debug, Clone)]
pub(crate) struct Resolved<'m> {
    target: Option<CartUse<'m>>,
    via: Option<CartUse<'m>>,
    /// One element of a `FOR` loop's array (the move is met once per
    /// element: compensated in place only, annotated once).
    looped: bool,
    /// The argument of a call of the move's procedure that gives its
    /// target (a parameter): where a compensated copy is passed.
    call_arg: Option<Target>,
}

/// The targets of one move: one, or those of the elements a `FOR` loop
/// reaches (a move of the loop is resolved once per element).
pub(crate) enum Uses<T> {
    /// The move's own.
    One(T),
    /// One per element, in loop order.
    Many(Vec<T>),
}

impl<T> Uses<T> {
    fn map<U>(self, mut f: impl FnMut(T) -> U) -> Uses<U> {
        match self {
            Uses::One(t) => Uses::One(f(t)),
            Uses::Many(v) => Uses::Many(v.into_iter().map(f).collect()),
        }
    }

    /// Every target, in order (no allocation for one).
    fn into_iter_all(self) -> impl Iterator<Item = T> {
        let (one, many) = match self {
            Uses::One(t) => (Some(t), Vec::new()),
            Uses::Many(v) => (None, v),
        };
        one.into_iter().chain(many)
    }
}

/// Why a module is not read a window at a time: a `FOR` loop's move goes
/// to the elements of an array that no other statement may name.
pub(crate) const LOOP_ELEMENTS: &str = "a FOR loop moves to the elements of an array";

impl Carry {
    /// The moves of a window whose targets are known before run time, with
    /// their targets resolved; each other move is left as written
    /// ([`Carry::leave`]).
    fn resolve<'m>(&mut self, text: ModuleText<'m>) -> Result<(Vec<&'m Move>, Vec<Resolved<'m>>)> {
        let (moves, resolved, _) = self.resolve_with(text, |_, _, _| ())?;
        Ok((moves, resolved))
    }

    /// [`Carry::resolve`], with `plan` run on each move resolved (given its
    /// own robot views): resolving and planning are independent per move,
    /// so both run in parallel, and what the moves leave (warnings, moves
    /// left as written, the first error in move order) is taken in order
    /// after, as one walk would.
    fn resolve_with<'m, P: Send>(
        &mut self,
        text: ModuleText<'m>,
        plan: impl Fn(&mut Views, &'m Move, &Resolved<'m>) -> P + Sync,
    ) -> Result<Resolved3<'m, P>> {
        let ModuleText { module, src, file } = text;
        let flow = match &self.scope {
            Some(scope) => Flow::of_program(module, src, &scope.procedures)
                .with_writes_elsewhere(&scope.writes),
            None => Flow::of(module, src),
        };
        let all: Vec<(At, &'m Move)> = flow.moves().collect();
        let foreign_from = self.scope.as_ref().map_or(usize::MAX, |s| s.from);
        type Found<'m, P> = Result<std::result::Result<Uses<(Resolved<'m>, P)>, Left>>;
        let found: Vec<Found<'m, P>> = all
            .par_iter()
            .map_init(Views::default, |views, &(at, mv)| {
                Ok(
                    resolve_move(&flow, src, file, at, mv, foreign_from)?.map(|rs| {
                        rs.map(|r| {
                            let p = plan(views, mv, &r);
                            (r, p)
                        })
                    }),
                )
            })
            .collect();
        let mut moves = Vec::with_capacity(all.len());
        let mut resolved = Vec::with_capacity(all.len());
        let mut plans = Vec::with_capacity(all.len());
        for ((_, mv), f) in all.iter().zip(found) {
            match f? {
                Ok(rs) => {
                    if self.joints_reported && mv.kind == MoveKind::MoveAbsJ {
                        self.note_as_written(mv, JOINT_TARGET, src);
                    }
                    if let Uses::Many(_) = rs {
                        // A window sees one routine: whether the loop's
                        // array is named elsewhere is the whole module's.
                        self.unsupported.get_or_insert(LOOP_ELEMENTS);
                    }
                    for (r, p) in rs.into_iter_all() {
                        moves.push(*mv);
                        resolved.push(r);
                        plans.push(p);
                    }
                }
                Err(left) => self.leave(mv, left, src, file),
            }
        }
        self.keep_read_by_other_statements(&flow, src);
        self.warnings.sort_by_key(|a| a.line);
        // A window sees one routine: data written in one window and read
        // in another would resolve otherwise read whole.
        self.module_written.extend(flow.module_data_written());
        self.module_read.extend(flow.module_data_read());
        if self
            .module_written
            .iter()
            .any(|w| self.module_read.contains(w))
        {
            self.unsupported.get_or_insert(MODULE_DATA_WRITTEN);
        }
        Ok((moves, resolved, plans))
    }

    /// The declarations that statements other than moves of the table may
    /// move to (an instruction not in the table, a procedure whose moves to
    /// its parameter are left as written) keep their values as written, as
    /// those of a move left as written ([`Flow::read_by_other_statements`]).
    fn keep_read_by_other_statements(&mut self, flow: &Flow<'_>, src: &str) {
        if self.time_line.is_some() {
            return;
        }
        let kept = LoadKey::as_written();
        for origin in flow.read_by_other_statements(src) {
            // A declaration an earlier window already gave to a compensated
            // move: the module is read whole instead.
            if self
                .owner
                .insert(origin, kept.clone())
                .is_some_and(|k| k != kept)
            {
                self.unsupported.get_or_insert(AS_WRITTEN_READS);
            }
        }
    }

    /// Gives each move of `plans` (one per move of `moves`) whose speed is
    /// known at run time only [`FALLBACK_TCP_SPEED`], warning once per
    /// speed name.
    fn fall_back_speeds(&mut self, moves: &[&Move], plans: &mut [Planned], file: &str) {
        for (mv, p) in moves.iter().zip(plans.iter_mut()) {
            if p.v_tcp.is_some() {
                continue;
            }
            p.v_tcp = Some(FALLBACK_TCP_SPEED);
            p.speed_fallback = true;
            let name = mv.speed.text.trim().to_ascii_lowercase();
            if self.time_line.is_none() && self.speeds_fallen_back.insert(name) {
                tracing::warn!(
                    "{}:{}: speed `{}` of {} cannot be resolved offline; the time line takes it as vmax, the robot's rated TCP speed ({FALLBACK_TCP_SPEED} mm/s), and a drilling move with it has no thrust",
                    crate::error::Escaped(file),
                    mv.line,
                    mv.speed.text.trim(),
                    mv.name
                );
            }
        }
    }

    /// Leaves a move as written: warned about with its place and reason,
    /// listed in the outcome; the declarations its target reads keep their
    /// values as written (a compensated move to one of them gets a copy).
    fn leave(&mut self, mv: &Move, left: Left, src: &str, file: &str) {
        if self.time_line.is_some() {
            return;
        }
        tracing::warn!(
            "{}:{}: {} left as written ({})",
            crate::error::Escaped(file),
            mv.line,
            mv.name,
            left.reason
        );
        for origin in left.reads {
            self.owner.insert(origin, LoadKey::as_written());
            self.unsupported.get_or_insert(AS_WRITTEN_READS);
        }
        self.warnings.push(LeftAsWritten::warning(
            mv.line,
            column_of(src, mv.span.start),
            mv.name,
            &left.reason,
        ));
    }

    /// Counts a move that stays on the time line but is written as it was
    /// (a reported `MoveAbsJ`: counted in the summary line, not warned
    /// about one by one, as nearly every program has its homes).
    fn note_as_written(&mut self, mv: &Move, reason: &str, src: &str) {
        if self.time_line.is_some() {
            return;
        }
        self.warnings.push(LeftAsWritten::warning(
            mv.line,
            column_of(src, mv.span.start),
            mv.name,
            reason,
        ));
    }
}

/// The moves resolved, their targets and what was planned of each
/// ([`Carry::resolve_with`]).
type Resolved3<'m, P> = (Vec<&'m Move>, Vec<Resolved<'m>>, Vec<P>);

/// Why a module is not read a window at a time: a routine writes module
/// data that moves read (a window does not see the other routines).
pub(crate) const MODULE_DATA_WRITTEN: &str = "a routine assigns module data that moves read";

/// Why a module is not read a window at a time: a move left as written
/// reads a declaration, which must keep its value from the first window on.
pub(crate) const AS_WRITTEN_READS: &str = "a move left as written reads a declared target";

/// The targets of move `mv` at `at`, or why it is left as written.
fn resolve_move<'m>(
    flow: &Flow<'m>,
    src: &str,
    file: &str,
    at: At,
    mv: &'m Move,
    foreign_from: usize,
) -> Result<std::result::Result<Uses<Resolved<'m>>, Left>> {
    if let Some(mut left) = flow.load_left(at, mv) {
        // The targets it goes to keep their values as written.
        if mv.kind != MoveKind::MoveAbsJ {
            for t in mv.via.iter().map(|v| &**v).chain([&mv.target]) {
                match flow.cart(src, file, at, t)? {
                    Ok(u) if matches!(u.origin, Origin::Decl { .. }) => left.reads.push(u.origin),
                    Ok(_) => {}
                    Err(l) => left.reads.extend(l.reads),
                }
            }
        }
        return Ok(Err(left));
    }
    if mv.kind == MoveKind::MoveAbsJ {
        return Ok(match flow.joint_left(at, &mv.target) {
            Some(left) => Err(left),
            None => Ok(Uses::One(Resolved {
                target: None,
                via: None,
                looped: false,
                call_arg: None,
            })),
        });
    }
    let via = match &mv.via {
        Some(v) => match flow.cart(src, file, at, v)? {
            Ok(u) => Some(u),
            Err(left) => return Ok(Err(left)),
        },
        None => None,
    };
    Ok(match flow.cart(src, file, at, &mv.target)? {
        Ok(u) => Ok(Uses::One(Resolved {
            target: Some(u),
            via,
            looped: false,
            call_arg: None,
        })),
        Err(left)
            if left.reason == crate::program::rapid::flow::RUN_TIME_INDEX && via.is_none() =>
        {
            // Another module's declaration is never edited in place.
            match flow.loop_elements(src, file, at, &mv.target).filter(|us| {
                us.iter()
                    .all(|u| matches!(u.origin, Origin::Decl { decl, .. } if decl < foreign_from))
            }) {
                Some(us) => Ok(Uses::Many(
                    us.into_iter()
                        .map(|u| Resolved {
                            target: Some(u),
                            via: None,
                            looped: true,
                            call_arg: None,
                        })
                        .collect(),
                )),
                None => Err(left),
            }
        }
        Err(left) if left.reason == crate::program::rapid::flow::PARAMETER && via.is_none() => {
            match flow.call_uses(src, file, at, &mv.target).filter(|us| {
                us.iter().all(
                    |(u, _)| matches!(u.origin, Origin::Decl { decl, .. } if decl < foreign_from),
                )
            }) {
                Some(us) => Ok(Uses::Many(
                    us.into_iter()
                        .map(|(u, span)| Resolved {
                            call_arg: Some(Target::Named {
                                name: u.stem.clone(),
                                index: None,
                                span,
                            }),
                            target: Some(u),
                            via: None,
                            looped: false,
                        })
                        .collect(),
                )),
                None => Err(left),
            }
        }
        Err(left) => Err(left),
    })
}

/// A parsed module (or the window of one being compensated) with the text
/// its spans point into and the file name of its messages.
#[derive(Clone, Copy)]
pub(crate) struct ModuleText<'a> {
    /// The parsed module.
    pub(crate) module: &'a Module,
    /// The text it was parsed from.
    pub(crate) src: &'a str,
    /// File name for messages.
    pub(crate) file: &'a str,
}

/// Compensates the moves of `text.module`, continuing the windows before
/// from `carry`. `directives`: the program's `! POSTPROC MILLING` settings
/// of the window (parsed from `text.src` when `None`). Returns the edits of
/// `text.src` from byte `before` on; those before it go to `carry.before`.
pub(crate) fn compensate_window(
    text: ModuleText,
    robot: &Robot,
    opts: &RapidOptions,
    carry: &mut Carry,
    directives: Option<Directives>,
    before: usize,
) -> Result<EditList> {
    let ModuleText { module, src, file } = text;
    carry.joints_reported = !opts.joint_cartesian;
    let (moves, resolved, plans) = carry.resolve_with(text, |views, mv, res| {
        plan_move(module, src, file, robot, views, (mv, res))
    })?;
    // The first error in move order is the error, as in order.
    let plans = plans.into_iter().collect::<Result<Vec<Planned>>>()?;
    let mut line = Window::of_window((&moves, plans), text, robot, opts, carry, directives)?;
    if carry.time_line.is_some() {
        carry.prev_plan = line.plans.pop();
        return Ok(EditList::new());
    }
    let mut rw = Rewriter::resume(text, robot, opts, carry);
    if opts.records {
        carry.records.reserve(moves.len());
    }
    rw.walks((&moves, &resolved), &line, carry)?;
    let edits = rw.suspend(carry);
    drop(std::mem::take(&mut line.timed));
    carry.prev_plan = line.plans.pop();
    if before == 0 {
        return Ok(edits);
    }
    let (head, rest) = edits.split_at(before);
    carry.before.append(&head);
    Ok(rest)
}

/// A window's moves planned and put on the robot time line
/// ([`time_line::put`]), before any target is compensated: each move's
/// plan, process wrench, duration, joint powers and thermal power, and the
/// nominal flange at its end.
struct Window {
    /// `plans[i + o]` is the plan of move `i`, `plans[i + o - 1]` that of
    /// the move before (the last of the windows before for the first).
    plans: Vec<Planned>,
    o: usize,
    /// The program's `! POSTPROC MILLING` settings.
    directives: Directives,
    /// Move `i` on the time line.
    timed: Vec<Timed>,
}

impl Window {
    /// Plans the moves of a window (continuing the windows before from
    /// `carry`) and puts them on the time line.
    fn of_window(
        (moves, window_plans): (&[&Move], Vec<Planned>),
        text: ModuleText,
        robot: &Robot,
        opts: &RapidOptions,
        carry: &mut Carry,
        directives: Option<Directives>,
    ) -> Result<Self> {
        let ModuleText { module, src, file } = text;
        let o = usize::from(carry.prev_plan.is_some());
        let mut plans = Vec::with_capacity(window_plans.len() + o);
        plans.extend(carry.prev_plan.take());
        plans.extend(window_plans);
        let start = carry.conf_continued.take().unwrap_or_default();
        let (free, end) = module.configuration_free_moves_from(src, start);
        carry.conf_end = end;
        if !free.is_empty() {
            free_configurations(robot, moves, &mut plans, o, &free);
        }
        let fx = opts.effects;
        let thermal = robot.thermal().filter(|_| fx.thermal != 0.0);
        if fx.process != 0.0 || thermal.is_some() {
            carry.fall_back_speeds(moves, &mut plans[o..], file);
        }
        let directives = match directives {
            Some(d) => d,
            None => Directives::parse(src, file)?,
        };
        let timed = Self::put(robot, (moves, &plans, o), &directives, opts, carry).map_err(
            |(i, why)| {
                let Some(mv) = moves.get(i) else {
                    return Error::Internal("time line move out of range".into());
                };
                let what = match why {
                    Refusal::NeedsSpeed(what) => what,
                    Refusal::NoDuration => "thermal time line",
                };
                input_err(
                    src,
                    file,
                    mv.speed.span.start,
                    format!(
                        "speed `{}` cannot be resolved offline; the {what} needs the TCP speed",
                        mv.speed.text
                    ),
                )
            },
        )?;
        if let Some(totals) = carry.time_line.as_mut() {
            if let Some(t) = thermal {
                let segments: Vec<Segment> = timed.iter().map(Timed::segment).collect();
                totals.add(&segments, t.time_constant_s);
            }
        } else if let Some(ThermalInput::JointPowers(p)) = timed.last().map(|t| t.ctx.thermal) {
            carry.thermal_x = Some(p);
        }
        Ok(Window {
            plans,
            o,
            directives,
            timed,
        })
    }

    /// The moves on the time line, each on the view of its tool (resolved
    /// from its name alone: equal names, equal views), continuing the
    /// windows before: a window after the first continues the thermal time
    /// line from the state they left (the first window of a module read a
    /// window at a time starts from the state its first pass found); a
    /// module compensated whole starts it as asked.
    fn put<'m>(
        robot: &Robot,
        (moves, plans, o): (&[&'m Move], &[Planned], usize),
        directives: &Directives,
        opts: &RapidOptions,
        carry: &mut Carry,
    ) -> std::result::Result<Vec<Timed>, (usize, Refusal)> {
        let mut views = Views::default();
        let mut of = Vec::with_capacity(moves.len());
        for (mv, plan) in moves.iter().zip(&plans[o..]) {
            of.push(views.index(&mv.tool.text, || {
                robot.with_tool(plan.tool.tframe, plan.tool.load)
            }));
        }
        let stream = |plan: &Planned, mv: Option<(&'m Move, usize)>| -> StreamMove<'_> {
            let kind = mv.map(|(m, _)| m.kind);
            let key: &str = mv.map_or("", |(m, _)| &*m.tool.text);
            StreamMove {
                view: mv.and_then(|(_, v)| views.robots.get(v)).unwrap_or(robot),
                key,
                pose: plan.pose,
                via: plan.via.map(|v| v.translation.vector),
                q: plan.q,
                wobj: plan.wobj,
                feed: matches!(kind, Some(MoveKind::MoveL | MoveKind::MoveC)),
                linear: kind == Some(MoveKind::MoveL),
                v_tcp: plan.v_tcp,
                fallback: plan.speed_fallback,
                line: mv.map_or(0, |(m, _)| m.line),
                set: mv.map_or_else(CutSettings::default, |(m, _)| directives.at(m.line)),
            }
        };
        let mut stream_moves = Vec::with_capacity(plans.len());
        stream_moves.extend(plans[..o].iter().map(|p| stream(p, None)));
        stream_moves.extend(
            moves
                .iter()
                .zip(&plans[o..])
                .zip(of)
                .map(|((mv, p), v)| stream(p, Some((*mv, v)))),
        );
        let fx = opts.effects;
        let asked = Asked {
            process: fx.process != 0.0,
            thermal: fx.thermal != 0.0,
            start: opts.thermal_start,
            x0: carry.thermal_x,
            effective: carry.time_line.is_none(),
            power: opts.records,
            flanges: fx.compensates(),
            table: opts.force_table.as_deref(),
        };
        time_line::put(robot, &stream_moves, o, &asked, &mut carry.last_end)
    }

    /// Load key and state of move `i`, made when a walk reaches it (not
    /// kept for every move). Consecutive moves mostly share their tool and
    /// work object: `names` shares the lower-case names instead of
    /// allocating them per move.
    fn keyed<'a>(
        &'a self,
        moves: &[&'a Move],
        i: usize,
        names: &mut LastNames<'a>,
    ) -> Option<Keyed<'a>> {
        let mv: &Move = moves.get(i)?;
        let plan = self.plans.get(i + self.o)?;
        let timed = self.timed.get(i)?;
        let seg = timed.segment();
        let power = match timed.ctx.thermal {
            ThermalInput::JointPowers(p) => Some(p),
            _ => None,
        };
        let wrench = timed.ctx.wrench;
        let rpm = self.directives.at(mv.line).spindle_rpm;
        let wobj_text = mv.wobj.as_ref().map_or("wobj0", |w| &*w.text);
        let tool_text: &'a str = &mv.tool.text;
        let (tool, wobj) = match &*names {
            // The texts as the move before wrote them (a comparison of
            // bytes, the common case), or the same names in another case.
            Some(((ts, ws), (t, w)))
                if (*ts == tool_text && *ws == wobj_text)
                    || (t.eq_ignore_ascii_case(tool_text) && w.eq_ignore_ascii_case(wobj_text)) =>
            {
                (Rc::clone(t), Rc::clone(w))
            }
            _ => (
                Rc::from(tool_text.to_ascii_lowercase()),
                Rc::from(wobj_text.to_ascii_lowercase()),
            ),
        };
        *names = Some(((tool_text, wobj_text), (Rc::clone(&tool), Rc::clone(&wobj))));
        let key = LoadKey {
            tool,
            wobj,
            wrench: wrench.as_ref().map(wrench_bits),
            power: power.map(|p| p.map(f64::to_bits)),
            rpm: rpm.map(f64::to_bits),
        };
        let flange = timed.flange.as_ref();
        Some((
            mv,
            (plan, flange),
            seg,
            MoveState { wrench, power, rpm },
            key,
        ))
    }
}

/// The tool and work object texts of the move a walk met last, as
/// written, with their lower-case names ([`Window::keyed`]).
type LastNames<'a> = Option<((&'a str, &'a str), (Rc<str>, Rc<str>))>;

/// A move on the time line with what its rewriting needs: the move, its
/// plan and nominal end flange, its segment, state and load key.
type Keyed<'a> = (
    &'a Move,
    (&'a Planned, Option<&'a Isometry3<f64>>),
    Segment,
    MoveState,
    LoadKey,
);

impl<'m> Rewriter<'m> {
    /// A rewriter of a window that continues the windows before (`carry`).
    fn resume(
        text: ModuleText<'m>,
        robot: &'m Robot,
        opts: &RapidOptions,
        carry: &mut Carry,
    ) -> Self {
        Rewriter {
            module: text.module,
            src: text.src,
            file: text.file,
            robot,
            opts: opts.clone(),
            edits: EditList::new(),
            inserts: std::mem::take(&mut carry.inserts),
            taken: std::mem::take(&mut carry.taken),
            reserved: std::mem::take(&mut carry.reserved),
            views: Views::default(),
            phase: Phase::Collect(Vec::new()),
            owner: std::mem::take(&mut carry.owner),
            made: std::mem::take(&mut carry.made),
            derived_count: std::mem::take(&mut carry.derived_count),
            added: carry.added,
            state: MoveState::default(),
            last_tcp: carry.last_tcp,
            last_q: [0.0; 6],
            foreign_from: carry.scope.as_ref().map_or(usize::MAX, |s| s.from),
            last_annotated: None,
        }
    }

    /// The window's edits; what the next window continues from goes to
    /// `carry`.
    fn suspend(mut self, carry: &mut Carry) -> EditList {
        let edits = std::mem::take(&mut self.edits);
        carry.inserts = std::mem::take(&mut self.inserts);
        carry.taken = std::mem::take(&mut self.taken);
        carry.reserved = std::mem::take(&mut self.reserved);
        carry.owner = std::mem::take(&mut self.owner);
        carry.made = std::mem::take(&mut self.made);
        carry.derived_count = std::mem::take(&mut self.derived_count);
        carry.added = self.added;
        carry.last_tcp = self.last_tcp;
        edits
    }

    /// Walk 1 over the next moves from `*collected`: collects their
    /// compensation jobs, up to [`JOB_CHUNK`] of them; stops for good
    /// (`*collecting` false) at the first error. Gives the jobs and the
    /// index after the last move walked.
    fn collect<'a>(
        &mut self,
        (moves, resolved): (&[&'a Move], &[Resolved]),
        line: &'a Window,
        collected: &mut usize,
        collecting: &mut bool,
        names: &mut LastNames<'a>,
    ) -> (Vec<SolveJob>, usize) {
        // A chunk holds a job per move (two for a MoveC) and ends at the
        // move that reaches JOB_CHUNK: room for that many from the start.
        let room = moves.len().saturating_sub(*collected).min(JOB_CHUNK) + 1;
        self.phase = Phase::Collect(Vec::with_capacity(room));
        while *collecting && *collected < moves.len() {
            let Some((mv, plan, _, state, key)) = line.keyed(moves, *collected, names) else {
                *collected += 1;
                continue;
            };
            self.state = state;
            let res = resolved.get(*collected);
            let ok = self.walk((mv, res), &key, plan).is_ok();
            // The failing move goes with this chunk (its jobs before the
            // error are in it).
            *collected += 1;
            *collecting = ok;
            if matches!(&self.phase, Phase::Collect(j) if j.len() >= JOB_CHUNK) {
                break;
            }
        }
        let jobs = match std::mem::replace(&mut self.phase, Phase::Apply(Vec::new().into_iter())) {
            Phase::Collect(jobs) => jobs,
            Phase::Apply(_) => Vec::new(),
        };
        (jobs, *collected)
    }

    /// The walks, a chunk of moves at a time. Walk 1 collects the jobs of
    /// the next chunk; it stops at the first error, which walk 2 meets at
    /// the same move after reporting any failure of an earlier target, as a
    /// single walk would. The chunk's jobs are solved on the pool while walk
    /// 2 writes back the chunk before.
    fn walks(
        &mut self,
        (moves, resolved): (&[&Move], &[Resolved]),
        line: &Window,
        carry: &mut Carry,
    ) -> Result<()> {
        let fx = self.opts.effects;
        let n = moves.len();
        let mut collected = 0;
        let mut collecting = true;
        let mut names_1 = None;
        let mut names_2 = None;
        let (jobs, mut end) = self.collect(
            (moves, resolved),
            line,
            &mut collected,
            &mut collecting,
            &mut names_1,
        );
        let mut results = solve_jobs(&self.views.robots, &jobs, fx);
        drop(jobs);
        let mut walked = 0;
        loop {
            // The last chunk takes the moves after a collection that stopped.
            let last = end >= n || !collecting;
            if last {
                end = n;
            }
            let (next_jobs, next_end) = if last {
                (Vec::new(), n)
            } else {
                self.collect(
                    (moves, resolved),
                    line,
                    &mut collected,
                    &mut collecting,
                    &mut names_1,
                )
            };
            let mut next_results = Vec::new();
            self.phase = Phase::Apply(std::mem::take(&mut results).into_iter());
            let mut failed = None;
            rayon::in_place_scope(|s| {
                if !next_jobs.is_empty() {
                    // The solve shares the views (walk 2 makes none).
                    let (views, jobs, slot) = (
                        Arc::clone(&self.views.robots),
                        &next_jobs,
                        &mut next_results,
                    );
                    s.spawn(move |_| *slot = solve_jobs(&views, jobs, fx));
                }
                // Walk 2: write the chunk's results back in source order.
                for i in walked..end {
                    let Some((mv, plan, seg, state, key)) = line.keyed(moves, i, &mut names_2)
                    else {
                        continue;
                    };
                    self.state = state;
                    match self.walk((mv, resolved.get(i)), &key, plan) {
                        Ok(Some(dev))
                            if mv.kind == MoveKind::MoveAbsJ && !self.opts.joint_cartesian =>
                        {
                            self.record_reported(carry, mv, &seg, &state, &dev)
                        }
                        Ok(Some(dev)) => {
                            let via = plan.0.via.map(|v| v.translation.vector.into());
                            self.record(carry, (mv, via), &seg, &state, &dev)
                        }
                        Ok(None) => continue,
                        Err(e) => {
                            failed = Some(e);
                            break;
                        }
                    }
                }
            });
            if let Some(e) = failed {
                return Err(e);
            }
            walked = end;
            if last {
                break;
            }
            drop(next_jobs);
            results = next_results;
            end = next_end;
        }
        Ok(())
    }

    /// Keeps the record of a move reported and left as written (a
    /// `MoveAbsJ`): its report row, not counted as compensated, not
    /// annotated.
    fn record_reported(
        &mut self,
        carry: &mut Carry,
        mv: &Move,
        seg: &Segment,
        state: &MoveState,
        dev: &Breakdown,
    ) {
        if !self.opts.records {
            return;
        }
        carry
            .records
            .push(self.move_record((mv, None), seg, state, dev, None));
    }

    /// Counts a compensated move, annotates it and keeps its record.
    fn record(
        &mut self,
        carry: &mut Carry,
        (mv, via_mm): (&Move, Option<[f64; 3]>),
        seg: &Segment,
        state: &MoveState,
        dev: &Breakdown,
    ) {
        carry.moves += 1;
        carry.deviation.add(dev.total.pos_mm.norm(), mv.line);
        self.watch_resonance(carry, mv.line, state, dev);
        if self.opts.annotate && self.last_annotated != Some(mv.span.start) {
            self.last_annotated = Some(mv.span.start);
            let u = self.opts.uncertainty.as_deref();
            let q = self.last_q;
            push_annotation(&mut self.edits, self.src, &mv.span, |out| {
                write_dev_comment(out, dev);
                push_u(out, u.and_then(|u| target_u_mm(u, &q, &dev.total.pos_mm)));
            });
        }
        if !self.opts.records {
            return;
        }
        carry
            .records
            .push(self.move_record((mv, via_mm), seg, state, dev, Some(self.last_q)));
    }
}

impl Rewriter<'_> {
    /// The report row of a move: where it was programmed, its predicted
    /// deviation, its place on the time line and the programmed joints of
    /// its target (where the report's U is taken; `None` for a move left
    /// as written).
    fn move_record(
        &self,
        (mv, via_mm): (&Move, Option<[f64; 3]>),
        seg: &Segment,
        state: &MoveState,
        dev: &Breakdown,
        q: Option<[f64; 6]>,
    ) -> Row {
        let mut row = robot_row((mv.line, mv.name), self.last_tcp, via_mm, *dev, q);
        if let Some(r) = row.robot.as_mut() {
            r.wrench = state.wrench;
            r.duration_s = seg.duration_s;
            r.power_w = seg.power_w;
            r.thermal_power_w = state.power.unwrap_or([0.0; 6]);
        }
        row
    }

    /// Hands a cutting move at a spindle speed to the resonance check
    /// (with the dynamic effect on): its tooth passing and its vibration
    /// amplitude before the effect's gain.
    fn watch_resonance(&self, carry: &mut Carry, line: usize, state: &MoveState, dev: &Breakdown) {
        let gain = self.opts.effects.dynamic;
        let (Some(pf), Some(modal), true) = (
            self.robot.process_force(),
            self.robot.modal(),
            gain != 0.0 && state.wrench.is_some(),
        ) else {
            return;
        };
        let pf = pf.with_rpm(state.rpm);
        if let (Some(rpm), Some(f_hz)) = (pf.spindle_rpm, pf.excitation_hz()) {
            let amp = dev.vibration_mm.norm() / gain;
            carry
                .resonance
                .observe(modal, (rpm, pf.flutes, f_hz), amp, line);
        }
    }
}

impl Rewriter<'_> {
    /// Compensates (or collects the jobs of) one move: the circle point of
    /// a MoveC, then its target. The deviation is that of the target.
    fn walk(
        &mut self,
        (mv, res): (&Move, Option<&Resolved>),
        key: &LoadKey,
        (plan, nominal_flange): (&Planned, Option<&Isometry3<f64>>),
    ) -> Result<Option<Breakdown>> {
        if mv.kind == MoveKind::MoveAbsJ {
            self.joint(mv, key, &plan.tool)
        } else {
            let (Some(res), Some(u)) = (res, res.and_then(|r| r.target.as_ref())) else {
                return Err(Error::Internal("move target not resolved".into()));
            };
            if let (Some(via), Some(v)) = (&mv.via, &res.via) {
                self.cart(
                    mv,
                    (via, v, false),
                    key,
                    &plan.tool,
                    &plan.wobj,
                    Seed::default(),
                )?;
            }
            // Planning solved the target's joints with the same pose,
            // confdata and TCP (`ik_conf`, limits checked), and the nominal
            // flange at them (for the thermal power).
            let seed = Seed {
                q: plan.q,
                branch: plan.branch,
                nominal_flange: nominal_flange.copied(),
                conf: plan.free_conf,
            };
            self.cart(
                mv,
                (res.call_arg.as_ref().unwrap_or(&mv.target), u, res.looped),
                key,
                &plan.tool,
                &plan.wobj,
                seed,
            )
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::predict::EffectSet;

    /// Predefined speeds in either case, `vmax`, a declared speeddata and
    /// `\V:=` give the TCP speed; an unknown name gives none.
    #[test]
    fn tcp_speeds_of_predefined_declared_and_given_speeds() {
        let src = "MODULE M\n  CONST speeddata vFast := [750,500,5000,1000];\n  PROC main()\n    MoveL p,v200,z1,t;\n    MoveL p,V1000,z1,t;\n    MoveL p,VMAX,z1,t;\n    MoveL p,vFast,z1,t;\n    MoveL p,v100\\V:=333,z1,t;\n    MoveL p,v123,z1,t;\n    MoveL p,speed,z1,t;\n  ENDPROC\nENDMODULE\n";
        let module = parse_module(src, "m.mod").unwrap();
        let speeds: Vec<Option<f64>> = module.moves().map(|mv| tcp_speed(&module, mv)).collect();
        assert_eq!(
            speeds,
            [
                Some(200.0),
                Some(1000.0),
                Some(7000.0),
                Some(750.0),
                Some(333.0),
                None,
                None
            ]
        );
    }

    /// A module of a few chunks of jobs ([`JOB_CHUNK`]), MoveC (two jobs)
    /// among them so that chunks end at different moves: each move is
    /// written back with its own result, the same as when it is the only
    /// move of a module (no thermal time line, so moves are independent).
    #[test]
    fn chunked_write_back_gives_each_move_its_own_result() {
        let robot = crate::machine::robot::test_irb1600();
        let mut rnd = crate::machine::robot::test_sequence(11);
        let head = "MODULE M\n  PERS tooldata t1 := [TRUE,[[0,0,150],[1,0,0,0]],[2,[0,0,70],[1,0,0,0],0,0,0]];\n  PROC main()\n";
        let tail = "  ENDPROC\nENDMODULE\n";
        let n = 2 * JOB_CHUNK + 9;
        let mut lines = Vec::with_capacity(n);
        for i in 0..n {
            let mut p = || {
                format!(
                    "[[{:.1},{:.1},{:.1}],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]",
                    660.0 + 40.0 * rnd(),
                    60.0 + 40.0 * rnd(),
                    340.0 + 60.0 * rnd()
                )
            };
            lines.push(if i % 997 == 3 {
                format!("    MoveC {},{},v100,z1,t1;", p(), p())
            } else {
                format!("    MoveL {},v100,z1,t1;", p())
            });
        }
        let opts = RapidOptions {
            effects: EffectSet {
                thermal: 0.0,
                ..EffectSet::ALL
            },
            ..RapidOptions::for_robot(&robot)
        };
        let src = format!("{head}{}\n{tail}", lines.join("\n"));
        let whole = compensate_module(&src, "m.mod", &robot, &opts).expect("compensates");
        let out: Vec<&str> = whole.text.lines().collect();
        assert_eq!(whole.summary.moves, n);
        let first = head.lines().count();
        let mut checked = 0;
        for i in (0..n).filter(|i| {
            i % 613 == 0 || (JOB_CHUNK - 3..JOB_CHUNK + 3).contains(&(i % JOB_CHUNK)) || *i == n - 1
        }) {
            let single = format!("{head}{}\n{tail}", lines[i]);
            let alone = compensate_module(&single, "m.mod", &robot, &opts).expect("compensates");
            assert_eq!(
                out.get(first + i).copied(),
                alone.text.lines().nth(first),
                "move {i}"
            );
            assert_ne!(
                out.get(first + i).copied(),
                Some(lines[i].as_str()),
                "move {i} compensated"
            );
            checked += 1;
        }
        assert!(checked > 20);
    }

    /// A module whose targets the TX200 cannot take in their confdata (the
    /// samples' plate, from the world origin) is refused at its first
    /// target, whose message lists the configurations that reach it; that
    /// list is searched once, and every other refused target costs two
    /// seed searches (its plan and its compensation), not a listing.
    #[test]
    fn a_refused_module_lists_the_reaching_configurations_once() {
        use crate::machine::robot::ik::NUMERIC_SOLVES;
        use crate::machine::robot::numeric_ik::{LISTED_CFX, LISTINGS, STARTS};
        let text = include_str!("../../machines/staubli-tx200.yaml")
            .lines()
            .map(|l| {
                if l.starts_with("base:") {
                    "base: { x_mm: 0.0, y_mm: 0.0, z_mm: 0.0, quaternion: [1.0, 0.0, 0.0, 0.0] }"
                } else {
                    l
                }
            })
            .collect::<Vec<_>>()
            .join("\n");
        let robot = Robot::from_yaml_str(&text, "tx200.yaml").expect("valid");
        let n = 24;
        let moves: String = (0..n)
            .map(|i| {
                format!(
                    "    MoveL [[{},{},345],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],v100,z1,t1;\n",
                    700 + 5 * i,
                    50 + 3 * i
                )
            })
            .collect();
        let src = format!(
            "MODULE M\n  PERS tooldata t1 := [TRUE,[[0,0,182.5],[1,0,0,0]],[2.4,[0,0,85],[1,0,0,0],0,0,0]];\n  PROC main()\n{moves}  ENDPROC\nENDMODULE\n"
        );
        let opts = RapidOptions::for_robot(&robot);
        // One worker: the jobs run on the thread whose counters are read.
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .expect("pool");
        let (result, listings, solves) = pool.install(|| {
            let (l0, s0) = (
                LISTINGS.with(std::cell::Cell::get),
                NUMERIC_SOLVES.with(std::cell::Cell::get),
            );
            let r = compensate_module(&src, "m.mod", &robot, &opts);
            (
                r,
                LISTINGS.with(std::cell::Cell::get) - l0,
                NUMERIC_SOLVES.with(std::cell::Cell::get) - s0,
            )
        });
        let err = result.expect_err("refused").to_string();
        assert!(
            err.contains("m.mod:4:") && err.contains("(reachable configurations: ["),
            "{err}"
        );
        assert_eq!(listings, 1);
        assert!(
            solves <= n * 2 * STARTS + LISTED_CFX * STARTS,
            "{solves} numeric solves for {n} refused targets"
        );
    }

    /// Without move records (no report) the outcome is the same but for
    /// the records.
    #[test]
    fn move_records_change_nothing_else() {
        let robot = crate::machine::robot::test_irb1600();
        let src = include_str!("../../samples/milling.mod");
        let with = RapidOptions::for_robot(&robot);
        let without = RapidOptions {
            records: false,
            ..with.clone()
        };
        let a = compensate_module(src, "milling.mod", &robot, &with).expect("compensates");
        let b = compensate_module(src, "milling.mod", &robot, &without).expect("compensates");
        // A record per compensated move and per reported MoveAbsJ.
        let reported = a
            .summary
            .warnings
            .iter()
            .filter(|w| w.left.as_ref().is_some_and(|l| l.reason == JOINT_TARGET))
            .count();
        assert_eq!(a.records.len(), a.summary.moves + reported);
        assert!(a.summary.moves > 0 && b.records.is_empty());
        assert_eq!(
            Compensated {
                records: Vec::new(),
                ..a
            },
            b
        );
    }
}
