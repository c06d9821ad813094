//! Forward kinematics (all joint frames and the flange) and the geometric
//! Jacobian of any point fixed to a link, in the robot base frame.
//! Units: mm, rad. Fixed-size nalgebra types, no heap.

use nalgebra::{Isometry3, Matrix6, Quaternion, Translation3, UnitQuaternion, Vector3};

use super::dh::{Convention, DhJoint, DhParams};

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

/// [`DhJoint::transform`] as one closed-form product (two sine/cosine pairs,
/// no intermediate isometries): with the half-angle quaternions
/// `qz = (cz, 0, 0, sz)` of θ and `qx = (cx, sx, 0, 0)` of α,
/// `qz·qx = (cz·cx, cz·sx, sz·sx, sz·cx)` (classic, translation
/// `Rz(θ)·(a, 0, d)`) and `qx·qz = (cx·cz, sx·cz, −sx·sz, cx·sz)` (modified,
/// translation `(a, 0, 0) + Rx(α)·(0, 0, d)`).
#[cfg(test)]
pub(crate) fn joint_transform(j: &DhJoint, convention: Convention, q: f64) -> Isometry3<f64> {
    prepared_transform(&PreparedJoint::new(j), convention, q)
}

/// A DH row with the half-angle sine and cosine of its twist precomputed
/// (constant for a parameter set: the iterations reuse them).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct PreparedJoint {
    a_mm: f64,
    d_mm: f64,
    theta_offset_rad: f64,
    sx: f64,
    cx: f64,
}

impl PreparedJoint {
    fn new(j: &DhJoint) -> Self {
        let (sx, cx) = (0.5 * j.alpha_rad).sin_cos();
        PreparedJoint {
            a_mm: j.a_mm,
            d_mm: j.d_mm,
            theta_offset_rad: j.theta_offset_rad,
            sx,
            cx,
        }
    }
}

/// A parameter set with every row prepared ([`PreparedJoint`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Prepared {
    convention: Convention,
    joints: [PreparedJoint; 6],
}

impl Prepared {
    /// Prepares every row of `p`.
    pub(crate) fn new(p: &DhParams) -> Self {
        Prepared {
            convention: p.convention,
            joints: p.joints.each_ref().map(PreparedJoint::new),
        }
    }

    /// These rows with the lengths and joint offsets of `p`, keeping the
    /// precomputed twists: for a parameter set whose twists equal these
    /// (a thermal growth changes lengths only), the same as
    /// `Prepared::new(p)` without its sines and cosines.
    pub(crate) fn with_lengths_of(&self, p: &DhParams) -> Self {
        let mut out = *self;
        for (o, j) in out.joints.iter_mut().zip(&p.joints) {
            o.a_mm = j.a_mm;
            o.d_mm = j.d_mm;
            o.theta_offset_rad = j.theta_offset_rad;
        }
        out
    }

    /// The convention of the rows.
    pub(crate) fn convention(&self) -> Convention {
        self.convention
    }

    /// The prepared rows.
    pub(crate) fn joints(&self) -> &[PreparedJoint; 6] {
        &self.joints
    }
}

/// [`joint_transform`] of a prepared row.
pub(crate) fn prepared_transform(
    j: &PreparedJoint,
    convention: Convention,
    q: f64,
) -> Isometry3<f64> {
    let (sz, cz) = half_angle(j, q);
    transform_of_half_angle(j, convention, sz, cz)
}

/// The half-angle sine and cosine `(sin θ/2, cos θ/2)` of a row's joint
/// angle `θ = q + offset` (the only transcendental part of a transform).
fn half_angle(j: &PreparedJoint, q: f64) -> (f64, f64) {
    let theta = q + j.theta_offset_rad;
    (0.5 * theta).sin_cos()
}

/// [`prepared_transform`] from the half-angle sine and cosine of its joint
/// angle ([`half_angle`]): the same arithmetic, so the same bits.
fn transform_of_half_angle(
    j: &PreparedJoint,
    convention: Convention,
    sz: f64,
    cz: f64,
) -> Isometry3<f64> {
    let (sx, cx) = (j.sx, j.cx);
    let (t, r) = match convention {
        Convention::Dh => {
            let (s, c) = (2.0 * sz * cz, cz * cz - sz * sz);
            (
                Translation3::new(j.a_mm * c, j.a_mm * s, j.d_mm),
                Quaternion::new(cz * cx, cz * sx, sz * sx, sz * cx),
            )
        }
        Convention::ModifiedDh => {
            let (s, c) = (2.0 * sx * cx, cx * cx - sx * sx);
            (
                Translation3::new(j.a_mm, -j.d_mm * s, j.d_mm * c),
                Quaternion::new(cx * cz, sx * cz, -sx * sz, cx * sz),
            )
        }
    };
    Isometry3::from_parts(t, UnitQuaternion::new_unchecked(r))
}

/// Computes every joint frame for joint values `q` (rad).
pub fn frames(p: &DhParams, q: &[f64; 6]) -> Frames {
    frames_upto(p, q, 6)
}

/// [`frames`] of the first `n` links only (the others stay at the
/// identity): the confdata test needs the frames up to the wrist centre.
pub(crate) fn frames_upto(p: &DhParams, q: &[f64; 6], n: usize) -> Frames {
    frames_prepared(&Prepared::new(p), q, n)
}

/// [`frames_upto`] of a prepared parameter set.
pub(crate) fn frames_prepared(p: &Prepared, q: &[f64; 6], n: usize) -> Frames {
    frames_core(p, None, q, n).0
}

/// The half-angle sine and cosine `(sin θi/2, cos θi/2)` of each joint
/// angle `θi = qi + offset_i` of a configuration.
pub(crate) type HalfAngles = [(f64, f64); 6];

/// [`frames_prepared`] of all six links, with the half angles it used.
pub(crate) fn frames_with_half_angles(p: &Prepared, q: &[f64; 6]) -> (Frames, HalfAngles) {
    let (f, _, half) = frames_core(p, None, q, 6);
    (f, half)
}

/// The frames of the first `n` links of `p` at `q`, the flange of `twin`
/// accumulated from the same half angles (the identity without a twin),
/// and the half angles. [`prepared_transform`] is [`half_angle`] followed
/// by [`transform_of_half_angle`], so every caller gets the bits of the
/// transform-by-transform product.
fn frames_core(
    p: &Prepared,
    twin: Option<&Prepared>,
    q: &[f64; 6],
    n: usize,
) -> (Frames, Isometry3<f64>, HalfAngles) {
    let mut link = [Isometry3::identity(); 6];
    let mut axis_origin = [Vector3::zeros(); 6];
    let mut axis_dir = [Vector3::z(); 6];
    let mut half = [(0.0, 1.0); 6];
    let mut prev = Isometry3::identity();
    let mut other = Isometry3::identity();
    for (i, (j, qi)) in p.joints.iter().zip(q).enumerate().take(n.min(6)) {
        let (sz, cz) = half_angle(j, *qi);
        half[i] = (sz, cz);
        let t = prev * transform_of_half_angle(j, p.convention, sz, cz);
        if let Some(jt) = twin.and_then(|tw| tw.joints.get(i)) {
            other *= transform_of_half_angle(jt, p.convention, sz, cz);
        }
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
    (
        Frames {
            link,
            axis_origin,
            axis_dir,
        },
        other,
        half,
    )
}

/// Largest half deflection `|Δq/2|` (rad) whose sine and cosine
/// [`flange_deflected`] takes from their series: the first omitted terms
/// (`δ⁷/5040`, `δ⁸/40320`) stay below 2e-18, far under the rounding of the
/// result.
const SERIES_MAX_RAD: f64 = 1e-2;

/// [`flange_prepared`] at `q + dq` from the half angles of `q`
/// ([`frames_with_half_angles`]): each half angle is turned by `dq/2`
/// (angle addition with the sine and cosine of the small `dq/2` from their
/// series) instead of calling `sin_cos` again; larger deflections take
/// `sin_cos` of the deflected angle. The same pose as [`flange_prepared`]
/// up to rounding (a few units in the last place of each half angle).
pub(crate) fn flange_deflected(
    p: &Prepared,
    q: &[f64; 6],
    half: &HalfAngles,
    dq: &[f64; 6],
) -> Isometry3<f64> {
    let mut prev = Isometry3::identity();
    for (((j, qi), (s, c)), d) in p.joints.iter().zip(q).zip(half).zip(dq) {
        let e = 0.5 * d;
        let (sz, cz) = if e.abs() <= SERIES_MAX_RAD {
            let e2 = e * e;
            let se = e * (1.0 - e2 / 6.0 * (1.0 - e2 / 20.0));
            let ce = 1.0 - e2 / 2.0 * (1.0 - e2 / 12.0 * (1.0 - e2 / 30.0));
            (s * ce + c * se, c * ce - s * se)
        } else {
            half_angle(j, qi + d)
        };
        prev *= transform_of_half_angle(j, p.convention, sz, cz);
    }
    prev
}

/// The flange of [`frames_prepared`] alone (the same products, no axes
/// and no stored link frames): for poses whose torques are not needed.
pub(crate) fn flange_prepared(p: &Prepared, q: &[f64; 6]) -> Isometry3<f64> {
    let mut prev = Isometry3::identity();
    for (j, qi) in p.joints.iter().zip(q) {
        prev *= prepared_transform(j, p.convention, *qi);
    }
    prev
}

/// [`frames_prepared`] of all six links of `p` together with
/// [`flange_prepared`] of `twin`, a parameter set with the same twists and
/// joint offsets as `p` (e.g. `p` with the thermal growth of its lengths,
/// [`Prepared::with_lengths_of`]): the two chains share their half angles
/// and their rotations, and only the translations are accumulated twice.
/// The same arithmetic as the two separate calls, so the same bits; `None`
/// when the twists or joint offsets differ (bit for bit) or the
/// conventions do.
pub(crate) fn frames_and_twin_flange(
    p: &Prepared,
    twin: &Prepared,
    q: &[f64; 6],
) -> Option<(Frames, Isometry3<f64>, HalfAngles)> {
    let same = p.convention == twin.convention
        && p.joints.iter().zip(&twin.joints).all(|(a, b)| {
            a.theta_offset_rad.to_bits() == b.theta_offset_rad.to_bits()
                && a.sx.to_bits() == b.sx.to_bits()
                && a.cx.to_bits() == b.cx.to_bits()
        });
    if !same {
        return None;
    }
    Some(frames_core(p, Some(twin), q, 6))
}

/// What the confdata test needs of a configuration (frames up to the
/// wrist centre), as [`frames_prepared`] with `n = 5` computes it, without
/// the other axes and links.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct WristFrames {
    /// Origin of frame 5 (the wrist centre of a spherical wrist).
    pub wrist_centre: Vector3<f64>,
    /// x axis of frame 1.
    pub x1: Vector3<f64>,
    /// Points on the axes of joints 1, 2 and 3 (`axis_origin[0..3]`).
    pub axis_origin: [Vector3<f64>; 3],
    /// Direction of the axis of joint 2 (`axis_dir[1]`).
    pub axis_dir_2: Vector3<f64>,
}

/// [`WristFrames`] of joint values `q`: the products of
/// [`frames_prepared`] (same bits) over the first five links only, no
/// frames stored.
pub(crate) fn wrist_frames(p: &Prepared, q: &[f64; 6]) -> WristFrames {
    let mut prev = Isometry3::identity();
    let mut axis_origin = [Vector3::zeros(); 3];
    let mut axis_dir_2 = Vector3::z();
    let mut x1 = Vector3::x();
    for (i, (j, qi)) in p.joints.iter().zip(q).enumerate().take(5) {
        let t = prev * prepared_transform(j, p.convention, *qi);
        let axis = match p.convention {
            Convention::Dh => &prev,
            Convention::ModifiedDh => &t,
        };
        if i < 3 {
            axis_origin[i] = axis.translation.vector;
        }
        if i == 1 {
            axis_dir_2 = axis.rotation * Vector3::z();
        }
        if i == 0 {
            x1 = t.rotation * Vector3::x();
        }
        prev = t;
    }
    WristFrames {
        wrist_centre: prev.translation.vector,
        x1,
        axis_origin,
        axis_dir_2,
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

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    /// Agreement of the closed-form joint transform with the product of
    /// elementary transforms ([`DhJoint::transform`]): rounding only, for
    /// rotation-matrix entries and for positions of links up to 600 mm.
    const ROT_TOL: f64 = 1e-12;
    const POS_TOL_MM: f64 = 1e-9;

    /// The shared and lean chains run the same arithmetic as the
    /// reference ones: equal to the last bit.
    const SAME: f64 = 0.0;

    /// The parameter sets of the bundled robot files, in both conventions
    /// (the same rows read as classic DH too), nominal and actual.
    fn parameter_sets() -> Vec<DhParams> {
        use crate::machine::Machine;
        use crate::machine::robot::Model;
        let files = [
            (
                include_str!("../../../machines/abb-irb1600.yaml"),
                "abb-irb1600.yaml",
            ),
            (
                include_str!("../../../machines/staubli-tx200.yaml"),
                "staubli-tx200.yaml",
            ),
        ];
        let mut out = Vec::new();
        for (text, file) in files {
            let Ok(Machine::Robot(r)) = Machine::from_yaml_str(text, file) else {
                panic!("{file} is a robot file")
            };
            for model in [Model::Nominal, Model::Actual] {
                let p = *r.params(model);
                out.push(p);
                out.push(DhParams {
                    convention: Convention::Dh,
                    ..p
                });
            }
        }
        out
    }

    /// Random joint vectors in ±π (a fixed linear congruential sequence).
    fn random_joints(n: usize) -> Vec<[f64; 6]> {
        let mut next = crate::machine::robot::test_sequence(0x9e37_79b9_7f4a_7c15);
        (0..n)
            .map(|_| std::array::from_fn(|_| next() * std::f64::consts::PI))
            .collect()
    }

    /// Positions within `pos_mm`, rotation matrices within `rot`.
    fn assert_pose_near(a: &Isometry3<f64>, b: &Isometry3<f64>, pos_mm: f64, rot: f64) {
        assert_abs_diff_eq!(a.translation.vector, b.translation.vector, epsilon = pos_mm);
        assert_abs_diff_eq!(
            a.rotation.to_rotation_matrix().into_inner(),
            b.rotation.to_rotation_matrix().into_inner(),
            epsilon = rot
        );
    }

    fn assert_same_pose(a: &Isometry3<f64>, b: &Isometry3<f64>) {
        assert_abs_diff_eq!(a.translation.vector, b.translation.vector, epsilon = SAME);
        assert_abs_diff_eq!(a.rotation.coords, b.rotation.coords, epsilon = SAME);
    }

    #[test]
    fn twin_flange_equals_the_separate_chains() {
        for p in parameter_sets() {
            let prep = Prepared::new(&p);
            // A thermal growth: other lengths, the same twists and offsets.
            let mut g = p;
            for (k, j) in g.joints.iter_mut().enumerate() {
                j.a_mm += 0.013 * k as f64;
                j.d_mm -= 0.007 * k as f64;
            }
            let twin = prep.with_lengths_of(&g);
            for q in random_joints(100) {
                let Some((f, other, _)) = frames_and_twin_flange(&twin, &prep, &q) else {
                    panic!("a length change keeps the twists and offsets")
                };
                let f_ref = frames_prepared(&twin, &q, 6);
                for i in 0..6 {
                    assert_same_pose(&f.link[i], &f_ref.link[i]);
                    assert_abs_diff_eq!(f.axis_origin[i], f_ref.axis_origin[i], epsilon = SAME);
                    assert_abs_diff_eq!(f.axis_dir[i], f_ref.axis_dir[i], epsilon = SAME);
                }
                assert_same_pose(&other, &flange_prepared(&prep, &q));
            }
            // Another joint offset: no shared chain.
            let mut moved = p;
            moved.joints[2].theta_offset_rad += 1e-3;
            let moved = prep.with_lengths_of(&moved);
            assert!(frames_and_twin_flange(&moved, &prep, &[0.1; 6]).is_none());
        }
    }

    /// [`flange_deflected`] against the forward kinematics of the
    /// deflected joints: rounding only (a few ulp of each half angle, over
    /// links up to about 1.5 m), for deflections below and above the series
    /// range, and the same half angles as [`frames_prepared`] uses.
    #[test]
    fn deflected_flange_equals_the_deflected_forward_kinematics() {
        const POS_ROUNDING_MM: f64 = 1e-11;
        const ROT_ROUNDING: f64 = 1e-14;
        for p in parameter_sets() {
            let prep = Prepared::new(&p);
            for (k, q) in random_joints(200).into_iter().enumerate() {
                let scale = [1e-6, 1e-4, 5e-3, 1.9e-2, 0.3][k % 5];
                let dq: [f64; 6] = std::array::from_fn(|i| {
                    scale
                        * (q[(i + 1) % 6] / std::f64::consts::PI)
                        * if i % 2 == 0 { 1.0 } else { -1.0 }
                });
                let (f, half) = frames_with_half_angles(&prep, &q);
                let f_ref = frames_prepared(&prep, &q, 6);
                for i in 0..6 {
                    assert_same_pose(&f.link[i], &f_ref.link[i]);
                }
                let qd: [f64; 6] = std::array::from_fn(|i| q[i] + dq[i]);
                let fast = flange_deflected(&prep, &q, &half, &dq);
                let slow = flange_prepared(&prep, &qd);
                assert_pose_near(&fast, &slow, POS_ROUNDING_MM, ROT_ROUNDING);
            }
        }
    }

    #[test]
    fn wrist_frames_equal_the_full_frames() {
        for p in parameter_sets() {
            let prep = Prepared::new(&p);
            for q in random_joints(100) {
                let w = wrist_frames(&prep, &q);
                let f = frames_prepared(&prep, &q, 5);
                assert_abs_diff_eq!(w.wrist_centre, f.link[4].translation.vector, epsilon = SAME);
                assert_abs_diff_eq!(w.x1, f.link[0].rotation * Vector3::x(), epsilon = SAME);
                for i in 0..3 {
                    assert_abs_diff_eq!(w.axis_origin[i], f.axis_origin[i], epsilon = SAME);
                }
                assert_abs_diff_eq!(w.axis_dir_2, f.axis_dir[1], epsilon = SAME);
            }
        }
    }

    #[test]
    fn closed_form_joint_transform_matches_elementary_product() {
        let rows = [
            (150.0, -1.2, 486.5, 0.3),
            (0.0, std::f64::consts::FRAC_PI_2, 0.0, -0.7),
            (-25.0, 2.9, -600.0, 3.0),
        ];
        for (a, alpha, d, off) in rows {
            let j = DhJoint {
                a_mm: a,
                alpha_rad: alpha,
                d_mm: d,
                theta_offset_rad: off,
            };
            for conv in [Convention::Dh, Convention::ModifiedDh] {
                for q in [-3.0, -0.4, 0.0, 1.1, 2.5] {
                    let fast = joint_transform(&j, conv, q);
                    let slow = j.transform(conv, q);
                    assert_pose_near(&fast, &slow, POS_TOL_MM, ROT_TOL);
                }
            }
        }
    }
}
