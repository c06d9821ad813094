//! Tool centre point control (G43.4/G43.5) in the compensation.
//!
//! Under tool centre point control the program gives tool-tip positions in
//! the workpiece frame and the rotary angles; the control's nominal
//! kinematics turns them into axis positions. The interpreter does the
//! same, so a block is predicted and compensated in axis positions like
//! any other: the compensated axis positions are those whose predicted
//! attained tip and tool axis are the programmed ones. They are written
//! back as the nominal tool tips of the compensated axis positions, which
//! the control turns into those axis positions again. Between the written
//! points the control moves the tip on a straight line where the
//! prediction assumed the axes to move on one; the two agree at every
//! written point.

use super::BlockResult;
use crate::machine::tool::MachineTool;
use crate::program::interp::Plan;

/// The plan and the result of a block under tool centre point control in
/// tool-tip positions, for the emitter: `plan_out` and `res_out` are
/// overwritten (their storage reused).
pub fn to_tips(
    m: &MachineTool,
    plan: &Plan,
    res: &BlockResult,
    plan_out: &mut Plan,
    res_out: &mut BlockResult,
) {
    *plan_out = *plan;
    if let Some(mv) = plan_out.mv.as_mut() {
        mv.start = m.tip_of(&mv.start, mv.tool_len_mm);
        mv.end = m.tip_of(&mv.end, mv.tool_len_mm);
        let tool = mv.tool_len_mm;
        res_out.clone_from(res);
        res_out.end = m.tip_of(&res.end, tool);
        for (out, p) in res_out.segments.iter_mut().zip(&res.segments) {
            *out = m.tip_of(p, tool);
        }
    } else {
        res_out.clone_from(res);
    }
}
