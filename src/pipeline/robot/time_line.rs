//! The robot time line, one for every robot language: what a move's
//! prediction needs from the moves before it. For each move in program
//! order its duration (at its TCP speed, or at the joints' rated speeds
//! for a joint move), its process wrench (`process_force:` of the robot
//! file: a constant force, a milling force or a drilling thrust from the
//! move's travel and speed, or a force table's row), the mean motor power
//! of each joint (gravity and process torques over the joint motion) and
//! the effective thermal power at its end (first order, from the start the
//! run asks for). Every robot language puts its moves on it with [`put`]:
//! the move stream pipeline ([`super`], KUKA KRL and FANUC TP) its whole
//! stream, RAPID ([`crate::pipeline::rapid`]) each window of its module,
//! continuing the windows before.

use nalgebra::{Isometry3, Vector3, Vector6};
use rayon::prelude::*;

use crate::machine::ThermalStart;
use crate::machine::robot::process::{feed_frame_vector, plunge_direction, travel_direction};
use crate::machine::robot::thermal::{Segment, effective_power, effective_power_from};
use crate::machine::robot::{ForceModel, Robot};
use crate::predict::{MoveContext, ThermalInput, Wrench, WrenchFrame};
use crate::process::{CutSettings, ForceTable, Frame, MillingCache};

/// TCP speed a straight or circular move whose speed is known at run time
/// only is taken at on the time line, mm/s: that of ABB's predefined
/// `vmax`, the robot's maximum (rated) TCP speed. Said in a warning.
pub const FALLBACK_TCP_SPEED: f64 = 7000.0;

/// What the process wrench of a move depends on (world frame).
pub(crate) struct WrenchMove<'a> {
    /// A feed move: straight or circular (a joint move never cuts).
    pub(crate) feed: bool,
    /// A straight move (the only one that drills).
    pub(crate) linear: bool,
    /// Programmed TCP position of the move before, mm.
    pub(crate) prev: Option<&'a Vector3<f64>>,
    /// Programmed TCP pose of the move.
    pub(crate) pose: &'a Isometry3<f64>,
    /// Programmed circle point of a circular move, mm.
    pub(crate) via: Option<&'a Vector3<f64>>,
    /// The work object in the world frame.
    pub(crate) wobj: &'a Isometry3<f64>,
    /// TCP speed, mm/s, when known (or its fallback).
    pub(crate) v_tcp: Option<f64>,
    /// `v_tcp` is [`FALLBACK_TCP_SPEED`]: known at run time only.
    pub(crate) fallback: bool,
    /// A force that needs the speed refuses a move without it.
    pub(crate) need_speed: bool,
    /// The force table of the run and the move's line.
    pub(crate) table: Option<(&'a ForceTable, usize)>,
}

/// The process wrench of a move (see `grammar/rapid.md`, "Process force"):
/// a constant force or a milling force on feed moves; a drilling thrust on
/// straight plunges (along +tool z) at a drilling feed; a table force on
/// the moves whose line has a row; none otherwise. `set`: the program's
/// cut settings in force at the move. `Err(what)`: the force `what` needs
/// the move's TCP speed, known at run time only.
pub(crate) fn process_wrench(
    robot: &Robot,
    m: &WrenchMove,
    set: &CutSettings,
    cache: &mut MillingCache,
) -> std::result::Result<Option<Wrench>, &'static str> {
    let Some(pf) = robot.process_force() else {
        return Ok(None);
    };
    let pf = pf.with_rpm(set.spindle_rpm);
    let z = m.pose.rotation * Vector3::z();
    // Direction of travel at the target (world frame); zero for the first
    // move.
    let travel = || {
        m.prev.map_or_else(Vector3::zeros, |p| {
            travel_direction(p, m.via, &m.pose.translation.vector)
        })
    };
    let to_base = robot.base().rotation.inverse();
    let in_base = |force_n: Vector3<f64>, moment_nmm: Vector3<f64>| Wrench {
        force_n: to_base * force_n,
        moment_nmm: to_base * moment_nmm,
        frame: WrenchFrame::Base,
    };
    let speed = |what: &'static str| match m.v_tcp {
        Some(v) if !m.fallback => Ok(Some(v)),
        _ if m.need_speed => Err(what),
        _ => Ok(None),
    };
    match pf.model {
        ForceModel::Constant {
            force_n,
            moment_nmm,
            frame,
        } => {
            if !m.feed {
                return Ok(None);
            }
            Ok(Some(match frame {
                Frame::Tool | Frame::Base => Wrench {
                    force_n,
                    moment_nmm,
                    frame: if frame == Frame::Tool {
                        WrenchFrame::Tool
                    } else {
                        WrenchFrame::Base
                    },
                },
                Frame::Workpiece => {
                    let r = robot.base().rotation.inverse() * m.wobj.rotation;
                    Wrench {
                        force_n: r * force_n,
                        moment_nmm: r * moment_nmm,
                        frame: WrenchFrame::Base,
                    }
                }
                Frame::Feed => {
                    // In the work object's frame, as on a machine tool: a
                    // plunge along the tool axis (no tangential direction)
                    // takes the work object's x, which moves with the cell,
                    // not the world's.
                    let w = m.wobj.rotation;
                    let (t, z) = (w.inverse() * travel(), w.inverse() * z);
                    in_base(
                        w * feed_frame_vector(&force_n, &t, &z),
                        w * feed_frame_vector(&moment_nmm, &t, &z),
                    )
                }
            }))
        }
        ForceModel::Milling(_) => {
            if !m.feed || m.prev.is_none() {
                return Ok(None);
            }
            let Some(v) = speed("milling force")? else {
                return Ok(None);
            };
            Ok(pf
                .milling_force(&travel(), &z, v, set, cache)
                .map(|l| in_base(l.force_n, Vector3::zeros())))
        }
        ForceModel::Drilling { .. } => {
            let Some(prev) = m.prev else {
                return Ok(None);
            };
            if !m.linear {
                return Ok(None);
            }
            let d = m.pose.translation.vector - prev;
            if plunge_direction(&d, &z, pf.axis_tolerance_rad) != Some(true) {
                return Ok(None);
            }
            // A speed known at run time only is taken as the fallback's, a
            // positioning speed: no thrust (said in the warning).
            if m.fallback {
                return Ok(None);
            }
            Ok(speed("drilling thrust")?.and_then(|v| pf.drilling_wrench(v, &(to_base * z))))
        }
        ForceModel::Table => Ok(m
            .table
            .and_then(|(t, line)| t.get(line))
            .map(|f| in_base(m.wobj.rotation * f, Vector3::zeros()))),
    }
}

/// One end of a move on the time line: the programmed TCP position and
/// circle point (mm, world frame) and the controller joints when known.
#[derive(Clone, Copy)]
pub(crate) struct MoveEnd<'a> {
    /// Programmed TCP position.
    pub(crate) at: &'a Vector3<f64>,
    /// Programmed circle point of a circular move.
    pub(crate) via: Option<&'a Vector3<f64>>,
    /// Controller joints, rad.
    pub(crate) q: Option<&'a [f64; 6]>,
}

/// Estimated duration of a move from `prev` to `cur`, s: a straight or
/// circular move (`joint` false) at its TCP speed (a circle along the two
/// chords through its circle point); a joint move at the larger of the
/// TCP-speed time and the time the slowest joint needs at its rated speed.
/// The first move (no known start) takes 0 s; `None`: a straight move
/// without a speed.
pub(crate) fn move_duration(
    robot: &Robot,
    prev: Option<MoveEnd>,
    cur: MoveEnd,
    joint: bool,
    v_tcp: Option<f64>,
) -> Option<f64> {
    let Some(prev) = prev else {
        return Some(0.0);
    };
    let (p0, p1) = (prev.at, cur.at);
    let dist = match cur.via {
        Some(v) => (v - p0).norm() + (p1 - v).norm(),
        None => (p1 - p0).norm(),
    };
    let t_tcp = v_tcp.map(|v| dist / v);
    if !joint {
        return t_tcp;
    }
    let t_joint = match (prev.q, cur.q) {
        (Some(a), Some(b)) => (0..6)
            .map(|j| (b[j] - a[j]).abs() / robot.joint_speed_rad_per_s()[j])
            .fold(0.0, f64::max),
        _ => 0.0,
    };
    Some(t_tcp.unwrap_or(0.0).max(t_joint))
}

/// Mean motor power per joint during a move from joints `qa` to `qb` of
/// `duration_s` (> 0), W: `|τ·q̇|` with `τ` the load torques averaged over
/// the two ends (`tau_a`, `tau_b`, N·mm) and `q̇` the joint change over the
/// duration.
pub(crate) fn mean_power(
    (tau_a, tau_b): (Vector6<f64>, Vector6<f64>),
    qa: &[f64; 6],
    qb: &[f64; 6],
    duration_s: f64,
) -> [f64; 6] {
    let t = (tau_a + tau_b) * 0.5e-3;
    std::array::from_fn(|j| (t[j] * (qb[j] - qa[j]) / duration_s).abs())
}

/// One move put on the time line ([`put`]), in the world frame, on its
/// robot view (tool mounted).
pub(crate) struct StreamMove<'a> {
    /// The robot view of the move.
    pub(crate) view: &'a Robot,
    /// What names the view (moves with equal keys share it).
    pub(crate) key: &'a str,
    /// Programmed TCP pose.
    pub(crate) pose: Isometry3<f64>,
    /// Programmed circle point of a circular move.
    pub(crate) via: Option<Vector3<f64>>,
    /// Programmed (controller) joints, when the target is reachable.
    pub(crate) q: Option<[f64; 6]>,
    /// The work object in the world frame.
    pub(crate) wobj: Isometry3<f64>,
    /// Straight or circular (a feed move), and straight.
    pub(crate) feed: bool,
    /// A straight move.
    pub(crate) linear: bool,
    /// TCP speed, mm/s, when known offline (or its fallback).
    pub(crate) v_tcp: Option<f64>,
    /// `v_tcp` is [`FALLBACK_TCP_SPEED`]: known at run time only.
    pub(crate) fallback: bool,
    /// 1-based line (the force table's key).
    pub(crate) line: usize,
    /// The program's cut settings in force at the move.
    pub(crate) set: CutSettings,
}

/// What the time line gives each move: its prediction context, duration,
/// mean joint power and, when asked, the nominal flange at its end.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Timed {
    /// The move's prediction context (process wrench, effective thermal
    /// power at its end, spindle speed and tooth frequency).
    pub(crate) ctx: MoveContext,
    /// Duration, s.
    pub(crate) duration_s: f64,
    /// Mean motor power per joint, W.
    pub(crate) power_w: [f64; 6],
    /// Nominal flange at the move's end (its programmed joints), when both
    /// ends are solved, the duration is positive and [`Asked::flanges`].
    pub(crate) flange: Option<Isometry3<f64>>,
}

impl Timed {
    /// The move's segment of the thermal time line.
    pub(crate) fn segment(&self) -> Segment {
        Segment {
            duration_s: self.duration_s,
            power_w: self.power_w,
        }
    }
}

/// What the run asks of the time line.
pub(crate) struct Asked<'a> {
    /// The process force is predicted.
    pub(crate) process: bool,
    /// The thermal drift is predicted.
    pub(crate) thermal: bool,
    /// The thermal state at the first move.
    pub(crate) start: ThermalStart,
    /// The effective thermal power at the start of the first move, when
    /// the time line continues one before (`start` otherwise).
    pub(crate) x0: Option<[f64; 6]>,
    /// The effective thermal power of each move is wanted (a first pass
    /// that only adds up the segments does without).
    pub(crate) effective: bool,
    /// The joint powers are wanted even without a thermal drift (for the
    /// report's rows).
    pub(crate) power: bool,
    /// The nominal flange at each move's end is wanted (the first stage of
    /// a compensation's breakdown).
    pub(crate) flanges: bool,
    /// The run's force table.
    pub(crate) table: Option<&'a ForceTable>,
}

/// Why a move is refused by the time line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Refusal {
    /// The force named needs the move's TCP speed, known at run time only.
    NeedsSpeed(&'static str),
    /// The thermal time line needs the speed of a straight move without
    /// one.
    NoDuration,
}

/// The view key, joints (bits), wrench (bits) and nominal load torques at
/// the end of the last move whose power was computed: the start of the
/// next move when it continues on the same view with the same wrench.
pub(crate) type LastEnd = Option<(String, Option<WrenchBits>, [u64; 6], Vector6<f64>)>;

/// A process wrench as bit patterns (a hashable key).
pub(crate) type WrenchBits = ([u64; 6], bool);

/// The bit patterns of a wrench.
pub(crate) fn wrench_bits(w: &Wrench) -> WrenchBits {
    (
        [
            w.force_n.x,
            w.force_n.y,
            w.force_n.z,
            w.moment_nmm.x,
            w.moment_nmm.y,
            w.moment_nmm.z,
        ]
        .map(f64::to_bits),
        w.in_tool_frame(),
    )
}

/// Puts `moves[o..]` on the time line, in order, after `moves[..o]` (the
/// last move of a part of the program put on it before, or none): one
/// [`Timed`] per move of `moves[o..]`. `last` carries the torques at the
/// end of the last move across calls. `Err((i, why))`: move `o + i` is
/// refused.
pub(crate) fn put(
    robot: &Robot,
    moves: &[StreamMove],
    o: usize,
    asked: &Asked,
    last: &mut LastEnd,
) -> std::result::Result<Vec<Timed>, (usize, Refusal)> {
    let thermal = robot.thermal().filter(|_| asked.thermal);
    let need = asked.process || thermal.is_some();
    let n = moves.len().saturating_sub(o);
    let mut cache = MillingCache::default();
    let mut out: Vec<Timed> = Vec::with_capacity(n);
    // The wrenches first, then the durations: the first refusal of each
    // kind in move order.
    for i in o..moves.len() {
        let m = &moves[i];
        let prev = i.checked_sub(1).and_then(|k| moves.get(k));
        let wrench = process_wrench(
            robot,
            &WrenchMove {
                feed: m.feed,
                linear: m.linear,
                prev: prev.map(|p| &p.pose.translation.vector),
                pose: &m.pose,
                via: m.via.as_ref(),
                wobj: &m.wobj,
                v_tcp: m.v_tcp,
                fallback: m.fallback,
                need_speed: need,
                table: asked.table.map(|t| (t, m.line)),
            },
            &m.set,
            &mut cache,
        )
        .map_err(|what| (i - o, Refusal::NeedsSpeed(what)))?;
        let pf = robot.process_force().map(|p| p.with_rpm(m.set.spindle_rpm));
        out.push(Timed {
            ctx: MoveContext {
                wrench,
                spindle_rpm: pf.and_then(|p| p.spindle_rpm).unwrap_or(0.0),
                tooth_hz: pf.and_then(|p| p.excitation_hz()).unwrap_or(0.0),
                ..MoveContext::default()
            },
            ..Timed::default()
        });
    }
    for (i, t) in out.iter_mut().enumerate() {
        let (prev, m) = (
            (i + o).checked_sub(1).and_then(|k| moves.get(k)),
            &moves[i + o],
        );
        let start = prev.map(|p| MoveEnd {
            at: &p.pose.translation.vector,
            via: None,
            q: p.q.as_ref(),
        });
        let cur = MoveEnd {
            at: &m.pose.translation.vector,
            via: m.via.as_ref(),
            q: m.q.as_ref(),
        };
        t.duration_s = match move_duration(robot, start, cur, !m.feed, m.v_tcp) {
            Some(d) => d,
            None if thermal.is_some() => return Err((i, Refusal::NoDuration)),
            None => 0.0,
        };
    }
    powers(
        moves,
        o,
        asked.power || thermal.is_some(),
        asked.flanges,
        &mut out,
        last,
    );
    if let Some(t) = thermal.filter(|_| asked.effective) {
        let segments: Vec<Segment> = out.iter().map(Timed::segment).collect();
        let powers = match asked.x0 {
            Some(x0) => effective_power_from(&segments, t.time_constant_s, x0),
            None => effective_power(&segments, t.time_constant_s, asked.start),
        };
        for (timed, p) in out.iter_mut().zip(powers) {
            timed.ctx.thermal = ThermalInput::JointPowers(p);
        }
    }
    Ok(out)
}

/// The joint powers of the moves `out` (of `moves[o..]`, with `power`)
/// and the nominal flange at each move's end (with `flanges`). The load
/// torques and flange at each end (the costly part) are computed in
/// parallel; the power chains the moves (a move starts where the one
/// before ended, with the torques computed there when its view and wrench
/// are the same).
fn powers(
    moves: &[StreamMove],
    o: usize,
    power: bool,
    flanges: bool,
    out: &mut [Timed],
    last: &mut LastEnd,
) {
    if !power && !flanges {
        return;
    }
    let ends: Vec<Option<(Vector6<f64>, Isometry3<f64>)>> = (0..out.len())
        .into_par_iter()
        .map(|i| {
            let t = out.get(i)?;
            moves.get((i + o).checked_sub(1)?)?.q?;
            let m = moves.get(i + o)?;
            let qb = m.q?;
            if t.duration_s <= 0.0 {
                return None;
            }
            Some(
                m.view
                    .nominal_load_torques_and_flange(&qb, t.ctx.wrench.as_ref()),
            )
        })
        .collect();
    for (i, (t, end)) in out.iter_mut().zip(ends).enumerate() {
        let Some((tau_b, flange)) = end else {
            continue;
        };
        if flanges {
            t.flange = Some(flange);
        }
        if !power {
            continue;
        }
        // `end` is Some: both ends are solved.
        let (Some(qa), Some(m)) = (
            (i + o).checked_sub(1).and_then(|k| moves.get(k)?.q),
            moves.get(i + o),
        ) else {
            continue;
        };
        let Some(qb) = m.q else {
            continue;
        };
        let bits = t.ctx.wrench.as_ref().map(wrench_bits);
        let qa_bits = qa.map(f64::to_bits);
        let tau_a = match last {
            Some((k, b, q, tau)) if k == m.key && *b == bits && *q == qa_bits => *tau,
            _ => m.view.nominal_load_torques(&qa, t.ctx.wrench.as_ref()),
        };
        match last {
            Some((k, b, q, tau)) if k == m.key => {
                (*b, *q, *tau) = (bits, qb.map(f64::to_bits), tau_b);
            }
            _ => *last = Some((m.key.to_string(), bits, qb.map(f64::to_bits), tau_b)),
        }
        t.power_w = mean_power((tau_a, tau_b), &qa, &qb, t.duration_s);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::machine::robot::Model;

    /// Straight moves at 100 mm/s through joint positions of the IRB 1600
    /// (thermal model and process force of its file).
    fn path(robot: &Robot) -> Vec<StreamMove<'_>> {
        (0..6)
            .map(|i| {
                let t = f64::from(i) * 0.05;
                let q = [t, -0.2 + t, 0.3 - t, 0.1, 0.4 + t, -t];
                StreamMove {
                    view: robot,
                    key: "tool0",
                    pose: robot.tcp_pose(Model::Nominal, &q),
                    via: None,
                    q: Some(q),
                    wobj: Isometry3::identity(),
                    feed: true,
                    linear: true,
                    v_tcp: Some(100.0),
                    fallback: false,
                    line: i as usize + 1,
                    set: CutSettings::default(),
                }
            })
            .collect()
    }

    fn asked(x0: Option<[f64; 6]>) -> Asked<'static> {
        Asked {
            process: true,
            thermal: true,
            start: ThermalStart::Cold,
            x0,
            effective: true,
            power: true,
            flanges: true,
            table: None,
        }
    }

    /// A time line put in two parts (the second continuing from the last
    /// move, the thermal state and the end torques of the first) gives
    /// every move the same bits as the whole put at once: a module read a
    /// window at a time is timed as if whole.
    #[test]
    fn a_time_line_put_in_parts_is_the_whole_one() {
        let robot = Robot::from_yaml_str(
            include_str!("../../../machines/abb-irb1600.yaml"),
            "abb-irb1600.yaml",
        )
        .unwrap();
        let moves = path(&robot);
        let whole = put(&robot, &moves, 0, &asked(None), &mut None).unwrap();
        let mut last = None;
        let mut parts = put(&robot, &moves[..3], 0, &asked(None), &mut last).unwrap();
        let x0 = match parts.last().map(|t| t.ctx.thermal) {
            Some(ThermalInput::JointPowers(p)) => Some(p),
            _ => None,
        };
        assert!(x0.is_some(), "the thermal model gives joint powers");
        parts.extend(put(&robot, &moves[2..], 1, &asked(x0), &mut last).unwrap());
        assert_eq!(parts.len(), whole.len());
        assert!(
            whole[1..]
                .iter()
                .all(|t| t.power_w.iter().any(|p| *p > 0.0))
        );
        for (a, b) in whole.iter().zip(&parts) {
            assert_eq!(a.duration_s.to_bits(), b.duration_s.to_bits());
            assert_eq!(a.power_w.map(f64::to_bits), b.power_w.map(f64::to_bits));
            assert_eq!(a.ctx, b.ctx);
            assert_eq!(a.flange, b.flange);
        }
    }
}
