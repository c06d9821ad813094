//! KRL resolution: a `.src` with its `.dat` (and a `$config.dat`, for
//! `TOOL_DATA[n]` and `BASE_DATA[n]`) to the language-neutral robot move
//! stream ([`crate::program::robot_moves`]).
//!
//! The `.src` is read line by line in order (each motion line once, as
//! written: a loop's move is one target). The tool and base in force are
//! those the lines before set: `$TOOL = …` and `$BASE = …` (an aggregate,
//! `TOOL_DATA[n]`, `BASE_DATA[n]`), an inline form's `Tool[n]` and
//! `Base[n]`, or, for a spline inline form without them, the `TOOL_NO`
//! and `BASE_NO` of the point's `FDAT` in the `.dat`. A target is an
//! `E6POS`, `POS` or `FRAME` (declared in the `.dat` or inline); an
//! `E6AXIS` or `AXIS` is a joint target, reported and left as written.
//! Everything else is left as written with its reason: a target computed
//! at run time, a geometric operator (`:`), a partial aggregate, a tool or
//! base not known offline.
//!
//! Configuration: a `PTP`/`SPTP` target with Status (and Turn) takes the
//! joint solution they describe ([`StatusTurn`]); without them, and for
//! every `LIN`, `CIRC`, `SLIN` and `SCIRC` (whose controller ignores Status
//! and Turn), the solution nearest the target before.

use std::collections::HashMap;
use std::sync::Arc;

use nalgebra::{Isometry3, Translation3};

use super::config::{StatusTurn, axes_to_model};
use super::syntax::{Aggregate, File, Kind, Line, Motion, Target};
use crate::machine::robot::Robot;
use crate::program::euler::zyx_to_quaternion;
use crate::program::robot_moves::{
    Configuration, JointMove, LeftAsWritten, PathKind, Place, RobotStep, RobotTarget, ToolUse,
};

/// A KRL program's texts with their parsed lines: the `.src` (source 0),
/// its `.dat` (source 1) and a `$config.dat` (source 2), the last two when
/// given.
#[derive(Clone, Copy)]
pub struct Program<'a> {
    /// The `.src`.
    pub src: &'a File,
    /// The `.dat`.
    pub dat: Option<&'a File>,
    /// The `$config.dat`.
    pub config: Option<&'a File>,
}

/// The source index of the `.src` in [`Place::source`].
pub const SRC: usize = 0;
/// The source index of the `.dat`.
pub const DAT: usize = 1;
/// The source index of the `$config.dat`.
pub const CONFIG: usize = 2;

/// A declared data object: its type (upper case), its value and where.
struct Datum<'a> {
    type_name: &'a str,
    value: Option<&'a Aggregate>,
    source: usize,
}

/// Known offline, or why not.
type Known<T> = std::result::Result<T, String>;

/// What the lines before a motion set.
struct State {
    tool: Known<ToolUse>,
    base: Known<Isometry3<f64>>,
    /// `$VEL.CP`, mm/s.
    vel_cp: Option<f64>,
    /// `$APO.CDIS`, mm.
    cdis: Option<f64>,
    /// The speed of the inline form around the motion, mm/s (`m/s` unit).
    form_vel: Option<f64>,
}

/// The frame of an aggregate with all of `X, Y, Z, A, B, C`.
pub fn frame_of(a: &Aggregate) -> Option<Isometry3<f64>> {
    let n = |k: &str| a.number(k).map(|n| n.value);
    let (x, y, z) = (n("X")?, n("Y")?, n("Z")?);
    let (aa, b, c) = (n("A")?, n("B")?, n("C")?);
    Some(Isometry3::from_parts(
        Translation3::new(x, y, z),
        zyx_to_quaternion(aa, b, c),
    ))
}

/// The axis angles `A1…A6` of an aggregate, degrees.
fn axes_of(a: &Aggregate) -> Option<[f64; 6]> {
    let mut q = [0.0; 6];
    for (i, v) in q.iter_mut().enumerate() {
        *v = a.number(&format!("A{}", i + 1))?.value;
    }
    Some(q)
}

/// The name of a motion keyword, as written in reports.
pub fn motion_name(m: Motion) -> &'static str {
    match m {
        Motion::Ptp => "PTP",
        Motion::Lin => "LIN",
        Motion::Circ => "CIRC",
        Motion::Sptp => "SPTP",
        Motion::Slin => "SLIN",
        Motion::Scirc => "SCIRC",
    }
}

/// The program's data: declarations of the `.dat` and the `$config.dat`
/// by upper-case name, and `TOOL_DATA[n]` / `BASE_DATA[n]` frames.
struct Data<'a> {
    decls: HashMap<String, Datum<'a>>,
    tools: HashMap<u32, Isometry3<f64>>,
    bases: HashMap<u32, Isometry3<f64>>,
    config: bool,
}

impl<'a> Data<'a> {
    fn of(p: &Program<'a>) -> Data<'a> {
        let mut d = Data {
            decls: HashMap::new(),
            tools: HashMap::new(),
            bases: HashMap::new(),
            config: p.config.is_some(),
        };
        let files = [(DAT, p.dat), (CONFIG, p.config)];
        for (source, f) in files.into_iter().filter_map(|(s, f)| Some((s, f?))) {
            for l in &f.lines {
                match &l.kind {
                    Kind::Decl {
                        type_name,
                        name,
                        value,
                    } => {
                        d.decls.entry(name.to_ascii_uppercase()).or_insert(Datum {
                            type_name,
                            value: value.as_ref(),
                            source,
                        });
                    }
                    Kind::Assign(lhs, Some(a), _) => {
                        let Some(frame) = frame_of(a) else { continue };
                        if let Some(n) = indexed(lhs, "TOOL_DATA") {
                            d.tools.insert(n, frame);
                        } else if let Some(n) = indexed(lhs, "BASE_DATA") {
                            d.bases.insert(n, frame);
                        }
                    }
                    _ => {}
                }
            }
        }
        d
    }

    fn tool(&self, n: u32) -> Known<ToolUse> {
        let frame = if n == 0 {
            Some(Isometry3::identity())
        } else {
            self.tools.get(&n).copied()
        };
        match frame {
            Some(f) => Ok(ToolUse {
                key: format!("TOOL_DATA[{n}]"),
                flange_to_tcp: f,
                load: None,
            }),
            None => Err(self.missing("TOOL_DATA", n)),
        }
    }

    fn base(&self, n: u32) -> Known<Isometry3<f64>> {
        if n == 0 {
            return Ok(Isometry3::identity());
        }
        self.bases
            .get(&n)
            .copied()
            .ok_or_else(|| self.missing("BASE_DATA", n))
    }

    fn missing(&self, what: &str, n: u32) -> String {
        if self.config {
            format!("{what}[{n}] is not in the $config.dat given")
        } else {
            format!("{what}[{n}] is in the robot's $config.dat, which was not given")
        }
    }
}

/// `n` of `NAME[n]` (case-insensitive), `None` for anything else.
fn indexed(text: &str, name: &str) -> Option<u32> {
    let t = text.trim();
    let head = t.get(..name.len())?;
    if !head.eq_ignore_ascii_case(name) {
        return None;
    }
    t[name.len()..]
        .trim()
        .strip_prefix('[')?
        .strip_suffix(']')?
        .trim()
        .parse()
        .ok()
}

/// Resolves `program` (`text` is the `.src`'s text) into the move stream.
pub fn resolve(program: &Program, text: &str) -> Vec<RobotStep> {
    let data = Data::of(program);
    let mut st = State {
        tool: Err("no tool is set before it ($TOOL at run time)".into()),
        base: Err("no base is set before it ($BASE at run time)".into()),
        vel_cp: None,
        cdis: None,
        form_vel: None,
    };
    let mut steps = Vec::new();
    for l in &program.src.lines {
        match &l.kind {
            Kind::Fold(_, Some(form)) => {
                st.form_vel = form
                    .vel
                    .as_ref()
                    .filter(|(_, unit)| unit.eq_ignore_ascii_case("m/s"))
                    .map(|(n, _)| n.value * 1000.0);
                let fdat = form.points.last().and_then(|p| {
                    let d = data.decls.get(&format!("F{}", p.to_ascii_uppercase()))?;
                    d.value.filter(|_| d.type_name == "FDAT")
                });
                let number =
                    |n: Option<u32>, key: &str| n.or_else(|| fdat.and_then(|a| a.bits(key)));
                if let Some(n) = number(form.tool, "TOOL_NO") {
                    st.tool = data.tool(n);
                }
                if let Some(n) = number(form.base, "BASE_NO") {
                    st.base = data.base(n);
                }
            }
            Kind::EndFold => st.form_vel = None,
            Kind::Assign(lhs, agg, span) => assign(&mut st, &data, lhs, agg.as_ref(), text, span),
            Kind::Move {
                motion,
                aux,
                target,
                rest,
            } => {
                let rest = text.get(rest.clone()).unwrap_or("");
                let step = motion_step(&st, &data, l, text, (*motion, aux.as_ref(), target), rest);
                steps.push(step);
            }
            _ => {}
        }
    }
    steps
}

/// The state after an assignment line.
fn assign(
    st: &mut State,
    data: &Data,
    lhs: &str,
    agg: Option<&Aggregate>,
    text: &str,
    span: &std::ops::Range<usize>,
) {
    let value = text.get(span.clone()).unwrap_or("").trim();
    let upper = lhs.to_ascii_uppercase();
    match upper.as_str() {
        "$TOOL" => {
            st.tool = match (agg.and_then(frame_of), indexed(value, "TOOL_DATA")) {
                (Some(f), _) => Ok(ToolUse {
                    key: value.to_string(),
                    flange_to_tcp: f,
                    load: None,
                }),
                (None, Some(n)) => data.tool(n),
                _ => Err(format!("$TOOL = {value} is known at run time only")),
            }
        }
        "$BASE" => {
            st.base = match (agg.and_then(frame_of), indexed(value, "BASE_DATA")) {
                (Some(f), _) => Ok(f),
                (None, Some(n)) => data.base(n),
                _ => Err(format!("$BASE = {value} is known at run time only")),
            }
        }
        "$VEL.CP" => st.vel_cp = value.parse::<f64>().ok().map(|v| v * 1000.0),
        "$APO.CDIS" => st.cdis = value.parse().ok(),
        _ => {}
    }
}

/// A target of a motion: its aggregate and where it is, or why it is not
/// known offline.
fn target_value<'a>(
    data: &'a Data,
    t: &'a Target,
) -> Known<(&'a Aggregate, usize, Option<&'a str>)> {
    match t {
        Target::Aggregate(a) => Ok((a, SRC, None)),
        Target::Named(name, _) => {
            if name.contains(['.', '[']) {
                return Err(format!("`{name}` is known at run time only"));
            }
            let Some(d) = data.decls.get(&name.to_ascii_uppercase()) else {
                return Err(format!("`{name}` is not declared in the .dat"));
            };
            match d.value {
                Some(a) => Ok((a, d.source, Some(d.type_name))),
                None => Err(format!(
                    "`{name}` has no value in the .dat: it is computed at run time"
                )),
            }
        }
    }
}

/// The step of one motion line.
fn motion_step(
    st: &State,
    data: &Data,
    l: &Line,
    text: &str,
    (motion, aux, target): (Motion, Option<&Target>, &Target),
    rest: &str,
) -> RobotStep {
    let name = motion_name(motion);
    let line_text = text.get(l.span.clone()).unwrap_or("");
    let column = line_text.len() - line_text.trim_start().len() + 1;
    let left =
        |reason: &str| RobotStep::Left(LeftAsWritten::warning(l.number, column, name, reason));
    if rest.trim_start().starts_with(':') {
        return left("geometric operator `:` with a frame known at run time only");
    }
    let (agg, source, type_name) = match target_value(data, target) {
        Ok(v) => v,
        Err(reason) => return left(&reason),
    };
    let joint_type = matches!(type_name, Some("E6AXIS" | "AXIS"));
    if joint_type || (type_name.is_none() && agg.get("A1").is_some()) {
        let Some(axes) = axes_of(agg) else {
            return left("partial axis aggregate: its other axes are the current position's");
        };
        return RobotStep::Joints(JointMove {
            line: l.number,
            column,
            instruction: name,
            q: axes_to_model(&axes),
            tool: st.tool.clone().ok(),
        });
    }
    let Some(pose) = frame_of(agg) else {
        return left("partial aggregate: its other components are the current position's");
    };
    let tool = match &st.tool {
        Ok(t) => t.clone(),
        Err(reason) => return left(reason),
    };
    let work = match &st.base {
        Ok(b) => *b,
        Err(reason) => return left(reason),
    };
    let via = match aux {
        Some(a) => match target_value(data, a) {
            Ok((va, vs, _)) => match frame_of(va) {
                Some(v) => Some((
                    v,
                    Place {
                        source: vs,
                        span: va.span.clone(),
                    },
                )),
                None => return left("partial auxiliary point"),
            },
            Err(reason) => return left(&format!("auxiliary point: {reason}")),
        },
        None => None,
    };
    let (path, speed) = match motion {
        Motion::Ptp | Motion::Sptp => (PathKind::Joint, None),
        Motion::Lin | Motion::Slin => (PathKind::Linear, st.form_vel.or(st.vel_cp)),
        Motion::Circ | Motion::Scirc => (PathKind::Circular, st.form_vel.or(st.vel_cp)),
    };
    let blended = rest.to_ascii_uppercase().contains("C_DIS");
    RobotStep::Target(Box::new(RobotTarget {
        line: l.number,
        column,
        instruction: name,
        path,
        pose,
        work,
        tool,
        via,
        configuration: configuration(motion, agg),
        speed_mm_s: speed,
        zone_mm: st.cdis.filter(|_| blended),
        place: Place {
            source,
            span: agg.span.clone(),
        },
    }))
}

/// The configuration rule of a target ([`resolve`]'s module documentation).
fn configuration(motion: Motion, agg: &Aggregate) -> Configuration {
    let ptp = matches!(motion, Motion::Ptp | Motion::Sptp);
    match (ptp, agg.bits("S")) {
        (true, Some(status)) => {
            let turn = agg.bits("T");
            let st = StatusTurn {
                status,
                turn: turn.unwrap_or(0),
            };
            let text = match turn {
                Some(t) => format!("Status {status} and Turn {t}"),
                None => format!("Status {status}"),
            };
            let admits = move |r: &Robot, q: &[f64; 6]| match turn {
                Some(_) => st.matches(r, q),
                None => r.confdata(q).cfx == st.cfx(),
            };
            Configuration::Admits(Arc::new(admits), text)
        }
        _ => Configuration::Previous,
    }
}
