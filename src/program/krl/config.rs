//! KUKA axis angles and the Status and Turn of a Cartesian target, in the
//! robot model's terms.
//!
//! The bundled KUKA models (machines/kuka-*.yaml) use the row pattern of
//! the ABB arms, so their joints are not KUKA's axes: A1, A4 and A6 turn
//! the other way (KUKA's axes 1, 4 and 6 are left-handed about the model's
//! axes) and A2, A3 count from the stretched arm (KUKA's mechanical zero
//! has the lower arm horizontal): [`axes_to_model`] and [`model_to_axes`].
//!
//! Status `S` (bits 0–2) and Turn `T` (bits 0–5) as KUKA defines them
//! (KUKA System Software 8, "Status" and "Turn"; the same table is in
//! Siemens' SINUMERIK ONE programming manual 12/2019, 6FC5398-2EP40-0BA0,
//! transformation `STAT`/`TU`, p. 710), see grammar/krl.md:
//! - S bit 0: the wrist root point (where A4, A5 and A6 meet) has a
//!   negative x in the A1 coordinate system (the overhead area) — the
//!   model's cfx bit 4 (behind axis 1);
//! - S bit 1: A3 at or beyond the angle φ where the wrist root point lies
//!   on the line through A2 and A3 (φ = 0 without an offset between A3 and
//!   A4; "elbow up") — the model's cfx bit 2 clear (wrist in front of the
//!   lower arm);
//! - S bit 2: A5 negative — the model's cfx bit 1 (q5 < 0, q5 = A5);
//! - T bit i: axis A(i+1) negative (0° counts as positive).
//!
//! S and T need no quadrants: the signs of the six axes fix the turns of
//! A1, A4 and A6 within their ranges (at most ±360°).

use crate::machine::robot::Robot;

/// The model's joint `i` is `SIGN[i]·A(i+1) + SHIFT_DEG[i]`.
const SIGN: [f64; 6] = [-1.0, 1.0, 1.0, -1.0, 1.0, -1.0];
/// See [`SIGN`].
const SHIFT_DEG: [f64; 6] = [0.0, 90.0, -90.0, 0.0, 0.0, 0.0];

/// The model's joints (rad) of KUKA axis angles A1…A6 (degrees).
pub fn axes_to_model(a_deg: &[f64; 6]) -> [f64; 6] {
    std::array::from_fn(|i| (SIGN[i] * a_deg[i] + SHIFT_DEG[i]).to_radians())
}

/// KUKA axis angles A1…A6 (degrees) of the model's joints (rad).
pub fn model_to_axes(q: &[f64; 6]) -> [f64; 6] {
    std::array::from_fn(|i| SIGN[i] * (q[i].to_degrees() - SHIFT_DEG[i]))
}

/// The Status and Turn of a KUKA `POS`/`E6POS`/`FRAME` target.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct StatusTurn {
    /// `S`: bits 0–2 as the module documentation says; higher bits are
    /// kept as written.
    pub status: u32,
    /// `T`: bit i set when axis A(i+1) is negative.
    pub turn: u32,
}

impl StatusTurn {
    /// The Status and Turn of the model's joints `q` on `robot` (a KUKA
    /// model: its confdata classifies the wrist and arm).
    pub fn of_joints(robot: &Robot, q: &[f64; 6]) -> StatusTurn {
        let cfx = robot.confdata(q).cfx;
        let status = ((cfx >> 2) & 1) | (((!cfx >> 1) & 1) << 1) | ((cfx & 1) << 2);
        let a = model_to_axes(q);
        let turn = a
            .iter()
            .enumerate()
            .fold(0, |t, (i, v)| t | u32::from(*v < 0.0) << i);
        StatusTurn {
            status: status as u32,
            turn,
        }
    }

    /// The model's cfx (0–7) of this Status.
    pub fn cfx(self) -> i32 {
        let s = self.status as i32;
        4 * (s & 1) + 2 * (((s >> 1) & 1) ^ 1) + ((s >> 2) & 1)
    }

    /// Whether the model's joints `q` have the axis signs of the Turn.
    pub fn admits(self, q: &[f64; 6]) -> bool {
        let a = model_to_axes(q);
        a.iter()
            .enumerate()
            .all(|(i, v)| (*v < 0.0) == (self.turn >> i & 1 == 1))
    }

    /// Whether the joints `q` are a solution of this Status and Turn on
    /// `robot` (the same cfx and the same axis signs).
    pub fn matches(self, robot: &Robot, q: &[f64; 6]) -> bool {
        robot.confdata(q).cfx == self.cfx() && self.admits(q)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Agreement of joint values, degrees (rounding only).
    const JOINT_TOL_DEG: f64 = 1e-9;

    #[test]
    fn home_is_the_models_zero_and_axes_round_trip() {
        let home = [0.0, -90.0, 90.0, 0.0, 0.0, 0.0];
        assert!(axes_to_model(&home).iter().all(|q| q.abs() < 1e-15));
        let a = [12.5, -33.0, 101.0, -170.0, 45.0, 300.0];
        let q = axes_to_model(&a);
        // A1 and A6 change sign, A2 shifts by +90°, A3 by −90°.
        assert!((q[0].to_degrees() + 12.5).abs() <= JOINT_TOL_DEG);
        assert!((q[1].to_degrees() - 57.0).abs() <= JOINT_TOL_DEG);
        assert!((q[2].to_degrees() - 11.0).abs() <= JOINT_TOL_DEG);
        assert!((q[5].to_degrees() + 300.0).abs() <= JOINT_TOL_DEG);
        for (x, y) in model_to_axes(&q).iter().zip(a) {
            assert!((x - y).abs() <= JOINT_TOL_DEG);
        }
    }

    #[test]
    fn status_bits_map_onto_cfx_both_ways() {
        // S 'B010' (elbow up, basic area, A5 positive) is cfx 0; every
        // status has its own cfx.
        let st = |s| StatusTurn { status: s, turn: 0 };
        assert_eq!(st(2).cfx(), 0);
        assert_eq!(st(6).cfx(), 1);
        assert_eq!(st(0).cfx(), 2);
        assert_eq!(st(3).cfx(), 4);
        let mut seen: Vec<i32> = (0..8).map(|s| st(s).cfx()).collect();
        seen.sort_unstable();
        assert_eq!(seen, (0..8).collect::<Vec<_>>());
    }

    #[test]
    fn turn_bits_are_the_signs_of_the_axes() {
        // A1 91, A2 −45, A3 37, A4 1, A5 −1, A6 0: bits 1 and 4, T 18.
        let q = axes_to_model(&[91.0, -45.0, 37.0, 1.0, -1.0, 0.0]);
        let t = StatusTurn {
            status: 2,
            turn: 0b010010,
        };
        assert!(t.admits(&q));
        assert!(
            !StatusTurn {
                turn: 0b010011,
                ..t
            }
            .admits(&q)
        );
    }
}
