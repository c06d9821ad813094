//! Fixed-decimal formatting without the exact (big-number) float
//! formatting: the digits of `format!("{v:.d$}")` (without the sign of a
//! zero) whenever an f64 product decides the rounding, shared by the
//! G-code and RAPID writers.

/// Powers of ten of the fast formatting path.
pub(crate) const POW10: [f64; 10] = [1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9];

/// Longest text of the fast path: sign, 16 digits, point, leading zeros of
/// the fraction.
pub(crate) const FIXED_MAX: usize = 32;

/// `10^d`: the table's exact powers (what `powi` gives for them), `powi`
/// beyond.
#[inline(always)]
pub(crate) fn pow10(d: usize) -> f64 {
    POW10
        .get(d)
        .copied()
        .unwrap_or_else(|| 10f64.powi(d as i32))
}

/// `format!("{v:.d$}")` with the sign of a zero dropped: the exact path of
/// both writers, taken where [`fixed_digits`] declines (near a rounding
/// tie, beyond its range).
pub(crate) fn exact_fixed(v: f64, d: usize) -> String {
    let mut s = format!("{v:.d$}");
    if s.starts_with('-') && s.bytes().skip(1).all(|b| b == b'0' || b == b'.') {
        s.remove(0);
    }
    s
}

/// `x.round()` (half away from zero) for `|x| < 2^52`, without the library
/// call: the conversion truncates exactly and `x − trunc(x)` is exact there.
#[inline(always)]
pub(crate) fn round_half_away(x: f64) -> f64 {
    if x.abs() < 4_503_599_627_370_496.0 {
        let t = x as i64;
        let frac = x - t as f64;
        let n = if frac >= 0.5 {
            t + 1
        } else if frac <= -0.5 {
            t - 1
        } else {
            t
        };
        let r = n as f64;
        // Keep the sign of a zero as `round` does (−0.4 → −0).
        if r == 0.0 { 0.0f64.copysign(x) } else { r }
    } else {
        x.round()
    }
}

/// `format!("{v:.d$}")` into `buf` without the exact (big-number) float
/// formatting when that is safe, with the sign of a zero dropped; the
/// length, or `None` near a rounding tie (the caller formats exactly).
///
/// `v · 10^d` is computed with one rounding (10^d is exact), so it lies
/// within `|v · 10^d| · ε` of the exact decimal product; when the product is
/// closer to its nearest integer `r` than half a unit minus twice that
/// bound, the exact value rounds to `r` too, whatever the tie rule, and the
/// digits of `r` are those of the exact formatting.
#[inline]
pub(crate) fn fixed_digits(buf: &mut [u8; FIXED_MAX], v: f64, d: usize) -> Option<usize> {
    let scale = *POW10.get(d)?;
    let scaled = v * scale;
    let r = round_half_away(scaled);
    if !r.is_finite()
        || r.abs() >= 1e15
        || (scaled - r).abs() >= 0.5 - 2.0 * f64::EPSILON * scaled.abs().max(1.0)
    {
        return None;
    }
    let n = r as i64;
    let mut m = n.unsigned_abs();
    // Decimal digits of |n| at the end of a scratch buffer of zeros (so
    // that the last `total` bytes are the digits zero-padded in front),
    // two at a time.
    let mut digits = [b'0'; 20];
    let mut first = digits.len();
    while m >= 100 {
        let pair = (m % 100) as usize * 2;
        m /= 100;
        first -= 2;
        *digits.get_mut(first)? = *DIGIT_PAIRS.get(pair)?;
        *digits.get_mut(first + 1)? = *DIGIT_PAIRS.get(pair + 1)?;
    }
    if m >= 10 {
        let pair = m as usize * 2;
        first -= 2;
        *digits.get_mut(first)? = *DIGIT_PAIRS.get(pair)?;
        *digits.get_mut(first + 1)? = *DIGIT_PAIRS.get(pair + 1)?;
    } else {
        first -= 1;
        *digits.get_mut(first)? = b'0' + m as u8;
    }
    let len = digits.len() - first;
    // At least one integer digit: `total` digits.
    let total = len.max(d + 1);
    let int_end = digits.len() - d;
    let int = digits.get(digits.len().checked_sub(total)?..int_end)?;
    let mut at = 0;
    if n < 0 {
        *buf.get_mut(at)? = b'-';
        at += 1;
    }
    // Byte loops: at most 17 bytes, cheaper than a library copy.
    for (o, &c) in buf.get_mut(at..at + int.len())?.iter_mut().zip(int) {
        *o = c;
    }
    at += int.len();
    if d > 0 {
        *buf.get_mut(at)? = b'.';
        at += 1;
        for (o, &c) in buf
            .get_mut(at..at + d)?
            .iter_mut()
            .zip(digits.get(int_end..)?)
        {
            *o = c;
        }
        at += d;
    }
    Some(at)
}

/// `00`, `01`, … `99`: two decimal digits per entry.
const DIGIT_PAIRS: &[u8; 200] = b"\
0001020304050607080910111213141516171819\
2021222324252627282930313233343536373839\
4041424344454647484950515253545556575859\
6061626364656667686970717273747576777879\
8081828384858687888990919293949596979899";
