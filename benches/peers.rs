//! Criterion benchmarks against peer implementations, on the same inputs
//! and the same machine in one run:
//!
//! - **G-code parsing**: postproc's syntactic parser (`parse_line`, the
//!   first stage of `check` and `compensate`) against the `gcode` crate
//!   (gcode-rs 0.6, a `no_std` lexer and parser) on a 100 000-line raster,
//!   with a `G1` on every line (`tests/peers.rs` checks that both read the
//!   same words there), and for reference with modal lines
//!   (`X400.000 Y0.010`, as `scripts/bench` writes them): not the same
//!   work, gcode-rs drops words that follow no command.
//! - **Robot kinematics**: postproc's closed-form inverse kinematics (all
//!   eight solutions; also with each solution checked by its forward
//!   kinematics and collected, as rs-opw-kinematics does) and nominal
//!   forward kinematics of the ABB IRB 1600
//!   against `rs-opw-kinematics` (the OPW closed form of Brandstötter et
//!   al.) with the same geometry, on 1 000 flange poses of random joint
//!   values within the limits (`tests/peers.rs` checks that both give the
//!   same poses and solutions).
//!
//! Run with `cargo bench --bench peers` (also run by `scripts/bench`).

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use nalgebra::Isometry3;
use postproc::machine::Machine;
use postproc::machine::robot::{Model, Robot};
use postproc::program::gcode::{Block, parse_line};
use rs_opw_kinematics::kinematic_traits::Kinematics;
use rs_opw_kinematics::kinematics_impl::OPWKinematics;
use rs_opw_kinematics::parameters::opw_kinematics::Parameters;

/// A raster of `lines` moves: 400 mm passes in X, 0.01 mm steps in Y; with
/// `explicit` every line starts with `G1`.
fn raster(lines: usize, explicit: bool) -> String {
    let mut out = String::from("G90 G17 G21\nG1 Z0 F2000\n");
    let g = if explicit { "G1 " } else { "" };
    let mut y = 0.0f64;
    for n in 0..lines {
        let x = if (n / 2) % 2 == 0 { 400.0 } else { 0.0 };
        if n % 2 == 0 {
            out.push_str(&format!("{g}X{x:.3} Y{y:.3}\n"));
        } else {
            y += 0.01;
            out.push_str(&format!("{g}Y{y:.3}\n"));
        }
    }
    out.push_str("M30\n");
    out
}

/// Words postproc's parser finds in `src`, line by line, one reused block.
fn postproc_words(src: &str) -> usize {
    let mut block = Block::default();
    let mut words = 0;
    for (i, line) in src.as_bytes().split(|&b| b == b'\n').enumerate() {
        if parse_line(line, i + 1, "raster.nc", &mut block).is_ok() {
            words += block.words.len();
        }
    }
    words
}

/// Words gcode-rs finds in `src`: every command and its arguments.
fn gcode_rs_words(src: &str) -> usize {
    gcode::parse(src).map(|g| 1 + g.arguments().len()).sum()
}

fn gcode_parsing(c: &mut Criterion) {
    let mut g = c.benchmark_group("peers: G-code parsing");
    for (name, explicit) in [("modal lines", false), ("G1 on every line", true)] {
        let src = raster(100_000, explicit);
        g.throughput(Throughput::Bytes(src.len() as u64));
        g.bench_function(format!("postproc parse_line, {name}"), |b| {
            b.iter(|| postproc_words(black_box(&src)))
        });
        g.bench_function(format!("gcode-rs 0.6 parse, {name}"), |b| {
            b.iter(|| gcode_rs_words(black_box(&src)))
        });
    }
    g.finish();
}

/// Position tolerance of the forward check of an inverse solution, mm
/// (rs-opw-kinematics checks its solutions to 1 µm).
const CHECK_TOL_MM: f64 = 1e-3;
/// Orientation tolerance of the same check, rad.
const CHECK_TOL_RAD: f64 = 1e-6;

/// The bundled IRB 1600 without its tool (the TCP is the flange).
fn irb1600() -> Robot {
    let path = format!("{}/machines/abb-irb1600.yaml", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(&path).expect("machine file");
    let Ok(Machine::Robot(r)) = Machine::from_yaml_str(&text, &path) else {
        panic!("abb-irb1600 is not a robot")
    };
    r.with_tool(Isometry3::identity(), None, true)
}

/// The OPW parameters of the IRB 1600's nominal geometry (metres).
fn irb1600_opw() -> OPWKinematics {
    OPWKinematics::new(Parameters {
        a1: 0.150,
        a2: 0.0,
        b: 0.0,
        c1: 0.4865,
        c2: 0.700,
        c3: 0.600,
        c4: 0.065,
        offsets: [0.0, 0.0, -std::f64::consts::FRAC_PI_2, 0.0, 0.0, 0.0],
        sign_corrections: [1; 6],
        dof: 6,
    })
}

/// `n` joint vectors spread over the joint ranges (a fixed sequence).
fn joints(robot: &Robot, n: usize) -> Vec<[f64; 6]> {
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let lim = *robot.joint_limits_rad();
    (0..n)
        .map(|_| std::array::from_fn(|i| lim[i][0] + (lim[i][1] - lim[i][0]) * next()))
        .collect()
}

fn robot_kinematics(c: &mut Criterion) {
    let robot = irb1600();
    let opw = irb1600_opw();
    let qs = joints(&robot, 1000);
    let ours: Vec<_> = qs
        .iter()
        .map(|q| robot.flange_pose(Model::Nominal, q))
        .collect();
    let theirs: Vec<_> = qs.iter().map(|q| opw.forward(q)).collect();
    let mut g = c.benchmark_group("peers: robot kinematics (1000 poses)");
    g.throughput(Throughput::Elements(qs.len() as u64));
    g.bench_function("postproc inverse, all 8 solutions", |b| {
        b.iter(|| {
            ours.iter()
                .filter_map(|p| robot.ik_all(black_box(p)).ok())
                .map(|s| s.iter().flatten().count())
                .sum::<usize>()
        })
    });
    // rs-opw-kinematics checks every solution by its forward kinematics
    // (and drops those off the pose) and returns them in a Vec: the same
    // work on postproc's side.
    g.bench_function(
        "postproc inverse, all 8 solutions, each checked by forward",
        |b| {
            b.iter(|| {
                ours.iter()
                    .filter_map(|p| robot.ik_all(black_box(p)).ok().map(|s| (p, s)))
                    .map(|(p, s)| {
                        s.iter()
                            .flatten()
                            .filter(|q| {
                                let f = robot.flange_pose(Model::Nominal, q);
                                (f.translation.vector - p.translation.vector).norm() < CHECK_TOL_MM
                                    && f.rotation.angle_to(&p.rotation) < CHECK_TOL_RAD
                            })
                            .copied()
                            .collect::<Vec<_>>()
                            .len()
                    })
                    .sum::<usize>()
            })
        },
    );
    g.bench_function("rs-opw-kinematics inverse, all solutions", |b| {
        b.iter(|| {
            theirs
                .iter()
                .map(|p| opw.inverse(black_box(p)).len())
                .sum::<usize>()
        })
    });
    g.bench_function("postproc forward", |b| {
        b.iter(|| {
            qs.iter()
                .map(|q| {
                    robot
                        .flange_pose(Model::Nominal, black_box(q))
                        .translation
                        .x
                })
                .sum::<f64>()
        })
    });
    g.bench_function("rs-opw-kinematics forward", |b| {
        b.iter(|| {
            qs.iter()
                .map(|q| opw.forward(black_box(q)).translation.x)
                .sum::<f64>()
        })
    });
    g.finish();
}

criterion_group!(benches, gcode_parsing, robot_kinematics);
criterion_main!(benches);
