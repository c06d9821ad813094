//! What a move's target is before run time: the data flow of a RAPID
//! module's routines, as far as straight-line code decides it.
//!
//! Every statement that may change a data value is a *write*: an
//! assignment (`p := …;`, `buf{i} := …;`, `p.trans.z := …;`), an
//! assignment inside a compact `IF`, a name passed to an instruction
//! (`StrToVal sData, pRecv;`, `Incr nCount;`), a name passed to a
//! procedure of the program as the argument of an `INOUT`, `VAR` or `PERS`
//! parameter ([`calls`]) and the search point of a `Search…` instruction. A move's target is then, per move:
//!
//! * the declaration's value, when the data is a constant or never
//!   written (a routine-local one: not written before the move in its
//!   routine, nor in a loop around the move);
//! * the value of the last assignment before the move in the same
//!   routine, when that assignment is straight-line code: a whole-value
//!   assignment in no loop, in the same branch as the move (or in none),
//!   with no call between them to a routine of the module that writes the
//!   data. Its right side is evaluated where it stands (`pV := Offs(pV, 0,
//!   0, 100);` offsets the value `pV` had before it);
//! * otherwise unknown before run time, with a short reason
//!   ([`LOOP`], [`BRANCH`], [`OTHER_ROUTINE`], …): the move is left as
//!   written.
//!
//! Numbers (offsets, angles and indices given by name) follow the same
//! rules.

use std::collections::{HashMap, HashSet};

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

use super::resolve::{
    CartUse, Origin, conf_of, element_at, element_count, element_stem, input_err, robtarget_pose,
};
use super::{
    Assign, DataType, DataValue, Decl, Module, Move, RoutineKind, Scalar, Stmt, Storage, Target,
};
use crate::error::Result;

pub mod calls;

use calls::Procedures;

/// Why a move is left as written: its target is reassigned in a loop
/// (around the move, or before it).
pub const LOOP: &str = "target reassigned in a loop";
/// … in a branch (`IF`, `TEST`, an error handler) before the move.
pub const BRANCH: &str = "target reassigned in a branch";
/// … in another routine, or a routine called between the assignment and
/// the move.
pub const OTHER_ROUTINE: &str = "target reassigned in another routine";
/// … after the move in its routine (the routine may run again).
pub const AFTER: &str = "target reassigned after the move";
/// … by a component (`p.trans.z := 10;`) or an array element.
pub const PART: &str = "target reassigned in part";
/// A routine parameter: the caller's value.
pub const PARAMETER: &str = "routine parameter";
/// A function call or another expression.
pub const RUN_TIME: &str = "run-time target";
/// The robot's current position.
pub const CROBT: &str = "CRobT";
/// An offset or angle of `Offs`/`RelTool` known at run time only.
pub const RUN_TIME_OFFSET: &str = "run-time offset";
/// A robtarget whose value is an expression (`[[0,0,safeHeight],…]`): not
/// evaluated.
pub const EXPRESSION_VALUE: &str = "robtarget value is an expression";
/// An array index known at run time only (a `FOR` variable).
pub const RUN_TIME_INDEX: &str = "indexed by a run-time value";

/// Deepest chain of assignments and nested `Offs`/`RelTool` followed.
const MAX_DEPTH: usize = 32;

/// A statement of a routine: routine index and statement index in its
/// body.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct At {
    /// Routine (index into [`Module::procs`]).
    pub proc: usize,
    /// Statement (index into [`super::Proc::body`]).
    pub stmt: usize,
}

/// A move left as written: why, and the declarations its target reads
/// (they keep their values as written, so that the move means what it
/// meant).
#[derive(Debug, Clone, PartialEq)]
pub struct Left {
    /// The reason, short ([`LOOP`], [`CROBT`], …).
    pub reason: String,
    /// Module declarations read on the way, as target origins.
    pub(crate) reads: Vec<Origin>,
}

/// How a write changes its data.
#[derive(Debug, Clone, PartialEq)]
enum Kind {
    /// A whole-value assignment (the statement is a [`Stmt::Assign`]).
    Whole,
    /// An element or a component.
    Part,
    /// Inside a compact `IF`.
    Conditional,
    /// Passed to an instruction (its name).
    Argument(String),
}

/// One write of a data name.
#[derive(Debug, Clone)]
struct Write {
    at: At,
    kind: Kind,
}

/// The control shape of one routine body.
#[derive(Debug, Default)]
struct Shape {
    /// Parameter names, lower case.
    params: Vec<String>,
    /// Block depth of each statement (`IF`, `FOR`, `WHILE`, `TEST` open
    /// around it; an error handler counts as one).
    depth: Vec<u32>,
    /// Statement ranges `[start, end]` of the `FOR`/`WHILE` loops.
    loops: Vec<(usize, usize)>,
    /// First statement of an error, backward or undo handler.
    handler: Option<usize>,
    /// The routine holds a label (a `GOTO` may loop).
    labels: bool,
    /// Statements that call a routine: (statement, callee lower case;
    /// `%` for a late-bound call).
    calls: Vec<(usize, String)>,
    /// Statements that declare routine data, in order.
    locals: Vec<usize>,
}

/// The data flow of a module (or of the window of one).
pub struct Flow<'m> {
    module: &'m Module,
    shapes: Vec<Shape>,
    /// Writes per data name (lower case), in routine and statement order.
    writes: HashMap<String, Vec<Write>>,
    /// The module-level data names looked up so far (lower case; moves
    /// may be resolved on several threads).
    read: std::sync::Mutex<Vec<String>>,
    /// The procedures whose parameters are known (the module's own, then
    /// those of the other modules of the program).
    procedures: Procedures,
}

/// Where a data value at a statement comes from.
enum Source<'m> {
    /// The module declaration (index) holds it.
    Module(usize, &'m Decl),
    /// The routine-local declaration holds it.
    Local(&'m Decl),
    /// The assignment at `At` gives it.
    Assigned(&'m Assign, At),
    /// Known at run time only.
    RunTime(String),
}

impl<'m> Flow<'m> {
    /// The flow of `module`, parsed from `src`.
    pub fn of(module: &'m Module, src: &str) -> Self {
        Self::of_program(module, src, &Procedures::default())
    }

    /// The flow of `module`, parsed from `src`, in a program whose other
    /// modules declare the procedures `elsewhere`.
    pub fn of_program(module: &'m Module, src: &str, elsewhere: &Procedures) -> Self {
        let mut procedures = Procedures::of_module(module, src, true);
        procedures.extend(elsewhere);
        let mut writes: HashMap<String, Vec<Write>> = HashMap::new();
        let mut shapes = Vec::with_capacity(module.procs.len());
        // Functions that may write their arguments: `StrToVal` and the
        // module's functions with `INOUT`, `VAR` or `PERS` parameters.
        let mut writers: Vec<&str> = vec!["StrToVal"];
        for p in &module.procs {
            let params = p.params.as_ref().and_then(|s| src.get(s.clone()));
            if p.kind == RoutineKind::Func
                && params.is_some_and(|t| {
                    t.split(|c: char| !c.is_ascii_alphanumeric()).any(|w| {
                        ["INOUT", "VAR", "PERS"]
                            .iter()
                            .any(|k| k.eq_ignore_ascii_case(w))
                    })
                })
            {
                writers.push(&p.name);
            }
        }
        for (p, proc) in module.procs.iter().enumerate() {
            let mut shape = Shape {
                params: proc
                    .params
                    .as_ref()
                    .and_then(|s| src.get(s.clone()))
                    .map(param_names)
                    .unwrap_or_default(),
                ..Shape::default()
            };
            shape.walk(&proc.body);
            for (k, s) in proc.body.iter().enumerate() {
                if matches!(s, Stmt::Decl(_)) {
                    shape.locals.push(k);
                }
                let at = At { proc: p, stmt: k };
                let mut add = |name: &str, kind: Kind| {
                    writes
                        .entry(name.to_ascii_lowercase())
                        .or_default()
                        .push(Write { at, kind });
                };
                if matches!(s, Stmt::Assign(_) | Stmt::Opaque { .. }) {
                    let text = src.get(s.span()).unwrap_or("");
                    for (name, func) in call_writes(text, &writers) {
                        add(name, Kind::Argument(func.to_string()));
                    }
                }
                match s {
                    Stmt::Assign(a) => {
                        let kind = if a.component || a.index.is_some() {
                            Kind::Part
                        } else {
                            Kind::Whole
                        };
                        add(&a.name, kind);
                    }
                    Stmt::Opaque { span, .. } => {
                        let text = src.get(span.clone()).unwrap_or("");
                        let (first, written) = opaque_writes(text);
                        // A known procedure changes its by-reference
                        // arguments only.
                        let by_ref = procedures.written(first, text);
                        for (name, assigned) in written {
                            if !assigned
                                && by_ref.as_ref().is_some_and(|b| {
                                    !b.iter().any(|w| w.eq_ignore_ascii_case(name))
                                })
                            {
                                continue;
                            }
                            let kind = match (assigned, first.eq_ignore_ascii_case("IF")) {
                                (true, false) => Kind::Whole,
                                (true, true) => Kind::Conditional,
                                (false, _) => Kind::Argument(first.to_string()),
                            };
                            add(name, kind);
                        }
                        if !first.eq_ignore_ascii_case("IF") && !first.is_empty() {
                            shape.calls.push((k, first.to_ascii_lowercase()));
                        }
                    }
                    Stmt::Move(m) if m.name.starts_with("Search") => {
                        let head = src.get(m.span.start..m.target.span().start).unwrap_or("");
                        for (name, _) in opaque_writes(head).1 {
                            add(name, Kind::Argument(m.name.to_string()));
                        }
                    }
                    _ => {}
                }
            }
            shapes.push(shape);
        }
        Flow {
            module,
            shapes,
            writes,
            read: std::sync::Mutex::new(Vec::new()),
            procedures,
        }
    }

    /// The module-level robtargets, jointtargets and nums that are not
    /// constants and that a routine writes, lower case (a window of a
    /// module cannot see the other routines).
    pub fn module_data_written(&self) -> Vec<String> {
        let mut out: Vec<String> = self
            .writes
            .iter()
            .filter(|(name, ws)| {
                ws.iter().any(|w| {
                    !self.is_param(w.at.proc, name)
                        && self.local_decl(w.at.proc, name).is_none()
                        && self
                            .module_decl(name)
                            .is_some_and(|(_, d)| d.storage != Storage::Const && resolves_moves(d))
                })
            })
            .map(|(name, _)| name.clone())
            .collect();
        out.sort_unstable();
        out
    }

    /// Every data name a statement of the module writes, lower case.
    pub fn written_names(&self) -> Vec<String> {
        let mut v: Vec<String> = self.writes.keys().cloned().collect();
        v.sort_unstable();
        v
    }

    /// The flow with the data names `names` (lower case) written by
    /// routines outside the module (another module of the program).
    pub fn with_writes_elsewhere(mut self, names: &[String]) -> Self {
        for n in names {
            self.writes.entry(n.clone()).or_default().push(Write {
                at: At {
                    proc: usize::MAX,
                    stmt: 0,
                },
                kind: Kind::Whole,
            });
        }
        self
    }

    /// The module-level data names the moves resolved so far read, lower
    /// case, sorted.
    pub fn module_data_read(&self) -> Vec<String> {
        let mut v = self
            .read
            .lock()
            .map_or_else(|p| p.into_inner().clone(), |r| r.clone());
        v.sort_unstable();
        v
    }

    /// The module robtargets and jointtargets (as target origins) that
    /// statements other than moves of the table may move to, read as
    /// written: an instruction not in the table (`PaintL p10, …`), or a
    /// call that passes them to a procedure whose body names the parameter
    /// (its moves to a parameter are left as written). A procedure whose
    /// parameters are not known may move to every name passed to it.
    /// `src` is the text the module was parsed from.
    pub(crate) fn read_by_other_statements(&self, src: &str) -> Vec<Origin> {
        // The names read, by routine; then one pass over the declarations.
        let mut read: Vec<(usize, &str)> = Vec::new();
        let mut names: HashSet<String> = HashSet::new();
        for (p, proc) in self.module.procs.iter().enumerate() {
            for s in &proc.body {
                let Stmt::Opaque { span, .. } = s else {
                    continue;
                };
                let text = src.get(span.clone()).unwrap_or("");
                let first = opaque_writes(text).0;
                let words: Vec<&str> = match self.procedures.named_by_body(first, text) {
                    Some(args) => args.into_iter().flat_map(super::words).collect(),
                    None => super::words(text).collect(),
                };
                for w in words {
                    read.push((p, w));
                    names.insert(w.to_ascii_lowercase());
                }
            }
        }
        if read.is_empty() {
            return Vec::new();
        }
        let mut decls: HashMap<String, usize> = HashMap::new();
        let mut lower = String::new();
        for (i, d) in self.module.decls.iter().enumerate() {
            lower.clear();
            lower.extend(d.name.chars().map(|c| c.to_ascii_lowercase()));
            if names.contains(&lower) && !decls.contains_key(&lower) {
                decls.insert(lower.clone(), i);
            }
        }
        let mut out = Vec::new();
        let mut seen = HashSet::new();
        // Names of each routine's parameters and local declarations.
        let mut own: HashMap<usize, HashSet<String>> = HashMap::new();
        for (p, w) in read {
            let w_lower = w.to_ascii_lowercase();
            let Some(&decl) = decls.get(&w_lower) else {
                continue;
            };
            let Some(d) = self.module.decls.get(decl) else {
                continue;
            };
            if !matches!(d.data_type, DataType::RobTarget | DataType::JointTarget) {
                continue;
            }
            let own = own.entry(p).or_insert_with(|| self.own_names(p));
            if own.contains(&w_lower) {
                continue;
            }
            let origins = match d.value {
                Some(DataValue::Array { .. }) => self.all_elements(w, p),
                _ => vec![Origin::Decl { decl, elem: None }],
            };
            out.extend(origins.into_iter().filter(|o| seen.insert(*o)));
        }
        out
    }

    /// The parameter and local data names of routine `proc`, lower case.
    fn own_names(&self, proc: usize) -> HashSet<String> {
        let mut out: HashSet<String> = self
            .shapes
            .get(proc)
            .map(|s| s.params.iter().cloned().collect())
            .unwrap_or_default();
        if let Some(p) = self.module.procs.get(proc) {
            out.extend(p.body.iter().filter_map(|s| match s {
                Stmt::Decl(d) => Some(d.name.to_ascii_lowercase()),
                _ => None,
            }));
        }
        out
    }

    /// The motion instructions of the module's routines with their
    /// places, in source order, except those of routines holding an editor
    /// placeholder (as [`Module::moves`]).
    pub fn moves(&self) -> impl Iterator<Item = (At, &'m Move)> + '_ {
        self.module
            .procs
            .iter()
            .enumerate()
            .filter(|(_, p)| !p.placeholder)
            .flat_map(|(p, proc)| {
                proc.body
                    .iter()
                    .enumerate()
                    .filter_map(move |(k, s)| match s {
                        Stmt::Move(m) => Some((At { proc: p, stmt: k }, m.as_ref())),
                        _ => None,
                    })
            })
    }

    fn is_param(&self, proc: usize, lower: &str) -> bool {
        self.shapes
            .get(proc)
            .is_some_and(|s| s.params.iter().any(|p| p == lower))
    }

    fn local_decl(&self, proc: usize, name: &str) -> Option<&'m Decl> {
        let body = &self.module.procs.get(proc)?.body;
        self.shapes
            .get(proc)?
            .locals
            .iter()
            .find_map(|&k| match body.get(k) {
                Some(Stmt::Decl(d)) if d.name.eq_ignore_ascii_case(name) => Some(d.as_ref()),
                _ => None,
            })
    }

    fn module_decl(&self, name: &str) -> Option<(usize, &'m Decl)> {
        super::resolve::lookup(self.module, name)
    }

    /// Where the value of `name` at statement `at` comes from; `None` when
    /// the name is declared nowhere (nor a parameter).
    fn source(&self, name: &str, at: At) -> Option<Source<'m>> {
        let lower = name.to_ascii_lowercase();
        if self.is_param(at.proc, &lower) {
            return Some(Source::RunTime(PARAMETER.into()));
        }
        let local = self.local_decl(at.proc, name);
        let (declared, decl) = match local {
            Some(d) => (Source::Local(d), d),
            None => {
                let (i, d) = self.module_decl(name)?;
                let mut read = self.read.lock().unwrap_or_else(|p| p.into_inner());
                if !read.contains(&lower) {
                    read.push(lower.clone());
                }
                (Source::Module(i, d), d)
            }
        };
        let all = self.writes.get(&lower).map_or(&[][..], Vec::as_slice);
        let writes: Vec<&Write> = all
            .iter()
            .filter(|w| local.is_none() || w.at.proc == at.proc)
            .collect();
        if decl.storage == Storage::Const || writes.is_empty() {
            return Some(declared);
        }
        Some(self.written(&lower, at, &writes, declared, local.is_some()))
    }

    /// [`Self::source`] of a data name that is written somewhere.
    fn written(
        &self,
        lower: &str,
        at: At,
        writes: &[&Write],
        declared: Source<'m>,
        local: bool,
    ) -> Source<'m> {
        let run_time = |r: &str| Source::RunTime(r.to_string());
        let Some(shape) = self.shapes.get(at.proc) else {
            return run_time(RUN_TIME);
        };
        let here: Vec<&Write> = writes
            .iter()
            .copied()
            .filter(|w| w.at.proc == at.proc)
            .collect();
        let trap = writes.iter().any(|w| {
            self.module
                .procs
                .get(w.at.proc)
                .is_some_and(|p| p.kind == RoutineKind::Trap)
        });
        if trap {
            return run_time(OTHER_ROUTINE);
        }
        if shape.labels && !here.is_empty() {
            return run_time(LOOP);
        }
        for &(s, e) in &shape.loops {
            if s < at.stmt && at.stmt <= e {
                if here.iter().any(|w| (s..=e).contains(&w.at.stmt)) {
                    return run_time(LOOP);
                }
                if !local && self.calls_writer(shape, lower, s, e) {
                    return run_time(OTHER_ROUTINE);
                }
            }
        }
        let in_handler = shape.handler.is_some_and(|h| at.stmt >= h);
        let Some(last) = here.iter().rev().find(|w| w.at.stmt < at.stmt) else {
            if local {
                return declared;
            }
            if in_handler {
                return run_time(BRANCH);
            }
            return run_time(if here.is_empty() {
                OTHER_ROUTINE
            } else {
                AFTER
            });
        };
        let w = last.at.stmt;
        if shape.loops.iter().any(|&(s, e)| (s..=e).contains(&w)) {
            return run_time(LOOP);
        }
        let depth_w = shape.depth.get(w).copied().unwrap_or(0);
        let same_branch =
            (w + 1..=at.stmt).all(|k| shape.depth.get(k).copied().unwrap_or(0) >= depth_w);
        if !same_branch || (in_handler && shape.handler.is_some_and(|h| w < h)) {
            return run_time(BRANCH);
        }
        if !local && self.calls_writer(shape, lower, w, at.stmt) {
            return run_time(OTHER_ROUTINE);
        }
        match &last.kind {
            Kind::Whole => match self.assignment(last.at) {
                Some(a) => Source::Assigned(a, last.at),
                None => run_time(RUN_TIME),
            },
            Kind::Part => run_time(PART),
            Kind::Conditional => run_time(BRANCH),
            Kind::Argument(instr) => Source::RunTime(format!("set by {instr}")),
        }
    }

    fn assignment(&self, at: At) -> Option<&'m Assign> {
        match self.module.procs.get(at.proc)?.body.get(at.stmt)? {
            Stmt::Assign(a) => Some(a),
            _ => None,
        }
    }

    /// True when a statement in `from..=to` of the routine calls a routine
    /// of the module that writes `lower` (or a routine named at run time).
    fn calls_writer(&self, shape: &Shape, lower: &str, from: usize, to: usize) -> bool {
        let Some(ws) = self.writes.get(lower) else {
            return false;
        };
        shape
            .calls
            .iter()
            .filter(|(k, _)| (from..=to).contains(k))
            .any(|(_, callee)| {
                callee == "%"
                    || ws.iter().any(|w| {
                        self.module
                            .procs
                            .get(w.at.proc)
                            .is_some_and(|p| p.name.eq_ignore_ascii_case(callee))
                    })
            })
    }

    /// The value of a number given by name (or `-name`) at `at`, when it is
    /// known before run time; a numeric literal is its value.
    fn number(&self, text: &str, at: At, depth: usize) -> Option<f64> {
        if let Some(v) = super::parser::parse_number(text) {
            return Some(v);
        }
        let t = text.trim();
        let (sign, name) = match t.strip_prefix('-') {
            Some(r) => (-1.0, r.trim_start()),
            None => (1.0, t.strip_prefix('+').unwrap_or(t).trim_start()),
        };
        let ident = name.bytes().next().is_some_and(|b| b.is_ascii_alphabetic())
            && name.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_');
        if !ident || depth > MAX_DEPTH {
            return None;
        }
        let value = match self.source(name, at)? {
            Source::Module(_, d) | Source::Local(d) => match (&d.data_type, &d.value) {
                (DataType::Num, Some(DataValue::Num(n))) if d.dims.is_empty() => Some(n.value),
                _ => None,
            },
            Source::Assigned(a, at2) => match &a.value {
                Target::Other { text, .. } => self.number(text, at2, depth + 1),
                Target::Named {
                    name, index: None, ..
                } => self.number(name, at2, depth + 1),
                _ => None,
            },
            Source::RunTime(_) => None,
        };
        value.map(|v| sign * v)
    }

    /// The robtarget a move's target (or circle point) `target` at `at`
    /// goes to, or why it is left as written. Errors: what is wrong in
    /// the module whatever the run (an undeclared name, a wrong type, an
    /// index out of range).
    pub(crate) fn cart(
        &self,
        src: &str,
        file: &str,
        at: At,
        target: &'m Target,
    ) -> Result<std::result::Result<CartUse<'m>, Left>> {
        let mut reads = Vec::new();
        match self.cart_at(src, file, at, target, &mut reads, 0)? {
            Ok(u) => Ok(Ok(u)),
            Err(reason) => Ok(Err(Left { reason, reads })),
        }
    }

    /// Why a `MoveAbsJ` target is left as written, if it is: a jointtarget
    /// that is written, a parameter, or an expression.
    pub(crate) fn joint_left(&self, at: At, target: &Target) -> Option<Left> {
        let left = |r: &str| {
            Some(Left {
                reason: r.to_string(),
                reads: Vec::new(),
            })
        };
        match target {
            Target::Named {
                name,
                index: Some(ix),
                ..
            } if ix.literals().is_none() => Some(Left {
                reason: RUN_TIME_INDEX.to_string(),
                reads: self.all_elements(name, at.proc),
            }),
            Target::Named { name, .. } => match self.source(name, at)? {
                Source::Module(..) => None,
                Source::Local(_) => left("routine-local jointtarget"),
                Source::Assigned(..) => left("jointtarget assigned at run time"),
                Source::RunTime(r) => left(&r),
            },
            Target::Other { text, .. } if is_call(text, "CJointT") => left("CJointT"),
            Target::Other { .. } => left(RUN_TIME),
            _ => None,
        }
    }

    /// The targets a move to `holes{k}` goes to in a `FOR k FROM a TO b
    /// [STEP c] DO` loop with bounds known before run time, one per
    /// element the loop reaches in order, when they can be compensated in
    /// place: `holes` is a module array that no statement writes and no
    /// other statement names, the loop is the only one around the move and
    /// its routine holds no label, and every element reached exists.
    /// `None` otherwise (the move is left as written).
    pub(crate) fn loop_elements(
        &self,
        src: &str,
        file: &str,
        at: At,
        target: &'m Target,
    ) -> Option<Vec<CartUse<'m>>> {
        let Target::Named {
            name,
            index: Some(ix),
            span,
        } = target
        else {
            return None;
        };
        let parts = ix.parts();
        let [var] = parts.as_slice() else {
            return None;
        };
        let shape = self.shapes.get(at.proc)?;
        let around: Vec<&(usize, usize)> = shape
            .loops
            .iter()
            .filter(|&&(s, e)| s < at.stmt && at.stmt <= e)
            .collect();
        let (&[&(start, _)], false) = (around.as_slice(), shape.labels) else {
            return None;
        };
        let body = &self.module.procs.get(at.proc)?.body;
        let Stmt::Control {
            keyword,
            span: head,
            ..
        } = body.get(start)?
        else {
            return None;
        };
        if keyword != "FOR" {
            return None;
        }
        let (v, from, to, step) = for_bounds(src.get(head.clone())?)?;
        if !v.eq_ignore_ascii_case(var) {
            return None;
        }
        let num = |t: &str| {
            let x = self.number(
                t,
                At {
                    proc: at.proc,
                    stmt: start,
                },
                0,
            )?;
            (x.fract() == 0.0 && x.abs() < 1e6).then_some(x as i64)
        };
        let (from, to) = (num(from)?, num(to)?);
        let step = match step {
            Some(t) => num(t)?,
            None => 1,
        };
        let Some(Source::Module(di, d)) = self.source(name, at) else {
            return None;
        };
        if d.dims.len() > 1 || self.named_elsewhere(src, name) {
            return None;
        }
        let count = if step > 0 && from <= to {
            (to - from) / step + 1
        } else if step < 0 && from >= to {
            (from - to) / -step + 1
        } else {
            0
        };
        if !(1..=10_000).contains(&count) {
            return None;
        }
        let mut out = Vec::with_capacity(count as usize);
        for i in 0..count {
            let k = usize::try_from(from + i * step).ok().filter(|&k| k >= 1)?;
            let (v, elem) = element(src, file, span.start, d, Some(&[k])).ok()?;
            let DataValue::RobTarget(rt) = v else {
                return None;
            };
            out.push(CartUse {
                rt,
                origin: Origin::Decl { decl: di, elem },
                stem: element_stem(&d.name, &[k]),
                derived: false,
                derived_key: String::new(),
                pose_obj: robtarget_pose(rt)?,
                conf: conf_of(rt)?,
            });
        }
        Some(out)
    }

    /// The targets a move to `param`, a parameter of its procedure passed
    /// by value, goes to: the argument of each call of the procedure in
    /// the module, in routine order, that is a module robtarget known
    /// before run time, with the span of the argument in the call (where
    /// a compensated copy is passed). `None` when the parameter is named
    /// by another statement of the procedure, or no call gives a target.
    pub(crate) fn call_uses(
        &self,
        src: &str,
        file: &str,
        at: At,
        target: &'m Target,
    ) -> Option<Vec<(CartUse<'m>, super::Span)>> {
        let Target::Named {
            name: param,
            index: None,
            ..
        } = target
        else {
            return None;
        };
        let proc = self.module.procs.get(at.proc)?;
        if proc.kind != RoutineKind::Proc {
            return None;
        }
        let lower = param.to_ascii_lowercase();
        let k = self.procedures.by_value_position(&proc.name, &lower)?;
        let named = proc
            .body
            .iter()
            .filter(|s| text_names(src.get(s.span()).unwrap_or(""), param))
            .count();
        if named != 1 {
            return None;
        }
        let base = src.as_ptr() as usize;
        let mut out = Vec::new();
        for (pi, p) in self.module.procs.iter().enumerate() {
            for (si, s) in p.body.iter().enumerate() {
                let Stmt::Opaque { span, .. } = s else {
                    continue;
                };
                let text = src.get(span.clone()).unwrap_or("");
                if !opaque_writes(text).0.eq_ignore_ascii_case(&proc.name) {
                    continue;
                }
                let Some(arg) = self
                    .procedures
                    .positional(&proc.name, text)
                    .and_then(|a| a.get(k).copied())
                else {
                    continue;
                };
                let here = At { proc: pi, stmt: si };
                let Some(Source::Module(di, d)) = self.source(arg, here) else {
                    continue;
                };
                let Ok((DataValue::RobTarget(rt), None)) = element(src, file, span.start, d, None)
                else {
                    continue;
                };
                let (Some(pose_obj), Some(conf)) = (robtarget_pose(rt), conf_of(rt)) else {
                    continue;
                };
                let from = arg.as_ptr() as usize - base;
                out.push((
                    CartUse {
                        rt,
                        origin: Origin::Decl {
                            decl: di,
                            elem: None,
                        },
                        stem: d.name.clone(),
                        derived: false,
                        derived_key: String::new(),
                        pose_obj,
                        conf,
                    },
                    from..from + arg.len(),
                ));
            }
        }
        (!out.is_empty()).then_some(out)
    }

    /// True when the word `name` appears in more than one statement of the
    /// module's routines (outside strings and comments, as a whole word).
    fn named_elsewhere(&self, src: &str, name: &str) -> bool {
        let mut seen = 0;
        for p in &self.module.procs {
            for s in &p.body {
                let text = src.get(s.span()).unwrap_or("");
                if text_names(text, name) {
                    seen += 1;
                    if seen > 1 {
                        return true;
                    }
                }
            }
        }
        false
    }

    /// Why a move is left as written because its tool or work object is
    /// known at run time only, if it is: a `tooldata`/`wobjdata` that a
    /// statement of the program writes (`tActual := tGripper;`), a
    /// parameter, a routine-local one, or one declared without a literal
    /// value. The reason names the data (`run-time tool `tActual``).
    pub(crate) fn load_left(&self, at: At, mv: &Move) -> Option<Left> {
        let wobj = mv.wobj.as_ref().map(|w| &*w.text);
        let pairs = [
            ("tool", Some(&*mv.tool.text), "tool0"),
            ("work object", wobj, "wobj0"),
        ];
        for (what, name, none) in pairs {
            let Some(name) = name.map(str::trim) else {
                continue;
            };
            if name.eq_ignore_ascii_case(none) {
                continue;
            }
            let literal = |d: &Decl| {
                matches!(
                    d.value,
                    Some(DataValue::ToolData(_)) | Some(DataValue::WobjData(_))
                )
            };
            // Lower case without an allocation per move (a RAPID name has
            // at most 32 characters; a longer one is declared nowhere).
            let mut buf = [0u8; 64];
            let Some(b) = buf.get_mut(..name.len()) else {
                continue;
            };
            b.copy_from_slice(name.as_bytes());
            b.make_ascii_lowercase();
            let Ok(lower) = std::str::from_utf8(b) else {
                continue;
            };
            // Assigned (whole, in part or in a compact IF) anywhere in the
            // program; a tool passed to an instruction is read, not written.
            let assigned = self
                .writes
                .get(lower)
                .is_some_and(|ws| ws.iter().any(|w| !matches!(w.kind, Kind::Argument(_))));
            let run_time =
                if self.is_param(at.proc, lower) || self.local_decl(at.proc, name).is_some() {
                    true
                } else {
                    match self.module_decl(name) {
                        // Undeclared: the move's resolution says so.
                        None => false,
                        Some((_, d)) => assigned || !literal(d),
                    }
                };
            if run_time {
                return Some(Left {
                    reason: format!("run-time {what} `{name}`"),
                    reads: Vec::new(),
                });
            }
        }
        None
    }

    #[allow(clippy::too_many_arguments)]
    fn cart_at(
        &self,
        src: &str,
        file: &str,
        at: At,
        target: &'m Target,
        reads: &mut Vec<Origin>,
        depth: usize,
    ) -> Result<std::result::Result<CartUse<'m>, String>> {
        let here = target.span().start;
        let bad = |what: &str| input_err(src, file, here, what.to_string());
        if depth > MAX_DEPTH {
            return Ok(Err("target computed through too many assignments".into()));
        }
        match target {
            Target::Inline(rt) => Ok(Ok(CartUse {
                rt,
                origin: Origin::Inline,
                stem: String::new(),
                derived: false,
                derived_key: String::new(),
                pose_obj: robtarget_pose(rt).ok_or_else(|| bad("zero quaternion"))?,
                conf: conf_of(rt).ok_or_else(|| bad("confdata must be integers"))?,
            })),
            Target::Named { name, index, .. } => {
                self.named(src, file, at, target, (name, index.as_ref()), reads, depth)
            }
            Target::Offs { base, offsets, .. } => {
                let b = match self.cart_at(src, file, at, base, reads, depth + 1)? {
                    Ok(b) => b,
                    Err(r) => return Ok(Err(r)),
                };
                let Some(d) = self.offsets(offsets, at) else {
                    return Ok(Err(RUN_TIME_OFFSET.into()));
                };
                let pose_obj = Isometry3::from_parts(
                    Translation3::from(b.pose_obj.translation.vector + Vector3::from(d)),
                    b.pose_obj.rotation,
                );
                let derived_key = if b.derived {
                    pose_key(&pose_obj)
                } else {
                    format!("offs {d:?}")
                };
                Ok(Ok(CartUse {
                    derived: true,
                    derived_key,
                    pose_obj,
                    ..b
                }))
            }
            Target::RelTool {
                base,
                offsets,
                rx,
                ry,
                rz,
                ..
            } => {
                let b = match self.cart_at(src, file, at, base, reads, depth + 1)? {
                    Ok(b) => b,
                    Err(r) => return Ok(Err(r)),
                };
                let angle = |s: &Option<Scalar>| match s {
                    Some(s) => s
                        .value
                        .or_else(|| self.number(&s.text, at, 0))
                        .map(f64::to_radians),
                    None => Some(0.0),
                };
                let (Some(d), Some(ax), Some(ay), Some(az)) =
                    (self.offsets(offsets, at), angle(rx), angle(ry), angle(rz))
                else {
                    return Ok(Err(RUN_TIME_OFFSET.into()));
                };
                // Translate along the tool axes, then rotate about the tool
                // x, the new y and the new z axis (intrinsic x-y-z).
                let rot = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), ax)
                    * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), ay)
                    * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), az);
                let pose_obj =
                    b.pose_obj * Isometry3::from_parts(Translation3::new(d[0], d[1], d[2]), rot);
                let derived_key = if b.derived {
                    pose_key(&pose_obj)
                } else {
                    format!("reltool {d:?} {ax} {ay} {az}")
                };
                Ok(Ok(CartUse {
                    derived: true,
                    derived_key,
                    pose_obj,
                    ..b
                }))
            }
            Target::InlineJoint(_) => Err(bad("a jointtarget needs MoveAbsJ")),
            Target::Other { text, .. } if is_call(text, "CRobT") => Ok(Err(CROBT.into())),
            Target::Other { .. } => Ok(Err(RUN_TIME.into())),
        }
    }

    /// The three offsets of `Offs`/`RelTool` at `at`, when known.
    fn offsets(&self, offsets: &[Scalar; 3], at: At) -> Option<[f64; 3]> {
        let v = |s: &Scalar| s.value.or_else(|| self.number(&s.text, at, 0));
        Some([v(&offsets[0])?, v(&offsets[1])?, v(&offsets[2])?])
    }

    /// A named target (`p`, `holes{3}`, `holes{k}`) at `at`.
    #[allow(clippy::too_many_arguments)]
    fn named(
        &self,
        src: &str,
        file: &str,
        at: At,
        target: &'m Target,
        (name, index): (&'m str, Option<&'m super::Index>),
        reads: &mut Vec<Origin>,
        depth: usize,
    ) -> Result<std::result::Result<CartUse<'m>, String>> {
        let here = target.span().start;
        let k = match index {
            None => None,
            Some(ix) => match self.indices(src, file, at, name, ix)? {
                Some(ks) => Some(ks),
                None => {
                    // Any element may be the one: they all keep their values.
                    reads.extend(self.all_elements(name, at.proc));
                    return Ok(Err(RUN_TIME_INDEX.into()));
                }
            },
        };
        let Some(source) = self.source(name, at) else {
            let e = super::resolve::lookup_or_err(self.module, src, file, here, name, "");
            return Err(e
                .err()
                .unwrap_or_else(|| input_err(src, file, here, "undeclared")));
        };
        let declared_rt = matches!(
            &source,
            Source::Module(_, d) | Source::Local(d) if d.data_type == DataType::RobTarget
        );
        let (value, origin, stem) = match source {
            Source::RunTime(r) => return Ok(Err(r)),
            Source::Assigned(a, at2) => {
                if k.is_some() {
                    return Ok(Err(PART.into()));
                }
                let u = match self.cart_at(src, file, at2, &a.value, reads, depth + 1)? {
                    Ok(u) => u,
                    Err(r) => return Ok(Err(r)),
                };
                return Ok(Ok(self.followed(u, name, at)));
            }
            Source::Module(di, d) => {
                let (v, elem) = element(src, file, here, d, k.as_deref())?;
                let origin = Origin::Decl { decl: di, elem };
                let stem = match &k {
                    Some(ks) => element_stem(&d.name, ks),
                    None => d.name.clone(),
                };
                (v, origin, stem)
            }
            Source::Local(d) => (
                element(src, file, here, d, k.as_deref())?.0,
                Origin::Inline,
                String::new(),
            ),
        };
        let DataValue::RobTarget(rt) = value else {
            // A robtarget whose value is an expression (a named constant
            // inside its literal): known by evaluating it, which is not
            // done; the move keeps it as written.
            if declared_rt && matches!(value, DataValue::Other { .. }) {
                if let Origin::Decl { .. } = origin {
                    reads.push(origin);
                }
                return Ok(Err(EXPRESSION_VALUE.into()));
            }
            return Err(input_err(src, file, here, "this move needs a robtarget"));
        };
        let u = CartUse {
            rt,
            origin,
            stem,
            derived: false,
            derived_key: String::new(),
            pose_obj: robtarget_pose(rt)
                .ok_or_else(|| input_err(src, file, here, "zero quaternion"))?,
            conf: conf_of(rt)
                .ok_or_else(|| input_err(src, file, here, "confdata must be integers"))?,
        };
        if let Origin::Decl { .. } = origin {
            reads.push(origin);
            return Ok(Ok(u));
        }
        // A routine-local declaration: its value is materialised.
        Ok(Ok(self.followed(u, name, at)))
    }

    /// The 1-based index of each dimension of `ix` (of array `name`) at
    /// `at`, when every one is known before run time.
    fn indices(
        &self,
        src: &str,
        file: &str,
        at: At,
        name: &str,
        ix: &super::Index,
    ) -> Result<Option<Vec<usize>>> {
        let mut ks = Vec::new();
        for part in ix.parts() {
            match self.number(part, at, 0) {
                Some(v) if v.fract() == 0.0 && (1.0..1e9).contains(&v) => ks.push(v as usize),
                Some(v) => {
                    return Err(input_err(
                        src,
                        file,
                        ix.span.start,
                        format!("index {v} of `{name}` is not a positive integer"),
                    ));
                }
                None => return Ok(None),
            }
        }
        Ok(Some(ks))
    }

    /// Every element of the module array `name` seen from routine `proc`
    /// (none for a parameter or a routine-local array): what a move to an
    /// element chosen at run time may read.
    fn all_elements(&self, name: &str, proc: usize) -> Vec<Origin> {
        if self.is_param(proc, &name.to_ascii_lowercase()) || self.local_decl(proc, name).is_some()
        {
            return Vec::new();
        }
        let Some((decl, d)) = self.module_decl(name) else {
            return Vec::new();
        };
        let n = d.value.as_ref().map_or(0, element_count);
        (0..n)
            .map(|i| Origin::Decl {
                decl,
                elem: Some(i),
            })
            .collect()
    }

    /// The value `u` that data `name` holds at `at` (followed through an
    /// assignment, or a routine-local declaration), as a move target: a
    /// declared target unchanged (`p := pHome;` goes to `pHome`), anything
    /// else materialised as a new declaration after the data's module
    /// declaration (or the base's, or the last one).
    fn followed(&self, mut u: CartUse<'m>, name: &str, at: At) -> CartUse<'m> {
        if !u.derived && matches!(u.origin, Origin::Decl { .. }) {
            return u;
        }
        let own = self
            .local_decl(at.proc, name)
            .is_none()
            .then(|| self.module_decl(name).map(|(i, _)| i))
            .flatten();
        let base = match u.origin {
            Origin::Decl { decl, .. } => Some(decl),
            Origin::Inline => None,
        };
        let anchor = own
            .or(base)
            .or_else(|| self.module.decls.len().checked_sub(1));
        u.derived_key = pose_key(&u.pose_obj);
        u.derived = true;
        u.stem = name.to_string();
        u.origin = match anchor {
            Some(decl) => Origin::Decl { decl, elem: None },
            None => Origin::Inline,
        };
        u
    }
}

/// True for the data types a move's resolution reads: robtarget,
/// jointtarget, num.
fn resolves_moves(d: &Decl) -> bool {
    matches!(
        d.data_type,
        DataType::RobTarget | DataType::JointTarget | DataType::Num
    )
}

/// The value of declaration `d` (element `ks`, 1-based, of an array),
/// with the element's place among the array's ([`element_at`]).
fn element<'m>(
    src: &str,
    file: &str,
    at: usize,
    d: &'m Decl,
    ks: Option<&[usize]>,
) -> Result<(&'m DataValue, Option<usize>)> {
    if let Some(ks) = ks {
        return element_at(src, file, at, d, ks).map(|(v, i)| (v, Some(i)));
    }
    let name = &d.name;
    match &d.value {
        None => Err(input_err(
            src,
            file,
            at,
            format!("`{name}` has no initial value"),
        )),
        Some(DataValue::Array { .. }) => Err(input_err(
            src,
            file,
            at,
            format!("`{name}` is an array; index it"),
        )),
        Some(v) => Ok((v, None)),
    }
}

/// The identity of a materialised pose: its numbers' bit patterns.
fn pose_key(p: &Isometry3<f64>) -> String {
    let t = p.translation.vector;
    let q = p.rotation.coords;
    format!(
        "pose {:x} {:x} {:x} {:x} {:x} {:x} {:x}",
        t.x.to_bits(),
        t.y.to_bits(),
        t.z.to_bits(),
        q.x.to_bits(),
        q.y.to_bits(),
        q.z.to_bits(),
        q.w.to_bits()
    )
}

/// True when `text` is a call of function `name` (`CRobT()`,
/// `CRobT(\Tool:=t)`).
fn is_call(text: &str, name: &str) -> bool {
    text.get(..name.len())
        .is_some_and(|h| h.eq_ignore_ascii_case(name))
        && text
            .get(name.len()..)
            .is_some_and(|r| r.trim_start().starts_with('('))
}

/// The parameter names of a routine's parameter text (`robtarget pt,
/// INOUT num n, \switch s | num t{*}`), lower case.
fn param_names(text: &str) -> Vec<String> {
    without_comments(text)
        .split([',', '|'])
        .filter_map(|p| {
            let p = p.split('{').next().unwrap_or("");
            let word = p
                .rsplit(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
                .find(|w| !w.is_empty())?;
            Some(word.to_ascii_lowercase())
        })
        .collect()
}

/// The variable, start, end and step texts of a `FOR v FROM a TO b [STEP
/// c] DO` line.
fn for_bounds(text: &str) -> Option<(&str, &str, &str, Option<&str>)> {
    let t = text.trim();
    let t = t.get(3..)?.trim_start();
    let word_at = |hay: &str, w: &str| -> Option<usize> {
        let up = hay.to_ascii_uppercase();
        let mut from = 0;
        while let Some(k) = up.get(from..)?.find(w) {
            let k = from + k;
            let before = up[..k]
                .chars()
                .last()
                .is_none_or(|c| !c.is_ascii_alphanumeric() && c != '_');
            let after = up[k + w.len()..]
                .chars()
                .next()
                .is_none_or(|c| !c.is_ascii_alphanumeric() && c != '_');
            if before && after {
                return Some(k);
            }
            from = k + w.len();
        }
        None
    };
    let f = word_at(t, "FROM")?;
    let v = t.get(..f)?.trim();
    let rest = t.get(f + 4..)?;
    let to = word_at(rest, "TO")?;
    let a = rest.get(..to)?.trim();
    let rest = rest.get(to + 2..)?;
    let d = word_at(rest, "DO")?;
    let rest = rest.get(..d)?;
    let (b, c) = match word_at(rest, "STEP") {
        Some(k) => (rest.get(..k)?.trim(), Some(rest.get(k + 4..)?.trim())),
        None => (rest.trim(), None),
    };
    Some((v, a, b, c))
}

/// True when `text` names `name` as a whole word anywhere outside strings
/// (inside brackets, calls and comments too: a comment only makes the
/// answer more careful).
fn text_names(text: &str, name: &str) -> bool {
    let mut quoted = false;
    let mut word = String::new();
    for c in text.chars().chain(std::iter::once(' ')) {
        if c == '"' {
            quoted = !quoted;
        }
        if !quoted && (c.is_ascii_alphanumeric() || c == '_') {
            word.push(c);
            continue;
        }
        if word.eq_ignore_ascii_case(name) {
            return true;
        }
        word.clear();
    }
    false
}

/// `text` without its `!` comments (a parameter list written over several
/// lines may hold some; a parameter list holds no strings).
pub(crate) fn without_comments(text: &str) -> String {
    text.lines()
        .map(|l| l.split('!').next().unwrap_or(""))
        .collect::<Vec<_>>()
        .join("\n")
}

/// Words that are never data names in a statement.
const KEYWORDS: [&str; 12] = [
    "IF", "THEN", "AND", "OR", "NOT", "XOR", "DIV", "MOD", "TRUE", "FALSE", "GOTO", "RETURN",
];

/// The first word of an opaque statement and the data names it may write:
/// each name followed by `:=` (with `true`; after an optional index or
/// component), and each other name outside parentheses, brackets and
/// strings that is not an optional argument's name (with `false`: passed
/// to the instruction, which may write it).
fn opaque_writes(text: &str) -> (&str, Vec<(&str, bool)>) {
    let b = text.as_bytes();
    let mut out = Vec::new();
    let mut first = "";
    let mut depth = 0usize;
    let mut k = 0;
    while let Some(&c) = b.get(k) {
        match c {
            b'"' => {
                k += 1;
                while b.get(k).is_some_and(|&c| c != b'"') {
                    k += 1;
                }
                k += 1;
            }
            b'!' => {
                while b.get(k).is_some_and(|&c| c != b'\n') {
                    k += 1;
                }
            }
            b'(' | b'[' => {
                depth += 1;
                k += 1;
            }
            b')' | b']' => {
                depth = depth.saturating_sub(1);
                k += 1;
            }
            b'%' if first.is_empty() => {
                first = "%";
                k += 1;
            }
            c if c.is_ascii_alphabetic() => {
                let s = k;
                while b
                    .get(k)
                    .is_some_and(|&c| c.is_ascii_alphanumeric() || c == b'_')
                {
                    k += 1;
                }
                let word = text.get(s..k).unwrap_or("");
                let option = s > 0 && b.get(s - 1) == Some(&b'\\');
                if first.is_empty() {
                    first = word;
                    if !after_is_assign(text.get(k..).unwrap_or("")) {
                        continue;
                    }
                }
                if depth > 0 || option || KEYWORDS.iter().any(|w| w.eq_ignore_ascii_case(word)) {
                    continue;
                }
                // A name followed by `(` is a function call.
                let rest = text.get(k..).unwrap_or("").trim_start();
                if rest.starts_with('(') {
                    continue;
                }
                out.push((word, after_is_assign(rest)));
            }
            c if c.is_ascii_digit() => {
                while b
                    .get(k)
                    .is_some_and(|&c| c.is_ascii_alphanumeric() || c == b'.')
                {
                    k += 1;
                }
            }
            _ => k += 1,
        }
    }
    (first, out)
}

/// The names passed to a call of one of `writers` in `text` (`StrToVal(sData,
/// pRecv)`), with the function's name as written: the function may write
/// them.
fn call_writes<'t>(text: &'t str, writers: &[&str]) -> Vec<(&'t str, &'t str)> {
    let mut out = Vec::new();
    let mut from = 0;
    while let Some(k) = text.get(from..).and_then(|t| t.find('(')) {
        let open = from + k;
        from = open + 1;
        let head = text.get(..open).unwrap_or("").trim_end();
        let n = head
            .bytes()
            .rev()
            .take_while(|b| b.is_ascii_alphanumeric() || *b == b'_')
            .count();
        let func = head.get(head.len() - n..).unwrap_or("");
        if !writers.iter().any(|w| w.eq_ignore_ascii_case(func)) {
            continue;
        }
        // The arguments: up to the matching `)`.
        let mut depth = 0usize;
        let mut end = text.len();
        for (i, c) in text.get(open..).unwrap_or("").char_indices() {
            match c {
                '(' | '[' => depth += 1,
                ')' | ']' => {
                    depth = depth.saturating_sub(1);
                    if depth == 0 {
                        end = open + i;
                        break;
                    }
                }
                _ => {}
            }
        }
        let args = text.get(open + 1..end).unwrap_or("");
        out.extend(bare_names(args).into_iter().map(|name| (name, func)));
    }
    out
}

/// The names in `text` outside parentheses, brackets and strings that are
/// not an optional argument's name nor a function called.
fn bare_names(text: &str) -> Vec<&str> {
    let b = text.as_bytes();
    let mut out = Vec::new();
    let (mut k, mut depth) = (0, 0usize);
    while let Some(&c) = b.get(k) {
        match c {
            b'"' => {
                k += 1;
                while b.get(k).is_some_and(|&c| c != b'"') {
                    k += 1;
                }
                k += 1;
            }
            b'(' | b'[' => {
                depth += 1;
                k += 1;
            }
            b')' | b']' => {
                depth = depth.saturating_sub(1);
                k += 1;
            }
            c if c.is_ascii_alphabetic() => {
                let s = k;
                while b
                    .get(k)
                    .is_some_and(|&c| c.is_ascii_alphanumeric() || c == b'_')
                {
                    k += 1;
                }
                let option = s > 0 && b.get(s - 1) == Some(&b'\\');
                let call = text.get(k..).unwrap_or("").trim_start().starts_with('(');
                if depth == 0 && !option && !call {
                    out.extend(text.get(s..k));
                }
            }
            c if c.is_ascii_digit() => {
                while b
                    .get(k)
                    .is_some_and(|&c| c.is_ascii_alphanumeric() || c == b'.')
                {
                    k += 1;
                }
            }
            _ => k += 1,
        }
    }
    out
}

/// True when `rest` (after a name) is an optional index or components
/// and then `:=`.
fn after_is_assign(rest: &str) -> bool {
    let mut r = rest.trim_start();
    if let Some(x) = r.strip_prefix('{') {
        r = x.find('}').map_or("", |p| &x[p + 1..]).trim_start();
    }
    while let Some(x) = r.strip_prefix('.') {
        let x = x.trim_start();
        let n = x
            .bytes()
            .take_while(|b| b.is_ascii_alphanumeric() || *b == b'_')
            .count();
        r = x.get(n..).unwrap_or("").trim_start();
    }
    r.starts_with(":=")
}

impl Shape {
    /// Block depths, loops, handlers and labels of a routine body.
    fn walk(&mut self, body: &[Stmt]) {
        // Open blocks: (keyword is a loop, first statement).
        let mut open: Vec<(bool, usize)> = Vec::new();
        let mut handler = 0u32;
        for (k, s) in body.iter().enumerate() {
            let mut depth = open.len() as u32 + handler;
            if let Stmt::Control { keyword, .. } = s {
                match keyword.as_str() {
                    "IF" | "TEST" => open.push((false, k)),
                    "FOR" | "WHILE" => open.push((true, k)),
                    "ENDIF" | "ENDTEST" | "ENDFOR" | "ENDWHILE" => {
                        if let Some((is_loop, start)) = open.pop()
                            && is_loop
                        {
                            self.loops.push((start, k));
                        }
                        depth = open.len() as u32 + handler;
                    }
                    "ELSE" | "ELSEIF" | "CASE" | "DEFAULT" => {
                        depth = depth.saturating_sub(1);
                    }
                    "ERROR" | "BACKWARD" | "UNDO" => {
                        self.handler.get_or_insert(k);
                        handler = 1;
                        depth = open.len() as u32;
                    }
                    "LABEL" => self.labels = true,
                    _ => {}
                }
            }
            self.depth.push(depth);
        }
        // A loop left open (a window of a routine) runs to the end.
        for (is_loop, start) in open {
            if is_loop {
                self.loops.push((start, body.len()));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parameter_names_of_a_parameter_list() {
        assert_eq!(
            param_names("robtarget pt, INOUT num n, \\switch s | num t{*}, PERS tooldata tl"),
            ["pt", "n", "s", "t", "tl"]
        );
    }

    #[test]
    fn opaque_statements_write_assigned_and_passed_names() {
        let (first, w) = opaque_writes("StrToVal sData, pRecv;");
        assert_eq!(first, "StrToVal");
        assert_eq!(w, [("sData", false), ("pRecv", false)]);
        let (first, w) = opaque_writes("IF Distance(p1, p2) > n p3 := CRobT();");
        assert_eq!(first, "IF");
        assert_eq!(w, [("n", false), ("p3", true)]);
        let (_, w) = opaque_writes("TPWrite \"x:=1\" \\Num:=nCount;");
        assert_eq!(w, [("nCount", false)]);
    }

    const RT: &str = "[[700,0,500],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]";

    /// Each move of `body` (the routines after a robtarget `p`, a VAR `v`
    /// and a VAR num `n` declared with [`RT`] and 10): its line and what
    /// its target is (`x,y,z` of the followed pose, or the reason it is
    /// left as written).
    fn fates(body: &str) -> Vec<(usize, String)> {
        let src = format!(
            "MODULE M\n  CONST robtarget p := {RT};\n  VAR robtarget v := {RT};\n  VAR num n := 10;\n{body}ENDMODULE\n"
        );
        let m = super::super::parse_module(&src, "m.mod").expect("parses");
        let flow = Flow::of(&m, &src);
        flow.moves()
            .map(|(at, mv)| {
                let what = match flow.cart(&src, "m.mod", at, &mv.target).expect("resolves") {
                    Ok(u) => {
                        let t = u.pose_obj.translation.vector;
                        format!("{},{},{}", t.x, t.y, t.z)
                    }
                    Err(left) => left.reason,
                };
                (mv.line, what)
            })
            .collect()
    }

    #[test]
    fn straight_line_assignments_are_followed() {
        let got = fates(
            "  PROC main()\n    MoveL v, v100, fine, tool0;\n    v := Offs(p, 0, 0, n);\n    MoveL v, v100, fine, tool0;\n    v := Offs(v, 5, 0, 0);\n    IF TRUE THEN\n      MoveL v, v100, fine, tool0;\n    ENDIF\n  ENDPROC\n",
        );
        assert_eq!(
            got,
            [
                (6, AFTER.to_string()),
                (8, "700,0,510".to_string()),
                (11, "705,0,510".to_string()),
            ]
        );
    }

    #[test]
    fn loops_branches_calls_and_traps_leave_moves_as_written() {
        let got = fates(
            "  PROC main()\n    IF n > 0 THEN\n      v := Offs(p, 0, 0, 1);\n    ENDIF\n    MoveL v, v100, fine, tool0;\n    WHILE TRUE DO\n      MoveL v, v100, fine, tool0;\n      v := Offs(v, 0, 0, 1);\n    ENDWHILE\n  ENDPROC\n  PROC other()\n    v := p;\n    shift;\n    MoveL v, v100, fine, tool0;\n    MoveL Offs(p, 0, 0, n), v100, fine, tool0;\n  ENDPROC\n  PROC shift()\n    v := Offs(v, 1, 0, 0);\n    n := n + 1;\n  ENDPROC\n",
        );
        assert_eq!(
            got,
            [
                (9, BRANCH.to_string()),
                (11, LOOP.to_string()),
                (18, OTHER_ROUTINE.to_string()),
                (19, RUN_TIME_OFFSET.to_string()),
            ]
        );
    }

    #[test]
    fn local_data_parameters_labels_and_run_time_values() {
        let got = fates(
            "  PROC main(robtarget pt)\n    VAR robtarget w := [[600,0,500],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n    CONST num k := 2;\n    MoveL w, v100, fine, tool0;\n    MoveL pt, v100, fine, tool0;\n    MoveL Offs(w, 0, 0, -k), v100, fine, tool0;\n    w := CRobT();\n    MoveL w, v100, fine, tool0;\n    IF n > 0 w := p;\n    MoveL w, v100, fine, tool0;\n  ENDPROC\n  PROC again()\n    again_label:\n    v := p;\n    MoveL v, v100, fine, tool0;\n    GOTO again_label;\n  ENDPROC\n",
        );
        assert_eq!(
            got,
            [
                (8, "600,0,500".to_string()),
                (9, PARAMETER.to_string()),
                (10, "600,0,498".to_string()),
                (12, CROBT.to_string()),
                (14, BRANCH.to_string()),
                (19, LOOP.to_string()),
            ]
        );
    }

    #[test]
    fn functions_that_write_their_arguments() {
        let w = call_writes("bOk := StrToVal(sData, pRecv) AND Ready(n);", &["StrToVal"]);
        assert_eq!(w, [("sData", "StrToVal"), ("pRecv", "StrToVal")]);
        assert!(call_writes("p := Offs(pBase, 0, 0, n);", &["StrToVal"]).is_empty());
    }
}
