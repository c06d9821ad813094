//! FANUC joint angles and the `CONFIG` of a Cartesian position, in the
//! robot model's terms.
//!
//! The bundled FANUC models (machines/fanuc-*.yaml) use the row pattern
//! of the ABB arms with the faceplate as the flange frame. FANUC's J3 is
//! the forearm's angle from the horizontal (the J2/J3 coupling of its
//! parallel-link arms: moving J2 alone keeps the forearm's attitude), and
//! J4, J5, J6 turn the other way to the model's joints:
//! [`joints_to_model`], [`model_to_joints`] (the relation the
//! ROS-Industrial FANUC driver uses, `J3_ros = J3 + J2`, and the joint
//! axes of its arm descriptions).
//!
//! `CONFIG : 'F U T, t1, t4, t6'` (see grammar/tp.md for the sources):
//! - `F`/`N`: wrist flipped when J5 is positive (the model's q5 < 0, its
//!   cfx bit 1); `N` at J5 = 0;
//! - `U`/`D`: elbow up when the wrist centre is in front of the lower arm
//!   (the model's cfx bit 2 clear), down behind it;
//! - `T`/`B`: the wrist centre in front of axis 1 (`T`, the model's cfx bit
//!   4 clear) or behind it (`B`);
//! - `t1, t4, t6`: the turn numbers of J1, J4 and J6: 0 for an angle in
//!   (−180°, 180°], 1 in (180°, 540°], −1 in (−540°, −180°].

use std::fmt;

use crate::machine::robot::Robot;

/// The model's joints (rad) of FANUC joint angles J1…J6 (degrees).
pub fn joints_to_model(j_deg: &[f64; 6]) -> [f64; 6] {
    let j = j_deg;
    [j[0], j[1], -(j[2] + j[1]), -j[3], -j[4], -j[5]].map(f64::to_radians)
}

/// FANUC joint angles J1…J6 (degrees) of the model's joints (rad).
pub fn model_to_joints(q: &[f64; 6]) -> [f64; 6] {
    let d = q.map(f64::to_degrees);
    [d[0], d[1], -d[2] - d[1], -d[3], -d[4], -d[5]]
}

/// The turn number of a joint angle in degrees.
pub fn turn_number(j_deg: f64) -> i32 {
    ((j_deg - 180.0) / 360.0).ceil() as i32
}

/// A FANUC configuration: the three letters and the turn numbers of J1,
/// J4 and J6.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Config {
    /// `F` (true) or `N`.
    pub flip: bool,
    /// `U` (true) or `D`.
    pub up: bool,
    /// `T` (true) or `B`.
    pub top: bool,
    /// Turn numbers of J1, J4, J6.
    pub turns: [i32; 3],
}

/// Why a `CONFIG` string was not read.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("a CONFIG is `F|N U|D T|B, t1, t4, t6`, found `{0}`")]
pub struct BadConfig(pub String);

impl Config {
    /// Reads the text between the quotes of `CONFIG : '…'`: three letters
    /// separated by blanks, then up to three comma-separated turn numbers
    /// (missing ones are 0), case as written by the controller (upper).
    pub fn parse(text: &str) -> Result<Config, BadConfig> {
        let bad = || BadConfig(text.to_string());
        let mut parts = text.split(',');
        let letters: Vec<&str> = parts.next().ok_or_else(bad)?.split_whitespace().collect();
        let [f, u, t] = letters.as_slice() else {
            return Err(bad());
        };
        let pick = |s: &str, yes: &str, no: &str| match s {
            _ if s.eq_ignore_ascii_case(yes) => Ok(true),
            _ if s.eq_ignore_ascii_case(no) => Ok(false),
            _ => Err(bad()),
        };
        let mut turns = [0; 3];
        for (k, p) in parts.enumerate() {
            let slot = turns.get_mut(k).ok_or_else(bad)?;
            *slot = p.trim().parse().map_err(|_| bad())?;
        }
        Ok(Config {
            flip: pick(f, "F", "N")?,
            up: pick(u, "U", "D")?,
            top: pick(t, "T", "B")?,
            turns,
        })
    }

    /// The configuration of the model's joints `q` on `robot` (a FANUC
    /// model).
    pub fn of_joints(robot: &Robot, q: &[f64; 6]) -> Config {
        let cfx = robot.confdata(q).cfx;
        let j = model_to_joints(q);
        Config {
            flip: cfx & 1 == 1,
            up: cfx & 2 == 0,
            top: cfx & 4 == 0,
            turns: [turn_number(j[0]), turn_number(j[3]), turn_number(j[5])],
        }
    }

    /// The model's cfx (0–7) of the three letters.
    pub fn cfx(self) -> i32 {
        4 * i32::from(!self.top) + 2 * i32::from(!self.up) + i32::from(self.flip)
    }

    /// Whether the model's joints `q` have the turn numbers of this
    /// configuration.
    pub fn admits(self, q: &[f64; 6]) -> bool {
        let j = model_to_joints(q);
        [j[0], j[3], j[5]]
            .iter()
            .zip(self.turns)
            .all(|(v, t)| turn_number(*v) == t)
    }

    /// Whether `q` is a solution in this configuration on `robot`.
    pub fn matches(self, robot: &Robot, q: &[f64; 6]) -> bool {
        robot.confdata(q).cfx == self.cfx() && self.admits(q)
    }
}

impl fmt::Display for Config {
    /// As the controller writes it: `N U T, 0, 0, 0`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let l = |b: bool, y: char, n: char| if b { y } else { n };
        write!(
            f,
            "{} {} {}, {}, {}, {}",
            l(self.flip, 'F', 'N'),
            l(self.up, 'U', 'D'),
            l(self.top, 'T', 'B'),
            self.turns[0],
            self.turns[1],
            self.turns[2]
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn config_strings_read_and_write_back() {
        let c = Config::parse("N U T, 0, 0, 0").expect("reads");
        assert_eq!(
            c,
            Config {
                flip: false,
                up: true,
                top: true,
                turns: [0, 0, 0]
            }
        );
        assert_eq!(c.cfx(), 0);
        let f = Config::parse("F D B, -1, 0, 1").expect("reads");
        assert_eq!((f.cfx(), f.turns), (7, [-1, 0, 1]));
        assert_eq!(f.to_string(), "F D B, -1, 0, 1");
        assert_eq!(Config::parse("N U T").expect("reads").turns, [0; 3]);
        for bad in ["", "N U", "X U T, 0, 0, 0", "N U T, 0, 0, 0, 0", "N U T, a"] {
            assert!(Config::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn turn_numbers_count_whole_turns_from_the_half_open_range() {
        let t: Vec<i32> = [0.0, 180.0, 180.5, 539.0, -180.0, -179.0, -541.0]
            .iter()
            .map(|v| turn_number(*v))
            .collect();
        assert_eq!(t, [0, 0, 1, 1, -1, 0, -2]);
    }

    #[test]
    fn j3_counts_from_the_horizontal() {
        // J2 = 30° forward with J3 = 0: the forearm stays horizontal, so
        // the model's elbow joint turns the forearm back up by 30°.
        let q = joints_to_model(&[0.0, 30.0, 0.0, 10.0, -20.0, 40.0]);
        let d = q.map(f64::to_degrees);
        assert!((d[1] - 30.0).abs() < 1e-12 && (d[2] + 30.0).abs() < 1e-12);
        assert!((d[3] + 10.0).abs() < 1e-12 && (d[4] - 20.0).abs() < 1e-12);
        let back = model_to_joints(&q);
        assert!((back[2]).abs() < 1e-12 && (back[5] - 40.0).abs() < 1e-12);
    }
}
