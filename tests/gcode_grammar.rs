//! Integration tests: every example of grammar/gcode.md parses as documented,
//! property tests of the G-code syntax and interpreter (no input panics; word
//! spans slice back to their text), and regression tests of the interpreter.

use postproc::error::Located;
use postproc::program::gcode::{Block, LETTERS, parse_line};
use postproc::program::interp::{Interpreter, Motion, Setup, Units};
use proptest::prelude::*;

use crate::common::repo;

/// The setup the grammar document promises its examples run with:
/// H1…H20 = 100 mm, no work offsets (G54…G59, G54.1 P1, G154 P1 and P2
/// at machine zero), the G30 point at X0 Y0 Z100, X Y Z only, a control
/// that reads programs without G20/G21 in mm.
fn doc_setup() -> Setup {
    let mut setup = Setup {
        axes: [true, true, true, false, false, false],
        units_default: Some(Units::Mm),
        ..Setup::default()
    };
    for h in 1..=20 {
        setup.tools.insert(h, 100.0);
    }
    for key in ["G54.1P1", "G154P1", "G154P2"] {
        setup.extra_offsets.insert(key.into(), [0.0; 3]);
    }
    setup
        .reference_points
        .insert("G30".into(), [0.0, 0.0, 100.0]);
    setup
}

/// Parses and interprets every line of `program` with a fresh interpreter;
/// the first error is returned.
fn run_program(
    program: &str,
    setup: Setup,
) -> Result<Vec<postproc::program::interp::Plan>, Located> {
    let mut interp = Interpreter::new(setup, "doc.nc");
    let mut block = Block::default();
    let mut plans = Vec::new();
    // Subprograms followed as the control runs them.
    let text = program.as_bytes();
    // Lathe programs are named by their content first, as `check` does.
    if let Some(e) = postproc::program::gcode::dialect::lathe_program(text, "doc.nc") {
        return Err(e);
    }
    let lines: Vec<(usize, Vec<u8>)> =
        match postproc::program::gcode::subprograms::expand(text, "doc.nc")? {
            Some(exp) => (0..exp.trace.len())
                .map(|k| (exp.trace[k].0, exp.input(text, k).into_owned()))
                .collect(),
            None => program
                .split_inclusive('\n')
                .map(|l| l.as_bytes().to_vec())
                .enumerate()
                .collect(),
        };
    for (i, line) in lines {
        parse_line(&line, i + 1, "doc.nc", &mut block)?;
        plans.push(interp.step(&block, &line)?);
    }
    Ok(plans)
}

/// One fenced example of the grammar document.
struct Example {
    /// Line of the opening fence in grammar/gcode.md.
    doc_line: usize,
    /// `Some(phrase)` for `gcode-reject` blocks.
    reject: Option<String>,
    /// The control's default unit, when an `<!-- units_default: … -->`
    /// comment before the block changes the document's (mm).
    units: Option<Option<Units>>,
    /// An `<!-- corner_words: comma -->` comment before the block: the
    /// control reads the corner words.
    corners: bool,
    text: String,
}

impl Example {
    /// The document's setup with the example's default unit.
    fn setup(&self) -> Setup {
        let mut setup = doc_setup();
        if let Some(u) = self.units {
            setup.units_default = u;
        }
        if self.corners {
            setup.corner_words = Some(postproc::program::interp::CornerWords::Comma);
        }
        setup
    }
}

fn doc_examples() -> Vec<Example> {
    let doc = std::fs::read_to_string(repo("grammar/gcode.md")).expect("grammar/gcode.md exists");
    let mut out = Vec::new();
    let mut expect: Option<String> = None;
    let mut units: Option<Option<Units>> = None;
    let mut corners = false;
    let mut current: Option<Example> = None;
    for (i, line) in doc.lines().enumerate() {
        let trimmed = line.trim_end();
        if let Some(ex) = current.as_mut() {
            if trimmed == "```" {
                out.push(current.take().expect("inside a block"));
            } else {
                ex.text.push_str(line);
                ex.text.push('\n');
            }
            continue;
        }
        if trimmed == "<!-- corner_words: comma -->" {
            corners = true;
        } else if let Some(rest) = trimmed.strip_prefix("<!-- units_default:") {
            units = Some(match rest.trim_end_matches("-->").trim() {
                "none" => None,
                "inch" => Some(Units::Inch),
                "mm" => Some(Units::Mm),
                other => panic!("grammar/gcode.md:{}: units_default `{other}`", i + 1),
            });
        } else if let Some(rest) = trimmed.strip_prefix("<!-- expect:") {
            let phrase = rest.trim_end_matches("-->").trim();
            expect = Some(phrase.to_string());
        } else if trimmed == "```gcode" {
            assert!(
                expect.is_none(),
                "grammar/gcode.md:{}: expect comment before an accepted block",
                i + 1
            );
            current = Some(Example {
                doc_line: i + 1,
                reject: None,
                units: units.take(),
                corners: std::mem::take(&mut corners),
                text: String::new(),
            });
        } else if trimmed == "```gcode-reject" {
            let phrase = expect.take().unwrap_or_else(|| {
                panic!(
                    "grammar/gcode.md:{}: gcode-reject block without <!-- expect: … -->",
                    i + 1
                )
            });
            current = Some(Example {
                doc_line: i + 1,
                reject: Some(phrase),
                units: units.take(),
                corners: std::mem::take(&mut corners),
                text: String::new(),
            });
        }
    }
    assert!(current.is_none(), "grammar/gcode.md: unclosed code fence");
    out
}

#[test]
fn grammar_doc_accepted_examples_interpret() {
    let examples: Vec<Example> = doc_examples()
        .into_iter()
        .filter(|e| e.reject.is_none())
        .collect();
    // The document has 5 accepted blocks (syntax tour, G codes, arcs, cycles,
    // cutter compensation); fewer means the extraction broke.
    assert!(
        examples.len() >= 5,
        "found {} accepted examples",
        examples.len()
    );
    for ex in &examples {
        let plans = run_program(&ex.text, ex.setup()).unwrap_or_else(|e| {
            panic!(
                "grammar/gcode.md:{}: documented as accepted, but: {e}",
                ex.doc_line
            )
        });
        assert!(
            plans.iter().any(|p| p.mv.is_some()),
            "grammar/gcode.md:{}: example moves nothing",
            ex.doc_line
        );
    }
}

#[test]
fn grammar_doc_rejected_examples_fail_with_their_phrase() {
    let examples: Vec<Example> = doc_examples()
        .into_iter()
        .filter(|e| e.reject.is_some())
        .collect();
    assert!(
        examples.len() >= 40,
        "found {} rejected examples",
        examples.len()
    );
    for ex in &examples {
        let phrase = ex.reject.as_deref().unwrap_or_default();
        match run_program(&ex.text, ex.setup()) {
            Ok(_) => panic!(
                "grammar/gcode.md:{}: documented as rejected (`{phrase}`), but accepted",
                ex.doc_line
            ),
            Err(e) => {
                assert!(
                    e.message.contains(phrase),
                    "grammar/gcode.md:{}: expected `{phrase}`, got `{}`",
                    ex.doc_line,
                    e.message
                );
                // The error points into the program: a real line, a column
                // within that line (or just past its end).
                let line = ex.text.lines().nth(e.line - 1).unwrap_or_else(|| {
                    panic!(
                        "grammar/gcode.md:{}: line {} out of range",
                        ex.doc_line, e.line
                    )
                });
                assert!(
                    e.column >= 1 && e.column <= line.len() + 1,
                    "grammar/gcode.md:{}: column {} outside `{line}`",
                    ex.doc_line,
                    e.column
                );
            }
        }
    }
}

/// Every sample program is inside the documented dialect.
#[test]
fn samples_parse_and_interpret() {
    let mut setup = doc_setup();
    setup.axes = [true; 6];
    let dir = repo("samples/gcode");
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).expect("samples/gcode exists") {
        let path = entry.expect("dir entry").path();
        if path.extension().is_some_and(|e| e == "md") {
            continue;
        }
        let text = std::fs::read_to_string(&path).expect("sample is text");
        if let Err(e) = run_program(&text, setup.clone()) {
            panic!("{}: {e}", path.display());
        }
        n += 1;
    }
    assert!(n >= 5, "only {n} samples");
}

// ---------------------------------------------------------------- regressions

/// `G53 G0` (and `G0 G28`) make G0 modal, so a later block with axis words
/// only is a rapid, not a feed at the G1 set before; G28 alone leaves the
/// modal motion as it is.
#[test]
fn g53_and_g28_keep_their_motion_code_modal() {
    let plans = run_program("G1 X1 F100\nG53 G0 Z0\nX5\n", doc_setup()).expect("valid");
    let mv = plans[2].mv.expect("X5 moves");
    assert_eq!(mv.motion, Motion::Rapid);
    let plans = run_program("G1 X1 F100\nG0 G28 G91 Z0\nG90 X5\n", doc_setup()).expect("valid");
    let mv = plans[2].mv.expect("X5 moves");
    assert_eq!(mv.motion, Motion::Rapid);
    // G28 alone leaves the modal motion as it was.
    let plans = run_program("G1 X1 F100\nG28 G91 Z0\nG90 X5\n", doc_setup()).expect("valid");
    assert_eq!(plans[2].mv.expect("X5 moves").motion, Motion::Linear);
}

/// `Interpreter::step` given a line text shorter than the block's word
/// spans reports the plane-normal error at the word's column instead of
/// panicking on the slice.
#[test]
fn step_with_text_shorter_than_the_block_does_not_panic() {
    let mut interp = Interpreter::new(doc_setup(), "t.nc");
    let mut block = Block::default();
    parse_line(b"G0 X0 Y0", 1, "t.nc", &mut block).expect("valid");
    interp.step(&block, b"G0 X0 Y0").expect("valid");
    parse_line(b"G2 X10 Y0 I5 K1 F100", 2, "t.nc", &mut block).expect("valid syntax");
    let e = interp.step(&block, b"").expect_err("K along the normal");
    assert!(e.message.contains("plane normal"), "{}", e.message);
    // K1 starts at byte 13: column 14.
    assert_eq!((e.line, e.column), (2, 14));
}

/// A Siemens-style `X=10.` is reported as an assignment, at the `=`, not as
/// "letter `X` without a number".
#[test]
fn assignment_after_a_letter_is_named() {
    let mut block = Block::default();
    let e = parse_line(b"G1 X=10.", 4, "t.nc", &mut block).expect_err("assignment");
    assert!(
        e.message
            .contains("assignments cannot be compensated offline"),
        "{}",
        e.message
    );
    // `=` is byte 4: column 5.
    assert_eq!((e.line, e.column), (4, 5));
}

// ---------------------------------------------------------------- properties

fn any_setup() -> Setup {
    let mut setup = Setup {
        axes: [true; 6],
        units_default: Some(Units::Mm),
        ..Setup::default()
    };
    setup.tools.insert(1, 100.0);
    setup.tools.insert(2, 50.0);
    setup.work_offsets[0] = Some([-300.0, -200.0, -400.0]);
    setup.work_offsets[1] = Some([10.0, 20.0, 30.0]);
    setup
}

/// Feeds lines to a parser and one interpreter; errors are fine, panics are not.
fn feed(lines: &[Vec<u8>]) {
    let mut interp = Interpreter::new(any_setup(), "p.nc");
    let mut block = Block::default();
    for (i, line) in lines.iter().enumerate() {
        if parse_line(line, i + 1, "p.nc", &mut block).is_ok() {
            if let Err(e) = interp.step(&block, line) {
                assert_eq!(e.line, i + 1);
            }
        }
    }
}

/// A token of "almost G-code": mostly sensible, sometimes broken.
fn token() -> impl Strategy<Value = String> {
    let g_code = prop::sample::select(vec![
        "0", "1", "2", "3", "4", "9", "17", "18", "19", "20", "21", "28", "40", "41", "43", "49",
        "53", "54", "55", "59", "73", "80", "81", "82", "83", "84", "85", "89", "90", "91", "90.1",
        "91.1", "94", "95", "98", "99", "10", "92", "68", "65", "43.4", "01", "02", "5.1",
    ]);
    prop_oneof![
        g_code.prop_map(|c| format!("G{c}")),
        (
            prop::sample::select(b"XYZABCIJKRFSTHPQLMNOD".to_vec()),
            "[+-]?([0-9]{1,4}(\\.[0-9]{0,4})?|\\.[0-9]{1,3})"
        )
            .prop_map(|(l, n)| format!("{}{n}", l as char)),
        (
            prop::sample::select(b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz".to_vec()),
            "[+-.0-9 ]{0,6}"
        )
            .prop_map(|(l, n)| format!("{}{n}", l as char)),
        Just(" ".to_string()),
        Just("\t".to_string()),
        "\\([ -~]{0,8}\\)?",
        ";[ -~]{0,8}",
        prop::sample::select(vec![
            "/", "%", "#1", "[", "]", "=", "*", "M98", "M99", "O1 sub", "\r"
        ])
        .prop_map(|s| s.to_string()),
    ]
}

fn almost_line() -> impl Strategy<Value = Vec<u8>> {
    prop::collection::vec(token(), 0..10).prop_map(|t| t.concat().into_bytes())
}

/// A valid number's text and its decimals.
fn number_text() -> impl Strategy<Value = String> {
    "[+-]?([0-9]{1,6}(\\.[0-9]{0,4})?|\\.[0-9]{1,4})"
}

/// A valid block: (letter as written, spaces after the letter, number text),
/// separators and optional comments, plus the line text.
fn valid_block() -> impl Strategy<Value = (Vec<(u8, String)>, String)> {
    let letter = prop::sample::select(
        LETTERS
            .iter()
            .flat_map(|&l| [l, l.to_ascii_lowercase()])
            .collect::<Vec<u8>>(),
    );
    let word = (
        letter,
        "[ \t]{0,2}",
        number_text(),
        "[ \t]{0,2}",
        "(\\([A-Z =.#]{0,6}\\))?",
    );
    (
        prop::collection::vec(word, 1..8),
        "(;[ -~]{0,10})?",
        any::<bool>(),
    )
        .prop_map(|(words, tail, slash)| {
            let mut line = String::new();
            if slash {
                line.push('/');
            }
            let mut spec = Vec::new();
            for (l, gap, num, sep, comment) in words {
                line.push(l as char);
                line.push_str(&gap);
                line.push_str(&num);
                line.push_str(&sep);
                line.push_str(&comment);
                spec.push((l, num));
            }
            line.push_str(&tail);
            (spec, line)
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn arbitrary_bytes_never_panic(lines in prop::collection::vec(prop::collection::vec(any::<u8>(), 0..80), 1..8)) {
        feed(&lines);
    }

    #[test]
    fn almost_gcode_never_panics(lines in prop::collection::vec(almost_line(), 1..12)) {
        feed(&lines);
    }

    #[test]
    fn valid_blocks_keep_word_spans((spec, line) in valid_block()) {
        let mut block = Block::default();
        let parsed = parse_line(line.as_bytes(), 1, "v.nc", &mut block);
        prop_assert!(parsed.is_ok(), "`{}`: {:?}", line, parsed);
        prop_assert_eq!(block.words.len(), spec.len(), "`{}`", line);
        let bytes = line.as_bytes();
        for (w, (letter, num)) in block.words.iter().zip(&spec) {
            prop_assert_eq!(bytes[w.start as usize], *letter);
            prop_assert_eq!(w.letter, letter.to_ascii_uppercase());
            prop_assert_eq!(w.number_text(bytes), num.as_bytes());
            let expected: f64 = num.parse().expect("generated number is valid");
            prop_assert_eq!(w.value, expected);
            let decimals = num.find('.').map(|d| (num.len() - d - 1) as u8);
            prop_assert_eq!(w.decimals, decimals);
            // Between the letter and the number only spaces and tabs.
            let gap = &bytes[w.start as usize + 1..w.num_start as usize];
            prop_assert!(gap.iter().all(|&b| b == b' ' || b == b'\t'));
        }
    }
}
