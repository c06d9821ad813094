//! Integration tests: shop_machine_z — the bundled AFM R-1000 counts
//! machine Z from the top of its travel (Haas/Fanuc, issue 37) and is the
//! same physical machine as the file that counted Z from the bottom
//! (`tests/shop/zbottom/afm-r1000-zbottom.yaml`, converted by
//! `tests/shop/zbottom/ztop.py`).
//!
//! A physical point at old machine Z `z` is at new machine Z `z − H` (H the
//! upper end of the old Z travel); the attained tip moves by the same
//! `−H` in z, so the predicted deviation (attained − programmed) must be
//! the same at every point, direction of approach, tool length, process
//! force and thermal state.

use crate::common::repo;
use nalgebra::Vector3;
use postproc::machine::tool::{MachineTool, ThermalState};
use postproc::machine::{AxisVec, DirVec};
use postproc::predict::{EffectSet, MoveContext, ThermalInput, ToolPredictor, Wrench, WrenchFrame};

/// Largest admitted difference of the two files' predictions, mm: the
/// converter writes 9 decimals of a µm (rounding ≤ 5e-13 mm per value).
const SAME_MACHINE_TOL_MM: f64 = 1e-9;

/// Tolerance on the tool direction (unit vector).
const SAME_DIR_TOL: f64 = 1e-12;

/// The converted file as the tests read it.
const NEW_FILE: &str = "tests/shop/zbottom/afm-r1000-ztop.yaml";
/// The file that counts machine Z from the bottom of its travel.
const OLD_FILE: &str = "tests/shop/zbottom/afm-r1000-zbottom.yaml";

fn load(text: &str, name: &str) -> MachineTool {
    MachineTool::from_yaml_str(text, name).expect("machine file loads")
}

fn read(rel: &str) -> String {
    std::fs::read_to_string(repo(rel)).expect("file reads")
}

/// Upper end of the Z travel of a machine file.
fn z_top(m: &MachineTool) -> f64 {
    m.travel(2).expect("Z axis").1
}

/// The largest difference of deviation and tool direction between `old`
/// and `new` over the grid, and the number of cases compared.
fn largest_difference(old: &MachineTool, new: &MachineTool) -> (f64, f64, usize) {
    let h = z_top(old) - z_top(new);
    let states = [
        // geometric only, cold, no force
        (EffectSet::ALL, None, None),
        // with a process force (static deflection)
        (
            EffectSet::ALL,
            Some(Vector3::new(180.0, -120.0, 240.0)),
            None,
        ),
        // warm (scale errors of every axis, spindle growth)
        (
            EffectSet::ALL,
            None,
            Some(ThermalState {
                growth_um: 35.0,
                scale_ppm: [22.0, -15.0, 30.0],
            }),
        ),
        // force and warm, geometric off
        (
            EffectSet {
                kinematic: 0.0,
                ..EffectSet::ALL
            },
            Some(Vector3::new(-250.0, 90.0, -160.0)),
            Some(ThermalState {
                growth_um: 12.0,
                scale_ppm: [-8.0, 40.0, -25.0],
            }),
        ),
    ];
    let (mut worst_pos, mut worst_dir, mut n) = (0.0f64, 0.0f64, 0usize);
    for (effects, force, warm) in states {
        let ctx = MoveContext {
            wrench: force.map(|f| Wrench::force(f, WrenchFrame::Workpiece)),
            thermal: warm.map_or(ThermalInput::Cold, ThermalInput::Tool),
            ..MoveContext::default()
        };
        let p_old = ToolPredictor::new(old, effects).with_context(ctx);
        let p_new = ToolPredictor::new(new, effects).with_context(ctx);
        for ix in 0..=8 {
            for iy in 0..=8 {
                for iz in 0..=8 {
                    let (x, y, z) = (125.0 * ix as f64, 62.5 * iy as f64, 62.5 * iz as f64);
                    let c_old: AxisVec = [x, y, z, 0.0, 0.0, 0.0];
                    let c_new: AxisVec = [x, y, z - h, 0.0, 0.0, 0.0];
                    for d in 0..8 {
                        let s = |bit: usize| if d >> bit & 1 == 1 { -1i8 } else { 1 };
                        let dirs: DirVec = [s(0), s(1), s(2), 1, 1, 1];
                        for tool in [0.0, 62.5, 180.0] {
                            let (b_old, a_old, _) = p_old.evaluate(&c_old, &dirs, tool);
                            let (b_new, a_new, _) = p_new.evaluate(&c_new, &dirs, tool);
                            let shift = Vector3::new(0.0, 0.0, h);
                            worst_pos = worst_pos
                                .max((b_old.total() - b_new.total()).norm())
                                .max((a_old.pos - (a_new.pos + shift)).norm());
                            worst_dir = worst_dir.max((a_old.dir - a_new.dir).norm());
                            n += 1;
                        }
                    }
                }
            }
        }
    }
    (worst_pos, worst_dir, n)
}

#[test]
fn converted_machine_predicts_the_same_deviation_at_the_same_physical_points() {
    let old = load(&read(OLD_FILE), OLD_FILE);
    let new = load(&read(NEW_FILE), NEW_FILE);
    assert_eq!(old.travel(2), Some((0.0, 500.0)));
    assert_eq!(new.travel(2), Some((-500.0, 0.0)));
    let (pos, dir, n) = largest_difference(&old, &new);
    eprintln!("largest difference {pos:e} mm, direction {dir:e}, {n} cases");
    assert_eq!(n, 4 * 729 * 8 * 3);
    assert!(
        pos <= SAME_MACHINE_TOL_MM,
        "largest deviation difference {pos:e} mm over {n} cases"
    );
    assert!(
        dir <= SAME_DIR_TOL,
        "largest tool direction difference {dir:e}"
    );
}

#[test]
fn the_comparison_sees_a_change_of_one_table_value_by_a_ten_thousandth_of_a_micrometre() {
    let old = load(&read(OLD_FILE), OLD_FILE);
    let text = read(NEW_FILE);
    // One value of one table (EXZ forward at Z −500), + 1e-4 µm.
    let from = "forward: [19.999999955,";
    assert_eq!(
        text.matches(from).count(),
        1,
        "the value is in the file once"
    );
    let bumped = load(&text.replace(from, "forward: [20.000099955,"), NEW_FILE);
    let (pos, _, _) = largest_difference(&old, &bumped);
    assert!(
        pos > SAME_MACHINE_TOL_MM,
        "a change of 1e-4 µm went unseen: {pos:e} mm"
    );
}

#[test]
fn converted_truth_of_the_observation_samples_is_the_same_machine() {
    // samples/observations/afm-r1000-truth.yaml made the simulated
    // measurements; its conversion by ztop.py must predict what it does.
    let old_file = "samples/observations/afm-r1000-truth.yaml";
    let new_file = "tests/shop/zbottom/afm-r1000-truth-ztop.yaml";
    let old = load(&read(old_file), old_file);
    let new = load(&read(new_file), new_file);
    assert_eq!(new.travel(2), Some((-500.0, 0.0)));
    let (pos, dir, n) = largest_difference(&old, &new);
    assert!(
        pos <= SAME_MACHINE_TOL_MM,
        "largest deviation difference {pos:e} mm over {n} cases"
    );
    assert!(
        dir <= SAME_DIR_TOL,
        "largest tool direction difference {dir:e}"
    );
}
