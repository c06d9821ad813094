//! Canned-cycle holes written as moves: a hole whose one X and Y misses
//! the tolerance along its depth (the Z squareness tilts a deep hole) gets
//! a correction that follows the depth, which no cycle can carry; where
//! the setup allows it ([`CycleSpec::expandable`]) the hole is written as
//! the `G0`/`G1`/`G4` moves the cycle makes (grammar/gcode.md, "Canned
//! cycles"): positioning, rapid to the R level, the feed (in pecks for
//! G73/G83), the dwell, the way out. Each feed is split where the
//! corrected X and Y must bend to hold the tolerance.

use super::{
    BlockResult, Carry, Failure, SKIP_MARGIN_MM, breaks_inside, check_travel, lerp, solve,
};
use crate::machine::{AxisVec, DirVec};
use crate::predict::ToolPredictor;
use crate::program::interp::{CycleSpec, DIRECTION_DEADBAND, Move, Plan, PlanKind};

/// What a warning of a block beyond the tolerance names (the words before
/// "is predicted …"): a hole written as a cycle is drilled at one X and Y,
/// and a cycle that is never written as moves says why — a tap's feed is
/// synchronised to the spindle (G74, G84), the boring cycles stop, orient
/// or hand the spindle to the operator at the bottom (G76, G86, G87, G88).
pub fn miss_words(plan: &Plan, res: &BlockResult) -> &'static str {
    if !matches!(plan.kind, PlanKind::Cycle { .. }) {
        return "a written piece of this block";
    }
    if !res.expansion.is_empty() {
        return "a written piece of this hole";
    }
    match plan.cycle.code10 {
        840 => {
            "the G84 tapping hole, drilled at one X and Y (a tap's feed follows the spindle: never written as moves),"
        }
        740 => {
            "the G74 tapping hole, drilled at one X and Y (a tap's feed follows the spindle: never written as moves),"
        }
        760 => {
            "the G76 boring hole, drilled at one X and Y (the spindle orients and the tool shifts at the bottom: never written as moves),"
        }
        860 => {
            "the G86 boring hole, drilled at one X and Y (the spindle stops at the bottom: never written as moves),"
        }
        870 => {
            "the G87 back-boring hole, drilled at one X and Y (the spindle orients and shifts: never written as moves),"
        }
        880 => {
            "the G88 boring hole, drilled at one X and Y (the operator jogs out at the bottom: never written as moves),"
        }
        _ => "the hole, drilled at one X and Y,",
    }
}

/// What one written line of an expanded hole does.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum StepKind {
    /// `G0` of X and Y only, at the height the machine stands at.
    Position,
    /// `G0` to the point.
    Rapid,
    /// `G1` to the point at the cycle's feed.
    Feed,
    /// `G4` with the cycle's dwell, where the machine stands.
    Dwell,
}

/// One written line of an expanded hole: what it does and where it ends
/// (machine coordinates, compensated).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Step {
    /// What the line does.
    pub kind: StepKind,
    /// Where it ends.
    pub to: AxisVec,
}

/// How far above the depth reached a G83 peck returns to by rapid before
/// it feeds on, and how far a G73 peck backs off, mm: LinuxCNC's fixed
/// 0.010 inch (Fanuc's parameters 5114 and 5115 hold the control's own).
pub const PECK_CLEARANCE_MM: f64 = 0.254;

/// Share of the direction deadband an axis a feed does not drive may move
/// against its direction on one piece (the rest is the words' rounding).
const DEADBAND_SHARE: f64 = 0.8;

/// Largest unit of the last decimal of the X and Y words of a hole
/// written as moves, as a share of the direction deadband. The Z
/// squareness moves X and Y by a fraction of a micron on each feed piece;
/// written with a unit of the deadband itself (three decimals in mm) such
/// a piece steps by a whole unit against the direction the hole is solved
/// with, which the interpreter may read as a reversal of the axis.
const HOLE_UNIT_SHARE: f64 = 0.3;

/// Margin of a feed piece's written travel below the direction deadband,
/// as a share of it.
const DEADBAND_MARGIN: f64 = 0.05;

/// The fewest decimals of the X and Y words of a hole written as moves
/// (in program units of `scale` mm) whose unit is at most
/// [`HOLE_UNIT_SHARE`] of the direction deadband: 4 in mm, 5 in inch.
/// With them a feed piece whose travel against the direction it is solved
/// with stays below the deadband less the unit (the solve halves it until
/// it does) is written below the deadband too, and read with the
/// direction it was solved with.
pub fn hole_decimals(scale: f64) -> usize {
    let max = crate::limits::EMIT_MAX_DECIMALS;
    (0..max)
        .find(|&d| scale / 10f64.powi(d as i32) <= HOLE_UNIT_SHARE * DIRECTION_DEADBAND)
        .unwrap_or(max)
}

/// The unit of the last decimal of an expanded hole's X and Y words, mm,
/// at most: those of [`hole_decimals`] (finer where the program's or the
/// machine file's decimals are).
fn hole_unit_mm(scale: f64) -> f64 {
    scale / 10f64.powi(hole_decimals(scale) as i32)
}

/// Most halvings of one feed of an expanded hole.
const MAX_HALVINGS: u32 = 16;

/// Most pecks of one hole written as moves.
const MAX_PECKS: usize = 10_000;

/// One hole being expanded.
struct Hole<'a, 'm> {
    pred: &'a ToolPredictor<'m>,
    mv: &'a Move,
    tol: f64,
    /// How far the written words' rounding may move the travel of a piece
    /// in X or Y (the unit of their last decimal, [`hole_unit_mm`]), mm.
    unit: f64,
    /// Share of the deadband a piece may travel in X or Y against the
    /// direction it is solved with, its words' rounding left below it.
    share: f64,
    steps: Vec<Step>,
    /// The largest distance of a feed's attained path across the
    /// programmed hole, mm.
    miss: f64,
}

impl Hole<'_, '_> {
    /// The programmed point of the hole at machine height `z`.
    fn at(&self, z: f64) -> AxisVec {
        let mut p = self.mv.end;
        p[2] = z;
        p
    }

    /// The command at height `z` solved with the directions `d`.
    fn solve(&self, z: f64, d: &DirVec) -> Result<AxisVec, Failure> {
        let (c, _) = solve(self.pred, &self.at(z), d, self.mv.tool_len_mm)?;
        check_travel(self.pred, &c)?;
        Ok(c)
    }

    /// The largest distance across the hole of the attained path of the
    /// straight command `ca → cb` (programmed `za → zb`, directions `d`):
    /// at its ends, its middle and every breakpoint of Z inside (the error
    /// model is piecewise linear in Z between breakpoints).
    fn across(&self, (ca, cb): (&AxisVec, &AxisVec), (za, zb): (f64, f64), d: &DirVec) -> f64 {
        let tool = self.mv.tool_len_mm;
        let off = |f: f64| -> f64 {
            let cmd = lerp(ca, cb, f);
            let prog = self.at(za + (zb - za) * f);
            let o = self.pred.attained(&cmd, d, tool).pos - self.pred.nominal(&prog, tool).pos;
            o[0].hypot(o[1])
        };
        let mut worst = off(0.0).max(off(0.5)).max(off(1.0));
        if cb[2] != ca[2] {
            for &z in breaks_inside(self.pred, 2, ca[2], cb[2]) {
                worst = worst.max(off((z - ca[2]) / (cb[2] - ca[2])));
            }
        }
        worst
    }

    /// The feed from the command `ca` (programmed height `za`) to height
    /// `zb` with the directions `d`, halved until each piece holds the
    /// tolerance: its pieces pushed as feed steps. Returns the end command.
    fn feed(&mut self, (ca, za): (AxisVec, f64), zb: f64, d: &DirVec) -> Result<AxisVec, Failure> {
        let cb = self.solve(zb, d)?;
        self.pieces((&ca, za), (&cb, zb), d, 0)?;
        Ok(cb)
    }

    fn pieces(
        &mut self,
        (ca, za): (&AxisVec, f64),
        (cb, zb): (&AxisVec, f64),
        d: &DirVec,
        depth: u32,
    ) -> Result<(), Failure> {
        let miss = self.across((ca, cb), (za, zb), d);
        // A piece that moves X or Y against the direction it is solved
        // with by more than the deadband would reverse that axis.
        let against = (0..2).any(|k| {
            let step = cb[k] - ca[k];
            step.abs() > self.share * DIRECTION_DEADBAND && step.signum() != f64::from(d[k])
        });
        if (miss > self.tol - SKIP_MARGIN_MM || against) && depth < MAX_HALVINGS {
            let zm = (za + zb) / 2.0;
            let cm = self.solve(zm, d)?;
            self.pieces((ca, za), (&cm, zm), d, depth + 1)?;
            return self.pieces((&cm, zm), (cb, zb), d, depth + 1);
        }
        // A piece whose travel in X or Y against its direction is that
        // close to the deadband may be written (its words rounded) as a
        // reversal of that axis: measured under that reading too.
        let mut read = miss;
        for k in 0..2 {
            let step = cb[k] - ca[k];
            if step != 0.0
                && step.signum() != f64::from(d[k])
                && step.abs() + self.unit >= DIRECTION_DEADBAND
            {
                let mut r = *d;
                r[k] = -r[k];
                read = read.max(self.across((ca, cb), (za, zb), &r));
            }
        }
        self.miss = self.miss.max(read);
        self.push(StepKind::Feed, *cb);
        Ok(())
    }

    fn push(&mut self, kind: StepKind, to: AxisVec) {
        self.steps.push(Step { kind, to });
    }
}

/// How far before the hole's X or Y the approach point of
/// [`approach`] lies, against the direction the hole is solved with, as a
/// multiple of the direction deadband.
const APPROACH_DEADBANDS: f64 = 5.0;

/// The point the positioning of an expanded hole goes to first, where the
/// positioning from where the machine stands (`from`, last moved with
/// `moved`) straight to the hole's command `c` would leave X or Y moving
/// otherwise than the hole is solved with (`d`), or might be read either
/// way (its travel within `band` mm of the deadband: the rounding of the
/// words at both ends): the hole's X and Y with each such axis
/// [`APPROACH_DEADBANDS`] deadbands before it, so that the move on from
/// there leaves the axis moving as solved. The hole's solve and the
/// directions its positioning gives need not agree (a correction that
/// reverses an axis with one direction and, with the other, moves it less
/// than the deadband): approached from one side, they do. `None` where the
/// positioning gives the directions it is solved with.
fn approach(
    (from, moved): (&AxisVec, &DirVec),
    c: &AxisVec,
    d: &DirVec,
    band: f64,
) -> Option<AxisVec> {
    let mut pre = *c;
    let mut any = false;
    for k in 0..2 {
        if positioning_reads((from, moved), c, k, band) != Some(d[k]) {
            pre[k] = c[k] - f64::from(d[k]) * APPROACH_DEADBANDS * DIRECTION_DEADBAND;
            any = true;
        }
    }
    any.then_some(pre)
}

/// The direction of axis `k` (X or Y) after the positioning from `from`
/// (last moved with `moved`) to `c`, as the interpreter reads the written
/// words whose rounding moves the travel by up to `band` mm: the
/// travel's where it is certainly beyond the direction deadband, the one
/// before where it is certainly within it, `None` where it may be read
/// either way.
pub(super) fn positioning_reads(
    (from, moved): (&AxisVec, &DirVec),
    c: &AxisVec,
    k: usize,
    band: f64,
) -> Option<i8> {
    let travel = c[k] - from[k];
    if travel.abs() > DIRECTION_DEADBAND + band {
        Some(if travel > 0.0 { 1 } else { -1 })
    } else if travel.abs() < DIRECTION_DEADBAND - band {
        Some(moved[k])
    } else {
        None
    }
}

/// Every reading of the directions of a hole drilled at one X and Y
/// after the positioning from `from` (last moved with `moved`) to `c`
/// ([`positioning_reads`], its words' rounding moving the travel by up to
/// `band` mm), Z moving down: one, or two or four where X or Y may be
/// read either way.
pub(super) fn hole_readings(
    (from, moved): (&AxisVec, &DirVec),
    c: &AxisVec,
    band: f64,
) -> impl Iterator<Item = DirVec> {
    let options = |k: usize| -> [i8; 2] {
        match positioning_reads((from, moved), c, k, band) {
            Some(v) => [v, v],
            None => [moved[k], if c[k] > from[k] { 1 } else { -1 }],
        }
    };
    let (xs, ys) = (options(0), options(1));
    let base = *moved;
    (0..4).map(move |i| {
        let mut d = base;
        d[0] = xs[i & 1];
        d[1] = ys[i >> 1];
        d[2] = -1;
        d
    })
}

/// Writes the hole of the cycle block `mv` (`spec`; programmed R level and
/// retract level) as moves into `res` ([`BlockResult::expansion`]), with
/// the directions of motion `d` its feed is solved with; `before` is
/// where the machine stands before it and the directions it last moved
/// in (its positioning approaches the hole from one side where they would
/// not give `d`, [`approach`]); `carry` (where the hole leaves the
/// machine) is moved to where the last move ends.
/// [`BlockResult::miss_mm`] becomes the largest miss of its feeds. The
/// other words of the program are rounded by up to `rounding` mm (twice
/// the unit of their last decimal, see `emit::gcode::rounding_mm`); the
/// hole's X and Y words (in program units of `scale` mm) are written with
/// [`hole_decimals`] at least, and each feed piece travels in X and Y
/// against the direction it is solved with by less than the deadband less
/// their unit, so that it is read back with that direction (a piece that
/// might still be read as a reversal is measured under both readings).
pub(super) fn expand(
    pred: &ToolPredictor,
    (mv, spec): (&Move, &CycleSpec),
    (r_level, retract): (f64, f64),
    (tol, rounding, scale): (f64, f64, f64),
    before: (&AxisVec, &DirVec),
    carry: &mut Carry,
    res: &mut BlockResult,
) -> Result<(), Failure> {
    let d = res.dirs;
    let unit = hole_unit_mm(scale);
    let share = DEADBAND_SHARE.min(1.0 - unit / DIRECTION_DEADBAND - DEADBAND_MARGIN);
    let mut hole = Hole {
        pred,
        mv,
        tol,
        unit,
        share,
        steps: Vec::new(),
        miss: 0.0,
    };
    let bottom = mv.end[2];
    let c_r = hole.solve(r_level, &d)?;
    if let Some(pre) = approach(before, &c_r, &d, rounding / 2.0 + unit) {
        check_travel(pred, &pre)?;
        hole.push(StepKind::Position, pre);
    }
    hole.push(StepKind::Position, c_r);
    hole.push(StepKind::Rapid, c_r);
    let mut from = (c_r, r_level);
    let peck = spec.peck_mm;
    let mut depth = r_level;
    for _ in 0..MAX_PECKS {
        let next = if peck > 0.0 {
            (depth - peck).max(bottom)
        } else {
            bottom
        };
        let reached = hole.feed(from, next, &d)?;
        depth = next;
        if depth <= bottom {
            break;
        }
        // Out of the hole (G83) or back off (G73), then down again to just
        // above the depth reached.
        if spec.code10 == 830 {
            let mut out = reached;
            out[2] = c_r[2];
            hole.push(StepKind::Rapid, out);
        }
        let again = (depth + PECK_CLEARANCE_MM).min(r_level);
        let c_again = hole.solve(again, &d)?;
        hole.push(StepKind::Rapid, c_again);
        from = (c_again, again);
    }
    let mut last = hole.steps.last().map_or(c_r, |s| s.to);
    if spec.dwell_p.is_some() {
        hole.push(StepKind::Dwell, last);
    }
    if matches!(spec.code10, 850 | 890) {
        // G85, G89: fed out to the R level.
        let mut up = d;
        up[2] = 1;
        last = hole.feed((last, bottom), r_level, &up)?;
    }
    if retract > r_level || !matches!(spec.code10, 850 | 890) {
        let mut top = last;
        top[2] = carry.c[2];
        hole.push(StepKind::Rapid, top);
        last = top;
    }
    carry.c = last;
    res.miss_mm = hole.miss;
    res.expansion = hole.steps;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::machine::tool::MachineTool;
    use crate::predict::EffectSet;
    use crate::program::interp::{Motion, PlanKind};

    /// The unit of an expanded hole's X and Y words is at most 0.3 µm:
    /// 0.0001 mm (0.1 µm) in mm, 0.00001 inch (0.254 µm) in inch; one
    /// decimal fewer would be 1 µm and 2.54 µm.
    #[test]
    fn hole_words_have_a_unit_well_below_the_deadband() {
        assert_eq!(hole_decimals(1.0), 4);
        assert_eq!(hole_decimals(25.4), 5);
        // A piece travelling 0.8 µm against its direction (mm), or 0.696
        // µm (inch: the share left by its unit), is written below 1 µm.
        for scale in [1.0, 25.4] {
            let unit = hole_unit_mm(scale);
            let share = DEADBAND_SHARE.min(1.0 - unit / DIRECTION_DEADBAND - DEADBAND_MARGIN);
            assert!(share * DIRECTION_DEADBAND + unit < 0.96 * DIRECTION_DEADBAND);
        }
    }

    /// A deep G83 hole on the bundled afm-r1000 (geometric effects): its
    /// steps peck as the cycle does and every feed holds the tolerance.
    #[test]
    fn a_deep_peck_hole_is_written_as_pecks_within_the_tolerance() {
        let text = std::fs::read_to_string(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/machines/afm-r1000.yaml"
        ))
        .expect("machine");
        let m = MachineTool::from_yaml_str(&text, "m.yaml").expect("machine");
        let effects = EffectSet::from_flags(
            &"geometric".parse().expect("effects"),
            &[],
            crate::predict::MachineKind::Tool,
        )
        .expect("effects");
        let pred = ToolPredictor::new(&m, effects);
        let setup = crate::program::interp::Setup {
            expand_cycles: true,
            ..crate::program::interp::Setup::for_machine(&m)
        };
        let mut it = crate::program::interp::Interpreter::new(setup, "t.nc");
        let mut b = crate::program::gcode::Block::default();
        let mut plan = None;
        for (i, l) in [
            "G21 G90 G17 G94",
            "G0 G54 X50. Y50.",
            "G43 Z100. H1",
            "G99 G83 X50. Y50. Z-87. R2. Q30. F100.",
        ]
        .iter()
        .enumerate()
        {
            crate::program::gcode::parse_line(l.as_bytes(), i + 1, "t.nc", &mut b).expect("parse");
            plan = Some(it.step(&b, l.as_bytes()).expect("interp"));
        }
        let plan = plan.expect("plan");
        let PlanKind::Cycle { r_level, .. } = plan.kind else {
            panic!("{plan:?}")
        };
        assert!(plan.cycle.expandable);
        assert_eq!(plan.cycle.peck_mm, 30.0);
        let mut carry = None;
        let settings = super::super::Settings {
            tolerance_mm: 0.003,
        };
        let res = super::super::block_recycling(
            &pred,
            &plan,
            &settings,
            &mut carry,
            (Vec::new(), Vec::new()),
            0.0,
        )
        .expect("compensates");
        let steps = &res.expansion;
        assert_eq!(steps[0].kind, StepKind::Position);
        // Three pecks of 30 mm from R2 to −87: feeds end at −28, −58, −87
        // (work Z), each peck but the last followed by the rapid out to R
        // and the rapid back to 0.254 mm above the depth reached.
        let feeds_ends: Vec<f64> = steps
            .windows(2)
            .filter(|w| w[0].kind == StepKind::Feed && w[1].kind != StepKind::Feed)
            .map(|w| w[0].to[2] - (r_level - 2.0))
            .collect();
        assert_eq!(feeds_ends.len(), 3, "{steps:?}");
        for (got, want) in feeds_ends.iter().zip([-28.0, -58.0]) {
            assert!((got - want).abs() < 0.01, "{got} {want}");
        }
        let rapids = steps.iter().filter(|s| s.kind == StepKind::Rapid).count();
        // To R, two pecks out and back in, the retract.
        assert_eq!(rapids, 1 + 2 * 2 + 1, "{steps:?}");
        assert!(res.miss_mm <= 0.003, "{}", res.miss_mm);
        assert_eq!(plan.mv.map(|m| m.motion), Some(Motion::Linear));
    }
}
