//! Per-point prediction: where the machine really puts the tool tip for a
//! commanded axis position, with each physical effect switched and scaled
//! separately (the thesis' VMSS idea), and the per-effect breakdown.
//!
//! Geometric, static and thermal effects are quasi-static: they shift the
//! attained tool tip and are compensated. The dynamic effect (vibration at
//! the tooth-passing frequency) is an amplitude, reported in the breakdown
//! but never part of the attained pose nor of [`Breakdown::total`].
//!
//! What the non-geometric effects need about the block (process force, time
//! and thermal state, spindle speed, vibration) is computed once per block in
//! program order by the job and handed over as a [`MoveContext`].

use nalgebra::Vector3;

use super::context::MoveContext;
pub use super::effect::{Breakdown, Effect, EffectSet};
use crate::machine::tool::MachineTool;
use crate::machine::{AxisVec, DirVec, TipPose};

/// The Lipschitz bound of [`ToolPredictor::lipschitz`] for one block and
/// tool length, valid on segments whose ends lie in the machine's box.
#[derive(Debug, Clone, Copy)]
pub struct LipschitzBound<'m> {
    machine: &'m MachineTool,
    l: f64,
}

impl LipschitzBound<'_> {
    /// The bound on the segment of commands `a → b` (`None` when an end
    /// leaves the box where it holds): the value of
    /// [`ToolPredictor::lipschitz`].
    #[inline]
    pub fn on(&self, a: &AxisVec, b: &AxisVec) -> Option<f64> {
        (self.machine.in_lipschitz_box(a) && self.machine.in_lipschitz_box(b)).then_some(self.l)
    }
}

/// A machine tool with the effects chosen for one run and the context of
/// one block. Immutable and `Copy`, shared by the worker threads; the job
/// makes a per-block copy with [`ToolPredictor::with_context`].
#[derive(Debug, Clone, Copy)]
pub struct ToolPredictor<'m> {
    /// The machine model.
    pub machine: &'m MachineTool,
    /// Effects and gains.
    pub effects: EffectSet,
    /// The block's context (zero: no force, cold, no vibration).
    pub ctx: MoveContext,
    /// Job-level process settings (`None`: the machine file's force model,
    /// cold start).
    pub process: Option<&'m ProcessSetup>,
    /// The uncertainty of the predictions from the machine file's
    /// parameter covariance (`None`: the file carries none, or the run
    /// does not state it).
    pub uncertainty: Option<&'m std::sync::Arc<crate::predict::uncertainty::BlockUncertainty>>,
}

/// Job-level settings of the process effects (force model, milling
/// engagement, thermal start), shared by every block of a job.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ProcessSetup {
    /// The process-force model of the job (`None`: no force).
    pub force: Option<crate::process::ForceModel>,
    /// The per-line forces of [`crate::process::ForceModel::Table`].
    pub force_table: Option<crate::process::ForceTable>,
    /// Axial depth of cut for milling until a program directive sets one, mm.
    pub milling_depth_mm: Option<f64>,
    /// Radial width of cut for milling until a program directive sets one, mm.
    pub milling_width_mm: Option<f64>,
    /// Initial thermal state.
    pub thermal_start: crate::machine::ThermalStart,
    /// Mean power of each heat source over the program (spindle, X, Y, Z),
    /// W, for the `steady` and warm-up starts.
    pub mean_power_w: Option<crate::machine::tool::thermal::Powers>,
}

impl ProcessSetup {
    /// The machine file's force model, cold start.
    pub fn for_machine(machine: &MachineTool) -> Self {
        ProcessSetup {
            force: machine.process_force().cloned(),
            ..Self::default()
        }
    }
}

impl<'m> ToolPredictor<'m> {
    /// Builds a predictor (empty context).
    pub fn new(machine: &'m MachineTool, effects: EffectSet) -> Self {
        ToolPredictor {
            machine,
            effects,
            ctx: MoveContext::default(),
            process: None,
            uncertainty: None,
        }
    }

    /// The same predictor stating the uncertainty `u` of its predictions.
    pub fn with_uncertainty(
        self,
        u: Option<&'m std::sync::Arc<crate::predict::uncertainty::BlockUncertainty>>,
    ) -> Self {
        ToolPredictor {
            uncertainty: u,
            ..self
        }
    }

    /// The same predictor with job-level process settings.
    pub fn with_process(self, process: &'m ProcessSetup) -> Self {
        ToolPredictor {
            process: Some(process),
            ..self
        }
    }

    /// The same predictor for a block with context `ctx`.
    pub fn with_context(&self, ctx: MoveContext) -> Self {
        ToolPredictor { ctx, ..*self }
    }

    /// Nominal tool tip pose for commanded axes.
    pub fn nominal(&self, cmd: &AxisVec, tool_mm: f64) -> TipPose {
        self.machine.nominal(cmd, tool_mm)
    }

    /// Static deflection (mm, unscaled) at the command; zero without a
    /// stiffness map or force.
    fn static_part(&self, cmd: &AxisVec) -> Vector3<f64> {
        match self.loaded_stiffness() {
            Some(k) => k.deflection_mm(&Vector3::new(cmd[0], cmd[1], cmd[2]), &self.ctx.force_n()),
            None => Vector3::zeros(),
        }
    }

    /// The stiffness map when the block has a process force to deflect the
    /// tool (`None` without either).
    fn loaded_stiffness(&self) -> Option<&'m crate::machine::tool::Stiffness> {
        self.machine
            .stiffness()
            .filter(|_| self.ctx.force_n() != Vector3::zeros())
    }

    /// Thermal deviation (mm, unscaled) at the command with the nominal tool
    /// axis `dir`.
    fn thermal_part(&self, cmd: &AxisVec, dir: &Vector3<f64>) -> Vector3<f64> {
        match self.machine.thermal() {
            Some(t) if self.ctx.tool_warm() => t.deviation_mm(
                &self.ctx.tool_thermal(),
                &Vector3::new(cmd[0], cmd[1], cmd[2]),
                dir,
            ),
            _ => Vector3::zeros(),
        }
    }

    /// Upper bound of the second derivative of the static deflection under
    /// the block's force along any straight line away from the stiffness
    /// grid positions (mm per mm², unscaled by the gain; 0 without a force
    /// or a stiffness map): [`crate::machine::tool::Stiffness::curvature_mm`].
    pub fn static_curvature_mm(&self) -> f64 {
        self.loaded_stiffness()
            .map_or(0.0, |k| k.curvature_mm(&self.ctx.force_n()))
    }

    /// Upper bound of `|d² attained(c).pos / ds²|` (1/mm; `s` the arc
    /// length of the commands, mm) on the straight segment of commands
    /// `a → b`, which must cross no breakpoint of the model
    /// ([`MachineTool::breakpoints`]), from bounds that hold for the whole
    /// machine (cheap, loose for long moves of several axes; see
    /// [`Self::curvature_in_cell`] for the tight one). `static_mm` is
    /// [`Self::static_curvature_mm`] (computed once per block by the
    /// caller). The sum of:
    ///
    /// * the geometric chain's: at most `K₂ · ((Σ|d_i|)² − 1)` for the unit
    ///   direction `d` of the segment, times the gain (the chain is affine
    ///   in each axis between knots, so a single moving axis does not bend
    ///   it; the nominal chain is affine on these machines);
    /// * the static deflection's, times its gain;
    /// * the thermal drift's: the scale errors are affine in the position;
    ///   the spindle growth acts along the tool axis, which bends with the
    ///   geometric errors when the geometric gain is one.
    ///
    /// `None` for machines with rotary axes, or an end outside the box of
    /// [`MachineTool::lipschitz_geo`].
    pub fn curvature(&self, a: &AxisVec, b: &AxisVec, tool_mm: f64, static_mm: f64) -> Option<f64> {
        let sg = self.machine.second_geo(a, b, tool_mm)?;
        let mut d = [0.0; 3];
        for (s, v) in d.iter_mut().enumerate() {
            *v = b[s] - a[s];
        }
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let x = if len > 0.0 {
            let l1 = (d[0].abs() + d[1].abs() + d[2].abs()) / len;
            (l1 * l1 - 1.0).max(0.0)
        } else {
            0.0
        };
        let g = self.effects.gain(Effect::Geometric);
        let mut m = g.abs() * sg.k2 * x + self.static_curvature_part(static_mm);
        if let Some(growth_mm) = self.bending_growth_mm() {
            m += growth_mm * (sg.axis2 * x + sg.axis1_sq);
        }
        m.is_finite().then_some(m)
    }

    /// [`Self::curvature`] from the cell polynomial of the segment (tight:
    /// the geometric part is the exact second derivative at the ends, which
    /// is affine along the segment) and the stiffness grid cell that holds
    /// it ([`crate::machine::tool::Stiffness::curvature_on_mm`]); `dirs`
    /// are the directions of motion.
    /// `None` on machines without the cell form (a rotary axis), or where
    /// the tool axis cannot be bounded.
    pub fn curvature_in_cell(
        &self,
        a: &AxisVec,
        b: &AxisVec,
        dirs: &DirVec,
        tool_mm: f64,
    ) -> Option<f64> {
        let growth = self.bending_growth_mm();
        let sb = self
            .machine
            .segment_bounds(a, b, dirs, tool_mm, growth.is_some())?;
        let g = self.effects.gain(Effect::Geometric);
        let stat = self.loaded_stiffness().map_or(0.0, |k| {
            let (pa, pb) = (
                Vector3::new(a[0], a[1], a[2]),
                Vector3::new(b[0], b[1], b[2]),
            );
            k.curvature_on_mm(&pa, &pb, &self.ctx.force_n())
        });
        let mut m = g.abs() * sb.pos2 + self.static_curvature_part(stat);
        if let Some(growth_mm) = growth {
            let n = sb.dir_norm_lo;
            if n.is_nan() || n <= 0.5 {
                return None;
            }
            m += growth_mm * (2.0 * sb.dir2 / n + 6.0 * sb.dir1 * sb.dir1 / (n * n));
        }
        m.is_finite().then_some(m)
    }

    /// The static part of the curvature bounds: `static_mm` times the gain.
    fn static_curvature_part(&self, static_mm: f64) -> f64 {
        let gs = self.effects.gain(Effect::Static);
        if gs != 0.0 { gs.abs() * static_mm } else { 0.0 }
    }

    /// The spindle growth (mm, times the gain) when it acts along the
    /// attained tool axis, which bends along a move (geometric gain one,
    /// thermal drift active; see [`Self::attained`]).
    fn bending_growth_mm(&self) -> Option<f64> {
        (self.effects.gain(Effect::Geometric) == 1.0 && self.thermal_active()).then(|| {
            self.effects.gain(Effect::Thermal).abs()
                * self.ctx.tool_thermal().growth_um.abs()
                * 1e-3
        })
    }

    /// True when the thermal part may be non-zero (so the nominal tool axis
    /// is needed).
    fn thermal_active(&self) -> bool {
        self.effects.gain(Effect::Thermal) != 0.0
            && self.machine.thermal().is_some()
            && self.ctx.tool_warm()
    }

    /// An upper bound of the Lipschitz constant (Euclidean norms) of
    /// `attained(c).pos − nominal(c).pos` on the segment of commands
    /// `a → b` (machines without rotary axes, commands near the travel;
    /// `None` otherwise): the geometric bound of the machine plus those of
    /// the static deflection under the block's force and of the thermal
    /// drift, each times its gain. Used to skip evaluations whose outcome
    /// it decides (see `compensate`).
    pub fn lipschitz(&self, a: &AxisVec, b: &AxisVec, tool_mm: f64) -> Option<f64> {
        self.lipschitz_bound(tool_mm)?.on(a, b)
    }

    /// The part of [`Self::lipschitz`] that does not depend on the segment
    /// (computed once per block; `None` for machines with rotary axes or a
    /// non-finite bound). [`LipschitzBound::on`] then gives the same value
    /// as [`Self::lipschitz`] for any segment.
    pub fn lipschitz_bound(&self, tool_mm: f64) -> Option<LipschitzBound<'m>> {
        let (geo, dir) = self.machine.lipschitz_geo_any(tool_mm)?;
        let mut l = self.effects.gain(Effect::Geometric).abs() * geo;
        let gs = self.effects.gain(Effect::Static);
        if let (true, Some(k)) = (gs != 0.0, self.machine.stiffness()) {
            l += gs.abs() * k.lipschitz_mm(&self.ctx.force_n());
        }
        let gt = self.effects.gain(Effect::Thermal);
        if let (true, Some(_)) = (gt != 0.0, self.machine.thermal()) {
            let th = &self.ctx.tool_thermal();
            let scale = th.scale_ppm.iter().fold(0.0f64, |m, v| m.max(v.abs())) * 1e-6;
            l += gt.abs() * (scale + th.growth_um.abs() * 1e-3 * dir);
        }
        l.is_finite().then_some(LipschitzBound {
            machine: self.machine,
            l,
        })
    }

    /// Predicted attained tool tip pose for commanded axes (the compensated
    /// effects only).
    pub fn attained(&self, cmd: &AxisVec, dirs: &DirVec, tool_mm: f64) -> TipPose {
        let g = self.effects.gain(Effect::Geometric);
        let gs = self.effects.gain(Effect::Static);
        let mut pose;
        let mut nom: Option<TipPose> = None;
        if g == 0.0 {
            pose = self.machine.nominal(cmd, tool_mm);
            nom = Some(pose);
        } else {
            let geo = self.machine.geometric(cmd, dirs, tool_mm);
            if g == 1.0 {
                pose = geo;
            } else {
                let n = self.machine.nominal(cmd, tool_mm);
                let dir = n.dir + (geo.dir - n.dir) * g;
                pose = TipPose {
                    pos: n.pos + (geo.pos - n.pos) * g,
                    dir: dir.normalize(),
                };
                nom = Some(n);
            }
        }
        if gs != 0.0 {
            pose.pos += self.static_part(cmd) * gs;
        }
        if self.thermal_active() {
            // The growth acts along the tool axis; the attained axis differs
            // from the nominal one by µrad, which changes a µm growth by
            // 1e-12 mm, so the chain is not evaluated a second time.
            let dir = nom.map_or(pose.dir, |n| n.dir);
            pose.pos += self.thermal_part(cmd, &dir) * self.effects.gain(Effect::Thermal);
        }
        pose
    }

    /// Predicted deviation (attained − nominal) with its breakdown; the
    /// dynamic part is the vibration amplitude of the block.
    pub fn breakdown(&self, cmd: &AxisVec, dirs: &DirVec, tool_mm: f64) -> Breakdown {
        self.evaluate(cmd, dirs, tool_mm).0
    }

    /// The breakdown at `cmd` together with the attained pose (as
    /// [`Self::attained`] gives it) and the nominal pose, from one
    /// evaluation of each chain.
    pub fn evaluate(
        &self,
        cmd: &AxisVec,
        dirs: &DirVec,
        tool_mm: f64,
    ) -> (Breakdown, TipPose, TipPose) {
        let nom = self.machine.nominal(cmd, tool_mm);
        let mut b = Breakdown::default();
        let g = self.effects.gain(Effect::Geometric);
        let mut pose = nom;
        if g != 0.0 {
            let geo = self.machine.geometric(cmd, dirs, tool_mm);
            b.kinematic.pos_mm = (geo.pos - nom.pos) * g;
            b.total.rot_rad = nom.dir.cross(&geo.dir) * g;
            pose = if g == 1.0 {
                geo
            } else {
                let dir = nom.dir + (geo.dir - nom.dir) * g;
                TipPose {
                    pos: nom.pos + (geo.pos - nom.pos) * g,
                    dir: dir.normalize(),
                }
            };
        }
        let gs = self.effects.gain(Effect::Static);
        if gs != 0.0 {
            let part = self.static_part(cmd) * gs;
            b.process.pos_mm = part;
            pose.pos += part;
        }
        if self.thermal_active() {
            let gt = self.effects.gain(Effect::Thermal);
            let part = self.thermal_part(cmd, &nom.dir) * gt;
            b.thermal.pos_mm = part;
            // `attained` takes the attained tool axis when the geometric
            // gain is one (see there); the same here.
            pose.pos += if g == 1.0 {
                self.thermal_part(cmd, &pose.dir) * gt
            } else {
                part
            };
        }
        b.vibration_mm = self.ctx.vibration_mm * self.effects.gain(Effect::Dynamic);
        b.total.pos_mm =
            Vector3::zeros() + b.kinematic.pos_mm + b.process.pos_mm + b.thermal.pos_mm;
        (b, pose, nom)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::Result;
    use crate::machine::effects::{EffectSpec, Gain};
    use crate::machine::tool::ThermalState;
    use crate::predict::context::{ThermalInput, Wrench, WrenchFrame};
    use crate::predict::effect::MachineKind;
    use approx::assert_abs_diff_eq;

    const POS_TOL_MM: f64 = 1e-12;

    /// Error-free XYZ mill with uniform stiffness (x 20, y 10, z 40/50 N/µm)
    /// and a thermal model.
    fn machine() -> MachineTool {
        let text = "kind: machine_tool
name: t
axes:
  - { name: X, type: linear, side: workpiece, travel_mm: [-500, 500], rapid_mm_per_min: 60000 }
  - { name: Y, type: linear, side: workpiece, travel_mm: [-500, 500], rapid_mm_per_min: 60000 }
  - { name: Z, type: linear, side: tool, travel_mm: [-500, 500], rapid_mm_per_min: 60000 }
stiffness:
  k_n_per_um: { x_pos: 20, x_neg: 20, y_pos: 10, y_neg: 10, z_pos: 40, z_neg: 50 }
thermal:
  spindle: { growth_um_per_kw: 10, time_constant_min: 1 }
  axes:
    X: { scale_ppm_per_kw: 50, time_constant_min: 1 }
";
        match MachineTool::from_yaml_str(text, "t.yaml") {
            Ok(m) => m,
            Err(e) => panic!("{e}"),
        }
    }

    fn ctx() -> MoveContext {
        MoveContext {
            wrench: Some(Wrench::force(
                Vector3::new(100.0, -50.0, 200.0),
                WrenchFrame::Workpiece,
            )),
            thermal: ThermalInput::Tool(ThermalState {
                growth_um: 4.0,
                scale_ppm: [10.0, 0.0, 0.0],
            }),
            vibration_mm: Vector3::new(0.002, 0.0, 0.0),
            ..MoveContext::default()
        }
    }

    #[test]
    fn parts_are_hand_derived_and_dynamic_is_not_compensated() {
        let m = machine();
        let p = ToolPredictor::new(&m, EffectSet::default()).with_context(ctx());
        let cmd = [200.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        let b = p.breakdown(&cmd, &[1; 6], 0.0);
        // Static: (100/20, −50/10, 200/40) µm = (5, −5, 5) µm.
        assert_abs_diff_eq!(
            b.part(Effect::Static),
            Vector3::new(0.005, -0.005, 0.005),
            epsilon = POS_TOL_MM
        );
        // Thermal: 10 ppm · 200 mm = 2 µm in X; growth 4 µm: −4 µm in Z.
        assert_abs_diff_eq!(
            b.part(Effect::Thermal),
            Vector3::new(0.002, 0.0, -0.004),
            epsilon = POS_TOL_MM
        );
        assert_abs_diff_eq!(
            b.part(Effect::Dynamic),
            Vector3::new(0.002, 0.0, 0.0),
            epsilon = POS_TOL_MM
        );
        // The total and the attained pose hold static + thermal only.
        let want = Vector3::new(0.007, -0.005, 0.001);
        assert_abs_diff_eq!(b.total(), want, epsilon = POS_TOL_MM);
        let got = p.attained(&cmd, &[1; 6], 0.0).pos - p.nominal(&cmd, 0.0).pos;
        assert_abs_diff_eq!(got, want, epsilon = POS_TOL_MM);
    }

    /// The effects of an `--effects` value.
    fn parse(spec: &str) -> Result<EffectSet> {
        let spec: EffectSpec = spec.parse().unwrap_or_else(|e| panic!("{spec}: {e}"));
        EffectSet::from_flags(&spec, &[], MachineKind::Tool)
    }

    /// Every effect, with the one `--gain` `gain`.
    fn with_gain(gain: &str) -> EffectSet {
        let g: Gain = gain.parse().unwrap_or_else(|e| panic!("{gain}: {e}"));
        EffectSet::from_flags(&EffectSpec::All, &[g], MachineKind::Tool)
            .unwrap_or_else(|e| panic!("{gain}: {e}"))
    }

    #[test]
    fn switches_and_gains_act_on_their_part_only() {
        let m = machine();
        let cmd = [200.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        let full = ToolPredictor::new(&m, EffectSet::default())
            .with_context(ctx())
            .breakdown(&cmd, &[1; 6], 0.0);
        for e in Effect::TOOL {
            let on: Vec<&str> = Effect::TOOL
                .iter()
                .filter(|&&x| x != e)
                .map(|x| x.name())
                .collect();
            let set = parse(&on.join(",")).unwrap_or_default();
            let b = ToolPredictor::new(&m, set)
                .with_context(ctx())
                .breakdown(&cmd, &[1; 6], 0.0);
            let set = with_gain(&format!("{}=0.25", e.name()));
            let g = ToolPredictor::new(&m, set)
                .with_context(ctx())
                .breakdown(&cmd, &[1; 6], 0.0);
            for x in Effect::TOOL {
                let want = if x == e {
                    Vector3::zeros()
                } else {
                    full.part(x)
                };
                assert_abs_diff_eq!(b.part(x), want, epsilon = POS_TOL_MM);
                let scale = if x == e { 0.25 } else { 1.0 };
                assert_abs_diff_eq!(g.part(x), full.part(x) * scale, epsilon = POS_TOL_MM);
            }
        }
    }

    /// Deterministic pseudo-random numbers in [0, 1) from `seed`.
    fn lcg(seed: u64) -> impl FnMut() -> f64 {
        let mut s = seed;
        move || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// Checks `|G(b) − G(a)| ≤ L·|b − a|` (G = attained − nominal) on
    /// random pairs of commands of the machine file `name` with `effects`;
    /// returns the largest ratio seen over far pairs (0 when the bound does
    /// not apply to this machine).
    fn lipschitz_worst_ratio(name: &str, effects: EffectSet) -> f64 {
        let path = format!("{}/machines/{name}", env!("CARGO_MANIFEST_DIR"));
        let text = std::fs::read_to_string(&path).unwrap_or_default();
        let m = match MachineTool::from_yaml_str(&text, &path) {
            Ok(m) => m,
            Err(e) => panic!("{e}"),
        };
        let hot = MoveContext {
            wrench: Some(Wrench::force(
                Vector3::new(300.0, -200.0, 150.0),
                WrenchFrame::Workpiece,
            )),
            thermal: ThermalInput::Tool(ThermalState {
                growth_um: 25.0,
                scale_ppm: [12.0, -8.0, 5.0],
            }),
            ..MoveContext::default()
        };
        let mut rng = lcg(11u64);
        let mut worst_ratio = 0.0f64;
        for ctx in [MoveContext::default(), hot] {
            let p = ToolPredictor::new(&m, effects).with_context(ctx);
            for k in 0..20000 {
                let mut a = [0.0; 6];
                for (slot, v) in a.iter_mut().enumerate().take(3) {
                    let (lo, hi) = m.travel(slot).unwrap_or((0.0, 0.0));
                    *v = lo - 20.0 + (hi - lo + 40.0) * rng();
                }
                // Near pairs (the solver's steps, short moves) and far ones.
                let scale = [1e-3, 1.0, 100.0, 1000.0][k % 4];
                let mut b = a;
                for v in b.iter_mut().take(3) {
                    *v += scale * (rng() - 0.5);
                }
                let dirs = [if rng() < 0.5 { 1 } else { -1 }, 1, -1, 0, 0, 0];
                let tool = 200.0 * rng();
                let Some(l) = p.lipschitz(&a, &b, tool) else {
                    continue;
                };
                let g = |c: &AxisVec| p.attained(c, &dirs, tool).pos - p.nominal(c, tool).pos;
                let dc = (Vector3::new(b[0], b[1], b[2]) - Vector3::new(a[0], a[1], a[2])).norm();
                let dg = (g(&b) - g(&a)).norm();
                // Rounding of the two evaluations, mm.
                const ROUND_MM: f64 = 1e-12;
                assert!(
                    dg <= l * dc + ROUND_MM,
                    "{a:?} {b:?}: {dg:e} > {l:e}·{dc:e}"
                );
                if dc > 1.0 {
                    worst_ratio = worst_ratio.max(dg / dc / l);
                }
            }
        }
        worst_ratio
    }

    #[test]
    fn lipschitz_bound_holds_on_the_afm_r1000() {
        let worst = lipschitz_worst_ratio("afm-r1000.yaml", EffectSet::default());
        // The bound is not vacuous: within a factor 100 of what is seen.
        assert!(worst > 0.01, "bound too loose: {worst}");
    }

    /// The bound holds for every bundled machine tool, each effect alone,
    /// and gains other than 1 (the skip it drives must never be wrong).
    #[test]
    fn lipschitz_bound_holds_for_every_machine_effect_and_gain() {
        let mut specs: Vec<EffectSet> = Vec::new();
        for spec in ["geometric", "static", "thermal", "all"] {
            match parse(spec) {
                Ok(e) => specs.push(e),
                Err(e) => panic!("{spec}: {e}"),
            }
        }
        for gain in ["thermal=0.5", "static=2", "geometric=0.25"] {
            specs.push(with_gain(gain));
        }
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/machines");
        let mut names: Vec<String> = std::fs::read_dir(dir)
            .map(|d| {
                d.filter_map(|e| e.ok())
                    .map(|e| e.file_name().to_string_lossy().into_owned())
                    .filter(|n| n.ends_with(".yaml"))
                    .collect()
            })
            .unwrap_or_default();
        names.sort();
        let mut tools = 0;
        for name in &names {
            let path = format!("{dir}/{name}");
            let text = std::fs::read_to_string(&path).unwrap_or_default();
            if MachineTool::from_yaml_str(&text, &path).is_err() {
                continue; // a robot
            }
            tools += 1;
            for e in &specs {
                lipschitz_worst_ratio(name, *e);
            }
        }
        assert!(tools >= 2, "machine tools found: {tools}");
    }

    /// The curvature bounds of [`ToolPredictor::curvature`] and
    /// [`ToolPredictor::curvature_in_cell`] hold against central second
    /// differences of the attained tip along random segments that cross no
    /// breakpoint, for each effect alone, all of them, gains other than one,
    /// cold and hot (force and thermal drift) contexts; the segments are
    /// general or one axis with a µm drift of the others.
    #[test]
    fn curvature_bounds_hold_against_second_differences() {
        use crate::machine::tool::testing;
        let text = testing::afm_text();
        // The AFM R-1000, with angular errors 300 times larger (the tool
        // axis, and so the spindle growth, bends visibly), and with a
        // stiffness map varying from 4 to 40 N/µm.
        let machines = [
            testing::load(&text, "afm-r1000.yaml"),
            testing::load(&testing::scale_angles(&text, 300.0), "afm-angles-x300.yaml"),
            testing::load(&testing::soft_stiffness(&text), "afm-soft.yaml"),
        ];
        let mut specs: Vec<EffectSet> = Vec::new();
        for spec in ["geometric", "static", "thermal", "all"] {
            match parse(spec) {
                Ok(e) => specs.push(e),
                Err(e) => panic!("{spec}: {e}"),
            }
        }
        for gain in ["thermal=0.5", "static=2", "geometric=0.25"] {
            specs.push(with_gain(gain));
        }
        let hot = MoveContext {
            wrench: Some(Wrench::force(
                Vector3::new(900.0, -700.0, 500.0),
                WrenchFrame::Workpiece,
            )),
            thermal: ThermalInput::Tool(ThermalState {
                growth_um: 60.0,
                scale_ppm: [12.0, -8.0, 5.0],
            }),
            ..MoveContext::default()
        };
        let mut rng = lcg(5u64);
        let mut checked = 0;
        let mut ratio = [0.0f64; 2];
        for m in &machines {
            for effects in &specs {
                for ctx in [MoveContext::default(), hot] {
                    let p = ToolPredictor::new(m, *effects).with_context(ctx);
                    let stat = p.static_curvature_mm();
                    for k in 0..300 {
                        let Some((a, b, dirs)) = testing::segment_in_cell(m, &mut rng, 200.0)
                        else {
                            continue;
                        };
                        let len = (0..3).map(|i| (b[i] - a[i]).powi(2)).sum::<f64>().sqrt();
                        let d = [0, 1, 2].map(|i| (b[i] - a[i]) / len);
                        let tool = [0.0, 62.5, 140.0][k % 3];
                        let (Some(global), Some(cell)) = (
                            p.curvature(&a, &b, tool, stat),
                            p.curvature_in_cell(&a, &b, &dirs, tool),
                        ) else {
                            panic!("no bound on {a:?} → {b:?}");
                        };
                        let h = len / 8.0;
                        let at = |t: f64| {
                            let mut c = a;
                            for i in 0..3 {
                                c[i] = a[i] + d[i] * t;
                            }
                            p.attained(&c, &dirs, tool).pos
                        };
                        // Rounding of three evaluations (≈ 1e-13 mm) over h².
                        let noise = 1e-12 / (h * h);
                        for j in 1..8 {
                            let t = h * j as f64;
                            let second = (at(t + h) - at(t) * 2.0 + at(t - h)).norm() / (h * h);
                            assert!(
                                second <= global * (1.0 + 1e-9) + noise,
                                "{second:e} > global {global:e}"
                            );
                            assert!(
                                second <= cell * (1.0 + 1e-9) + noise,
                                "{second:e} > cell {cell:e}"
                            );
                            if second > 10.0 * noise {
                                ratio[0] = ratio[0].max(second / global);
                                ratio[1] = ratio[1].max(second / cell);
                            }
                        }
                        checked += 1;
                    }
                }
            }
        }
        assert!(checked > 6000, "{checked} segments");
        // Not vacuous: the bounds are approached (global, per cell).
        assert!(
            ratio[1] > 0.1 && ratio[0] > 0.01,
            "largest ratios {ratio:?}"
        );
    }
}
