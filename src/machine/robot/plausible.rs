//! Plausibility limits of a robot file, like those of a machine-tool file
//! ([`crate::machine::tool::plausible`]): a value beyond them is a typing
//! or unit mistake, not a robot (documented in docs/limits.md). The ranges
//! admit real arms from a 3 kg-payload ABB IRB 120 (0.58 m reach) to the
//! largest (a 235 kg-payload IRB 6700, 2.3 t on a Fanuc M-2000iA). Each
//! refusal names the key path and the range; `plausibility: { KEY: off }`
//! accepts a value on purpose ([`crate::machine::plausibility`]).

use crate::error::{Invalid, show_number};
use crate::machine::plausibility::{ForceKeys, PLACEMENT, Pass, Range};

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
/// Payload (`tool_load.mass_kg`), kg: the largest robots carry about
/// 2.3 t.
pub const PAYLOAD_KG: Range = Range::new(0.0, 3000.0, "kg", "a payload");
/// Largest process force (`force_n` of a wrench or a constant model), N.
pub const PROCESS_FORCE_MAX_N: f64 = 20_000.0;

/// A DH length (`a_mm`, `d_mm`) of the nominal model, mm.
pub const DH_LENGTH_MM: Range = Range::new(-5000.0, 5000.0, "mm", "a DH length");
/// An arm's reach: the sum of its nominal DH lengths, mm.
pub const REACH_MM: Range = Range::new(200.0, 10_000.0, "mm", "an arm's reach");
/// Joint limits, degrees (an ABB wrist axis may turn ±242 turns).
pub const JOINT_LIMIT_DEG: Range = Range::new(-100_000.0, 100_000.0, "°", "a joint limit");
/// Joint speeds, °/s (the largest arms' first axes about 50, small
/// wrists about 1000).
pub const JOINT_SPEED_DEG_PER_S: Range = Range::new(5.0, 3000.0, "°/s", "a joint speed");
/// Stiffness of joints 1–3 per kilogram-metre of the arm's mass (links
/// and payload) times its reach, N·m/rad/(kg·m): the torques a joint
/// carries grow with both, and so does the stiffness arms are built with
/// (IRB 1600 360–1100, TX200 330–2040; the bundled arms from the IRB 120
/// to the IRB 6700 290–2040).
pub const MAIN_JOINT_STIFFNESS: Range = Range::new(
    30.0,
    30_000.0,
    "N·m/rad per kg·m",
    "a main joint's (1–3) stiffness",
);
/// Stiffness of the wrist joints 4–6 per kilogram-metre of mass times
/// reach (IRB 1600 14–29, TX200 52–317; the bundled arms 11–317).
pub const WRIST_JOINT_STIFFNESS: Range = Range::new(
    1.5,
    5000.0,
    "N·m/rad per kg·m",
    "a wrist joint's (4–6) stiffness",
);
/// Mass of links 1–3, kg (the heaviest arms' columns weigh a tonne or two).
pub const MAIN_LINK_MASS: Range = Range::new(0.0, 5000.0, "kg", "the mass of link 1, 2 or 3");
/// Mass of links 4 and 5 (forearm, wrist), kg.
pub const WRIST_LINK_MASS: Range = Range::new(0.0, 1000.0, "kg", "the mass of link 4 or 5");
/// Mass of link 6 (the flange), kg.
pub const FLANGE_MASS: Range = Range::new(0.0, 100.0, "kg", "the flange's (link 6) mass");
/// Natural frequency of a robot's mode, Hz (first modes 7–10 Hz).
pub const MODAL_HZ: Range = Range::new(0.5, 200.0, "Hz", "a robot's natural frequency");
/// Damping ratio of a mode.
pub const DAMPING: Range = Range::new(0.001, 0.5, "", "a damping ratio");
/// Modal stiffness at the TCP, N/µm (an IRB 4600 about 0.1–0.3, one to
/// two orders of magnitude below machine tools).
pub const MODAL_N_PER_UM: Range = Range::new(0.01, 50.0, "N/µm", "a robot's modal stiffness");
/// Thermal time constant, minutes (steady state after about 2 h on small
/// robots, up to two days on very large ones).
pub const TIME_CONSTANT_MIN: Range = Range::new(1.0, 2880.0, "min", "a thermal time constant");
/// Rate `ts` of a thermal term, 1/W (joint powers are tens to hundreds
/// of W).
pub const THERMAL_RATE_PER_W: Range = Range::new(0.0, 1.0, "1/W", "a thermal rate");

/// Checks every plausibility limit of a robot file whose values are already
/// known to be finite; the warnings of values accepted through overrides.
pub(crate) fn check(raw: &RawRobot) -> Result<Vec<Invalid>, Invalid> {
    let mut p = Pass::new();
    let mut reach = 0.0;
    for (i, n) in raw.nominal.iter().enumerate() {
        p.range(&format!("nominal[{i}].a_mm"), n.a_mm, DH_LENGTH_MM);
        p.range(&format!("nominal[{i}].d_mm"), n.d_mm, DH_LENGTH_MM);
        reach += n.a_mm.abs() + n.d_mm.abs();
    }
    p.range("nominal", reach, REACH_MM);
    if let Some(actual) = &raw.actual {
        for (i, (a, n)) in actual.iter().zip(&raw.nominal).enumerate() {
            dh_deviation(&mut p, i, a, n);
        }
    }
    for (i, l) in raw.joint_limits_deg.iter().enumerate() {
        p.each(&format!("joint_limits_deg[{i}]"), l, JOINT_LIMIT_DEG);
    }
    p.each(
        "joint_speed_deg_per_s",
        &raw.joint_speed_deg_per_s,
        JOINT_SPEED_DEG_PER_S,
    );
    // Frames and mass offsets within the arm's reach (a tool or a load
    // longer than the arm is a unit mistake).
    let within_reach = Range::new(
        0.0,
        reach.max(REACH_MM.lo),
        "mm",
        "an offset within the arm's reach",
    );
    if let Some(f) = &raw.flange_to_tool {
        p.norm("flange_to_tool", &[f.x_mm, f.y_mm, f.z_mm], within_reach);
    }
    for (key, f) in [
        ("base", &raw.base),
        ("measurement_frame", &raw.measurement_frame),
    ] {
        if let Some(f) = f {
            p.norm(key, &[f.x_mm, f.y_mm, f.z_mm], PLACEMENT);
        }
    }
    gravity(&mut p, &raw.gravity_m_per_s2);
    for (i, l) in raw.links.iter().enumerate() {
        let r = match i {
            0..=2 => MAIN_LINK_MASS,
            3 | 4 => WRIST_LINK_MASS,
            _ => FLANGE_MASS,
        };
        p.range(&format!("links[{i}].mass_kg"), l.mass_kg, r);
        p.norm(&format!("links[{i}].com_mm"), &l.com_mm, within_reach);
    }
    if let Some(l) = &raw.tool_load {
        p.range("tool_load.mass_kg", l.mass_kg, PAYLOAD_KG);
        p.norm("tool_load.cog_mm", &l.cog_mm, within_reach);
    }
    joint_stiffness(&mut p, raw, reach);
    if let Some(t) = &raw.thermal {
        // Up to the rated power the file states (`thermal.rated_power_w`),
        // else up to the highest joint power of any robot.
        let (p_max, whose) = match t.rated_power_w {
            Some(w) => (w, "the rated power thermal.rated_power_w"),
            None => (JOINT_POWER_MAX_W, "the limit without thermal.rated_power_w"),
        };
        p.range(
            "thermal.time_constant_min",
            t.time_constant_min,
            TIME_CONSTANT_MIN,
        );
        for (i, term) in t.terms.iter().enumerate() {
            p.range(
                &format!("thermal.terms[{i}].ts_per_w"),
                term.ts_per_w,
                THERMAL_RATE_PER_W,
            );
            // The growth is monotonic in the power: its extremes are at the
            // ends of the range.
            let cold = term.ub_mm - term.lb_mm;
            let hot = term.ub_mm - term.lb_mm * (-term.ts_per_w * p_max).exp();
            let worst = cold.abs().max(hot.abs());
            p.custom(
                &format!("thermal.terms[{i}]"),
                (worst > THERMAL_GROWTH_MAX_MM).then(|| format!(
                    "grows its DH length by {} mm between 0 and {} W ({whose}), more than the {THERMAL_GROWTH_MAX_MM} mm limit (check lb_mm, ub_mm and ts_per_w)",
                    show_number(worst),
                    show_number(p_max)
                )),
            );
        }
    }
    if let Some(w) = &raw.process_wrench {
        let force = Range::new(0.0, PROCESS_FORCE_MAX_N, "N", "a robot's process force");
        p.norm("process_wrench.force_n", &w.force_n, force);
        p.norm(
            "process_wrench.moment_nm",
            &w.moment_nm,
            Range::new(0.0, 5000.0, "N·m", "a process moment"),
        );
    }
    if let Some(f) = &raw.process_force {
        if let Some(v) = &f.force_n {
            let force = Range::new(0.0, PROCESS_FORCE_MAX_N, "N", "a robot's process force");
            p.norm("process_force.force_n", v, force);
        }
        p.force(&ForceKeys {
            force_n: None,
            moment_nm: f.moment_nm,
            k: [
                f.kt_n_per_mm2,
                f.kr_n_per_mm2,
                f.ka_n_per_mm2,
                f.kte_n_per_mm,
                f.kre_n_per_mm,
                f.kae_n_per_mm,
            ],
            tool_diameter_mm: f.tool_diameter_mm,
            axial_depth_mm: f.axial_depth_mm,
            thrust_n_per_mm2: f.thrust_coefficient_n_per_mm2,
            drill_diameter_mm: f.drill_diameter_mm,
            spindle_rpm: f.spindle_rpm,
            max_feed_mm_per_rev: f.max_feed_mm_per_rev,
        });
    }
    if let Some(modes) = &raw.modal {
        for (i, m) in modes.iter().enumerate() {
            p.range(
                &format!("modal[{i}].frequency_hz"),
                m.frequency_hz,
                MODAL_HZ,
            );
            p.range(
                &format!("modal[{i}].damping_ratio"),
                m.damping_ratio,
                DAMPING,
            );
            p.range(
                &format!("modal[{i}].stiffness_n_per_um"),
                m.stiffness_n_per_um,
                MODAL_N_PER_UM,
            );
        }
    }
    p.settle(raw.plausibility.as_ref())
}

/// Joint stiffness against the arm's size: the range per kg·m times the
/// arm's mass (links and payload) and reach.
fn joint_stiffness(p: &mut Pass, raw: &RawRobot, reach_mm: f64) {
    let mass = raw.links.iter().map(|l| l.mass_kg).sum::<f64>()
        + raw.tool_load.as_ref().map_or(0.0, |l| l.mass_kg);
    let size = mass * reach_mm / 1000.0;
    for (i, k) in raw.k_nm_per_rad.iter().enumerate() {
        let r = if i < 3 {
            MAIN_JOINT_STIFFNESS
        } else {
            WRIST_JOINT_STIFFNESS
        };
        let (lo, hi) = (r.lo * size, r.hi * size);
        let bad = size.is_finite() && size > 0.0 && k.is_finite() && !(lo..=hi).contains(k);
        p.custom(
            &format!("k_nm_per_rad[{i}]"),
            bad.then(|| {
                format!(
                    "{} N·m/rad is outside {}..{} N·m/rad, the plausible range of {} on an arm of {} kg and {} mm reach ({} times its mass and reach; check the unit)",
                    show_number(*k),
                    show_number(round3(lo)),
                    show_number(round3(hi)),
                    r.what,
                    show_number(round3(mass)),
                    show_number(round3(reach_mm)),
                    r.shown()
                )
            }),
        );
    }
}

/// `v` rounded to three significant digits, for messages.
fn round3(v: f64) -> f64 {
    if v == 0.0 || !v.is_finite() {
        return v;
    }
    let e = 10f64.powi(v.abs().log10().floor() as i32 - 2);
    (v / e).round() * e
}

fn dh_deviation(p: &mut Pass, i: usize, a: &RawJoint, n: &RawJoint) {
    for (k, va, vn) in [("a_mm", a.a_mm, n.a_mm), ("d_mm", a.d_mm, n.d_mm)] {
        let dev = (va - vn).abs();
        p.custom(
            &format!("actual[{i}].{k}"),
            (dev > DH_LENGTH_DEVIATION_MAX_MM).then(|| {
                format!(
                    "{} mm is {} mm from the nominal {} mm, more than the {DH_LENGTH_DEVIATION_MAX_MM} mm limit of a calibrated deviation",
                    show_number(va),
                    show_number(dev),
                    show_number(vn)
                )
            }),
        );
    }
    for (k, va, vn) in [
        ("alpha_deg", a.alpha_deg, n.alpha_deg),
        ("theta_offset_deg", a.theta_offset_deg, n.theta_offset_deg),
    ] {
        let dev = ((va - vn + 180.0).rem_euclid(360.0) - 180.0).abs();
        p.custom(
            &format!("actual[{i}].{k}"),
            (dev > DH_ANGLE_DEVIATION_MAX_DEG).then(|| {
                format!(
                    "{}° is {}° from the nominal {}°, more than the {DH_ANGLE_DEVIATION_MAX_DEG}° limit of a calibrated deviation",
                    show_number(va),
                    show_number(dev),
                    show_number(vn)
                )
            }),
        );
    }
}

fn gravity(p: &mut Pass, g: &[f64; 3]) {
    let m = g.iter().map(|v| v * v).sum::<f64>().sqrt();
    let [lo, hi] = GRAVITY_RANGE_M_PER_S2;
    p.custom(
        "gravity_m_per_s2",
        (m != 0.0 && !(lo..=hi).contains(&m)).then(|| {
            format!(
                "magnitude {} m/s² is outside {lo}..{hi} m/s² (0 turns gravity off; check the unit)",
                show_number(m)
            )
        }),
    );
}
