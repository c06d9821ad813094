//! FANUC TP (ASCII `.ls`) front end (syntax and data only; not yet
//! compensated).
//!
//! [`config`]: FANUC's joint angles and `CONFIG` in the robot model's
//! terms. Orientation `W, P, R` is [`crate::program::euler`].
//! grammar/tp.md documents the accepted subset.

pub mod config;
pub mod syntax;

pub use syntax::{Group, Instruction, MnLine, Motion, Number, PosRef, Position, Program, parse};
