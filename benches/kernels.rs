//! Criterion benchmarks of the hot kernels: the machine-tool prediction per
//! block (AFM R-1000, attained pose and per-effect breakdown), the
//! machine-tool compensation per block (a 400 mm raster line and a 0.01 mm
//! step of `examples/bench_inputs.rs`, every effect on), the robot
//! inverse kinematics per target and the robot compensation per target
//! (ABB IRB 1600 with a 2 kg spindle, every effect on), and the module-level
//! RAPID compensation of 1 000 targets; the RAPID parser, the fixed-decimal
//! formatter and the gravity torques ("rapid kernels").
//! Run with `cargo bench --bench kernels`.

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use postproc::compensate::{Settings, block_after};
use postproc::machine::Machine;
use postproc::machine::robot::{ConfData, IkSelect, PointMass, Robot};
use postproc::pipeline::rapid::{RapidOptions, compensate_module};
use postproc::predict::{EffectSet, ToolPredictor};
use postproc::program::interp::{Motion, Move, Plan, PlanKind};

fn machine(name: &str) -> Machine {
    let path = format!("{}/machines/{name}.yaml", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(&path).expect("machine file");
    Machine::from_yaml_str(&text, &path).expect("valid machine file")
}

fn robot() -> Robot {
    let Machine::Robot(r) = machine("abb-irb1600") else {
        panic!("abb-irb1600 is not a robot")
    };
    // The spindle of `examples/bench_inputs.rs`: TCP 150 mm along z, 2 kg
    // with its centre of gravity 70 mm along z.
    r.with_tool(
        Isometry3::translation(0.0, 0.0, 150.0),
        Some(PointMass {
            mass_kg: 2.0,
            com_mm: Vector3::new(0.0, 0.0, 70.0),
        }),
    )
}

/// The RAPID module of `examples/bench_inputs.rs` with `n` targets.
fn module(n: usize) -> String {
    let mut m = String::from(
        "MODULE Bench\n  PERS tooldata tSpindle := [TRUE,[[0,0,150],[1,0,0,0]],[2,[0,0,70],[1,0,0,0],0.01,0.01,0.004]];\n  PROC main()\n",
    );
    for i in 0..n {
        let x = 650.0 + (i % 41) as f64 * 5.0;
        let y = 50.0 + ((i / 41) % 41) as f64 * 5.0;
        let z = 300.0 + ((i / 1681) % 41) as f64 * 5.0;
        m.push_str(&format!(
            "    MoveL [[{x:.1},{y:.1},{z:.1}],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],v200,z1,tSpindle;\n"
        ));
    }
    m.push_str("  ENDPROC\nENDMODULE\n");
    m
}

fn tool_prediction(c: &mut Criterion) {
    let Machine::Tool(m) = machine("afm-r1000") else {
        panic!("afm-r1000 is not a machine tool")
    };
    let p = ToolPredictor::new(&m, EffectSet::default());
    let cmd = [250.0, 120.0, -80.0, 0.0, 0.0, 0.0];
    let dirs = [1, -1, 0, 0, 0, 0];
    let mut g = c.benchmark_group("machine tool");
    g.throughput(Throughput::Elements(1));
    g.bench_function("attained per block (afm-r1000)", |b| {
        b.iter(|| p.attained(black_box(&cmd), black_box(&dirs), black_box(100.0)))
    });
    g.bench_function("breakdown per block (afm-r1000)", |b| {
        b.iter(|| p.breakdown(black_box(&cmd), black_box(&dirs), black_box(100.0)))
    });
    // The raster of `examples/bench_inputs.rs` with G54 and tool H1: a
    // 400 mm line in X (split at a table knot) and a 0.01 mm step in Y.
    let plan = |start: [f64; 3], end: [f64; 3], dirs: [i8; 6]| Plan {
        kind: PlanKind::Motion,
        mv: Some(Move {
            motion: Motion::Linear,
            start: [start[0], start[1], start[2], 0.0, 0.0, 0.0],
            end: [end[0], end[1], end[2], 0.0, 0.0, 0.0],
            arc: None,
            dirs,
            prev_dirs: dirs,
            feed_mm_min: 2000.0,
            spindle_rpm: 0.0,
            tool: 1,
            tool_len_mm: 62.5,
        }),
        programmed: 0b11,
        ..Plan::default()
    };
    let line = plan(
        [250.0, 150.5, 150.0],
        [650.0, 150.5, 150.0],
        [1, 1, 1, 1, 1, 1],
    );
    let step = plan(
        [650.0, 150.5, 150.0],
        [650.0, 150.51, 150.0],
        [1, 1, 1, 1, 1, 1],
    );
    let settings = Settings::default();
    g.bench_function("compensate 400 mm line (afm-r1000, all effects)", |b| {
        b.iter(|| block_after(&p, black_box(&line), &settings, &mut None))
    });
    g.bench_function("compensate 0.01 mm step after a line (afm-r1000)", |b| {
        b.iter(|| {
            let mut carry = None;
            let _ = block_after(&p, &line, &settings, &mut carry);
            block_after(&p, black_box(&step), &settings, &mut carry)
        })
    });
    g.finish();
}

fn robot_kernels(c: &mut Criterion) {
    let r = robot();
    // Tool pointing down (ABB quaternion [0,0,1,0]) in the bench grid.
    let pose = Isometry3::from_parts(
        Translation3::new(750.0, 150.0, 400.0),
        UnitQuaternion::from_axis_angle(&Vector3::y_axis(), std::f64::consts::PI),
    );
    let conf = ConfData {
        cf1: 0,
        cf4: 0,
        cf6: 0,
        cfx: 0,
    };
    let sel = IkSelect::Conf(conf);
    let mut g = c.benchmark_group("robot");
    g.throughput(Throughput::Elements(1));
    g.bench_function("ik per target (irb1600, confdata)", |b| {
        b.iter(|| r.ik_conf(black_box(&pose), black_box(conf)))
    });
    g.bench_function("compensate per target (irb1600, all effects)", |b| {
        b.iter(|| {
            r.compensate(
                &r.file_context(),
                black_box(&pose),
                black_box(&sel),
                EffectSet::ALL,
            )
        })
    });
    g.finish();
    let Machine::Robot(plain) = machine("abb-irb1600") else {
        panic!("abb-irb1600 is not a robot")
    };
    let src = module(1000);
    let opts = RapidOptions::for_robot(&plain);
    let mut g = c.benchmark_group("rapid");
    g.throughput(Throughput::Elements(1000));
    g.sample_size(10);
    g.bench_function("compensate_module 1000 targets (all effects)", |b| {
        b.iter(|| compensate_module(black_box(&src), "bench.mod", &plain, &opts))
    });
    g.finish();
}

/// The RAPID pieces around the solve: parsing a 1 000-target module, the
/// fixed-decimal formatting of one target's seven numbers and the gravity
/// torques of one configuration.
fn rapid_kernels(c: &mut Criterion) {
    let src = module(1000);
    let r = robot();
    let q = [0.2, -0.3, 0.4, 0.1, 1.2, -0.5];
    let numbers = [
        751.234_567_8,
        -149.987_654_3,
        400.000_4,
        0.000_123_4,
        -0.707_106_9,
        0.999_999_9,
        -0.000_000_04,
    ];
    let mut g = c.benchmark_group("rapid kernels");
    g.throughput(Throughput::Elements(1000));
    g.sample_size(20);
    g.bench_function("parse_module 1000 targets", |b| {
        b.iter(|| postproc::program::rapid::parse_module(black_box(&src), "bench.mod"))
    });
    g.finish();
    let mut g = c.benchmark_group("rapid kernels");
    g.throughput(Throughput::Elements(1));
    g.bench_function("format one target (3 mm + 4 quaternion numbers)", |b| {
        b.iter(|| {
            let mut s = String::with_capacity(96);
            for (k, v) in black_box(&numbers).iter().enumerate() {
                let d = if k < 3 { 3 } else { 7 };
                postproc::emit::rapid::push_fixed(&mut s, *v, d);
            }
            s
        })
    });
    g.bench_function("gravity torques (irb1600 with spindle)", |b| {
        b.iter(|| r.gravity_torques(postproc::machine::robot::Model::Nominal, black_box(&q)))
    });
    g.finish();
}

criterion_group!(benches, tool_prediction, robot_kernels, rapid_kernels);
criterion_main!(benches);
