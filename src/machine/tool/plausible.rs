//! Plausibility ranges of a machine-tool file (docs/limits.md): each model
//! quantity against the range of real machine tools, so that a unit or
//! typing mistake (a stiffness in N/mm under a key in N/µm, a tool length
//! in µm) is refused with its key path rather than turned into millimetres
//! of confident correction. A file accepts a value beyond its range with
//! `plausibility: { KEY: off }` ([`crate::machine::plausibility`]).
//!
//! The hard limits of [`super::load`] (finite numbers, signs, the 1 mm and
//! 10 000 µrad limits of the small-error model) come first and cannot be
//! lifted.

use super::raw::{RawAxisType, RawMachineTool, RawProcessForce};
use crate::error::{Invalid, show_number};
use crate::machine::plausibility::{ForceKeys, PLACEMENT, Pass, Range};

/// A linear axis' travel ends and the positions of its tables, mm: the
/// largest gantry machines travel a few tens of metres.
pub const TRAVEL_MM: Range = Range::new(-100_000.0, 100_000.0, "mm", "a linear axis position");
/// A rotary axis' travel ends and table positions, degrees (continuous
/// axes are given a few hundred turns).
pub const TRAVEL_DEG: Range = Range::new(-100_000.0, 100_000.0, "°", "a rotary axis position");
/// Rapid rate of a linear axis, mm/min (linear-motor machines reach a few
/// hundred m/min).
pub const RAPID_MM_PER_MIN: Range =
    Range::new(100.0, 500_000.0, "mm/min", "a linear axis' rapid rate");
/// Rapid rate of a rotary axis, °/min (up to a few thousand 1/min).
pub const RAPID_DEG_PER_MIN: Range =
    Range::new(100.0, 2_000_000.0, "°/min", "a rotary axis' rapid rate");
/// A rotary axis' pivot, mm from the machine zero.
pub const PIVOT_MM: Range = Range::new(-20_000.0, 20_000.0, "mm", "a pivot coordinate");
/// Work offsets and reference points, mm.
pub const OFFSET_MM: Range = Range::new(-100_000.0, 100_000.0, "mm", "a machine coordinate");
/// Tool lengths reach the Z travel plus this, mm (the spindle nose is
/// above the table by about the travel at the top of Z).
pub const TOOL_BEYOND_TRAVEL_MM: f64 = 500.0;
/// Static stiffness at the tool tip, N/µm: general-purpose machines about
/// 10, precision ones 20, heavy cutting up to 500 (docs/physics.md).
pub const STIFFNESS_N_PER_UM: Range =
    Range::new(1.0, 1000.0, "N/µm", "a machine tool's static stiffness");
/// Natural frequency of a mode, Hz: first structural modes of machine
/// tools at 50–70 Hz, spindle and tool modes up to a few kHz.
pub const MODAL_HZ: Range = Range::new(1.0, 10_000.0, "Hz", "a machine tool's natural frequency");
/// Damping ratio of a mode: structures damp 1–10 %.
pub const DAMPING: Range = Range::new(0.001, 0.5, "", "a damping ratio");
/// Modal stiffness, N/µm (a slender tool's mode softer than the static
/// stiffness of the machine).
pub const MODAL_N_PER_UM: Range =
    Range::new(0.5, 2000.0, "N/µm", "a machine tool's modal stiffness");
/// Thermal time constant, minutes (steady state after a few hours).
pub const TIME_CONSTANT_MIN: Range = Range::new(1.0, 1440.0, "min", "a thermal time constant");
/// Spindle idle power per speed, W/(1/min).
pub const IDLE_W_PER_RPM: Range = Range::new(0.0, 2.0, "W·min", "a spindle's idle power per speed");
/// Spindle growth per power, µm/kW (spindles grow tens of µm at full
/// power).
pub const GROWTH_UM_PER_KW: Range =
    Range::new(-200.0, 200.0, "µm/kW", "a spindle's thermal growth");
/// Axis thermal scale error per power, ppm/kW.
pub const SCALE_PPM_PER_KW: Range =
    Range::new(-2000.0, 2000.0, "ppm/kW", "an axis' thermal scale error");
/// Friction force of an axis, N.
pub const FRICTION_N: Range = Range::new(0.0, 20_000.0, "N", "an axis' friction force");

/// The plausibility pass of a machine-tool file (its values are finite:
/// [`super::load::validate`] checked them first).
pub(crate) fn check(raw: &RawMachineTool) -> Result<Vec<Invalid>, Invalid> {
    let mut p = Pass::new();
    axes(&mut p, raw);
    tools(&mut p, raw);
    for (name, map) in [
        ("work_offsets_mm", &raw.work_offsets_mm),
        ("reference_points_mm", &raw.reference_points_mm),
    ] {
        for (code, xyz) in map {
            p.each(&format!("{name}.{code}"), xyz, OFFSET_MM);
        }
    }
    if let Some(f) = &raw.measurement_frame {
        p.norm("measurement_frame", &[f.x_mm, f.y_mm, f.z_mm], PLACEMENT);
    }
    if let Some(f) = &raw.process_force {
        p.force(&force_keys(f));
    }
    if let Some(s) = &raw.stiffness {
        let v = &s.k_n_per_um;
        for (name, values) in [
            ("x_pos", &v.x_pos),
            ("x_neg", &v.x_neg),
            ("y_pos", &v.y_pos),
            ("y_neg", &v.y_neg),
            ("z_pos", &v.z_pos),
            ("z_neg", &v.z_neg),
        ] {
            let path = format!("stiffness.k_n_per_um.{name}");
            match values {
                super::raw::RawGridValues::Uniform(k) => p.range(&path, *k, STIFFNESS_N_PER_UM),
                super::raw::RawGridValues::Grid(g) => {
                    for k in g.iter().flatten().flatten() {
                        p.range(&path, *k, STIFFNESS_N_PER_UM);
                    }
                }
            }
        }
        if let Some(g) = &s.grid_mm {
            for (name, v) in [("x", &g.x), ("y", &g.y), ("z", &g.z)] {
                p.each(&format!("stiffness.grid_mm.{name}"), v, TRAVEL_MM);
            }
        }
    }
    thermal(&mut p, raw);
    if let Some(m) = &raw.modal {
        for (name, mode) in [("x", &m.x), ("y", &m.y), ("z", &m.z)] {
            if let Some(mode) = mode {
                let k = format!("modal.{name}");
                p.range(
                    &format!("{k}.natural_frequency_hz"),
                    mode.natural_frequency_hz,
                    MODAL_HZ,
                );
                p.range(&format!("{k}.damping_ratio"), mode.damping_ratio, DAMPING);
                p.range(
                    &format!("{k}.stiffness_n_per_um"),
                    mode.stiffness_n_per_um,
                    MODAL_N_PER_UM,
                );
            }
        }
    }
    p.settle(raw.plausibility.as_ref())
}

fn axes(p: &mut Pass, raw: &RawMachineTool) {
    for (i, a) in raw.axes.iter().enumerate() {
        let ax = format!("axes[{i}]");
        let linear = a.axis_type == RawAxisType::Linear;
        let (travel, key, range, rapid, rapid_key, rapid_range, pos_key) = if linear {
            (
                a.travel_mm,
                "travel_mm",
                TRAVEL_MM,
                a.rapid_mm_per_min,
                "rapid_mm_per_min",
                RAPID_MM_PER_MIN,
                "positions_mm",
            )
        } else {
            (
                a.travel_deg,
                "travel_deg",
                TRAVEL_DEG,
                a.rapid_deg_per_min,
                "rapid_deg_per_min",
                RAPID_DEG_PER_MIN,
                "positions_deg",
            )
        };
        if let Some(t) = travel {
            p.each(&format!("{ax}.{key}"), &t, range);
        }
        if let Some(r) = rapid {
            p.range(&format!("{ax}.{rapid_key}"), r, rapid_range);
        }
        if let Some(v) = a.pivot_mm {
            p.each(&format!("{ax}.pivot_mm"), &v, PIVOT_MM);
        }
        for (name, t) in &a.component_errors {
            let positions = if linear {
                &t.positions_mm
            } else {
                &t.positions_deg
            };
            if let Some(v) = positions {
                p.each(&format!("{ax}.component_errors.{name}.{pos_key}"), v, range);
            }
        }
    }
}

/// Tool lengths: from 0 (H0, a gauge line at the tip) to the Z travel plus
/// [`TOOL_BEYOND_TRAVEL_MM`], at most [`super::MAX_TOOL_LENGTH_MM`].
fn tools(p: &mut Pass, raw: &RawMachineTool) {
    let z_span = raw
        .axes
        .iter()
        .find(|a| a.name == "Z")
        .and_then(|a| a.travel_mm)
        .map(|[lo, hi]| hi - lo)
        .filter(|s| s.is_finite() && *s > 0.0);
    let max = z_span.map_or(super::MAX_TOOL_LENGTH_MM, |s| {
        (s + TOOL_BEYOND_TRAVEL_MM).min(super::MAX_TOOL_LENGTH_MM)
    });
    for (h, t) in &raw.tools {
        let path = format!("tools.{h}.length_mm");
        let problem = (t.length_mm.is_finite() && t.length_mm > max).then(|| {
            format!(
                "{} mm is outside 0..{} mm, the plausible range of a tool length ({}; check the unit)",
                show_number(t.length_mm),
                show_number(max),
                match z_span {
                    Some(s) => format!(
                        "the Z travel of {} mm plus {} mm",
                        show_number(s),
                        show_number(TOOL_BEYOND_TRAVEL_MM)
                    ),
                    None => "the longest tool of any machine".to_string(),
                }
            )
        });
        p.custom(&path, problem);
    }
}

fn thermal(p: &mut Pass, raw: &RawMachineTool) {
    let Some(t) = &raw.thermal else { return };
    if let Some(s) = &t.spindle {
        p.range(
            "thermal.spindle.idle_w_per_rpm",
            s.idle_w_per_rpm,
            IDLE_W_PER_RPM,
        );
        p.range(
            "thermal.spindle.growth_um_per_kw",
            s.growth_um_per_kw,
            GROWTH_UM_PER_KW,
        );
        p.range(
            "thermal.spindle.time_constant_min",
            s.time_constant_min,
            TIME_CONSTANT_MIN,
        );
    }
    for (name, a) in &t.axes {
        let k = format!("thermal.axes.{name}");
        p.range(
            &format!("{k}.scale_ppm_per_kw"),
            a.scale_ppm_per_kw,
            SCALE_PPM_PER_KW,
        );
        p.range(
            &format!("{k}.time_constant_min"),
            a.time_constant_min,
            TIME_CONSTANT_MIN,
        );
        p.range(&format!("{k}.friction_n"), a.friction_n, FRICTION_N);
        if let Some(origin) = a.scale_origin_mm {
            scale_origin(p, raw, name, &k, origin);
        }
    }
}

/// The scale origin of axis `name` lies within its travel widened by one
/// travel length on each side: a ball screw grows from its fixed bearing,
/// at a travel end or near it; an origin farther out is most often a
/// coordinate of another convention (machine zero at the other end, or
/// another unit).
fn scale_origin(p: &mut Pass, raw: &RawMachineTool, name: &str, key: &str, origin: f64) {
    let travel = raw
        .axes
        .iter()
        .find(|a| a.name == name)
        .and_then(|a| a.travel_mm)
        .filter(|[lo, hi]| lo.is_finite() && hi.is_finite() && hi > lo);
    let Some([lo, hi]) = travel else { return };
    let span = hi - lo;
    let (from, to) = (lo - span, hi + span);
    let problem = (origin.is_finite() && !(from..=to).contains(&origin)).then(|| {
        format!(
            "{} mm is outside {}..{} mm, the plausible range of a scale origin (the {name} travel {}..{} mm widened by its length on each side; check the machine-zero convention and the unit)",
            show_number(origin),
            show_number(from),
            show_number(to),
            show_number(lo),
            show_number(hi),
        )
    });
    p.custom(&format!("{key}.scale_origin_mm"), problem);
}

fn force_keys(f: &RawProcessForce) -> ForceKeys {
    ForceKeys {
        force_n: f.force_n,
        moment_nm: None,
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
        spindle_rpm: None,
        max_feed_mm_per_rev: None,
    }
}
