//! The pipelines: a whole program from input to output, one per language,
//! through the same stages — read, resolve or interpret to a typed move
//! stream, predict, compensate, emit, summary and report rows.
//!
//! [`gcode`] streams a G-code program in chunks; [`rapid`] compensates an
//! ABB RAPID module whole or a window at a time ([`rapid::stream`]). Both fill
//! the result types of [`crate::compensate::outcome`].

pub mod gcode;
pub mod rapid;
mod resonance;
pub mod robot;
pub mod shop;
