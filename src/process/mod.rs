//! Process-force models: the force the workpiece exerts ON the tool while a
//! block cuts, machine independent (machine tools use it at the tool tip,
//! robots as the force part of a wrench at the tool centre point).
//!
//! Every model answers one question per block, [`ForceModel::load`]: given
//! the cutting state of the block ([`CutState`]: direction of travel, tool
//! axis, feed, spindle speed, milling engagement), what is the mean force on
//! the tool (N, workpiece frame), the cutting power at the spindle (W), the
//! tooth-passing frequency (Hz) and the complex amplitude of the force at
//! that frequency (the dynamic excitation)? Models:
//!
//! * [`ForceModel::Constant`] — a fixed vector in the workpiece, tool or feed
//!   frame, on feed moves only;
//! * [`ForceModel::Milling`] — mechanistic average forces (Altintas) from
//!   specific cutting and edge coefficients, with the feed per tooth from the
//!   program's F and S;
//! * [`ForceModel::Drilling`] — thrust along the tool axis from the feed per
//!   revolution, on drilling moves;
//! * [`ForceModel::Table`] — per-block forces read from a CSV keyed by line.
//!
//! Frames: the *feed frame* has x tangential (along the direction of travel,
//! projected normal to the tool axis), z axial (the tool axis, from the tip
//! towards the spindle) and y = z × x (normal, to the left of the travel).
//! The *tool frame* has z along the tool axis, x the workpiece X axis made
//! normal to it (workpiece Y when X is along the tool) and y = z × x.

mod force_spec;
pub mod limits;
pub mod modal;
mod table;
mod wrench;

/// Cutting settings a program sets from a position on, by a
/// `POSTPROC MILLING` comment in its text; `None` keeps the machine
/// file's (or the command line's) value.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CutSettings {
    /// Axial depth of cut, mm.
    pub depth_mm: Option<f64>,
    /// Radial width of cut, mm.
    pub width_mm: Option<f64>,
    /// Spindle speed, 1/min.
    pub spindle_rpm: Option<f64>,
}

pub use force_spec::{ForceSpec, MAX_FORCE_N};
pub use table::ForceTable;
pub use wrench::{Wrench, WrenchFrame};

use std::f64::consts::PI;

use nalgebra::Vector3;

/// Samples per tooth period for the harmonic of the milling force.
const HARMONIC_SAMPLES: usize = 64;
/// Below this (mm/min, 1/min, unit-vector length) a quantity counts as zero.
const EPS: f64 = 1e-9;

/// Frame in which a constant force is given.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Frame {
    /// Workpiece coordinates (X, Y, Z).
    Workpiece,
    /// Tool frame: z along the tool axis (see the module doc).
    Tool,
    /// Feed frame: tangential, normal, axial (see the module doc).
    Feed,
    /// The robot base frame (robots only: a machine tool's file and flags
    /// do not take it; its workpiece axes are the machine's).
    Base,
}

impl Frame {
    /// Parses `workpiece`, `tool` or `feed`.
    pub fn parse(s: &str) -> Option<Frame> {
        match s.trim() {
            "workpiece" => Some(Frame::Workpiece),
            "tool" => Some(Frame::Tool),
            "feed" => Some(Frame::Feed),
            _ => None,
        }
    }
}

/// Mechanistic milling model (Altintas): specific cutting coefficients for
/// the tangential, radial and axial chip load and edge (rubbing)
/// coefficients, with the cutter and its default engagement. Down milling
/// (climb): the tooth leaves the cut at the full chip thickness.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Milling {
    /// Tangential cutting coefficient, N/mm².
    pub kt_n_per_mm2: f64,
    /// Radial cutting coefficient, N/mm².
    pub kr_n_per_mm2: f64,
    /// Axial cutting coefficient, N/mm².
    pub ka_n_per_mm2: f64,
    /// Tangential edge coefficient, N/mm.
    pub kte_n_per_mm: f64,
    /// Radial edge coefficient, N/mm.
    pub kre_n_per_mm: f64,
    /// Axial edge coefficient, N/mm.
    pub kae_n_per_mm: f64,
    /// Cutter diameter, mm.
    pub tool_diameter_mm: f64,
    /// Number of flutes.
    pub flutes: u32,
    /// Default axial depth of cut, mm.
    pub axial_depth_mm: f64,
    /// Default radial width of cut, mm.
    pub radial_width_mm: f64,
}

/// Forces of a milling engagement in the feed frame (see the module doc).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MillingForces {
    /// Mean force on the tool over a revolution, N.
    pub mean_n: Vector3<f64>,
    /// Mean sum of the tangential tooth forces (torque / radius), N.
    pub tangential_n: f64,
    /// Complex amplitude of the force at the tooth-passing frequency:
    /// real and imaginary parts, N (the force is `re·cos ωt + im·sin ωt`
    /// plus the mean and higher harmonics).
    pub harmonic_n: [Vector3<f64>; 2],
}

impl Milling {
    /// Entry and exit angles of a tooth (rad, from the feed-frame +y axis,
    /// clockwise) for radial width `w`, down milling.
    pub fn immersion(&self, width_mm: f64) -> (f64, f64) {
        let r = self.tool_diameter_mm / 2.0;
        let w = width_mm.clamp(0.0, self.tool_diameter_mm);
        let phi = (1.0 - w / r).clamp(-1.0, 1.0).acos();
        (PI - phi, PI)
    }

    /// Force of all teeth on the tool in the feed frame at cutter angle `phi`
    /// of tooth 0 (rad), feed per tooth `c` (mm), axial depth `a` (mm),
    /// immersion `(st, ex)`.
    fn instant(&self, phi: f64, c: f64, a: f64, st: f64, ex: f64) -> Vector3<f64> {
        let n = self.flutes.max(1);
        let pitch = 2.0 * PI / f64::from(n);
        let mut f = Vector3::zeros();
        for j in 0..n {
            let p = (phi + f64::from(j) * pitch).rem_euclid(2.0 * PI);
            if p < st || p > ex {
                continue;
            }
            let h = c * p.sin();
            let ft = self.kt_n_per_mm2 * a * h + self.kte_n_per_mm * a;
            let fr = self.kr_n_per_mm2 * a * h + self.kre_n_per_mm * a;
            let fa = self.ka_n_per_mm2 * a * h + self.kae_n_per_mm * a;
            f += Vector3::new(
                -ft * p.cos() - fr * p.sin(),
                ft * p.sin() - fr * p.cos(),
                fa,
            );
        }
        f
    }

    /// Mean forces (closed form), mean tangential force and the first
    /// harmonic at the tooth-passing frequency (sampled over one tooth
    /// period) for feed per tooth `c`, axial depth `a` and radial width `w`
    /// (mm). No allocation.
    pub fn forces(&self, c: f64, a: f64, w: f64) -> MillingForces {
        let (st, ex) = self.immersion(w);
        let n = f64::from(self.flutes.max(1));
        let (kt, kr, ka) = (self.kt_n_per_mm2, self.kr_n_per_mm2, self.ka_n_per_mm2);
        let (kte, kre, kae) = (self.kte_n_per_mm, self.kre_n_per_mm, self.kae_n_per_mm);
        let cut = |p: f64| {
            Vector3::new(
                n * a * c / (8.0 * PI) * (kt * (2.0 * p).cos() - kr * (2.0 * p - (2.0 * p).sin()))
                    + n * a / (2.0 * PI) * (-kte * p.sin() + kre * p.cos()),
                n * a * c / (8.0 * PI) * (kt * (2.0 * p - (2.0 * p).sin()) + kr * (2.0 * p).cos())
                    - n * a / (2.0 * PI) * (kte * p.cos() + kre * p.sin()),
                n * a / (2.0 * PI) * (-ka * c * p.cos() + kae * p),
            )
        };
        let mean_n = cut(ex) - cut(st);
        let tangential_n = n * a / (2.0 * PI) * (kt * c * (st.cos() - ex.cos()) + kte * (ex - st));
        let pitch = 2.0 * PI / n;
        let mut re = Vector3::zeros();
        let mut im = Vector3::zeros();
        for k in 0..HARMONIC_SAMPLES {
            let u = k as f64 / HARMONIC_SAMPLES as f64;
            let f = self.instant(u * pitch, c, a, st, ex);
            let wt = 2.0 * PI * u;
            re += f * wt.cos();
            im += f * wt.sin();
        }
        let s = 2.0 / HARMONIC_SAMPLES as f64;
        MillingForces {
            mean_n,
            tangential_n,
            harmonic_n: [re * s, im * s],
        }
    }
}

/// Drilling thrust model: `F = K · (D/2) · f_rev` along the tool axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Drilling {
    /// Thrust coefficient K, N/mm².
    pub thrust_coefficient_n_per_mm2: f64,
    /// Drill diameter D, mm.
    pub drill_diameter_mm: f64,
}

impl Drilling {
    /// Thrust force for a feed per revolution (mm), N.
    pub fn thrust_n(&self, feed_per_rev_mm: f64) -> f64 {
        self.thrust_coefficient_n_per_mm2 * self.drill_diameter_mm / 2.0 * feed_per_rev_mm
    }
}

/// A process-force model, of either machine kind.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ForceModel {
    /// A fixed force (and moment) on the tool, on feed moves only. A
    /// machine tool takes the force at the tool tip and no moment.
    Constant {
        /// Force components in `frame`, N.
        force_n: Vector3<f64>,
        /// Moment components in `frame`, N·mm (zero on machine tools).
        moment_nmm: Vector3<f64>,
        /// Frame of the components.
        frame: Frame,
    },
    /// Mechanistic milling forces.
    Milling(Milling),
    /// Drilling thrust along the tool axis on drilling moves.
    Drilling {
        /// Thrust model `F = K · (D/2) · f_rev`.
        drill: Drilling,
        /// Largest feed per revolution taken as drilling, mm/rev (machine
        /// tools: unbounded, a drilling move is a cycle feed or a feed along
        /// the tool axis).
        max_feed_mm_per_rev: f64,
    },
    /// Per-line forces from the run's force table ([`ForceTable`],
    /// workpiece frame), given per run with `--force-table FILE`.
    Table,
}

impl ForceModel {
    /// A constant force without moment.
    pub fn constant(force_n: Vector3<f64>, frame: Frame) -> Self {
        ForceModel::Constant {
            force_n,
            moment_nmm: Vector3::zeros(),
            frame,
        }
    }

    /// Drilling with no feed-per-revolution limit (machine tools).
    pub fn drilling(drill: Drilling) -> Self {
        ForceModel::Drilling {
            drill,
            max_feed_mm_per_rev: f64::INFINITY,
        }
    }
}

/// The cutting state of one block, as the force models need it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CutState {
    /// Source line of the block (the key of a force table).
    pub line: usize,
    /// The block is a feed move (G1/G2/G3 or a canned-cycle feed).
    pub cutting: bool,
    /// The block is a drilling move (cycle feed or feed along the tool axis).
    pub drilling: bool,
    /// Unit direction of travel of the tool relative to the workpiece
    /// (workpiece frame; zero when not moving).
    pub feed_dir: Vector3<f64>,
    /// Unit tool axis, from the tip towards the spindle (workpiece frame).
    pub tool_axis: Vector3<f64>,
    /// Feed rate, mm/min.
    pub feed_mm_min: f64,
    /// Spindle speed, 1/min (0 when stopped).
    pub spindle_rpm: f64,
    /// Axial depth of cut set by the program (overrides the model's), mm.
    pub depth_mm: Option<f64>,
    /// Radial width of cut set by the program (overrides the model's), mm.
    pub width_mm: Option<f64>,
}

/// What a force model predicts for one block.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ProcessLoad {
    /// Mean force on the tool from the workpiece, workpiece frame, N.
    pub force_n: Vector3<f64>,
    /// Cutting power at the spindle, W.
    pub cutting_power_w: f64,
    /// Tooth-passing frequency, Hz (0 without a milling engagement).
    pub tooth_hz: f64,
    /// Complex force amplitude at the tooth-passing frequency (real,
    /// imaginary), workpiece frame, N.
    pub harmonic_n: [Vector3<f64>; 2],
}

/// Remembers the last milling evaluation, so a run of blocks with the same
/// feed per tooth and engagement costs one evaluation.
#[derive(Debug, Clone, Copy, Default)]
pub struct MillingCache {
    key: Option<[f64; 3]>,
    value: MillingForces,
}

/// Orthonormal basis (x, y, z) with z = `axis` and x the projection of
/// `toward` normal to it (`fallback` when `toward` is along the axis).
/// Largest angle between a feed direction and the tool axis at which the
/// feed counts as axial (a plunge or a retract, no feed across the cutter),
/// rad. A compensated program tilts such moves by a few micrometres over
/// their length, which must not turn them into side cuts.
pub const AXIAL_FEED_RAD: f64 = 0.01;

fn basis(
    axis: &Vector3<f64>,
    toward: &Vector3<f64>,
    fallback: &Vector3<f64>,
) -> Option<[Vector3<f64>; 3]> {
    let z = axis.try_normalize(EPS)?;
    let x = (toward - z * z.dot(toward))
        .try_normalize(AXIAL_FEED_RAD.sin())
        .or_else(|| (fallback - z * z.dot(fallback)).try_normalize(1e-6))?;
    Some([x, z.cross(&x), z])
}

fn to_workpiece(b: &[Vector3<f64>; 3], v: &Vector3<f64>) -> Vector3<f64> {
    b[0] * v[0] + b[1] * v[1] + b[2] * v[2]
}

impl ForceModel {
    /// Predicted load of one block, with the run's force table `table`
    /// for [`ForceModel::Table`]. Zero on rapids and without motion.
    pub fn load(
        &self,
        s: &CutState,
        cache: &mut MillingCache,
        table: Option<&ForceTable>,
    ) -> ProcessLoad {
        let mut out = ProcessLoad::default();
        match self {
            ForceModel::Constant { force_n, frame, .. } => {
                if !s.cutting {
                    return out;
                }
                out.force_n = match frame {
                    Frame::Workpiece | Frame::Base => *force_n,
                    Frame::Tool => match basis(&s.tool_axis, &Vector3::x(), &Vector3::y()) {
                        Some(b) => to_workpiece(&b, force_n),
                        None => Vector3::zeros(),
                    },
                    Frame::Feed => match basis(&s.tool_axis, &s.feed_dir, &Vector3::x()) {
                        Some(b) => to_workpiece(&b, force_n),
                        None => Vector3::zeros(),
                    },
                };
            }
            ForceModel::Milling(m) => {
                if !s.cutting || s.spindle_rpm <= EPS || s.feed_mm_min <= EPS || s.drilling {
                    return out;
                }
                let Some(b) = basis(&s.tool_axis, &s.feed_dir, &Vector3::zeros()) else {
                    return out;
                };
                let n = f64::from(m.flutes.max(1));
                let c = s.feed_mm_min / (s.spindle_rpm * n);
                let a = s.depth_mm.unwrap_or(m.axial_depth_mm);
                let w = s.width_mm.unwrap_or(m.radial_width_mm);
                let key = [c, a, w];
                if cache.key != Some(key) {
                    cache.value = m.forces(c, a, w);
                    cache.key = Some(key);
                }
                let f = &cache.value;
                out.force_n = to_workpiece(&b, &f.mean_n);
                out.harmonic_n = [
                    to_workpiece(&b, &f.harmonic_n[0]),
                    to_workpiece(&b, &f.harmonic_n[1]),
                ];
                let vc_m_s = PI * m.tool_diameter_mm * s.spindle_rpm / 60_000.0;
                out.cutting_power_w = f.tangential_n * vc_m_s;
                out.tooth_hz = s.spindle_rpm * n / 60.0;
            }
            ForceModel::Drilling {
                drill,
                max_feed_mm_per_rev,
            } => {
                if !s.drilling || s.spindle_rpm <= EPS {
                    return out;
                }
                let f_rev = s.feed_mm_min / s.spindle_rpm;
                if f_rev > *max_feed_mm_per_rev {
                    return out;
                }
                if let Some(z) = s.tool_axis.try_normalize(EPS) {
                    out.force_n = z * drill.thrust_n(f_rev);
                }
            }
            ForceModel::Table => {
                if let Some(f) = table.and_then(|t| t.get(s.line)) {
                    out.force_n = f;
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    const FORCE_TOL_N: f64 = 1e-9;
    /// The sampled harmonic integrates a piecewise-smooth force with 64
    /// samples per tooth period.
    const SAMPLED_TOL_N: f64 = 1e-6;

    fn mill(flutes: u32) -> Milling {
        Milling {
            kt_n_per_mm2: 2000.0,
            kr_n_per_mm2: 800.0,
            ka_n_per_mm2: 300.0,
            kte_n_per_mm: 20.0,
            kre_n_per_mm: 10.0,
            kae_n_per_mm: 5.0,
            tool_diameter_mm: 10.0,
            flutes,
            axial_depth_mm: 2.0,
            radial_width_mm: 10.0,
        }
    }

    fn state() -> CutState {
        CutState {
            line: 7,
            cutting: true,
            drilling: false,
            feed_dir: Vector3::x(),
            tool_axis: Vector3::z(),
            feed_mm_min: 400.0,
            spindle_rpm: 1000.0,
            depth_mm: None,
            width_mm: None,
        }
    }

    #[test]
    fn slot_mean_forces_match_the_closed_form() {
        // Full slot (φst = 0, φex = π), N = 2, a = 2 mm, c = 0.1 mm:
        //   Fx = −N a c Kr/4 − N a Kre/π = −2·2·0.1·800/4 − 2·2·10/π = −80 − 12.7324
        //   Fy = N a c Kt/4 + N a Kte/π = 2·2·0.1·2000/4 + 2·2·20/π = 200 + 25.4648
        //   Fz = N a c Ka/π + N a Kae/2 = 2·2·0.1·300/π + 2·2·5/2 = 38.1972 + 10
        //   Ft = N a/(2π)·(Kt c·2 + Kte·π) = 2·2/(2π)·(400 + 20π) = 254.6479 + 40
        let f = mill(2).forces(0.1, 2.0, 10.0);
        assert_abs_diff_eq!(f.mean_n[0], -80.0 - 40.0 / PI, epsilon = FORCE_TOL_N);
        assert_abs_diff_eq!(f.mean_n[1], 200.0 + 80.0 / PI, epsilon = FORCE_TOL_N);
        assert_abs_diff_eq!(f.mean_n[2], 120.0 / PI + 10.0, epsilon = FORCE_TOL_N);
        assert_abs_diff_eq!(f.tangential_n, 800.0 / PI + 40.0, epsilon = FORCE_TOL_N);
    }

    #[test]
    fn sampled_force_averages_to_the_closed_form_mean() {
        // Independent check of the instantaneous force: its average over a
        // tooth period (fine sampling) equals the closed-form mean, for a
        // partial immersion.
        let m = mill(3);
        let (st, ex) = m.immersion(4.0);
        let n = 20_000;
        let pitch = 2.0 * PI / 3.0;
        let mut sum = Vector3::zeros();
        for k in 0..n {
            sum += m.instant((k as f64 + 0.5) / n as f64 * pitch, 0.08, 3.0, st, ex);
        }
        let f = m.forces(0.08, 3.0, 4.0);
        // Down milling enters at full chip thickness, so the integrand jumps
        // (by at most ~300 N here); the midpoint rule then errs by at most
        // jump × step = 300 · (2π/3)/20000 ≈ 0.03 N.
        const SAMPLED_MEAN_TOL_N: f64 = 0.05;
        assert_abs_diff_eq!(sum / n as f64, f.mean_n, epsilon = SAMPLED_MEAN_TOL_N);
    }

    #[test]
    fn four_flute_slot_without_radial_or_edge_load_has_no_harmonic() {
        // N = 4 in a slot with Kr = Kte = Kre = Kae = Ka = 0: two teeth at φ and
        // φ + π/2 are in the cut, Fx = −Kt a c (sinφ cosφ − cosφ sinφ) = 0 and
        // Fy = Kt a c (sin²φ + cos²φ) = Kt a c: constant, so no harmonic, and
        // the mean Fy = 2000·2·0.1 = 400 N.
        let mut m = mill(4);
        m.kr_n_per_mm2 = 0.0;
        m.ka_n_per_mm2 = 0.0;
        m.kte_n_per_mm = 0.0;
        m.kre_n_per_mm = 0.0;
        m.kae_n_per_mm = 0.0;
        let f = m.forces(0.1, 2.0, 10.0);
        assert_abs_diff_eq!(f.mean_n[1], 400.0, epsilon = FORCE_TOL_N);
        assert_abs_diff_eq!(f.harmonic_n[0].norm(), 0.0, epsilon = SAMPLED_TOL_N);
        assert_abs_diff_eq!(f.harmonic_n[1].norm(), 0.0, epsilon = SAMPLED_TOL_N);
    }

    #[test]
    fn one_flute_half_immersion_harmonic_is_nonzero() {
        // A single tooth cuts only part of the revolution: the force pulses
        // once per revolution, so its fundamental is not zero.
        let f = mill(1).forces(0.1, 2.0, 5.0);
        assert!(f.harmonic_n[0].norm() + f.harmonic_n[1].norm() > 1.0);
    }

    #[test]
    fn milling_rotates_the_feed_frame_into_the_workpiece() {
        // Travel along −Y with the tool along +Z: feed x = −Y, normal y =
        // z × x = +X. Slot forces (N = 2, c = 400/(1000·2) = 0.2 mm):
        //   Fx_feed = −2·2·0.2·800/4 − 40/π = −160 − 12.7324
        //   Fy_feed = 2·2·0.2·2000/4 + 80/π = 400 + 25.4648
        // so the workpiece force is (Fy_feed, −Fx_feed, Fz).
        let m = ForceModel::Milling(mill(2));
        let mut s = state();
        s.feed_dir = -Vector3::y();
        let mut cache = MillingCache::default();
        let l = m.load(&s, &mut cache, None);
        assert_abs_diff_eq!(l.force_n[0], 400.0 + 80.0 / PI, epsilon = FORCE_TOL_N);
        assert_abs_diff_eq!(l.force_n[1], 160.0 + 40.0 / PI, epsilon = FORCE_TOL_N);
        // Tooth passing: 1000 rpm · 2 / 60.
        assert_abs_diff_eq!(l.tooth_hz, 2000.0 / 60.0, epsilon = FORCE_TOL_N);
        // Power: Ft = 2·2/(2π)(2000·0.2·2 + 20π) = 1600/π + 40 N at
        // v_c = π·10·1000/60000 m/s → (1600/π + 40)·π/6 W.
        assert_abs_diff_eq!(
            l.cutting_power_w,
            (1600.0 / PI + 40.0) * PI / 6.0,
            epsilon = FORCE_TOL_N
        );
        // Rapids and stopped spindles cut nothing.
        s.cutting = false;
        assert_eq!(m.load(&s, &mut cache, None), ProcessLoad::default());
    }

    #[test]
    fn constant_force_frames() {
        let f = Vector3::new(10.0, 20.0, 30.0);
        let mut cache = MillingCache::default();
        let mut s = state();
        s.feed_dir = Vector3::y();
        let wp = ForceModel::constant(f, Frame::Workpiece);
        assert_abs_diff_eq!(
            wp.load(&s, &mut cache, None).force_n,
            f,
            epsilon = FORCE_TOL_N
        );
        // Feed frame, travel along +Y, tool along +Z: tangential = +Y,
        // normal = z × y = −X, axial = +Z → (−20, 10, 30).
        let feed = ForceModel::constant(f, Frame::Feed);
        assert_abs_diff_eq!(
            feed.load(&s, &mut cache, None).force_n,
            Vector3::new(-20.0, 10.0, 30.0),
            epsilon = FORCE_TOL_N
        );
        // Tool frame with the tool along +X (horizontal spindle): z = +X,
        // x = workpiece Y (X is along the tool), y = z × x = X × Y = +Z →
        // (30, 10, 20).
        s.tool_axis = Vector3::x();
        let tool = ForceModel::constant(f, Frame::Tool);
        assert_abs_diff_eq!(
            tool.load(&s, &mut cache, None).force_n,
            Vector3::new(30.0, 10.0, 20.0),
            epsilon = FORCE_TOL_N
        );
        s.cutting = false;
        assert_eq!(wp.load(&s, &mut cache, None).force_n, Vector3::zeros());
    }

    #[test]
    fn drilling_thrust() {
        // K = 1500 N/mm², D = 8 mm, f_rev = 200/1000 = 0.2 mm:
        // F = 1500 · 4 · 0.2 = 1200 N along +Z (pushing the drill back).
        let m = ForceModel::drilling(Drilling {
            thrust_coefficient_n_per_mm2: 1500.0,
            drill_diameter_mm: 8.0,
        });
        let mut s = state();
        s.feed_mm_min = 200.0;
        s.drilling = true;
        let mut cache = MillingCache::default();
        assert_abs_diff_eq!(
            m.load(&s, &mut cache, None).force_n,
            Vector3::new(0.0, 0.0, 1200.0),
            epsilon = FORCE_TOL_N
        );
        // Above a feed-per-revolution limit the move is not drilling.
        let limited = ForceModel::Drilling {
            drill: Drilling {
                thrust_coefficient_n_per_mm2: 1500.0,
                drill_diameter_mm: 8.0,
            },
            max_feed_mm_per_rev: 0.1,
        };
        assert_eq!(limited.load(&s, &mut cache, None).force_n, Vector3::zeros());
        s.drilling = false;
        assert_eq!(m.load(&s, &mut cache, None).force_n, Vector3::zeros());
    }

    #[test]
    fn thrust_sensitivity_matches_finite_differences() {
        let d = Drilling {
            thrust_coefficient_n_per_mm2: 1500.0,
            drill_diameter_mm: 8.0,
        };
        // dF/df_rev = K·D/2 = 6000 N/mm.
        let h = 1e-6;
        let fd = (d.thrust_n(0.2 + h) - d.thrust_n(0.2 - h)) / (2.0 * h);
        assert_abs_diff_eq!(fd, 6000.0, epsilon = 1e-4);
    }

    #[test]
    fn milling_mean_force_sensitivity_to_feed_per_tooth_matches_finite_differences() {
        // The mean force is affine in c: dFy/dc = N a Kt/4 in a slot
        // = 2·2·2000/4 = 2000 N/mm.
        let m = mill(2);
        let h = 1e-6;
        let fd =
            (m.forces(0.1 + h, 2.0, 10.0).mean_n - m.forces(0.1 - h, 2.0, 10.0).mean_n) / (2.0 * h);
        assert_abs_diff_eq!(fd[1], 2000.0, epsilon = 1e-3);
        assert_abs_diff_eq!(fd[0], -2.0 * 2.0 * 800.0 / 4.0, epsilon = 1e-3);
    }
}
