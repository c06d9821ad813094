//! Tool centre point control (G43.4/G43.5) through the nominal kinematics
//! the control uses: from axis positions to the tool tip in the workpiece
//! frame, and back.

use nalgebra::{Matrix3, Vector3};

use super::MachineTool;
use crate::machine::AxisVec;

impl MachineTool {
    /// The nominal tool tip of axis positions `cmd`: X, Y, Z of the tip in
    /// the workpiece frame, the rotary axes as commanded.
    pub fn tip_of(&self, cmd: &AxisVec, tool_mm: f64) -> AxisVec {
        let p = self.nominal(cmd, tool_mm).pos;
        [p.x, p.y, p.z, cmd[3], cmd[4], cmd[5]]
    }

    /// The axis positions whose nominal tool tip is at `tip` (X, Y, Z in
    /// the workpiece frame) with the rotary axes at `tip[3..]`; `None` when
    /// the linear axes cannot place it (a machine without X, Y or Z).
    pub fn axes_for_tip(&self, tip: &AxisVec, tool_mm: f64) -> Option<AxisVec> {
        // With the rotary axes fixed the nominal tip is affine in X, Y, Z.
        let mut cmd = *tip;
        cmd[..3].fill(0.0);
        let c0 = self.nominal(&cmd, tool_mm).pos;
        let mut a = Matrix3::zeros();
        for i in 0..3 {
            let mut e = cmd;
            e[i] = 1.0;
            a.set_column(i, &(self.nominal(&e, tool_mm).pos - c0));
        }
        let x = a.try_inverse()? * (Vector3::new(tip[0], tip[1], tip[2]) - c0);
        x.iter()
            .all(|v| v.is_finite())
            .then_some([x.x, x.y, x.z, tip[3], tip[4], tip[5]])
    }
}

#[cfg(test)]
mod tests {
    use super::super::testing;

    /// Round trip of the kinematics, mm.
    const ROUND_TRIP_MM: f64 = 1e-9;

    #[test]
    fn axes_for_a_tip_give_that_tip_back() {
        for file in ["five-axis-ac", "head-table-bc"] {
            let path = format!("{}/machines/{file}.yaml", env!("CARGO_MANIFEST_DIR"));
            let m = testing::load(&std::fs::read_to_string(path).unwrap_or_default(), file);
            for cmd in [
                [10.0, -20.0, -150.0, 0.0, 0.0, 0.0],
                [-35.0, 42.0, -210.0, 25.0, 25.0, 130.0],
                [80.0, 5.0, -90.0, -60.0, -60.0, -45.0],
            ] {
                let tip = m.tip_of(&cmd, 100.0);
                let back = m.axes_for_tip(&tip, 100.0).expect("reachable");
                for s in 0..6 {
                    assert!(
                        (back[s] - cmd[s]).abs() < ROUND_TRIP_MM,
                        "{file} {cmd:?} {back:?}"
                    );
                }
            }
        }
    }
}
