//! Integration test: the Paper B thermal form through the binary: the
//! IRB 1600's a2 stays between 149.95 and 150.15 mm over the Paper B power
//! range (docs/physics.md, "Figures from the sources").

use approx::assert_abs_diff_eq;

use crate::common::{postproc, repo};

/// The Paper B powers (W) at TCP speeds 300/750/1200/1350 mm/s (thesis,
/// Paper B; summarised in docs/physics.md, "Figures from the sources").
const P_J1: [f64; 4] = [22.0, 60.0, 115.0, 126.0];
const P_J2: [f64; 4] = [18.0, 52.0, 94.0, 112.0];
const P_J3: [f64; 4] = [9.0, 20.0, 35.0, 38.0];

/// a2 of the bundled file at a power level, by hand from its terms:
/// a2 = 149.95 + 0.10·(1 − e^(−0.015·P1)) + 0.12·(1 − e^(−0.020·P2)) mm
/// (each term adds ub − lb·e^(−ts·P) with lb = ub).
fn a2_by_hand(p1: f64, p2: f64) -> f64 {
    149.95 + 0.10 * (1.0 - (-0.015 * p1).exp()) + 0.12 * (1.0 - (-0.020 * p2).exp())
}

#[test]
fn paper_b_a2_range_through_simulate() {
    // Keep only the a2 terms so the flange moves by the a2 growth alone: at
    // all joints zero the IRB 1600 flange sits at x = a2 + d4 + d6 (mDH), so
    // x(P) − x(0) = a2(P) − a2(0) and a2(0) is the file's actual 149.95.
    let text = std::fs::read_to_string(repo("machines/abb-irb1600.yaml")).unwrap();
    assert!(
        text.contains("{ a_mm: 149.95,"),
        "the actual a2 the test assumes"
    );
    let only_a2: String = text
        .lines()
        .filter(|l| !(l.contains("parameter: d4") || l.contains("parameter: a3")))
        .map(|l| format!("{l}\n"))
        .collect();
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("m.yaml"), only_a2).unwrap();
    let mut poses = String::from(
        "id,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,mp_x_mm,mp_y_mm,mp_z_mm,p1_w,p2_w,p3_w\n",
    );
    poses.push_str("cold,0,0,0,0,0,0,0,0,0,0,0,0\n");
    for k in 0..4 {
        poses.push_str(&format!(
            "v{k},0,0,0,0,0,0,0,0,0,{},{},{}\n",
            P_J1[k], P_J2[k], P_J3[k]
        ));
    }
    std::fs::write(dir.path().join("poses.csv"), poses).unwrap();
    let out = postproc()
        .args(["simulate", "--machine"])
        .arg(dir.path().join("m.yaml"))
        .arg("--observations")
        .arg(dir.path().join("poses.csv"))
        .args(["-o", "-"])
        .output()
        .unwrap();
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let csv = String::from_utf8(out.stdout).unwrap();
    let mut lines = csv.lines().filter(|l| !l.starts_with('#'));
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let x_col = header.iter().position(|h| *h == "x_mm").expect("x_mm");
    let xs: Vec<f64> = lines
        .map(|l| l.split(',').nth(x_col).unwrap().parse().unwrap())
        .collect();
    assert_eq!(xs.len(), 5);
    // The example calibration's angle errors (≈ 1 mrad) tilt a 0.2 mm growth
    // by ≈ 0.2 µm; the gravity sag changes by less.
    const A2_TOL_MM: f64 = 1e-3;
    for k in 0..4 {
        let a2 = 149.95 + (xs[k + 1] - xs[0]);
        assert_abs_diff_eq!(a2, a2_by_hand(P_J1[k], P_J2[k]), epsilon = A2_TOL_MM);
        assert!((149.95..=150.15).contains(&a2), "a2 {a2} at level {k}");
    }
    // The hand values at the ends of the range: 150.0144 and 150.1422 mm.
    assert_abs_diff_eq!(a2_by_hand(22.0, 18.0), 150.0144, epsilon = 1e-4);
    assert_abs_diff_eq!(a2_by_hand(126.0, 112.0), 150.1422, epsilon = 1e-4);
}
