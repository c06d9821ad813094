//! Component errors of one axis (ISO 230-1): six functions of the axis' own
//! commanded position — three translations (µm in the file, mm here) and
//! three rotations (µrad in the file, rad here) — each a bidirectional table.

use nalgebra::{Matrix4, Vector3};

use super::geometry::{d_small_angle, small_angle};
use super::table::ErrorTable;

/// The six component-error tables of one axis, indexed by the direction of
/// the error: 0..3 = translation along x, y, z; 3..6 = rotation about x, y, z.
/// A missing table means the error is zero.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ComponentErrors {
    /// Tables by error direction (X Y Z A B C).
    pub tables: [Option<ErrorTable>; 6],
}

/// Component errors evaluated at one position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ComponentValue {
    /// Translations δx, δy, δz, mm.
    pub d: Vector3<f64>,
    /// Rotations εa, εb, εc about x, y, z, rad.
    pub e: Vector3<f64>,
    /// Derivative of `d` with respect to the axis position (per mm or per degree).
    pub dd: Vector3<f64>,
    /// Derivative of `e` with respect to the axis position (per mm or per degree).
    pub de: Vector3<f64>,
    /// True when any table clamped the position.
    pub clamped: bool,
}

impl ComponentErrors {
    /// Evaluates all six errors at position `q` for direction of motion `dir`.
    pub fn eval(&self, q: f64, dir: i8) -> ComponentValue {
        let mut out = ComponentValue {
            d: Vector3::zeros(),
            e: Vector3::zeros(),
            dd: Vector3::zeros(),
            de: Vector3::zeros(),
            clamped: false,
        };
        let mut hint = 0;
        for (i, t) in self.tables.iter().enumerate() {
            let Some(t) = t else { continue };
            let l = t.lookup_hinted(q, dir, &mut hint);
            out.clamped |= l.clamped;
            if i < 3 {
                out.d[i] = l.value;
                out.dd[i] = l.slope;
            } else {
                out.e[i - 3] = l.value;
                out.de[i - 3] = l.slope;
            }
        }
        out
    }

    /// True when every table is zero (or absent).
    pub fn is_zero(&self) -> bool {
        self.tables.iter().flatten().all(ErrorTable::is_zero)
    }

    /// True when `q` lies outside any of the tables.
    pub fn is_clamped(&self, q: f64) -> bool {
        self.tables.iter().flatten().any(|t| {
            let (lo, hi) = t.range();
            q.is_nan() || q < lo || q > hi
        })
    }
}

impl ComponentValue {
    /// The small-angle component-error HTM.
    pub fn htm(&self) -> Matrix4<f64> {
        small_angle(&self.d, &self.e)
    }

    /// Derivative of [`Self::htm`] with respect to the axis position.
    pub fn d_htm(&self) -> Matrix4<f64> {
        d_small_angle(&self.dd, &self.de)
    }
}
