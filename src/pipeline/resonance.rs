//! The resonance check both pipelines run: each cutting move reports its
//! spindle speed, tooth-passing frequency and predicted vibration; every
//! spindle speed whose tooth passing lies within 10 % of a natural
//! frequency is warned about once, at the end of the run, with the first
//! line at that speed, the largest vibration at that speed and its line,
//! and a spindle speed clear of every mode
//! ([`crate::process::modal::Modal::suggested_hz`]). Memory grows with the
//! number of distinct resonant speeds, not with the program.

use crate::process::modal::{Modal, Resonance};
use crate::program::interp::Warning;

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
        if let Some(s) = self
            .seen
            .iter_mut()
            .find(|s| s.rpm == rpm && s.teeth == teeth)
        {
            s.moves += 1;
            if vibration_mm > s.max_mm {
                s.max_mm = vibration_mm;
                s.max_line = line;
            }
            return;
        }
        if let Some(resonance) = modal.resonance(f_hz) {
            self.seen.push(Seen {
                rpm,
                teeth,
                resonance,
                first_line: line,
                moves: 1,
                max_mm: vibration_mm,
                max_line: line,
            });
        }
    }

    /// One warning per resonant spindle speed, in the order met, each also
    /// logged as `file:line: message`.
    pub(crate) fn warnings(&self, modal: &Modal, file: &str) -> Vec<Warning> {
        self.seen
            .iter()
            .map(|s| {
                let message = message(modal, s);
                tracing::warn!("{file}:{}: {message}", s.first_line);
                Warning {
                    line: s.first_line,
                    message,
                    count: s.moves,
                }
            })
            .collect()
    }
}

fn message(modal: &Modal, s: &Seen) -> String {
    let r = &s.resonance;
    let suggested_hz = modal.suggested_hz(r.excitation_hz);
    let teeth = f64::from(s.teeth.max(1));
    format!(
        "tooth-passing frequency {:.2} Hz ({:.0} rpm x {} teeth / 60) is within 10 % of the {} natural frequency {:.2} Hz: predicted vibration up to {:.4} mm (line {}); at {:.0} rpm the tooth passing ({:.2} Hz) is clear of every mode",
        r.excitation_hz,
        s.rpm,
        s.teeth,
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
        // No excitation, no warning.
        let mut quiet = ResonanceWatch::default();
        quiet.observe(&m, (0.0, 2, 0.0), 0.0, 1);
        assert!(quiet.warnings(&m, "p.nc").is_empty());
    }
}
