//! Test helpers: the bundled AFM R-1000 and variants of it made by editing
//! its text (larger angular errors, a stiffness map that varies a lot, a
//! table value of −0).

use super::MachineTool;
use crate::machine::{AxisVec, DirVec};

/// The text of `machines/afm-r1000.yaml`.
pub(crate) fn afm_text() -> String {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/machines/afm-r1000.yaml");
    std::fs::read_to_string(path).unwrap_or_default()
}

/// A machine from its text; panics (in a test) on an error.
pub(crate) fn load(text: &str, name: &str) -> MachineTool {
    match MachineTool::from_yaml_str(text, name) {
        Ok(m) => m,
        Err(e) => panic!("{name}: {e}"),
    }
}

/// `list` (`[a, b, …]`, the text after the key) with every number times
/// `factor`.
fn scale_list(list: &str, factor: f64) -> String {
    let inner = list.trim().trim_start_matches('[').trim_end_matches(']');
    let values: Vec<String> = inner
        .split(',')
        .map(|v| match v.trim().parse::<f64>() {
            Ok(x) => format!("{:?}", x * factor),
            Err(_) => v.trim().to_string(),
        })
        .collect();
    format!("[{}]", values.join(", "))
}

/// Every angular component-error table (keys ending in `_urad`) times
/// `factor`: larger bends of the tool axis and of the tip along a move.
pub(crate) fn scale_angles(text: &str, factor: f64) -> String {
    let mut out = String::new();
    let mut angular = false;
    for line in text.lines() {
        let t = line.trim_start();
        if t.ends_with(':') && !t.starts_with('-') {
            angular = t.ends_with("_urad:");
        }
        let scaled = ["forward:", "reverse:"].iter().find_map(|key| {
            t.strip_prefix(key).filter(|_| angular).map(|rest| {
                format!(
                    "{}{key} {}",
                    &line[..line.len() - t.len()],
                    scale_list(rest, factor)
                )
            })
        });
        out.push_str(&scaled.unwrap_or_else(|| line.to_string()));
        out.push('\n');
    }
    out
}

/// The stiffness values replaced by pseudo-random ones within 4..40 N/µm:
/// a map that varies by a factor ten from corner to corner.
pub(crate) fn soft_stiffness(text: &str) -> String {
    let mut s = 17u64;
    let mut out = String::new();
    for line in text.lines() {
        if line.trim_start().starts_with("- [[") {
            let indent = &line[..line.len() - line.trim_start().len()];
            let mut row = |n: usize| {
                (0..n)
                    .map(|_| {
                        s ^= s << 13;
                        s ^= s >> 7;
                        s ^= s << 17;
                        format!(
                            "{:.2}",
                            4.0 + 36.0 * ((s >> 11) as f64 / (1u64 << 53) as f64)
                        )
                    })
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            let (a, b) = (row(3), row(3));
            out.push_str(&format!("{indent}- [[{a}], [{b}]]\n"));
        } else {
            out.push_str(line);
            out.push('\n');
        }
    }
    out
}

/// The numbers of a list `[a, b, …]`.
fn numbers(list: &str) -> Vec<f64> {
    list.trim()
        .trim_start_matches('[')
        .trim_end_matches(']')
        .split(',')
        .filter_map(|v| v.trim().parse().ok())
        .collect()
}

/// Every component-error table resampled on a pitch of `step_mm` by linear
/// interpolation: the same error functions with many more knots (as a
/// laser calibration at a fine pitch gives).
pub(crate) fn fine_tables(text: &str, step_mm: f64) -> String {
    let mut out = String::new();
    let mut positions: Vec<f64> = Vec::new();
    let mut fine: Vec<f64> = Vec::new();
    let list = |v: &[f64]| {
        let items: Vec<String> = v.iter().map(|x| format!("{x:?}")).collect();
        format!("[{}]", items.join(", "))
    };
    for line in text.lines() {
        let t = line.trim_start();
        let indent = &line[..line.len() - t.len()];
        if let Some(rest) = t.strip_prefix("positions_mm:") {
            positions = numbers(rest);
            fine.clear();
            if let (Some(&a), Some(&b)) = (positions.first(), positions.last()) {
                let n = ((b - a) / step_mm).round() as usize;
                fine = (0..=n).map(|k| a + (b - a) * k as f64 / n as f64).collect();
            }
            out.push_str(&format!("{indent}positions_mm: {}\n", list(&fine)));
            continue;
        }
        let key = ["forward:", "reverse:"]
            .into_iter()
            .find(|k| t.starts_with(k));
        match key {
            Some(key) if !fine.is_empty() && positions.len() >= 2 => {
                let v = numbers(&t[key.len()..]);
                let at = |x: f64| {
                    let i = positions
                        .partition_point(|&p| p <= x)
                        .clamp(1, positions.len() - 1);
                    let (p0, p1) = (positions[i - 1], positions[i]);
                    v[i - 1] + (v[i] - v[i - 1]) * (x - p0) / (p1 - p0)
                };
                let resampled: Vec<f64> = fine.iter().map(|&x| at(x)).collect();
                out.push_str(&format!("{indent}{key} {}\n", list(&resampled)));
            }
            _ => {
                out.push_str(line);
                out.push('\n');
            }
        }
    }
    out
}

/// A random straight segment of commands inside one cell of `m` (no
/// breakpoint between its ends): start in the travel, a direction that
/// is either general or one axis with a µm-scale drift of the others
/// (a compensated axis-parallel move), length up to `max_len_mm`. `None` when
/// the cell is too short for second differences.
pub(crate) fn segment_in_cell(
    m: &MachineTool,
    rng: &mut dyn FnMut() -> f64,
    max_len_mm: f64,
) -> Option<(AxisVec, AxisVec, DirVec)> {
    let mut a = [0.0; 6];
    for (slot, v) in a.iter_mut().enumerate().take(3) {
        let (lo, hi) = m.travel(slot).unwrap_or((-100.0, 100.0));
        *v = lo + (hi - lo) * rng();
    }
    let mut d = [0.0; 3];
    if rng() < 0.5 {
        for v in d.iter_mut() {
            *v = rng() - 0.5;
        }
    } else {
        for v in d.iter_mut() {
            *v = (rng() - 0.5) * 1e-5;
        }
        d[(rng() * 3.0) as usize % 3] = 1.0;
    }
    let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    let mut len = max_len_mm * rng();
    for slot in 0..3 {
        d[slot] /= n;
        if d[slot] == 0.0 || !m.has_axis(slot) {
            continue;
        }
        let bp = m.breakpoints(slot);
        let next = if d[slot] > 0.0 {
            bp.iter()
                .find(|&&x| x > a[slot])
                .map(|x| (x - a[slot]) / d[slot])
        } else {
            bp.iter()
                .rev()
                .find(|&&x| x < a[slot])
                .map(|x| (x - a[slot]) / d[slot])
        };
        if let Some(t) = next {
            len = len.min(t);
        }
    }
    if len < 4.0 {
        return None;
    }
    let mut b = a;
    let mut dirs = [1i8; 6];
    for slot in 0..3 {
        if !m.has_axis(slot) {
            d[slot] = 0.0;
            a[slot] = 0.0;
        }
        b[slot] = a[slot] + d[slot] * len;
        if d[slot] < 0.0 {
            dirs[slot] = -1;
        }
    }
    Some((a, b, dirs))
}
