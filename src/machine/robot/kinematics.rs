//! Forward kinematics (all joint frames and the flange) and the geometric
//! Jacobian of any point fixed to a link, in the robot base frame.
//! Units: mm, rad. Fixed-size nalgebra types, no heap.

use nalgebra::{Isometry3, Matrix6, Vector3};

use super::dh::{Convention, DhParams};

/// All frames of one configuration, expressed in the robot base frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frames {
    /// Frame `i+1` (fixed to link `i+1`); `link[5]` is the flange.
    pub link: [Isometry3<f64>; 6],
    /// A point on the axis of joint `i+1`, mm.
    pub axis_origin: [Vector3<f64>; 6],
    /// Unit direction of the axis of joint `i+1` (positive rotation sense).
    pub axis_dir: [Vector3<f64>; 6],
}

impl Frames {
    /// Flange frame in the robot base frame.
    pub fn flange(&self) -> Isometry3<f64> {
        self.link[5]
    }
}

/// Computes every joint frame for joint values `q` (rad).
pub fn frames(p: &DhParams, q: &[f64; 6]) -> Frames {
    let mut link = [Isometry3::identity(); 6];
    let mut axis_origin = [Vector3::zeros(); 6];
    let mut axis_dir = [Vector3::z(); 6];
    let mut prev = Isometry3::identity();
    for i in 0..6 {
        let t = prev * p.joints[i].transform(p.convention, q[i]);
        match p.convention {
            // Classic: joint i turns about z of frame i-1.
            Convention::Dh => {
                axis_origin[i] = prev.translation.vector;
                axis_dir[i] = prev.rotation * Vector3::z();
            }
            // Modified: joint i turns about z of frame i.
            Convention::ModifiedDh => {
                axis_origin[i] = t.translation.vector;
                axis_dir[i] = t.rotation * Vector3::z();
            }
        }
        link[i] = t;
        prev = t;
    }
    Frames {
        link,
        axis_origin,
        axis_dir,
    }
}

/// Flange pose in the robot base frame.
pub fn flange(p: &DhParams, q: &[f64; 6]) -> Isometry3<f64> {
    frames(p, q).flange()
}

/// Geometric Jacobian (rows: linear velocity mm/rad, then angular velocity)
/// of a point given in the frame of link `link` (0-based: 5 = flange);
/// columns of joints beyond that link are zero.
pub fn jacobian_link(f: &Frames, link: usize, point_in_link: &Vector3<f64>) -> Matrix6<f64> {
    let link = link.min(5);
    let p = f.link[link] * nalgebra::Point3::from(*point_in_link);
    let mut j = Matrix6::zeros();
    for i in 0..=link {
        let z = f.axis_dir[i];
        let v = z.cross(&(p.coords - f.axis_origin[i]));
        j.fixed_view_mut::<3, 1>(0, i).copy_from(&v);
        j.fixed_view_mut::<3, 1>(3, i).copy_from(&z);
    }
    j
}

/// Geometric Jacobian of a point fixed to the flange (given in the flange
/// frame): `[ṗ; ω] = J q̇`, in the robot base frame.
pub fn jacobian(f: &Frames, point_in_flange: &Vector3<f64>) -> Matrix6<f64> {
    jacobian_link(f, 5, point_in_flange)
}
