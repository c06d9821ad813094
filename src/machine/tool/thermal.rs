//! Thermal drift of a machine tool over time (docs/physics.md): heat sources
//! (the spindle and the feed drive of each linear axis) with a power
//! estimated per block, each driving one error parameter through a
//! first-order response
//!
//! ```text
//! τ · dy/dt = G · P(t) − y        (y: error parameter, G: steady-state gain)
//! ```
//!
//! integrated exactly over each block (power constant within a block):
//! `y₁ = G·P + (y₀ − G·P) · exp(−Δt/τ)`.
//!
//! Error parameters:
//! * spindle growth `g` (µm), gain `growth_um_per_kw`: the spindle lengthens
//!   towards the workpiece, the tip moves by `−g` along the tool axis;
//! * axis positioning scale `s_i` (ppm), gain `scale_ppm_per_kw`: the axis
//!   overshoots its machine coordinate by `s_i · 10⁻⁶ · (q_i − o_i)`, with
//!   `o_i` the axis' scale origin (`scale_origin_mm`, default 0): the
//!   machine coordinate of the point the scale grows from (where the screw
//!   is held, or where the axis was at the reference measurement).
//!
//! Powers: spindle `P_s = idle_w_per_rpm · n + P_cut` (cutting power from
//! the process model); feed drive of axis i `P_i = (|F_i| + friction_n) · |v_i|`
//! with `F_i` the process force along the axis and `v_i` the axis speed.

use nalgebra::Vector3;

use super::raw::RawThermal;
use crate::error::Invalid;

/// A heat source with its error parameter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Source {
    /// Steady-state gain: µm per kW (spindle) or ppm per kW (axes).
    pub gain_per_kw: f64,
    /// Time constant, s.
    pub time_constant_s: f64,
}

impl Source {
    /// Value after `dt_s` at constant power `p_w`, starting from `y0`.
    pub fn step(&self, y0: f64, p_w: f64, dt_s: f64) -> f64 {
        let ss = self.gain_per_kw * p_w / 1000.0;
        if dt_s <= 0.0 {
            return y0;
        }
        ss + (y0 - ss) * (-dt_s / self.time_constant_s).exp()
    }

    /// Steady-state value at constant power.
    pub fn steady(&self, p_w: f64) -> f64 {
        self.gain_per_kw * p_w / 1000.0
    }
}

/// Powers of the heat sources of one block, W: spindle, then X, Y, Z drives.
pub type Powers = [f64; 4];

/// The thermal error parameters at one instant.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ThermalState {
    /// Spindle growth, µm.
    pub growth_um: f64,
    /// Positioning scale error of X, Y, Z, ppm.
    pub scale_ppm: [f64; 3],
}

/// Validated thermal model.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Thermal {
    /// Spindle source (growth along the tool axis).
    pub spindle: Option<Source>,
    /// Idle spindle power per rpm, W.
    pub idle_w_per_rpm: f64,
    /// Feed-drive source of X, Y, Z (positioning scale).
    pub axes: [Option<Source>; 3],
    /// Friction force of each feed drive, N.
    pub friction_n: [f64; 3],
    /// Machine coordinate (mm) of X, Y, Z from which each axis' scale
    /// error grows (`scale_origin_mm`, default 0).
    pub scale_origin_mm: [f64; 3],
}

impl Thermal {
    /// Powers of one block: spindle speed (1/min), cutting power (W),
    /// process force on the tool (N), axis speeds (mm/min, signed).
    pub fn powers(
        &self,
        spindle_rpm: f64,
        cutting_power_w: f64,
        force_n: &Vector3<f64>,
        axis_mm_min: &Vector3<f64>,
    ) -> Powers {
        let mut p = [0.0; 4];
        if self.spindle.is_some() {
            p[0] = self.idle_w_per_rpm * spindle_rpm.max(0.0) + cutting_power_w.max(0.0);
        }
        for i in 0..3 {
            if self.axes[i].is_some() {
                let v_m_s = axis_mm_min[i].abs() / 60_000.0;
                p[i + 1] = (force_n[i].abs() + self.friction_n[i]) * v_m_s;
            }
        }
        p
    }

    /// State after `dt_s` seconds at constant powers.
    pub fn step(&self, s: &ThermalState, p: &Powers, dt_s: f64) -> ThermalState {
        let mut o = *s;
        if let Some(src) = &self.spindle {
            o.growth_um = src.step(s.growth_um, p[0], dt_s);
        }
        for i in 0..3 {
            if let Some(src) = &self.axes[i] {
                o.scale_ppm[i] = src.step(s.scale_ppm[i], p[i + 1], dt_s);
            }
        }
        o
    }

    /// State after warming up from cold for `minutes` at constant powers
    /// (`f64::INFINITY`: the steady state).
    pub fn warm_up(&self, p: &Powers, minutes: f64) -> ThermalState {
        if minutes.is_infinite() {
            let mut o = ThermalState::default();
            if let Some(src) = &self.spindle {
                o.growth_um = src.steady(p[0]);
            }
            for i in 0..3 {
                if let Some(src) = &self.axes[i] {
                    o.scale_ppm[i] = src.steady(p[i + 1]);
                }
            }
            return o;
        }
        self.step(&ThermalState::default(), p, minutes * 60.0)
    }

    /// Tool-tip deviation (mm) of a state at machine position `q` (mm) with
    /// the unit tool axis `dir` (tip → spindle).
    pub fn deviation_mm(
        &self,
        s: &ThermalState,
        q: &Vector3<f64>,
        dir: &Vector3<f64>,
    ) -> Vector3<f64> {
        let mut d = -dir * (s.growth_um * 1e-3);
        for i in 0..3 {
            d[i] += s.scale_ppm[i] * 1e-6 * (q[i] - self.scale_origin_mm[i]);
        }
        d
    }

    /// Validates the `thermal:` block.
    pub(crate) fn from_raw(
        raw: &RawThermal,
        has_axis: impl Fn(usize) -> bool,
    ) -> Result<Self, Invalid> {
        let tau = |path: &str, v: f64| {
            if v.is_finite() && v > 0.0 && v <= 1e5 {
                Ok(v * 60.0)
            } else {
                Err(Invalid::new(
                    path,
                    format!("time constant `{v}` min must be within (0, 100000]"),
                ))
            }
        };
        let gain = |path: &str, v: f64, max: f64| {
            if v.is_finite() && v.abs() <= max {
                Ok(v)
            } else {
                Err(Invalid::new(
                    path,
                    format!("gain `{v}` is outside ±{max} (check the unit)"),
                ))
            }
        };
        let mut t = Thermal::default();
        if let Some(s) = &raw.spindle {
            t.spindle = Some(Source {
                gain_per_kw: gain(
                    "thermal.spindle.growth_um_per_kw",
                    s.growth_um_per_kw,
                    1000.0,
                )?,
                time_constant_s: tau("thermal.spindle.time_constant_min", s.time_constant_min)?,
            });
            let idle = s.idle_w_per_rpm;
            if !idle.is_finite() || !(0.0..=100.0).contains(&idle) {
                return Err(Invalid::new(
                    "thermal.spindle.idle_w_per_rpm",
                    format!("`{idle}` W per rpm is outside 0..100"),
                ));
            }
            t.idle_w_per_rpm = idle;
        }
        for (name, a) in &raw.axes {
            let p = format!("thermal.axes.{name}");
            let slot = match name.as_str() {
                "X" => 0,
                "Y" => 1,
                "Z" => 2,
                _ => {
                    return Err(Invalid::new(
                        p,
                        format!("unknown axis `{name}` (expected X, Y or Z)"),
                    ));
                }
            };
            if !has_axis(slot) {
                return Err(Invalid::new(p, format!("the machine has no {name} axis")));
            }
            let friction = a.friction_n;
            if !friction.is_finite() || !(0.0..=1e5).contains(&friction) {
                return Err(Invalid::new(
                    format!("{p}.friction_n"),
                    format!("`{friction}` N is outside 0..100000"),
                ));
            }
            t.friction_n[slot] = friction;
            let origin = a.scale_origin_mm.unwrap_or(0.0);
            if !origin.is_finite() || origin.abs() > 1e5 {
                return Err(Invalid::new(
                    format!("{p}.scale_origin_mm"),
                    format!("`{origin}` mm is outside ±100000"),
                ));
            }
            t.scale_origin_mm[slot] = origin;
            t.axes[slot] = Some(Source {
                gain_per_kw: gain(&format!("{p}.scale_ppm_per_kw"), a.scale_ppm_per_kw, 1e4)?,
                time_constant_s: tau(&format!("{p}.time_constant_min"), a.time_constant_min)?,
            });
        }
        Ok(t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    const UM_TOL: f64 = 1e-12;

    fn model() -> Thermal {
        Thermal {
            spindle: Some(Source {
                gain_per_kw: 10.0,
                time_constant_s: 600.0,
            }),
            idle_w_per_rpm: 0.1,
            axes: [
                Some(Source {
                    gain_per_kw: 50.0,
                    time_constant_s: 1200.0,
                }),
                None,
                None,
            ],
            friction_n: [100.0, 0.0, 0.0],
            scale_origin_mm: [0.0; 3],
        }
    }

    #[test]
    fn first_order_response() {
        let t = model();
        // 10000 rpm idle: 1 kW → steady 10 µm; after one τ: 10(1 − e⁻¹).
        let p = t.powers(10_000.0, 0.0, &Vector3::zeros(), &Vector3::zeros());
        assert_abs_diff_eq!(p[0], 1000.0, epsilon = UM_TOL);
        let s = t.step(&ThermalState::default(), &p, 600.0);
        assert_abs_diff_eq!(
            s.growth_um,
            10.0 * (1.0 - (-1.0f64).exp()),
            epsilon = UM_TOL
        );
        // Two half-τ steps equal one τ step (exact integration).
        let h = t.step(&t.step(&ThermalState::default(), &p, 300.0), &p, 300.0);
        assert_abs_diff_eq!(h.growth_um, s.growth_um, epsilon = UM_TOL);
        // Cooling at zero power: decays by e⁻¹ per τ.
        let c = t.step(&s, &[0.0; 4], 600.0);
        assert_abs_diff_eq!(c.growth_um, s.growth_um * (-1.0f64).exp(), epsilon = UM_TOL);
        // Warm-up and steady state.
        assert_abs_diff_eq!(t.warm_up(&p, 10.0).growth_um, s.growth_um, epsilon = UM_TOL);
        assert_abs_diff_eq!(
            t.warm_up(&p, f64::INFINITY).growth_um,
            10.0,
            epsilon = UM_TOL
        );
    }

    #[test]
    fn drive_power_and_deviation() {
        let t = model();
        // X at 6000 mm/min = 0.1 m/s with 400 N process force + 100 N
        // friction: 50 W.
        let p = t.powers(
            0.0,
            0.0,
            &Vector3::new(-400.0, 0.0, 0.0),
            &Vector3::new(6000.0, 0.0, 0.0),
        );
        assert_abs_diff_eq!(p[1], 50.0, epsilon = UM_TOL);
        assert_abs_diff_eq!(p[0], 0.0, epsilon = UM_TOL);
        // 20 ppm at X = 500 mm: +10 µm; growth 5 µm with the tool along +Z:
        // −5 µm in Z.
        let s = ThermalState {
            growth_um: 5.0,
            scale_ppm: [20.0, 0.0, 0.0],
        };
        let d = t.deviation_mm(&s, &Vector3::new(500.0, 0.0, 0.0), &Vector3::z());
        assert_abs_diff_eq!(d, Vector3::new(0.010, 0.0, -0.005), epsilon = UM_TOL);
    }

    /// The scale grows from `scale_origin_mm`: 20 ppm on X with the origin
    /// at X = −300 gives 20e-6 · (500 − (−300)) = 16 µm at X = 500, and
    /// nothing at the origin itself.
    #[test]
    fn the_scale_grows_from_its_origin() {
        let mut t = model();
        t.scale_origin_mm = [-300.0, 0.0, 0.0];
        let s = ThermalState {
            growth_um: 0.0,
            scale_ppm: [20.0, 0.0, 0.0],
        };
        let d = t.deviation_mm(&s, &Vector3::new(500.0, 0.0, 0.0), &Vector3::z());
        assert_abs_diff_eq!(d, Vector3::new(0.016, 0.0, 0.0), epsilon = UM_TOL);
        let at = t.deviation_mm(&s, &Vector3::new(-300.0, 0.0, 0.0), &Vector3::z());
        assert_abs_diff_eq!(at, Vector3::zeros(), epsilon = UM_TOL);
    }

    #[test]
    fn response_slope_matches_finite_differences() {
        // dy/dt at y0 = 0 under power P: G·P/τ = 10 µm / 600 s.
        let src = model().spindle.unwrap_or(Source {
            gain_per_kw: 0.0,
            time_constant_s: 1.0,
        });
        let h = 1e-3;
        let fd = (src.step(0.0, 1000.0, h) - src.step(0.0, 1000.0, 0.0)) / h;
        assert_abs_diff_eq!(fd, 10.0 / 600.0, epsilon = 1e-6);
    }
}
