//! Screening of identification data before and after a fit: repeated rows,
//! a hold-out split that never separates repeats of one pose, and the rows
//! that dominate a fit.
//!
//! - **Repeats**: two rows are *repeats* when everything the model sees of
//!   them is equal (pose, measured point, loads, powers, ambient, time not
//!   included). Repeats with the same measured values are *copies*: they carry
//!   no information and are dropped ([`drop_copies`]). Repeats with different
//!   measured values are repeated measurements of one pose: they count once
//!   towards the number of distinct poses, and the hold-out split keeps them
//!   together ([`grouped_split`]), so a held-out row is never predicted from
//!   its own repeat.
//! - **Dominating rows** ([`dominating_rows`]): for a least-squares fit with
//!   Jacobian `J` (3 equations per row) and residuals `e`, the deleted
//!   residual of row `i` — its residual predicted by the fit of all *other*
//!   rows — is `(I − H_ii)⁻¹ e_i` with `H = J (JᵀJ)⁺ Jᵀ` (3 × 3 block of the
//!   row). A row whose deleted residual norm exceeds [`OUTLIER_K`] robust
//!   standard deviations (1.4826 × the median absolute deleted-residual
//!   coordinate, times √3 for the norm) disagrees with everything else the
//!   fit sees: an outlier. Calibration removes such rows from the fit,
//!   reports them by file line and id, and fits again.

use std::collections::HashMap;

use nalgebra::{DMatrix, DVector, Matrix3};

use super::observations::{Observation, Observations, Pose, holdout_split};

/// Deleted-residual norm, in robust standard deviations of the norm, above
/// which a row is an outlier. For Gaussian noise the norm of a 3-D residual
/// exceeds 6 σ√3 with a probability below 10⁻¹⁵: a row beyond is not noise.
pub const OUTLIER_K: f64 = 6.0;

/// Smallest deleted residual that can make an outlier, mm (1 µm): on
/// noise-free data the robust σ is rounding noise, and no instrument
/// resolves below this.
pub const OUTLIER_FLOOR_MM: f64 = 1e-3;

/// Consistency factor of the median absolute deviation for a normal
/// distribution (σ ≈ 1.4826 · MAD).
const MAD_TO_SIGMA: f64 = 1.4826;

/// `1 − h` below this: the row alone determines some combination of the
/// parameters (leverage 1) and nothing else can check it.
const LEVERAGE_FLOOR: f64 = 1e-6;

/// Everything the model sees of a row, as bit patterns (time and the
/// measured values excluded).
fn input_key(r: &Observation) -> Vec<u64> {
    let mut k: Vec<u64> = Vec::with_capacity(40);
    let opt = |v: Option<f64>| v.map_or(u64::MAX, f64::to_bits);
    k.extend(
        r.force_n
            .iter()
            .chain(r.moment_nm.iter())
            .map(|v| v.to_bits()),
    );
    k.push(opt(r.ambient_c));
    match &r.pose {
        Pose::Robot(p) => {
            k.push(1);
            k.extend(p.q_deg.iter().map(|v| v.to_bits()));
            for pt in [p.mp_mm, p.wp_mm] {
                match pt {
                    Some(v) => k.extend(v.iter().map(|x| x.to_bits())),
                    None => k.push(u64::MAX),
                }
            }
            k.extend(p.p_w.iter().map(|v| opt(*v)));
            k.extend(
                p.dir
                    .iter()
                    .map(|d| d.map_or(0, |d| (i64::from(d) + 7) as u64)),
            );
        }
        Pose::Tool(p) => {
            k.push(2);
            k.extend(p.xyz_mm.iter().map(|v| v.to_bits()));
            k.extend(p.abc_deg.iter().map(|v| opt(*v)));
            k.extend(
                p.dir
                    .iter()
                    .map(|d| d.map_or(0, |d| (i64::from(d) + 7) as u64)),
            );
            k.push(opt(p.tool_mm));
            k.push(opt(p.spindle_rpm));
            k.push(opt(p.spindle_w));
            k.extend(p.p_w.iter().map(|v| opt(*v)));
        }
    }
    k
}

fn full_key(r: &Observation) -> Vec<u64> {
    let mut k = input_key(r);
    k.extend(r.measured_mm.iter().map(|v| v.to_bits()));
    if let Some(q) = &r.orientation {
        k.extend(q.coords.iter().map(|v| v.to_bits()));
    }
    k
}

/// Joint angles (robot) and rotary axes (machine tool) closer than this
/// are one pose, degrees: a point 1 m out moves by 0.17 mm, far less than
/// any two poses of an identification data set differ.
pub const NEAR_DEG: f64 = 0.01;
/// Linear axes, measured and wrench points and tool lengths closer than
/// this are one pose, mm.
pub const NEAR_MM: f64 = 0.01;
/// Forces (N), moments (N·m), powers (W), speeds (1/min) and temperatures
/// (°C) closer than this are the same.
const NEAR_OTHER: f64 = 0.1;

/// Everything the model sees of a row as (value, tolerance) pairs, and its
/// discrete part (kind, given or not, last-motion signs) as bit patterns.
fn near_features(r: &Observation) -> (Vec<u64>, Vec<(f64, f64)>) {
    let mut d: Vec<u64> = Vec::new();
    let mut c: Vec<(f64, f64)> = Vec::new();
    let opt = |d: &mut Vec<u64>, c: &mut Vec<(f64, f64)>, v: Option<f64>, tol: f64| match v {
        Some(v) => {
            d.push(1);
            c.push((v, tol));
        }
        None => d.push(0),
    };
    c.extend(
        r.force_n
            .iter()
            .chain(r.moment_nm.iter())
            .map(|v| (*v, NEAR_OTHER)),
    );
    opt(&mut d, &mut c, r.ambient_c, NEAR_OTHER);
    let dirs = |d: &mut Vec<u64>, dir: &[Option<i8>]| {
        d.extend(
            dir.iter()
                .map(|x| x.map_or(0, |x| (i64::from(x) + 7) as u64)),
        );
    };
    match &r.pose {
        Pose::Robot(p) => {
            d.push(1);
            c.extend(p.q_deg.iter().map(|v| (*v, NEAR_DEG)));
            for pt in [p.mp_mm, p.wp_mm] {
                match pt {
                    Some(v) => {
                        d.push(1);
                        c.extend(v.iter().map(|x| (*x, NEAR_MM)));
                    }
                    None => d.push(0),
                }
            }
            for w in p.p_w {
                opt(&mut d, &mut c, w, NEAR_OTHER);
            }
            dirs(&mut d, &p.dir);
        }
        Pose::Tool(p) => {
            d.push(2);
            c.extend(p.xyz_mm.iter().map(|v| (*v, NEAR_MM)));
            for a in p.abc_deg {
                opt(&mut d, &mut c, a, NEAR_DEG);
            }
            dirs(&mut d, &p.dir);
            opt(&mut d, &mut c, p.tool_mm, NEAR_MM);
            opt(&mut d, &mut c, p.spindle_rpm, NEAR_OTHER);
            opt(&mut d, &mut c, p.spindle_w, NEAR_OTHER);
            for w in p.p_w {
                opt(&mut d, &mut c, w, NEAR_OTHER);
            }
        }
    }
    (d, c)
}

/// A pose group's first row: its first continuous input, its group and
/// all its continuous inputs with their tolerances.
type Representative = (f64, usize, Vec<(f64, f64)>);

/// The pose group (0-based, in order of first appearance) of every row:
/// rows whose inputs all agree within [`NEAR_DEG`], [`NEAR_MM`] and 0.1 N,
/// N·m, W, 1/min, °C of the group's first row (repeats, and near-copies
/// measured again with a jitter of the pose) are one pose — in every
/// split, held-out figure, cross-validation fold and count of distinct
/// poses.
pub fn pose_groups(obs: &Observations) -> (Vec<usize>, usize) {
    // Group representatives by discrete key, sorted by their first
    // continuous value, so that a row is compared with the few whose first
    // value is within tolerance.
    let mut reps: HashMap<Vec<u64>, Vec<Representative>> = HashMap::new();
    let mut of_row = Vec::with_capacity(obs.rows.len());
    let mut n = 0;
    for r in &obs.rows {
        let (d, c) = near_features(r);
        let first = c.first().map_or(0.0, |x| x.0);
        let tol = c.first().map_or(0.0, |x| x.1);
        let list = reps.entry(d).or_default();
        let lo = list.partition_point(|x| x.0 < first - tol);
        let hit = list[lo..]
            .iter()
            .take_while(|x| x.0 <= first + tol)
            .find(|x| {
                x.2.len() == c.len() && x.2.iter().zip(&c).all(|(a, b)| (a.0 - b.0).abs() <= b.1)
            })
            .map(|x| x.1);
        match hit {
            Some(g) => of_row.push(g),
            None => {
                let at = list.partition_point(|x| x.0 < first);
                list.insert(at, (first, n, c));
                of_row.push(n);
                n += 1;
            }
        }
    }
    (of_row, n)
}

/// Number of distinct poses among `rows` (repeats counted once).
pub fn distinct_poses(obs: &Observations, rows: &[usize]) -> usize {
    let (of_row, _) = pose_groups(obs);
    let mut g: Vec<usize> = rows
        .iter()
        .filter_map(|&i| of_row.get(i).copied())
        .collect();
    g.sort_unstable();
    g.dedup();
    g.len()
}

/// `obs` without the rows that are exact copies of an earlier row (same
/// inputs and same measured values), and a note naming how many were
/// dropped (`None` when there were none).
pub fn drop_copies(obs: &Observations, file: &str) -> (Observations, Option<String>) {
    let mut seen: HashMap<Vec<u64>, usize> = HashMap::new();
    let mut out = obs.clone();
    out.rows.clear();
    let mut dropped: Vec<String> = Vec::new();
    for r in &obs.rows {
        match seen.get(&full_key(r)) {
            Some(&first) => dropped.push(format!("{}:{} (copy of line {first})", file, r.line)),
            None => {
                seen.insert(full_key(r), r.line);
                out.rows.push(r.clone());
            }
        }
    }
    if dropped.is_empty() {
        return (out, None);
    }
    let shown: Vec<&str> = dropped.iter().take(3).map(String::as_str).collect();
    let note = format!(
        "{} row(s) are exact copies of earlier rows and count once ({}{}): copies add no \
         information, they would only shrink the uncertainties and leak into the hold-out",
        dropped.len(),
        shown.join(", "),
        if dropped.len() > 3 { ", …" } else { "" }
    );
    tracing::warn!("{note}");
    (out, Some(note))
}

/// Reproducible split of the rows into (fit, held-out) by pose group: the
/// groups are split by [`holdout_split`] (the same split as rows when every
/// pose is distinct) and each group's rows go together. Both ascending.
pub fn grouped_split(obs: &Observations, fraction: f64, seed: u64) -> (Vec<usize>, Vec<usize>) {
    let (of_row, n) = pose_groups(obs);
    let (_, hold_groups) = holdout_split(n, fraction, seed);
    let mut held = vec![false; n];
    for g in hold_groups {
        if let Some(h) = held.get_mut(g) {
            *h = true;
        }
    }
    let mut fit = Vec::new();
    let mut hold = Vec::new();
    for (i, g) in of_row.iter().enumerate() {
        if held.get(*g).copied().unwrap_or(false) {
            hold.push(i);
        } else {
            fit.push(i);
        }
    }
    (fit, hold)
}

/// One row that disagrees with the rest of the fit.
#[derive(Debug, Clone, PartialEq)]
pub struct Outlier {
    /// Index of the row in the observations.
    pub row: usize,
    /// Norm of its deleted residual, mm.
    pub deleted_mm: f64,
    /// The robust standard deviation of a coordinate, mm.
    pub sigma_mm: f64,
}

/// Rows (indices into `rows`' observations) whose deleted residual exceeds
/// [`OUTLIER_K`] robust standard deviations (and [`OUTLIER_FLOOR_MM`]),
/// worst first. `j` is the
/// Jacobian of the residuals over the free parameters and `e` the residuals
/// at the solution, `eq` equations per row in the order of `rows`.
pub fn dominating_rows(j: &DMatrix<f64>, e: &DVector<f64>, rows: &[usize]) -> Vec<Outlier> {
    let m = 3 * rows.len();
    if j.nrows() < m || e.len() < m || j.ncols() == 0 || rows.len() < 4 {
        return Vec::new();
    }
    // Column scaling does not change H; it keeps the SVD's rank decision fair.
    let mut js = j.rows(0, m).into_owned();
    for mut c in js.column_iter_mut() {
        let n = c.norm();
        if n > 0.0 {
            c /= n;
        }
    }
    let svd = js.svd(true, false);
    let Some(u) = svd.u else { return Vec::new() };
    let smax = svd.singular_values.max();
    let keep: Vec<usize> = (0..svd.singular_values.len())
        .filter(|&k| svd.singular_values[k] > smax * 1e-10)
        .collect();
    let mut deleted: Vec<Option<f64>> = Vec::with_capacity(rows.len());
    let mut coords: Vec<f64> = Vec::with_capacity(m);
    for k in 0..rows.len() {
        let mut h = Matrix3::zeros();
        for &c in &keep {
            let ui = nalgebra::Vector3::new(u[(3 * k, c)], u[(3 * k + 1, c)], u[(3 * k + 2, c)]);
            h += ui * ui.transpose();
        }
        let ei = nalgebra::Vector3::new(e[3 * k], e[3 * k + 1], e[3 * k + 2]);
        let ih = Matrix3::identity() - h;
        let min_eig = ih.symmetric_eigenvalues().min();
        match (min_eig > LEVERAGE_FLOOR)
            .then(|| ih.try_inverse())
            .flatten()
        {
            Some(inv) => {
                let d = inv * ei;
                coords.extend(d.iter().map(|v| v.abs()));
                deleted.push(Some(d.norm()));
            }
            None => deleted.push(None),
        }
    }
    if coords.len() < 6 {
        return Vec::new();
    }
    coords.sort_by(f64::total_cmp);
    let sigma = MAD_TO_SIGMA * coords[coords.len() / 2];
    if sigma.is_nan() || sigma <= 0.0 {
        return Vec::new();
    }
    let limit = (OUTLIER_K * sigma * 3f64.sqrt()).max(OUTLIER_FLOOR_MM);
    let mut out: Vec<Outlier> = rows
        .iter()
        .zip(&deleted)
        .filter_map(|(&row, d)| {
            d.filter(|d| *d > limit).map(|d| Outlier {
                row,
                deleted_mm: d,
                sigma_mm: sigma,
            })
        })
        .collect();
    out.sort_by(|a, b| b.deleted_mm.total_cmp(&a.deleted_mm));
    out
}

/// Words for a list of outliers: `file:line` and id of each, its deleted
/// residual and the robust σ.
pub fn describe_outliers(obs: &Observations, file: &str, out: &[Outlier]) -> String {
    out.iter()
        .take(5)
        .map(|o| {
            let (line, id) = obs
                .rows
                .get(o.row)
                .map_or((0, String::new()), |r| (r.line, r.id.clone()));
            format!(
                "{file}:{line} (row `{id}`): {:.4} mm from what the other rows predict \
                 (robust σ {:.4} mm per coordinate)",
                o.deleted_mm, o.sigma_mm
            )
        })
        .collect::<Vec<_>>()
        .join("; ")
        + if out.len() > 5 { "; …" } else { "" }
}

/// The error of a calibration whose identified values do not make a valid
/// machine file: the data, not the machine file, are the cause, so the
/// message names the observation file (with the validation's words).
pub fn implausible(e: &crate::error::Error, obs_file: &str, n_fit: usize) -> crate::error::Error {
    crate::error::Error::Data(format!(
        "{obs_file}: the values identified from these {n_fit} rows are not plausible \
         ({e}); the rows do not determine them — look for outliers, wrong units or \
         axes that are not varied"
    ))
}

/// Largest ratio of the spread of the measured positions to the spread of
/// the positions the model predicts for the same rows (either way) that
/// passes as the same unit: a model wrong by a fifth of its size is not a
/// calibration problem.
pub const UNIT_SPREAD_RATIO: f64 = 1.25;

/// Units a position column is often written in by mistake, with their size
/// in mm.
const LIKELY_UNITS: [(&str, f64); 5] = [
    ("inch", 25.4),
    ("m", 1000.0),
    ("cm", 10.0),
    ("µm", 1e-3),
    ("dm", 100.0),
];

/// RMS distance of points from their centroid (the spread; unchanged by a
/// rigid motion of the instrument).
fn spread(p: &[nalgebra::Vector3<f64>]) -> f64 {
    if p.is_empty() {
        return 0.0;
    }
    let c = p.iter().sum::<nalgebra::Vector3<f64>>() / p.len() as f64;
    (p.iter().map(|v| (v - c).norm_squared()).sum::<f64>() / p.len() as f64).sqrt()
}

/// Refuses measured positions whose scale does not fit the model: the
/// spread of `x/y/z_mm` against the spread of the positions `machine`
/// predicts for the same rows, beyond [`UNIT_SPREAD_RATIO`], names the
/// likely unit (inch, m, cm, µm, dm: the one whose factor is nearest the
/// ratio). Deviations (`dx_mm` …) and data whose poses do not spread are
/// not judged.
pub fn check_units(
    machine: &crate::machine::Machine,
    obs: &Observations,
    file: &str,
) -> crate::error::Result<()> {
    use super::observations::MeasuredKind;
    super::forward::check_kind(machine, obs, file)?;
    if obs.measured != MeasuredKind::Position || obs.rows.len() < 3 {
        return Ok(());
    }
    let meas: Vec<_> = obs.rows.iter().map(|r| r.measured_mm).collect();
    let pred: Vec<_> = obs
        .rows
        .iter()
        .map(|r| super::forward::predict(machine, r, file).map(|p| p.attained_mm))
        .collect::<crate::error::Result<_>>()?;
    let (sm, sp) = (spread(&meas), spread(&pred));
    // Poses within a millimetre of each other tell no unit.
    if !(sp > 1.0 && sm.is_finite()) {
        return Ok(());
    }
    let ratio = sm / sp;
    if (1.0 / UNIT_SPREAD_RATIO..=UNIT_SPREAD_RATIO).contains(&ratio) {
        return Ok(());
    }
    let factor = 1.0 / ratio.max(f64::MIN_POSITIVE);
    let (unit, _) = LIKELY_UNITS
        .iter()
        .min_by(|a, b| {
            (a.1.ln() - factor.ln())
                .abs()
                .total_cmp(&(b.1.ln() - factor.ln()).abs())
        })
        .copied()
        .unwrap_or(("another unit", 1.0));
    Err(crate::error::Error::Data(format!(
        "{file}: the measured positions spread {} mm around their centre where the model's \
         positions for the same rows spread {} mm (ratio {}): the x_mm, y_mm, z_mm columns look \
         like {unit}, not mm; convert them to mm (or check the machine file)",
        crate::error::show_number((sm * 1000.0).round() / 1000.0),
        crate::error::show_number((sp * 1000.0).round() / 1000.0),
        crate::error::show_number((ratio * 10000.0).round() / 10000.0)
    )))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calibrate::observations::parse_observations;

    fn obs(body: &str) -> Observations {
        parse_observations(
            &format!("X_mm,Y_mm,Z_mm,dx_mm,dy_mm,dz_mm\n{body}"),
            "o.csv",
        )
        .expect("parses")
    }

    /// Machine-tool rows 0.005 mm apart are one pose; 0.05 mm apart, two
    /// (the measured deviations do not count).
    #[test]
    fn near_copies_are_one_pose() {
        let o = obs("10,20,30,40,50,60\n10.005,20,29.995,40,50,60.004\n10.05,20,30,40,50,60\n");
        let (of_row, n) = pose_groups(&o);
        assert_eq!((of_row, n), (vec![0, 0, 1], 2));
    }

    #[test]
    fn copies_dropped_repeats_grouped() {
        let o = obs("0,0,0,1,0,0\n0,0,0,1,0,0\n0,0,0,2,0,0\n1,0,0,0,0,0\n");
        let (d, note) = drop_copies(&o, "o.csv");
        assert_eq!(d.rows.len(), 3);
        assert!(note.is_some_and(|n| n.contains("o.csv:3 (copy of line 2)")));
        assert_eq!(distinct_poses(&d, &[0, 1, 2]), 2);
        for seed in 0..20 {
            let (fit, hold) = grouped_split(&d, 0.5, seed);
            // Rows 0 and 1 repeat one pose: always on the same side.
            assert_eq!(fit.contains(&0), fit.contains(&1), "{fit:?} {hold:?}");
            assert_eq!(fit.len() + hold.len(), 3);
        }
    }

    /// A straight line fitted to 200 points with one point moved far away:
    /// the moved point, and only it, is reported.
    #[test]
    fn one_outlier_of_a_line_fit_is_found() {
        let n = 200;
        let mut j = DMatrix::zeros(3 * n, 2);
        let mut e = DVector::zeros(3 * n);
        let mut rng = crate::calibrate::stats::SplitMix64::new(3);
        for k in 0..n {
            for c in 0..3 {
                j[(3 * k + c, 0)] = 1.0;
                j[(3 * k + c, 1)] = k as f64;
                e[3 * k + c] = rng.gaussian(0.0, 0.01);
            }
        }
        e[3 * 7] = 5.0;
        // The residuals of the least-squares fit.
        let svd = j.clone().svd(true, true);
        let x = svd.solve(&e, 1e-12).expect("solves");
        let r = &e - &j * x;
        let rows: Vec<usize> = (0..n).collect();
        let out = dominating_rows(&j, &r, &rows);
        assert_eq!(out.iter().map(|o| o.row).collect::<Vec<_>>(), vec![7]);
        assert!(out[0].deleted_mm > 4.0, "{out:?}");
    }
}
