//! FANUC controller frames of a robot file (`fanuc:`): the user frames
//! (`UFRAME`) and tool frames (`UTOOL`) a TP program's positions name by
//! number. They live in the controller, not in the program, so the robot
//! file holds them:
//!
//! ```yaml
//! fanuc:
//!   user_frames:
//!     1: {x_mm: 800, y_mm: -200, z_mm: 0, w_deg: 0, p_deg: 0, r_deg: 90}
//!   tool_frames:
//!     2: {x_mm: 0, y_mm: 0, z_mm: 180, w_deg: 0, p_deg: 0, r_deg: 0}
//! ```
//!
//! Each frame is the controller's `X, Y, Z, W, P, R` (mm, degrees, the
//! rotation `Rz(R)·Ry(P)·Rx(W)`): a user frame in the world frame, a tool
//! frame in the faceplate frame. Frame 0 is fixed by the controller (the
//! world frame, the faceplate) and may not be given; numbers go from 1 to
//! [`MAX_FRAME`].

use std::collections::BTreeMap;

use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use serde::Deserialize;

use crate::error::Invalid;

/// The highest frame number read (FANUC's extended user and tool frames
/// go up to 61).
pub const MAX_FRAME: u32 = 61;

/// `fanuc:` as written.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawFanuc {
    #[serde(default)]
    pub user_frames: BTreeMap<u32, RawFanucFrame>,
    #[serde(default)]
    pub tool_frames: BTreeMap<u32, RawFanucFrame>,
}

/// One frame as written: the controller's `X, Y, Z, W, P, R`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawFanucFrame {
    pub x_mm: f64,
    pub y_mm: f64,
    pub z_mm: f64,
    pub w_deg: f64,
    pub p_deg: f64,
    pub r_deg: f64,
}

/// The validated frames (empty when the file has no `fanuc:`).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FanucFrames {
    user: BTreeMap<u32, Isometry3<f64>>,
    tool: BTreeMap<u32, Isometry3<f64>>,
}

impl FanucFrames {
    /// User frame `n` in the world frame: the identity for 0, `None` when
    /// the robot file does not give it.
    pub fn user(&self, n: u32) -> Option<Isometry3<f64>> {
        if n == 0 {
            return Some(Isometry3::identity());
        }
        self.user.get(&n).copied()
    }

    /// Tool frame `n` in the faceplate frame: the identity for 0, `None`
    /// when the robot file does not give it.
    pub fn tool(&self, n: u32) -> Option<Isometry3<f64>> {
        if n == 0 {
            return Some(Isometry3::identity());
        }
        self.tool.get(&n).copied()
    }
}

/// The pose of `X, Y, Z, W, P, R`: `R = Rz(R)·Ry(P)·Rx(W)` in degrees, the
/// convention `program::euler` documents for the programs (nalgebra's
/// roll-pitch-yaw is that product; the machine layer does not use the
/// program layer).
pub fn xyzwpr(x: f64, y: f64, z: f64, w: f64, p: f64, r: f64) -> Isometry3<f64> {
    let q = UnitQuaternion::from_euler_angles(w.to_radians(), p.to_radians(), r.to_radians());
    Isometry3::from_parts(Translation3::new(x, y, z), q)
}

fn frames(
    key: &str,
    raw: &BTreeMap<u32, RawFanucFrame>,
) -> Result<BTreeMap<u32, Isometry3<f64>>, Invalid> {
    let mut out = BTreeMap::new();
    for (n, f) in raw {
        let path = format!("fanuc.{key}.{n}");
        if *n == 0 || *n > MAX_FRAME {
            return Err(Invalid::new(
                path,
                format!("frame numbers go from 1 to {MAX_FRAME} (frame 0 is the controller's)"),
            ));
        }
        let v = [f.x_mm, f.y_mm, f.z_mm, f.w_deg, f.p_deg, f.r_deg];
        if let Some(bad) = v.iter().find(|v| !v.is_finite()) {
            return Err(Invalid::new(path, format!("{bad} is not a finite number")));
        }
        out.insert(*n, xyzwpr(v[0], v[1], v[2], v[3], v[4], v[5]));
    }
    Ok(out)
}

impl TryFrom<Option<&RawFanuc>> for FanucFrames {
    type Error = Invalid;
    fn try_from(raw: Option<&RawFanuc>) -> Result<Self, Invalid> {
        let Some(raw) = raw else {
            return Ok(FanucFrames::default());
        };
        Ok(FanucFrames {
            user: frames("user_frames", &raw.user_frames)?,
            tool: frames("tool_frames", &raw.tool_frames)?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn raw(n: u32, x: f64) -> RawFanuc {
        let f = RawFanucFrame {
            x_mm: x,
            y_mm: 0.0,
            z_mm: 0.0,
            w_deg: 0.0,
            p_deg: 0.0,
            r_deg: 90.0,
        };
        RawFanuc {
            user_frames: BTreeMap::from([(n, f.clone())]),
            tool_frames: BTreeMap::new(),
        }
    }

    #[test]
    fn frames_are_validated_and_frame_zero_is_the_controllers() {
        let f = FanucFrames::try_from(Some(&raw(3, 100.0))).expect("valid");
        let u = f.user(3).expect("given");
        // R = 90° about z: the frame's x axis is the world's y axis.
        let x = u.rotation * nalgebra::Vector3::x();
        assert!((x - nalgebra::Vector3::y()).norm() < 1e-12);
        assert_eq!(u.translation.vector.x, 100.0);
        assert_eq!(f.user(0), Some(Isometry3::identity()));
        assert_eq!(f.tool(0), Some(Isometry3::identity()));
        assert_eq!(f.user(1), None);
        let e = FanucFrames::try_from(Some(&raw(0, 1.0))).expect_err("frame 0");
        assert_eq!(e.path, "fanuc.user_frames.0");
        let e = FanucFrames::try_from(Some(&raw(62, 1.0))).expect_err("too high");
        assert!(e.message.contains("1 to 61"), "{e}");
        let e = FanucFrames::try_from(Some(&raw(1, f64::NAN))).expect_err("NaN");
        assert!(e.message.contains("finite"), "{e}");
    }
}
