//! KUKA KRL front end (syntax and data only; not yet compensated).
//!
//! [`config`]: KUKA's axis angles and Status/Turn in the robot model's
//! terms. Orientation `A, B, C` is [`crate::program::euler`].
//! grammar/krl.md documents the accepted subset.

pub mod config;
pub mod resolve;
pub mod syntax;

pub use syntax::{Aggregate, File, InlineForm, Kind, Line, Motion, Number, Target, Value, parse};
