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
use postproc::machine::robot::Model;
use postproc::program::gcode::{Block, parse_line};
use rs_opw_kinematics::kinematic_traits::Kinematics;

mod peer_setup;
use peer_setup::{irb1600, irb1600_opw, joints};

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
