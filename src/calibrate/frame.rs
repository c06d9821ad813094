//! Measurement frames: observations in the world frame of a robot (through
//! the machine file's `base`) brought into the reference frame, and the
//! rigid transform of an instrument frame — its first registration
//! (least-squares rigid fit, Kabsch) and its six identification parameters.
//!
//! The instrument frame `F` is the pose of the instrument in the machine's
//! reference frame: a point measured at `m` (instrument coordinates) is at
//! `F · m` in the reference frame. Identification parameters: the origin
//! of `F` (mm, `frame.x_mm` …) and a small rotation of `F` about the
//! reference frame's axes through that origin (mrad internally, reported
//! in degrees as `frame.rx_deg` …),
//! `F(δ) = (Rot(δr) · R₀, t₀ + δt)`: the translation parameters are the
//! origin itself, so its uncertainty is theirs.

use crate::machine::yaml_write::{self, Edit};
use nalgebra::{
    DMatrix, DVector, Isometry3, Matrix3, Matrix3x6, Rotation3, Translation3, UnitQuaternion,
    Vector3,
};

use crate::error::{Error, Result};
use crate::machine::Machine;

use super::lsq::{LsqOptions, solve_linear};
use super::observations::{MeasurementFrame, Observations};
use super::report::{Estimate, FrameEstimate, names_at};

/// Number of frame parameters.
pub const FRAME_PARAMS: usize = 6;

/// Relative rank threshold of the screen against the frame in the
/// calibrations of geometric tables and machine-tool thermal gains
/// (unit-norm columns): a combination of
/// model columns that the frame's columns explain to within 10⁻³ of its
/// size moves the points like a rigid motion of the instrument, up to the
/// second-order effect of the machine's own errors on the lever arms; it
/// is absorbed by the frame (as [`super::kinematics::KIN_RANK_RTOL`]).
pub const FRAME_RANK_RTOL: f64 = 1e-3;

/// Degrees per mrad (the internal unit of the frame's small rotations).
pub const DEG_PER_MRAD: f64 = 0.18 / std::f64::consts::PI;

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

/// `F · m`: a measured point carried into the reference frame.
pub fn carry(f: &Isometry3<f64>, m: &Vector3<f64>) -> Vector3<f64> {
    (f * nalgebra::Point3::from(*m)).coords
}

/// The 3 × 6 Jacobian of `F(δ) · m` at `δ = 0` ([`frame_with`] around
/// `f`): `I` for the origin (per mm) and `−[R m]×` for the small rotation
/// (per mrad).
pub fn point_jacobian(f: &Isometry3<f64>, m: &Vector3<f64>) -> Matrix3x6<f64> {
    let v = f.rotation * m;
    let mut j = Matrix3x6::zeros();
    j.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&Matrix3::identity());
    j.fixed_view_mut::<3, 3>(0, 3)
        .copy_from(&(-v.cross_matrix() * 1e-3));
    j
}

/// The frame columns of an identification Jacobian for the residuals
/// `F · m_i − model_i` of `rows` (3 equations per row, in order), at `f`.
pub fn frame_columns(f: &Isometry3<f64>, obs: &Observations, rows: &[usize]) -> DMatrix<f64> {
    let mut j = DMatrix::zeros(3 * rows.len(), FRAME_PARAMS);
    for (k, &i) in rows.iter().enumerate() {
        if let Some(row) = obs.rows.get(i) {
            j.view_mut((3 * k, 0), (3, FRAME_PARAMS))
                .copy_from(&point_jacobian(f, &row.measured_mm));
        }
    }
    j
}

/// The start pose of an instrument frame: the rigid registration (Kabsch,
/// [`register`]) of the measured points of `rows` onto the positions the
/// machine `m` predicts for them. Refused (exit 2) for points on a line or
/// fewer than three.
pub fn start_frame(
    m: &Machine,
    obs: &Observations,
    rows: &[usize],
    obs_file: &str,
) -> Result<Isometry3<f64>> {
    let mut meas = Vec::with_capacity(rows.len());
    let mut model = Vec::with_capacity(rows.len());
    for &i in rows {
        if let Some(row) = obs.rows.get(i) {
            meas.push(row.measured_mm);
            model.push(super::forward::predict(m, row, obs_file)?.attained_mm);
        }
    }
    register(&meas, &model).ok_or_else(|| not_registered(obs_file, rows.len()))
}

/// The refusal of points that cannot register a frame (`n` fit rows).
fn not_registered(obs_file: &str, n: usize) -> Error {
    Error::Data(format!(
        "{obs_file}: the measured points lie on a line or are too few (fit rows: {n}): \
         the instrument frame cannot be registered; measure varied poses"
    ))
}

/// The instrument frame re-solved alone for a model whose values are
/// fixed (the written ones, after the honesty rule kept some at the
/// file's value): the rigid registration ([`register`]) of the `measured`
/// points onto the positions `model` that model predicts for them. Its
/// standard uncertainties (origin mm, small rotations mrad, the order of
/// [`FRAME_NAMES`]) are per component the larger of the registration's
/// own ([`frame_uncertainty`]) and `joint`, those of the joint fit with
/// the withheld values fixed ([`conditional_uncertainty`]), which carry
/// the uncertainty of the model values taken from it. Refused for points
/// on a line or fewer than three.
pub fn refit(
    measured: &[Vector3<f64>],
    model: &[Vector3<f64>],
    joint: Option<[f64; FRAME_PARAMS]>,
    obs_file: &str,
) -> Result<(Isometry3<f64>, Option<[f64; FRAME_PARAMS]>)> {
    let f = register(measured, model).ok_or_else(|| not_registered(obs_file, measured.len()))?;
    let own = frame_uncertainty(&f, measured, model).map(|(t, r)| {
        let mrad = |deg: f64| deg.to_radians() * 1e3;
        [t[0], t[1], t[2], mrad(r[0]), mrad(r[1]), mrad(r[2])]
    });
    let u = match (own, joint) {
        (Some(a), Some(b)) => Some(std::array::from_fn(|k| a[k].max(b[k]))),
        (a, b) => a.or(b),
    };
    Ok((f, u))
}

/// The standard uncertainties of the frame parameters at indices `frame`
/// of a joint covariance `cov`, given the model parameters at `fixed`
/// (kept at the file's value; those the fit did not identify, with zero
/// variance, change nothing): the Schur complement
/// `C_FF − C_FW C_WW⁻¹ C_WF`, the covariance the fit with those values
/// fixed would give. `None` without a covariance, or when the index lists
/// do not fit it or `C_WW` is singular.
pub fn conditional_uncertainty(
    cov: Option<&DMatrix<f64>>,
    frame: &[usize],
    fixed: &[usize],
) -> Option<[f64; FRAME_PARAMS]> {
    if frame.len() != FRAME_PARAMS {
        return None;
    }
    let reduced = conditional_covariance(cov?, frame, fixed)?;
    Some(std::array::from_fn(|k| reduced[(k, k)].max(0.0).sqrt()))
}

/// The covariance of the parameters `keep` of `c` given those at `fixed`
/// (zero-variance ones skipped), as [`conditional_uncertainty`].
pub fn conditional_covariance(
    c: &DMatrix<f64>,
    keep: &[usize],
    fixed: &[usize],
) -> Option<DMatrix<f64>> {
    let n = c.nrows();
    if keep.iter().chain(fixed).any(|&k| k >= n) {
        return None;
    }
    let fixed: Vec<usize> = fixed.iter().copied().filter(|&k| c[(k, k)] > 0.0).collect();
    let ckk = c.select_rows(keep.iter()).select_columns(keep.iter());
    if fixed.is_empty() {
        return Some(ckk);
    }
    let ckw = c.select_rows(keep.iter()).select_columns(fixed.iter());
    let cww = c.select_rows(fixed.iter()).select_columns(fixed.iter());
    Some(ckk - &ckw * cww.try_inverse()? * ckw.transpose())
}

/// The end of a calibration that identified an instrument frame `f` (with
/// uncertainties `u`, as [`estimate`]): the frame written to
/// `measurement_frame` of `yaml`, the note naming the `absorbed` model
/// parameters (`example` as [`absorbed_note`]) and [`IDENTIFIED_NOTE`].
/// Returns the edited text and the frame's estimate.
pub fn finish(
    yaml: &str,
    machine_file: &str,
    f: &Isometry3<f64>,
    u: Option<[f64; FRAME_PARAMS]>,
    absorbed: &[String],
    example: &str,
    notes: &mut Vec<String>,
) -> Result<(String, FrameEstimate)> {
    let est = estimate(f, u);
    let frame = Edit::MeasurementFrame {
        xyz_mm: est.xyz_mm,
        rpy_deg: est.rpy_deg,
    };
    let yaml = yaml_write::apply(yaml, machine_file, "postproc calibrate", &[frame])?;
    notes.extend(absorbed_note(absorbed, example));
    notes.push(IDENTIFIED_NOTE.into());
    Ok((yaml, est))
}

/// [`finish`] when an instrument frame was identified (`frame`: the frame
/// and its uncertainties), naming the parameters of `params` at the indices
/// `absorbed`; `yaml` unchanged and no estimate otherwise.
pub fn finish_if_any(
    yaml: String,
    machine_file: &str,
    frame: Option<(Isometry3<f64>, Option<[f64; FRAME_PARAMS]>)>,
    (params, absorbed): (&[Estimate], &[usize]),
    example: &str,
    notes: &mut Vec<String>,
) -> Result<(String, Option<FrameEstimate>)> {
    match frame {
        Some((f, u)) => {
            let names = names_at(params, absorbed);
            let (yaml, est) = finish(&yaml, machine_file, &f, u, &names, example, notes)?;
            Ok((yaml, Some(est)))
        }
        None => Ok((yaml, None)),
    }
}

/// Which model parameters a Jacobian identifies, with the frame columns
/// `jf` (if any) beside the model columns `jm`. Without a frame: the rank
/// screen of [`solve_linear`] on `jm`. With one: the frame columns must
/// have full rank (else `Err` with the reason), and the model columns are
/// screened after removing what the frame columns explain
/// (`(I − Q Qᵀ) J_model`, `Q` an orthonormal basis of the frame columns):
/// a model parameter that moves the measured points like a rigid motion of
/// the instrument is unidentifiable. A projected column below
/// `lsq.rank_rtol` of the strongest model column (unscaled problems) or of
/// its own norm (column-scaled ones) counts as gone. Returns
/// (unidentifiable given the frame, unidentifiable without it), indices
/// into the model columns.
pub fn screen_model(
    jm: &DMatrix<f64>,
    jf: Option<&DMatrix<f64>>,
    r0: &DVector<f64>,
    lsq: &LsqOptions,
) -> std::result::Result<(Vec<usize>, Vec<usize>), String> {
    let plain = solve_linear(jm, r0, lsq).map_err(|e| e.to_string())?;
    let Some(jf) = jf else {
        let u = plain.identifiability.unidentifiable.clone();
        return Ok((u.clone(), u));
    };
    let f = solve_linear(jf, r0, &LsqOptions::default()).map_err(|e| e.to_string())?;
    if !f.identifiability.unidentifiable.is_empty() {
        return Err(
            "the measured points do not span the space (too few or too little varied poses): \
             the instrument frame cannot be registered"
                .into(),
        );
    }
    let q = jf.clone().qr().q();
    let proj = jm - &q * (q.transpose() * jm);
    // The rank threshold stays relative to the columns before the
    // projection: a column the frame explains must count as gone, not be
    // judged against other weakened columns.
    let strongest = jm.column_iter().map(|c| c.norm()).fold(0.0, f64::max);
    let mut given = solve_linear(&proj, r0, lsq)
        .map_err(|e| e.to_string())?
        .identifiability
        .unidentifiable;
    for (k, c) in proj.column_iter().enumerate() {
        let reference = if lsq.scale_columns {
            jm.column(k).norm()
        } else {
            strongest
        };
        if c.norm() < lsq.rank_rtol * reference && !given.contains(&k) {
            given.push(k);
        }
    }
    given.sort_unstable();
    Ok((given, plain.identifiability.unidentifiable))
}

/// The identified frame with its standard uncertainties `u` (origin mm,
/// small rotations mrad, the order of [`FRAME_NAMES`]).
pub fn estimate(f: &Isometry3<f64>, u: Option<[f64; FRAME_PARAMS]>) -> FrameEstimate {
    let deg = |v: f64| v * DEG_PER_MRAD;
    FrameEstimate {
        xyz_mm: f.translation.vector.into(),
        rpy_deg: rpy_deg(f),
        u_xyz_mm: u.map(|u| [u[0], u[1], u[2]]),
        u_rot_deg: u.map(|u| [deg(u[3]), deg(u[4]), deg(u[5])]),
    }
}

/// The note listing the model parameters an instrument frame absorbs
/// (`names`; `None` when there are none). `example` says what such a
/// parameter does to the frame.
pub fn absorbed_note(names: &[String], example: &str) -> Option<String> {
    if names.is_empty() {
        return None;
    }
    Some(format!(
        "absorbed by the instrument frame (they move the measured points like a rigid \
         motion of the instrument; kept at the file's value, and the frame is identified \
         relative to these values — {example}): {}",
        names.join(", ")
    ))
}

/// The note of a calibration that identified an instrument frame with its
/// model.
pub const IDENTIFIED_NOTE: &str = "positions measured in an instrument frame: the frame is \
    identified together with the model and written to `measurement_frame`";

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
