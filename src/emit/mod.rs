//! Writers: byte-faithful program emitters and deviation reports.

pub(crate) mod fixed;
pub mod gcode;
mod inverse_time;
pub mod header;
pub mod rapid;
pub mod report;
pub mod svg;
