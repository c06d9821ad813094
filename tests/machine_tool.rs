//! Integration tests: machine_tool — the machine file loader and the
//! geometric error model against hand-derived goldens.
//!
//! Chain convention (machines/README.md): `W_T_tip = E_1 ··· E_k · G(L) ·
//! E_k+1 ··· E_n · S · T(−L)`, workpiece-side axes first, each `E` the
//! motion of the tool relative to the workpiece:
//! linear `E = LOC · Trans(q ê) · COM(q)`, rotary
//! `E = Trans(P+d) · LOC · Rot(ê, θ+ε0) · COM(θ) · Trans(−(P+d))`,
//! small-angle `COM = [[1,−εc,εb,δx],[εc,1,−εa,δy],[−εb,εa,1,δz]]`.

use crate::common::repo;
use approx::assert_abs_diff_eq;
use postproc::machine::tool::MachineTool;
use postproc::machine::{AxisVec, DirVec, Machine};

/// Position tolerance for exact (closed-form) goldens, mm.
const POS_TOL_MM: f64 = 1e-12;
/// Tolerance on unit tool directions.
const DIR_TOL: f64 = 1e-12;
/// Tolerance for Jacobian vs central finite differences.
const FD_TOL: f64 = 1e-6;
/// Finite-difference step, mm or degrees.
const FD_STEP: f64 = 1e-4;

const FWD: DirVec = [1; 6];
const REV: DirVec = [-1; 6];

/// A 3-axis machine (X, Y workpiece side; Z tool side) with no errors;
/// `{X}`, `{Y}`, `{Z}` are replaced by extra keys of each axis.
const BASE3: &str = "kind: machine_tool
name: test3
axes:
  - name: X
    type: linear
    side: workpiece
    travel_mm: [0, 1000]
    rapid_mm_per_min: 10000
{X}  - name: Y
    type: linear
    side: workpiece
    travel_mm: [0, 500]
    rapid_mm_per_min: 10000
{Y}  - name: Z
    type: linear
    side: tool
    travel_mm: [0, 500]
    rapid_mm_per_min: 10000
{Z}";

fn three_axis(x: &str, y: &str, z: &str) -> MachineTool {
    let text = BASE3.replace("{X}", x).replace("{Y}", y).replace("{Z}", z);
    match MachineTool::from_yaml_str(&text, "t.yaml") {
        Ok(m) => m,
        Err(e) => panic!("test machine must load: {e}\n{text}"),
    }
}

fn err_of(text: &str) -> String {
    match MachineTool::from_yaml_str(text, "f.yaml") {
        Ok(_) => panic!("expected an error for:\n{text}"),
        Err(e) => e.to_string(),
    }
}

fn load_bundled(rel: &str) -> MachineTool {
    let path = repo(rel);
    match Machine::load(&path) {
        Ok(Machine::Tool(t)) => t,
        Ok(_) => panic!("{rel} is not a machine tool"),
        Err(e) => panic!("{rel}: {e}"),
    }
}

/// Deterministic pseudo-random numbers in [0, 1) (64-bit LCG).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next()
    }
}

#[test]
fn positioning_error_only_shifts_along_x() {
    // EXX table: 0 µm at x=0, 10 µm at x=1000 (forward). At x=250 the
    // interpolated value is 2.5 µm = 0.0025 mm. COM_X is then a pure
    // translation (δx, 0, 0), so geometric − nominal = (0.0025, 0, 0)
    // whatever Y, Z and L are.
    let m = three_axis(
        "    component_errors:\n      EXX_um:\n        positions_mm: [0, 1000]\n        forward: [0, 10]\n",
        "",
        "",
    );
    assert!(!m.is_error_free());
    let cmd: AxisVec = [250.0, 100.0, 50.0, 0.0, 0.0, 0.0];
    let nom = m.nominal(&cmd, 100.0);
    let geo = m.geometric(&cmd, &FWD, 100.0);
    assert_abs_diff_eq!(nom.pos.x, 250.0, epsilon = POS_TOL_MM);
    assert_abs_diff_eq!(nom.pos.y, 100.0, epsilon = POS_TOL_MM);
    assert_abs_diff_eq!(nom.pos.z, 50.0, epsilon = POS_TOL_MM);
    let d = geo.pos - nom.pos;
    assert_abs_diff_eq!(d.x, 0.0025, epsilon = POS_TOL_MM);
    assert_abs_diff_eq!(d.y, 0.0, epsilon = POS_TOL_MM);
    assert_abs_diff_eq!(d.z, 0.0, epsilon = POS_TOL_MM);
    assert_abs_diff_eq!(geo.dir, nalgebra::Vector3::z(), epsilon = DIR_TOL);
}

#[test]
fn xy_squareness_gives_minus_eps_y_in_x() {
    // EC0Y = ε = 50 µrad (rotation of the Y axis about z relative to X).
    // E_Y = R(εc=ε) · Trans(0, y, 0); the small-angle matrix maps (0, y, 0)
    // to (−ε·y, y, 0), and leaves the following Z translation (0, 0, z) and
    // the tool offsets unchanged (its third column is (0, 0, 1)).
    // So at y = 400: x error = −50e-6 · 400 = −0.02 mm, y and z errors 0.
    let m = three_axis("", "    location_errors:\n      EC0Y_urad: 50\n", "");
    let cmd: AxisVec = [300.0, 400.0, 120.0, 0.0, 0.0, 0.0];
    let d = m.tip_error_mm(&cmd, &FWD, 80.0);
    assert_abs_diff_eq!(d.x, -0.02, epsilon = POS_TOL_MM);
    assert_abs_diff_eq!(d.y, 0.0, epsilon = POS_TOL_MM);
    assert_abs_diff_eq!(d.z, 0.0, epsilon = POS_TOL_MM);
}

/// Squareness between X and the tool-side Z: `EB0Z = ε` tilts the Z motion
/// about y. The tilt acts on everything after Z in the chain, i.e. from the
/// Z frame origin (machine zero of the gauge line) to the tip at height
/// z − L: x error = ε·(z − L), exactly ε·z only for a zero-length tool.
/// ε = 40 µrad, z = 200 mm: L = 0 → 0.008 mm; L = 150 → 0.002 mm;
/// L = 260 (tip below machine zero) → −0.0024 mm.
#[test]
fn xz_squareness_acts_through_z_minus_the_tool_length() {
    let m = three_axis("", "", "    location_errors:\n      EB0Z_urad: 40\n");
    let cmd: AxisVec = [300.0, 100.0, 200.0, 0.0, 0.0, 0.0];
    for (l, want) in [(0.0, 0.008), (150.0, 0.002), (260.0, -0.0024)] {
        let d = m.tip_error_mm(&cmd, &FWD, l);
        assert_abs_diff_eq!(d.x, 40e-6 * (200.0 - l), epsilon = POS_TOL_MM);
        assert_abs_diff_eq!(d.x, want, epsilon = 1e-9);
        assert_abs_diff_eq!(d.y, 0.0, epsilon = POS_TOL_MM);
    }
}

#[test]
fn z_pitch_acts_through_the_tool_length() {
    // EBZ = ε = 20 µrad (constant), Z on the tool side. Its COM sits at the
    // gauge line; the tip is T(−L) below it: COM · (0, 0, −L) = (εb·(−L), 0, −L),
    // so the tip moves by −L·ε in x: L = 150 mm → −0.003 mm. With L = 0 the
    // shift vanishes. The tool direction is COM's third column (ε, 0, 1)
    // normalized.
    let m = three_axis(
        "",
        "",
        "    component_errors:\n      EBZ_urad:\n        positions_mm: [0, 500]\n        forward: [20, 20]\n",
    );
    let cmd: AxisVec = [500.0, 250.0, 200.0, 0.0, 0.0, 0.0];
    let d = m.tip_error_mm(&cmd, &FWD, 150.0);
    assert_abs_diff_eq!(d.x, -0.003, epsilon = POS_TOL_MM);
    assert_abs_diff_eq!(d.y, 0.0, epsilon = POS_TOL_MM);
    assert_abs_diff_eq!(d.z, 0.0, epsilon = POS_TOL_MM);
    let d0 = m.tip_error_mm(&cmd, &FWD, 0.0);
    assert_abs_diff_eq!(d0.x, 0.0, epsilon = POS_TOL_MM);
    let dir = m.geometric(&cmd, &FWD, 150.0).dir;
    let n = (1.0f64 + 20e-6 * 20e-6).sqrt();
    assert_abs_diff_eq!(dir.x, 20e-6 / n, epsilon = DIR_TOL);
    assert_abs_diff_eq!(dir.z, 1.0 / n, epsilon = DIR_TOL);
}

#[test]
fn workpiece_side_pitch_lever_is_tip_height_above_machine_zero() {
    // EBX = ε = 30 µrad on the workpiece-side X axis. COM_X acts about the
    // X frame origin; the rest of the chain reaches the tip at (0, y, z) from
    // it, so the x error is εb·z = 30e-6 · 200 = 0.006 mm (independent of L),
    // and the z error is −εb·0 = 0.
    let m = three_axis(
        "    component_errors:\n      EBX_urad:\n        positions_mm: [0, 1000]\n        forward: [30, 30]\n",
        "",
        "",
    );
    let cmd: AxisVec = [400.0, 100.0, 200.0, 0.0, 0.0, 0.0];
    for l in [0.0, 120.0] {
        let d = m.tip_error_mm(&cmd, &FWD, l);
        assert_abs_diff_eq!(d.x, 0.006, epsilon = POS_TOL_MM);
        assert_abs_diff_eq!(d.z, 0.0, epsilon = POS_TOL_MM);
    }
}

#[test]
fn bidirectional_lookup_interpolation_and_clamping() {
    // Forward 0 → 10 µm and reverse 4 → 14 µm over 0..1000 mm. At x = 250:
    // forward 2.5 µm, reverse 4 + 2.5 = 6.5 µm. Beyond the table (x = 1200)
    // the end value is used (10 µm forward) and bit 0 of clamped_axes is set;
    // Y has no tables, so it is never clamped.
    let m = three_axis(
        "    component_errors:\n      EXX_um:\n        positions_mm: [0, 1000]\n        forward: [0, 10]\n        reverse: [4, 14]\n",
        "",
        "",
    );
    let cmd: AxisVec = [250.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    assert_abs_diff_eq!(
        m.tip_error_mm(&cmd, &FWD, 0.0).x,
        0.0025,
        epsilon = POS_TOL_MM
    );
    assert_abs_diff_eq!(
        m.tip_error_mm(&cmd, &REV, 0.0).x,
        0.0065,
        epsilon = POS_TOL_MM
    );
    let mut dirs = FWD;
    dirs[0] = 0; // unknown (not moved yet) counts as forward
    assert_abs_diff_eq!(
        m.tip_error_mm(&cmd, &dirs, 0.0).x,
        0.0025,
        epsilon = POS_TOL_MM
    );
    assert_eq!(m.clamped_axes(&cmd), 0);
    let out: AxisVec = [1200.0, -50.0, 0.0, 0.0, 0.0, 0.0];
    assert_abs_diff_eq!(
        m.tip_error_mm(&out, &FWD, 0.0).x,
        0.010,
        epsilon = POS_TOL_MM
    );
    assert_eq!(m.clamped_axes(&out), 0b1);
    let low: AxisVec = [-1.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    assert_eq!(m.clamped_axes(&low), 0b1);
    assert_abs_diff_eq!(
        m.tip_error_mm(&low, &REV, 0.0).x,
        0.004,
        epsilon = POS_TOL_MM
    );
}

/// A 5-axis AC trunnion (C on A on Y; X, Z tool side) without errors.
const BASE5: &str = "kind: machine_tool
name: test5
axes:
  - name: C
    type: rotary
    side: workpiece
    pivot_mm: [10, 20, 0]
    travel_deg: [-360, 360]
    rapid_deg_per_min: 3600
{C}  - name: A
    type: rotary
    side: workpiece
    pivot_mm: [0, 0, -100]
    travel_deg: [-110, 110]
    rapid_deg_per_min: 3600
{A}  - name: Y
    type: linear
    side: workpiece
    travel_mm: [-300, 300]
    rapid_mm_per_min: 10000
  - name: X
    type: linear
    side: tool
    travel_mm: [-400, 400]
    rapid_mm_per_min: 10000
  - name: Z
    type: linear
    side: tool
    travel_mm: [-500, 0]
    rapid_mm_per_min: 10000
";

fn five_axis(c: &str, a: &str) -> MachineTool {
    let text = BASE5.replace("{C}", c).replace("{A}", a);
    match MachineTool::from_yaml_str(&text, "t5.yaml") {
        Ok(m) => m,
        Err(e) => panic!("test machine must load: {e}"),
    }
}

#[test]
fn five_axis_nominal_by_hand() {
    // Nominal: pos = E_C(E_A(p)), p = (X, Y, Z), with E_A(v) = P_A + Rx(A)(v − P_A),
    // E_C(v) = P_C + Rz(C)(v − P_C), P_A = (0, 0, −100), P_C = (10, 20, 0);
    // Rx(90°)(x, y, z) = (x, −z, y), Rz(90°)(x, y, z) = (−y, x, z).
    let m = five_axis("", "");
    assert!(m.is_error_free());
    let l = 75.0;
    // A = C = 0: pos = p, dir = +z.
    let t = m.nominal(&[10.0, 20.0, 30.0, 0.0, 0.0, 0.0], l);
    assert_abs_diff_eq!(
        t.pos,
        nalgebra::Vector3::new(10.0, 20.0, 30.0),
        epsilon = POS_TOL_MM
    );
    assert_abs_diff_eq!(t.dir, nalgebra::Vector3::z(), epsilon = DIR_TOL);
    // A = 90°, C = 0, p = (10, 20, 30): v − P_A = (10, 20, 130) → (10, −130, 20)
    // → + P_A = (10, −130, −80); dir Rx(90°)ẑ = (0, −1, 0).
    let t = m.nominal(&[10.0, 20.0, 30.0, 90.0, 0.0, 0.0], l);
    assert_abs_diff_eq!(
        t.pos,
        nalgebra::Vector3::new(10.0, -130.0, -80.0),
        epsilon = 1e-9
    );
    assert_abs_diff_eq!(
        t.dir,
        nalgebra::Vector3::new(0.0, -1.0, 0.0),
        epsilon = DIR_TOL
    );
    // A = 0, C = 90°, p = (50, 20, 30): v − P_C = (40, 0, 30) → (0, 40, 30)
    // → + P_C = (10, 60, 30); dir stays +z.
    let t = m.nominal(&[50.0, 20.0, 30.0, 0.0, 0.0, 90.0], l);
    assert_abs_diff_eq!(
        t.pos,
        nalgebra::Vector3::new(10.0, 60.0, 30.0),
        epsilon = 1e-9
    );
    assert_abs_diff_eq!(t.dir, nalgebra::Vector3::z(), epsilon = DIR_TOL);
    // A = 90°, C = 90°, p = (10, 20, 30): E_A gives (10, −130, −80);
    // − P_C = (0, −150, −80) → Rz(90°) → (150, 0, −80) → + P_C = (160, 20, −80);
    // dir Rz(90°)(0, −1, 0) = (1, 0, 0).
    let t = m.nominal(&[10.0, 20.0, 30.0, 90.0, 0.0, 90.0], l);
    assert_abs_diff_eq!(
        t.pos,
        nalgebra::Vector3::new(160.0, 20.0, -80.0),
        epsilon = 1e-9
    );
    assert_abs_diff_eq!(
        t.dir,
        nalgebra::Vector3::new(1.0, 0.0, 0.0),
        epsilon = DIR_TOL
    );
}

#[test]
fn rotary_offset_shows_only_when_rotated() {
    // EY0A = d = 0.01 mm moves the A line to P_A + (0, d, 0). The tip is
    // P' + Rx(A)(p − P'), so its error is (I − Rx(A))·(0, d, 0):
    // A = 0 → 0; A = 90° → (0, d, 0) − (0, 0, d) = (0, 0.01, −0.01).
    let m = five_axis("", "    location_errors:\n      EY0A_mm: 0.01\n");
    let at0 = m.tip_error_mm(&[10.0, 20.0, 30.0, 0.0, 0.0, 0.0], &FWD, 50.0);
    assert_abs_diff_eq!(at0, nalgebra::Vector3::zeros(), epsilon = POS_TOL_MM);
    let at90 = m.tip_error_mm(&[10.0, 20.0, 30.0, 90.0, 0.0, 0.0], &FWD, 50.0);
    assert_abs_diff_eq!(
        at90,
        nalgebra::Vector3::new(0.0, 0.01, -0.01),
        epsilon = 1e-9
    );
}

#[test]
fn zero_errors_give_nominal_for_random_commands() {
    let m3 = three_axis("", "", "");
    let m5 = five_axis("", "");
    assert!(m3.is_error_free() && m5.is_error_free());
    let mut r = Lcg(42);
    for _ in 0..200 {
        let cmd: AxisVec = [
            r.range(-400.0, 1000.0),
            r.range(-300.0, 500.0),
            r.range(-500.0, 500.0),
            r.range(-110.0, 110.0),
            0.0,
            r.range(-360.0, 360.0),
        ];
        let dirs: DirVec = [if r.next() < 0.5 { 1 } else { -1 }; 6];
        let l = r.range(0.0, 200.0);
        // 3-axis: the nominal tip is the command itself.
        let n3 = m3.nominal(&cmd, l);
        assert_abs_diff_eq!(
            n3.pos,
            nalgebra::Vector3::new(cmd[0], cmd[1], cmd[2]),
            epsilon = 1e-9
        );
        let g3 = m3.geometric(&cmd, &dirs, l);
        assert_abs_diff_eq!(g3.pos, n3.pos, epsilon = POS_TOL_MM);
        assert_abs_diff_eq!(g3.dir, n3.dir, epsilon = DIR_TOL);
        let n5 = m5.nominal(&cmd, l);
        let g5 = m5.geometric(&cmd, &dirs, l);
        assert_abs_diff_eq!(g5.pos, n5.pos, epsilon = POS_TOL_MM);
        assert_abs_diff_eq!(g5.dir, n5.dir, epsilon = DIR_TOL);
        // Rigid rotations keep the tool direction a unit vector.
        assert_abs_diff_eq!(n5.dir.norm(), 1.0, epsilon = DIR_TOL);
    }
}

fn check_jacobian(m: &MachineTool, cmd: &AxisVec, dirs: &DirVec, l: f64) {
    let j = m.jacobian(cmd, dirs, l);
    for slot in 0..6 {
        let mut plus = *cmd;
        let mut minus = *cmd;
        plus[slot] += FD_STEP;
        minus[slot] -= FD_STEP;
        let gp = m.geometric(&plus, dirs, l);
        let gm = m.geometric(&minus, dirs, l);
        let dpos = (gp.pos - gm.pos) / (2.0 * FD_STEP);
        let ddir = (gp.dir - gm.dir) / (2.0 * FD_STEP);
        for r in 0..3 {
            assert_abs_diff_eq!(j[(r, slot)], dpos[r], epsilon = FD_TOL);
            assert_abs_diff_eq!(j[(r + 3, slot)], ddir[r], epsilon = FD_TOL);
        }
    }
}

#[test]
fn jacobian_matches_central_differences() {
    // Commands inside table segments (not on knots), both directions.
    let afm = load_bundled("machines/afm-r1000.yaml");
    check_jacobian(&afm, &[123.4, 321.7, 87.3, 0.0, 0.0, 0.0], &FWD, 140.0);
    check_jacobian(&afm, &[777.7, 12.3, 456.1, 0.0, 0.0, 0.0], &REV, 62.5);
    let ac = load_bundled("machines/five-axis-ac.yaml");
    check_jacobian(&ac, &[-123.4, 56.7, -210.9, 33.3, 0.0, 71.1], &FWD, 110.0);
    check_jacobian(&ac, &[250.1, -170.3, -30.2, -71.7, 0.0, -222.2], &REV, 72.5);
}

#[test]
fn bundled_machine_files_load() {
    let afm = load_bundled("machines/afm-r1000.yaml");
    assert!(!afm.is_error_free());
    assert!(afm.has_axis(0) && afm.has_axis(1) && afm.has_axis(2) && !afm.has_axis(3));
    assert_eq!(afm.travel(0), Some((0.0, 1000.0)));
    assert_eq!(afm.tool_length_mm(1), Some(62.5));
    assert_eq!(afm.tool_length_mm(10), Some(180.0));
    assert_eq!(afm.work_offset_mm("G54"), Some([250.0, 150.0, 150.0]));
    assert_eq!(afm.output_decimals(), Some(4));
    assert_eq!(afm.rapid_per_min(3), f64::INFINITY);
    // Predicted errors stay within tens of µm over the work zone.
    let d = afm.tip_error_mm(&[1000.0, 500.0, 500.0, 0.0, 0.0, 0.0], &FWD, 180.0);
    assert!(d.norm() < 0.1, "{d}");
    let ac = load_bundled("machines/five-axis-ac.yaml");
    assert!(ac.has_axis(3) && ac.has_axis(5) && !ac.has_axis(4));
    let d = ac.tip_error_mm(&[100.0, 100.0, -100.0, 45.0, 0.0, 120.0], &FWD, 100.0);
    assert!(d.norm() < 0.2, "{d}");
}

/// Valid 3-axis file used by the malformed-snippet tests (line numbers
/// matter: each case replaces one line).
const GOOD: [&str; 26] = [
    "kind: machine_tool",
    "name: test",
    "axes:",
    "  - name: X",
    "    type: linear",
    "    side: workpiece",
    "    travel_mm: [0, 1000]",
    "    rapid_mm_per_min: 10000",
    "    component_errors:",
    "      EXX_um:",
    "        positions_mm: [0, 1000]",
    "        forward: [0, 10]",
    "  - name: Y",
    "    type: linear",
    "    side: workpiece",
    "    travel_mm: [0, 500]",
    "    rapid_mm_per_min: 10000",
    "  - name: Z",
    "    type: linear",
    "    side: tool",
    "    travel_mm: [0, 500]",
    "    rapid_mm_per_min: 10000",
    "tools:",
    "  1: { length_mm: 100 }",
    "work_offsets_mm:",
    "  G54: [1, 2, 3]",
];

fn with_line(line: usize, text: &str) -> String {
    let mut lines: Vec<String> = GOOD.iter().map(|s| s.to_string()).collect();
    lines[line - 1] = text.to_string();
    lines.join("\n") + "\n"
}

#[test]
fn good_snippet_loads() {
    let text = GOOD.join("\n");
    let m = MachineTool::from_yaml_str(&text, "f.yaml");
    assert!(m.is_ok(), "{:?}", m.err());
}

#[test]
fn malformed_files_give_located_errors() {
    // (line replaced, new text, expected message prefix)
    let cases: &[(usize, &str, &str)] = &[
        (
            12,
            "        forward: [0, .nan]",
            "f.yaml:12:9: axes[0].component_errors.EXX_um.forward: value `NaN` is not a finite number",
        ),
        (
            12,
            "        forward: [0, .inf]",
            "f.yaml:12:9: axes[0].component_errors.EXX_um.forward: value `inf`",
        ),
        (
            7,
            "    travel_mm: [1000, 0]",
            "f.yaml:7:5: axes[0].travel_mm: minimum 1000 must be below maximum 0",
        ),
        (
            11,
            "        positions_mm: [0, 0]",
            "f.yaml:11:9: axes[0].component_errors.EXX_um.positions_mm: positions must be strictly increasing",
        ),
        (
            12,
            "        forward: [0, 10, 20]",
            "f.yaml:12:9: axes[0].component_errors.EXX_um.forward: 3 values for 2 positions",
        ),
        (
            18,
            "  - name: X",
            "f.yaml:18:5: axes[2].name: duplicate axis `X`",
        ),
        (
            10,
            "      EXY_um:",
            "f.yaml:10:7: axes[0].component_errors.EXY_um: unknown component error `EXY_um` for the X axis",
        ),
        (
            24,
            "  1: { length_mm: -5 }",
            "f.yaml:24:8: tools.1.length_mm: tool length `-5` is negative",
        ),
        (
            14,
            "    type: rotary",
            "f.yaml:14:5: axes[1].type: axis `Y` must be linear",
        ),
        (
            12,
            "        forward: [0, 1500]",
            "f.yaml:12:9: axes[0].component_errors.EXX_um.forward: 1.5 mm exceeds the 1 mm limit",
        ),
        (
            26,
            "  G60: [1, 2, 3]",
            "f.yaml:26:3: work_offsets_mm.G60: unknown work offset `G60`",
        ),
        (
            6,
            "    side: tool",
            "f.yaml:15:5: axes[1].side: workpiece-side axes must all come before",
        ),
        (
            4,
            "  - name: Q",
            "f.yaml:4:5: axes[0].name: unknown axis `Q`",
        ),
        (
            1,
            "kind: robot",
            "f.yaml:1:1: kind: expected `machine_tool`",
        ),
        (
            16,
            "    travel_deg: [0, 500]",
            "f.yaml:16:5: axes[1].travel_deg: a linear axis takes values in mm",
        ),
    ];
    for (line, new, want) in cases {
        let text = with_line(*line, new);
        let err = err_of(&text);
        assert!(
            err.starts_with(want),
            "line {line} `{new}`:\n got  {err}\n want {want}"
        );
    }
    // Angular magnitude: 20000 µrad = 0.02 rad > 0.01 rad.
    let text = with_line(10, "      EAX_urad:");
    let text = text.replace("forward: [0, 10]", "forward: [0, 20000]");
    let err = err_of(&text);
    assert!(
        err.starts_with("f.yaml:12:9: axes[0].component_errors.EAX_urad.forward: 20000")
            && err.contains("0.01 rad"),
        "{err}"
    );
    // Serde-level errors: unknown key, wrong type, missing key.
    let err = err_of(&with_line(8, "    rapid_mm_per_minute: 10000"));
    assert!(
        err.starts_with("f.yaml:8:") && err.contains("rapid_mm_per_minute"),
        "{err}"
    );
    let err = err_of(&with_line(7, "    travel_mm: [0, abc]"));
    assert!(
        err.starts_with("f.yaml:7:") && err.contains("axes[0].travel_mm"),
        "{err}"
    );
    let err = err_of(&with_line(5, "    type: helical"));
    assert!(
        err.starts_with("f.yaml:5:") && err.contains("axes[0].type"),
        "{err}"
    );
}

#[test]
fn garbage_never_panics() {
    let inputs = [
        "",
        "kind: [",
        "kind: machine_tool\n",
        "kind: machine_tool\nname: x\naxes: []\n",
        "kind: machine_tool\nname: x\naxes: 5\n",
        "\u{0}\u{1}binary",
        "kind: machine_tool\nname: x\naxes:\n  - {name: X, type: linear, side: workpiece, travel_mm: [0, 1], rapid_mm_per_min: 1, component_errors: {EXX_um: {positions_mm: [], forward: []}}}\n",
        "kind: machine_tool\nname: x\naxes:\n  - {name: XX, type: linear, side: workpiece}\n",
    ];
    for t in inputs {
        let r = MachineTool::from_yaml_str(t, "g.yaml");
        let e = match r {
            Ok(_) => panic!("accepted `{t}`"),
            Err(e) => e.to_string(),
        };
        assert!(e.starts_with("g.yaml:"), "{e}");
    }
    let e = err_of("kind: machine_tool\nname: x\naxes: []\n");
    assert!(
        e.starts_with("f.yaml:3:1: axes: a machine tool needs at least one axis"),
        "{e}"
    );
}

#[test]
fn output_decimals_are_read_and_bounded() {
    let base = BASE3
        .replace("{X}", "")
        .replace("{Y}", "")
        .replace("{Z}", "");
    let ok = format!("{base}output:\n  decimals_mm: 4\n  decimals_deg: 6\n");
    let m = MachineTool::from_yaml_str(&ok, "f.yaml").expect("valid output block");
    assert_eq!(m.output_decimals(), Some(4));
    assert_eq!(m.output_decimals_deg(), Some(6));
    let bad = format!("{base}output:\n  decimals_deg: 12\n");
    let e = err_of(&bad);
    assert!(e.contains("output.decimals_deg"), "{e}");
    assert!(e.contains("12"), "{e}");
}

#[test]
fn compensation_tolerance_is_read_and_validated() {
    // The bundled machine tools give the model's own accuracy.
    for rel in ["machines/afm-r1000.yaml", "machines/five-axis-ac.yaml"] {
        let m = load_bundled(rel);
        assert_eq!(m.compensation_tolerance_mm(), Some(0.003), "{rel}");
    }
    let base = BASE3
        .replace("{X}", "")
        .replace("{Y}", "")
        .replace("{Z}", "");
    let m = MachineTool::from_yaml_str(&base, "t.yaml").unwrap();
    assert_eq!(m.compensation_tolerance_mm(), None);
    let with = |v: &str| format!("{base}compensation:\n  tolerance_mm: {v}\n");
    let m = MachineTool::from_yaml_str(&with("0.002"), "t.yaml").unwrap();
    assert_eq!(m.compensation_tolerance_mm(), Some(0.002));
    // Below ten times the solver's convergence, above 1 mm, not a number,
    // or an unknown key: refused at the key.
    for bad in ["0.0000001", "2", "-0.003", ".nan"] {
        let e = err_of(&with(bad));
        assert!(e.contains("compensation.tolerance_mm"), "{bad}: {e}");
    }
    let e = err_of(&format!("{base}compensation:\n  tolerance_um: 3\n"));
    assert!(e.contains("tolerance_um"), "{e}");
}
