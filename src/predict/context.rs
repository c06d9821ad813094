//! What a prediction needs to know about one move besides the machine
//! model: its time, the process load, the thermal input, spindle speed and
//! tooth frequency. The models are immutable; the caller computes one
//! [`MoveContext`] per move in program order (small and `Copy`: no
//! allocation per move) and hands it to the predictor of either machine
//! kind ([`super::ToolPredictor`], [`super::robot`]).

use nalgebra::Vector3;

use crate::machine::tool::ThermalState;
pub use crate::process::{Wrench, WrenchFrame};

/// The thermal input of a move: the machine tool's thermal error state, or
/// the effective motor power of each robot joint.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum ThermalInput {
    /// No heat: the machine tool at its cold state, the robot's joints at
    /// zero power.
    #[default]
    Cold,
    /// Thermal error parameters of a machine tool at the end of the move.
    Tool(ThermalState),
    /// Effective motor power of each robot joint, W.
    JointPowers([f64; 6]),
}

/// The per-move context of a prediction.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MoveContext {
    /// Time at the end of the move since the program start, s.
    pub time_s: f64,
    /// Process load on the tool with its frame (`None`: no load).
    pub wrench: Option<Wrench>,
    /// Thermal input at the end of the move.
    pub thermal: ThermalInput,
    /// Spindle speed, 1/min (0 when stopped or not known).
    pub spindle_rpm: f64,
    /// Tooth-passing frequency, Hz (0 without a cutting spindle).
    pub tooth_hz: f64,
    /// Predicted vibration amplitude per direction, mm, where the caller
    /// computes it (machine tools).
    pub vibration_mm: Vector3<f64>,
}

impl MoveContext {
    /// The force of the process load, N, in its frame (zero without one).
    #[inline]
    pub fn force_n(&self) -> Vector3<f64> {
        self.wrench.map_or_else(Vector3::zeros, |w| w.force_n)
    }

    /// The machine tool's thermal state (cold unless given).
    #[inline]
    pub fn tool_thermal(&self) -> ThermalState {
        match self.thermal {
            ThermalInput::Tool(t) => t,
            _ => ThermalState::default(),
        }
    }

    /// True when the machine tool's thermal state is not the cold one.
    #[inline]
    pub fn tool_warm(&self) -> bool {
        matches!(self.thermal, ThermalInput::Tool(t) if t != ThermalState::default())
    }

    /// The robot's effective joint powers, W (zero unless given).
    #[inline]
    pub fn joint_powers_w(&self) -> [f64; 6] {
        match self.thermal {
            ThermalInput::JointPowers(p) => p,
            _ => [0.0; 6],
        }
    }

    /// The same context with process load `wrench`.
    pub fn with_wrench(self, wrench: Option<Wrench>) -> Self {
        MoveContext { wrench, ..self }
    }

    /// The same context with the robot's joint powers `p_w` (W).
    pub fn with_joint_powers(self, p_w: [f64; 6]) -> Self {
        MoveContext {
            thermal: ThermalInput::JointPowers(p_w),
            ..self
        }
    }
}
