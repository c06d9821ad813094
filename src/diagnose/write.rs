//! Writing the machine file with the accepted effects added.
//!
//! Effects the machine-file format has a key for are added to the values of
//! that key: robot actual DH (`actual`, created from `nominal` when absent),
//! joint stiffness (`k_nm_per_rad`), TCP (`flange_to_tool`), payload
//! (`tool_load`), Paper B thermal growth (`thermal.terms`, see below);
//! machine-tool location errors, component tables (linear/quadratic terms;
//! backlash = offset of the reverse column), axis compliance (every value
//! of the direction's `stiffness.k_n_per_um` map, both load signs,
//! `k' = 1/(1/k + c)`; only when the file has that section) and spindle
//! thermal growth with power (`thermal.spindle.growth_um_per_kw`). The
//! others (spindle growth with time alone, robot joint backlash, axis
//! stiffness without a `stiffness:` section, measurement-frame
//! registration) are listed as not written.
//!
//! Thermal growth is written as text (comments kept), adding the section or
//! the term when absent:
//! - robot: the linearised growth `g` µm/W of a DH length with a joint's
//!   power becomes the Paper B term `ub − lb·e^(−ts·P)` with slope `g` at
//!   0 W that saturates: `ts = x/P_max` ([`saturation_x`], `P_max` the
//!   highest power of that joint in the rows) keeps it within
//!   [`LINEAR_WITHIN`] of the straight line over the powers the data cover,
//!   and `lb = ub = g·10⁻³/ts` mm bounds it at any power
//!   ([`paper_b_term`]); `calibrate thermal` refines lb, ub and ts from rows
//!   at several power levels. A file whose section states no
//!   `rated_power_w` (the power the plausibility limit is evaluated to)
//!   gets the rows' highest joint power, marked as assumed. A new section
//!   gets `time_constant_min: 30` (assumed: steady-state rows carry no time
//!   information);
//! - machine tool: the fitted `g` µm/kW is added to
//!   `thermal.spindle.growth_um_per_kw` (a new `spindle:` gets
//!   `idle_w_per_rpm: 0` and an assumed `time_constant_min: 30`).
//!
//! Uncertain parameters (the calibration rule of
//! [`crate::calibrate::honesty`], on the added value) are not added unless
//! asked for ([`withhold_uncertain`]).
//!
//! Each accepted effect becomes a list of typed edits of the file's values
//! (`Edit::Robot(RobotParam, v)`, `Edit::Tool(ToolParam, v)`, a whole
//! component table, a new thermal term, a header comment per effect),
//! applied by the one machine-file writer ([`crate::machine::yaml_write`]),
//! which edits the text in place so comments and layout are kept (other
//! layouts: by key path on the document's values); a key the file does
//! not have yet (a location error, `actual`, `tool_load` — at the TCP, as
//! the payload candidate assumes) is added where it belongs.

use super::Found;
use super::effects::{Action, DhField, dh_param, round9, tool_edits};
use crate::calibrate::honesty::{Rule, relative_uncertainty};
use crate::calibrate::lsq::COVERAGE_K;
use crate::calibrate::observations::{Observation, Pose};
use crate::calibrate::report::{Estimate, FitCovariance};
use crate::error::{Error, Result};
use crate::machine::Machine;
use crate::machine::robot::{Robot, RobotParam};
use crate::machine::tool::ToolParam;
use crate::machine::yaml_write::{self, Edit, ThermalTermText, round_sig, round_to};

/// `ts_per_w` of a Paper B term written for a linear growth when the rows
/// give no power range, 1/W.
pub const LINEAR_TS_PER_W: f64 = 1e-6;

/// Largest shortfall of a written Paper B term from the straight line of
/// its fitted slope over the powers the rows cover (fraction).
pub const LINEAR_WITHIN: f64 = 0.02;

/// `x = ts·P_max` at which the saturating growth `(1 − e^(−x))/x` of a term
/// with slope 1 at 0 W has fallen [`LINEAR_WITHIN`] below the line (≈ 0.0405;
/// bisection, the ratio falls monotonically in x).
pub fn saturation_x() -> f64 {
    let ratio = |x: f64| -(-x).exp_m1() / x;
    let (mut lo, mut hi) = (1e-9, 1.0);
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if ratio(mid) > 1.0 - LINEAR_WITHIN {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

const ASSUMED_RATED: &str = "postproc diagnose: rated_power_w is ASSUMED: the highest joint power in the observations; the plausibility limit of every thermal term is evaluated from 0 to it (set the motors' rated power)";

/// Decimals of the thermal lengths and gains written (mm, µm/kW).
const THERMAL_DECIMALS: usize = 6;

/// Time constant written into a new thermal section, min (assumed).
pub const ASSUMED_TIME_CONSTANT_MIN: f64 = 30.0;

const ASSUMED_TAU: &str = "postproc diagnose: time_constant_min is ASSUMED (rows at the thermal steady state carry no time information)";

/// Highest power of joint `j` in `rows`, W (`None`: none above 0).
fn max_power_w(rows: &[Observation], j: usize) -> Option<f64> {
    rows.iter()
        .filter_map(|r| match &r.pose {
            Pose::Robot(rp) => rp.p_w.get(j).copied().flatten(),
            Pose::Tool(_) => None,
        })
        .filter(|p| p.is_finite() && *p > 0.0)
        .max_by(f64::total_cmp)
}

/// The Paper B term `ub − lb·e^(−ts·P)` of a linearised growth `g` µm/W
/// whose rows cover joint powers up to `p_max_w`: slope `g` at 0 W,
/// saturating so that it stays within [`LINEAR_WITHIN`] of the line up to
/// `p_max_w` (`ts = x/p_max_w`, [`saturation_x`]) and bounded by
/// `lb = ub = g·10⁻³/ts` mm at any power; without a power range, the
/// nearly linear [`LINEAR_TS_PER_W`]. Returns `(lb = ub, ts)`.
pub fn paper_b_term(g_um_per_w: f64, p_max_w: Option<f64>) -> (f64, f64) {
    let ts = round_sig(p_max_w.map_or(LINEAR_TS_PER_W, |p| saturation_x() / p));
    let amp = round_to(round9(g_um_per_w * 1e-3 / ts), THERMAL_DECIMALS);
    (amp, ts)
}

/// The edit that writes a thermal effect; `rows`: the observations (their
/// power range shapes a robot term).
fn thermal_edit(action: &Action, v0: f64, m: &Machine, rows: &[Observation]) -> Result<Edit> {
    let edit = match (action, m) {
        (
            Action::Thermal {
                joint,
                field,
                power,
            },
            Machine::Robot(_),
        ) => {
            let l = match field {
                DhField::A => 'a',
                _ => 'd',
            };
            let (amp, ts) = paper_b_term(v0, max_power_w(rows, *power));
            let term = ThermalTermText {
                parameter: format!("{l}{}", joint + 1),
                joint: power + 1,
                lb_mm: amp,
                ub_mm: amp,
                ts_per_w: ts,
            };
            Edit::ThermalTerm {
                term,
                time_constant_min: ASSUMED_TIME_CONSTANT_MIN,
                comment: ASSUMED_TAU.into(),
            }
        }
        (Action::SpindlePower, Machine::Tool(t)) => {
            let spindle = t.thermal().and_then(|th| th.spindle);
            let old = spindle.map_or(0.0, |s| s.gain_per_kw);
            let growth = round_to(round9(old + v0), THERMAL_DECIMALS);
            match spindle {
                Some(_) => Edit::Tool(ToolParam::SpindleGrowth, growth),
                None => Edit::Spindle {
                    growth_um_per_kw: growth,
                    time_constant_min: ASSUMED_TIME_CONSTANT_MIN,
                    comment: ASSUMED_TAU.into(),
                },
            }
        }
        _ => {
            return Err(Error::Internal(
                "this effect is not written into the thermal section".into(),
            ));
        }
    };
    Ok(edit)
}

fn is_thermal(action: &Action) -> bool {
    matches!(action, Action::Thermal { .. } | Action::SpindlePower)
}

/// The new machine file and what went into it.
#[derive(Debug, Clone)]
pub struct Written {
    /// YAML text.
    pub text: String,
    /// Names of the effects written.
    pub written: Vec<String>,
    /// Effects not written, with the reason.
    pub not_written: Vec<(String, String)>,
}

/// The edits of the robot file that add the fitted values `p` (display
/// units) of an effect to the file's values.
fn robot_edits(r: &Robot, action: &Action, p: &[f64]) -> Result<Vec<Edit>> {
    let v0 = p.first().copied().unwrap_or(0.0);
    let value = |param: RobotParam| {
        r.param_value(param).ok_or_else(|| {
            Error::Internal(format!("validated robot file without {}", param.path()))
        })
    };
    let added = |param: RobotParam, add: f64| -> Result<Edit> {
        Ok(Edit::Robot(param, round9(value(param)? + add)))
    };
    Ok(match action {
        Action::Dh(j, f) => {
            let (param, add) = dh_param(*j, *f, v0);
            vec![added(param, add)?]
        }
        Action::Compliance(j) => {
            let param = RobotParam::JointStiffness { joint: *j };
            let old = value(param)?;
            // Compliance in rad/(N·m) is 1/k; the fitted addition is µrad/(N·m).
            let new = 1.0 / (1.0 / old + v0 * 1e-6);
            if !(new.is_finite() && new > 0.0) {
                return Err(Error::Data(format!(
                    "the fitted joint {} compliance {v0} µrad/(N·m) gives a non-positive \
                     stiffness: the data ask for a stiffer joint than any the file can hold",
                    j + 1
                )));
            }
            vec![Edit::Robot(param, (new * 1000.0).round() / 1000.0)]
        }
        Action::Tcp => p
            .iter()
            .take(3)
            .enumerate()
            .map(|(axis, v)| added(RobotParam::ToolOffset { axis }, v * 1e-3))
            .collect::<Result<_>>()?,
        Action::Payload => vec![added(RobotParam::PayloadMass, v0)?],
        _ => {
            return Err(Error::Internal(
                "this effect has no key in the robot file".into(),
            ));
        }
    })
}

/// Writes `found` into the machine file text (thermal terms without the
/// rows' power range: [`write_model_for`]).
pub fn write_model(machine: &Machine, machine_text: &str, found: &[Found]) -> Result<Written> {
    write_model_for(machine, machine_text, found, &[])
}

/// Writes `found`, fitted on `rows`, into the machine file text. A robot
/// thermal term is shaped by the powers the rows cover ([`paper_b_term`]);
/// a robot file whose `thermal` section states no `rated_power_w` gets the
/// highest joint power of the rows, marked as assumed.
pub fn write_model_for(
    machine: &Machine,
    machine_text: &str,
    found: &[Found],
    rows: &[Observation],
) -> Result<Written> {
    let mut written = Vec::new();
    let mut not_written = Vec::new();
    let mut edits = Vec::new();
    let mut thermal = Vec::new();
    for f in found {
        if let Some(why) = &f.effect.not_writable {
            not_written.push((f.effect.name.clone(), why.clone()));
            continue;
        }
        let values: Vec<f64> = f.params.iter().map(|p| p.value).collect();
        let v0 = values.first().copied().unwrap_or(0.0);
        if is_thermal(&f.effect.action) {
            thermal.push(thermal_edit(&f.effect.action, v0, machine, rows)?);
        } else {
            edits.extend(match machine {
                Machine::Robot(r) => robot_edits(r, &f.effect.action, &values)?,
                Machine::Tool(t) => tool_edits(&f.effect.action, v0, t)?,
            });
        }
        written.push(f.effect.name.clone());
    }
    for f in found {
        let vals: Vec<String> = f
            .params
            .iter()
            .map(|p| format!("{} = {:.4} ± {:.4}", p.name, p.value, p.u))
            .collect();
        let state = if written.contains(&f.effect.name) {
            "added"
        } else {
            "NOT written (no key in the file format)"
        };
        edits.push(Edit::HeaderComment(format!(
            "postproc diagnose: {} {state}: {}",
            f.effect.name,
            vals.join(", ")
        )));
    }
    if let (Machine::Robot(r), false) = (machine, thermal.is_empty()) {
        let stated = r.thermal().and_then(|t| t.rated_power_w);
        let highest = (0..6)
            .filter_map(|j| max_power_w(rows, j))
            .max_by(f64::total_cmp);
        if let (None, Some(p)) = (stated, highest) {
            thermal.push(Edit::RatedPower {
                watts: p.ceil(),
                comment: ASSUMED_RATED.into(),
            });
        }
    }
    edits.extend(thermal);
    let text = yaml_write::apply(machine_text, "(machine file)", "postproc diagnose", &edits)?;
    // The written file must load.
    Machine::from_yaml_str(&text, "(model that was to be written)")?;
    Ok(Written {
        text,
        written,
        not_written,
    })
}

/// A value of the written file that an effect's fitted parameter moved.
#[derive(Debug, Clone, PartialEq)]
pub struct WrittenKey {
    /// Index of the parameter in the effect's list.
    pub param: usize,
    /// Key path of the value (`axes[Y].location_errors.EC0Y_urad`).
    pub path: String,
    /// Change of the value per unit of the parameter (the key's unit per
    /// display unit): the slope of the written map, at the written value
    /// where it is not linear (a stiffness from a compliance).
    pub per_unit: f64,
}

/// The values `written` (the model read from the written file) holds for
/// the written effect `f`, fitted on `machine` (the model it was written
/// from), with their slopes ([`WrittenKey`]). `thermal_term` is the index
/// of the robot thermal term a thermal effect appended. Values no key path
/// names alone (the cells of a stiffness grid) are not listed.
fn written_keys(
    machine: &Machine,
    written: &Machine,
    f: &Found,
    thermal_term: usize,
) -> Result<Vec<WrittenKey>> {
    use super::effects::{location_param, slot_of};
    let key = |param: usize, p: String, per_unit: f64| WrittenKey {
        param,
        path: p,
        per_unit,
    };
    let mut out = Vec::new();
    match (&f.effect.action, machine, written) {
        (Action::Dh(j, field), _, _) => {
            let (p, per) = dh_param(*j, *field, 1.0);
            out.push(key(0, p.path(), per));
        }
        (Action::Compliance(j), _, Machine::Robot(w)) => {
            // k' = 1/(1/k + c·10⁻⁶): dk'/dc = −k'²·10⁻⁶.
            let p = RobotParam::JointStiffness { joint: *j };
            let k = w.param_value(p).unwrap_or(0.0);
            out.push(key(0, p.path(), -k * k * 1e-6));
        }
        (Action::Tcp, _, _) => {
            for axis in 0..3 {
                out.push(key(axis, RobotParam::ToolOffset { axis }.path(), 1e-3));
            }
        }
        (Action::Payload, _, _) => out.push(key(0, RobotParam::PayloadMass.path(), 1.0)),
        (Action::Thermal { .. }, _, Machine::Robot(w)) => {
            // lb = ub = g·10⁻³/ts with ts fixed by the rows' powers.
            let ts = RobotParam::Thermal {
                term: thermal_term,
                field: crate::machine::robot::ThermalField::Ts,
            };
            let ts = w.param_value(ts).filter(|t| *t > 0.0);
            if let Some(ts) = ts {
                for field in [
                    crate::machine::robot::ThermalField::Lb,
                    crate::machine::robot::ThermalField::Ub,
                ] {
                    let p = RobotParam::Thermal {
                        term: thermal_term,
                        field,
                    };
                    out.push(key(0, p.path(), 1e-3 / ts));
                }
            }
        }
        (Action::SpindlePower, _, _) => out.push(key(0, ToolParam::SpindleGrowth.path(), 1.0)),
        (Action::Location { axis, key: k }, _, _) => {
            let per = if k.ends_with("_mm") { 1e-3 } else { 1.0 };
            out.push(key(0, location_param(*axis, k)?.path(), per));
        }
        (
            Action::Component {
                axis,
                key: k,
                power,
            },
            Machine::Tool(t),
            Machine::Tool(w),
        ) => {
            let slot = slot_of(*axis)?;
            let error = slot_of(k.chars().nth(1).unwrap_or('?'))?;
            let (lo, hi) = t.axis(slot).map_or((0.0, 0.0), |a| a.travel);
            let mid = 0.5 * (lo + hi);
            let half = 0.5 * (hi - lo);
            let [pos, _, _] = w.component_table(slot, error).unwrap_or_default();
            for forward in [true, false] {
                for (node, q) in pos.iter().enumerate() {
                    let p = ToolParam::Component {
                        axis: slot,
                        error,
                        node,
                        forward,
                    };
                    let per = if half > 0.0 {
                        ((q - mid) / half).powi(*power)
                    } else {
                        0.0
                    };
                    out.push(key(0, p.path(), per));
                }
            }
        }
        (Action::AxisBacklash { axis, key: k }, _, Machine::Tool(w)) => {
            let slot = slot_of(*axis)?;
            let error = slot_of(k.chars().nth(1).unwrap_or('?'))?;
            let [pos, _, _] = w.component_table(slot, error).unwrap_or_default();
            for node in 0..pos.len() {
                let p = ToolParam::Component {
                    axis: slot,
                    error,
                    node,
                    forward: false,
                };
                out.push(key(0, p.path(), 1.0));
            }
        }
        (Action::AxisStiffness(slot), _, Machine::Tool(w)) => {
            // k' = 1/(1/k + c): dk'/dc = −k'²; a grid's cells share a path.
            for positive in [true, false] {
                for p in w.stiffness_params(*slot, positive) {
                    if let (ToolParam::Stiffness { cell: None, .. }, Some(k)) =
                        (p, w.param_value(p))
                    {
                        out.push(key(0, p.path(), -k * k));
                    }
                }
            }
        }
        _ => {}
    }
    Ok(out)
}

/// The covariance of the values written for the effects `kept` (as
/// [`withhold_uncertain`] left them; those named in `written` were
/// written) from the covariance `cov` of the fitted parameters of `all`
/// (the diagnosis's effects, their parameters in turn): each value's
/// change is its [`WrittenKey::per_unit`] slope times its parameter's, so
/// the block is `S cov Sᵀ` on the values' key paths, in their keys' units.
/// Parameters withheld as uncertain and values no parameter moves are not
/// in it. `machine` is the model written from, `model` the model read
/// from the written file. `None` when nothing written is in it.
pub fn written_covariance(
    machine: &Machine,
    model: &Machine,
    all: &[Found],
    kept: &[Found],
    written: &[String],
    cov: &nalgebra::DMatrix<f64>,
) -> Result<Option<FitCovariance>> {
    let mut thermal_term = match machine {
        Machine::Robot(r) => (0..)
            .take_while(|&term| {
                r.param_value(RobotParam::Thermal {
                    term,
                    field: crate::machine::robot::ThermalField::Lb,
                })
                .is_some()
            })
            .count(),
        Machine::Tool(_) => 0,
    };
    let mut cols = Vec::new();
    for f in kept.iter().filter(|f| written.contains(&f.effect.name)) {
        let Some(at) = all.iter().position(|a| a.effect.name == f.effect.name) else {
            continue;
        };
        let offset: usize = all.iter().take(at).map(|a| a.params.len()).sum();
        let keys = written_keys(machine, model, f, thermal_term)?;
        if matches!(
            (&f.effect.action, machine),
            (Action::Thermal { .. }, Machine::Robot(_))
        ) {
            thermal_term += 1;
        }
        for k in keys {
            let withheld = f
                .params
                .get(k.param)
                .is_none_or(|p| p.name.ends_with(WITHHELD));
            if !withheld && k.per_unit != 0.0 && k.per_unit.is_finite() {
                cols.push((offset + k.param, k.path, k.per_unit));
            }
        }
    }
    Ok(FitCovariance::select(Some(cov), &cols))
}

/// The suffix [`withhold_uncertain`] gives the name of a parameter it
/// withheld.
const WITHHELD: &str = "(uncertain, not added)";

/// The unit of a fitted parameter's name (`dx [µm]` → `µm`), for the
/// length floor of [`honesty`]; empty when it is not a length.
fn length_unit(name: &str) -> &'static str {
    let unit = name
        .rsplit_once('[')
        .and_then(|(_, u)| u.strip_suffix(']'))
        .unwrap_or("");
    match unit {
        "µm" => "µm",
        "mm" => "mm",
        _ => "",
    }
}

/// Applies the calibration honesty rule ([`crate::calibrate::honesty`]) to the accepted
/// effects before they are written: an uncertain parameter is not added
/// (its value becomes 0, the file keeps its value), an effect whose every
/// parameter is uncertain is left out. Returns the effects to write and,
/// per parameter withheld, the effect's name and why.
pub fn withhold_uncertain(
    machine: &Machine,
    found: &[Found],
    rule: &Rule,
) -> (Vec<Found>, Vec<(String, String)>) {
    let mut kept = Vec::with_capacity(found.len());
    let mut withheld = Vec::new();
    for f in found {
        let mut f = f.clone();
        let mut n_uncertain = 0;
        for p in &mut f.params {
            let est = Estimate {
                name: p.name.clone(),
                unit: length_unit(&p.name),
                start: 0.0,
                value: p.value,
                u: Some(p.u),
                fixed: false,
            };
            if rule.withholds(&est) {
                n_uncertain += 1;
                let ratio = relative_uncertainty(&est).unwrap_or(f64::INFINITY);
                withheld.push((
                    f.effect.name.clone(),
                    format!(
                        "{} = {:.4} ± {:.4} (U(k=2) = {:.1} % of the value) is uncertain; \
                         not added (--write-uncertain adds it)",
                        p.name,
                        p.value,
                        COVERAGE_K * p.u,
                        100.0 * ratio
                    ),
                ));
                p.value = 0.0;
                p.name = format!("{} {WITHHELD}", p.name);
            }
        }
        // Thermal and machine-tool effects write their first parameter only.
        let first_withheld = f.params.first().is_some_and(|p| p.name.ends_with(WITHHELD));
        let first_only = is_thermal(&f.effect.action) || matches!(machine, Machine::Tool(_));
        if n_uncertain < f.params.len() && !(first_withheld && first_only) {
            kept.push(f);
        }
    }
    (kept, withheld)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::effects::library;
    use crate::diagnose::{Found, Param};
    use approx::assert_abs_diff_eq;

    /// Written stiffness tolerance, N·m/rad (the file keeps 3 decimals).
    const K_TOL: f64 = 1e-3;
    /// Written length tolerance, mm (values are rounded to 1e-9).
    const LEN_TOL: f64 = 1e-9;
    /// Written angle tolerance, rad.
    const ANGLE_TOL: f64 = 1e-12;

    fn found(m: &Machine, name: &str, values: &[f64]) -> Found {
        let lib = library(m, &[]);
        let e = lib.into_iter().find(|e| e.name == name).expect("effect");
        Found {
            params: values
                .iter()
                .map(|v| Param {
                    name: "p".into(),
                    value: *v,
                    u: 0.0,
                })
                .collect(),
            effect: e,
            bootstrap: 1.0,
        }
    }

    /// Joint 3 compliance +1 µrad/(N·m): k = 1/(1/140940 + 1e-6)
    /// = 1/(7.09522e-6 + 1e-6) = 123529.721 N·m/rad. TCP +0.4 mm in x.
    #[test]
    fn robot_keys_written() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/machines/abb-irb1600.yaml");
        let text = std::fs::read_to_string(path).unwrap();
        let m = Machine::from_yaml_str(&text, "m").unwrap();
        let w = write_model(
            &m,
            &text,
            &[
                found(&m, "joint3_compliance", &[1.0]),
                found(&m, "tcp_offset", &[400.0, 0.0, 0.0]),
            ],
        )
        .unwrap();
        assert!(w.text.starts_with("# ABB IRB 1600"));
        let Machine::Robot(r) = Machine::from_yaml_str(&w.text, "w").unwrap() else {
            panic!("robot")
        };
        assert_abs_diff_eq!(r.k_nm_per_rad()[2], 123529.721, epsilon = K_TOL);
        assert_abs_diff_eq!(
            r.flange_to_tool().translation.vector.x,
            0.4,
            epsilon = LEN_TOL
        );
        assert_eq!(w.written, vec!["joint3_compliance", "tcp_offset"]);
        assert!(
            text.lines()
                .filter(|l| l.trim_start().starts_with('#'))
                .all(|l| w.text.contains(l)),
            "comments kept: {}",
            w.text
        );
        assert!(w.text.contains("# Paper C Table 6"), "comments kept");
        assert!(
            w.text
                .contains("k_nm_per_rad: [270990.0, 430040.0, 123529.721,")
        );
    }

    fn effect(m: &Machine, name: &str, action: Action, value: f64) -> Found {
        let mut f = found(
            m,
            if matches!(m, Machine::Robot(_)) {
                "joint3_compliance"
            } else {
                "EC0Y"
            },
            &[value],
        );
        f.effect.name = name.into();
        f.effect.action = action;
        f
    }

    /// Robot thermal growth a3 ← P2, 0.3 µm/W: the Paper B term with
    /// ts = 1e-6/W and lb = ub = 0.3e-3/1e-6 = 300 mm. At P2 = 100 W it grows
    /// a3 by 300·(1 − e^(−1e-4)) = 300·(1e-4 − 5e-9) = 0.0299985 mm (≈ 0.3 ×
    /// 100 µm). Machine-tool spindle growth +8 µm/kW: 3.0 → 11.0 in the
    /// one-line `spindle:` map.
    #[test]
    fn thermal_written_into_the_section() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/machines/abb-irb1600.yaml");
        let text = std::fs::read_to_string(path).unwrap();
        let m = Machine::from_yaml_str(&text, "m").unwrap();
        let a = Action::Thermal {
            joint: 2,
            field: DhField::A,
            power: 1,
        };
        let w = write_model(&m, &text, &[effect(&m, "thermal_joint3_a_p2", a, 0.3)]).unwrap();
        assert!(
            text.lines()
                .filter(|l| l.trim_start().starts_with('#'))
                .all(|l| w.text.contains(l)),
            "comments kept: {}",
            w.text
        );
        assert_eq!(w.written, vec!["thermal_joint3_a_p2"]);
        assert!(
            w.text.contains(
                "    - { parameter: a3, joint: 2, lb_mm: 300.0, ub_mm: 300.0, ts_per_w: 0.000001 }\n"
            ),
            "{}",
            w.text
        );
        let Machine::Robot(r) = Machine::from_yaml_str(&w.text, "w").unwrap() else {
            panic!("robot")
        };
        let g = r.thermal_growth_mm(&[0.0, 100.0, 0.0, 0.0, 0.0, 0.0]);
        let Machine::Robot(r0) = &m else {
            panic!("robot")
        };
        let g0 = r0.thermal_growth_mm(&[0.0, 100.0, 0.0, 0.0, 0.0, 0.0]);
        assert_abs_diff_eq!(g[2][0] - g0[2][0], 0.0299985, epsilon = 1e-9);

        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/machines/afm-r1000.yaml");
        let text = std::fs::read_to_string(path).unwrap();
        let m = Machine::from_yaml_str(&text, "m").unwrap();
        let w = write_model(
            &m,
            &text,
            &[effect(
                &m,
                "spindle_growth_power",
                Action::SpindlePower,
                8.0,
            )],
        )
        .unwrap();
        assert!(w.text.contains(
            "  spindle: { idle_w_per_rpm: 0.2, growth_um_per_kw: 11.0, time_constant_min: 25.0 }"
        ));
        let Machine::Tool(t) = Machine::from_yaml_str(&w.text, "w").unwrap() else {
            panic!("tool")
        };
        let gain = t.thermal().and_then(|th| th.spindle).map(|s| s.gain_per_kw);
        assert_eq!(gain, Some(11.0));
    }

    /// Squareness EC0Y 35 + 40 = 75 µrad; robot-only effects are refused
    /// for a machine tool and thermal ones are listed as not written.
    #[test]
    fn tool_location_written() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/machines/afm-r1000.yaml");
        let text = std::fs::read_to_string(path).unwrap();
        let m = Machine::from_yaml_str(&text, "m").unwrap();
        let w = write_model(&m, &text, &[found(&m, "EC0Y", &[40.0])]).unwrap();
        let Machine::Tool(t) = Machine::from_yaml_str(&w.text, "w").unwrap() else {
            panic!("tool")
        };
        let y = t.axis(1).expect("Y axis");
        assert_abs_diff_eq!(y.location.angles_rad.z, 75e-6, epsilon = ANGLE_TOL);
        assert!(
            text.lines()
                .filter(|l| l.trim_start().starts_with('#'))
                .all(|l| w.text.contains(l)),
            "comments kept: {}",
            w.text
        );
        assert!(w.text.contains("      EC0Y_urad: 75.0\n"));
        assert!(w.text.contains("# Structure: X is carried by Y"));
        // A backlash edits the X positioning table's columns in place.
        let mut f = found(&m, "EC0Y", &[8.0]);
        f.effect.name = "X_backlash".into();
        f.effect.action = crate::diagnose::effects::Action::AxisBacklash {
            axis: 'X',
            key: "EXX_um".into(),
        };
        let w = write_model(&m, &text, &[f]).unwrap();
        assert!(
            text.lines()
                .filter(|l| l.trim_start().starts_with('#'))
                .all(|l| w.text.contains(l)),
            "comments kept: {}",
            w.text
        );
        assert!(w.text.contains("reverse: [11.0, "), "{}", w.text);
    }
}
