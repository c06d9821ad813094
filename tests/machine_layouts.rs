//! Machine files in any layout the loader reads are calibrated and written
//! back with every comment: the bundled starting files rewritten with block
//! lists (`- 1.0` on separate lines), block maps and comments between the
//! items go through `check`, `calibrate stiffness`, `kinematics`,
//! `geometry`, `thermal` and `diagnose --write-model`, and the written
//! model equals the one written from the bundled layout.

use std::path::Path;

use postproc::machine::Machine;

use crate::common::{postproc, repo, text, write};

/// Splits the inside of a flow collection at its top-level commas.
fn items(inner: &str) -> Vec<String> {
    let mut out = Vec::new();
    let (mut depth, mut cur) = (0i32, String::new());
    for c in inner.chars() {
        match c {
            '[' | '{' => depth += 1,
            ']' | '}' => depth -= 1,
            ',' if depth == 0 => {
                out.push(cur.trim().to_string());
                cur.clear();
                continue;
            }
            _ => {}
        }
        cur.push(c);
    }
    if !cur.trim().is_empty() {
        out.push(cur.trim().to_string());
    }
    out
}

/// `text` with every one-line flow list of numbers written as a block list
/// and every one-line flow map (a value or a list item) as a block map,
/// a comment line after the first item of each. Returns the text and the
/// number of collections rewritten.
fn block_layout(text: &str) -> (String, usize) {
    block_layout_but(text, &[])
}

/// [`block_layout`], without the comment line inside the lists of the keys
/// `whole` (tables a fit may write whole, with other positions: the
/// comments between their old numbers cannot stay).
fn block_layout_but(text: &str, whole: &[&str]) -> (String, usize) {
    let mut out = String::new();
    let mut n = 0;
    for line in text.lines() {
        let (body, comment) = match line.find(" #") {
            Some(i) => (&line[..i], &line[i..]),
            None => (line, ""),
        };
        if line.trim_start().starts_with('#') {
            out.push_str(line);
            out.push('\n');
            continue;
        }
        let indent = body.len() - body.trim_start().len();
        let t = body.trim();
        let pad = " ".repeat(indent);
        // `- { k: v, … }`: an item of a list as a block map.
        if let Some(inner) = t.strip_prefix("- {").and_then(|r| r.strip_suffix('}')) {
            let pairs = items(inner);
            out.push_str(&format!("{pad}- {}{comment}\n", pairs[0]));
            out.push_str(&format!("{pad}  # layout {n}: a block map item\n"));
            for p in &pairs[1..] {
                out.push_str(&format!("{pad}  {p}\n"));
            }
            n += 1;
            continue;
        }
        if let Some((key, value)) = t.split_once(": ") {
            let v = value.trim();
            let list = v.starts_with('[') && v.ends_with(']') && !v[1..].contains('[');
            let map = v.starts_with('{') && v.ends_with('}');
            if (list || map) && v.len() > 2 && !key.starts_with('-') {
                let inner = &v[1..v.len() - 1];
                out.push_str(&format!("{pad}{key}:{comment}\n"));
                for (i, item) in items(inner).iter().enumerate() {
                    if list {
                        out.push_str(&format!("{pad}  - {item}\n"));
                    } else {
                        out.push_str(&format!("{pad}  {item}\n"));
                    }
                    if i == 0 && !whole.contains(&key) {
                        out.push_str(&format!("{pad}  # layout {n}: between items\n"));
                    }
                }
                n += 1;
                continue;
            }
        }
        out.push_str(line);
        out.push('\n');
    }
    (out, n)
}

/// The model values of a machine file (a machine tool's caches left out).
fn model(text: &str) -> String {
    match Machine::from_yaml_str(text, "written").expect("written file loads") {
        Machine::Robot(r) => format!("{r:?}"),
        Machine::Tool(t) => format!(
            "{:?}{:?}{:?}{:?}",
            t.axes(),
            t.stiffness(),
            t.thermal(),
            t.spindle_errors()
        ),
    }
}

/// Every comment line of `before` is in `after`, except the example-values
/// comment that calibrate owns: that one becomes the calibrated section's
/// "… CALIBRATED date FROM file" line.
fn assert_comments_kept(before: &str, after: &str, what: &str) {
    for l in before.lines().filter(|l| l.trim_start().starts_with('#')) {
        if l.contains("EXAMPLE CALIBRATION, NOT MEASURED DATA") && !after.contains(l) {
            assert!(
                after.lines().any(|a| a.trim_start().starts_with('#')
                    && a.contains(" CALIBRATED ")
                    && a.contains(" FROM ")),
                "{what}: example comment `{l}` neither kept nor marked calibrated:\n{after}"
            );
            continue;
        }
        assert!(after.contains(l), "{what}: comment `{l}` lost:\n{after}");
    }
}

/// Runs `postproc calibrate KIND` on `machine` and returns the written text.
fn calibrate(kind: &str, machine: &Path, obs: &str, out: &Path) -> String {
    let a = postproc()
        .args(["calibrate", kind, "--machine"])
        .arg(machine)
        .arg("--observations")
        .arg(repo(obs))
        .arg("-o")
        .arg(out)
        .assert();
    let o = a.get_output();
    assert_eq!(
        o.status.code(),
        Some(0),
        "calibrate {kind}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    std::fs::read_to_string(out).expect("written")
}

/// One calibration in the bundled layout and in the block layout: both
/// succeed, the block file keeps every comment and its model equals the
/// bundled one's.
fn same_calibration(kind: &str, start: &str, obs: &str) {
    let dir = tempfile::tempdir().expect("tmp");
    let bundled = text(start);
    let whole: &[&str] = if kind == "geometry" {
        &["positions_mm", "forward", "reverse"]
    } else {
        &[]
    };
    let (block, n) = block_layout_but(&bundled, whole);
    assert!(n >= 2, "{kind}: {n} collections rewritten");
    assert_eq!(model(&block), model(&bundled), "{kind}: same model");
    let b = write(dir.path(), "block.yaml", &block);
    let want = calibrate(kind, &repo(start), obs, &dir.path().join("a.yaml"));
    let got = calibrate(kind, &b, obs, &dir.path().join("b.yaml"));
    assert_comments_kept(&block, &got, kind);
    assert_ne!(model(&got), model(&block), "{kind}: values written");
    assert_eq!(model(&got), model(&want), "{kind}: same values written");
}

/// The case: a robot whose `k_nm_per_rad` is a block list passes
/// `check`, then `calibrate stiffness` fits and writes it back.
#[test]
fn block_list_stiffness_checks_and_calibrates() {
    let (block, _) = block_layout(&text("machines/abb-irb1600.yaml"));
    assert!(block.contains("k_nm_per_rad:\n  - 270990.0\n  # layout"));
    let dir = tempfile::tempdir().expect("tmp");
    let b = write(dir.path(), "block.yaml", &block);
    postproc()
        .arg("check")
        .arg(repo("samples/milling.mod"))
        .arg("--machine")
        .arg(&b)
        .assert()
        .success();
    same_calibration(
        "stiffness",
        "machines/abb-irb1600.yaml",
        "samples/observations/irb1600-ldbb-measured.csv",
    );
}

#[test]
fn block_layout_kinematics() {
    same_calibration(
        "kinematics",
        "machines/abb-irb1600.yaml",
        "samples/observations/irb1600-kinematic-measured.csv",
    );
}

#[test]
fn block_layout_geometry() {
    same_calibration(
        "geometry",
        "machines/afm-r1000.yaml",
        "samples/observations/afm-r1000-grid-measured.csv",
    );
}

#[test]
fn block_layout_thermal() {
    same_calibration(
        "thermal",
        "samples/observations/irb1600-thermal-start.yaml",
        "samples/observations/irb1600-thermal-measured.csv",
    );
}

/// `diagnose --write-model` on the diagnose sample's model in the block
/// layout: the effect is written, comments kept, the same model as from
/// the sample's own layout.
#[test]
fn block_layout_diagnose_write_model() {
    let dir = tempfile::tempdir().expect("tmp");
    let start = text("samples/diagnose/model.yaml");
    let (block, n) = block_layout(&start);
    assert!(n >= 2, "{n}");
    let run = |m: &Path, out: &Path| {
        let a = postproc()
            .args(["diagnose", "--bootstrap", "5", "--machine"])
            .arg(m)
            .arg("--observations")
            .arg(repo("samples/diagnose/measured.csv"))
            .arg("--write-model")
            .arg(out)
            .assert();
        let o = a.get_output();
        assert_eq!(
            o.status.code(),
            Some(0),
            "{}",
            String::from_utf8_lossy(&o.stderr)
        );
        assert!(
            String::from_utf8_lossy(&o.stdout).contains("values edited in place, comments kept")
        );
        std::fs::read_to_string(out).expect("written")
    };
    let b = write(dir.path(), "block.yaml", &block);
    let want = run(
        &repo("samples/diagnose/model.yaml"),
        &dir.path().join("a.yaml"),
    );
    let got = run(&b, &dir.path().join("b.yaml"));
    assert_comments_kept(&block, &got, "diagnose");
    assert_ne!(model(&got), model(&block), "values written");
    assert_eq!(model(&got), model(&want), "same values written");
}

/// The robot in block layout, calibrated for stiffness through the binary,
/// is written back in its own layout: `k_nm_per_rad` stays a block list
/// (one number a line, the comment after its first item kept there), the
/// TCP a block map, and the keys the calibration adds (`calibrations`) are
/// block lines as in the bundled files.
#[test]
fn block_lists_stay_block_lists_when_written_back() {
    let (block, _) = block_layout(&text("machines/abb-irb1600.yaml"));
    let dir = tempfile::tempdir().expect("tmp");
    let b = write(dir.path(), "block.yaml", &block);
    let got = calibrate(
        "stiffness",
        &b,
        "samples/observations/irb1600-ldbb-measured.csv",
        &dir.path().join("out.yaml"),
    );
    assert_comments_kept(&block, &got, "stiffness");
    let k_at = got.find("\nk_nm_per_rad:\n").expect("k_nm_per_rad key") + 1;
    let k: Vec<&str> = got[k_at..].lines().skip(1).take(7).collect();
    assert!(k[0].starts_with("  - "), "{k:?}");
    assert!(k[1].starts_with("  # layout "), "{k:?}");
    assert!(k[2..].iter().all(|l| l.starts_with("  - ")), "{k:?}");
    let written: Vec<f64> = k
        .iter()
        .filter_map(|l| l.strip_prefix("  - "))
        .map(|v| v.trim().parse().expect("a number a line"))
        .collect();
    let Machine::Robot(r) = Machine::from_yaml_str(&got, "out.yaml").expect("loads") else {
        panic!("a robot")
    };
    let read: Vec<f64> = (0..6)
        .map(|joint| {
            r.param_value(postproc::machine::robot::RobotParam::JointStiffness { joint })
                .expect("joint stiffness")
        })
        .collect();
    assert_eq!(written, read);
    assert!(got.contains("\nflange_to_tool:\n  x_mm: "), "{got}");
    assert!(got.contains("\ncalibrations:\n  - { date: "), "{got}");
}

/// The same robot in flow style (one JSON line, which the loader reads as
/// YAML): the calibration writes it back in flow style, with the same
/// model as from the bundled layout.
#[test]
fn flow_style_file_calibrates_in_flow_style() {
    let bundled = text("machines/abb-irb1600.yaml");
    let v: serde_yaml::Value = serde_yaml::from_str(&bundled).expect("yaml");
    let flow = format!("{}\n", serde_json::to_string(&v).expect("json"));
    let dir = tempfile::tempdir().expect("tmp");
    let f = write(dir.path(), "flow.yaml", &flow);
    let obs = "samples/observations/irb1600-ldbb-measured.csv";
    let got = calibrate("stiffness", &f, obs, &dir.path().join("b.yaml"));
    let want = calibrate(
        "stiffness",
        &repo("machines/abb-irb1600.yaml"),
        obs,
        &dir.path().join("a.yaml"),
    );
    assert_eq!(got.lines().count(), 1, "{got}");
    assert!(
        got.contains("\"calibrations\"") || got.contains("calibrations: ["),
        "{got}"
    );
    assert_eq!(model(&got), model(&want));
}
