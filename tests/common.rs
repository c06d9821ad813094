//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::path::PathBuf;

/// Path of a file in the repository.
pub fn repo(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(rel)
}

/// The `postproc` binary under test.
/// The text of a file of the repository.
pub fn text(rel: &str) -> String {
    std::fs::read_to_string(repo(rel)).expect("file in the repository")
}

/// The fenced blocks of the Markdown `md` whose info string is exactly
/// `lang`, each with its lines and their line ends.
pub fn fenced_blocks(md: &str, lang: &str) -> Vec<String> {
    let open = format!("```{lang}");
    let (mut out, mut cur): (Vec<String>, Option<String>) = (Vec::new(), None);
    for line in md.lines() {
        match &mut cur {
            None if line.trim_end() == open => cur = Some(String::new()),
            None => {}
            Some(b) if line.trim_end() == "```" => {
                out.push(std::mem::take(b));
                cur = None;
            }
            Some(b) => {
                b.push_str(line);
                b.push('\n');
            }
        }
    }
    out
}

/// Writes `body` to `dir/name` and gives the path.
pub fn write(dir: &std::path::Path, name: &str, body: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, body).expect("write");
    p
}

/// The `postproc` binary.
pub fn postproc() -> assert_cmd::Command {
    assert_cmd::Command::cargo_bin("postproc").expect("binary built")
}

/// Largest difference between numbers of two simulated CSV files that still
/// counts as the same data (floating-point noise of a refactored model).
pub const CSV_NOISE_TOL: f64 = 1e-9;

/// Asserts two CSV texts have the same header and text cells and numbers
/// equal within [`CSV_NOISE_TOL`].
pub fn assert_csv_close(got: &str, want: &str, what: &str) {
    let (a, b): (Vec<&str>, Vec<&str>) = (got.lines().collect(), want.lines().collect());
    assert_eq!(a.len(), b.len(), "{what}: line count");
    for (n, (la, lb)) in a.iter().zip(&b).enumerate() {
        let (ca, cb): (Vec<&str>, Vec<&str>) = (la.split(',').collect(), lb.split(',').collect());
        assert_eq!(ca.len(), cb.len(), "{what}: cells of line {}", n + 1);
        for (x, y) in ca.iter().zip(&cb) {
            match (x.parse::<f64>(), y.parse::<f64>()) {
                (Ok(x), Ok(y)) => assert!(
                    (x - y).abs() <= CSV_NOISE_TOL,
                    "{what}: line {}: {x} vs {y}",
                    n + 1
                ),
                _ => assert_eq!(x, y, "{what}: line {}", n + 1),
            }
        }
    }
}

/// Words that open the lines of a postproc provenance header after its
/// first line (docs/provenance.md).
const HEADER_KEYS: [&str; 7] = [
    "machine ",
    "sha256 ",
    "observations ",
    "effects ",
    "tolerance ",
    "note: ",
    "postproc ",
];

/// The program without its postproc provenance header: the marker line
/// (`postproc VERSION compensated program - …`) and the header lines after
/// it are removed, every other byte is kept. Panics when the program has no
/// header: every compensated program carries one.
pub fn without_header(program: &[u8]) -> Vec<u8> {
    let lines: Vec<&[u8]> = program.split_inclusive(|&b| b == b'\n').collect();
    let body = |l: &[u8]| -> Option<String> {
        let t = String::from_utf8_lossy(l).trim().to_string();
        let inner = if let Some(r) = t.strip_prefix('(') {
            r.strip_suffix(')')?.to_string()
        } else if let Some(r) = t.strip_prefix(';').or_else(|| t.strip_prefix('!')) {
            r.trim_start().to_string()
        } else {
            return None;
        };
        Some(inner)
    };
    let start = lines
        .iter()
        .position(|l| {
            body(l).is_some_and(|b| {
                b.starts_with("postproc ")
                    && b.ends_with("compensated program - do not compensate it again")
            })
        })
        .expect("a postproc header in the compensated program");
    let mut end = start + 1;
    while end < lines.len()
        && body(lines[end]).is_some_and(|b| HEADER_KEYS.iter().any(|k| b.starts_with(k)))
    {
        end += 1;
    }
    let mut out = Vec::with_capacity(program.len());
    for l in lines[..start].iter().chain(&lines[end..]) {
        out.extend_from_slice(l);
    }
    out
}

/// [`without_header`] of a text.
pub fn text_without_header(program: &str) -> String {
    String::from_utf8(without_header(program.as_bytes())).expect("utf-8")
}

/// Pose of a robtarget literal: position, quaternion with the scalar first.
pub fn robtarget_pose(rt: &postproc::program::rapid::RobTarget) -> nalgebra::Isometry3<f64> {
    let q = rt.rot.each_ref().map(|n| n.value);
    nalgebra::Isometry3::from_parts(
        nalgebra::Translation3::new(rt.trans[0].value, rt.trans[1].value, rt.trans[2].value),
        nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
            q[0], q[1], q[2], q[3],
        )),
    )
}

/// The confdata of a robtarget literal.
pub fn robtarget_conf(
    rt: &postproc::program::rapid::RobTarget,
) -> postproc::machine::robot::ConfData {
    let v = rt.robconf.each_ref().map(|n| n.value as i32);
    postproc::machine::robot::ConfData {
        cf1: v[0],
        cf4: v[1],
        cf6: v[2],
        cfx: v[3],
    }
}

/// The bundled TX200 file at the world origin: its `base` (where it stands
/// in the bundled samples' cell) replaced by the identity, for tests of the
/// arm in its own base frame and of the refusals the samples' plate gets
/// from there.
pub fn tx200_at_the_origin_text() -> String {
    let text = text("machines/staubli-tx200.yaml");
    let mut found = 0;
    let out: Vec<String> = text
        .lines()
        .map(|l| {
            if l.starts_with("base:") {
                found += 1;
                "base: { x_mm: 0.0, y_mm: 0.0, z_mm: 0.0, quaternion: [1.0, 0.0, 0.0, 0.0] }"
                    .to_string()
            } else {
                l.to_string()
            }
        })
        .collect();
    assert_eq!(found, 1, "one `base:` line in the bundled TX200 file");
    out.join("\n") + "\n"
}

/// Runs `postproc args…` in `dir`: exit code, stdout, stderr.
pub fn run_in(dir: &std::path::Path, args: &[&str]) -> (i32, String, String) {
    let out = postproc()
        .current_dir(dir)
        .args(args)
        .output()
        .expect("runs");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}
