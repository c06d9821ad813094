//! `postproc diagnose`: where the model and the measurements disagree, which
//! named effect is missing, and the model with that effect added.

use crate::machine::yaml_write::{self, Edit};
use std::io::Write;
use std::path::{Path, PathBuf};

use clap::{Args, ValueEnum};

use crate::calibrate::observations::load_observations;
use crate::diagnose::{self, Options, report, write};
use crate::error::{Error, Result};
use crate::machine::{Machine, MachineFile};

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
    /// Frame of the measured positions, overriding the file's `# frame:`
    /// line: base, world (robot: through `base`) or instrument (registered
    /// to the model first).
    #[arg(long, value_parser = super::calibrate::parse_frame)]
    pub frame: Option<crate::calibrate::observations::MeasurementFrame>,
    /// With --write-model: add the uncertain parameters of the accepted
    /// effects too (U(k=2) above --uncertain-above of their value; they are
    /// listed as not added otherwise).
    #[arg(long)]
    pub write_uncertain: bool,
    /// Largest accepted expanded uncertainty U(k=2) of an added parameter,
    /// as a fraction of its value (a length known to within 2 µm is always
    /// accepted); see `calibrate --uncertain-above`.
    #[arg(long, value_name = "FRACTION", default_value_t = crate::calibrate::honesty::MAX_RELATIVE_UNCERTAINTY)]
    pub uncertain_above: f64,
    /// Ratio of position to orientation noise for rows with `qw…qz`, mm per
    /// rad, as in `calibrate` (0 ignores measured orientations).
    #[arg(long, default_value_t = crate::calibrate::stiffness::ORIENTATION_MM_PER_RAD)]
    pub orientation_weight_mm_per_rad: f64,
}

/// Observations in the machine's reference frame: world positions through
/// `base`; instrument positions through the rigid transform that registers
/// them to the model's predictions (reported in the returned text). Exact
/// copies of rows are dropped, and too few distinct poses are refused.
fn in_reference_frame(
    machine: &Machine,
    obs: &crate::calibrate::observations::Observations,
    file: &str,
    w_rot: f64,
) -> Result<(
    crate::calibrate::observations::Observations,
    String,
    Option<nalgebra::Isometry3<f64>>,
)> {
    use crate::calibrate::frame::{
        frame_uncertainty, register, rpy_deg, world_note, world_to_reference,
    };
    use crate::calibrate::observations::MeasurementFrame;
    let world = world_note(machine, obs.frame);
    crate::calibrate::screen::check_units(machine, &world_to_reference(machine, obs), file)?;
    let (mut obs, copies) =
        crate::calibrate::screen::drop_copies(&world_to_reference(machine, obs), file);
    let all: Vec<usize> = (0..obs.rows.len()).collect();
    let distinct = crate::calibrate::screen::distinct_poses(&obs, &all);
    if distinct < MIN_DISTINCT_POSES {
        return Err(Error::Data(format!(
            "{file}: {distinct} distinct pose(s) in {} rows (repeats count once); diagnosis \
             needs at least {MIN_DISTINCT_POSES} different poses",
            obs.rows.len()
        )));
    }
    let mut said = copies.map(|c| format!("note: {c}\n")).unwrap_or_default();
    if let Some(w) = world {
        said.push_str(&format!("note: {w}\n"));
    }
    said.push_str(&orientation_note(machine, &obs, w_rot));
    if obs.frame == MeasurementFrame::Instrument {
        let model: Vec<nalgebra::Vector3<f64>> = obs
            .rows
            .iter()
            .map(|r| crate::calibrate::forward::predict(machine, r, file).map(|p| p.attained_mm))
            .collect::<Result<_>>()?;
        let meas: Vec<nalgebra::Vector3<f64>> = obs.rows.iter().map(|r| r.measured_mm).collect();
        let f = register(&meas, &model).ok_or_else(|| {
            Error::Data(format!(
                "{file}: the measured points lie on a line or are too few: the instrument frame cannot be registered"
            ))
        })?;
        let u = frame_uncertainty(&f, &meas, &model);
        let t = f.translation.vector;
        let r = rpy_deg(&f);
        said.push_str(&format!(
            "measurement frame (instrument in the reference frame, registered to the model): \
             x {:.4} y {:.4} z {:.4} mm{}, roll {:.6} pitch {:.6} yaw {:.6} deg{}\n",
            t.x,
            t.y,
            t.z,
            u.map_or(String::new(), |u| format!(
                " (u {:.4} {:.4} {:.4})",
                u.0[0], u.0[1], u.0[2]
            )),
            r[0],
            r[1],
            r[2],
            u.map_or(String::new(), |u| format!(
                " (u {:.6} {:.6} {:.6})",
                u.1[0], u.1[1], u.1[2]
            )),
        ));
        said.push_str(
            "note: the frame is fitted again with every candidate effect (each is judged \
             with the frame that suits it); effects that move the points like a rigid motion \
             of the instrument are absorbed by the frame and not candidates\n",
        );
        for row in &mut obs.rows {
            row.measured_mm = (f * nalgebra::Point3::from(row.measured_mm)).coords;
            row.orientation = row.orientation.map(|q| f.rotation * q);
        }
        obs.frame = MeasurementFrame::Reference;
        return Ok((obs, said, Some(f)));
    }
    Ok((obs, said, None))
}

/// What the diagnosis does with the measured orientations of `obs` (empty
/// when no row has one): compared with weight `w_rot` (mm/rad), or left out
/// (weight 0, or a machine tool, whose model predicts positions only).
fn orientation_note(
    machine: &Machine,
    obs: &crate::calibrate::observations::Observations,
    w_rot: f64,
) -> String {
    let n = obs.rows.iter().filter(|r| r.orientation.is_some()).count();
    if n == 0 {
        return String::new();
    }
    let w = crate::error::show_number(w_rot);
    if matches!(machine, Machine::Tool(_)) {
        format!(
            "note: {n} row(s) carry a measured orientation (qw, qx, qy, qz); the machine-tool \
             model predicts the tool tip's position only: diagnose compares positions\n"
        )
    } else if w_rot > 0.0 {
        format!(
            "note: {n} row(s) carry a measured orientation (qw, qx, qy, qz): its residual \
             enters every fit, test and held-out figure, weighted {w} mm/rad \
             (--orientation-weight-mm-per-rad; θ rad counts like θ × {w} mm of position)\n"
        )
    } else {
        format!(
            "note: {n} row(s) carry a measured orientation (qw, qx, qy, qz); \
             --orientation-weight-mm-per-rad 0 leaves them out: diagnose compares positions\n"
        )
    }
}

/// Fewest distinct poses a diagnosis accepts.
const MIN_DISTINCT_POSES: usize = 4;

fn load(name: &str) -> Result<(Machine, String)> {
    let file = MachineFile::open(name)?;
    let m = file.load()?;
    Ok((m, file.text.into_owned()))
}

fn print(s: &str) -> Result<()> {
    let mut out = std::io::stdout().lock();
    out.write_all(s.as_bytes())
        .and_then(|_| out.flush())
        .map_err(|e| Error::io(std::path::Path::new("<stdout>"), e))
}

/// What `--write-model` writes from: the current model, the observations
/// in the reference frame, the registration that carried instrument
/// positions there (if any), the diagnosis options.
struct WrittenModel<'a> {
    machine: &'a Machine,
    text: &'a str,
    obs: &'a crate::calibrate::observations::Observations,
    registration: Option<nalgebra::Isometry3<f64>>,
    opts: &'a Options,
}

impl WrittenModel<'_> {
    /// Writes the model with the accepted effects of `d` to `path` (and,
    /// for instrument data, its `measurement_frame`); returns the lines the
    /// table report adds.
    fn write(&self, a: &DiagnoseArgs, d: &diagnose::Diagnosis, path: &Path) -> Result<String> {
        let o = a.observations.as_deref().unwrap_or(Path::new("-"));
        let file = o.display().to_string();
        let rule = crate::calibrate::honesty::Rule {
            max_relative: a.uncertain_above,
            write_uncertain: a.write_uncertain,
        };
        let (found, withheld) = write::withhold_uncertain(self.machine, &d.found, &rule);
        let mut w = write::write_model_for(self.machine, self.text, &found, &self.obs.rows)?;
        w.not_written.extend(withheld);
        let shown = path.display().to_string();
        let model = Machine::from_yaml_str(&w.text, &shown)?;
        // Instrument data: the frame re-identified with the written model
        // fixed, on the training rows; the held-out rows are judged in it.
        let (check_obs, frame_said) = match self.registration {
            Some(f) => {
                let (obs, est) = reidentified(&model, self.obs, &f, self.opts, &file)?;
                let frame = Edit::MeasurementFrame {
                    xyz_mm: est.xyz_mm,
                    rpy_deg: est.rpy_deg,
                };
                w.text = yaml_write::apply(&w.text, &shown, "postproc diagnose", &[frame])?;
                (Some(obs), Some(est))
            }
            None => (None, None),
        };
        if !w.written.is_empty() {
            // The fit: the 3D RMS of the held-out rows with the accepted
            // effects (µm → mm).
            let record = super::calibrate::calibration_record(
                "diagnose",
                o,
                self.obs.rows.len(),
                d.gap.after.rms_um * 1e-3,
            )?;
            let block = match &d.covariance {
                Some(cov) => write::written_covariance(
                    self.machine,
                    &model,
                    &d.found,
                    &found,
                    &w.written,
                    cov,
                )?
                .map(|c| {
                    crate::predict::uncertainty::CovarianceBlock::from_fit(
                        "diagnose",
                        &record.observations,
                        &record.observations_sha256,
                        d.train_rows,
                        c.parameters,
                        &c.matrix,
                    )
                }),
                None => None,
            };
            let status = Edit::Calibrated(record);
            let edited = yaml_write::apply(&w.text, &shown, "postproc diagnose", &[status])?;
            w.text = crate::machine::status::mark_calibrated(&w.text, &edited, &shown, "diagnose")?;
            if let Some(b) = &block {
                w.text = crate::predict::uncertainty::put_covariance(&w.text, &shown, b)?;
            }
            // Older blocks of the covariance list that the edits made stale
            // (a table re-gridded) are dropped, with a warning.
            let fresh = block.as_ref().map(|b| b.kind.as_str());
            let (kept, stale) = crate::predict::uncertainty::drop_stale_covariance(
                self.machine,
                &w.text,
                &shown,
                fresh,
            )?;
            w.text = kept;
            for line in stale {
                tracing::warn!("{line}");
            }
        }
        let mut inputs = vec![o.to_path_buf()];
        if let Some(m) = &a.machine {
            inputs.extend(MachineFile::open(m)?.path);
        }
        super::output::refuse_overwrite(path, &inputs)?;
        super::output::write_atomically(path, |out| {
            out.write_all(w.text.as_bytes())
                .map_err(|e| Error::io(path, e))
        })?;
        let mut out = format!(
            "\nwrote {} (values edited in place, comments kept): {}\n",
            path.display(),
            if w.written.is_empty() {
                "no effect added (the model is unchanged)".to_string()
            } else {
                format!("added {}", w.written.join(", "))
            }
        );
        if let Some(est) = &frame_said {
            out.push_str(&format!(
                "wrote measurement_frame, re-identified with the written model on the {} fit \
                 rows: {}",
                d.train_rows,
                frame_line(est)
            ));
        }
        if !w.written.is_empty() || check_obs.is_some() {
            let obs = check_obs.as_ref().unwrap_or(self.obs);
            let skip: Vec<usize> = d.outliers.rows.iter().map(|o| o.index).collect();
            let (m, rot) = diagnose::holdout_check_without(&model, obs, &file, self.opts, &skip)?;
            out.push_str(&format!(
                "written model on the {} held-out rows (full forward model{}): RMS {:.1} µm, max {:.1} µm, 95th {:.1} µm{}\n",
                d.gap.rows,
                if check_obs.is_some() {
                    ", in the re-identified frame"
                } else {
                    ""
                },
                m.rms_um,
                m.max_um,
                m.p95_um,
                rot.map_or(String::new(), |r| format!(
                    "; orientation RMS {:.4} deg, max {:.4} deg",
                    r.rms_deg, r.max_deg
                ))
            ));
        }
        for (name, why) in &w.not_written {
            out.push_str(&format!("not written: {name}: {why}\n"));
        }
        Ok(out)
    }
}

/// A frame as one line: origin (mm) and roll, pitch, yaw (deg), with the
/// standard uncertainties when known.
fn frame_line(est: &crate::calibrate::report::FrameEstimate) -> String {
    let t = est.xyz_mm;
    let r = est.rpy_deg;
    format!(
        "x {:.4} y {:.4} z {:.4} mm{}, roll {:.6} pitch {:.6} yaw {:.6} deg{}\n",
        t[0],
        t[1],
        t[2],
        est.u_xyz_mm.map_or(String::new(), |u| format!(
            " (u {:.4} {:.4} {:.4})",
            u[0], u[1], u[2]
        )),
        r[0],
        r[1],
        r[2],
        est.u_rot_deg.map_or(String::new(), |u| format!(
            " (u {:.6} {:.6} {:.6})",
            u[0], u[1], u[2]
        )),
    )
}

/// The instrument frame re-identified for the written `model` (fixed): the
/// rigid registration of the instrument positions (`obs` carried back
/// through the first registration `f`) onto the positions `model` predicts,
/// on the training rows of the split `opts` selects. Returns the
/// observations carried into the reference frame by it, and the frame.
fn reidentified(
    model: &Machine,
    obs: &crate::calibrate::observations::Observations,
    f: &nalgebra::Isometry3<f64>,
    opts: &Options,
    file: &str,
) -> Result<(
    crate::calibrate::observations::Observations,
    crate::calibrate::report::FrameEstimate,
)> {
    use crate::calibrate::frame::{estimate, refit};
    let back = f.inverse();
    let (train, _) = crate::calibrate::screen::grouped_split(obs, opts.holdout, opts.seed);
    let mut meas = Vec::with_capacity(train.len());
    let mut pred = Vec::with_capacity(train.len());
    for &i in &train {
        let Some(row) = obs.rows.get(i) else { continue };
        meas.push((back * nalgebra::Point3::from(row.measured_mm)).coords);
        pred.push(crate::calibrate::forward::predict(model, row, file)?.attained_mm);
    }
    let (g, u) = refit(&meas, &pred, None, file)?;
    let carry = g * back;
    let mut out = obs.clone();
    for row in &mut out.rows {
        row.measured_mm = (carry * nalgebra::Point3::from(row.measured_mm)).coords;
        row.orientation = row.orientation.map(|q| carry.rotation * q);
    }
    Ok((out, estimate(&g, u)))
}

/// Runs `postproc diagnose`.
pub fn run(a: &DiagnoseArgs) -> Result<i32> {
    super::calibrate::check_uncertain_above(a.uncertain_above)?;
    super::calibrate::check_orientation_weight(a.orientation_weight_mm_per_rad)?;
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
    if let Some(path) = &a.write_model {
        // Refused before anything is fitted.
        let mut inputs = vec![o.to_path_buf()];
        inputs.extend(MachineFile::open(m)?.path);
        super::output::refuse_overwrite(path, &inputs)?;
    }
    let (machine, text) = load(m)?;
    let mut obs = load_observations(o)?;
    if let Some(f) = a.frame {
        obs.frame = f;
    }
    let instrument = obs.frame == crate::calibrate::observations::MeasurementFrame::Instrument;
    let (obs, frame_text, registration) = in_reference_frame(
        &machine,
        &obs,
        &o.display().to_string(),
        a.orientation_weight_mm_per_rad,
    )?;
    let opts = Options {
        holdout: a.holdout,
        seed: a.seed,
        bootstrap: a.bootstrap,
        instrument,
        orientation_mm_per_rad: a.orientation_weight_mm_per_rad,
    };
    let d = diagnose::diagnose(&machine, &text, &obs, &o.display().to_string(), &opts)?;
    if a.format == DiagnoseFormat::Json && !frame_text.is_empty() {
        tracing::info!("{}", frame_text.trim_end());
    }
    let mut out = match a.format {
        DiagnoseFormat::Table => frame_text + &report::render_table(&d),
        DiagnoseFormat::Json => serde_json::to_string_pretty(&d)
            .map(|s| s + "\n")
            .map_err(|e| Error::Usage(format!("cannot write JSON: {e}")))?,
    };
    if let Some(path) = &a.write_model {
        let written = WrittenModel {
            machine: &machine,
            text: &text,
            obs: &obs,
            registration,
            opts: &opts,
        };
        match written.write(a, &d, path) {
            Ok(said) => {
                if a.format == DiagnoseFormat::Table {
                    out.push_str(&said);
                }
            }
            Err(e) => {
                // The diagnosis stands whatever became of the file: it is
                // printed whole, then why nothing was written (exit 1).
                print(&out)?;
                let mut msg = e.to_string();
                let mut src = std::error::Error::source(&e);
                while let Some(s) = src {
                    msg.push_str(&format!(": {s}"));
                    src = s.source();
                }
                eprintln!(
                    "error: --write-model {}: the diagnosis above stands, but the model was not \
                     written (no file left): {msg}",
                    path.display()
                );
                return Ok(1);
            }
        }
    }
    print(&out)?;
    Ok(0)
}
