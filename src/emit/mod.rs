//! Writers: byte-faithful program emitters and deviation reports.

pub(crate) mod fixed;
pub mod gcode;
pub mod header;
pub mod html;
pub mod krl;
mod inverse_time;
pub mod rapid;
pub mod report;
pub mod subprograms;
pub mod svg;
