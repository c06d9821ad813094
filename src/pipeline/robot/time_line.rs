//! The robot time line, one for every robot language: what a move's
//! prediction needs from the moves before it. For each move in program
//! order its duration (at its TCP speed, or at the joints' rated speeds
//! for a joint move), its process wrench (`process_force:` of the robot
//! file: a constant force, a milling force or a drilling thrust from the
//! move's travel and speed, or a force table's row), the mean motor power
//! of each joint (gravity and process torques over the joint motion) and
//! the effective thermal power at its end (first order, from the start the
//! run asks for). RAPID ([`crate::pipeline::rapid`]) computes its moves'
//! wrenches, durations and powers with the functions here; the move stream
//! pipeline ([`super`], KUKA KRL) puts its whole stream on it with
//! [`of_stream`].

use nalgebra::{Isometry3, Vector3, Vector6};

use crate::machine::ThermalStart;
use crate::machine::robot::process::{feed_frame_vector, plunge_direction, travel_direction};
use crate::machine::robot::thermal::{Segment, effective_power};
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

/// One move of a stream put on the time line ([`of_stream`]), in the
/// world frame, on its robot view (tool mounted).
pub(crate) struct StreamMove<'a> {
    /// The robot view of the move.
    pub(crate) view: &'a Robot,
    /// Programmed TCP pose.
    pub(crate) pose: Isometry3<f64>,
    /// Programmed circle point of a circular move.
    pub(crate) via: Option<Vector3<f64>>,
    /// Programmed (controller) joints.
    pub(crate) q: [f64; 6],
    /// The work object in the world frame.
    pub(crate) wobj: Isometry3<f64>,
    /// Straight or circular (a feed move), and straight.
    pub(crate) feed: bool,
    /// A straight move.
    pub(crate) linear: bool,
    /// TCP speed, mm/s, when known offline.
    pub(crate) v_tcp: Option<f64>,
    /// 1-based line (the force table's key).
    pub(crate) line: usize,
}

/// What the time line gives each move of a stream: its prediction
/// context, duration and mean joint power.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Timed {
    /// The move's prediction context (process wrench, effective thermal
    /// power at its end, spindle speed and tooth frequency).
    pub(crate) ctx: MoveContext,
    /// Duration, s.
    pub(crate) duration_s: f64,
    /// Mean motor power per joint, W.
    pub(crate) power_w: [f64; 6],
}

/// What the run asks of the time line.
pub(crate) struct Asked<'a> {
    /// The process force is predicted.
    pub(crate) process: bool,
    /// The thermal drift is predicted.
    pub(crate) thermal: bool,
    /// The thermal state at the first move.
    pub(crate) start: ThermalStart,
    /// The run's force table.
    pub(crate) table: Option<&'a ForceTable>,
}

/// Why a stream move is refused by the time line: its index and the force
/// that needs its speed.
pub(crate) type NeedsSpeed = (usize, &'static str);

/// Puts the moves of a stream on the time line, in order. A straight or
/// circular move without a speed is taken at [`FALLBACK_TCP_SPEED`] (the
/// indices of those moves are pushed to `fallen_back`); a milling force or
/// a drilling thrust on it refuses the move ([`NeedsSpeed`]).
pub(crate) fn of_stream(
    robot: &Robot,
    moves: &[StreamMove],
    asked: &Asked,
    fallen_back: &mut Vec<usize>,
) -> std::result::Result<Vec<Timed>, NeedsSpeed> {
    let thermal = robot.thermal().filter(|_| asked.thermal);
    let need = asked.process || thermal.is_some();
    let pf = robot.process_force().map(|p| p.with_rpm(None));
    let set = CutSettings::default();
    let mut cache = MillingCache::default();
    let mut out: Vec<Timed> = Vec::with_capacity(moves.len());
    let mut segments = Vec::with_capacity(if thermal.is_some() { moves.len() } else { 0 });
    for (i, m) in moves.iter().enumerate() {
        let prev = i.checked_sub(1).and_then(|k| moves.get(k));
        let fallback = need && m.feed && m.v_tcp.is_none();
        if fallback {
            fallen_back.push(i);
        }
        let v_tcp = if fallback {
            Some(FALLBACK_TCP_SPEED)
        } else {
            m.v_tcp
        };
        let wrench = process_wrench(
            robot,
            &WrenchMove {
                feed: m.feed,
                linear: m.linear,
                prev: prev.map(|p| &p.pose.translation.vector),
                pose: &m.pose,
                via: m.via.as_ref(),
                wobj: &m.wobj,
                v_tcp,
                fallback,
                need_speed: need,
                table: asked.table.map(|t| (t, m.line)),
            },
            &set,
            &mut cache,
        )
        .map_err(|what| (i, what))?;
        let start = prev.map(|p| MoveEnd {
            at: &p.pose.translation.vector,
            via: None,
            q: Some(&p.q),
        });
        let cur = MoveEnd {
            at: &m.pose.translation.vector,
            via: m.via.as_ref(),
            q: Some(&m.q),
        };
        let duration_s = move_duration(robot, start, cur, !m.feed, v_tcp).unwrap_or(0.0);
        let power_w = match prev {
            Some(p) if need && duration_s > 0.0 => {
                let tau_a = m.view.nominal_load_torques(&p.q, wrench.as_ref());
                let tau_b = m.view.nominal_load_torques(&m.q, wrench.as_ref());
                mean_power((tau_a, tau_b), &p.q, &m.q, duration_s)
            }
            _ => [0.0; 6],
        };
        if thermal.is_some() {
            segments.push(Segment {
                duration_s,
                power_w,
            });
        }
        out.push(Timed {
            ctx: MoveContext {
                wrench,
                spindle_rpm: pf.and_then(|p| p.spindle_rpm).unwrap_or(0.0),
                tooth_hz: pf.and_then(|p| p.excitation_hz()).unwrap_or(0.0),
                ..MoveContext::default()
            },
            duration_s,
            power_w,
        });
    }
    if let Some(t) = thermal {
        let powers = effective_power(&segments, t.time_constant_s, asked.start);
        for (timed, p) in out.iter_mut().zip(powers) {
            timed.ctx.thermal = ThermalInput::JointPowers(p);
        }
    }
    Ok(out)
}
