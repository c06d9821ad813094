//! Name resolution of a RAPID module: the robtarget, tool and work object
//! each move names, looked up in the module's declarations and resolved to
//! poses (object frame, flange frame) with the spans of their numbers, and
//! the TCP speed of a move. The counterpart of the G-code interpreter: what
//! cannot be known before run time is refused here, at its span.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

use crate::error::{Error, Located, Result};
use crate::machine::robot::pose::pose_from_abb;
use crate::machine::robot::{ConfData, PointMass};
use crate::program::rapid::{
    DataValue, Decl, Module, Move, Number, Pose, RobTarget, Scalar, Target,
};

/// 1-based line and byte column of a byte offset.
pub(crate) fn line_col(src: &str, at: usize) -> (usize, usize) {
    let before = src.get(..at).unwrap_or(src);
    let line = 1 + before.bytes().filter(|&b| b == b'\n').count();
    let col = before
        .rfind('\n')
        .map_or(before.len(), |k| before.len() - k - 1)
        + 1;
    (line, col)
}

pub(crate) fn input_err(src: &str, file: &str, at: usize, msg: impl Into<String>) -> Error {
    let (l, c) = line_col(src, at);
    Error::Input(Located::new(file, l, c, msg))
}

pub(crate) fn pose_of(p: &Pose) -> Option<Isometry3<f64>> {
    pose_from_abb(
        p.trans.each_ref().map(|n| n.value),
        p.rot.each_ref().map(|n| n.value),
    )
}

pub(crate) fn robtarget_pose(rt: &RobTarget) -> Option<Isometry3<f64>> {
    pose_from_abb(
        rt.trans.each_ref().map(|n| n.value),
        rt.rot.each_ref().map(|n| n.value),
    )
}

pub(crate) fn conf_of(rt: &RobTarget) -> Option<ConfData> {
    let v = rt.robconf.each_ref().map(|n| n.value);
    if v.iter()
        .any(|x| !x.is_finite() || x.fract() != 0.0 || x.abs() > 1e6)
    {
        return None;
    }
    Some(ConfData {
        cf1: v[0] as i32,
        cf4: v[1] as i32,
        cf6: v[2] as i32,
        cfx: v[3] as i32,
    })
}

/// A resolved tool: TCP in the flange frame and load (flange frame).
#[derive(Debug, Clone, Copy)]
pub(crate) struct ToolView {
    pub(crate) tframe: Isometry3<f64>,
    pub(crate) load: Option<PointMass>,
}

/// Where a robtarget's numbers are and how a compensated one is written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub(crate) enum Origin {
    /// Module declaration `decl`, element `elem` (0-based) of an array.
    Decl { decl: usize, elem: Option<usize> },
    /// An inline literal in a move (edited in place).
    Inline,
}

pub(crate) fn lookup<'m>(module: &'m Module, name: &str) -> Option<(usize, &'m Decl)> {
    module
        .decls
        .iter()
        .enumerate()
        .find(|(_, d)| d.name.eq_ignore_ascii_case(name))
}

/// [`lookup`], or an error at `at`: "`what` `name` is not declared in this
/// module" (`what` empty: just the name).
pub(crate) fn lookup_or_err<'m>(
    module: &'m Module,
    src: &str,
    file: &str,
    at: usize,
    name: &str,
    what: &str,
) -> Result<(usize, &'m Decl)> {
    lookup(module, name).ok_or_else(|| {
        let subject = if what.is_empty() {
            format!("`{name}`")
        } else {
            format!("{what} `{name}`")
        };
        input_err(
            src,
            file,
            at,
            format!("{subject} is not declared in this module"),
        )
    })
}

/// The value of a named target (`p`, `holes{3}`), with its origin.
pub(crate) fn named_value<'m>(
    module: &'m Module,
    src: &str,
    file: &str,
    target: &Target,
) -> Result<(&'m DataValue, Origin, String)> {
    let Target::Named { name, index, span } = target else {
        return Err(input_err(src, file, target.span().start, "expected a name"));
    };
    let (di, decl) = lookup_or_err(module, src, file, span.start, name, "")?;
    let value = decl.value.as_ref().ok_or_else(|| {
        input_err(
            src,
            file,
            span.start,
            format!("`{name}` has no initial value"),
        )
    })?;
    match (index, value) {
        (None, DataValue::Array { .. }) => Err(input_err(
            src,
            file,
            span.start,
            format!("`{name}` is an array; index it"),
        )),
        (None, v) => Ok((
            v,
            Origin::Decl {
                decl: di,
                elem: None,
            },
            decl.name.clone(),
        )),
        (Some(ix), DataValue::Array { .. }) => {
            let ks = ix.literals().ok_or_else(|| {
                input_err(
                    src,
                    file,
                    ix.span.start,
                    format!(
                        "index `{}` is not an integer literal; it cannot be resolved offline",
                        ix.text
                    ),
                )
            })?;
            let (item, flat) = element_at(src, file, ix.span.start, decl, &ks)?;
            Ok((
                item,
                Origin::Decl {
                    decl: di,
                    elem: Some(flat),
                },
                element_stem(&decl.name, &ks),
            ))
        }
        (Some(_), _) => Err(input_err(
            src,
            file,
            span.start,
            format!("`{name}` is not an array"),
        )),
    }
}

/// The element of array declaration `d` at the 1-based indices `ks`, one
/// per dimension, with its place among the declaration's elements
/// (0-based, row by row: RAPID nests the value of `{2, 3}` as two
/// aggregates of three). Errors at `at`: no value, an index outside its
/// dimension, a count of indices that is not the array's.
pub(crate) fn element_at<'m>(
    src: &str,
    file: &str,
    at: usize,
    d: &'m Decl,
    ks: &[usize],
) -> Result<(&'m DataValue, usize)> {
    let name = &d.name;
    let mut value = d
        .value
        .as_ref()
        .ok_or_else(|| input_err(src, file, at, format!("`{name}` has no initial value")))?;
    let dims = || {
        let n = d.dims.len().max(1);
        let s = if n == 1 { "" } else { "s" };
        format!(
            "`{name}` has {n} dimension{s}; the index gives {}",
            ks.len()
        )
    };
    if !d.dims.is_empty() && d.dims.len() != ks.len() {
        return Err(input_err(src, file, at, dims()));
    }
    let mut flat = 0usize;
    for (level, &k) in ks.iter().enumerate() {
        let DataValue::Array { items, .. } = value else {
            let what = if level == 0 {
                format!("`{name}` is not an array")
            } else {
                dims()
            };
            return Err(input_err(src, file, at, what));
        };
        let Some((i, item)) = k.checked_sub(1).and_then(|i| Some((i, items.get(i)?))) else {
            return Err(input_err(
                src,
                file,
                at,
                format!("index {k} is outside `{name}` (1..={})", items.len()),
            ));
        };
        flat = flat * items.len() + i;
        value = item;
    }
    if matches!(value, DataValue::Array { .. }) {
        return Err(input_err(src, file, at, dims()));
    }
    Ok((value, flat))
}

/// How many elements an array value holds in all its dimensions (one for
/// a value that is not an array).
pub(crate) fn element_count(value: &DataValue) -> usize {
    match value {
        DataValue::Array { items, .. } => items.iter().map(element_count).sum(),
        _ => 1,
    }
}

/// The name stem of element `ks` of array `name`: `holes3`, `grid1_2`.
pub(crate) fn element_stem(name: &str, ks: &[usize]) -> String {
    let ks: Vec<String> = ks.iter().map(usize::to_string).collect();
    format!("{name}{}", ks.join("_"))
}

pub(crate) fn literal(src: &str, file: &str, s: &Scalar) -> Result<f64> {
    s.value.ok_or_else(|| {
        input_err(
            src,
            file,
            s.span.start,
            format!(
                "`{}` is not a numeric literal; it cannot be resolved offline",
                s.text
            ),
        )
    })
}

/// A robtarget use resolved to its pose in the object frame.
#[derive(Debug, Clone)]
pub(crate) struct CartUse<'m> {
    /// The literal whose numbers (conf, extax) are the template.
    pub(crate) rt: &'m RobTarget,
    pub(crate) origin: Origin,
    /// Name stem for new declarations (`p10`, `holes3`).
    pub(crate) stem: String,
    /// True for `Offs`/`RelTool`: the result is materialised.
    pub(crate) derived: bool,
    /// Identity of a derived target (offsets and rotations as written).
    pub(crate) derived_key: String,
    pub(crate) pose_obj: Isometry3<f64>,
    pub(crate) conf: ConfData,
}

pub(crate) fn resolve_cart<'m>(
    module: &'m Module,
    src: &str,
    file: &str,
    target: &'m Target,
) -> Result<CartUse<'m>> {
    let at = target.span().start;
    let bad_rt = |what: &str| input_err(src, file, at, what.to_string());
    // The robtarget an `Offs`/`RelTool` starts from, and its offsets.
    let offset_base =
        |base: &'m Target, offsets: &[Scalar; 3]| -> Result<(CartUse<'m>, [f64; 3])> {
            let b = resolve_cart(module, src, file, base)?;
            if b.derived {
                return Err(bad_rt("nested Offs/RelTool is not supported"));
            }
            let d = [
                literal(src, file, &offsets[0])?,
                literal(src, file, &offsets[1])?,
                literal(src, file, &offsets[2])?,
            ];
            Ok((b, d))
        };
    match target {
        Target::Inline(rt) => Ok(CartUse {
            rt,
            origin: Origin::Inline,
            stem: String::new(),
            derived: false,
            derived_key: String::new(),
            pose_obj: robtarget_pose(rt).ok_or_else(|| bad_rt("zero quaternion"))?,
            conf: conf_of(rt).ok_or_else(|| bad_rt("confdata must be integers"))?,
        }),
        Target::Named { .. } => {
            let (v, origin, stem) = named_value(module, src, file, target)?;
            let DataValue::RobTarget(rt) = v else {
                return Err(bad_rt("this move needs a robtarget"));
            };
            Ok(CartUse {
                rt,
                origin,
                stem,
                derived: false,
                derived_key: String::new(),
                pose_obj: robtarget_pose(rt).ok_or_else(|| bad_rt("zero quaternion"))?,
                conf: conf_of(rt).ok_or_else(|| bad_rt("confdata must be integers"))?,
            })
        }
        Target::Offs { base, offsets, .. } => {
            let (b, d) = offset_base(base, offsets)?;
            // Offs: translation along the object frame axes.
            let pose_obj = Isometry3::from_parts(
                Translation3::from(b.pose_obj.translation.vector + Vector3::from(d)),
                b.pose_obj.rotation,
            );
            Ok(CartUse {
                derived: true,
                derived_key: format!("offs {d:?}"),
                pose_obj,
                ..b
            })
        }
        Target::RelTool {
            base,
            offsets,
            rx,
            ry,
            rz,
            ..
        } => {
            let (b, d) = offset_base(base, offsets)?;
            let angle = |s: &Option<Scalar>| -> Result<f64> {
                match s {
                    Some(s) => Ok(literal(src, file, s)?.to_radians()),
                    None => Ok(0.0),
                }
            };
            let (ax, ay, az) = (angle(rx)?, angle(ry)?, angle(rz)?);
            // RelTool: translate along the tool axes, then rotate about the
            // tool x, the new y and the new z axis (intrinsic x-y-z).
            let rot = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), ax)
                * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), ay)
                * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), az);
            let pose_obj =
                b.pose_obj * Isometry3::from_parts(Translation3::new(d[0], d[1], d[2]), rot);
            Ok(CartUse {
                derived: true,
                derived_key: format!("reltool {d:?} {ax} {ay} {az}"),
                pose_obj,
                ..b
            })
        }
        Target::InlineJoint(_) => Err(bad_rt("a jointtarget needs MoveAbsJ")),
        Target::Other { text, .. } => Err(bad_rt(&format!(
            "target `{text}` is computed at run time; it cannot be compensated offline"
        ))),
    }
}

pub(crate) fn resolve_tool(module: &Module, src: &str, file: &str, mv: &Move) -> Result<ToolView> {
    let name = &*mv.tool.text;
    if name.eq_ignore_ascii_case("tool0") {
        return Ok(ToolView {
            tframe: Isometry3::identity(),
            load: None,
        });
    }
    let at = mv.tool.span.start;
    let (_, decl) = lookup_or_err(module, src, file, at, name, "tool")?;
    let Some(DataValue::ToolData(t)) = &decl.value else {
        return Err(input_err(
            src,
            file,
            at,
            format!("`{name}` is not a tooldata literal"),
        ));
    };
    if !t.robhold {
        return Err(input_err(
            src,
            file,
            at,
            format!("tool `{name}` is stationary (robhold FALSE): not supported"),
        ));
    }
    let tframe = pose_of(&t.tframe)
        .ok_or_else(|| input_err(src, file, at, format!("tool `{name}`: zero quaternion")))?;
    let mass = t.mass.value;
    if !mass.is_finite() || mass < 0.0 {
        return Err(input_err(
            src,
            file,
            t.mass.span.start,
            format!("tool `{name}`: mass {mass} must be a non-negative number"),
        ));
    }
    let load = (mass > 0.0).then(|| PointMass {
        mass_kg: mass,
        com_mm: Vector3::from(t.cog.each_ref().map(|n: &Number| n.value)),
    });
    Ok(ToolView { tframe, load })
}

pub(crate) fn resolve_wobj(
    module: &Module,
    src: &str,
    file: &str,
    mv: &Move,
) -> Result<Isometry3<f64>> {
    let Some(arg) = &mv.wobj else {
        return Ok(Isometry3::identity());
    };
    let name = &*arg.text;
    if name.eq_ignore_ascii_case("wobj0") {
        return Ok(Isometry3::identity());
    }
    let at = arg.span.start;
    let (_, decl) = lookup_or_err(module, src, file, at, name, "work object")?;
    let Some(DataValue::WobjData(w)) = &decl.value else {
        return Err(input_err(
            src,
            file,
            at,
            format!("`{name}` is not a wobjdata literal"),
        ));
    };
    if w.robhold || !w.ufprog {
        return Err(input_err(
            src,
            file,
            at,
            format!(
                "work object `{name}` is robot-held or moved by a mechanical unit: not supported"
            ),
        ));
    }
    match (pose_of(&w.uframe), pose_of(&w.oframe)) {
        (Some(u), Some(o)) => Ok(u * o),
        _ => Err(input_err(
            src,
            file,
            at,
            format!("work object `{name}`: zero quaternion"),
        )),
    }
}

/// Predefined ABB speeddata `vN` (TCP speed N mm/s); `vmax` is taken as
/// v7000.
pub(crate) const PREDEFINED_SPEEDS: [u32; 25] = [
    5, 10, 20, 30, 40, 50, 60, 80, 100, 150, 200, 300, 400, 500, 600, 800, 1000, 1500, 2000, 2500,
    3000, 4000, 5000, 6000, 7000,
];

/// TCP speed of a move, mm/s: `\V:=` if given as a number, else a
/// speeddata literal declared in the module, else a predefined `vN`.
pub(crate) fn tcp_speed(module: &Module, mv: &Move) -> Option<f64> {
    if let Some(v) = mv
        .opt("V")
        .and_then(|o| o.value.as_ref())
        .and_then(|a| a.text.trim().parse::<f64>().ok())
    {
        return (v.is_finite() && v > 0.0).then_some(v);
    }
    let name = mv.speed.text.trim();
    if let Some((_, decl)) = lookup(module, name) {
        return match &decl.value {
            Some(DataValue::SpeedData(sd)) => {
                let v = sd.values[0].value;
                (v.is_finite() && v > 0.0).then_some(v)
            }
            _ => None,
        };
    }
    if name.eq_ignore_ascii_case("vmax") {
        return Some(7000.0);
    }
    let n: u32 = name.strip_prefix(['v', 'V'])?.parse().ok()?;
    PREDEFINED_SPEEDS.contains(&n).then_some(f64::from(n))
}
