//! Text rendering of a [`Diagnosis`] (the JSON form is its serde form) and
//! the listing of the candidate library.

use std::fmt::Write as _;

use super::patterns::PATTERNS_SHOWN;
use super::select::{Outcome, SHOW};
use super::{Diagnosis, Metrics};
use crate::diagnose::effects::{Effect, FAMILIES};

/// Trends shown in the "where" table.
const TRENDS_SHOWN: usize = 8;

fn pct(x: f64) -> String {
    if x < 1e-99 {
        "<1e-99".into()
    } else {
        format!("{x:.1e}")
    }
}

fn metrics_row(out: &mut String, label: &str, m: &Metrics) {
    let _ = writeln!(
        out,
        "  {label:<8} {:>9.1} {:>9.1} {:>9.1} {:>9.1} {:>9.1} {:>9.1}",
        m.rms_um, m.max_um, m.p95_um, m.axis_rms_um[0], m.axis_rms_um[1], m.axis_rms_um[2]
    );
}

/// The gross outliers left out, each by row, and the rule.
fn render_outliers(o: &mut String, d: &Diagnosis) {
    let out = &d.outliers;
    if out.rows.is_empty() {
        return;
    }
    let _ = writeln!(
        o,
        "outliers: {} row(s) left out of every fit, test and held-out figure (a coordinate more \
         than {} robust σ from the median after the library's {} best candidates; \
         σ = 1.4826·MAD = {:.1} µm):",
        out.rows.len(),
        super::outliers::K_SIGMA,
        out.structure_candidates,
        out.sigma_um
    );
    for r in &out.rows {
        let line = if r.line > 0 {
            format!(" (line {})", r.line)
        } else {
            String::new()
        };
        let _ = writeln!(
            o,
            "  row {}{line}: {:.1} µm ({:.0} σ)",
            r.id, r.residual_um, r.sigmas
        );
    }
}

/// The text report.
pub fn render_table(d: &Diagnosis) -> String {
    let mut o = String::new();
    let _ = writeln!(
        o,
        "diagnose: {} rows ({} fit, {} held out), {} candidate effects ({})",
        d.rows, d.train_rows, d.holdout_rows, d.candidates, d.machine_kind
    );
    render_outliers(&mut o, d);
    let _ = writeln!(o, "\nWHERE  residual = measured − simulated");
    let _ = writeln!(
        o,
        "  residual RMS  x {:.1}  y {:.1}  z {:.1} µm",
        d.where_.rms_um[0], d.where_.rms_um[1], d.where_.rms_um[2]
    );
    let _ = writeln!(
        o,
        "  {:<12} {:>4} {:>7} {:>9} {:>9} {:>6} {:>9}  binned mean residual (µm)",
        "covariate", "comp", "rho", "p", "p_runs", "DW", "p_holm"
    );
    for t in d.where_.trends.iter().take(TRENDS_SHOWN) {
        let bins: Vec<String> = t.bins.iter().map(|b| format!("{:+.1}", b.1)).collect();
        let _ = writeln!(
            o,
            "  {:<12} {:>4} {:>+7.2} {:>9} {:>9} {:>6.2} {:>9}  {}",
            t.covariate,
            t.component,
            t.rho,
            pct(t.p_spearman),
            pct(t.p_runs),
            t.durbin_watson,
            pct(t.p_holm),
            bins.join(" ")
        );
    }
    if !d.where_.patterns.is_empty() {
        let _ = writeln!(o, "  {:<44} {:>6} {:>8}", "pattern", "params", "R² adj");
        for p in d.where_.patterns.iter().take(PATTERNS_SHOWN) {
            let _ = writeln!(o, "  {:<44} {:>6} {:>8.3}", p.name, p.params, p.r2_adj);
        }
    }
    let _ = writeln!(o, "  {}", d.where_.sentence);

    let _ = writeln!(
        o,
        "\nWHAT  forward selection (F test Holm-corrected, ΔBIC, margin, held-out)"
    );
    if let Some(u) = &d.orientation {
        let _ = writeln!(
            o,
            "  RSS and held-out RMS below count the orientation residuals of {} row(s), weighted {} mm/rad (in µm like the positions)",
            u.rows,
            crate::error::show_number(u.weight_mm_per_rad)
        );
    }
    if d.screen.is_empty() {
        let _ = writeln!(
            o,
            "  identifiability screen: every candidate pair is separable in these rows"
        );
    } else {
        let pairs: Vec<String> = d
            .screen
            .iter()
            .map(|c| format!("{} ≡ {}", c.a, c.b))
            .collect();
        let _ = writeln!(
            o,
            "  identifiability screen: these rows cannot separate {}",
            pairs.join(", ")
        );
    }
    for g in &d.groups {
        let _ = writeln!(
            o,
            "  identifiability screen: {} is a combination of {} in these rows",
            g.candidate,
            g.of.join(" + ")
        );
    }
    for (i, s) in d.steps.iter().enumerate() {
        let _ = writeln!(
            o,
            "  step {}: training RSS {:.0} µm²",
            i + 1,
            s.rss_before_um2
        );
        let _ = writeln!(
            o,
            "    {:<24} {:>12} {:>9} {:>9} {:>9} {:>6}",
            "candidate", "RSS µm²", "F", "p_holm", "ΔBIC", "boot"
        );
        for c in s.candidates.iter().take(SHOW) {
            let _ = writeln!(
                o,
                "    {:<24} {:>12.0} {:>9.1} {:>9} {:>9.1} {:>5.0}%",
                c.name,
                c.rss_um2,
                c.f,
                pct(c.p_holm),
                c.delta_bic,
                100.0 * c.bootstrap
            );
        }
        let margin = if s.margin_chi2 >= f64::MAX {
            "∞".to_string()
        } else {
            format!("{:.1}", s.margin_chi2)
        };
        let line = match &s.outcome {
            Outcome::Accepted { name } => format!(
                "accepted {name} (margin over runner-up {margin} σ², held-out RMS {:.1} → {:.1} µm)",
                s.holdout_rms_um.0, s.holdout_rms_um.1
            ),
            Outcome::Confounded { name, with } => format!(
                "{name} is confounded with {} (margin {margin} σ²): not claimed",
                with.join(", ")
            ),
            Outcome::NotConfirmed { name } => format!(
                "{name} not confirmed on the held-out rows (RMS {:.1} → {:.1} µm): not claimed",
                s.holdout_rms_um.0, s.holdout_rms_um.1
            ),
            Outcome::NothingDetectable => "no detectable missing effect".to_string(),
        };
        let _ = writeln!(o, "    → {line}");
    }
    if !d.found.is_empty() {
        let _ = writeln!(o, "\n  fitted (± standard uncertainty):");
        for f in &d.found {
            let _ = writeln!(
                o,
                "    {} — {} (bootstrap inclusion {:.0}%)",
                f.effect.name,
                f.effect.description,
                100.0 * f.bootstrap
            );
            for p in &f.params {
                let _ = writeln!(o, "      {} = {:.4} ± {:.4}", p.name, p.value, p.u);
            }
            if let Some(why) = &f.effect.not_writable {
                let _ = writeln!(o, "      note: {why}");
            }
        }
    }
    render_gap(&mut o, d);
    let _ = writeln!(o, "\nVERDICT: {}", d.verdict);
    o
}

/// The GAP section of the text report.
fn render_gap(o: &mut String, d: &Diagnosis) {
    let _ = writeln!(o, "\nGAP on {} held-out rows (µm)", d.gap.rows);
    let _ = writeln!(
        o,
        "  {:<8} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9}",
        "", "RMS", "max", "95th", "x RMS", "y RMS", "z RMS"
    );
    metrics_row(o, "before", &d.gap.before);
    metrics_row(o, "after", &d.gap.after);
    if let Some(g) = &d.gap.orientation {
        let _ = writeln!(
            o,
            "  orientation of the {} held-out rows with qw…qz (deg): RMS {:.4} → {:.4}, max {:.4} → {:.4}",
            g.rows, g.before.rms_deg, g.after.rms_deg, g.before.max_deg, g.after.max_deg
        );
    }
    let _ = writeln!(
        o,
        "  gap closed: {:.1} % of the RMS; {:.1} % of the closable part (noise floor ≈ {:.1} µm RMS, what no candidate of the library explains)",
        d.gap.closed_pct, d.gap.closed_of_closable_pct, d.gap.noise_floor_um
    );
}

/// The `--list-effects` listing: families, and the instances for a machine.
pub fn render_library(lib: Option<&[Effect]>) -> String {
    let mut o = String::new();
    match lib {
        None => {
            let _ = writeln!(
                o,
                "candidate effects (give --machine and --observations for the instances):"
            );
            for (kind, text) in FAMILIES {
                let _ = writeln!(o, "  {kind:<13} {text}");
            }
        }
        Some(lib) => {
            for e in lib {
                let w = if e.not_writable.is_some() {
                    "  (not written to the machine file)"
                } else {
                    ""
                };
                let _ = writeln!(
                    o,
                    "  {:<26} {} — {}{w}",
                    e.name,
                    e.params.join(", "),
                    e.description
                );
            }
        }
    }
    o
}
