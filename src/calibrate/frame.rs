//! Measurement frames: observations in the world frame of a robot (through
//! the machine file's `base`) brought into the reference frame, and the
//! rigid transform of an instrument frame — its first registration
//! (least-squares rigid fit, Kabsch) and its six identification parameters.
//!
//! The instrument frame `F` is the pose of the instrument in the machine's
//! reference frame: a point measured at `m` (instrument coordinates) is at
//! `F · m` in the reference frame. Identification parameters: the origin
//! of `F` (mm, `frame.x_mm` …) and a small rotation of `F` about the
//! reference frame's axes through that origin (mrad, `frame.rx_mrad` …),
//! `F(δ) = (Rot(δr) · R₀, t₀ + δt)`: the translation parameters are the
//! origin itself, so its uncertainty is theirs.

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};

use crate::machine::Machine;

use super::observations::{MeasurementFrame, Observations};

/// Number of frame parameters.
pub const FRAME_PARAMS: usize = 6;

/// Names and units of the frame parameters.
pub const FRAME_NAMES: [(&str, &str); FRAME_PARAMS] = [
    ("frame.x_mm", "mm"),
    ("frame.y_mm", "mm"),
    ("frame.z_mm", "mm"),
    ("frame.rx_deg", "deg"),
    ("frame.ry_deg", "deg"),
    ("frame.rz_deg", "deg"),
];

/// The frame `F(δ)` for parameters `δ = [δt (mm); δr (mrad)]` around `f0`.
pub fn frame_with(f0: &Isometry3<f64>, d: &[f64]) -> Isometry3<f64> {
    let v = |k: usize| d.get(k).copied().unwrap_or(0.0);
    let rot = UnitQuaternion::from_scaled_axis(Vector3::new(v(3), v(4), v(5)) * 1e-3);
    Isometry3::from_parts(
        Translation3::from(f0.translation.vector + Vector3::new(v(0), v(1), v(2))),
        rot * f0.rotation,
    )
}

/// Roll, pitch, yaw of a rotation, degrees.
pub fn rpy_deg(f: &Isometry3<f64>) -> [f64; 3] {
    let (r, p, y) = f.rotation.euler_angles();
    [r.to_degrees(), p.to_degrees(), y.to_degrees()]
}

/// The rigid transform `F` minimising `Σ ‖F · m_i − p_i‖²` (Kabsch: SVD of
/// the cross-covariance of the centred point sets, with the reflection
/// removed). `None` for fewer than 3 points or points on one line (the
/// rotation about that line is not determined).
pub fn register(measured: &[Vector3<f64>], model: &[Vector3<f64>]) -> Option<Isometry3<f64>> {
    let n = measured.len();
    if n < 3 || model.len() != n {
        return None;
    }
    let cm = measured.iter().sum::<Vector3<f64>>() / n as f64;
    let cp = model.iter().sum::<Vector3<f64>>() / n as f64;
    let mut h = Matrix3::zeros();
    for (m, p) in measured.iter().zip(model) {
        h += (m - cm) * (p - cp).transpose();
    }
    let svd = h.svd(true, true);
    let (u, vt) = (svd.u?, svd.v_t?);
    let s = &svd.singular_values;
    let mut sorted = [s[0], s[1], s[2]];
    sorted.sort_by(f64::total_cmp);
    // Two vanishing singular values: collinear points.
    let floor = 1e-9 * sorted[2].max(f64::MIN_POSITIVE);
    if sorted[1].is_nan() || sorted[1] <= floor {
        return None;
    }
    let mut d = Matrix3::identity();
    if (vt.transpose() * u.transpose()).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let r = vt.transpose() * d * u.transpose();
    let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    let t = cp - rot * cm;
    Some(Isometry3::from_parts(Translation3::from(t), rot))
}

/// The note of a command that read robot positions in the world frame
/// (`# frame: world`): they were carried into the robot base frame through
/// the machine file's `base`, given as position (mm) and roll, pitch, yaw
/// (deg). `None` for any other frame or machine.
pub fn world_note(machine: &Machine, frame: MeasurementFrame) -> Option<String> {
    let Machine::Robot(r) = machine else {
        return None;
    };
    if frame != MeasurementFrame::World {
        return None;
    }
    let b = r.base();
    // Rounded to the printed digits first: no `-0.0000`.
    let shown = |v: f64, digits: i32| {
        let s = 10f64.powi(digits);
        (v * s).round() / s + 0.0
    };
    let t = b.translation.vector.map(|v| shown(v, 4));
    let [roll, pitch, yaw] = rpy_deg(b).map(|v| shown(v, 6));
    Some(format!(
        "positions in the world frame, carried into the robot base frame through the \
         machine file's `base` (x {:.4} y {:.4} z {:.4} mm, roll {roll:.6} pitch {pitch:.6} \
         yaw {yaw:.6} deg)",
        t.x, t.y, t.z
    ))
}

/// Observations in the world frame (`# frame: world`) brought into the
/// robot base frame through the machine file's `base`; other frames are
/// returned unchanged.
pub fn world_to_reference(machine: &Machine, obs: &Observations) -> Observations {
    let mut out = obs.clone();
    if obs.frame != MeasurementFrame::World {
        return out;
    }
    if let Machine::Robot(r) = machine {
        let inv = r.base().inverse();
        for row in &mut out.rows {
            row.measured_mm = (inv * nalgebra::Point3::from(row.measured_mm)).coords;
            row.orientation = row.orientation.map(|q| inv.rotation * q);
        }
    }
    out.frame = MeasurementFrame::Reference;
    out
}

/// Standard uncertainties of a registered frame `f` (translation mm,
/// rotation about the reference axes deg) from the residuals
/// `f · m_i − p_i` of its points: `σ² (JᵀJ)⁻¹` with the Jacobian of the
/// six parameters of [`frame_with`] and `σ² = RSS / (3n − 6)`. `None`
/// without redundancy or for a singular design.
pub fn frame_uncertainty(
    f: &Isometry3<f64>,
    measured: &[Vector3<f64>],
    model: &[Vector3<f64>],
) -> Option<([f64; 3], [f64; 3])> {
    let n = measured.len().min(model.len());
    if 3 * n <= FRAME_PARAMS {
        return None;
    }
    let mut jtj = nalgebra::Matrix6::<f64>::zeros();
    let mut rss = 0.0;
    for (m, p) in measured.iter().zip(model) {
        let v = f.rotation * m;
        let e = v + f.translation.vector - p;
        rss += e.norm_squared();
        // ∂(F·m)/∂δt = I; ∂(F·m)/∂δr = −[v]× per rad.
        let mut j = nalgebra::Matrix3x6::<f64>::zeros();
        j.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&Matrix3::identity());
        j.fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&(-v.cross_matrix()));
        jtj += j.transpose() * j;
    }
    let cov = jtj.try_inverse()? * (rss / (3 * n - FRAME_PARAMS) as f64);
    let u = |k: usize| cov[(k, k)].max(0.0).sqrt();
    Some((
        [u(0), u(1), u(2)],
        [u(3).to_degrees(), u(4).to_degrees(), u(5).to_degrees()],
    ))
}

/// Runs a calibration on instrument-frame observations by alternation:
/// the frame is registered to the start model's predictions, the
/// calibration runs on the positions carried into the reference frame, the
/// frame is registered again to the calibrated model and the calibration
/// repeated from the start file. The result carries the final frame with
/// its uncertainty (from the registration residuals) and the file gets its
/// `measurement_frame`. (Kinematic calibration identifies the frame
/// together with the model instead.)
pub fn calibrate_by_registration(
    text: &str,
    machine_file: &str,
    obs: &Observations,
    obs_file: &str,
    run: &dyn Fn(&Observations) -> crate::error::Result<super::report::Calibration>,
) -> crate::error::Result<super::report::Calibration> {
    use crate::error::Error;
    let start = Machine::from_yaml_str(text, machine_file)?;
    let attained = |m: &Machine| -> crate::error::Result<Vec<Vector3<f64>>> {
        obs.rows
            .iter()
            .map(|r| super::forward::predict(m, r, obs_file).map(|p| p.attained_mm))
            .collect()
    };
    let measured: Vec<Vector3<f64>> = obs.rows.iter().map(|r| r.measured_mm).collect();
    let refuse = || {
        Error::Usage(format!(
            "{obs_file}: the measured points lie on a line or are too few: the instrument \
             frame cannot be registered; measure varied poses"
        ))
    };
    let carried = |f: &Isometry3<f64>| {
        let mut o = obs.clone();
        o.frame = MeasurementFrame::Reference;
        for r in &mut o.rows {
            r.measured_mm = (f * nalgebra::Point3::from(r.measured_mm)).coords;
            r.orientation = r.orientation.map(|q| f.rotation * q);
        }
        o
    };
    let f1 = register(&measured, &attained(&start)?).ok_or_else(refuse)?;
    let first = run(&carried(&f1))?;
    let calibrated = Machine::from_yaml_str(&first.yaml, machine_file)?;
    let model = attained(&calibrated)?;
    let f2 = register(&measured, &model).ok_or_else(refuse)?;
    let mut cal = run(&carried(&f2))?;
    let model = attained(&Machine::from_yaml_str(&cal.yaml, machine_file)?)?;
    let f3 = register(&measured, &model).ok_or_else(refuse)?;
    let u = frame_uncertainty(&f3, &measured, &model);
    let est = super::report::FrameEstimate {
        xyz_mm: f3.translation.vector.into(),
        rpy_deg: rpy_deg(&f3),
        u_xyz_mm: u.map(|u| u.0),
        u_rot_deg: u.map(|u| u.1),
    };
    cal.yaml =
        super::yaml_edit::set_measurement_frame(&cal.yaml, machine_file, est.xyz_mm, est.rpy_deg)?;
    Machine::from_yaml_str(&cal.yaml, machine_file)?;
    cal.frame = Some(est);
    cal.notes.push(
        "positions measured in an instrument frame: the frame is registered to the model \
         (alternating with the calibration, not fitted with it; its uncertainty is that of \
         the registration) and written to `measurement_frame`; parameters that move the \
         points rigidly are not told from the frame"
            .into(),
    );
    Ok(cal)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    const TOL_MM: f64 = 1e-9;

    /// Points moved by a known transform are registered back to it.
    #[test]
    fn register_recovers_a_rigid_transform() {
        let f = Isometry3::from_parts(
            Translation3::new(2500.0, -800.0, 300.0),
            UnitQuaternion::from_euler_angles(0.1, -0.2, 2.5),
        );
        let model: Vec<Vector3<f64>> = (0..10)
            .map(|k| {
                let k = k as f64;
                Vector3::new(100.0 * k, 50.0 * (k * 0.7).sin(), 30.0 * k * k)
            })
            .collect();
        let measured: Vec<Vector3<f64>> = model
            .iter()
            .map(|p| (f.inverse() * nalgebra::Point3::from(*p)).coords)
            .collect();
        let got = register(&measured, &model).expect("registers");
        for (m, p) in measured.iter().zip(&model) {
            assert_abs_diff_eq!(
                (got * nalgebra::Point3::from(*m)).coords,
                *p,
                epsilon = TOL_MM
            );
        }
        let line: Vec<Vector3<f64>> = (0..5).map(|k| Vector3::x() * k as f64).collect();
        assert!(register(&line, &line).is_none());
    }

    #[test]
    fn small_rotation_parameters_turn_about_the_reference_axes() {
        let f0 = Isometry3::translation(1000.0, 0.0, 0.0);
        // 1 mrad about z: the frame axes turn, the origin stays.
        let f = frame_with(&f0, &[0.0, 0.0, 0.0, 0.0, 0.0, 1.0]);
        assert_abs_diff_eq!(
            f.translation.vector,
            f0.translation.vector,
            epsilon = TOL_MM
        );
        let y = f * nalgebra::Point3::new(1000.0, 0.0, 0.0);
        assert_abs_diff_eq!(y.y, 1.0, epsilon = 1e-3);
    }
}
