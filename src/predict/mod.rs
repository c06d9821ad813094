//! Per-point prediction: where the machine really puts the tool tip for a
//! commanded axis position, with each physical effect switched and scaled
//! separately (the thesis' VMSS idea), and the per-effect breakdown.

use nalgebra::Vector3;

use crate::error::{Error, Result};
use crate::machine::tool::MachineTool;
use crate::machine::{AxisVec, DirVec, TipPose};

/// The physical effects a prediction can include.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Effect {
    /// Geometric errors of the axes (location and component errors).
    Geometric,
}

impl Effect {
    /// Every effect, in breakdown order.
    pub const ALL: [Effect; 1] = [Effect::Geometric];

    /// Name used on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Effect::Geometric => "geometric",
        }
    }

    /// Short label used in annotations.
    pub fn short(self) -> &'static str {
        match self {
            Effect::Geometric => "geo",
        }
    }
}

/// Which effects are on and their gains.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EffectSet {
    gains: [f64; Effect::ALL.len()],
}

impl Default for EffectSet {
    fn default() -> Self {
        EffectSet {
            gains: [1.0; Effect::ALL.len()],
        }
    }
}

impl EffectSet {
    /// No effect on: prediction equals the nominal pose.
    pub fn none() -> Self {
        EffectSet {
            gains: [0.0; Effect::ALL.len()],
        }
    }

    /// Parses `--effects` (`all`, `none` or a comma-separated list of names).
    pub fn parse(spec: &str) -> Result<Self> {
        let spec = spec.trim();
        if spec == "all" {
            return Ok(Self::default());
        }
        let mut set = Self::none();
        if spec == "none" || spec.is_empty() {
            return Ok(set);
        }
        for name in spec.split(',') {
            let name = name.trim();
            let e = Effect::ALL
                .iter()
                .find(|e| e.name() == name)
                .ok_or_else(|| {
                    Error::Usage(format!(
                        "unknown effect `{name}` in --effects (known: all, none, {})",
                        names()
                    ))
                })?;
            set.gains[*e as usize] = 1.0;
        }
        Ok(set)
    }

    /// Applies `--gain name=value`.
    pub fn set_gain(&mut self, spec: &str) -> Result<()> {
        let (name, value) = spec
            .split_once('=')
            .ok_or_else(|| Error::Usage(format!("--gain expects NAME=VALUE, got `{spec}`")))?;
        let e = Effect::ALL
            .iter()
            .find(|e| e.name() == name.trim())
            .ok_or_else(|| {
                Error::Usage(format!(
                    "unknown effect `{name}` in --gain (known: {})",
                    names()
                ))
            })?;
        let v: f64 = value
            .trim()
            .parse()
            .map_err(|_| Error::Usage(format!("--gain {name}: `{value}` is not a number")))?;
        if !v.is_finite() || !(0.0..=10.0).contains(&v) {
            return Err(Error::Usage(format!("--gain {name}: {v} is outside 0..10")));
        }
        if self.gains[*e as usize] != 0.0 {
            self.gains[*e as usize] = v;
        }
        Ok(())
    }

    /// Gain of an effect (0 when off).
    pub fn gain(&self, e: Effect) -> f64 {
        self.gains[e as usize]
    }

    /// True when no effect is on.
    pub fn is_none(&self) -> bool {
        self.gains.iter().all(|&g| g == 0.0)
    }
}

fn names() -> String {
    Effect::ALL
        .iter()
        .map(|e| e.name())
        .collect::<Vec<_>>()
        .join(", ")
}

/// Predicted deviation of the tool tip, split by effect, mm.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Breakdown {
    /// Deviation vector of each effect, in [`Effect::ALL`] order.
    pub parts: [Vector3<f64>; Effect::ALL.len()],
    /// Tool-axis direction error (rad, small-angle vector).
    pub orientation: Vector3<f64>,
}

impl Breakdown {
    /// Total deviation vector.
    pub fn total(&self) -> Vector3<f64> {
        self.parts.iter().fold(Vector3::zeros(), |a, b| a + b)
    }
}

/// A machine tool with the effects chosen for one run. Immutable, shared by
/// the worker threads.
#[derive(Debug, Clone)]
pub struct ToolPredictor<'m> {
    /// The machine model.
    pub machine: &'m MachineTool,
    /// Effects and gains.
    pub effects: EffectSet,
}

impl<'m> ToolPredictor<'m> {
    /// Builds a predictor.
    pub fn new(machine: &'m MachineTool, effects: EffectSet) -> Self {
        ToolPredictor { machine, effects }
    }

    /// Nominal tool tip pose for commanded axes.
    pub fn nominal(&self, cmd: &AxisVec, tool_mm: f64) -> TipPose {
        self.machine.nominal(cmd, tool_mm)
    }

    /// Predicted attained tool tip pose for commanded axes.
    pub fn attained(&self, cmd: &AxisVec, dirs: &DirVec, tool_mm: f64) -> TipPose {
        let g = self.effects.gain(Effect::Geometric);
        if g == 0.0 {
            return self.machine.nominal(cmd, tool_mm);
        }
        let geo = self.machine.geometric(cmd, dirs, tool_mm);
        if g == 1.0 {
            return geo;
        }
        let nom = self.machine.nominal(cmd, tool_mm);
        let dir = nom.dir + (geo.dir - nom.dir) * g;
        TipPose {
            pos: nom.pos + (geo.pos - nom.pos) * g,
            dir: dir.normalize(),
        }
    }

    /// Predicted deviation (attained − nominal) with its breakdown.
    pub fn breakdown(&self, cmd: &AxisVec, dirs: &DirVec, tool_mm: f64) -> Breakdown {
        let nom = self.machine.nominal(cmd, tool_mm);
        let mut b = Breakdown::default();
        let g = self.effects.gain(Effect::Geometric);
        if g != 0.0 {
            let geo = self.machine.geometric(cmd, dirs, tool_mm);
            b.parts[Effect::Geometric as usize] = (geo.pos - nom.pos) * g;
            b.orientation = nom.dir.cross(&geo.dir) * g;
        }
        b
    }
}
