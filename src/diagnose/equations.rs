//! The equations of a diagnosis: 3 per row for the measured triple, and 3
//! more for a row with a measured orientation (`qw…qz`) when the model
//! predicts one (robots) and the orientation weight is positive — the
//! rotation vector of `measured · predicted⁻¹` times the weight, the ratio
//! of position to orientation noise (mm/rad), as in `calibrate kinematics`.
//! Residuals and sensitivities are laid out row after row in this order;
//! the weighted orientation equations are in µm like the position ones (an
//! orientation residual of θ rad counts like a position residual of
//! θ × weight mm).
//!
//! Also the projection off an instrument frame's six parameters on these
//! equations.

use std::ops::Range;

use nalgebra::{DMatrix, DVector, Matrix3, UnitQuaternion, Vector3};

use super::effects::SLOTS;
use crate::calibrate::observations::Observation;
use crate::machine::Machine;

/// The equation layout of the rows.
#[derive(Debug, Clone)]
pub struct Equations {
    /// First equation of each row.
    start: Vec<usize>,
    /// Whether each row has orientation equations.
    oriented: Vec<bool>,
    /// Number of equations.
    total: usize,
    /// Orientation weight, mm/rad.
    w_rot: f64,
}

impl Equations {
    /// The layout of `rows` for `machine` with the orientation weight
    /// `w_rot` (mm/rad; 0 leaves measured orientations out). Machine tools
    /// have no orientation equations: their model predicts the tool tip's
    /// position only.
    pub fn new(machine: &Machine, rows: &[Observation], w_rot: f64) -> Equations {
        let use_rot = w_rot > 0.0 && matches!(machine, Machine::Robot(_));
        let mut start = Vec::with_capacity(rows.len());
        let mut oriented = Vec::with_capacity(rows.len());
        let mut total = 0;
        for r in rows {
            let o = use_rot && r.orientation.is_some();
            start.push(total);
            oriented.push(o);
            total += if o { 6 } else { 3 };
        }
        Equations {
            start,
            oriented,
            total,
            w_rot,
        }
    }

    /// The layout of `rows` rows with positions only (3 equations each).
    pub fn positions_only(rows: usize) -> Equations {
        Equations {
            start: (0..rows).map(|i| 3 * i).collect(),
            oriented: vec![false; rows],
            total: 3 * rows,
            w_rot: 0.0,
        }
    }

    /// Number of equations.
    pub fn total(&self) -> usize {
        self.total
    }

    /// Orientation weight, mm/rad.
    pub fn weight(&self) -> f64 {
        self.w_rot
    }

    /// Rows with orientation equations.
    pub fn oriented_rows(&self) -> usize {
        self.oriented.iter().filter(|o| **o).count()
    }

    /// First equation of row `i` (its measured triple's x).
    pub fn start(&self, i: usize) -> usize {
        self.start.get(i).copied().unwrap_or(self.total)
    }

    /// The orientation equations of row `i`, if it has any.
    pub fn orientation(&self, i: usize) -> Option<Range<usize>> {
        let s = self.start(i);
        self.oriented
            .get(i)
            .copied()
            .unwrap_or(false)
            .then_some(s + 3..s + 6)
    }

    /// The equations of `rows`, row after row.
    pub fn of(&self, rows: &[usize]) -> Vec<usize> {
        let mut out = Vec::with_capacity(6 * rows.len());
        for &i in rows {
            let s = self.start(i);
            out.extend(s..s + 3);
            if let Some(o) = self.orientation(i) {
                out.extend(o);
            }
        }
        out
    }

    /// A pose sensitivity ([`super::effects::pose_sensitivity`], [`SLOTS`]
    /// per row) laid out on these equations, orientation slots weighted.
    pub fn from_slots(&self, s: &DMatrix<f64>) -> DMatrix<f64> {
        let mut out = DMatrix::zeros(self.total, s.ncols());
        for (i, &at) in self.start.iter().enumerate() {
            for j in 0..s.ncols() {
                for c in 0..3 {
                    out[(at + c, j)] = s.get((SLOTS * i + c, j)).copied().unwrap_or(0.0);
                }
                if self.oriented.get(i).copied().unwrap_or(false) {
                    for c in 0..3 {
                        out[(at + 3 + c, j)] =
                            s.get((SLOTS * i + 3 + c, j)).copied().unwrap_or(0.0) * self.w_rot;
                    }
                }
            }
        }
        out
    }

    /// The weighted orientation residual of a row, mm: the rotation vector
    /// of `measured · predicted⁻¹` times the weight.
    pub fn orientation_residual(
        &self,
        measured: &UnitQuaternion<f64>,
        predicted: &UnitQuaternion<f64>,
    ) -> Vector3<f64> {
        (measured * predicted.inverse()).scaled_axis() * self.w_rot
    }

    /// The orientation residual (rad) of row `i` in a weighted residual
    /// vector `r` in µm, if the row has orientation equations.
    pub fn angle_rad(&self, r: &DVector<f64>, i: usize) -> Option<f64> {
        let o = self.orientation(i)?;
        let v = Vector3::new(
            r.get(o.start).copied().unwrap_or(0.0),
            r.get(o.start + 1).copied().unwrap_or(0.0),
            r.get(o.start + 2).copied().unwrap_or(0.0),
        );
        (self.w_rot > 0.0).then(|| v.norm() * 1e-3 / self.w_rot)
    }
}

/// Projection off the columns of an instrument frame's six parameters
/// (a shift, and a small rotation `−[p]×` about the reference axes, at the
/// measured points `p`; the orientation equations turn with the rotation,
/// weighted as they are), on each of the row sets separately: what remains
/// of a residual or a sensitivity after the frame of those rows is fitted
/// with it (Frisch–Waugh–Lovell).
pub struct FrameProjection {
    /// Per row set: its equations and an orthonormal basis of the frame
    /// columns on them.
    blocks: Vec<(Vec<usize>, DMatrix<f64>)>,
}

impl FrameProjection {
    /// The projection for `rows` laid out by `eq`, on each of `sets`.
    pub fn new(rows: &[Observation], eq: &Equations, sets: &[&[usize]]) -> Self {
        let blocks = sets
            .iter()
            .map(|set| {
                let idx = eq.of(set);
                let mut j = DMatrix::zeros(idx.len(), 6);
                let mut at = 0;
                for &i in set.iter() {
                    let p = rows.get(i).map_or(Vector3::zeros(), |r| r.measured_mm);
                    j.view_mut((at, 0), (3, 3)).copy_from(&Matrix3::identity());
                    j.view_mut((at, 3), (3, 3)).copy_from(&(-p.cross_matrix()));
                    at += 3;
                    if eq.orientation(i).is_some() {
                        j.view_mut((at, 3), (3, 3))
                            .copy_from(&(Matrix3::identity() * eq.weight()));
                        at += 3;
                    }
                }
                (idx, j.qr().q())
            })
            .collect();
        FrameProjection { blocks }
    }

    /// `m` (laid out on the equations) with the frame's part removed.
    pub fn apply(&self, m: &DMatrix<f64>) -> DMatrix<f64> {
        let mut out = m.clone();
        for (idx, q) in &self.blocks {
            let block = m.select_rows(idx.iter());
            let rest = &block - q * (q.transpose() * &block);
            for (k, &r) in idx.iter().enumerate() {
                out.row_mut(r).copy_from(&rest.row(k));
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    /// Exact arithmetic of a small layout.
    const EXACT_TOL: f64 = 1e-12;

    fn rows(oriented: &[bool]) -> Vec<Observation> {
        oriented
            .iter()
            .enumerate()
            .map(|(i, &o)| Observation {
                orientation: o.then(UnitQuaternion::identity),
                line: i,
                id: i.to_string(),
                t_s: None,
                measured_mm: Vector3::new(100.0 * i as f64, 50.0, 800.0),
                force_n: Vector3::zeros(),
                moment_nm: Vector3::zeros(),
                ambient_c: None,
                pose: crate::calibrate::observations::Pose::Robot(
                    crate::calibrate::observations::RobotPose {
                        q_deg: [0.0; 6],
                        mp_mm: None,
                        wp_mm: None,
                        p_w: [None; 6],
                        dir: [None; 6],
                    },
                ),
            })
            .collect()
    }

    fn robot() -> Machine {
        Machine::from_yaml_str(
            &std::fs::read_to_string(
                std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("machines/abb-irb1600.yaml"),
            )
            .unwrap(),
            "m.yaml",
        )
        .unwrap()
    }

    /// Rows with an orientation get 6 equations, the others 3; a weight of
    /// 0 leaves every row at 3; orientation slots are weighted.
    #[test]
    fn layout_and_weighting() {
        let r = rows(&[true, false, true]);
        let eq = Equations::new(&robot(), &r, 100.0);
        assert_eq!(eq.total(), 15);
        assert_eq!(eq.of(&[1, 2]), vec![6, 7, 8, 9, 10, 11, 12, 13, 14]);
        assert_eq!(eq.orientation(1), None);
        let s = DMatrix::from_fn(SLOTS * 3, 1, |i, _| i as f64);
        let c = eq.from_slots(&s);
        assert_abs_diff_eq!(c[(3, 0)], 300.0, epsilon = EXACT_TOL);
        assert_abs_diff_eq!(c[(6, 0)], 6.0, epsilon = EXACT_TOL);
        assert_abs_diff_eq!(c[(9, 0)], 12.0, epsilon = EXACT_TOL);
        assert_abs_diff_eq!(c[(12, 0)], 1500.0, epsilon = EXACT_TOL);
        assert_eq!(Equations::new(&robot(), &r, 0.0).total(), 9);
    }

    /// A residual that is exactly a small rotation of the instrument frame
    /// (on the points and on the orientations) is removed by the projection.
    #[test]
    fn frame_rotation_is_projected_off_points_and_orientations() {
        let r = rows(&[true, true, false, true]);
        let eq = Equations::new(&robot(), &r, 100.0);
        let delta = Vector3::new(1e-4, -2e-4, 3e-4);
        let mut v = DVector::zeros(eq.total());
        for (i, row) in r.iter().enumerate() {
            let s = eq.start(i);
            let d = delta.cross(&row.measured_mm);
            for c in 0..3 {
                v[s + c] = d[c];
            }
            if let Some(o) = eq.orientation(i) {
                for c in 0..3 {
                    v[o.start + c] = delta[c] * 100.0;
                }
            }
        }
        let all: Vec<usize> = (0..r.len()).collect();
        let p = FrameProjection::new(&r, &eq, &[&all]);
        let rest = p.apply(&DMatrix::from_column_slice(v.len(), 1, v.as_slice()));
        assert!(rest.norm() < EXACT_TOL * 1e3 * v.norm(), "{rest}");
    }
}
