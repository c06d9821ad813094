//! The resonance check both pipelines run: each cutting move reports its
//! spindle speed, tooth-passing frequency and predicted vibration; every
//! spindle speed whose tooth passing lies within 10 % of a natural
//! frequency is warned about once, at the end of the run, with the first
//! line at that speed, the largest vibration at that speed and its line,
//! and a spindle speed clear of every mode
//! ([`crate::process::modal::Modal::suggested_hz`]). At most
//! [`MAX_SPEEDS`] speeds are warned about one by one; the others are
//! counted in one last warning, so memory and time per move stay bounded
//! whatever the program.

use crate::process::modal::{Modal, RESONANCE_BAND, Resonance};
use crate::program::interp::Warning;

/// Resonant spindle speeds warned about one by one.
pub(crate) const MAX_SPEEDS: usize = 32;

/// One resonant spindle speed and what the moves at it showed.
#[derive(Debug, Clone, Copy)]
struct Seen {
    rpm: f64,
    teeth: u32,
    resonance: Resonance,
    first_line: usize,
    moves: usize,
    max_mm: f64,
    max_line: usize,
}

/// The resonant spindle speeds met so far.
#[derive(Debug, Clone, Default)]
pub(crate) struct ResonanceWatch {
    seen: Vec<Seen>,
    /// The entry of the last move's speed (moves mostly keep their speed).
    last: Option<usize>,
    /// Resonant speeds beyond [`MAX_SPEEDS`]: how many, the first line and
    /// how many moves.
    more: (usize, usize, usize),
    /// The last speed counted in `more`.
    more_last: Option<(f64, u32)>,
}

impl ResonanceWatch {
    /// One cutting move at `rpm` with `teeth` cutting edges: its tooth
    /// passing `f_hz` and its predicted vibration amplitude `vibration_mm`.
    pub(crate) fn observe(
        &mut self,
        modal: &Modal,
        (rpm, teeth, f_hz): (f64, u32, f64),
        vibration_mm: f64,
        line: usize,
    ) {
        if f_hz.is_nan() || f_hz <= 0.0 {
            return;
        }
        let same = |s: &Seen| s.rpm == rpm && s.teeth == teeth;
        let at = match self.last.filter(|&i| self.seen.get(i).is_some_and(same)) {
            Some(i) => Some(i),
            None => self.seen.iter().position(same),
        };
        if let Some(i) = at {
            self.last = Some(i);
            let s = &mut self.seen[i];
            s.moves += 1;
            if vibration_mm > s.max_mm {
                s.max_mm = vibration_mm;
                s.max_line = line;
            }
            return;
        }
        let Some(resonance) = modal.resonance(f_hz) else {
            return;
        };
        if self.seen.len() < MAX_SPEEDS {
            self.last = Some(self.seen.len());
            self.seen.push(Seen {
                rpm,
                teeth,
                resonance,
                first_line: line,
                moves: 1,
                max_mm: vibration_mm,
                max_line: line,
            });
            return;
        }
        // Beyond the bound: a speed counts once per run of moves at it.
        if self.more_last != Some((rpm, teeth)) {
            self.more_last = Some((rpm, teeth));
            self.more.0 += 1;
            if self.more.1 == 0 {
                self.more.1 = line;
            }
        }
        self.more.2 += 1;
    }

    /// One warning per resonant spindle speed, in the order met, each also
    /// logged as `file:line: message`.
    pub(crate) fn warnings(&self, modal: &Modal, file: &str) -> Vec<Warning> {
        let mut out: Vec<Warning> = self
            .seen
            .iter()
            .map(|s| Warning {
                line: s.first_line,
                message: message(modal, s),
                count: s.moves,
                left: None,
            })
            .collect();
        let (speeds, line, moves) = self.more;
        if speeds > 0 {
            out.push(Warning {
                line,
                message: format!(
                    "{speeds} more changes of spindle speed resonate besides the {MAX_SPEEDS} above ({moves} moves)"
                ),
                count: moves,
                left: None,
            });
        }
        for w in &out {
            tracing::warn!("{file}:{}: {}", w.line, w.message);
        }
        out
    }
}

fn message(modal: &Modal, s: &Seen) -> String {
    let r = &s.resonance;
    let suggested_hz = modal.suggested_hz(r.excitation_hz);
    let teeth = f64::from(s.teeth.max(1));
    format!(
        "tooth-passing frequency {:.2} Hz ({:.0} rpm x {} teeth / 60) is within {:.0} % of the {} natural frequency {:.2} Hz: predicted vibration up to {:.4} mm (line {}); at {:.0} rpm the tooth passing ({:.2} Hz) is clear of every mode",
        r.excitation_hz,
        s.rpm,
        s.teeth,
        RESONANCE_BAND * 100.0,
        r.axis_letter(),
        r.natural_hz,
        s.max_mm,
        s.max_line,
        suggested_hz * 60.0 / teeth,
        suggested_hz,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::process::modal::Mode;

    fn modal60() -> Modal {
        Modal {
            modes: [
                Some(Mode {
                    natural_frequency_hz: 60.0,
                    damping_ratio: 0.05,
                    stiffness_n_per_mm: 20_000.0,
                }),
                None,
                None,
            ],
        }
    }

    #[test]
    fn once_per_speed_with_the_first_line_and_the_largest_vibration() {
        let m = modal60();
        let mut w = ResonanceWatch::default();
        // 1800 rpm x 2 teeth = 60 Hz: resonant; 3000 rpm x 2 = 100 Hz: not.
        w.observe(&m, (1800.0, 2, 60.0), 0.010, 3);
        w.observe(&m, (3000.0, 2, 100.0), 0.001, 4);
        w.observe(&m, (1800.0, 2, 60.0), 0.030, 7);
        w.observe(&m, (1800.0, 2, 60.0), 0.020, 9);
        let ws = w.warnings(&m, "p.nc");
        assert_eq!(ws.len(), 1);
        assert_eq!((ws[0].line, ws[0].count), (3, 3));
        // Suggested: 0.7 x 60 Hz = 42 Hz = 1260 rpm with 2 teeth.
        assert_eq!(
            ws[0].message,
            "tooth-passing frequency 60.00 Hz (1800 rpm x 2 teeth / 60) is within 10 % of the X natural frequency 60.00 Hz: predicted vibration up to 0.0300 mm (line 7); at 1260 rpm the tooth passing (42.00 Hz) is clear of every mode"
        );
        // Beyond MAX_SPEEDS resonant speeds, one warning counts the rest:
        // speeds 1801.. rpm all lie within 10 % of 60 Hz with 2 teeth.
        let mut many = ResonanceWatch::default();
        for k in 0..MAX_SPEEDS + 5 {
            let rpm = 1800.0 + k as f64;
            for rep in 0..2 {
                many.observe(&m, (rpm, 2, rpm * 2.0 / 60.0), 0.01, 10 + 2 * k + rep);
            }
        }
        let ws = many.warnings(&m, "p.nc");
        assert_eq!(ws.len(), MAX_SPEEDS + 1);
        let last = &ws[MAX_SPEEDS];
        assert_eq!((last.line, last.count), (10 + 2 * MAX_SPEEDS, 10));
        assert!(
            last.message.starts_with("5 more changes of spindle speed"),
            "{}",
            last.message
        );
        // No excitation, no warning.
        let mut quiet = ResonanceWatch::default();
        quiet.observe(&m, (0.0, 2, 0.0), 0.0, 1);
        assert!(quiet.warnings(&m, "p.nc").is_empty());
    }
}
