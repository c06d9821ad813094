//! ISO 9283: pose accuracy and repeatability of a robot from repeated
//! visits of poses, and path accuracy and repeatability from repeated runs
//! of a path (positions; docs/verify.md).
//!
//! For a pose visited n times at attained positions x_j with commanded
//! position x_c: the barycentre x̄ = mean_j x_j; pose accuracy
//! AP_p = |x̄ − x_c| with its components APx, APy, APz; with
//! l_j = |x_j − x̄|, l̄ = mean_j l_j and S_l = sqrt(Σ_j (l_j − l̄)² / (n − 1)),
//! pose repeatability RP_l = l̄ + 3 S_l. For a path, the same at each of
//! its points (the attained points of each run where they cross the
//! point's normal plane): path accuracy AT_P = max over points of
//! |x̄_i − x_ci|, path repeatability RT_P = max over points of
//! l̄_i + 3 S_li. The robot's AP and RP are the largest of its poses'.
//!
//! Where a pose file gives orientations (angles a, b, c about x, y, z,
//! commanded and attained, degrees), the orientation characteristics of
//! each pose: with d_j = a_j − a_c (taken within ±180°),
//! APa = mean_j d_j and RPa = 3 S_a, S_a = sqrt(Σ_j (d_j − APa)² / (n − 1))
//! (b and c alike); the robot's APa … RPc are those of largest magnitude
//! over its poses (group `orientation`, degrees).

use nalgebra::Vector3;
use serde_json::json;

use super::table::{Column, Kind, Row, Table};
use super::{Evaluation, Figure, Group, Standard, fmt_mm, json_mm};
use crate::error::{Error, Located, Result};

/// The figures, in report order.
pub const FIGURES: [&str; 10] = [
    "AP", "RP", "AT", "RT", "APa", "APb", "APc", "RPa", "RPb", "RPc",
];

/// The orientation figures (degrees), in report order.
pub const ORIENTATION_FIGURES: [&str; 6] = ["APa", "APb", "APc", "RPa", "RPb", "RPc"];

/// The orientation columns of a pose file: commanded, then attained.
pub const ORIENTATION_COLUMNS: [&str; 6] =
    ["ac_deg", "bc_deg", "cc_deg", "a_deg", "b_deg", "c_deg"];

/// Fewest poses of a pose test.
pub const MIN_POSES: usize = 5;

/// Fewest visits of each pose or path point.
pub const MIN_VISITS: usize = 5;

/// Fewest points of a path.
pub const MIN_PATH_POINTS: usize = 2;

/// Commanded positions of one pose further apart than this are an error, mm.
pub const SAME_COMMAND_MM: f64 = 1e-6;

/// The columns of a pose file.
pub const POSE_COLUMNS: &[Column] = &[
    Column::optional("id", Kind::Text),
    Column::required("pose", Kind::Text),
    Column::optional("cycle", Kind::Count),
    Column::required("xc_mm", Kind::Number),
    Column::required("yc_mm", Kind::Number),
    Column::required("zc_mm", Kind::Number),
    Column::required("x_mm", Kind::Number),
    Column::required("y_mm", Kind::Number),
    Column::required("z_mm", Kind::Number),
    Column::optional("ac_deg", Kind::Number),
    Column::optional("bc_deg", Kind::Number),
    Column::optional("cc_deg", Kind::Number),
    Column::optional("a_deg", Kind::Number),
    Column::optional("b_deg", Kind::Number),
    Column::optional("c_deg", Kind::Number),
    Column::optional("t_s", Kind::Number),
];

/// The columns of a path file.
pub const PATH_COLUMNS: &[Column] = &[
    Column::optional("id", Kind::Text),
    Column::required("point", Kind::Text),
    Column::optional("cycle", Kind::Count),
    Column::required("xc_mm", Kind::Number),
    Column::required("yc_mm", Kind::Number),
    Column::required("zc_mm", Kind::Number),
    Column::required("x_mm", Kind::Number),
    Column::required("y_mm", Kind::Number),
    Column::required("z_mm", Kind::Number),
    Column::optional("t_s", Kind::Number),
];

/// The visits of one pose (or path point).
#[derive(Debug, Clone, PartialEq)]
pub struct Visits {
    /// Its label.
    pub label: String,
    /// Commanded position, mm.
    pub commanded: Vector3<f64>,
    /// Attained positions, mm.
    pub attained: Vec<Vector3<f64>>,
    /// Commanded and attained orientations (a, b, c about x, y, z,
    /// degrees), when the file gives them.
    pub orientation: Option<(Vector3<f64>, Vec<Vector3<f64>>)>,
}

/// The orientation characteristics of one pose, degrees.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OrientationStats {
    /// APa, APb, APc: mean attained − commanded angle.
    pub ap_abc: Vector3<f64>,
    /// S_a, S_b, S_c.
    pub s_abc: Vector3<f64>,
    /// RPa, RPb, RPc = 3 S.
    pub rp_abc: Vector3<f64>,
}

/// An angle difference within ±180°.
fn wrapped_deg(d: f64) -> f64 {
    let r = d.rem_euclid(360.0);
    if r > 180.0 { r - 360.0 } else { r }
}

/// The orientation characteristics of the visits of a pose.
pub fn orientation_stats(commanded: &Vector3<f64>, attained: &[Vector3<f64>]) -> OrientationStats {
    let mut ap = Vector3::zeros();
    let mut sd = Vector3::zeros();
    for i in 0..3 {
        let d: Vec<f64> = attained
            .iter()
            .map(|x| wrapped_deg(x[i] - commanded[i]))
            .collect();
        let (m, s) = super::iso230_2::mean_s(&d);
        ap[i] = m;
        sd[i] = s;
    }
    OrientationStats {
        ap_abc: ap,
        s_abc: sd,
        rp_abc: sd * 3.0,
    }
}

/// The statistics of one pose (or path point), mm.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseStats {
    /// Its label.
    pub label: String,
    /// Visits.
    pub visits: usize,
    /// Barycentre − commanded (APx, APy, APz).
    pub ap_xyz: Vector3<f64>,
    /// |barycentre − commanded|.
    pub ap: f64,
    /// l̄.
    pub l_mean: f64,
    /// S_l.
    pub s_l: f64,
    /// l̄ + 3 S_l.
    pub rp: f64,
    /// The orientation characteristics, when the visits give orientations.
    pub orientation: Option<OrientationStats>,
}

/// The statistics of one pose.
pub fn pose_stats(v: &Visits) -> PoseStats {
    let n = v.attained.len() as f64;
    let bary = v.attained.iter().sum::<Vector3<f64>>() / n;
    let ls: Vec<f64> = v.attained.iter().map(|x| (x - bary).norm()).collect();
    let (l_mean, s_l) = super::iso230_2::mean_s(&ls);
    let ap_xyz = bary - v.commanded;
    PoseStats {
        label: v.label.clone(),
        visits: v.attained.len(),
        ap_xyz,
        ap: ap_xyz.norm(),
        l_mean,
        s_l,
        rp: l_mean + 3.0 * s_l,
        orientation: v.orientation.as_ref().map(|(c, a)| orientation_stats(c, a)),
    }
}

/// Reads a pose file (`path` false) or a path file, visits grouped by
/// label in order of first appearance.
pub fn read_visits(text: &str, file: &str, path: bool) -> Result<Vec<Visits>> {
    let (columns, label_col) = if path {
        (PATH_COLUMNS, "point")
    } else {
        (POSE_COLUMNS, "pose")
    };
    let table = Table::parse(text, file, columns)?;
    let mut out: Vec<(Visits, usize)> = Vec::new();
    for row in &table.rows {
        let label = row
            .text(&table, label_col)
            .ok_or_else(|| row.error(&table, label_col, format!("empty `{label_col}`")))?;
        let cmd = triple(row, &table, ["xc_mm", "yc_mm", "zc_mm"])?;
        let att = triple(row, &table, ["x_mm", "y_mm", "z_mm"])?;
        let orient = orientation_of(row, &table)?;
        match out.iter_mut().find(|(v, _)| v.label == label) {
            Some((v, _)) => {
                match (&mut v.orientation, orient) {
                    (Some((c, a)), Some((oc, oa))) => {
                        if (*c - oc).amax() > SAME_COMMAND_DEG {
                            return Err(row.error(
                                &table,
                                "ac_deg",
                                format!(
                                    "{label_col} `{label}` commanded at another orientation than on its first row"
                                ),
                            ));
                        }
                        a.push(oa);
                    }
                    (None, None) => {}
                    _ => return Err(orientation_mismatch(row, &table)),
                }
                if (v.commanded - cmd).amax() > SAME_COMMAND_MM {
                    return Err(row.error(
                        &table,
                        "xc_mm",
                        format!(
                            "{label_col} `{label}` commanded at another position than on its first row"
                        ),
                    ));
                }
                v.attained.push(att);
            }
            None => out.push((
                Visits {
                    label: label.to_string(),
                    commanded: cmd,
                    attained: vec![att],
                    orientation: orient.map(|(c, a)| (c, vec![a])),
                },
                row.line,
            )),
        }
    }
    let (least, what) = if path {
        (MIN_PATH_POINTS, "path points")
    } else {
        (MIN_POSES, "poses")
    };
    if out.len() < least {
        return Err(table.header_error(format!(
            "{} {what}; ISO 9283 asks for at least {least}",
            out.len()
        )));
    }
    for (v, line) in &out {
        if v.attained.len() < MIN_VISITS {
            return Err(Error::Input(Located::new(
                file,
                *line,
                1,
                format!(
                    "{label_col} `{}`: {} visits; at least {MIN_VISITS} are needed",
                    v.label,
                    v.attained.len()
                ),
            )));
        }
    }
    if out.iter().any(|(v, _)| v.orientation.is_some())
        && out.iter().any(|(v, _)| v.orientation.is_none())
    {
        return Err(table.header_error("orientations given for some poses and not for others"));
    }
    Ok(out.into_iter().map(|(v, _)| v).collect())
}

/// Commanded orientations of one pose further apart than this are an
/// error, degrees.
pub const SAME_COMMAND_DEG: f64 = 1e-6;

/// The commanded and attained orientation of a row: all six orientation
/// cells or none.
fn orientation_of(row: &Row, table: &Table) -> Result<Option<(Vector3<f64>, Vector3<f64>)>> {
    let cells: Vec<Option<f64>> = ORIENTATION_COLUMNS
        .iter()
        .map(|n| row.number(table, n))
        .collect();
    if cells.iter().all(Option::is_none) {
        return Ok(None);
    }
    if let Some(i) = cells.iter().position(Option::is_none) {
        let n = ORIENTATION_COLUMNS[i];
        return Err(row.error(
            table,
            if table.has(n) { n } else { "pose" },
            format!(
                "`{n}` not given: an orientation needs all of {}",
                ORIENTATION_COLUMNS.join(", ")
            ),
        ));
    }
    let v = |i: usize| cells[i].unwrap_or(0.0);
    Ok(Some((
        Vector3::new(v(0), v(1), v(2)),
        Vector3::new(v(3), v(4), v(5)),
    )))
}

fn orientation_mismatch(row: &Row, table: &Table) -> Error {
    row.error(
        table,
        "pose",
        "orientation given on some visits of this pose and not on others",
    )
}

fn triple(row: &Row, table: &Table, names: [&str; 3]) -> Result<Vector3<f64>> {
    let mut v = Vector3::zeros();
    for (i, n) in names.iter().enumerate() {
        v[i] = row
            .number(table, n)
            .ok_or_else(|| row.error(table, n, format!("empty `{n}`")))?;
    }
    Ok(v)
}

/// The evaluated poses and, where given, path.
#[derive(Debug, Clone, PartialEq)]
pub struct Iso9283 {
    /// Per pose.
    pub poses: Vec<PoseStats>,
    /// Per path point (empty without path data).
    pub path: Vec<PoseStats>,
}

/// Evaluates poses and path points.
pub fn evaluate(poses: &[Visits], path: &[Visits]) -> Iso9283 {
    Iso9283 {
        poses: poses.iter().map(pose_stats).collect(),
        path: path.iter().map(pose_stats).collect(),
    }
}

fn worst(s: &[PoseStats], f: impl Fn(&PoseStats) -> f64) -> f64 {
    s.iter().map(f).fold(0.0, f64::max)
}

/// The value of largest magnitude (signed; 0 for none).
fn worst_signed(v: impl Iterator<Item = f64>) -> f64 {
    v.fold(0.0, |w, x| if x.abs() > w.abs() { x } else { w })
}

/// The `orientation` group of poses that all give orientations.
fn orientation_group(poses: &[PoseStats]) -> Option<Group> {
    let o: Vec<OrientationStats> = poses.iter().map(|p| p.orientation).collect::<Option<_>>()?;
    if o.is_empty() {
        return None;
    }
    let mut figures = Vec::with_capacity(6);
    for (k, name) in ORIENTATION_FIGURES.iter().enumerate() {
        let i = k % 3;
        let value = if k < 3 {
            worst_signed(o.iter().map(|s| s.ap_abc[i]))
        } else {
            o.iter().map(|s| s.rp_abc[i]).fold(0.0, f64::max)
        };
        figures.push(Figure {
            name,
            value_mm: value,
            u_mm: None,
        });
    }
    Some(Group {
        name: "orientation".into(),
        figures,
    })
}

impl Evaluation for Iso9283 {
    fn standard(&self) -> Standard {
        Standard::Iso9283
    }

    fn groups(&self) -> Vec<Group> {
        let mut g = vec![Group {
            name: "poses".into(),
            figures: vec![
                Figure {
                    name: "AP",
                    value_mm: worst(&self.poses, |p| p.ap),
                    u_mm: None,
                },
                Figure {
                    name: "RP",
                    value_mm: worst(&self.poses, |p| p.rp),
                    u_mm: None,
                },
            ],
        }];
        g.extend(orientation_group(&self.poses));
        if !self.path.is_empty() {
            g.push(Group {
                name: "path".into(),
                figures: vec![
                    Figure {
                        name: "AT",
                        value_mm: worst(&self.path, |p| p.ap),
                        u_mm: None,
                    },
                    Figure {
                        name: "RT",
                        value_mm: worst(&self.path, |p| p.rp),
                        u_mm: None,
                    },
                ],
            });
        }
        g
    }

    fn detail_json(&self) -> serde_json::Value {
        let rows = |s: &[PoseStats]| -> Vec<serde_json::Value> {
            s.iter()
                .map(|p| {
                    let mut o = json!({
                        "label": p.label,
                        "visits": p.visits,
                        "ap_x_mm": json_mm(p.ap_xyz[0]),
                        "ap_y_mm": json_mm(p.ap_xyz[1]),
                        "ap_z_mm": json_mm(p.ap_xyz[2]),
                        "ap_mm": json_mm(p.ap),
                        "l_mean_mm": json_mm(p.l_mean),
                        "s_l_mm": json_mm(p.s_l),
                        "rp_mm": json_mm(p.rp),
                    });
                    if let (Some(s), Some(map)) = (p.orientation, o.as_object_mut()) {
                        for (i, c) in ["a", "b", "c"].iter().enumerate() {
                            map.insert(format!("ap_{c}_deg"), json_mm(s.ap_abc[i]));
                            map.insert(format!("s_{c}_deg"), json_mm(s.s_abc[i]));
                            map.insert(format!("rp_{c}_deg"), json_mm(s.rp_abc[i]));
                        }
                    }
                    o
                })
                .collect()
        };
        json!({ "poses": rows(&self.poses), "path": rows(&self.path) })
    }

    fn detail_table(&self, out: &mut String) {
        for (title, s) in [("pose", &self.poses), ("point", &self.path)] {
            if s.is_empty() {
                continue;
            }
            out.push_str(&format!(
                "{title:<8} {:>6} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9}\n",
                "visits", "APx", "APy", "APz", "AP", "l_mean", "S_l", "RP"
            ));
            for p in s.iter() {
                out.push_str(&format!(
                    "{:<8} {:>6} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9}\n",
                    p.label,
                    p.visits,
                    fmt_mm(p.ap_xyz[0]),
                    fmt_mm(p.ap_xyz[1]),
                    fmt_mm(p.ap_xyz[2]),
                    fmt_mm(p.ap),
                    fmt_mm(p.l_mean),
                    fmt_mm(p.s_l),
                    fmt_mm(p.rp)
                ));
            }
        }
        if self.poses.iter().all(|p| p.orientation.is_some()) && !self.poses.is_empty() {
            out.push_str(&format!(
                "{:<8} {:>6} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9}   (deg)\n",
                "pose", "visits", "APa", "APb", "APc", "RPa", "RPb", "RPc"
            ));
            for p in &self.poses {
                let Some(s) = p.orientation else { continue };
                out.push_str(&format!(
                    "{:<8} {:>6} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9}\n",
                    p.label,
                    p.visits,
                    fmt_mm(s.ap_abc[0]),
                    fmt_mm(s.ap_abc[1]),
                    fmt_mm(s.ap_abc[2]),
                    fmt_mm(s.rp_abc[0]),
                    fmt_mm(s.rp_abc[1]),
                    fmt_mm(s.rp_abc[2])
                ));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    const NM: f64 = 1e-6;

    #[test]
    fn figures_of_a_hand_derived_pose() {
        // Visits at ±0.05 mm in x and in y about a barycentre offset by
        // (0.3, −0.4, 0) from the command: AP = 0.5; l = 0.05 (four times)
        // and 0, l̄ = 0.04, S_l = sqrt((4·0.01² + 0.04²)/4) = sqrt(5e-4).
        let c = Vector3::new(100.0, 200.0, 300.0);
        let b = c + Vector3::new(0.3, -0.4, 0.0);
        let v = Visits {
            label: "P1".into(),
            commanded: c,
            attained: vec![
                b + Vector3::new(0.05, 0.0, 0.0),
                b + Vector3::new(-0.05, 0.0, 0.0),
                b + Vector3::new(0.0, 0.05, 0.0),
                b + Vector3::new(0.0, -0.05, 0.0),
                b,
            ],
            orientation: None,
        };
        let s = pose_stats(&v);
        assert_abs_diff_eq!(s.ap, 0.5, epsilon = NM);
        assert_abs_diff_eq!(s.ap_xyz[1], -0.4, epsilon = NM);
        assert_abs_diff_eq!(s.l_mean, 0.04, epsilon = NM);
        assert_abs_diff_eq!(s.s_l, 0.022_360_68, epsilon = NM);
        assert_abs_diff_eq!(s.rp, 0.107_082_04, epsilon = NM);
    }

    #[test]
    fn a_moved_command_or_too_few_visits_is_refused() {
        let head = "pose,xc_mm,yc_mm,zc_mm,x_mm,y_mm,z_mm\n";
        let e = read_visits(
            &format!("{head}P1,0,0,0,0,0,0\nP1,0,0,1,0,0,0\n"),
            "p.csv",
            false,
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.starts_with("p.csv:3:4: pose `P1` commanded at another position"),
            "{e}"
        );
        let e = read_visits(&format!("{head}P1,0,0,0,0,0,0\n"), "p.csv", false)
            .unwrap_err()
            .to_string();
        assert!(e.contains("1 poses; ISO 9283 asks for at least 5"), "{e}");
        let mut text = String::from(head);
        for p in 1..=5 {
            for _ in 0..(if p == 4 { 4 } else { 5 }) {
                text.push_str(&format!("P{p},{p},0,0,{p},0,0\n"));
            }
        }
        let e = read_visits(&text, "p.csv", false).unwrap_err().to_string();
        assert!(e.starts_with("p.csv:17:1: pose `P4`: 4 visits"), "{e}");
    }
}
