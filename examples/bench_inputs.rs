//! Writes the benchmark inputs of `scripts/bench` into a folder: a 3-axis
//! raster program (`raster.nc`, `BENCH_BLOCKS` blocks, default 1 000 000) and
//! an ABB RAPID module of robot targets (`targets.mod`, `BENCH_TARGETS`
//! targets, default 100 000) reachable by the IRB 1600 with the tool pointing
//! down. Usage: `cargo run --release --example bench_inputs -- DIR`.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::PathBuf;

fn count(var: &str, default: usize) -> usize {
    std::env::var(var)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn raster(path: &PathBuf, blocks: usize) -> std::io::Result<()> {
    let mut out = BufWriter::new(File::create(path)?);
    writeln!(
        out,
        "%\nO2000 (RASTER)\nG90 G17 G21 G54\nT1 M6\nG43 H1 G0 X0 Y0 Z20\nG1 Z0 F2000"
    )?;
    let mut y = 0.0f64;
    for n in 0..blocks {
        if n % 2 == 0 {
            let x = if (n / 2) % 2 == 0 { 400.0 } else { 0.0 };
            writeln!(out, "X{x:.3} Y{y:.3}")?;
        } else {
            y += 0.01;
            if y > 300.0 {
                y = 0.0;
            }
            writeln!(out, "Y{y:.3}")?;
        }
    }
    writeln!(out, "M30\n%")?;
    out.flush()
}

fn targets(path: &PathBuf, n: usize) -> std::io::Result<()> {
    let mut out = BufWriter::new(File::create(path)?);
    writeln!(out, "MODULE Bench")?;
    writeln!(
        out,
        "  PERS tooldata tSpindle := [TRUE,[[0,0,150],[1,0,0,0]],[2,[0,0,70],[1,0,0,0],0.01,0.01,0.004]];"
    )?;
    writeln!(out, "  PROC main()")?;
    // A grid 650–850 mm in front of the base, y 50–250 mm (first joint in
    // its first quadrant: cf1 = 0), z 300–500 mm, tool pointing down.
    for i in 0..n {
        let x = 650.0 + (i % 41) as f64 * 5.0;
        let y = 50.0 + ((i / 41) % 41) as f64 * 5.0;
        let z = 300.0 + ((i / 1681) % 41) as f64 * 5.0;
        writeln!(
            out,
            "    MoveL [[{x:.1},{y:.1},{z:.1}],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],v200,z1,tSpindle;"
        )?;
    }
    writeln!(out, "  ENDPROC\nENDMODULE")?;
    out.flush()
}

fn main() -> std::io::Result<()> {
    let dir = PathBuf::from(
        std::env::args()
            .nth(1)
            .unwrap_or_else(|| "bench-inputs".into()),
    );
    std::fs::create_dir_all(&dir)?;
    raster(&dir.join("raster.nc"), count("BENCH_BLOCKS", 1_000_000))?;
    targets(&dir.join("targets.mod"), count("BENCH_TARGETS", 100_000))?;
    Ok(())
}
