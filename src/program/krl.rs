//! KUKA KRL front end: [`syntax`] with spans, [`resolve`] into the robot
//! move stream ([`crate::program::robot_moves`]).
//!
//! [`config`]: KUKA's axis angles and Status/Turn in the robot model's
//! terms. Orientation `A, B, C` is [`crate::program::euler`].
//! grammar/krl.md documents the accepted subset.

pub mod config;
pub mod resolve;
pub mod syntax;

pub use syntax::{Aggregate, File, InlineForm, Kind, Line, Motion, Number, Target, Value, parse};
