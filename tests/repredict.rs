//! A compensated program, read and predicted again with the same machine
//! model (`report` of the output), attains every programmed target of the
//! input within the tolerance: the directions of motion, the feed
//! directions and the process loads of its written pieces are those the
//! compensation was solved with. Checked through the interpreter and the
//! predictor, not through the compensation's own residual.

use crate::common::{postproc, repo};

/// Tolerance of the compensation in these runs, mm.
const TOLERANCE_MM: f64 = 0.003;

/// One row of a `report --format csv`: line, motion, the programmed point
/// and the attained point (programmed + predicted deviation), residual.
struct Row {
    line: String,
    motion: String,
    programmed: [f64; 3],
    attained: [f64; 3],
    residual_mm: f64,
}

fn report(path: &std::path::Path) -> Vec<Row> {
    let out = postproc()
        .args(["report", "--machine", "afm-r1000", "--format", "csv"])
        .arg(path)
        .output()
        .expect("runs");
    assert!(
        out.status.success() || out.status.code() == Some(1),
        "{out:?}"
    );
    let text = String::from_utf8(out.stdout).expect("utf-8");
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let head: Vec<&str> = lines.next().expect("header").split(',').collect();
    let col = |name: &str| head.iter().position(|h| *h == name).expect(name);
    let num = |cells: &[&str], name: &str| -> f64 { cells[col(name)].parse().expect(name) };
    lines
        .map(|l| {
            let c: Vec<&str> = l.split(',').collect();
            let p = [num(&c, "X_mm"), num(&c, "Y_mm"), num(&c, "Z_mm")];
            let d = [num(&c, "dx_mm"), num(&c, "dy_mm"), num(&c, "dz_mm")];
            Row {
                line: c[col("line")].to_string(),
                motion: c[col("motion")].to_string(),
                programmed: p,
                attained: [p[0] + d[0], p[1] + d[1], p[2] + d[2]],
                residual_mm: num(&c, "residual_mm"),
            }
        })
        .collect()
}

fn dist(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>().sqrt()
}

fn attains_every_target(name: &str) {
    let input = repo(&format!("tests/repredict/{name}"));
    let dir = tempfile::tempdir().expect("tempdir");
    let output = dir.path().join(name);
    postproc()
        .args(["compensate", "--machine", "afm-r1000", "--tolerance"])
        .arg(TOLERANCE_MM.to_string())
        .arg(&input)
        .arg("-o")
        .arg(&output)
        .assert()
        .success();
    let landed = report(&output);
    let targets = report(&input);
    let mut checked = 0;
    for t in targets
        .iter()
        .filter(|t| t.motion != "rapid" && t.motion != "fixed")
    {
        let off = landed
            .iter()
            .map(|l| dist(&l.attained, &t.programmed))
            .fold(f64::INFINITY, f64::min);
        assert!(
            off <= TOLERANCE_MM + t.residual_mm,
            "{name}:{} ({}): attained {off:.6} mm from its target, tolerance {TOLERANCE_MM} mm, residual {} mm",
            t.line,
            t.motion,
            t.residual_mm
        );
        checked += 1;
    }
    assert!(checked > 5, "{name}: {checked} targets");
}

#[test]
fn a_compensated_hand_written_frame_attains_its_targets() {
    attains_every_target("hand_frame.nc");
}
