//! Programs: syntax (G-code and RAPID parsers that keep byte spans) and the
//! modal interpretation that turns G-code blocks into a stream of moves.

pub mod charset;
pub mod directive;
pub mod euler;
pub mod gcode;
pub mod interp;
pub mod krl;
pub mod language;
pub mod rapid;
pub mod robot_moves;
pub mod tp;

/// The powers of ten that are exact in f64 (`1e0` to `1e22`): a decimal
/// literal of at most 15 significant digits scaled by one of them is
/// rounded once, as `str::parse` rounds it (the fast number paths of both
/// parsers).
pub(crate) const EXACT_POW10: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
    1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
];
