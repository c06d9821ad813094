//! Validation of a raw machine-tool file into a [`MachineTool`]: every value
//! is checked (finite, ordered, plausible magnitude, allowed name) and a
//! failure names the YAML key path and line.

use std::collections::BTreeMap;

use nalgebra::Vector3;

use super::component::ComponentErrors;
use super::location::{
    LocationErrors, LocationKey, SpindleErrors, component_key, location_key, spindle_key,
};
use super::raw::{
    RawAxis, RawAxisType, RawCornerWords, RawIntegerWords, RawMachineTool, RawMeasurementFrame,
    RawOutput, RawProcessForce, RawSide, RawSpindle, RawTable, RawTool, RawUnits,
};
use super::table::ErrorTable;
use super::{Axis, AxisKind, ControlDefaults, MachineTool, Side};
use crate::error::{Invalid, Result};
use crate::machine::{axis_slot, yaml};
use crate::process::{Drilling, ForceModel, Frame, Milling};

/// Largest accepted translational error, mm.
const MAX_ERROR_MM: f64 = 1.0;
/// Largest accepted angular error, rad.
const MAX_ERROR_RAD: f64 = 0.01;
/// Largest accepted `output.decimals_mm`.
const MAX_DECIMALS: usize = 9;

type V<T> = std::result::Result<T, Invalid>;

/// A magnitude check of one value in internal units.
type Check = fn(&str, f64) -> V<f64>;

/// Validates a machine-tool file read by [`yaml::Source::read`].
pub(crate) fn load(src: &yaml::Source) -> Result<MachineTool> {
    let (text, file) = (src.text(), src.file());
    let raw: RawMachineTool = src.deserialize()?;
    let m = validate(raw).map_err(|inv| locate_invalid(text, file, inv))?;
    // The values accepted through `plausibility:` overrides.
    for w in super::plausible::check(&m.raw).unwrap_or_default() {
        tracing::warn!("{}", locate_invalid(text, file, w));
    }
    Ok(m)
}

/// Like [`yaml::invalid`], but when the full key path cannot be found in the
/// text (a value inside a flow mapping such as `{ length_mm: -5 }`), points
/// at the deepest enclosing key that can be found.
fn locate_invalid(text: &str, file: &str, inv: Invalid) -> crate::error::Error {
    let mut prefix: &str = &inv.path;
    loop {
        if let Some((line, column)) = yaml::locate(text, prefix) {
            return crate::error::Error::Machine(crate::error::Located::new(
                file,
                line,
                column,
                format!("{}: {}", inv.path, inv.message),
            ));
        }
        match prefix.rfind(['.', '[']) {
            Some(cut) if cut > 0 => prefix = &prefix[..cut],
            _ => return yaml::invalid(text, file, inv),
        }
    }
}

/// A compensation tolerance ([`crate::limits::tolerance_mm`]).
fn tolerance(path: &str, v: f64) -> V<f64> {
    crate::limits::tolerance_mm(v).map_err(|m| Invalid::new(path, m))
}

fn finite(path: &str, v: f64) -> V<f64> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(Invalid::new(
            path,
            format!("value `{v}` is not a finite number"),
        ))
    }
}

/// Largest magnitude of a position, length or speed of a machine-tool file
/// (mm, deg, mm/min, deg/min): beyond every real machine, so that an
/// absurd value is an error rather than an infinity later on. (Errors and
/// stiffnesses have limits of their own.)
const MAX_PLAUSIBLE: f64 = 1e7;

/// [`finite`] and within ±[`MAX_PLAUSIBLE`].
fn plausible(path: &str, v: f64) -> V<f64> {
    let v = finite(path, v)?;
    if v.abs() > MAX_PLAUSIBLE {
        return Err(Invalid::new(
            path,
            format!(
                "value `{}` is beyond ±{} (not a plausible value)",
                crate::error::show_number(v),
                crate::error::show_number(MAX_PLAUSIBLE)
            ),
        ));
    }
    Ok(v)
}

pub(super) fn validate(raw: RawMachineTool) -> V<MachineTool> {
    validate_with(raw, Plausibility::Checked)
}

/// Whether [`validate_with`] checks the plausibility of the values
/// (`plausible.rs`): a file and a parameter set by key are checked, a fit's
/// trial step is not (its result is, once, at the edge).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Plausibility {
    /// Checked.
    Checked,
    /// Not checked.
    Unchecked,
}

/// [`validate`], with the plausibility check as `plausibility` says.
pub(super) fn validate_with(raw: RawMachineTool, plausibility: Plausibility) -> V<MachineTool> {
    if raw.kind != "machine_tool" {
        return Err(Invalid::new(
            "kind",
            format!("expected `machine_tool`, found `{}`", raw.kind),
        ));
    }
    if raw.name.trim().is_empty() {
        return Err(Invalid::new("name", "the machine name is empty"));
    }
    let (mut axes, slot_index) = validate_axes(&raw.axes)?;
    let n_workpiece = axes.iter().filter(|a| a.side == Side::Workpiece).count();
    let spindle = validate_spindle(raw.spindle.as_ref())?;
    let tools = validate_tools(&raw.tools)?;
    let work_offsets = validate_work_offsets(&raw.work_offsets_mm)?;
    let reference_points = validate_reference_points(&raw.reference_points_mm)?;
    let units_default = raw.units_default.map(|u| match u {
        RawUnits::Mm => super::Units::Mm,
        RawUnits::Inch => super::Units::Inch,
    });
    let integer_words = raw.integer_words.map(|w| match w {
        RawIntegerWords::Units => super::IntegerWords::Units,
        RawIntegerWords::Increments => super::IntegerWords::Increments,
    });
    let corner_words = raw.corner_words.map(|w| match w {
        RawCornerWords::Comma => super::CornerWords::Comma,
    });
    let (decimals, decimals_deg) = validate_decimals(raw.output.as_ref())?;

    let tolerance_mm = raw
        .compensation
        .as_ref()
        .and_then(|c| c.tolerance_mm)
        .map(|t| tolerance("compensation.tolerance_mm", t))
        .transpose()?;

    let process_force = raw.process_force.as_ref().map(validate_force).transpose()?;
    let stiffness = raw
        .stiffness
        .as_ref()
        .map(super::stiffness::Stiffness::from_raw)
        .transpose()?;
    let thermal = raw
        .thermal
        .as_ref()
        .map(|t| super::thermal::Thermal::from_raw(t, |s| slot_index[s].is_some()))
        .transpose()?;
    let modal = raw
        .modal
        .as_ref()
        .map(super::dynamics::modal_from_raw)
        .transpose()?;

    let measurement_frame = raw
        .measurement_frame
        .as_ref()
        .map(validate_measurement_frame)
        .transpose()?;
    let error_free = spindle.is_zero()
        && axes
            .iter()
            .all(|a| a.location.is_zero() && a.components.is_zero());
    if plausibility == Plausibility::Checked {
        super::plausible::check(&raw)?;
    }
    super::set_breakpoints(&mut axes, stiffness.as_ref());
    let pre = Box::new(super::fast::Precomputed::new(&axes, spindle));
    Ok(MachineTool {
        pre,
        name: raw.name.clone(),
        axes,
        n_workpiece,
        slot_index,
        tools,
        work_offsets,
        control: Box::new(ControlDefaults {
            reference_points,
            units_default,
            integer_words,
            corner_words,
            tolerance_mm,
            expand_deep_holes: raw
                .output
                .as_ref()
                .and_then(|o| o.expand_deep_holes_to_moves)
                .unwrap_or(false),
        }),
        decimals,
        decimals_deg,
        error_free,
        measurement_frame: measurement_frame.map(Box::new),
        process: (process_force.is_some()
            || stiffness.is_some()
            || thermal.is_some()
            || modal.is_some())
        .then(|| {
            Box::new(super::ProcessSections {
                force: process_force,
                stiffness,
                thermal,
                modal,
            })
        }),
        raw: std::sync::Arc::new(raw),
    })
}

/// The axes in chain order (workpiece side first) and the index of the
/// axis of each slot (X, Y, Z, A, B, C).
fn validate_axes(raw: &[RawAxis]) -> V<(Vec<Axis>, [Option<u8>; 6])> {
    if raw.is_empty() {
        return Err(Invalid::new(
            "axes",
            "a machine tool needs at least one axis",
        ));
    }
    let mut axes: Vec<Axis> = Vec::with_capacity(raw.len());
    let mut slot_index = [None; 6];
    let mut seen_tool_side = false;
    for (i, ra) in raw.iter().enumerate() {
        let p = format!("axes[{i}]");
        let axis = validate_axis(&p, ra)?;
        let Some(entry) = slot_index.get_mut(axis.slot) else {
            return Err(Invalid::new(format!("{p}.name"), "axis slot out of range"));
        };
        if entry.is_some() {
            return Err(Invalid::new(
                format!("{p}.name"),
                format!("duplicate axis `{}`", ra.name),
            ));
        }
        *entry = u8::try_from(i).ok();
        match axis.side {
            Side::Tool => seen_tool_side = true,
            Side::Workpiece if seen_tool_side => {
                return Err(Invalid::new(
                    format!("{p}.side"),
                    "workpiece-side axes must all come before the tool-side axes (chain order: from the workpiece out to the base, then from the base to the spindle)",
                ));
            }
            Side::Workpiece => {}
        }
        axes.push(axis);
    }
    Ok((axes, slot_index))
}

/// `spindle.location_errors`.
fn validate_spindle(raw: Option<&RawSpindle>) -> V<SpindleErrors> {
    let mut spindle = SpindleErrors::default();
    if let Some(s) = raw {
        for (k, v) in &s.location_errors {
            let path = format!("spindle.location_errors.{k}");
            let key = spindle_key(k).map_err(|m| Invalid::new(&path, m))?;
            let v = finite(&path, *v)?;
            match key {
                LocationKey::Offset(t) => spindle.offset_mm[t] = check_mm(&path, v)?,
                LocationKey::Angle(r) => spindle.angles_rad[r] = check_rad(&path, v * 1e-6)?,
                LocationKey::Zero => {}
            }
        }
    }
    Ok(spindle)
}

/// `tools`: the length of each tool, by H number.
fn validate_tools(raw: &BTreeMap<u32, RawTool>) -> V<BTreeMap<u32, f64>> {
    let mut tools = BTreeMap::new();
    for (h, t) in raw {
        let path = format!("tools.{h}.length_mm");
        let l = plausible(&path, t.length_mm)?;
        if l < 0.0 {
            return Err(Invalid::new(path, format!("tool length `{l}` is negative")));
        }
        tools.insert(*h, l);
    }
    Ok(tools)
}

/// `work_offsets_mm`, by code (`G54`, `G54.1P7`, `G154P3`).
fn validate_work_offsets(raw: &BTreeMap<String, [f64; 3]>) -> V<BTreeMap<String, [f64; 3]>> {
    let mut work_offsets = BTreeMap::new();
    for (code, xyz) in raw {
        let path = format!("work_offsets_mm.{code}");
        if !work_offset_key(code) {
            return Err(Invalid::new(
                path,
                format!(
                    "unknown work offset `{code}` (expected G54 … G59, G54.1P1 … G54.1P300 or G154P1 … G154P99)"
                ),
            ));
        }
        for v in xyz {
            plausible(&path, *v)?;
        }
        work_offsets.insert(code.clone(), *xyz);
    }
    Ok(work_offsets)
}

/// `reference_points_mm`, by code (`G30`, `G30P3`, `G30P4`).
fn validate_reference_points(raw: &BTreeMap<String, [f64; 3]>) -> V<BTreeMap<String, [f64; 3]>> {
    let mut reference_points = BTreeMap::new();
    for (code, xyz) in raw {
        let path = format!("reference_points_mm.{code}");
        if !matches!(code.as_str(), "G30" | "G30P3" | "G30P4") {
            return Err(Invalid::new(
                path,
                format!("unknown reference point `{code}` (expected G30, G30P3 or G30P4)"),
            ));
        }
        for v in xyz {
            plausible(&path, *v)?;
        }
        reference_points.insert(code.clone(), *xyz);
    }
    Ok(reference_points)
}

/// `output.decimals_mm` and `output.decimals_deg`.
fn validate_decimals(raw: Option<&RawOutput>) -> V<(Option<usize>, Option<usize>)> {
    let decimals = raw.and_then(|o| o.decimals_mm);
    let decimals_deg = raw.and_then(|o| o.decimals_deg);
    for (key, value) in [
        ("output.decimals_mm", decimals),
        ("output.decimals_deg", decimals_deg),
    ] {
        if let Some(d) = value {
            if d > MAX_DECIMALS {
                return Err(Invalid::new(
                    key,
                    format!("`{d}` decimals is more than {MAX_DECIMALS}"),
                ));
            }
        }
    }
    Ok((decimals, decimals_deg))
}

/// `measurement_frame`: the pose of the measuring instrument's frame.
fn validate_measurement_frame(f: &RawMeasurementFrame) -> V<nalgebra::Isometry3<f64>> {
    let v = [
        f.x_mm,
        f.y_mm,
        f.z_mm,
        f.rpy_deg[0],
        f.rpy_deg[1],
        f.rpy_deg[2],
    ];
    if v.iter().any(|x| !x.is_finite()) {
        return Err(Invalid::new(
            "measurement_frame",
            "every value must be a finite number",
        ));
    }
    let [r, p, y] = f.rpy_deg.map(f64::to_radians);
    Ok(nalgebra::Isometry3::from_parts(
        nalgebra::Translation3::new(f.x_mm, f.y_mm, f.z_mm),
        nalgebra::UnitQuaternion::from_euler_angles(r, p, y),
    ))
}

/// Validates `process_force:`: the keys the model needs must be there, the
/// keys it does not use must not.
fn validate_force(r: &RawProcessForce) -> V<ForceModel> {
    const P: &str = "process_force";
    let given: [(&str, bool); 14] = [
        ("force_n", r.force_n.is_some()),
        ("frame", r.frame.is_some()),
        ("kt_n_per_mm2", r.kt_n_per_mm2.is_some()),
        ("kr_n_per_mm2", r.kr_n_per_mm2.is_some()),
        ("ka_n_per_mm2", r.ka_n_per_mm2.is_some()),
        ("kte_n_per_mm", r.kte_n_per_mm.is_some()),
        ("kre_n_per_mm", r.kre_n_per_mm.is_some()),
        ("kae_n_per_mm", r.kae_n_per_mm.is_some()),
        ("tool_diameter_mm", r.tool_diameter_mm.is_some()),
        ("flutes", r.flutes.is_some()),
        ("axial_depth_mm", r.axial_depth_mm.is_some()),
        ("radial_width_mm", r.radial_width_mm.is_some()),
        (
            "thrust_coefficient_n_per_mm2",
            r.thrust_coefficient_n_per_mm2.is_some(),
        ),
        ("drill_diameter_mm", r.drill_diameter_mm.is_some()),
    ];
    let allowed: &[&str] = match r.model.as_str() {
        "constant" => &["force_n", "frame"],
        "milling" => &[
            "kt_n_per_mm2",
            "kr_n_per_mm2",
            "ka_n_per_mm2",
            "kte_n_per_mm",
            "kre_n_per_mm",
            "kae_n_per_mm",
            "tool_diameter_mm",
            "flutes",
            "axial_depth_mm",
            "radial_width_mm",
        ],
        "drilling" => &["thrust_coefficient_n_per_mm2", "drill_diameter_mm"],
        "table" => {
            return Err(Invalid::new(
                format!("{P}.model"),
                "a force table is given per job with --force-table FILE",
            ));
        }
        other => {
            return Err(Invalid::new(
                format!("{P}.model"),
                format!("unknown model `{other}` (expected constant, milling or drilling)"),
            ));
        }
    };
    for (k, present) in given {
        if present && !allowed.contains(&k) {
            return Err(Invalid::new(
                format!("{P}.{k}"),
                format!("`{k}` is not used by the `{}` model", r.model),
            ));
        }
    }
    let need = |k: &str, v: Option<f64>, lo: f64, hi: f64| -> V<f64> {
        let path = format!("{P}.{k}");
        let v = v.ok_or_else(|| Invalid::new(P, format!("the `{}` model needs `{k}`", r.model)))?;
        let v = finite(&path, v)?;
        if v < lo || v > hi {
            return Err(Invalid::new(path, format!("`{v}` is outside {lo}..{hi}")));
        }
        Ok(v)
    };
    let opt = |k: &str, v: Option<f64>| -> V<f64> {
        match v {
            Some(_) => need(k, v, 0.0, 1e6),
            None => Ok(0.0),
        }
    };
    Ok(match r.model.as_str() {
        "constant" => {
            let f = r
                .force_n
                .ok_or_else(|| Invalid::new(P, "the `constant` model needs `force_n`"))?;
            let path = format!("{P}.force_n");
            for v in f {
                if !v.is_finite() || v.abs() > 1e6 {
                    return Err(Invalid::new(
                        &path,
                        format!("`{v}` is not a force within ±1e6 N"),
                    ));
                }
            }
            let frame = match &r.frame {
                None => Frame::Workpiece,
                Some(s) => Frame::parse(s).ok_or_else(|| {
                    Invalid::new(
                        format!("{P}.frame"),
                        format!("unknown frame `{s}` (expected workpiece, tool or feed)"),
                    )
                })?,
            };
            ForceModel::constant(Vector3::new(f[0], f[1], f[2]), frame)
        }
        "milling" => {
            let d = need("tool_diameter_mm", r.tool_diameter_mm, 0.01, 1000.0)?;
            let flutes = r
                .flutes
                .ok_or_else(|| Invalid::new(P, "the `milling` model needs `flutes`"))?;
            if !(1..=64).contains(&flutes) {
                return Err(Invalid::new(
                    format!("{P}.flutes"),
                    format!("`{flutes}` flutes is outside 1..64"),
                ));
            }
            ForceModel::Milling(Milling {
                kt_n_per_mm2: need("kt_n_per_mm2", r.kt_n_per_mm2, 0.0, 1e5)?,
                kr_n_per_mm2: need("kr_n_per_mm2", r.kr_n_per_mm2, 0.0, 1e5)?,
                ka_n_per_mm2: opt("ka_n_per_mm2", r.ka_n_per_mm2)?,
                kte_n_per_mm: opt("kte_n_per_mm", r.kte_n_per_mm)?,
                kre_n_per_mm: opt("kre_n_per_mm", r.kre_n_per_mm)?,
                kae_n_per_mm: opt("kae_n_per_mm", r.kae_n_per_mm)?,
                tool_diameter_mm: d,
                flutes,
                axial_depth_mm: need("axial_depth_mm", r.axial_depth_mm, 0.0, 1000.0)?,
                radial_width_mm: need("radial_width_mm", r.radial_width_mm, 0.0, d)?,
            })
        }
        _ => ForceModel::drilling(Drilling {
            thrust_coefficient_n_per_mm2: need(
                "thrust_coefficient_n_per_mm2",
                r.thrust_coefficient_n_per_mm2,
                0.0,
                1e5,
            )?,
            drill_diameter_mm: need("drill_diameter_mm", r.drill_diameter_mm, 0.01, 1000.0)?,
        }),
    })
}

fn check_mm(path: &str, v: f64) -> V<f64> {
    if v.abs() > MAX_ERROR_MM {
        return Err(Invalid::new(
            path,
            format!(
                "{} mm exceeds the 1 mm limit of a geometric error (small-deviation model; check the unit)",
                crate::error::show_number(v)
            ),
        ));
    }
    Ok(v)
}

fn check_rad(path: &str, v: f64) -> V<f64> {
    if v.abs() > MAX_ERROR_RAD {
        return Err(Invalid::new(
            path,
            format!(
                "{} µrad exceeds the 10000 µrad (0.01 rad) limit of the small-angle error model (check the unit)",
                crate::error::show_number(v * 1e6)
            ),
        ));
    }
    Ok(v)
}

/// A key of `work_offsets_mm`: `G54`…`G59`, `G54.1P1`…`G54.1P300`,
/// `G154P1`…`G154P99`.
pub(crate) fn work_offset_key(code: &str) -> bool {
    let numbered = |prefix: &str, max: u32| {
        code.strip_prefix(prefix).is_some_and(|n| {
            !n.starts_with('0')
                && n.bytes().all(|c| c.is_ascii_digit())
                && n.parse::<u32>().is_ok_and(|n| (1..=max).contains(&n))
        })
    };
    matches!(code, "G54" | "G55" | "G56" | "G57" | "G58" | "G59")
        || numbered("G54.1P", 300)
        || numbered("G154P", 99)
}

fn validate_axis(p: &str, ra: &RawAxis) -> V<Axis> {
    let slot = match ra.name.as_bytes() {
        [b] => axis_slot(*b),
        _ => None,
    }
    .ok_or_else(|| {
        Invalid::new(
            format!("{p}.name"),
            format!("unknown axis `{}` (expected X, Y, Z, A, B or C)", ra.name),
        )
    })?;
    let kind = match ra.axis_type {
        RawAxisType::Linear => AxisKind::Linear,
        RawAxisType::Rotary => AxisKind::Rotary,
    };
    let expected = if slot < 3 {
        AxisKind::Linear
    } else {
        AxisKind::Rotary
    };
    if kind != expected {
        return Err(Invalid::new(
            format!("{p}.type"),
            format!(
                "axis `{}` must be {}",
                ra.name,
                if slot < 3 { "linear" } else { "rotary" }
            ),
        ));
    }
    let side = match ra.side {
        RawSide::Workpiece => Side::Workpiece,
        RawSide::Tool => Side::Tool,
    };
    let linear = kind == AxisKind::Linear;
    let (unit, travel_key, rapid_key, pos_key) = if linear {
        ("mm", "travel_mm", "rapid_mm_per_min", "positions_mm")
    } else {
        ("deg", "travel_deg", "rapid_deg_per_min", "positions_deg")
    };
    let (travel, wrong_travel) = if linear {
        (ra.travel_mm, ra.travel_deg)
    } else {
        (ra.travel_deg, ra.travel_mm)
    };
    let (rapid, wrong_rapid) = if linear {
        (ra.rapid_mm_per_min, ra.rapid_deg_per_min)
    } else {
        (ra.rapid_deg_per_min, ra.rapid_mm_per_min)
    };
    if wrong_travel.is_some() || wrong_rapid.is_some() {
        let k = if wrong_travel.is_some() {
            if linear { "travel_deg" } else { "travel_mm" }
        } else if linear {
            "rapid_deg_per_min"
        } else {
            "rapid_mm_per_min"
        };
        return Err(Invalid::new(
            format!("{p}.{k}"),
            format!(
                "a {} axis takes values in {unit}",
                if linear { "linear" } else { "rotary" }
            ),
        ));
    }
    let tpath = format!("{p}.{travel_key}");
    let [lo, hi] = travel.ok_or_else(|| Invalid::new(p, format!("missing `{travel_key}`")))?;
    let lo = plausible(&tpath, lo)?;
    let hi = plausible(&tpath, hi)?;
    if lo >= hi {
        return Err(Invalid::new(
            tpath,
            format!("minimum {lo} must be below maximum {hi}"),
        ));
    }
    let rpath = format!("{p}.{rapid_key}");
    let rapid = rapid.ok_or_else(|| Invalid::new(p, format!("missing `{rapid_key}`")))?;
    let rapid = plausible(&rpath, rapid)?;
    if rapid <= 0.0 {
        return Err(Invalid::new(
            rpath,
            format!("rapid rate `{rapid}` must be positive"),
        ));
    }
    let pivot_mm = match (ra.pivot_mm, linear) {
        (Some(_), true) => {
            return Err(Invalid::new(
                format!("{p}.pivot_mm"),
                "`pivot_mm` is only for rotary axes",
            ));
        }
        (Some(v), false) => {
            let path = format!("{p}.pivot_mm");
            Vector3::new(
                plausible(&path, v[0])?,
                plausible(&path, v[1])?,
                plausible(&path, v[2])?,
            )
        }
        (None, _) => Vector3::zeros(),
    };

    let mut location = LocationErrors::default();
    for (k, v) in &ra.location_errors {
        let path = format!("{p}.location_errors.{k}");
        let key = location_key(slot, k).map_err(|m| Invalid::new(&path, m))?;
        let v = finite(&path, *v)?;
        match key {
            LocationKey::Offset(t) => location.offset_mm[t] = check_mm(&path, v)?,
            LocationKey::Angle(r) => location.angles_rad[r] = check_rad(&path, v * 1e-6)?,
            LocationKey::Zero => location.zero_rad = check_rad(&path, v * 1e-6)?,
        }
    }

    let mut components = ComponentErrors::default();
    for (k, t) in &ra.component_errors {
        let path = format!("{p}.component_errors.{k}");
        let dir = component_key(slot, k).map_err(|m| Invalid::new(&path, m))?;
        let table = validate_table(&path, pos_key, linear, dir < 3, t)?;
        if let Some(s) = components.tables.get_mut(dir) {
            *s = Some(table);
        }
    }

    Ok(Axis {
        slot,
        kind,
        side,
        travel: (lo, hi),
        rapid_per_min: rapid,
        pivot_mm,
        location,
        components,
        breakpoints: Vec::new(),
    })
}

fn validate_table(
    path: &str,
    pos_key: &str,
    linear: bool,
    translation: bool,
    t: &RawTable,
) -> V<ErrorTable> {
    let (positions, wrong) = if linear {
        (&t.positions_mm, &t.positions_deg)
    } else {
        (&t.positions_deg, &t.positions_mm)
    };
    if wrong.is_some() {
        let k = if linear {
            "positions_deg"
        } else {
            "positions_mm"
        };
        return Err(Invalid::new(
            format!("{path}.{k}"),
            format!("this axis' tables take `{pos_key}`"),
        ));
    }
    let ppath = format!("{path}.{pos_key}");
    let positions = positions
        .as_ref()
        .ok_or_else(|| Invalid::new(path, format!("missing `{pos_key}`")))?;
    if positions.is_empty() {
        return Err(Invalid::new(ppath, "the table has no positions"));
    }
    for v in positions {
        plausible(&ppath, *v)?;
    }
    for w in positions.windows(2) {
        if let [a, b] = w {
            if a >= b {
                return Err(Invalid::new(
                    ppath,
                    format!("positions must be strictly increasing (`{a}` is followed by `{b}`)"),
                ));
            }
        }
    }
    let (scale, check): (f64, Check) = if translation {
        (1e-3, check_mm)
    } else {
        (1e-6, check_rad)
    };
    let column = |name: &str, col: &[f64]| -> V<Vec<f64>> {
        let cpath = format!("{path}.{name}");
        if col.len() != positions.len() {
            return Err(Invalid::new(
                cpath,
                format!("{} values for {} positions", col.len(), positions.len()),
            ));
        }
        col.iter()
            .map(|v| check(&cpath, finite(&cpath, *v)? * scale))
            .collect()
    };
    let forward = column("forward", &t.forward)?;
    let reverse = match &t.reverse {
        Some(r) => column("reverse", r)?,
        None => forward.clone(),
    };
    Ok(ErrorTable::new(positions.clone(), forward, reverse))
}
