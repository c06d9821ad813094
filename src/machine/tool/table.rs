//! Bidirectional error tables: one error value per table position and per
//! direction of motion, linearly interpolated and clamped at the table ends.

/// Result of a table lookup at one axis position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lookup {
    /// Interpolated error value (mm or rad).
    pub value: f64,
    /// Derivative of `value` with respect to the axis position (per mm or per
    /// degree); zero outside the table.
    pub slope: f64,
    /// True when the position lies outside the table and the end value was used.
    pub clamped: bool,
}

/// Whether the direction of motion `dir` selects the forward column: the
/// one convention of every command for an axis whose last motion is not
/// known (`0`: it has not moved yet in the program, or the observation row
/// has no `dir` cell) is that it arrived moving in + — the G-code
/// interpreter starts every axis at +1. Only a known −1 selects `reverse`.
#[inline(always)]
pub fn uses_forward(dir: i8) -> bool {
    dir >= 0
}

/// A validated error table (positions strictly increasing, equal column
/// lengths, finite values). Values are stored in internal units (mm, rad);
/// positions in command units (mm for linear, degrees for rotary axes).
#[derive(Debug, Clone, PartialEq)]
pub struct ErrorTable {
    positions: Vec<f64>,
    forward: Vec<f64>,
    reverse: Vec<f64>,
}

impl ErrorTable {
    /// Builds a table. The caller has validated that `positions` is non-empty
    /// and strictly increasing and that both columns have its length.
    pub(crate) fn new(positions: Vec<f64>, forward: Vec<f64>, reverse: Vec<f64>) -> Self {
        ErrorTable {
            positions,
            forward,
            reverse,
        }
    }

    /// Table positions (mm or degrees).
    pub fn positions(&self) -> &[f64] {
        &self.positions
    }

    /// Positions, forward and reverse columns.
    pub(crate) fn columns(&self) -> (&[f64], &[f64], &[f64]) {
        (&self.positions, &self.forward, &self.reverse)
    }

    /// First and last table position.
    pub fn range(&self) -> (f64, f64) {
        let lo = self.positions.first().copied().unwrap_or(0.0);
        let hi = self.positions.last().copied().unwrap_or(0.0);
        (lo, hi)
    }

    /// True when every value of both columns is zero.
    pub fn is_zero(&self) -> bool {
        self.forward.iter().chain(&self.reverse).all(|v| *v == 0.0)
    }

    /// Largest absolute slope between consecutive positions, both columns
    /// (per mm or per degree).
    pub fn max_abs_slope(&self) -> f64 {
        let mut m = 0.0f64;
        for col in [&self.forward, &self.reverse] {
            for (p, v) in self.positions.windows(2).zip(col.windows(2)) {
                if let ([p0, p1], [v0, v1]) = (p, v) {
                    m = m.max(((v1 - v0) / (p1 - p0)).abs());
                }
            }
        }
        m
    }

    /// Largest absolute value of both columns.
    pub fn max_abs(&self) -> f64 {
        self.forward
            .iter()
            .chain(&self.reverse)
            .fold(0.0, |m, v| m.max(v.abs()))
    }

    /// Value at position `q` for the direction of motion `dir` (see
    /// `uses_forward`: `−1` uses the reverse column, `+1` and `0` the
    /// forward one).
    pub fn lookup(&self, q: f64, dir: i8) -> Lookup {
        let mut hint = 0;
        self.lookup_hinted(q, dir, &mut hint)
    }

    /// [`Self::lookup`] that first tries the segment `hint` (the index of
    /// the segment's upper position, as left by a previous call): tables of
    /// one axis usually share their positions, so the search runs once per
    /// axis rather than once per table. The result is the same as
    /// [`Self::lookup`]'s.
    pub fn lookup_hinted(&self, q: f64, dir: i8, hint: &mut usize) -> Lookup {
        let col = if uses_forward(dir) {
            &self.forward
        } else {
            &self.reverse
        };
        let p = &self.positions;
        let n = p.len().min(col.len());
        let (Some(&first), Some(&last)) = (p.first(), p.get(n.wrapping_sub(1))) else {
            return Lookup {
                value: 0.0,
                slope: 0.0,
                clamped: false,
            };
        };
        let end = |i: usize, clamped: bool| Lookup {
            value: col.get(i).copied().unwrap_or(0.0),
            slope: 0.0,
            clamped,
        };
        if q.is_nan() {
            return end(0, true);
        }
        if q <= first {
            return end(0, q < first);
        }
        if q >= last {
            return end(n - 1, q > last);
        }
        // first < q < last, so 1 <= k <= n-1.
        let h = *hint;
        let k = match (h.checked_sub(1).and_then(|i| p.get(i)), p.get(h)) {
            (Some(&a), Some(&b)) if h < n && a <= q && q < b => h,
            _ => p[..n].partition_point(|&x| x <= q),
        };
        *hint = k;
        match (p.get(k - 1), p.get(k), col.get(k - 1), col.get(k)) {
            (Some(&p0), Some(&p1), Some(&v0), Some(&v1)) => {
                let slope = (v1 - v0) / (p1 - p0);
                Lookup {
                    value: v0 + slope * (q - p0),
                    slope,
                    clamped: false,
                }
            }
            _ => end(0, true),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    const TOL: f64 = 1e-12;

    fn table() -> ErrorTable {
        // forward: 0 at 0, 10 at 100, 4 at 200; reverse shifted by +2.
        ErrorTable::new(
            vec![0.0, 100.0, 200.0],
            vec![0.0, 10.0, 4.0],
            vec![2.0, 12.0, 6.0],
        )
    }

    #[test]
    fn interpolates_per_direction() {
        let t = table();
        // 25 % of the way from 0 to 100: 0 + 0.25·10 = 2.5 forward, 4.5 reverse.
        assert_abs_diff_eq!(t.lookup(25.0, 1).value, 2.5, epsilon = TOL);
        assert_abs_diff_eq!(t.lookup(25.0, -1).value, 4.5, epsilon = TOL);
        assert_abs_diff_eq!(t.lookup(25.0, 1).slope, 0.1, epsilon = TOL);
        // Second segment: 10 + (150−100)/100·(4−10) = 7, slope −0.06.
        assert_abs_diff_eq!(t.lookup(150.0, 1).value, 7.0, epsilon = TOL);
        assert_abs_diff_eq!(t.lookup(150.0, 1).slope, -0.06, epsilon = TOL);
        // Exactly on a knot.
        assert_abs_diff_eq!(t.lookup(100.0, -1).value, 12.0, epsilon = TOL);
        // dir 0 (not moved yet) uses the forward column.
        assert_abs_diff_eq!(t.lookup(0.0, 0).value, 0.0, epsilon = TOL);
        assert_abs_diff_eq!(t.lookup(25.0, 0).value, 2.5, epsilon = TOL);
    }

    #[test]
    fn clamps_outside() {
        let t = table();
        let l = t.lookup(-5.0, 1);
        assert!(l.clamped);
        assert_abs_diff_eq!(l.value, 0.0, epsilon = TOL);
        assert_abs_diff_eq!(l.slope, 0.0, epsilon = TOL);
        let l = t.lookup(250.0, -1);
        assert!(l.clamped);
        assert_abs_diff_eq!(l.value, 6.0, epsilon = TOL);
        assert!(!t.lookup(200.0, 1).clamped);
        assert!(t.lookup(f64::NAN, 1).clamped);
    }

    #[test]
    fn hinted_lookup_equals_the_plain_one_whatever_the_hint() {
        let t = table();
        for q in [-5.0, 0.0, 25.0, 99.9, 100.0, 150.0, 200.0, 250.0] {
            for start in [0, 1, 2, 3, 7] {
                let mut hint = start;
                let got = t.lookup_hinted(q, 1, &mut hint);
                let want = t.lookup(q, 1);
                assert_abs_diff_eq!(got.value, want.value, epsilon = TOL);
                assert_abs_diff_eq!(got.slope, want.slope, epsilon = TOL);
                assert_eq!(got.clamped, want.clamped);
            }
        }
        // 150 lies in the segment 100..200: the hint ends at its upper index 2.
        let mut hint = 0;
        t.lookup_hinted(150.0, 1, &mut hint);
        assert_eq!(hint, 2);
    }

    #[test]
    fn single_point_is_constant() {
        let t = ErrorTable::new(vec![5.0], vec![3.0], vec![3.0]);
        assert_abs_diff_eq!(t.lookup(-100.0, 1).value, 3.0, epsilon = TOL);
        assert_abs_diff_eq!(t.lookup(100.0, -1).value, 3.0, epsilon = TOL);
    }
}
