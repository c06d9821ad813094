//! The physical effects of a prediction, the set of them a run switches on
//! with their gains, and the per-effect breakdown of a predicted deviation:
//! one of each for both machine kinds.
//!
//! A machine tool has geometric, static (deflection under the process
//! force), thermal and dynamic effects; a robot has kinematic (its geometric
//! errors: DH parameters), gravity, process (deflection under the process
//! wrench), thermal and dynamic effects. The same physics shares one
//! [`Effect`]: the robot's kinematic effect is [`Effect::Geometric`], its
//! process effect [`Effect::Static`]; [`Effect::Gravity`] is the robot's own.

use nalgebra::{Isometry3, Vector3};

use crate::error::Result;
use crate::machine::effects::{EffectName, EffectSpec, Gain, gains_for};
use crate::machine::robot::pose::pose_error;

/// The kind of machine a run predicts, for the effects it takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MachineKind {
    /// A machine tool (G-code).
    Tool,
    /// An industrial robot.
    Robot,
}

/// The physical effects a prediction can include.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Effect {
    /// Geometric errors: a machine tool's axis location and component
    /// errors, a robot's DH parameter errors (its `kinematic` effect).
    Geometric,
    /// Static deflection under the process load: a machine tool's stiffness
    /// map, a robot's joints under the process wrench (its `process`
    /// effect).
    Static,
    /// Thermal drift over the program's time line.
    Thermal,
    /// Vibration amplitude at the tooth-passing frequency (reported only).
    Dynamic,
    /// A robot's joint deflection under gravity.
    Gravity,
}

impl Effect {
    /// A machine tool's effects, in breakdown order.
    pub const TOOL: [Effect; 4] = [
        Effect::Geometric,
        Effect::Static,
        Effect::Thermal,
        Effect::Dynamic,
    ];

    /// A robot's effects, in the order its options list them.
    pub const ROBOT: [Effect; 5] = [
        Effect::Geometric,
        Effect::Gravity,
        Effect::Static,
        Effect::Thermal,
        Effect::Dynamic,
    ];

    /// Name used on the command line and in reports of a machine tool.
    pub fn name(self) -> &'static str {
        match self {
            Effect::Geometric => "geometric",
            Effect::Static => "static",
            Effect::Thermal => "thermal",
            Effect::Dynamic => "dynamic",
            Effect::Gravity => "gravity",
        }
    }

    /// Name used on the command line and in reports of a robot.
    pub fn robot_name(self) -> &'static str {
        match self {
            Effect::Geometric => "kinematic",
            Effect::Static => "process",
            e => e.name(),
        }
    }

    /// Short label used in annotations.
    pub fn short(self) -> &'static str {
        match self {
            Effect::Geometric => "geo",
            Effect::Static => "stat",
            Effect::Thermal => "therm",
            Effect::Dynamic => "vib",
            Effect::Gravity => "grav",
        }
    }

    /// The effect a command-line name means for a machine of `kind`
    /// (`None`: the name does not apply to it).
    pub fn named(name: EffectName, kind: MachineKind) -> Option<Effect> {
        use EffectName as N;
        match (name, kind) {
            (N::Geometric, _) | (N::Kinematic, MachineKind::Robot) => Some(Effect::Geometric),
            (N::Static, MachineKind::Tool) | (N::Process | N::Load, MachineKind::Robot) => {
                Some(Effect::Static)
            }
            (N::Gravity, MachineKind::Robot) => Some(Effect::Gravity),
            (N::Thermal, _) => Some(Effect::Thermal),
            (N::Dynamic, _) | (N::Vibration, MachineKind::Robot) => Some(Effect::Dynamic),
            _ => None,
        }
    }

    /// True for the effects that shift the tool tip and are compensated.
    pub fn compensated(self) -> bool {
        self != Effect::Dynamic
    }
}

/// Which effects are on and their gains: 0 = off, 1 = as modelled; other
/// values scale the effect linearly (geometric: the machine tool's error
/// terms times `gain`, the robot's DH parameters `gain` of the way from
/// nominal to actual; thermal: the drift or DH growth times `gain`; static,
/// gravity: the deflection or torques times `gain`; dynamic: the reported
/// amplitude times `gain`). A machine tool reads no gravity gain.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EffectSet {
    /// [`Effect::Geometric`]: geometric errors (robots: actual instead of
    /// nominal DH parameters).
    pub kinematic: f64,
    /// [`Effect::Gravity`]: robot joint deflection from gravity.
    pub gravity: f64,
    /// [`Effect::Static`]: deflection under the process force or wrench.
    pub process: f64,
    /// [`Effect::Thermal`]: thermal drift.
    pub thermal: f64,
    /// [`Effect::Dynamic`]: vibration amplitude (reported, never
    /// compensated).
    pub dynamic: f64,
}

impl Default for EffectSet {
    fn default() -> Self {
        EffectSet::ALL
    }
}

impl EffectSet {
    /// Every effect on.
    pub const ALL: EffectSet = EffectSet {
        kinematic: 1.0,
        gravity: 1.0,
        process: 1.0,
        thermal: 1.0,
        dynamic: 1.0,
    };

    /// Every effect off (prediction = the nominal model).
    pub const NONE: EffectSet = EffectSet {
        kinematic: 0.0,
        gravity: 0.0,
        process: 0.0,
        thermal: 0.0,
        dynamic: 0.0,
    };

    /// No effect on: prediction equals the nominal pose.
    pub fn none() -> Self {
        EffectSet::NONE
    }

    /// The effects `--effects` turns on for a machine of `kind`, scaled by
    /// `--gain`; names that do not apply to it (a tool's `gravity`, a
    /// robot's `static`, …) are refused.
    pub fn from_flags(spec: &EffectSpec, gains: &[Gain], kind: MachineKind) -> Result<Self> {
        let (list, engine): (&[Effect], _) = match kind {
            MachineKind::Tool => (&Effect::TOOL, "a machine tool"),
            MachineKind::Robot => (&Effect::ROBOT, "a robot"),
        };
        let label = |e: &Effect| match kind {
            MachineKind::Tool => e.name(),
            MachineKind::Robot => e.robot_name(),
        };
        let known = list.iter().map(label).collect::<Vec<_>>().join(", ");
        let slot = |name| Effect::named(name, kind).map(|e| e as usize);
        let g: [f64; 5] = gains_for(spec, gains, slot, engine, &known)?;
        let mut set = EffectSet::NONE;
        for &e in list {
            set = set.with_gain(e, g[e as usize]);
        }
        Ok(set)
    }

    /// The same set with effect `e` at gain `g` (0: off).
    pub fn with_gain(mut self, e: Effect, g: f64) -> Self {
        *self.slot(e) = g;
        self
    }

    fn slot(&mut self, e: Effect) -> &mut f64 {
        match e {
            Effect::Geometric => &mut self.kinematic,
            Effect::Static => &mut self.process,
            Effect::Thermal => &mut self.thermal,
            Effect::Dynamic => &mut self.dynamic,
            Effect::Gravity => &mut self.gravity,
        }
    }

    /// Gain of an effect (0 when off).
    pub fn gain(&self, e: Effect) -> f64 {
        match e {
            Effect::Geometric => self.kinematic,
            Effect::Static => self.process,
            Effect::Thermal => self.thermal,
            Effect::Dynamic => self.dynamic,
            Effect::Gravity => self.gravity,
        }
    }

    /// True when no effect is on.
    pub fn is_none(&self) -> bool {
        *self == EffectSet::NONE
    }

    /// True when some quasi-static effect (one that changes targets) is on.
    pub fn compensates(&self) -> bool {
        self.kinematic != 0.0 || self.gravity != 0.0 || self.process != 0.0 || self.thermal != 0.0
    }
}

/// A small pose difference: attained − reference.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PoseDelta {
    /// Position difference, mm (world frame).
    pub pos_mm: Vector3<f64>,
    /// Orientation difference, rad (small-angle vector, world frame): the
    /// rotation vector of `R_attained · R_referenceᵀ` (robots), the tool
    /// axis direction error (machine tools, total only).
    pub rot_rad: Vector3<f64>,
}

impl PoseDelta {
    /// The difference of two poses.
    pub(crate) fn between(attained: &Isometry3<f64>, reference: &Isometry3<f64>) -> Self {
        let (p, r) = pose_error(attained, reference);
        PoseDelta {
            pos_mm: p,
            rot_rad: r,
        }
    }

    /// A position difference only.
    pub fn pos(pos_mm: Vector3<f64>) -> Self {
        PoseDelta {
            pos_mm,
            rot_rad: Vector3::zeros(),
        }
    }
}

/// Predicted deviation of the tool tip (TCP), split by effect. The
/// compensated parts sum to `total`'s position (a robot's parts are
/// successive differences of its stages); the vibration amplitude is
/// reported beside them and is never part of `total`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Breakdown {
    /// [`Effect::Geometric`]: geometric (robots: actual vs nominal
    /// parameters at the commanded joints).
    pub kinematic: PoseDelta,
    /// [`Effect::Thermal`]: thermal drift (robots: added by the thermal
    /// growth of the DH lengths).
    pub thermal: PoseDelta,
    /// [`Effect::Gravity`]: added by gravity deflection (robots).
    pub gravity: PoseDelta,
    /// [`Effect::Static`]: added by the deflection under the process load.
    pub process: PoseDelta,
    /// Attained − programmed (machine tools: the sum of the compensated
    /// parts, with the tool axis direction error).
    pub total: PoseDelta,
    /// [`Effect::Dynamic`]: predicted vibration amplitude per direction,
    /// mm (reported, not part of `total`).
    pub vibration_mm: Vector3<f64>,
}

impl Breakdown {
    /// Total deviation vector of the compensated (quasi-static) effects,
    /// mm: the position of `total`.
    pub fn total(&self) -> Vector3<f64> {
        self.total.pos_mm
    }

    /// The position part of one effect, mm (dynamic: the amplitude).
    pub fn part(&self, e: Effect) -> Vector3<f64> {
        match e {
            Effect::Geometric => self.kinematic.pos_mm,
            Effect::Static => self.process.pos_mm,
            Effect::Thermal => self.thermal.pos_mm,
            Effect::Gravity => self.gravity.pos_mm,
            Effect::Dynamic => self.vibration_mm,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flags(spec: &str, gains: &[&str], kind: MachineKind) -> Result<EffectSet> {
        let spec: EffectSpec = spec.parse().expect("spec");
        let gains: Vec<Gain> = gains.iter().map(|g| g.parse().expect("gain")).collect();
        EffectSet::from_flags(&spec, &gains, kind)
    }

    #[test]
    fn one_effect_set_reads_each_kinds_names() {
        let tool = flags("all", &["static=0.5"], MachineKind::Tool).expect("tool");
        assert_eq!(
            tool,
            EffectSet {
                gravity: 0.0,
                process: 0.5,
                ..EffectSet::ALL
            }
        );
        let robot = flags(
            "kinematic,load,vibration",
            &["process=2"],
            MachineKind::Robot,
        )
        .expect("robot");
        assert_eq!(
            robot,
            EffectSet {
                kinematic: 1.0,
                process: 2.0,
                dynamic: 1.0,
                ..EffectSet::NONE
            }
        );
        assert_eq!(
            flags("all", &[], MachineKind::Robot).ok(),
            Some(EffectSet::ALL)
        );
        let err = flags("gravity", &[], MachineKind::Tool).expect_err("a robot effect");
        assert!(
            err.to_string().contains(
                "unknown effect `gravity` in --effects for a machine tool (known: geometric, static, thermal, dynamic)"
            ),
            "{err}"
        );
        let err = flags("all", &["static=1"], MachineKind::Robot).expect_err("a tool effect");
        assert!(
            err.to_string().contains(
                "unknown effect `static` in --gain for a robot (known: kinematic, gravity, process, thermal, dynamic)"
            ),
            "{err}"
        );
        assert!(
            flags("none", &[], MachineKind::Tool)
                .expect("none")
                .is_none()
        );
    }

    #[test]
    fn gains_and_parts_address_the_same_effect() {
        let mut b = Breakdown::default();
        b.kinematic.pos_mm.x = 1.0;
        b.process.pos_mm.x = 2.0;
        b.thermal.pos_mm.x = 3.0;
        b.gravity.pos_mm.x = 4.0;
        b.vibration_mm.x = 5.0;
        for (k, e) in [
            Effect::Geometric,
            Effect::Static,
            Effect::Thermal,
            Effect::Gravity,
            Effect::Dynamic,
        ]
        .into_iter()
        .enumerate()
        {
            assert_eq!(b.part(e).x, k as f64 + 1.0, "{e:?}");
            let set = EffectSet::NONE.with_gain(e, 0.5);
            assert_eq!(set.gain(e), 0.5, "{e:?}");
            assert_eq!(
                Effect::ROBOT
                    .iter()
                    .filter(|&&x| set.gain(x) != 0.0)
                    .count(),
                1
            );
        }
    }
}
