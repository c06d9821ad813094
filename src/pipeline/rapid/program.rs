//! Compensation of one module of a RAPID program of several modules
//! ([`crate::program::rapid::program`]): the module is resolved with the
//! global declarations of the other modules after its own, and only its
//! own text is rewritten. A target declared in another module is never
//! edited there: a move to it goes to a compensated copy (`_cN`, or a
//! materialised `_oN`) declared in the moving module, after its last
//! declaration (after its `MODULE` line when it has none).

use super::{Carry, ProgramScope, RapidOptions, compensate_carried};
use crate::compensate::outcome::Compensated;
use crate::error::{Error, Result};
use crate::machine::robot::Robot;
use crate::program::interp::Warning;
use crate::program::rapid::program::{
    Member, procedures_elsewhere, relocate, scoped, written_elsewhere,
};

/// What module `i` of `members` carries in: the scope of the others.
fn carry_of(members: &[Member], i: usize, own: &Member) -> Carry {
    let anchor = match own.module.decls.last() {
        Some(d) => d.span.clone(),
        None => own.module.span.start..own.module.span.start + "MODULE".len(),
    };
    let mut carry = Carry {
        scope: Some(ProgramScope {
            from: own.module.decls.len(),
            anchor,
            writes: written_elsewhere(members, i),
            procedures: procedures_elsewhere(members, i),
        }),
        ..Carry::default()
    };
    for m in members {
        carry.reserve_names_of(&m.module);
    }
    carry
}

/// The moves of module `i` of the program `members` that a compensation
/// leaves as written, with their reasons: names resolved across the
/// modules, no robot needed.
pub fn left_as_written_member(members: &[Member], i: usize) -> Result<Vec<Warning>> {
    let own = members
        .get(i)
        .ok_or_else(|| Error::Internal("module index".into()))?;
    let (text, module, borrowed) = scoped(members, i)?;
    let carry = carry_of(members, i, own);
    super::left_as_written_carried(&module, &text, &own.name, carry)
        .map_err(|e| relocate(e, members, i, &text, &borrowed))
}

/// Compensates module `i` of the program `members` (its outcome's text is
/// the module's own text, rewritten).
pub fn compensate_member(
    members: &[Member],
    i: usize,
    robot: &Robot,
    opts: &RapidOptions,
) -> Result<Compensated> {
    let own = members
        .get(i)
        .ok_or_else(|| Error::Internal("module index".into()))?;
    let (text, module, borrowed) = scoped(members, i)?;
    let carry = carry_of(members, i, own);
    let mut outcome = compensate_carried(module, (&text, &own.name), robot, opts, carry)
        .map_err(|e| relocate(e, members, i, &text, &borrowed))?;
    let tail = text.get(own.text.len()..).unwrap_or("");
    let Some(own_text) = outcome.text.strip_suffix(tail) else {
        return Err(Error::Internal(
            "another module's declarations were rewritten".into(),
        ));
    };
    outcome.text = own_text.to_string();
    Ok(outcome)
}
