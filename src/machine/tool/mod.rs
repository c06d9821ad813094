//! Machine-tool model: a validated machine file (axes, travel, rapid rates,
//! tool table, work offsets) and its geometric error model — a chain of
//! homogeneous transformations from the workpiece to the tool tip with
//! location and bidirectional component errors per axis (ISO 230-1,
//! docs/physics.md). The file format and every sign convention are documented
//! in `machines/README.md`.
//!
//! Chain (product from left to right, in the order of `axes` in the file):
//!
//! ```text
//! W_T_tip = E_1 · … · E_k · G(L) · E_k+1 · … · E_n · S · T(−L)
//! ```
//!
//! `E_1 … E_k` are the workpiece-side axes (nearest the workpiece first),
//! `E_k+1 … E_n` the tool-side axes (from the base to the spindle),
//! `G(L) = Trans(0, 0, L)` moves to the spindle gauge line, `S` is the
//! spindle location error and `T(−L)` goes down the tool to its tip. Every
//! `E_i` describes the motion of the tool relative to the workpiece caused by
//! axis `i` (for a workpiece-side axis this is the inverse of the table's
//! own motion):
//!
//! * linear axis: `E = LOC · Trans(q·ê) · COM(q)`
//! * rotary axis with pivot `P` and offset `d`:
//!   `E = Trans(P + d) · LOC · Rot(ê, θ + ε0) · COM(θ) · Trans(−(P + d))`

mod cells;
mod component;
pub mod dynamics;
mod fast;
mod geometry;
mod load;
mod location;
mod offsets;
mod params;
pub mod plausible;
mod raw;
pub mod stiffness;
mod table;
mod tcpm;
#[cfg(test)]
pub(crate) mod testing;
pub mod thermal;

pub(crate) use cells::SegmentBounds;
pub use component::{ComponentErrors, ComponentValue};
pub use dynamics::{Modal, Mode};
pub(crate) use fast::SecondGeo;
pub use location::{LocationErrors, SpindleErrors};
pub use offsets::{MAX_TOOL_LENGTH_MM, MAX_WORK_OFFSET_MM, ToolLength, WorkOffset};
pub use params::{LocationParam, ToolParam};
pub use stiffness::Stiffness;
pub use table::{ErrorTable, Lookup};
pub use thermal::{Thermal, ThermalState};

use std::collections::BTreeMap;

use nalgebra::{Matrix3, Matrix4, Matrix6, Vector3};

use crate::error::Result;
use crate::machine::{AxisVec, DirVec, TipPose};

/// Kind of motion of an axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AxisKind {
    /// Translation along x, y or z (mm).
    Linear,
    /// Rotation about x, y or z (degrees in commands).
    Rotary,
}

/// The unit of length of part programs (G20/G21).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Units {
    /// Millimetres (G21).
    Mm,
    /// Inches (G20).
    Inch,
}

/// How the control reads a length or angle word written without a decimal
/// point (`X100`): the machine file's `integer_words`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum IntegerWords {
    /// In whole units: `X100` is 100 mm (or inches, or degrees), as
    /// LinuxCNC reads it, and Fanuc with calculator-type decimal input or
    /// Haas with setting 162 on.
    Units,
    /// In least input increments: `X100` is 0.100 mm, 0.0100 inch or
    /// 0.100°, as Fanuc and Haas controls read it as delivered.
    Increments,
}

/// The corner words the control reads on a linear move (`G1 X50. ,C2.`):
/// the machine file's `corner_words`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CornerWords {
    /// `,C` (chamfer: the distance from the corner along each line) and
    /// `,R` (corner radius: the radius of the arc tangent to both lines),
    /// as Fanuc (chamfering and corner R) and Haas read them.
    Comma,
}

/// Which side of the machine structure carries an axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// The axis moves the workpiece (table side).
    Workpiece,
    /// The axis moves the spindle (column side).
    Tool,
}

/// One validated axis of the kinematic chain.
#[derive(Debug, Clone, PartialEq)]
pub struct Axis {
    /// Slot 0..6 (X Y Z A B C); also the direction of motion (slot mod 3).
    pub slot: usize,
    /// Linear or rotary.
    pub kind: AxisKind,
    /// Workpiece or tool side.
    pub side: Side,
    /// Travel limits (mm or degrees).
    pub travel: (f64, f64),
    /// Rapid traverse rate (mm/min or deg/min).
    pub rapid_per_min: f64,
    /// A point on the nominal line of a rotary axis, machine coordinates
    /// with all axes at zero, mm (zero for linear axes).
    pub pivot_mm: Vector3<f64>,
    /// Location errors.
    pub location: LocationErrors,
    /// Component errors.
    pub components: ComponentErrors,
    /// Sorted, distinct positions (mm or degrees) where the error model
    /// changes slope along this axis (see [`MachineTool::breakpoints`]).
    pub breakpoints: Vec<f64>,
}

/// A validated machine tool (immutable; `Send + Sync`).
#[derive(Debug, Clone)]
pub struct MachineTool {
    name: String,
    /// Axes in chain order (workpiece side first, then tool side).
    axes: Vec<Axis>,
    /// Number of workpiece-side axes (they come first in `axes`).
    n_workpiece: usize,
    /// Index into `axes` per slot.
    slot_index: [Option<u8>; 6],
    tools: BTreeMap<u32, f64>,
    work_offsets: BTreeMap<String, [f64; 3]>,
    /// The control's settings a program may rely on (G30 points, default
    /// unit, tolerance), boxed to keep `Machine` small.
    control: Box<ControlDefaults>,
    decimals: Option<usize>,
    decimals_deg: Option<usize>,
    error_free: bool,
    /// `measurement_frame`: pose of the measuring instrument in the
    /// workpiece frame (not part of the model); boxed to keep `Machine` small.
    measurement_frame: Option<Box<nalgebra::Isometry3<f64>>>,
    /// The optional process sections, boxed to keep `Machine` small.
    process: Option<Box<ProcessSections>>,
    /// Position-independent parts of the chain (see [`fast`]), boxed to
    /// keep `Machine` small.
    pre: Box<fast::Precomputed>,
    /// The file's values as read, from which [`MachineTool::with_params`]
    /// validates a model with some of them changed.
    raw: std::sync::Arc<raw::RawMachineTool>,
}

/// The control's settings of a machine file that programs rely on.
#[derive(Debug, Clone)]
pub(crate) struct ControlDefaults {
    /// The reference points of G30 by key (`G30`, `G30P3`, `G30P4`).
    pub(crate) reference_points: BTreeMap<String, [f64; 3]>,
    /// `units_default`: the unit of programs without G20/G21.
    pub(crate) units_default: Option<Units>,
    /// `integer_words`: how words without a decimal point are read.
    pub(crate) integer_words: Option<IntegerWords>,
    /// `corner_words`: the corner words the control reads.
    pub(crate) corner_words: Option<CornerWords>,
    /// `compensation.tolerance_mm`: the default tolerance of compensated
    /// programs, mm.
    pub(crate) tolerance_mm: Option<f64>,
    /// `output.expand_deep_holes_to_moves`: deep canned-cycle holes may be
    /// written as moves (as `--expand-cycles`).
    pub(crate) expand_deep_holes: bool,
}

/// The optional process sections of a machine file.
#[derive(Debug, Clone, Default)]
struct ProcessSections {
    force: Option<crate::process::ForceModel>,
    stiffness: Option<Stiffness>,
    thermal: Option<Thermal>,
    modal: Option<Modal>,
}

/// Maximum number of factors in the chain: 6 axes, gauge line, spindle, tool.
const MAX_FACTORS: usize = 9;

/// The factors of the chain for one command.
struct Chain {
    m: [Matrix4<f64>; MAX_FACTORS],
    n: usize,
    /// Factor index and derivative (per mm / per degree) of each axis, by slot.
    deriv: [Option<(usize, Matrix4<f64>)>; 6],
}

impl MachineTool {
    /// Parses and validates machine-tool YAML; `file` names it in errors.
    pub fn from_yaml_str(text: &str, file: &str) -> Result<Self> {
        load::load(&crate::machine::yaml::Source::read(text, file)?)
    }

    /// Validates a machine-tool file read by
    /// [`crate::machine::yaml::Source::read`].
    pub fn from_source(src: &crate::machine::yaml::Source) -> Result<Self> {
        load::load(src)
    }

    /// Display name of the machine.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Whether the machine has the axis in `slot` (0..6 = X Y Z A B C).
    pub fn has_axis(&self, slot: usize) -> bool {
        self.axis(slot).is_some()
    }

    /// The validated axis in `slot`, if the machine has it.
    pub fn axis(&self, slot: usize) -> Option<&Axis> {
        let i = (*self.slot_index.get(slot)?)?;
        self.axes.get(usize::from(i))
    }

    /// All axes in chain order (workpiece side from the workpiece out, then
    /// tool side from the base to the spindle).
    pub fn axes(&self) -> &[Axis] {
        &self.axes
    }

    /// Spindle location errors.
    pub fn spindle_errors(&self) -> &SpindleErrors {
        &self.pre.spindle_errors
    }

    /// Travel limits of the axis in `slot` (mm or deg), `None` if absent.
    pub fn travel(&self, slot: usize) -> Option<(f64, f64)> {
        self.axis(slot).map(|a| a.travel)
    }

    /// Rapid traverse rate of the axis in `slot` (mm/min or deg/min);
    /// `f64::INFINITY` for an axis the machine does not have (it costs no time).
    pub fn rapid_per_min(&self, slot: usize) -> f64 {
        self.axis(slot).map_or(f64::INFINITY, |a| a.rapid_per_min)
    }

    /// Tool length for offset number `h` from the tool table, mm.
    pub fn tool_length_mm(&self, h: u32) -> Option<f64> {
        self.tools.get(&h).copied()
    }

    /// The whole tool table: (H number, length in mm), by H number.
    pub fn tools(&self) -> impl Iterator<Item = (u32, f64)> + '_ {
        self.tools.iter().map(|(&h, &l)| (h, l))
    }

    /// Work offset `G54`…`G59`, `G54.1P1`…, `G154P1`… (machine
    /// coordinates of the work zero), mm.
    pub fn work_offset_mm(&self, code: &str) -> Option<[f64; 3]> {
        self.work_offsets.get(code).copied()
    }

    /// The default tolerance of compensated programs
    /// (`compensation.tolerance_mm`: the accuracy of the model itself), mm,
    /// if the machine file gives one.
    pub fn compensation_tolerance_mm(&self) -> Option<f64> {
        self.control.tolerance_mm
    }

    /// Every work offset of the file, by key.
    pub fn work_offsets(&self) -> impl Iterator<Item = (&String, &[f64; 3])> {
        self.work_offsets.iter()
    }

    /// The reference points of G30 (`G30`, `G30P3`, `G30P4`), machine
    /// coordinates of X, Y, Z, mm.
    pub fn reference_points(&self) -> impl Iterator<Item = (&String, &[f64; 3])> {
        self.control.reference_points.iter()
    }

    /// The control's unit for programs that set none (`units_default`).
    pub fn units_default(&self) -> Option<Units> {
        self.control.units_default
    }

    /// How the control reads length and angle words without a decimal
    /// point (`integer_words`; `None` when the file does not say).
    pub fn integer_words(&self) -> Option<IntegerWords> {
        self.control.integer_words
    }

    /// The chamfer and corner-radius words the control reads
    /// (`corner_words`; `None`: the file does not say, and they are
    /// refused).
    pub fn corner_words(&self) -> Option<CornerWords> {
        self.control.corner_words
    }

    /// Whether canned-cycle holes whose one X and Y would miss the
    /// tolerance may be written as the cycle's moves
    /// (`output.expand_deep_holes_to_moves`, as `--expand-cycles`).
    pub fn expand_deep_holes_to_moves(&self) -> bool {
        self.control.expand_deep_holes
    }

    /// Output decimals for mm programs, if the machine file fixes them.
    pub fn output_decimals(&self) -> Option<usize> {
        self.decimals
    }

    /// Output decimals for rotary-axis words (degrees), if the machine file
    /// fixes them.
    pub fn output_decimals_deg(&self) -> Option<usize> {
        self.decimals_deg
    }

    /// The process-force model of the machine file (`process_force:`).
    pub fn process_force(&self) -> Option<&crate::process::ForceModel> {
        self.process.as_ref().and_then(|p| p.force.as_ref())
    }

    /// The static stiffness map (`stiffness:`).
    pub fn stiffness(&self) -> Option<&Stiffness> {
        self.process.as_ref().and_then(|p| p.stiffness.as_ref())
    }

    /// The thermal model (`thermal:`).
    pub fn thermal(&self) -> Option<&Thermal> {
        self.process.as_ref().and_then(|p| p.thermal.as_ref())
    }

    /// Pose of the measuring instrument in the workpiece frame (the
    /// file's `measurement_frame`), if given.
    pub fn measurement_frame(&self) -> Option<&nalgebra::Isometry3<f64>> {
        self.measurement_frame.as_deref()
    }

    /// The dominant modes (`modal:`).
    pub fn modal(&self) -> Option<&Modal> {
        self.process.as_ref().and_then(|p| p.modal.as_ref())
    }

    /// Sorted, distinct positions of axis `slot` (mm or degrees) where the
    /// error model is not smooth: the positions of its component-error tables
    /// and, for X, Y and Z, the stiffness grid. Between two of them every
    /// table and the stiffness map are linear in the axis position.
    pub fn breakpoints(&self, slot: usize) -> &[f64] {
        self.axis(slot).map_or(&[], |a| a.breakpoints.as_slice())
    }

    /// True when every geometric error is zero.
    pub fn is_error_free(&self) -> bool {
        self.error_free
    }

    /// Nominal tool tip pose in the workpiece frame for commanded axis values
    /// (machine coordinates) and tool length.
    ///
    /// On a machine whose axes are all linear the nominal chain is a
    /// translation: the tip is accumulated by its column alone, with the
    /// same additions in the same order as the chain product (same bits).
    pub fn nominal(&self, cmd: &AxisVec, tool_mm: f64) -> TipPose {
        if self.pre.cells_id.is_some() && tool_mm.is_finite() && cmd.iter().all(|v| v.is_finite()) {
            // The rotation part stays the identity: an axis in slot `r`
            // adds its value to row `r` alone (the other rows add a zero,
            // which leaves them as they are), each slot has at most one
            // axis, and the tool length is added where the workpiece side
            // of the chain ends (before or after the Z axis) and taken off
            // at the tip. The sums start from zero as the chain's do
            // (`0 + q` turns a −0 into +0).
            let slots = self.pre.cells_slots;
            let along = |s: usize| {
                if slots & (1 << s) != 0 {
                    0.0 + cmd[s]
                } else {
                    0.0
                }
            };
            let z = if self.pre.z_index == usize::MAX {
                0.0 + tool_mm
            } else if self.pre.z_index >= self.n_workpiece {
                (0.0 + tool_mm) + cmd[2]
            } else {
                (0.0 + cmd[2]) + tool_mm
            };
            return TipPose {
                pos: Vector3::new(along(0), along(1), z + -tool_mm),
                dir: Vector3::z(),
            };
        }
        pose_aff(&self.tip_htm(cmd, &[1; 6], tool_mm, false))
    }

    /// Predicted (attained) tool tip pose including the geometric errors,
    /// with component errors looked up for the given direction of motion.
    ///
    /// Machines whose axes are all linear evaluate the chain from its
    /// multi-affine form in the command's cell (see `cells.rs`), which
    /// agrees with the chain product to rounding.
    pub fn geometric(&self, cmd: &AxisVec, dirs: &DirVec, tool_mm: f64) -> TipPose {
        if let Some((d, p)) = cells::geometric(self, cmd, dirs, tool_mm) {
            return pose_cols(&d, &p);
        }
        pose_aff(&self.tip_htm(cmd, dirs, tool_mm, true))
    }

    /// Bounds of the derivatives of the geometric chain along the straight
    /// segment `a → b` of commands, which must not cross a breakpoint
    /// ([`Self::breakpoints`]) of an X, Y or Z table: `None` on machines
    /// without the multi-affine cell form (a rotary axis) or when the ends
    /// are not in one cell.
    /// With `axis` false the tool-axis bounds are left at zero.
    pub(crate) fn segment_bounds(
        &self,
        a: &AxisVec,
        b: &AxisVec,
        dirs: &DirVec,
        tool_mm: f64,
        axis: bool,
    ) -> Option<SegmentBounds> {
        cells::segment_bounds(self, a, b, dirs, tool_mm, axis)
    }

    /// [`Self::geometric`] by the chain product alone (the reference of the
    /// cell form in the tests).
    #[cfg(test)]
    fn geometric_chain(&self, cmd: &AxisVec, dirs: &DirVec, tool_mm: f64) -> TipPose {
        pose_aff(&self.tip_htm(cmd, dirs, tool_mm, true))
    }

    /// The chain product `W_T_tip` (its top three rows) for one command,
    /// accumulated factor by factor without storing the factors (the
    /// per-point hot path; the Jacobian uses [`Self::chain`]). Translations
    /// are applied as column updates rather than full products.
    fn tip_htm(&self, cmd: &AxisVec, dirs: &DirVec, tool_mm: f64, errors: bool) -> fast::Aff {
        let mut acc = fast::IDENTITY;
        for (i, (a, f)) in self.axes.iter().zip(&self.pre.axes).enumerate() {
            if i == self.n_workpiece {
                fast::translate_z(&mut acc, tool_mm);
            }
            let q = cmd.get(a.slot).copied().unwrap_or(0.0);
            let dir = dirs.get(a.slot).copied().unwrap_or(1);
            fast::apply_axis(&mut acc, a, f, q, dir, errors);
        }
        if self.n_workpiece == self.axes.len() {
            fast::translate_z(&mut acc, tool_mm);
        }
        if let (true, Some(s)) = (errors, &self.pre.spindle) {
            acc = fast::mul(&acc, s);
        }
        fast::translate_z(&mut acc, -tool_mm);
        acc
    }

    /// For a machine without rotary axes and a command in a box around the
    /// travel: an upper bound of the Lipschitz constant (Euclidean norms) of
    /// the geometric error `geometric(c).pos − nominal(c).pos` in the
    /// command (for tool length `tool_mm`, any directions of motion) and one
    /// of the attained tool axis `geometric(c).dir`. `None` outside the box
    /// or for machines with rotary axes.
    pub fn lipschitz_geo(&self, c: &AxisVec, tool_mm: f64) -> Option<(f64, f64)> {
        let l = self.pre.lip.as_ref()?;
        l.contains(c).then(|| l.bounds(tool_mm))
    }

    /// Global bounds of the second derivatives of the geometric chain along
    /// a straight segment of commands `a → b` crossing no breakpoint, for
    /// tool length `tool_mm` (see `fast::LipGeo`): `None` when an end leaves
    /// the box of [`Self::lipschitz_geo`] or for machines with rotary axes.
    pub(crate) fn second_geo(&self, a: &AxisVec, b: &AxisVec, tool_mm: f64) -> Option<SecondGeo> {
        let l = self.pre.lip.as_ref()?;
        (l.contains(a) && l.contains(b)).then(|| l.second(tool_mm))
    }

    /// [`Self::lipschitz_geo`] without the box test (see
    /// [`Self::in_lipschitz_box`]).
    pub fn lipschitz_geo_any(&self, tool_mm: f64) -> Option<(f64, f64)> {
        self.pre.lip.as_ref().map(|l| l.bounds(tool_mm))
    }

    /// True when `c` lies in the box of commands where
    /// [`Self::lipschitz_geo`] holds (false for machines with rotary axes).
    #[inline]
    pub fn in_lipschitz_box(&self, c: &AxisVec) -> bool {
        self.pre.lip.as_ref().is_some_and(|l| l.contains(c))
    }

    /// Attained minus nominal tool tip position, mm.
    pub fn tip_error_mm(&self, cmd: &AxisVec, dirs: &DirVec, tool_mm: f64) -> Vector3<f64> {
        self.geometric(cmd, dirs, tool_mm).pos - self.nominal(cmd, tool_mm).pos
    }

    /// Analytic Jacobian of [`Self::geometric`] with respect to the commanded
    /// axis values. Rows 0..3: tip position (mm), rows 3..6: unit tool
    /// direction; column `slot` per mm (linear) or per degree (rotary); zero
    /// columns for absent axes. Table slopes are those of the segment the
    /// command lies in (zero outside the tables).
    pub fn jacobian(&self, cmd: &AxisVec, dirs: &DirVec, tool_mm: f64) -> Matrix6<f64> {
        let c = self.chain(cmd, dirs, tool_mm, true, true);
        let factors = &c.m[..c.n];
        let full = product(factors);
        let v: Vector3<f64> = full.fixed_view::<3, 1>(0, 2).into_owned();
        let norm = v.norm();
        let u = if norm > 0.0 { v / norm } else { Vector3::z() };
        let proj = if norm > 0.0 {
            (Matrix3::identity() - u * u.transpose()) / norm
        } else {
            Matrix3::zeros()
        };
        let mut j = Matrix6::zeros();
        for (slot, d) in c.deriv.iter().enumerate() {
            let Some((k, dm)) = d else { continue };
            let left = product(factors.get(..*k).unwrap_or(&[]));
            let right = product(factors.get(k + 1..).unwrap_or(&[]));
            let dt = left * dm * right;
            let dpos: Vector3<f64> = dt.fixed_view::<3, 1>(0, 3).into_owned();
            let ddir = proj * dt.fixed_view::<3, 1>(0, 2).into_owned();
            for r in 0..3 {
                j[(r, slot)] = dpos[r];
                j[(r + 3, slot)] = ddir[r];
            }
        }
        j
    }

    /// Bit `i` set when axis slot `i` of `cmd` lies outside its component
    /// error tables (the lookup is clamped at the table ends).
    pub fn clamped_axes(&self, cmd: &AxisVec) -> u8 {
        let mut bits = 0u8;
        for (a, f) in self.axes.iter().zip(&self.pre.axes) {
            let q = cmd.get(a.slot).copied().unwrap_or(0.0);
            if f.is_clamped(q) {
                bits |= 1 << a.slot;
            }
        }
        bits
    }

    /// Builds the chain factors for one command; `errors` includes the
    /// geometric errors, `derivs` also fills the axis derivatives.
    fn chain(
        &self,
        cmd: &AxisVec,
        dirs: &DirVec,
        tool_mm: f64,
        errors: bool,
        derivs: bool,
    ) -> Chain {
        let mut c = Chain {
            m: [Matrix4::identity(); MAX_FACTORS],
            n: 0,
            deriv: [None; 6],
        };
        let push = |c: &mut Chain, m: Matrix4<f64>| {
            if let Some(slot) = c.m.get_mut(c.n) {
                *slot = m;
                c.n += 1;
            }
        };
        for (i, a) in self.axes.iter().enumerate() {
            if i == self.n_workpiece {
                push(
                    &mut c,
                    geometry::translation(&Vector3::new(0.0, 0.0, tool_mm)),
                );
            }
            let q = cmd.get(a.slot).copied().unwrap_or(0.0);
            let dir = dirs.get(a.slot).copied().unwrap_or(1);
            let (m, dm) = axis_htm(a, q, dir, errors, derivs);
            if derivs {
                if let Some(d) = c.deriv.get_mut(a.slot) {
                    *d = Some((c.n, dm));
                }
            }
            push(&mut c, m);
        }
        if self.n_workpiece == self.axes.len() {
            push(
                &mut c,
                geometry::translation(&Vector3::new(0.0, 0.0, tool_mm)),
            );
        }
        if errors {
            push(&mut c, self.pre.spindle_errors.htm());
        }
        push(
            &mut c,
            geometry::translation(&Vector3::new(0.0, 0.0, -tool_mm)),
        );
        c
    }
}

/// Fills the breakpoints of every axis (see [`MachineTool::breakpoints`]).
fn set_breakpoints(axes: &mut [Axis], stiffness: Option<&Stiffness>) {
    for a in axes {
        let mut v: Vec<f64> = Vec::new();
        for t in a.components.tables.iter().flatten() {
            v.extend_from_slice(t.positions());
        }
        if let (Some(k), true) = (stiffness, a.kind == AxisKind::Linear && a.slot < 3) {
            let g = k.grid_mm()[a.slot];
            // A single grid position is a uniform map: no break.
            if g.len() > 1 {
                v.extend_from_slice(g);
            }
        }
        v.retain(|x| x.is_finite());
        v.sort_by(f64::total_cmp);
        v.dedup();
        a.breakpoints = v;
    }
}

/// HTM of one axis at command `q` (mm or degrees) and its derivative with
/// respect to `q` (zero matrix unless `derivs`).
fn axis_htm(a: &Axis, q: f64, dir: i8, errors: bool, derivs: bool) -> (Matrix4<f64>, Matrix4<f64>) {
    let com = if errors {
        a.components.eval(q, dir)
    } else {
        ComponentErrors::default().eval(q, dir)
    };
    let loc = if errors {
        a.location
    } else {
        LocationErrors::default()
    };
    let r = a.slot % 3;
    let orient = loc.orientation_htm();
    let mut dm = Matrix4::zeros();
    match a.kind {
        AxisKind::Linear => {
            let mut e = Vector3::zeros();
            e[r] = 1.0;
            let mot = geometry::translation(&(e * q));
            let m = orient * mot * com.htm();
            if derivs {
                let mut dmot = Matrix4::zeros();
                dmot[(r, 3)] = 1.0;
                dm = orient * (dmot * com.htm() + mot * com.d_htm());
            }
            (m, dm)
        }
        AxisKind::Rotary => {
            let c = a.pivot_mm + loc.offset_mm;
            let to = geometry::translation(&c);
            let back = geometry::translation(&-c);
            let theta = q.to_radians() + loc.zero_rad;
            let rot = geometry::rotation(r, theta);
            let m = to * orient * rot * com.htm() * back;
            if derivs {
                let drot = geometry::d_rotation(r, theta) * (std::f64::consts::PI / 180.0);
                dm = to * orient * (drot * com.htm() + rot * com.d_htm()) * back;
            }
            (m, dm)
        }
    }
}

/// Product of HTMs in order.
fn product(ms: &[Matrix4<f64>]) -> Matrix4<f64> {
    ms.iter().fold(Matrix4::identity(), |acc, m| acc * m)
}

/// The tip pose from columns 2 (tool axis, normalised here) and 3 (tip) of
/// a chain HTM.
fn pose_cols(d: &[f64; 3], p: &[f64; 3]) -> TipPose {
    let pos = Vector3::new(p[0], p[1], p[2]);
    let d = Vector3::new(d[0], d[1], d[2]);
    let n = d.norm();
    let dir = if n > 0.0 { d / n } else { Vector3::z() };
    TipPose { pos, dir }
}

/// Tip pose of (the top three rows of) a chain HTM.
fn pose_aff(t: &fast::Aff) -> TipPose {
    let [r0, r1, r2] = t;
    pose_cols(&[r0[2], r1[2], r2[2]], &[r0[3], r1[3], r2[3]])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `acc · Trans(0, 0, l)`: column 3 gains `l` times column 2.
    fn translate_z(acc: &mut Matrix4<f64>, l: f64) {
        for row in 0..4 {
            acc[(row, 3)] += acc[(row, 2)] * l;
        }
    }

    /// The full 4×4 chain product: the reference the top-three-rows path
    /// must match bit for bit.
    fn tip_htm_reference(
        m: &MachineTool,
        cmd: &AxisVec,
        dirs: &DirVec,
        tool_mm: f64,
        errors: bool,
    ) -> Matrix4<f64> {
        let mut acc = Matrix4::identity();
        for (i, a) in m.axes.iter().enumerate() {
            if i == m.n_workpiece {
                translate_z(&mut acc, tool_mm);
            }
            let q = cmd.get(a.slot).copied().unwrap_or(0.0);
            let dir = dirs.get(a.slot).copied().unwrap_or(1);
            let r = a.slot % 3;
            match (a.kind, errors) {
                (AxisKind::Linear, false) => {
                    // acc · Trans(q·ê): column 3 gains q times column r.
                    for row in 0..4 {
                        acc[(row, 3)] += acc[(row, r)] * q;
                    }
                }
                (AxisKind::Linear, true) => {
                    // LOC · Trans(q·ê) · COM(q): the translation only adds
                    // q to row r of COM's last column.
                    let mut m = a.components.eval(q, dir).htm();
                    m[(r, 3)] += q;
                    if a.location.angles_rad != Vector3::zeros() {
                        m = a.location.orientation_htm() * m;
                    }
                    acc *= m;
                }
                (AxisKind::Rotary, _) => {
                    let (m, _) = axis_htm(a, q, dir, errors, false);
                    acc *= m;
                }
            }
        }
        if m.n_workpiece == m.axes.len() {
            translate_z(&mut acc, tool_mm);
        }
        if errors && !m.pre.spindle_errors.is_zero() {
            acc *= m.pre.spindle_errors.htm();
        }
        translate_z(&mut acc, -tool_mm);
        acc
    }

    fn bundled() -> Vec<MachineTool> {
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/machines");
        let mut out = Vec::new();
        let Ok(entries) = std::fs::read_dir(dir) else {
            return out;
        };
        let mut paths: Vec<_> = entries.flatten().map(|e| e.path()).collect();
        paths.sort();
        for p in paths {
            if p.extension().is_none_or(|e| e != "yaml") {
                continue;
            }
            let text = std::fs::read_to_string(&p).unwrap_or_default();
            if !text.contains("kind: machine_tool") {
                continue;
            }
            match MachineTool::from_yaml_str(&text, &p.to_string_lossy()) {
                Ok(m) => out.push(m),
                Err(e) => panic!("{e}"),
            }
        }
        out
    }

    /// Deterministic pseudo-random numbers in [0, 1).
    fn rng(state: &mut u64) -> f64 {
        *state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (*state >> 11) as f64 / (1u64 << 53) as f64
    }

    #[test]
    fn fast_chain_is_bit_identical_to_the_4x4_product() {
        let machines = bundled();
        assert!(machines.len() >= 2);
        let mut s = 7u64;
        for m in &machines {
            // Commands inside and beyond the travel, on table knots and at
            // special values.
            let mut cmds: Vec<AxisVec> = Vec::new();
            for _ in 0..4000 {
                let mut c = [0.0; 6];
                for (slot, v) in c.iter_mut().enumerate() {
                    let (lo, hi) = m.travel(slot).unwrap_or((-100.0, 100.0));
                    let span = hi - lo;
                    *v = lo - 0.1 * span + 1.2 * span * rng(&mut s);
                    if rng(&mut s) < 0.1 {
                        let bp = m.breakpoints(slot);
                        if !bp.is_empty() {
                            let i = ((rng(&mut s) * bp.len() as f64) as usize).min(bp.len() - 1);
                            *v = bp[i];
                        }
                    }
                }
                cmds.push(c);
            }
            cmds.push([0.0; 6]);
            cmds.push([-0.0; 6]);
            cmds.push([f64::NAN, 1.0, 2.0, f64::NAN, 0.0, 3.0]);
            cmds.push([f64::INFINITY, -1e9, 2.0, 1e9, 0.0, f64::NEG_INFINITY]);
            for (k, c) in cmds.iter().enumerate() {
                let mut dirs = [0i8; 6];
                for d in dirs.iter_mut() {
                    *d = (k % 3) as i8 - 1;
                    if rng(&mut s) < 0.5 {
                        *d = -*d;
                    }
                }
                let tool = [0.0, 62.5, 140.0][k % 3];
                for errors in [false, true] {
                    let want = tip_htm_reference(m, c, &dirs, tool, errors);
                    let got = m.tip_htm(c, &dirs, tool, errors);
                    for i in 0..3 {
                        for j in 0..4 {
                            let (a, b) = (got[i][j], want[(i, j)]);
                            assert!(
                                a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
                                "{} {c:?} {dirs:?} errors {errors}: ({i},{j}) {a:e} != {b:e}",
                                m.name()
                            );
                        }
                    }
                }
            }
        }
    }

    /// The AFM R-1000 and variants of it that move the tool-length and
    /// spindle factors around the chain: every axis on the tool side,
    /// every axis on the workpiece side, and a spindle with offsets and
    /// tilts.
    fn linear_machines() -> Vec<MachineTool> {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/machines/afm-r1000.yaml");
        let text = std::fs::read_to_string(path).unwrap_or_default();
        let spindle = "spindle:\n  location_errors: { EX0S_mm: 0.004, EY0S_mm: -0.003, EA0S_urad: 10.0, EB0S_urad: -12.0 }\n";
        let variants = [
            text.clone(),
            text.replace("side: workpiece", "side: tool"),
            text.replace("side: tool", "side: workpiece"),
            text.replacen("tools:\n", &format!("{spindle}tools:\n"), 1),
            // Tables of one axis on different knots: merged regions shorter
            // than any table's segments, and a table reaching past the travel.
            text.replacen(
                "positions_mm: [0.0, 100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 700.0, 800.0, 900.0, 1000.0]",
                "positions_mm: [-20.0, 75.0, 210.0, 333.0, 400.0, 480.0, 600.0, 690.0, 800.0, 930.0, 1010.0]",
                1,
            )
            .replacen(
                "positions_mm: [0.0, 50.0, 100.0, 150.0, 200.0, 250.0, 300.0, 350.0, 400.0, 450.0, 500.0]",
                "positions_mm: [10.0, 40.0, 90.0, 160.0, 200.0, 260.0, 300.0, 340.0, 420.0, 450.0, 490.0]",
                1,
            ),
            // No Z axis: a slot without an axis (X Y table).
            match (text.find("  - name: Z"), text.find("\ntools:")) {
                (Some(z), Some(t)) => format!("{}{}", &text[..z], &text[t + 1..])
                    .replace("    Z: { scale_ppm_per_kw", "    # Z: { scale_ppm_per_kw"),
                _ => String::new(),
            },
        ];
        assert!(
            variants.iter().skip(1).all(|v| *v != text),
            "every variant differs"
        );
        variants
            .iter()
            .map(|t| match MachineTool::from_yaml_str(t, "afm.yaml") {
                Ok(m) => m,
                Err(e) => panic!("{e}"),
            })
            .collect()
    }

    /// Agreement of the cell form with the chain product: positions in mm
    /// (the chain's own rounding at 1 000 mm is about 1e-13 mm; the largest
    /// difference seen is 6e-13 mm), unit tool axis.
    const CELL_POS_TOL_MM: f64 = 1e-11;
    const CELL_DIR_TOL: f64 = 1e-12;

    /// Random commands over and beyond the travel, a tenth of them on a knot.
    fn commands(m: &MachineTool, s: &mut u64, n: usize) -> Vec<AxisVec> {
        let mut cmds = Vec::new();
        for _ in 0..n {
            let mut c = [0.0; 6];
            for (slot, v) in c.iter_mut().enumerate().take(3) {
                let (lo, hi) = m.travel(slot).unwrap_or((-100.0, 100.0));
                let span = hi - lo;
                *v = lo - 0.1 * span + 1.2 * span * rng(s);
                if rng(s) < 0.1 {
                    let bp = m.breakpoints(slot);
                    if !bp.is_empty() {
                        let i = ((rng(s) * bp.len() as f64) as usize).min(bp.len() - 1);
                        *v = bp[i];
                    }
                }
            }
            cmds.push(c);
        }
        cmds
    }

    /// The derivative bounds of a segment inside a cell, per cell and
    /// global, hold against central second differences of the geometric
    /// tip and unit tool axis (the cell form is cubic along a line, so the
    /// differences are exact up to rounding), and the per-cell bound of
    /// the tip is tight: it is the second derivative at an end.
    #[test]
    fn segment_bounds_hold_against_second_differences() {
        let mut s = 29u64;
        let mut tested = 0;
        let mut tight = 0;
        // Angular errors 300 times the calibrated ones: the tool axis bends
        // enough along a move for its second differences to stand above
        // the rounding.
        let mut machines = linear_machines();
        machines.push(testing::load(
            &testing::scale_angles(&testing::afm_text(), 300.0),
            "afm-angles-x300.yaml",
        ));
        let mut axis_seen = 0.0f64;
        for m in machines {
            for k in 0..400 {
                let Some((a, b, dirs)) = testing::segment_in_cell(&m, &mut || rng(&mut s), 300.0)
                else {
                    continue;
                };
                let tool = [0.0, 62.5, 140.0][k % 3];
                let Some(sb) = m.segment_bounds(&a, &b, &dirs, tool, true) else {
                    panic!("{}: no bounds on {a:?} → {b:?}", m.name());
                };
                let Some(sg) = m.second_geo(&a, &b, tool) else {
                    panic!("{}: no global bounds", m.name());
                };
                let len = (0..3).map(|i| (b[i] - a[i]).powi(2)).sum::<f64>().sqrt();
                let l1 = (0..3).map(|i| (b[i] - a[i]).abs()).sum::<f64>() / len;
                let x = (l1 * l1 - 1.0).max(0.0);
                let h = len / 8.0;
                let at = |t: f64| {
                    let mut c = a;
                    for i in 0..3 {
                        c[i] = a[i] + (b[i] - a[i]) * (t / len);
                    }
                    m.geometric(&c, &dirs, tool)
                };
                let mut pos_max = 0.0f64;
                for j in 1..8 {
                    let t = h * j as f64;
                    let (p0, p1, p2) = (at(t - h), at(t), at(t + h));
                    let pos = (p2.pos - p1.pos * 2.0 + p0.pos).norm() / (h * h);
                    let dir = (p2.dir - p1.dir * 2.0 + p0.dir).norm() / (h * h);
                    // Rounding of the tip (≈ 1e-13 mm) over h² ≥ 0.25 mm².
                    let noise = 1e-12 / (h * h);
                    assert!(
                        pos <= sb.pos2 * (1.0 + 1e-9) + noise,
                        "{}: tip {pos:e} > cell {:e}",
                        m.name(),
                        sb.pos2
                    );
                    assert!(
                        pos <= sg.k2 * x + noise,
                        "{}: tip {pos:e} > global {:e}",
                        m.name(),
                        sg.k2 * x
                    );
                    // The unit axis: u'' varies along the segment; its
                    // second difference is u'' at some point of the stretch.
                    let n = sb.dir_norm_lo;
                    let cell_axis = 2.0 * sb.dir2 / n + 6.0 * sb.dir1 * sb.dir1 / (n * n);
                    assert!(
                        dir <= cell_axis * (1.0 + 1e-6) + noise,
                        "{}: axis {dir:e} > cell {cell_axis:e}",
                        m.name()
                    );
                    assert!(
                        dir <= sg.axis2 * x + sg.axis1_sq + noise,
                        "{}: axis {dir:e} > global",
                        m.name()
                    );
                    pos_max = pos_max.max(pos);
                    if dir > noise {
                        axis_seen = axis_seen.max(dir / cell_axis);
                    }
                }
                tested += 1;
                // The tip's second derivative is affine along the segment
                // and the bound is its value at an end, one step h beyond
                // the outermost difference.
                if pos_max >= 0.75 * sb.pos2 - 1e-12 / (h * h) {
                    tight += 1;
                }
            }
        }
        assert!(tested > 1000, "{tested} segments");
        assert!(tight * 10 > tested * 9, "tight on {tight} of {tested}");
        // The axis bound is exercised: some bend stands above the rounding
        // and reaches a good part of it.
        assert!(axis_seen > 0.05, "axis bend / bound at most {axis_seen}");
    }

    #[test]
    fn cell_form_agrees_with_the_chain_product() {
        use approx::assert_abs_diff_eq;
        let machines = linear_machines();
        assert_eq!(machines.len(), 6);
        let mut s = 11u64;
        for m in &machines {
            assert!(m.pre.cells_id.is_some(), "{}", m.name());
            for (k, c) in commands(m, &mut s, 3000).iter().enumerate() {
                let mut dirs = [1i8; 6];
                for d in dirs.iter_mut() {
                    if rng(&mut s) < 0.5 {
                        *d = -1;
                    }
                }
                let tool = [0.0, 62.5, 140.0, -20.0][k % 4];
                let got = m.geometric(c, &dirs, tool);
                let want = m.geometric_chain(c, &dirs, tool);
                assert_abs_diff_eq!(got.pos, want.pos, epsilon = CELL_POS_TOL_MM);
                assert_abs_diff_eq!(got.dir, want.dir, epsilon = CELL_DIR_TOL);
                // The error itself (µm; the X Y machine, without the Z
                // errors and squareness, has points below 0.1 µm) is not
                // lost in the rounding.
                let floor = if m.axes.len() == 3 { 1e-4 } else { 1e-6 };
                let err = (want.pos - m.nominal(c, tool).pos).norm();
                assert!(err > floor, "{c:?}: error {err}");
            }
        }
    }

    /// Far beyond the tables a zero coefficient times an overflowing
    /// monomial would give NaN: the cell form must equal the finite chain.
    #[test]
    fn cell_form_far_beyond_the_travel_is_the_chain() {
        use approx::assert_relative_eq;
        let m = &linear_machines()[0];
        for v in [1e8, -3e8, 1e103, -1e200, f64::MAX] {
            let c = [v, -v / 2.0, v / 3.0, 0.0, 0.0, 0.0];
            for tool in [0.0, 62.5, 1e150] {
                let got = m.geometric(&c, &[1; 6], tool);
                let want = m.geometric_chain(&c, &[1; 6], tool);
                for r in 0..3 {
                    assert!(got.pos[r].is_nan() == want.pos[r].is_nan(), "{c:?} {tool}");
                    if want.pos[r].is_finite() {
                        assert_relative_eq!(got.pos[r], want.pos[r], max_relative = 1e-12);
                    }
                }
                assert_relative_eq!(got.dir, want.dir, max_relative = 1e-12);
            }
        }
    }

    #[test]
    fn cell_form_does_not_depend_on_the_order_of_evaluation() {
        let m = &linear_machines()[0];
        let mut s = 5u64;
        let cmds = commands(m, &mut s, 2000);
        let dirs = [1, -1, 1, 1, 1, 1];
        let run = |order: Vec<usize>| {
            let cmds = cmds.clone();
            let m = m.clone();
            // A fresh thread: a fresh cache, filled in this order.
            std::thread::spawn(move || {
                let mut out = vec![[0u64; 6]; cmds.len()];
                for i in order {
                    let p = m.geometric(&cmds[i], &dirs, 62.5);
                    for r in 0..3 {
                        out[i][r] = p.pos[r].to_bits();
                        out[i][r + 3] = p.dir[r].to_bits();
                    }
                }
                out
            })
            .join()
            .unwrap_or_default()
        };
        let forward = run((0..cmds.len()).collect());
        let backward = run((0..cmds.len()).rev().collect());
        assert_eq!(forward.len(), cmds.len());
        assert!(forward == backward);
    }

    #[test]
    fn fast_nominal_is_bit_identical_to_the_chain() {
        let mut s = 3u64;
        for m in &linear_machines() {
            let mut cmds = commands(m, &mut s, 2000);
            cmds.push([0.0; 6]);
            cmds.push([-0.0; 6]);
            cmds.push([f64::NAN, 1.0, 2.0, 0.0, 0.0, 0.0]);
            cmds.push([f64::INFINITY, -1e9, 2.0, 0.0, 0.0, 0.0]);
            for (k, c) in cmds.iter().enumerate() {
                let tool = [0.0, 62.5, 140.3, -20.0][k % 4];
                let got = m.nominal(c, tool);
                let want = pose_aff(&m.tip_htm(c, &[1; 6], tool, false));
                for r in 0..3 {
                    for (a, b) in [(got.pos[r], want.pos[r]), (got.dir[r], want.dir[r])] {
                        assert!(
                            a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
                            "{c:?} tool {tool}: {a:e} != {b:e}"
                        );
                    }
                }
            }
        }
    }

    /// A B head on X, Y, Z over a C table, error free: table pivot
    /// (10, 20, 0), head pivot 120 mm above the gauge line.
    const HEAD_TABLE: &str = "kind: machine_tool
name: head table
axes:
  - { name: C, type: rotary, side: workpiece, pivot_mm: [10, 20, 0], travel_deg: [-360, 360], rapid_deg_per_min: 3600 }
  - { name: X, type: linear, side: tool, travel_mm: [-500, 500], rapid_mm_per_min: 10000 }
  - { name: Y, type: linear, side: tool, travel_mm: [-500, 500], rapid_mm_per_min: 10000 }
  - { name: Z, type: linear, side: tool, travel_mm: [-500, 500], rapid_mm_per_min: 10000 }
  - { name: B, type: rotary, side: tool, pivot_mm: [0, 0, 120], travel_deg: [-110, 110], rapid_deg_per_min: 3600 }
";

    /// Tolerance of hand-derived head poses (rounded decimals of cos 30°).
    const HAND_TOL: f64 = 1e-9;

    #[test]
    fn a_swivel_head_turns_the_tool_about_its_pivot_by_hand() {
        // pos = P_C + Rz(C)·(p + c − Ry(B)·c − P_C), c = P_B + L·ẑ, dir =
        // Rz(C)·Ry(B)·ẑ, with Ry(θ)(x, y, z) = (x cos θ + z sin θ, y,
        // −x sin θ + z cos θ) and Rz(90°)(x, y, z) = (−y, x, z).
        let m = testing::load(HEAD_TABLE, "head.yaml");
        let l = 80.0;
        // c = (0, 0, 200). B = 90°, C = 0: Ry c = (200, 0, 0), tip at
        // p + (−200, 0, 200), tool axis +x.
        let t = m.nominal(&[10.0, 20.0, 30.0, 0.0, 90.0, 0.0], l);
        assert!(
            (t.pos - Vector3::new(-190.0, 20.0, 230.0)).norm() < HAND_TOL,
            "{t:?}"
        );
        assert!((t.dir - Vector3::x()).norm() < HAND_TOL, "{t:?}");
        // B = 30°, C = 90°, p = (50, 20, 30): Ry c = (100, 0, 173.2050808),
        // r = p + c − Ry c = (−50, 20, 56.7949192), r − P_C = (−60, 0, 56.79…)
        // → (0, −60, 56.79…) → + P_C = (10, −40, 56.7949192); dir
        // Rz(90°)(0.5, 0, 0.8660254) = (0, 0.5, 0.8660254).
        let t = m.nominal(&[50.0, 20.0, 30.0, 0.0, 30.0, 90.0], l);
        let z = 230.0 - 200.0 * 30f64.to_radians().cos();
        assert!(
            (t.pos - Vector3::new(10.0, -40.0, z)).norm() < HAND_TOL,
            "{t:?}"
        );
        let d = Vector3::new(0.0, 0.5, 30f64.to_radians().cos());
        assert!((t.dir - d).norm() < HAND_TOL, "{t:?}");
        // An error-free head attains what it is commanded.
        let g = m.geometric(&[50.0, 20.0, 30.0, 0.0, 30.0, 90.0], &[1; 6], l);
        assert!((g.pos - t.pos).norm() < HAND_TOL);
    }

    #[test]
    fn a_head_offset_error_acts_only_when_the_head_turns() {
        // EX0B = d along x: the error is (I − Ry(B))·d, zero at B = 0; at
        // B = 90° Ry(90°)(d, 0, 0) = (0, 0, −d), so the tip moves by (d, 0, d).
        let text = HEAD_TABLE.replace(
            "pivot_mm: [0, 0, 120], travel_deg: [-110, 110], rapid_deg_per_min: 3600 }",
            "pivot_mm: [0, 0, 120], travel_deg: [-110, 110], rapid_deg_per_min: 3600, location_errors: { EX0B_mm: 0.01 } }",
        );
        let m = testing::load(&text, "head.yaml");
        let at = |b: f64| {
            let c = [10.0, 20.0, 30.0, 0.0, b, 0.0];
            m.geometric(&c, &[1; 6], 80.0).pos - m.nominal(&c, 80.0).pos
        };
        assert!(at(0.0).norm() < HAND_TOL, "{:?}", at(0.0));
        assert!(
            (at(90.0) - Vector3::new(0.01, 0.0, 0.01)).norm() < HAND_TOL,
            "{:?}",
            at(90.0)
        );
    }

    #[test]
    fn machines_with_rotary_axes_have_no_cells() {
        for m in bundled() {
            let rotary = m.axes.iter().any(|a| a.kind == AxisKind::Rotary);
            assert_eq!(m.pre.cells_id.is_none(), rotary, "{}", m.name());
        }
    }

    #[test]
    fn precomputed_clamp_test_agrees_with_the_tables() {
        let mut s = 9u64;
        for m in bundled().iter().chain(&linear_machines()) {
            let mut cmds = commands(m, &mut s, 500);
            cmds.push([f64::NAN; 6]);
            for c in &cmds {
                for (a, f) in m.axes.iter().zip(&m.pre.axes) {
                    let mut qs = vec![c[a.slot % 3]];
                    qs.extend_from_slice(m.breakpoints(a.slot));
                    for q in qs {
                        assert_eq!(f.is_clamped(q), a.components.is_clamped(q), "{q}");
                    }
                }
            }
        }
    }
}
