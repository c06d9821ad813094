//! Plausibility limits of a robot file, like the magnitude limits of a
//! machine-tool file: a value beyond them is a typing or unit mistake, not
//! a robot (documented in docs/limits.md). Each refusal names the key path.

use crate::error::{Invalid, show_number};

use super::raw::{RawJoint, RawRobot};

/// Largest difference of an `actual` DH length (`a_mm`, `d_mm`) from its
/// nominal, mm. Calibrated robots differ by tenths of a millimetre.
pub const DH_LENGTH_DEVIATION_MAX_MM: f64 = 5.0;
/// Largest difference of an `actual` DH angle (`alpha_deg`,
/// `theta_offset_deg`) from its nominal, degrees.
pub const DH_ANGLE_DEVIATION_MAX_DEG: f64 = 1.0;
/// Largest thermal growth of one term, mm, at any joint power from 0 to
/// [`JOINT_POWER_MAX_W`] (`ub − lb·e^(−ts·P)`).
pub const THERMAL_GROWTH_MAX_MM: f64 = 2.0;
/// Highest joint power the thermal growth is checked to when the file
/// states no `thermal.rated_power_w`, W.
pub const JOINT_POWER_MAX_W: f64 = 5000.0;
/// Gravity magnitude band, m/s² (any direction); zero turns gravity off.
pub const GRAVITY_RANGE_M_PER_S2: [f64; 2] = [9.7, 9.9];
/// Heaviest payload (`tool_load.mass_kg`), kg: the largest robots carry
/// about 2.3 t.
pub const PAYLOAD_MAX_KG: f64 = 3000.0;
/// Heaviest link, kg.
pub const LINK_MASS_MAX_KG: f64 = 20_000.0;
/// Farthest centre of mass of a link or the payload from its frame, mm.
pub const MASS_OFFSET_MAX_MM: f64 = 5000.0;
/// Largest process force (`force_n` of a wrench or a constant model), N.
pub const PROCESS_FORCE_MAX_N: f64 = 20_000.0;

type V = Result<(), Invalid>;

/// Checks every plausibility limit of a robot file whose values are already
/// known to be finite.
pub(crate) fn check(raw: &RawRobot) -> V {
    if let Some(actual) = &raw.actual {
        for (i, (a, n)) in actual.iter().zip(&raw.nominal).enumerate() {
            dh_deviation(i, a, n)?;
        }
    }
    gravity(&raw.gravity_m_per_s2)?;
    for (i, l) in raw.links.iter().enumerate() {
        at_most(
            &format!("links[{i}].mass_kg"),
            l.mass_kg,
            LINK_MASS_MAX_KG,
            "kg",
        )?;
        offset(&format!("links[{i}].com_mm"), &l.com_mm)?;
    }
    if let Some(l) = &raw.tool_load {
        at_most("tool_load.mass_kg", l.mass_kg, PAYLOAD_MAX_KG, "kg")?;
        offset("tool_load.cog_mm", &l.cog_mm)?;
    }
    if let Some(t) = &raw.thermal {
        // Up to the rated power the file states (`thermal.rated_power_w`),
        // else up to the highest joint power of any robot.
        let (p_max, whose) = match t.rated_power_w {
            Some(w) => (w, "the rated power thermal.rated_power_w"),
            None => (JOINT_POWER_MAX_W, "the limit without thermal.rated_power_w"),
        };
        for (i, term) in t.terms.iter().enumerate() {
            // The growth is monotonic in the power: its extremes are at the
            // ends of the range.
            let cold = term.ub_mm - term.lb_mm;
            let hot = term.ub_mm - term.lb_mm * (-term.ts_per_w * p_max).exp();
            let worst = cold.abs().max(hot.abs());
            if worst > THERMAL_GROWTH_MAX_MM {
                return Err(Invalid::new(
                    format!("thermal.terms[{i}]"),
                    format!(
                        "grows its DH length by {} mm between 0 and {} W ({whose}), more than the {THERMAL_GROWTH_MAX_MM} mm limit (check lb_mm, ub_mm and ts_per_w)",
                        show_number(worst),
                        show_number(p_max)
                    ),
                ));
            }
        }
    }
    if let Some(w) = &raw.process_wrench {
        force("process_wrench.force_n", &w.force_n)?;
    }
    if let Some(f) = raw.process_force.as_ref().and_then(|f| f.force_n.as_ref()) {
        force("process_force.force_n", f)?;
    }
    Ok(())
}

fn dh_deviation(i: usize, a: &RawJoint, n: &RawJoint) -> V {
    for (k, va, vn) in [("a_mm", a.a_mm, n.a_mm), ("d_mm", a.d_mm, n.d_mm)] {
        let dev = (va - vn).abs();
        if dev > DH_LENGTH_DEVIATION_MAX_MM {
            return Err(Invalid::new(
                format!("actual[{i}].{k}"),
                format!(
                    "{} mm is {} mm from the nominal {} mm, more than the {DH_LENGTH_DEVIATION_MAX_MM} mm limit of a calibrated deviation",
                    show_number(va),
                    show_number(dev),
                    show_number(vn)
                ),
            ));
        }
    }
    for (k, va, vn) in [
        ("alpha_deg", a.alpha_deg, n.alpha_deg),
        ("theta_offset_deg", a.theta_offset_deg, n.theta_offset_deg),
    ] {
        let dev = ((va - vn + 180.0).rem_euclid(360.0) - 180.0).abs();
        if dev > DH_ANGLE_DEVIATION_MAX_DEG {
            return Err(Invalid::new(
                format!("actual[{i}].{k}"),
                format!(
                    "{}° is {}° from the nominal {}°, more than the {DH_ANGLE_DEVIATION_MAX_DEG}° limit of a calibrated deviation",
                    show_number(va),
                    show_number(dev),
                    show_number(vn)
                ),
            ));
        }
    }
    Ok(())
}

fn gravity(g: &[f64; 3]) -> V {
    let m = g.iter().map(|v| v * v).sum::<f64>().sqrt();
    let [lo, hi] = GRAVITY_RANGE_M_PER_S2;
    if m != 0.0 && !(lo..=hi).contains(&m) {
        return Err(Invalid::new(
            "gravity_m_per_s2",
            format!(
                "magnitude {} m/s² is outside {lo}..{hi} m/s² (0 turns gravity off; check the unit)",
                show_number(m)
            ),
        ));
    }
    Ok(())
}

fn at_most(path: &str, v: f64, max: f64, unit: &str) -> V {
    if v > max {
        return Err(Invalid::new(
            path,
            format!(
                "{} {unit} exceeds the {max} {unit} limit (check the unit)",
                show_number(v)
            ),
        ));
    }
    Ok(())
}

fn offset(path: &str, v: &[f64; 3]) -> V {
    let m = v.iter().map(|x| x * x).sum::<f64>().sqrt();
    at_most(path, m, MASS_OFFSET_MAX_MM, "mm")
}

fn force(path: &str, v: &[f64; 3]) -> V {
    let m = v.iter().map(|x| x * x).sum::<f64>().sqrt();
    at_most(path, m, PROCESS_FORCE_MAX_N, "N")
}
