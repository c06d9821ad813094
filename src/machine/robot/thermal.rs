//! Thermal drift of a robot arm (the thesis' Paper B model): DH lengths grow
//! with the mean power of neighbouring joint motors,
//! `Δp = ub − lb · exp(−ts · P_joint)` (mm, P in W), and the effective
//! (thermal) power follows the motor power through a first-order filter in
//! time. Parameter names `a1..a6` / `d1..d6` are the `a_mm` / `d_mm` of row
//! 1..6 of the machine file's DH table (whatever convention it uses).

use super::raw::RawThermal;
use super::{DhParams, Robot};
use crate::error::Invalid;
use crate::machine::ThermalStart;

/// Which DH length a thermal term changes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DhLength {
    /// `a_mm` of a row.
    A,
    /// `d_mm` of a row.
    D,
}

/// One Paper B coupling term: parameter ← power of one joint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ThermalTerm {
    /// Which length.
    pub length: DhLength,
    /// Row of the DH table, 0-based (`a2` → 1).
    pub row: usize,
    /// Joint whose motor power drives it, 0-based (`joint: 1` → 0).
    pub joint: usize,
    /// Lower-bound coefficient `lb`, mm.
    pub lb_mm: f64,
    /// Upper bound `ub`, mm (the growth at infinite power).
    pub ub_mm: f64,
    /// Thermal stability `ts`, 1/W.
    pub ts_per_w: f64,
}

impl ThermalTerm {
    /// The growth of this term at joint power `p_w` (W): `ub − lb·e^(−ts·P)`.
    pub fn growth_mm(&self, p_w: f64) -> f64 {
        self.ub_mm - self.lb_mm * (-self.ts_per_w * p_w).exp()
    }
}

/// The `thermal:` section of a robot file.
#[derive(Debug, Clone, PartialEq)]
pub struct Thermal {
    /// Time constant of the first-order heat-up, s.
    pub time_constant_s: f64,
    /// Highest mean motor power of a joint the robot is rated for, W
    /// (`rated_power_w`; `None`: not stated, the plausibility limit is then
    /// evaluated up to [`super::plausible::JOINT_POWER_MAX_W`]).
    pub rated_power_w: Option<f64>,
    /// Coupling terms.
    pub terms: Vec<ThermalTerm>,
}

/// Growth of the DH lengths, mm: `[Δa, Δd]` per row.
pub type DhGrowth = [[f64; 2]; 6];

impl Thermal {
    /// Sum of the terms' growth per row for the joint powers `p_w` (W).
    pub fn growth_mm(&self, p_w: &[f64; 6]) -> DhGrowth {
        let mut g = [[0.0; 2]; 6];
        for t in &self.terms {
            let p = p_w.get(t.joint).copied().unwrap_or(0.0);
            if let Some(row) = g.get_mut(t.row) {
                row[t.length as usize] += t.growth_mm(p);
            }
        }
        g
    }

    pub(crate) fn from_raw(raw: &RawThermal) -> Result<Self, Invalid> {
        let p = "thermal.time_constant_min";
        if !raw.time_constant_min.is_finite() || raw.time_constant_min <= 0.0 {
            return Err(Invalid::new(
                p,
                format!(
                    "time constant {} must be a positive number of minutes",
                    raw.time_constant_min
                ),
            ));
        }
        if let Some(w) = raw.rated_power_w {
            if !(w.is_finite() && w > 0.0) {
                return Err(Invalid::new(
                    "thermal.rated_power_w",
                    format!("rated power {w} must be a positive number of watts"),
                ));
            }
        }
        let mut terms = Vec::with_capacity(raw.terms.len());
        for (i, t) in raw.terms.iter().enumerate() {
            let path = format!("thermal.terms[{i}]");
            let name = t.parameter.trim().to_ascii_lowercase();
            let (length, row) = match (name.get(..1), name.get(1..).map(str::parse::<usize>)) {
                (Some("a"), Some(Ok(r @ 1..=6))) => (DhLength::A, r - 1),
                (Some("d"), Some(Ok(r @ 1..=6))) => (DhLength::D, r - 1),
                _ => {
                    return Err(Invalid::new(
                        format!("{path}.parameter"),
                        format!(
                            "`{}` is not a DH length (a1..a6 or d1..d6, row of the DH table)",
                            t.parameter
                        ),
                    ));
                }
            };
            if !(1..=6).contains(&t.joint) {
                return Err(Invalid::new(
                    format!("{path}.joint"),
                    format!("joint {} must be 1..6", t.joint),
                ));
            }
            for (k, v) in [
                ("lb_mm", t.lb_mm),
                ("ub_mm", t.ub_mm),
                ("ts_per_w", t.ts_per_w),
            ] {
                if !v.is_finite() {
                    return Err(Invalid::new(
                        format!("{path}.{k}"),
                        format!("value `{v}` is not a finite number"),
                    ));
                }
            }
            if t.ts_per_w < 0.0 {
                return Err(Invalid::new(
                    format!("{path}.ts_per_w"),
                    format!("thermal stability {} must not be negative", t.ts_per_w),
                ));
            }
            terms.push(ThermalTerm {
                length,
                row,
                joint: t.joint - 1,
                lb_mm: t.lb_mm,
                ub_mm: t.ub_mm,
                ts_per_w: t.ts_per_w,
            });
        }
        Ok(Thermal {
            time_constant_s: raw.time_constant_min * 60.0,
            rated_power_w: raw.rated_power_w,
            terms,
        })
    }
}

/// Adds a growth to the lengths of a parameter set.
pub(crate) fn grown(p: &DhParams, g: &DhGrowth, gain: f64) -> DhParams {
    let mut out = *p;
    for (j, d) in out.joints.iter_mut().zip(g) {
        j.a_mm += gain * d[0];
        j.d_mm += gain * d[1];
    }
    out
}

/// One piece of the program's time line: a move of `duration_s` with
/// constant joint motor powers `power_w` (W).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    /// Duration, s.
    pub duration_s: f64,
    /// Mean motor power per joint during the move, W.
    pub power_w: [f64; 6],
}

/// One first-order step: state `x` relaxes toward `input` for `dt_s`.
pub fn first_order(x: f64, input: f64, dt_s: f64, tau_s: f64) -> f64 {
    input + (x - input) * (-dt_s / tau_s).exp()
}

/// Time-weighted mean power of a time line, W (zero for an empty one).
pub fn mean_power(segments: &[Segment]) -> [f64; 6] {
    let t: f64 = segments.iter().map(|s| s.duration_s).sum();
    if t <= 0.0 {
        return [0.0; 6];
    }
    std::array::from_fn(|j| {
        segments
            .iter()
            .map(|s| s.duration_s * s.power_w[j])
            .sum::<f64>()
            / t
    })
}

/// Effective (thermal) power per joint at the END of every segment, W,
/// filtered with time constant `tau_s` from the initial state `start`.
pub fn effective_power(segments: &[Segment], tau_s: f64, start: ThermalStart) -> Vec<[f64; 6]> {
    // The start state of a warm start (steady: the periodic state, where
    // end(x0) = x0·e^(−T/τ) + end(0) equals x0) follows from the totals.
    let mut totals = ThermalTotals::default();
    if start != ThermalStart::Cold {
        totals.add(segments, tau_s);
    }
    effective_power_from(segments, tau_s, totals.start_state(start, tau_s))
}

/// The totals of a time line met a piece at a time (a module read a window
/// at a time): its duration, energy per joint and end state from cold, from
/// which [`ThermalTotals::start_state`] gives the start state of
/// [`effective_power`] with the same bits.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ThermalTotals {
    total_s: f64,
    energy_j: [f64; 6],
    end_cold: [f64; 6],
}

impl ThermalTotals {
    /// Adds the next segments of the time line.
    pub fn add(&mut self, segments: &[Segment], tau_s: f64) {
        for s in segments {
            self.total_s += s.duration_s;
            for j in 0..6 {
                self.energy_j[j] += s.duration_s * s.power_w[j];
                self.end_cold[j] = first_order(self.end_cold[j], s.power_w[j], s.duration_s, tau_s);
            }
        }
    }

    /// The effective power at the start of the time line for `start`.
    pub fn start_state(&self, start: ThermalStart, tau_s: f64) -> [f64; 6] {
        match start {
            ThermalStart::Cold => [0.0; 6],
            ThermalStart::WarmUpMin(m) => {
                let f = 1.0 - (-m * 60.0 / tau_s).exp();
                if self.total_s <= 0.0 {
                    return [0.0; 6];
                }
                self.energy_j.map(|e| e / self.total_s * f)
            }
            ThermalStart::Steady => {
                let decay = (-self.total_s / tau_s).exp();
                if decay < 1.0 {
                    self.end_cold.map(|e| e / (1.0 - decay))
                } else {
                    [0.0; 6]
                }
            }
        }
    }
}

/// [`effective_power`] from the effective power `x0` at the start of the
/// first segment (a module compensated a window at a time continues the
/// time line of the windows before with the last state of theirs).
pub fn effective_power_from(segments: &[Segment], tau_s: f64, x0: [f64; 6]) -> Vec<[f64; 6]> {
    let mut x = x0;
    segments
        .iter()
        .map(|s| {
            for (xj, pj) in x.iter_mut().zip(&s.power_w) {
                *xj = first_order(*xj, *pj, s.duration_s, tau_s);
            }
            x
        })
        .collect()
}

impl Robot {
    /// The thermal model, if the file has one.
    pub fn thermal(&self) -> Option<&Thermal> {
        self.d.thermal.as_ref()
    }

    /// Growth of the DH lengths at joint powers `p_w` (W); zero without a
    /// thermal model.
    pub fn thermal_growth_mm(&self, p_w: &[f64; 6]) -> DhGrowth {
        self.thermal().map_or([[0.0; 2]; 6], |t| t.growth_mm(p_w))
    }

    /// The robot whose ACTUAL DH lengths have grown for the mean joint motor
    /// powers `p_w` (W): for calibration and diagnosis rows with measured
    /// powers. The thermal stage of the prediction is left as it was.
    pub fn at_joint_power(&self, p_w: &[f64; 6]) -> Robot {
        let mut r = self.clone();
        r.set_actual(grown(
            self.d.actual.params(),
            &self.thermal_growth_mm(p_w),
            1.0,
        ));
        r
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The start state from totals taken in pieces has the bits of the one
    /// [`effective_power`] finds from the whole time line.
    #[test]
    fn totals_in_pieces_give_the_whole_time_line_start() {
        let segments: Vec<Segment> = (0..57)
            .map(|k| {
                let k = k as f64;
                Segment {
                    duration_s: 0.3 + (k * 0.7).sin().abs() * 4.0,
                    power_w: std::array::from_fn(|j| (k * 1.3 + j as f64).cos().abs() * 150.0),
                }
            })
            .collect();
        let tau = 900.0;
        for start in [
            ThermalStart::Cold,
            ThermalStart::Steady,
            ThermalStart::WarmUpMin(20.0),
        ] {
            let whole = effective_power(&segments, tau, start);
            for piece in [1, 5, 57] {
                let mut totals = ThermalTotals::default();
                for chunk in segments.chunks(piece) {
                    totals.add(chunk, tau);
                }
                let x0 = totals.start_state(start, tau);
                assert_eq!(effective_power_from(&segments, tau, x0), whole, "{start:?}");
            }
        }
        // The start states by their definitions: the steady state repeats
        // itself at the end of the program, a warm-up is the mean power
        // reached after `m` minutes from cold.
        let cold = effective_power(&segments, tau, ThermalStart::Cold);
        let total: f64 = segments.iter().map(|s| s.duration_s).sum();
        let end0 = *cold.last().unwrap();
        let steady_x0 = end0.map(|e| e / (1.0 - (-total / tau).exp()));
        let steady = effective_power(&segments, tau, ThermalStart::Steady);
        assert_eq!(steady, effective_power_from(&segments, tau, steady_x0));
        for (end, x0) in steady.last().unwrap().iter().zip(&steady_x0) {
            approx::assert_relative_eq!(*end, *x0, max_relative = 1e-12);
        }
        let f = 1.0 - (-20.0 * 60.0 / tau).exp();
        let warm_x0 = mean_power(&segments).map(|p| p * f);
        assert_eq!(
            effective_power(&segments, tau, ThermalStart::WarmUpMin(20.0)),
            effective_power_from(&segments, tau, warm_x0)
        );
        // Steady and warm-up starts are warm: the check is not vacuous.
        assert_ne!(
            effective_power(&segments, tau, ThermalStart::Steady)[0],
            effective_power(&segments, tau, ThermalStart::Cold)[0]
        );
        let empty = ThermalTotals::default();
        assert_eq!(empty.start_state(ThermalStart::Steady, tau), [0.0; 6]);
        assert_eq!(
            empty.start_state(ThermalStart::WarmUpMin(5.0), tau),
            [0.0; 6]
        );
    }
}
