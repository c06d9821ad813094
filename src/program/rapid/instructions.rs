//! The motion instructions parsed as moves, with the place of each
//! positional argument.
//!
//! Every instruction here moves the TCP to a target the way `MoveL`,
//! `MoveJ`, `MoveC` or `MoveAbsJ` does (its [`MoveKind`]), and takes its
//! positional (non-`\`) arguments in the order given by its roles. The
//! arguments that are not a target, speed, zone or tool (a signal, a
//! trigger, seam and weld data, spot-weld gun and spot data, the
//! `SearchPoint` the controller writes) are kept as written and never
//! compensated. The table is documented in `grammar/rapid.md`.

use super::MoveKind;

/// What a positional argument of a motion instruction is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// The circle point of a circular move.
    CirPoint,
    /// The target (`ToPoint`; `ToJointPos` for an absolute-joint move).
    ToPoint,
    /// The speeddata.
    Speed,
    /// The zonedata.
    Zone,
    /// The tooldata.
    Tool,
    /// Any other argument, by its name in the instruction's signature; kept
    /// as written.
    Other(&'static str),
}

/// One motion instruction: its name, motion kind and argument roles.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MotionInstruction {
    /// The name in its canonical spelling (matched case-insensitively).
    pub name: &'static str,
    /// How the TCP moves to the target.
    pub kind: MoveKind,
    /// The positional arguments in order.
    pub args: &'static [Role],
    /// Whether other software versions of its process package write it
    /// with other positional arguments: a statement whose positional
    /// arguments are not those of [`Self::args`] is then not a move but an
    /// opaque statement (left as written and named), not an error.
    pub other_forms: bool,
}

impl MotionInstruction {
    /// The 0-based position of `role` among the positional arguments.
    pub fn position(&self, role: Role) -> Option<usize> {
        self.args.iter().position(|&r| r == role)
    }

    /// The positional arguments by name, comma separated
    /// (`ToPoint, Speed, Zone, Tool`).
    pub fn signature(&self) -> String {
        let names: Vec<&str> = self
            .args
            .iter()
            .map(|r| match r {
                Role::CirPoint => "CirPoint",
                Role::ToPoint if self.kind == MoveKind::MoveAbsJ => "ToJointPos",
                Role::ToPoint => "ToPoint",
                Role::Speed => "Speed",
                Role::Zone => "Zone",
                Role::Tool => "Tool",
                Role::Other(name) => name,
            })
            .collect();
        names.join(", ")
    }
}

use Role::{CirPoint as C, Other as O, Speed as S, ToPoint as P, Tool as T, Zone as Z};

const MOVE: &[Role] = &[P, S, Z, T];
const MOVE_C: &[Role] = &[C, P, S, Z, T];
const DO: &[Role] = &[P, S, Z, T, O("Signal"), O("Value")];
const DO_C: &[Role] = &[C, P, S, Z, T, O("Signal"), O("Value")];
const SYNC: &[Role] = &[P, S, Z, T, O("ProcName")];
const SYNC_C: &[Role] = &[C, P, S, Z, T, O("ProcName")];
const TRIGG: &[Role] = &[P, S, O("Trigg1"), Z, T];
const TRIGG_C: &[Role] = &[C, P, S, O("Trigg1"), Z, T];
const SEARCH: &[Role] = &[O("Signal"), O("SearchPoint"), P, S, T];
const SEARCH_C: &[Role] = &[O("Signal"), O("SearchPoint"), C, P, S, T];
const ARC: &[Role] = &[P, S, O("Seam"), O("Weld"), Z, T];
const ARC_C: &[Role] = &[C, P, S, O("Seam"), O("Weld"), Z, T];
const SPOT: &[Role] = &[P, S, O("Gun"), O("Spot"), T];

const fn entry(name: &'static str, kind: MoveKind, args: &'static [Role]) -> MotionInstruction {
    MotionInstruction {
        name,
        kind,
        args,
        other_forms: false,
    }
}

/// An entry whose process package writes it otherwise in other software
/// versions ([`MotionInstruction::other_forms`]).
const fn versioned(name: &'static str, kind: MoveKind, args: &'static [Role]) -> MotionInstruction {
    MotionInstruction {
        other_forms: true,
        ..entry(name, kind, args)
    }
}

/// Every motion instruction parsed as a move.
pub const MOTION_INSTRUCTIONS: &[MotionInstruction] = &[
    entry("MoveL", MoveKind::MoveL, MOVE),
    entry("MoveJ", MoveKind::MoveJ, MOVE),
    entry("MoveC", MoveKind::MoveC, MOVE_C),
    entry("MoveAbsJ", MoveKind::MoveAbsJ, MOVE),
    entry("MoveLDO", MoveKind::MoveL, DO),
    entry("MoveJDO", MoveKind::MoveJ, DO),
    entry("MoveCDO", MoveKind::MoveC, DO_C),
    entry("MoveLAO", MoveKind::MoveL, DO),
    entry("MoveJAO", MoveKind::MoveJ, DO),
    entry("MoveCAO", MoveKind::MoveC, DO_C),
    entry("MoveLGO", MoveKind::MoveL, DO),
    entry("MoveJGO", MoveKind::MoveJ, DO),
    entry("MoveCGO", MoveKind::MoveC, DO_C),
    entry("MoveLSync", MoveKind::MoveL, SYNC),
    entry("MoveJSync", MoveKind::MoveJ, SYNC),
    entry("MoveCSync", MoveKind::MoveC, SYNC_C),
    entry("TriggL", MoveKind::MoveL, TRIGG),
    entry("TriggJ", MoveKind::MoveJ, TRIGG),
    entry("TriggC", MoveKind::MoveC, TRIGG_C),
    entry("SearchL", MoveKind::MoveL, SEARCH),
    entry("SearchC", MoveKind::MoveC, SEARCH_C),
    entry("ArcL", MoveKind::MoveL, ARC),
    entry("ArcLStart", MoveKind::MoveL, ARC),
    entry("ArcLEnd", MoveKind::MoveL, ARC),
    entry("ArcC", MoveKind::MoveC, ARC_C),
    entry("ArcCStart", MoveKind::MoveC, ARC_C),
    entry("ArcCEnd", MoveKind::MoveC, ARC_C),
    versioned("SpotL", MoveKind::MoveL, SPOT),
    versioned("SpotJ", MoveKind::MoveJ, SPOT),
];

/// The motion instruction named `name` (case-insensitive, as RAPID).
///
/// The four plain moves, nearly every statement of a large module, are
/// told by [`plain_move_at`]; other names are looked up in the table only
/// when their first letter starts one of its names.
#[inline]
pub fn motion_instruction(name: &str) -> Option<&'static MotionInstruction> {
    let b = name.as_bytes();
    if !b.first().is_some_and(|&c| may_start_motion(c)) {
        return None;
    }
    if let Some((m, n)) = plain_move_at(b) {
        if n == b.len() {
            return Some(m);
        }
    }
    MOTION_INSTRUCTIONS
        .iter()
        .find(|m| m.name.eq_ignore_ascii_case(name))
}

/// The plain move (`MoveL`, `MoveJ`, `MoveC` or `MoveAbsJ`, any case)
/// whose name starts `b` as a whole word (no letter, digit or `_` after
/// it), and the length of the name: by the fifth letter and the length,
/// without a table search.
#[inline]
pub fn plain_move_at(b: &[u8]) -> Option<(&'static MotionInstruction, usize)> {
    let head = b.get(..5)?;
    if !head[..4].eq_ignore_ascii_case(b"Move") {
        return None;
    }
    let (k, n) = match head[4].to_ascii_uppercase() {
        b'L' => (0, 5),
        b'J' => (1, 5),
        b'C' => (2, 5),
        b'A' if b.get(5..8).is_some_and(|t| t.eq_ignore_ascii_case(b"bsJ")) => (3, 8),
        _ => return None,
    };
    if b.get(n)
        .is_some_and(|&c| c.is_ascii_alphanumeric() || c == b'_')
    {
        return None;
    }
    Some((MOTION_INSTRUCTIONS.get(k)?, n))
}

/// Whether `c` is the first letter (either case) of a name in
/// [`MOTION_INSTRUCTIONS`].
#[inline]
pub fn may_start_motion(c: u8) -> bool {
    matches!(c.to_ascii_uppercase(), b'M' | b'T' | b'S' | b'A')
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_entry_has_one_target_speed_and_tool_and_a_via_when_circular() {
        for m in MOTION_INSTRUCTIONS {
            let count = |role| m.args.iter().filter(|&&r| r == role).count();
            assert_eq!(count(Role::ToPoint), 1, "{}", m.name);
            assert_eq!(count(Role::Speed), 1, "{}", m.name);
            assert_eq!(count(Role::Tool), 1, "{}", m.name);
            assert!(count(Role::Zone) <= 1, "{}", m.name);
            let circular = usize::from(m.kind == MoveKind::MoveC);
            assert_eq!(count(Role::CirPoint), circular, "{}", m.name);
            if let (Some(c), Some(p)) = (m.position(Role::CirPoint), m.position(Role::ToPoint)) {
                assert!(c < p, "{}", m.name);
            }
        }
    }

    #[test]
    fn names_are_unique_case_insensitively() {
        for (k, a) in MOTION_INSTRUCTIONS.iter().enumerate() {
            for b in &MOTION_INSTRUCTIONS[k + 1..] {
                assert!(!a.name.eq_ignore_ascii_case(b.name), "{}", a.name);
            }
        }
    }

    #[test]
    fn every_name_is_found_in_any_case_and_no_other() {
        for m in MOTION_INSTRUCTIONS {
            assert!(may_start_motion(m.name.as_bytes()[0]), "{}", m.name);
            for name in [
                m.name.to_string(),
                m.name.to_ascii_lowercase(),
                m.name.to_ascii_uppercase(),
            ] {
                assert_eq!(motion_instruction(&name), Some(m), "{name}");
                for cut in [1, 2] {
                    if let Some(shorter) = name.get(..name.len() - cut) {
                        let found = motion_instruction(shorter).map(|f| f.name);
                        let listed = MOTION_INSTRUCTIONS
                            .iter()
                            .find(|e| e.name.eq_ignore_ascii_case(shorter))
                            .map(|e| e.name);
                        assert_eq!(found, listed, "{shorter}");
                    }
                }
                assert_eq!(motion_instruction(&format!("{name}X")), None, "{name}X");
            }
        }
        for other in [
            "",
            "M",
            "Move",
            "MoveX",
            "MoveAbsL",
            "MoveAbsJJ",
            "WaitTime",
            "moveabs",
        ] {
            assert_eq!(motion_instruction(other), None, "{other}");
        }
    }

    #[test]
    fn plain_moves_are_told_like_the_table_does() {
        for text in [
            "MoveL p1",
            "movel,",
            "MOVEJ;",
            "MoveC\t",
            "MoveAbsJ [",
            "moveabsj",
            "MoveL",
            "MoveLDO p",
            "MoveL_2 p",
            "MoveL2",
            "MoveAbs j",
            "MoveAbsJX",
            "Move",
            "MoveX",
            "MoveJSync",
            "Movec",
            "MoveAbsJ_",
            "MoveL\u{e9}",
        ] {
            let n = text
                .bytes()
                .take_while(|c| c.is_ascii_alphanumeric() || *c == b'_')
                .count();
            let word = &text[..n];
            let listed = MOTION_INSTRUCTIONS
                .iter()
                .find(|m| m.name.eq_ignore_ascii_case(word));
            let plain = listed.filter(|m| MOTION_INSTRUCTIONS[..4].contains(m));
            assert_eq!(
                plain_move_at(text.as_bytes()),
                plain.map(|m| (m, n)),
                "{text}"
            );
        }
    }

    #[test]
    fn search_point_is_not_a_target() {
        let s = motion_instruction("searchl").unwrap();
        assert_eq!(s.position(Role::ToPoint), Some(2));
        assert_eq!(s.position(Role::Other("SearchPoint")), Some(1));
        assert_eq!(s.position(Role::Zone), None);
        assert_eq!(s.signature(), "Signal, SearchPoint, ToPoint, Speed, Tool");
    }

    #[test]
    fn spot_welds_end_in_a_stop_point_and_keep_gun_and_spot_data() {
        for (name, kind) in [("spotl", MoveKind::MoveL), ("SPOTJ", MoveKind::MoveJ)] {
            let s = motion_instruction(name).unwrap();
            assert_eq!(s.kind, kind, "{name}");
            assert_eq!(s.position(Role::ToPoint), Some(0), "{name}");
            assert_eq!(s.position(Role::Zone), None, "{name}");
            assert_eq!(s.signature(), "ToPoint, Speed, Gun, Spot, Tool");
            assert!(s.other_forms, "{name}");
        }
        let only_listed = MOTION_INSTRUCTIONS
            .iter()
            .filter(|m| m.other_forms)
            .all(|m| m.name.starts_with("Spot"));
        assert!(only_listed);
    }
}
