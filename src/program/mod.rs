//! Programs: syntax (G-code and RAPID parsers that keep byte spans) and the
//! modal interpretation that turns G-code blocks into a stream of moves.

pub mod gcode;
pub mod interp;
pub mod rapid;
