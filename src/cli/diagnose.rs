//! `postproc diagnose`: where the model and the measurements disagree, which
//! named effect is missing, and the model with that effect added.

use std::io::Write;
use std::path::PathBuf;

use clap::{Args, ValueEnum};

use crate::calibrate::observations::load_observations;
use crate::diagnose::{self, Options, report, write};
use crate::error::{Error, Result};
use crate::machine::Machine;

/// Output format of `diagnose`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum DiagnoseFormat {
    /// Text report.
    Table,
    /// JSON document.
    Json,
}

/// `postproc diagnose`.
#[derive(Debug, Args)]
pub struct DiagnoseArgs {
    /// Machine file (the current model), or the name of a bundled one.
    #[arg(short, long)]
    pub machine: Option<String>,
    /// Measured observation file (CSV, see the observation format).
    #[arg(long)]
    pub observations: Option<PathBuf>,
    /// Fraction of rows held out of every fit to check the improvement.
    #[arg(long, default_value_t = 0.3)]
    pub holdout: f64,
    /// Seed of the hold-out split and the bootstrap.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Bootstrap resamples for the inclusion frequency.
    #[arg(long, default_value_t = 30)]
    pub bootstrap: usize,
    /// Write the machine file with the accepted effects added here.
    #[arg(long, value_name = "OUT.yaml")]
    pub write_model: Option<PathBuf>,
    /// Output format.
    #[arg(long, value_enum, default_value_t = DiagnoseFormat::Table)]
    pub format: DiagnoseFormat,
    /// List the candidate effects (instances for --machine and --observations, when given) and exit.
    #[arg(long)]
    pub list_effects: bool,
}

fn load(name: &str) -> Result<(Machine, String)> {
    let path = Machine::resolve(name)?;
    let text = Machine::read_text(&path)?;
    let m = Machine::from_yaml_str(&text, &path.display().to_string())?;
    Ok((m, text))
}

fn print(s: &str) -> Result<()> {
    let mut out = std::io::stdout().lock();
    out.write_all(s.as_bytes())
        .and_then(|_| out.flush())
        .map_err(|e| Error::io(std::path::Path::new("<stdout>"), e))
}

/// Runs `postproc diagnose`.
pub fn run(a: &DiagnoseArgs) -> Result<i32> {
    if a.list_effects {
        let text = match (&a.machine, &a.observations) {
            (Some(m), Some(o)) => {
                let (machine, _) = load(m)?;
                let obs = load_observations(o)?;
                report::render_library(Some(&diagnose::library(&machine, &obs.rows)))
            }
            (Some(m), None) => {
                let (machine, _) = load(m)?;
                let mut t = report::render_library(Some(&diagnose::library(&machine, &[])));
                t.push_str("(effects that need row columns — thermal, backlash, stiffness — appear when --observations is given)\n");
                t
            }
            _ => report::render_library(None),
        };
        print(&text)?;
        return Ok(0);
    }
    let (Some(m), Some(o)) = (&a.machine, &a.observations) else {
        return Err(Error::Usage(
            "diagnose needs --machine and --observations (or --list-effects)".into(),
        ));
    };
    if !(a.holdout > 0.0 && a.holdout < 1.0) {
        return Err(Error::Usage(format!(
            "--holdout {} must be above 0 and below 1 (an effect is accepted only when held-out rows confirm it)",
            crate::error::show_number(a.holdout)
        )));
    }
    let (machine, text) = load(m)?;
    let obs = load_observations(o)?;
    let opts = Options {
        holdout: a.holdout,
        seed: a.seed,
        bootstrap: a.bootstrap,
    };
    let d = diagnose::diagnose(&machine, &text, &obs, &o.display().to_string(), &opts)?;
    let mut out = match a.format {
        DiagnoseFormat::Table => report::render_table(&d),
        DiagnoseFormat::Json => serde_json::to_string_pretty(&d)
            .map(|s| s + "\n")
            .map_err(|e| Error::Usage(format!("cannot write JSON: {e}")))?,
    };
    if let Some(path) = &a.write_model {
        let w = write::write_model(&machine, &text, &d.found)?;
        super::gcode::refuse_overwrite(path, &[&Machine::resolve(m)?, o])?;
        super::gcode::write_atomically(path, |out| {
            out.write_all(w.text.as_bytes())
                .map_err(|e| Error::io(path, e))
        })?;
        if a.format == DiagnoseFormat::Table {
            out.push_str(&format!(
                "\nwrote {} ({}): {}\n",
                path.display(),
                if w.in_place {
                    "values edited in place, comments kept"
                } else {
                    "document rewritten, inner comments not kept"
                },
                if w.written.is_empty() {
                    "no effect added (the model is unchanged)".to_string()
                } else {
                    format!("added {}", w.written.join(", "))
                }
            ));
            if !w.written.is_empty() {
                let written = Machine::from_yaml_str(&w.text, &path.display().to_string())?;
                let m = diagnose::holdout_metrics(&written, &obs, &o.display().to_string(), &opts)?;
                out.push_str(&format!(
                    "written model on the {} held-out rows (full forward model): RMS {:.1} µm, max {:.1} µm, 95th {:.1} µm\n",
                    d.gap.rows, m.rms_um, m.max_um, m.p95_um
                ));
            }
            for (name, why) in &w.not_written {
                out.push_str(&format!("not written: {name}: {why}\n"));
            }
        }
    }
    print(&out)?;
    Ok(0)
}
