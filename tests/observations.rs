//! Integration tests: observations — every error of the contract with its
//! exact `file:line:column` text, canonical writing, round trips, robustness
//! against arbitrary bytes, the reproducible holdout split and seeded noise.

use approx::assert_abs_diff_eq;
use postproc::calibrate::observations::{
    MAX_MAGNITUDE, MeasuredKind, ObsKind, Observations, Pose, add_measurement_noise, holdout_split,
    parse_observations, read_observations, write_observations,
};
use proptest::prelude::*;

/// Tolerance of values read from text with ≤ 6 decimals.
const READ_TOL: f64 = 1e-12;

/// Robot header used by most cases. Byte columns: `qN_deg,` is 7 bytes, so
/// q1..q6 start at 1, 8, 15, 22, 29, 36; x_mm at 43, y_mm at 48, z_mm at 53,
/// and a tenth column would start at 58.
const H: &str = "q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,x_mm,y_mm,z_mm";

fn err(text: &str) -> String {
    match parse_observations(text, "t.csv") {
        Ok(_) => "accepted".to_string(),
        Err(e) => e.to_string(),
    }
}

#[test]
fn unknown_column_with_suggestion_after_comment() {
    let text = "# exported by tracker\nq1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,x_mn,y_mm,z_mm\n";
    assert_eq!(
        err(text),
        "t.csv:2:43: unknown column \"x_mn\" (did you mean \"x_mm\"?)"
    );
    assert_eq!(
        err(&format!("{H},banana\n")),
        "t.csv:1:58: unknown column \"banana\""
    );
}

#[test]
fn duplicate_column() {
    assert_eq!(
        err(&format!("{H},y_mm\n")),
        "t.csv:1:58: duplicate column \"y_mm\" (first at column 48)"
    );
}

#[test]
fn missing_required_columns() {
    assert_eq!(
        err("q1_deg,q2_deg,q3_deg,q5_deg,q6_deg,x_mm,y_mm,z_mm\n"),
        "t.csv:1:1: missing required column \"q4_deg\""
    );
    assert_eq!(
        err("X_mm,Y_mm,dx_mm,dy_mm,dz_mm\n"),
        "t.csv:1:1: missing required column \"Z_mm\""
    );
}

#[test]
fn kind_both_or_neither() {
    assert_eq!(
        err(&format!("{H},X_mm\n")),
        "t.csv:1:58: column \"X_mm\" belongs to machine-tool files, but column \"q1_deg\" makes this a robot file"
    );
    assert_eq!(
        err("x_mm,y_mm,z_mm\n"),
        "t.csv:1:1: cannot tell the machine kind: no robot joint columns (q1_deg … q6_deg) \
         nor machine-tool axis columns (X_mm, Y_mm, Z_mm)"
    );
}

#[test]
fn position_triples_both_neither_partial() {
    assert_eq!(
        err(&format!("{H},dx_mm,dy_mm,dz_mm\n")),
        "t.csv:1:58: both the measured position (x_mm, y_mm, z_mm) and the deviation \
         (dx_mm, dy_mm, dz_mm) are given; a file holds exactly one of them"
    );
    assert_eq!(
        err("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n"),
        "t.csv:1:1: missing the measured position (x_mm, y_mm, z_mm) or deviation \
         (dx_mm, dy_mm, dz_mm) columns"
    );
    assert_eq!(
        err("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,x_mm,z_mm\n"),
        "t.csv:1:43: column \"x_mm\" needs \"y_mm\" too (a point needs all three coordinates)"
    );
    // mp columns: mp_x_mm at 58, mp_z_mm at 66.
    assert_eq!(
        err(&format!("{H},mp_x_mm,mp_z_mm\n")),
        "t.csv:1:58: column \"mp_x_mm\" needs \"mp_y_mm\" too (a point needs all three coordinates)"
    );
}

#[test]
fn bad_cells() {
    // Row "1,2,3,4,5,6,…": each one-digit cell plus comma is 2 bytes, so cell k
    // (1-based) starts at column 2k − 1: x_mm (7th) at 13, y_mm (8th) at 15.
    assert_eq!(
        err(&format!("{H}\n1,2,3,4,5,6,abc,0,0\n")),
        "t.csv:2:13: column \"x_mm\": non-numeric cell \"abc\""
    );
    assert_eq!(
        err(&format!("{H}\n1,2,3,4,5,6,7,NaN,0\n")),
        "t.csv:2:15: column \"y_mm\": cell \"NaN\" is not a finite number"
    );
    assert_eq!(
        err(&format!("{H}\n1,2,3,4,5,6,7,8,-inf\n")),
        "t.csv:2:17: column \"z_mm\": cell \"-inf\" is not a finite number"
    );
    // 1e999 overflows to infinity.
    assert_eq!(
        err(&format!("{H}\n1,2,3,4,5,6,7,8,1e999\n")),
        "t.csv:2:17: column \"z_mm\": cell \"1e999\" is not a finite number"
    );
    // Quoted cell: column of the opening quote.
    assert_eq!(
        err(&format!("{H}\n1,2,3,4,5,6,\"1,5\",0,0\n")),
        "t.csv:2:13: column \"x_mm\": non-numeric cell \"1,5\""
    );
    // Empty required cell: q4 (4th) at column 7.
    assert_eq!(
        err(&format!("{H}\n1,2,3,,5,6,7,8,9\n")),
        "t.csv:2:7: column \"q4_deg\": value required (empty cell)"
    );
}

#[test]
fn wrong_width_rows() {
    // 10 cells: the extra one ("10") starts after nine 2-byte cells, column 19.
    assert_eq!(
        err(&format!("{H}\n1,2,3,4,5,6,7,8,9,10\n")),
        "t.csv:2:19: row has 10 cells but the header (line 1) has 9 columns"
    );
    // 8 cells, line length 15: reported one past the end, column 16. Line 4
    // because of a comment and a blank line before it.
    assert_eq!(
        err(&format!("{H}\n# pause\n\n1,2,3,4,5,6,7,8\n")),
        "t.csv:4:16: row has 8 cells but the header (line 1) has 9 columns"
    );
}

#[test]
fn dir_values_must_be_plus_or_minus_one() {
    assert_eq!(
        err(&format!("{H},dir2\n1,2,3,4,5,6,7,8,9,2\n")),
        "t.csv:2:19: column \"dir2\": cell \"2\" must be 1 or -1"
    );
    assert_eq!(
        err(&format!("{H},dir2\n1,2,3,4,5,6,7,8,9,0\n")),
        "t.csv:2:19: column \"dir2\": cell \"0\" must be 1 or -1"
    );
    let ok = parse_observations(&format!("{H},dir2\n1,2,3,4,5,6,7,8,9,-1.0\n"), "t.csv");
    assert!(ok.is_ok());
}

#[test]
fn partial_point_in_a_row() {
    // mp_x at 19, comma at 20, empty mp_y at 21.
    assert_eq!(
        err(&format!(
            "{H},mp_x_mm,mp_y_mm,mp_z_mm\n1,2,3,4,5,6,7,8,9,1,,3\n"
        )),
        "t.csv:2:21: column \"mp_y_mm\": empty but \"mp_x_mm\" is given (a point needs all three coordinates)"
    );
}

#[test]
fn malformed_text() {
    assert_eq!(
        err(&format!("{H}\n\"abc,2,3\n")),
        "t.csv:2:1: unterminated quoted cell (a quoted cell cannot span lines)"
    );
    assert_eq!(
        err(&format!("{H}\n1,2\"x,3\n")),
        "t.csv:2:4: quote inside an unquoted cell (quote the whole cell)"
    );
    assert_eq!(
        err("# nothing here\n"),
        "t.csv:1:1: no header row (the file has no data)"
    );
    assert_eq!(err(""), "t.csv:1:1: no header row (the file has no data)");
    assert_eq!(err("q1_deg,,x_mm\n"), "t.csv:1:8: empty column name");
}

#[test]
fn reads_a_robot_file_with_bom_crlf_comments_and_defaults() {
    let text = "\u{feff}# campaign 3\r\n\
                q6_deg,q5_deg,q4_deg,q3_deg,q2_deg,q1_deg, id ,dx_mm,dy_mm,dz_mm,fz_n,wp_x_mm,wp_y_mm,wp_z_mm\r\n\
                0,0,0,0,-30,10.5,\"pose, A\",0.125,-0.25,1e-3,-310,,,\r\n\
                \r\n\
                # second pose\r\n\
                6,5,4,3,2,1,,0,0,0,,1,2,3\r\n";
    let obs = parse_observations(text, "r.csv").expect("valid");
    assert_eq!(obs.kind, ObsKind::Robot);
    assert_eq!(obs.measured, MeasuredKind::Deviation);
    assert_eq!(obs.rows.len(), 2);
    let r = &obs.rows[0];
    assert_eq!(r.line, 3);
    assert_eq!(r.id, "pose, A");
    assert_abs_diff_eq!(r.measured_mm.z, 0.001, epsilon = READ_TOL);
    assert_abs_diff_eq!(r.force_n.z, -310.0, epsilon = READ_TOL);
    assert_abs_diff_eq!(r.force_n.x, 0.0, epsilon = READ_TOL);
    let Pose::Robot(p) = &r.pose else {
        panic!("robot pose expected")
    };
    assert_eq!(p.q_deg, [10.5, -30.0, 0.0, 0.0, 0.0, 0.0]);
    assert_eq!(p.wp_mm, None);
    let r = &obs.rows[1];
    assert_eq!((r.line, r.id.as_str()), (6, "2"));
    let Pose::Robot(p) = &r.pose else {
        panic!("robot pose expected")
    };
    assert_eq!(p.q_deg, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
    assert_eq!(p.wp_mm.map(|v| [v.x, v.y, v.z]), Some([1.0, 2.0, 3.0]));
}

#[test]
fn writes_canonical_text_and_round_trips() {
    let text = "# tool file\n\
                dirX,Z_mm,x_mm,y_mm,z_mm,X_mm,Y_mm,C_deg,spindle_rpm,t_s\n\
                -1,-50,100.5,20,-50.0000004,100.5,20,,12000,0\n\
                1,-0,0,0,0,0,0,90,,3.25\n";
    let obs = parse_observations(text, "m.csv").expect("valid");
    assert_eq!(obs.kind, ObsKind::MachineTool);
    let mut out = Vec::new();
    write_observations(&mut out, &obs).expect("writes");
    let written = String::from_utf8(out).expect("utf-8");
    // Canonical order: t_s, x y z, X Y Z, C, dirX, spindle_rpm. −0 is written 0;
    // -50.0000004 has 7 decimals and keeps its shortest exact form.
    let want = "t_s,x_mm,y_mm,z_mm,X_mm,Y_mm,Z_mm,C_deg,dirX,spindle_rpm\n\
                0.000000,100.500000,20.000000,-50.0000004,100.500000,20.000000,-50.000000,,-1,12000.000000\n\
                3.250000,0.000000,0.000000,0.000000,0.000000,0.000000,0.000000,90.000000,1,\n";
    assert_eq!(written, want);
    let again = read_observations(written.as_bytes(), "w.csv").expect("re-reads");
    assert_eq!(again, obs);
}

#[test]
fn writer_adds_columns_the_caller_filled_in() {
    let mut obs = parse_observations(&format!("{H}\n1,2,3,4,5,6,7,8,9\n"), "t.csv").expect("valid");
    obs.rows[0].ambient_c = Some(21.5);
    obs.rows[0].id = "P1".into();
    let mut out = Vec::new();
    write_observations(&mut out, &obs).expect("writes");
    let written = String::from_utf8(out).expect("utf-8");
    assert!(written.starts_with("id,x_mm,y_mm,z_mm,ambient_c,q1_deg,"));
    let again = read_observations(written.as_bytes(), "w.csv").expect("re-reads");
    assert_eq!(again.rows, obs.rows);
}

#[test]
fn holdout_split_is_reproducible() {
    // Expected values from an independent Python implementation of SplitMix64
    // with rejection sampling and the same Fisher–Yates loop.
    assert_eq!(
        holdout_split(10, 0.3, 1),
        (vec![0, 1, 2, 3, 4, 8, 9], vec![5, 6, 7])
    );
    // round(3.5) = 4 holdout rows.
    assert_eq!(holdout_split(7, 0.5, 42), (vec![2, 4, 6], vec![0, 1, 3, 5]));
    assert_eq!(holdout_split(5, 0.0, 3), (vec![0, 1, 2, 3, 4], vec![]));
    assert_eq!(holdout_split(3, f64::NAN, 3).1.len(), 0);
    assert_eq!(holdout_split(0, 0.5, 3), (vec![], vec![]));
}

#[test]
fn measurement_noise_is_seeded() {
    let mut text = format!("{H}\n");
    for _ in 0..2000 {
        text.push_str("0,0,0,0,0,0,0,0,0\n");
    }
    let base = parse_observations(&text, "t.csv").expect("valid");
    let mut a = base.clone();
    let mut b = base.clone();
    add_measurement_noise(&mut a, 0.01, 5);
    add_measurement_noise(&mut b, 0.01, 5);
    assert_eq!(a, b);
    // 6000 draws of sd 0.01: sample sd within 5 % (≈ 5.5 standard errors of √(1/2n)).
    let ss: f64 = a.rows.iter().map(|r| r.measured_mm.norm_squared()).sum();
    assert_abs_diff_eq!((ss / 6000.0).sqrt(), 0.01, epsilon = 0.0005);
}

const VALID: &str = "# sample\nid,t_s,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,x_mm,y_mm,z_mm,fx_n,mp_x_mm,mp_y_mm,mp_z_mm,dir1\n\
                     a,0,1,2,3,4,5,6,1000.5,-20.25,300,12.5,,,,1\n\
                     \"b,c\",1.5,10,20,30,40,50,60,1,2,3,,0,0,100,-1\n";

fn sample() -> Observations {
    parse_observations(VALID, "v.csv").expect("valid sample")
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..300)) {
        let _ = read_observations(bytes.as_slice(), "f");
    }

    #[test]
    fn mutated_valid_files_never_panic_and_round_trip(
        edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>(), 0u8..3), 1..6)
    ) {
        let mut bytes = VALID.as_bytes().to_vec();
        for (pos, byte, op) in edits {
            let i = pos.index(bytes.len() + 1);
            match op {
                0 => bytes.insert(i, byte),
                1 if i < bytes.len() => bytes[i] = byte,
                _ if i < bytes.len() => { bytes.remove(i); }
                _ => {}
            }
        }
        if let Ok(obs) = read_observations(bytes.as_slice(), "f") {
            let mut out = Vec::new();
            prop_assert!(write_observations(&mut out, &obs).is_ok());
            let again = read_observations(out.as_slice(), "w");
            prop_assert_eq!(again.ok(), Some(obs));
        }
    }

    #[test]
    fn any_accepted_values_round_trip(
        // Every finite value within the reader's magnitude limit (larger
        // ones are refused as absurd, see tests/bad/observations).
        vals in proptest::collection::vec(
            prop_oneof![
                (-MAX_MAGNITUDE..=MAX_MAGNITUDE),
                (-1e-300f64..1e-300),
                (-10_000_000i64..10_000_000).prop_map(|k| k as f64 / 1e6)
            ],
            12,
        )
    ) {
        let mut obs = sample();
        obs.rows[0].measured_mm = nalgebra::Vector3::new(vals[0], vals[1], vals[2]);
        obs.rows[1].force_n = nalgebra::Vector3::new(vals[3], vals[4], vals[5]);
        obs.rows[1].t_s = Some(vals[6]);
        if let Pose::Robot(p) = &mut obs.rows[0].pose {
            p.q_deg = [vals[7], vals[8], vals[9], vals[10], vals[11], 0.0];
        }
        let mut out = Vec::new();
        prop_assert!(write_observations(&mut out, &obs).is_ok());
        let text = String::from_utf8(out).unwrap_or_default();
        // Data lines hold no exponent (ids "a" and "b,c" have no 'e').
        prop_assert!(text.lines().skip(1).all(|l| !l.contains('e')));
        let again = read_observations(text.as_bytes(), "w");
        // The filled-in force adds columns: compare against the effective set.
        let mut want = obs.clone();
        want.columns = obs.effective_columns();
        prop_assert_eq!(again.ok(), Some(want));
    }
}
