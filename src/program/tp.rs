//! FANUC TP (ASCII `.ls`) front end: [`syntax`] with spans, [`resolve`]
//! to the robot move stream.
//!
//! [`config`]: FANUC's joint angles and `CONFIG` in the robot model's
//! terms. Orientation `W, P, R` is [`crate::program::euler`].
//! grammar/tp.md documents the accepted subset.

pub mod config;
pub mod resolve;
pub mod syntax;

pub use syntax::{Group, Instruction, MnLine, Motion, Number, PosRef, Position, Program, parse};
