//! The F words of the pieces of a split move under G93 (inverse-time feed).
//!
//! Under G93 the F word of a feed block is the inverse of its duration
//! (1/min), and every feed block needs one. When a compensated move is
//! written as several lines, each piece gets the F that gives it its share
//! of the block's duration, the share being its share of the move's length
//! (the path of the linear axes, or the largest rotary angle for a move of
//! rotary axes alone), so that the pieces together last as long as the
//! block did — within the inverse-time range a control takes
//! ([`MAX_PIECE_F`]).

use crate::machine::AxisVec;
use crate::program::gcode::Word;

/// Least share of the block's duration a piece is given: a takeup point a
/// few microns from the start would otherwise ask for an F thousands of
/// times the block's, beyond any control's limit.
pub(crate) const MIN_SHARE: f64 = 1e-3;

/// Largest F a piece is given, 1/min: the top of the inverse-time range of
/// Fanuc controls (0.001–9999.999). A takeup point of microns so lasts at
/// least 6 ms, and the block that much longer than programmed; a block
/// whose own F is larger keeps it for its pieces.
pub(crate) const MAX_PIECE_F: f64 = 9999.999;

/// Fewest decimals written in a piece's F (a relative resolution of 5e-5
/// at F20).
const MIN_DECIMALS: usize = 3;

/// Below this the linear axes are taken not to move, mm.
const STILL_MM: f64 = 1e-9;

/// The feeds of the pieces of one block.
pub(crate) struct PieceFeeds {
    /// The block's F, 1/min.
    f: f64,
    /// The move's length over all its pieces.
    total: f64,
    /// Lengths are those of the linear axes (else the largest rotary angle).
    linear: bool,
    /// Least duration of a piece, min: [`MIN_SHARE`] of the block's, and no
    /// shorter than an F of [`MAX_PIECE_F`] allows.
    least_min: f64,
    /// The block's duration left to the pieces longer than the least, min,
    /// and their length: they share it by length.
    rest: (f64, f64),
}

impl PieceFeeds {
    /// The pieces from `start` through `points` (the last is the block's
    /// end) of a block with F `f`.
    pub(crate) fn new<'a>(
        f: f64,
        start: &AxisVec,
        points: impl Iterator<Item = &'a AxisVec> + Clone,
    ) -> Self {
        let mut linear_total = 0.0;
        let mut rotary_total = 0.0;
        let mut prev = start;
        for p in points.clone() {
            linear_total += linear_len(prev, p);
            rotary_total += rotary_len(prev, p);
            prev = p;
        }
        let linear = linear_total > STILL_MM;
        let total = if linear { linear_total } else { rotary_total };
        let block_min = 1.0 / f;
        let least_min = (MIN_SHARE * block_min).max(1.0 / MAX_PIECE_F.max(f));
        // The pieces held at the least duration, and the others' length.
        let (mut held, mut others) = (0.0, 0.0);
        let mut prev = start;
        for p in points {
            let len = if linear {
                linear_len(prev, p)
            } else {
                rotary_len(prev, p)
            };
            if total > 0.0 && block_min * len / total < least_min {
                held += least_min;
            } else {
                others += len;
            }
            prev = p;
        }
        PieceFeeds {
            f,
            total,
            linear,
            least_min,
            rest: ((block_min - held).max(0.0), others),
        }
    }

    /// The F of the piece from `a` to `b`, 1/min: the pieces held at the
    /// least duration take it, and the others share what is left of the
    /// block's duration by their length, so that together they last as
    /// long as the block (when its duration holds the least of each).
    pub(crate) fn feed(&self, a: &AxisVec, b: &AxisVec) -> f64 {
        if self.total <= 0.0 {
            return self.f;
        }
        let len = if self.linear {
            linear_len(a, b)
        } else {
            rotary_len(a, b)
        };
        let (rest_min, others) = self.rest;
        if len * self.total.recip() / self.f < self.least_min || others <= 0.0 {
            return 1.0 / self.least_min;
        }
        let d = rest_min * len / others;
        if d < self.least_min {
            1.0 / self.least_min
        } else {
            1.0 / d
        }
    }
}

/// Decimals of the pieces' F words: the block's own, at least
/// [`MIN_DECIMALS`].
pub(crate) fn decimals(f: &Word) -> usize {
    usize::from(f.decimals.unwrap_or(0)).max(MIN_DECIMALS)
}

fn linear_len(a: &AxisVec, b: &AxisVec) -> f64 {
    (0..3).map(|s| (b[s] - a[s]).powi(2)).sum::<f64>().sqrt()
}

fn rotary_len(a: &AxisVec, b: &AxisVec) -> f64 {
    (3..6).map(|s| (b[s] - a[s]).abs()).fold(0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    /// Agreement of computed feeds and durations: rounding only.
    const F_TOL: f64 = 1e-9;

    #[test]
    fn pieces_share_the_blocks_duration_by_length() {
        let start = [0.0; 6];
        let mid = [3.0, 4.0, 0.0, 10.0, 0.0, 0.0];
        let end = [6.0, 8.0, 0.0, 20.0, 0.0, 0.0];
        let pf = PieceFeeds::new(10.0, &start, [mid, end].iter());
        // Two halves of the length: each lasts half of 1/10 min.
        assert_eq!(pf.feed(&start, &mid), 20.0);
        assert_eq!(pf.feed(&mid, &end), 20.0);
        let total: f64 = [pf.feed(&start, &mid), pf.feed(&mid, &end)]
            .iter()
            .map(|f| 1.0 / f)
            .sum();
        assert_eq!(total, 0.1);
        // A rotary-only move shares by the largest angle.
        let r1 = [0.0, 0.0, 0.0, 0.0, 0.0, 30.0];
        let r2 = [0.0, 0.0, 0.0, 0.0, 0.0, 120.0];
        let pf = PieceFeeds::new(4.0, &start, [r1, r2].iter());
        assert_eq!(pf.feed(&start, &r1), 16.0);
        // A takeup point of no length gets the least share, and the rest of
        // the block the rest of its duration.
        let pf = PieceFeeds::new(5.0, &start, [start, end].iter());
        assert_abs_diff_eq!(pf.feed(&start, &start), 5.0 / MIN_SHARE, epsilon = F_TOL);
        let lasts = |pf: &PieceFeeds| 1.0 / pf.feed(&start, &start) + 1.0 / pf.feed(&start, &end);
        assert_abs_diff_eq!(lasts(&pf), 1.0 / 5.0, epsilon = F_TOL);
        // Never an F above the inverse-time range of the control, unless
        // the block's own was; the block still lasts as long.
        let pf = PieceFeeds::new(250.0, &start, [start, end].iter());
        assert_abs_diff_eq!(pf.feed(&start, &start), MAX_PIECE_F, epsilon = F_TOL);
        assert_abs_diff_eq!(lasts(&pf), 1.0 / 250.0, epsilon = F_TOL);
        let pf = PieceFeeds::new(20_000.0, &start, [start, end].iter());
        assert_abs_diff_eq!(pf.feed(&start, &start), 20_000.0, epsilon = F_TOL);
    }
}
