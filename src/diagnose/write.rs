//! Writing the machine file with the accepted effects added.
//!
//! Effects the machine-file format has a key for are added to the values of
//! that key: robot actual DH (`actual`, created from `nominal` when absent),
//! joint stiffness (`k_nm_per_rad`), TCP (`flange_to_tool`), payload
//! (`tool_load`); machine-tool location errors, component tables
//! (linear/quadratic terms; backlash = offset of the reverse column) and the
//! tool table. The others (thermal growth, robot joint backlash, axis
//! stiffness, measurement-frame registration) are listed as not written.
//!
//! The document is rewritten from its parsed form: the file's leading
//! comment block is kept, comments inside the document are not.

use serde_yaml::{Mapping, Value};

use super::Found;
use super::effects::{Action, DhField, apply_to_yaml, round9};
use crate::error::{Error, Result};
use crate::machine::Machine;

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

fn key(s: &str) -> Value {
    Value::String(s.to_string())
}

fn as_f64(v: &Value) -> Option<f64> {
    v.as_f64().or_else(|| v.as_i64().map(|i| i as f64))
}

fn root(doc: &mut Value) -> Result<&mut Mapping> {
    doc.as_mapping_mut()
        .ok_or_else(|| Error::Usage("machine file is not a mapping".into()))
}

fn add_num(m: &mut Mapping, k: &str, add: f64) {
    let old = m.get(k).and_then(as_f64).unwrap_or(0.0);
    m.insert(key(k), Value::from(round9(old + add)));
}

fn robot_edit(doc: &mut Value, action: &Action, p: &[f64], m: &Machine) -> Result<()> {
    let r = root(doc)?;
    let v0 = p.first().copied().unwrap_or(0.0);
    match action {
        Action::Dh(j, f) => {
            if !r.get("actual").is_some_and(Value::is_sequence) {
                let nominal = r
                    .get("nominal")
                    .cloned()
                    .ok_or_else(|| Error::Usage("robot file has no `nominal`".into()))?;
                r.insert(key("actual"), nominal);
            }
            let joint = r
                .get_mut("actual")
                .and_then(Value::as_sequence_mut)
                .and_then(|s| s.get_mut(*j))
                .and_then(Value::as_mapping_mut)
                .ok_or_else(|| Error::Usage(format!("robot file: no actual[{j}]")))?;
            match f {
                DhField::Theta => add_num(joint, "theta_offset_deg", (v0 * 1e-6).to_degrees()),
                DhField::Alpha => add_num(joint, "alpha_deg", (v0 * 1e-6).to_degrees()),
                DhField::A => add_num(joint, "a_mm", v0 * 1e-3),
                DhField::D => add_num(joint, "d_mm", v0 * 1e-3),
            }
        }
        Action::Compliance(j) => {
            let k = r
                .get_mut("k_nm_per_rad")
                .and_then(Value::as_sequence_mut)
                .and_then(|s| s.get_mut(*j))
                .ok_or_else(|| Error::Usage(format!("robot file: no k_nm_per_rad[{j}]")))?;
            let old = as_f64(k).unwrap_or(f64::INFINITY);
            // Compliance in rad/(N·m) is 1/k; the fitted addition is µrad/(N·m).
            let new = 1.0 / (1.0 / old + v0 * 1e-6);
            if !(new.is_finite() && new > 0.0) {
                return Err(Error::Usage(format!(
                    "joint {} compliance {v0} µrad/(N·m) gives a non-positive stiffness",
                    j + 1
                )));
            }
            *k = Value::from((new * 1000.0).round() / 1000.0);
        }
        Action::Tcp => {
            if !r.get("flange_to_tool").is_some_and(Value::is_mapping) {
                let mut t = Mapping::new();
                for c in ["x_mm", "y_mm", "z_mm"] {
                    t.insert(key(c), Value::from(0.0));
                }
                r.insert(key("flange_to_tool"), Value::Mapping(t));
            }
            let t = r
                .get_mut("flange_to_tool")
                .and_then(Value::as_mapping_mut)
                .ok_or_else(|| Error::Usage("robot file: bad flange_to_tool".into()))?;
            for (c, v) in ["x_mm", "y_mm", "z_mm"].iter().zip(p) {
                add_num(t, c, v * 1e-3);
            }
        }
        Action::Payload => {
            if !r.get("tool_load").is_some_and(Value::is_mapping) {
                let tcp = match m {
                    Machine::Robot(rb) => rb.flange_to_tool().translation.vector,
                    Machine::Tool(_) => nalgebra::Vector3::zeros(),
                };
                let mut t = Mapping::new();
                t.insert(key("mass_kg"), Value::from(0.0));
                t.insert(
                    key("cog_mm"),
                    Value::Sequence(tcp.iter().map(|v| Value::from(*v)).collect()),
                );
                r.insert(key("tool_load"), Value::Mapping(t));
            }
            if let Some(t) = r.get_mut("tool_load").and_then(Value::as_mapping_mut) {
                add_num(t, "mass_kg", v0);
            }
        }
        _ => {
            return Err(Error::Usage(
                "this effect has no key in the robot file".into(),
            ));
        }
    }
    Ok(())
}

/// Writes `found` into the machine file text.
pub fn write_model(machine: &Machine, machine_text: &str, found: &[Found]) -> Result<Written> {
    let mut doc: Value = serde_yaml::from_str(machine_text)
        .map_err(|e| Error::Usage(format!("machine file: {e}")))?;
    let mut written = Vec::new();
    let mut not_written = Vec::new();
    for f in found {
        if let Some(why) = &f.effect.not_writable {
            not_written.push((f.effect.name.clone(), why.clone()));
            continue;
        }
        let values: Vec<f64> = f.params.iter().map(|p| p.value).collect();
        match machine {
            Machine::Robot(_) => robot_edit(&mut doc, &f.effect.action, &values, machine)?,
            Machine::Tool(_) => apply_to_yaml(
                &mut doc,
                &f.effect.action,
                values.first().copied().unwrap_or(0.0),
                machine,
            )?,
        }
        written.push(f.effect.name.clone());
    }
    let body = serde_yaml::to_string(&doc)
        .map_err(|e| Error::Usage(format!("cannot write the machine file: {e}")))?;
    let mut text = String::new();
    for line in machine_text.lines() {
        if line.starts_with('#') || line.trim().is_empty() {
            text.push_str(line);
            text.push('\n');
        } else {
            break;
        }
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
        text.push_str(&format!(
            "# postproc diagnose: {} {state}: {}\n",
            f.effect.name,
            vals.join(", ")
        ));
    }
    text.push_str(&body);
    // The written file must load.
    Machine::from_yaml_str(&text, "(written model)")?;
    Ok(Written {
        text,
        written,
        not_written,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::effects::library;
    use crate::diagnose::{Found, Param};
    use approx::assert_abs_diff_eq;

    /// Written stiffness tolerance, N·m/rad (the file keeps 3 decimals).
    const K_TOL: f64 = 1e-3;

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
        assert_abs_diff_eq!(r.k_nmm_per_rad()[2] / 1000.0, 123529.721, epsilon = K_TOL);
        assert_abs_diff_eq!(r.flange_to_tool().translation.vector.x, 0.4, epsilon = 1e-9);
        assert_eq!(w.written, vec!["joint3_compliance", "tcp_offset"]);
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
        assert_abs_diff_eq!(y.location.angles_rad.z, 75e-6, epsilon = 1e-12);
    }
}
