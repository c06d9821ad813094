//! Throughput of the G-code pipeline on a generated raster program:
//! parse + interpret (`check`), parse + interpret + emit with effects off,
//! and full compensation with the AFM R-1000 example model. Prints MB/s and
//! blocks/s. Run with `scripts/bench` or `cargo bench --bench throughput`
//! (`BENCH_BLOCKS` sets the program size, default 1 000 000).

use std::io::{BufReader, Cursor, Write};
use std::time::Instant;

use postproc::compensate::Settings;
use postproc::emit::gcode::EmitOptions;
use postproc::machine::Machine;
use postproc::pipeline::gcode::Job;
use postproc::predict::{EffectSet, ToolPredictor};
use postproc::program::interp::Setup;

fn raster(blocks: usize) -> Vec<u8> {
    let mut out = Vec::with_capacity(blocks * 28);
    writeln!(
        out,
        "%\nO2000 (RASTER)\nG90 G17 G21 G54\nT1 M6\nG43 H1 G0 X0 Y0 Z20\nG1 Z0 F2000"
    )
    .unwrap();
    let mut n = 0usize;
    let mut y = 0.0f64;
    while n < blocks {
        let x = if (n / 2) % 2 == 0 { 400.0 } else { 0.0 };
        if n % 2 == 0 {
            writeln!(out, "X{x:.3} Y{y:.3}").unwrap();
        } else {
            y += 0.01;
            if y > 300.0 {
                y = 0.0;
            }
            writeln!(out, "Y{y:.3}").unwrap();
        }
        n += 1;
    }
    writeln!(out, "M30\n%").unwrap();
    out
}

fn main() {
    let blocks: usize = std::env::var("BENCH_BLOCKS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1_000_000);
    let program = raster(blocks);
    let mb = program.len() as f64 / 1e6;
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/machines/afm-r1000.yaml"
    ))
    .expect("machine file");
    let Ok(Machine::Tool(machine)) = Machine::from_yaml_str(&text, "afm-r1000.yaml") else {
        panic!("afm-r1000.yaml is not a machine tool")
    };
    let setup = Setup::for_machine(&machine);
    let emit = EmitOptions {
        decimals_mm: Some(4),
        decimals_deg: None,
        annotate: false,
    };
    println!(
        "program: {blocks} blocks, {mb:.1} MB, {} threads",
        rayon::current_num_threads()
    );
    let cases: [(&str, Option<EffectSet>); 3] = [
        ("check (parse+interpret)", None),
        ("compensate --effects none", Some(EffectSet::none())),
        ("compensate (geometric)", Some(EffectSet::default())),
    ];
    for (name, effects) in cases {
        let predictor = effects.map(|e| ToolPredictor::new(&machine, e));
        let job = Job {
            predictor,
            setup: setup.clone(),
            settings: Settings::default(),
            emit,
            pool: None,
            travel: None,
        };
        let mut sink: Vec<u8> = Vec::with_capacity(program.len() * 2);
        let t = Instant::now();
        let summary = job
            .run(
                BufReader::new(Cursor::new(&program)),
                "raster.nc",
                Some(&mut sink),
                None,
            )
            .expect("job runs");
        let s = t.elapsed().as_secs_f64();
        println!(
            "{name:<28} {:>8.1} MB/s {:>12.0} blocks/s  ({:.2} s, {} blocks changed, {} added)",
            mb / s,
            summary.blocks as f64 / s,
            s,
            summary.changed,
            summary.added
        );
    }
}
