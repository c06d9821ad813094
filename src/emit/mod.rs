//! Writers: byte-faithful program emitters and deviation reports.

pub(crate) mod fixed;
pub mod gcode;
pub mod header;
pub mod html;
mod inverse_time;
pub mod krl;
pub mod rapid;
pub mod report;
pub mod subprograms;
pub mod svg;
pub mod tp;
