//! postproc — an offline compensation post-processor for CNC machine tools and
//! industrial robots.
//!
//! The pipeline: a program (G-code or ABB RAPID) is parsed syntactically
//! ([`program`]), interpreted into a stream of poses, predicted block by block
//! against a calibrated [`machine`] model ([`predict`]), compensated by an
//! inverse solve ([`compensate`]) and written back byte-faithfully ([`emit`]);
//! [`pipeline`] drives a whole program of either language through these
//! stages.
#![deny(missing_docs)]

pub mod calibrate;
pub mod cli;
pub mod compensate;
pub mod diagnose;
pub mod emit;
pub mod error;
pub mod limits;
pub mod machine;
pub mod pipeline;
pub mod predict;
pub mod process;
pub mod program;
pub mod verify;

pub use error::{Error, Result};
