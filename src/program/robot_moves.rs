//! The language-neutral robot move stream: what a robot language's front
//! end hands to the robot pipeline.
//!
//! A front end (ABB RAPID today; KUKA KRL and FANUC TP next) reads its
//! language, resolves every motion instruction to what the controller will
//! do, and reports each one either as a resolved move or as a move it
//! leaves as written, with the reason. After it the pipeline is the same
//! for every language: the time line, the prediction, the compensation,
//! the records and the summary.
//!
//! What is left as written goes out on the one diagnostics channel of
//! every pipeline, [`crate::program::interp::Warning`], with a
//! [`LeftAsWritten`] that names the instruction, its column and the
//! reason: the summary counts them, `--strict` refuses the program at the
//! first one.

/// A motion instruction a front end leaves as written (its target is not
/// compensated), and why: the part of a [`crate::program::interp::Warning`]
/// that a `--strict` run refuses.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LeftAsWritten {
    /// 1-based byte column of the instruction's name.
    pub column: usize,
    /// The instruction's name as written (`MoveL`, `SpotL`).
    pub instruction: String,
    /// Why it is not compensated.
    pub reason: String,
}

impl LeftAsWritten {
    /// The warning of a move left as written at `line`, on the one
    /// diagnostics channel: `MoveL left as written (reason)`.
    pub fn warning(
        line: usize,
        column: usize,
        instruction: &str,
        reason: &str,
    ) -> crate::program::interp::Warning {
        crate::program::interp::Warning {
            line,
            message: format!("{instruction} left as written ({reason})"),
            count: 1,
            left: Some(LeftAsWritten {
                column,
                instruction: instruction.to_string(),
                reason: reason.to_string(),
            }),
        }
    }
}
