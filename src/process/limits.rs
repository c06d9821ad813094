//! Plausibility limits of the process inputs a program gives (documented in
//! docs/limits.md): a value beyond them is a typing or unit mistake that
//! would otherwise turn into a confident, wrong process-force correction.
//! Each is refused at its block.

/// Fastest programmed feed, mm/min (G94): the fastest machining feeds are
/// a few tens of metres a minute.
pub const FEED_MAX_MM_PER_MIN: f64 = 100_000.0;

/// Largest inverse-time feed, 1/min (G93: the inverse of a block's
/// duration): a block of 60 µs.
pub const INVERSE_TIME_MAX_PER_MIN: f64 = 1_000_000.0;

/// Largest programmed feed per revolution, mm/rev (G95).
pub const FEED_MAX_MM_PER_REV: f64 = 50.0;

/// Fastest spindle speed, 1/min (the fastest machining spindles run at
/// about 100 000).
pub const SPINDLE_MAX_RPM: f64 = 200_000.0;

/// Largest axial depth and radial width of cut (`DEPTH=`, `WIDTH=`), mm.
pub const CUT_MAX_MM: f64 = 100.0;

/// Whether a feed `f_mm` (mm/min, or mm/rev when `per_rev`) is plausible;
/// the limit it exceeds otherwise, with its unit.
pub fn feed_limit(f_mm: f64, per_rev: bool) -> Option<(f64, &'static str)> {
    feed_limit_in(f_mm, per_rev, false)
}

/// [`feed_limit`] of a block's F in its feed mode: under G93
/// (`inverse_time`) F is the inverse of the block's duration, 1/min, and
/// is held against [`INVERSE_TIME_MAX_PER_MIN`].
pub fn feed_limit_in(f: f64, per_rev: bool, inverse_time: bool) -> Option<(f64, &'static str)> {
    if inverse_time {
        return (f > INVERSE_TIME_MAX_PER_MIN)
            .then_some((INVERSE_TIME_MAX_PER_MIN, "1/min (inverse time)"));
    }
    let f_mm = f;
    let (max, unit) = if per_rev {
        (FEED_MAX_MM_PER_REV, "mm/rev")
    } else {
        (FEED_MAX_MM_PER_MIN, "mm/min")
    };
    (f_mm > max).then_some((max, unit))
}
