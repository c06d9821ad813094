//! gcode (in progress).
