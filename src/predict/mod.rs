//! Forward prediction for both machine kinds: where the machine really puts
//! the tool for a commanded position, split by physical effect.
//!
//! * [`tool`] — the machine tool's per-block prediction ([`ToolPredictor`]);
//! * [`robot`] — the robot's per-target prediction through its stages;
//! * [`context`] — the one per-move context both take ([`MoveContext`]);
//! * [`effect`] — the one set of effects and gains ([`EffectSet`]) and the
//!   one per-effect breakdown ([`Breakdown`]) of both;
//! * [`uncertainty`] — the propagation of parameter uncertainty.
//!
//! The models (`crate::machine`) are immutable and carry no run state:
//! everything a move adds (time, process load, thermal input, spindle speed)
//! comes in its [`MoveContext`].

pub mod context;
pub mod effect;
pub mod robot;
pub mod robot_uncertainty;
pub mod tool;
pub mod uncertainty;

pub use context::{MoveContext, ThermalInput, Wrench, WrenchFrame};
pub use effect::{Breakdown, Effect, EffectSet, MachineKind, PoseDelta};
pub use tool::{LipschitzBound, ProcessSetup, ToolPredictor};
