//! Compensation of a RAPID module read a window at a time
//! ([`crate::program::rapid::windows`]), so that memory does not grow with
//! the module: each window is parsed as a module of its own (the
//! declarations and the window's lines), compensated from the state the
//! windows before left (the engine's `Carry`), and its rewritten lines are written
//! out at once. Only the edits of the declarations (in-place values, new
//! `_cN`/`_oN` declarations) wait for the end, with the declarations.
//!
//! The result is the one of the module compensated whole, byte for byte
//! (tested with windows of every size on the sample modules). A thermal
//! time line that starts from the program's own mean power (`steady`, a
//! warm-up) is added up by a first pass over the module that compensates
//! nothing. Where the window reading does not apply — a module of another
//! shape, or any error — the caller compensates the module whole, which
//! also reports every error exactly as it always does.

use std::io::{BufRead, Write};

use super::{Carry, ModuleText, RapidOptions, compensate_window};
use crate::compensate::outcome::{Row, Summary};
use crate::error::{Error, Result};
use crate::machine::ThermalStart;
use crate::machine::robot::Robot;
use crate::machine::robot::thermal::ThermalTotals;
use crate::predict::EffectSet;
use crate::process::CutSettings;
use crate::program::rapid::directives::Directives;
use crate::program::rapid::windows::{Piece, Unsupported, Windows};
use crate::program::rapid::{Span, Stmt, parse_module};

/// Lines per window unless asked otherwise: windows of a few megabytes
/// (the memory of a window is about 2 KB per move while it is worked on).
pub const WINDOW_LINES: usize = 8192;

/// What a window costs beyond the lines it holds, in bytes of parsing:
/// the declarations (bytes before the first routine), parsed again with
/// every window, and this much for the rest of its set-up. That cost, for
/// the windows a routine's end cuts short, is held to a quarter of the
/// routines' parse, after four windows' worth:
/// many short routines after declarations are read whole instead (each
/// routine gives a window of its own; the windows of a routine after
/// declarations of [`crate::program::rapid::windows::BIG_PROLOGUE_BYTES`]
/// and more are made [`crate::program::rapid::windows::PROLOGUE_WINDOWS`] times as long as they).
const WINDOW_SETUP_BYTES: usize = 256;

/// Bytes after which a window ends at the next statement boundary whatever
/// its number of lines.
const WINDOW_BYTES: usize = 4 << 20;

/// A module compensated (or checked) a window at a time.
#[derive(Debug)]
pub struct Streamed {
    /// What the run did, as [`super::compensate_module`] gives it (the
    /// text went to the output as it was made, the rows to the sink).
    pub summary: Summary,
    /// The module's name.
    pub name: String,
    /// Module-level declarations.
    pub decls: usize,
    /// Routines.
    pub routines: usize,
    /// Motion instructions.
    pub moves: usize,
}

/// What takes the move records of each window (with `opts.records`), in
/// move order: a report writer, row by row.
pub type RecordSink<'s> = &'s mut dyn FnMut(&[Row]) -> Result<()>;

/// Why a module was not read a window at a time.
#[derive(Debug)]
pub enum Fallback {
    /// Its shape ([`Unsupported`]).
    Shape(Unsupported),
    /// An error, left for the whole-module run to report as it does.
    Error(Error),
}

impl From<Unsupported> for Fallback {
    fn from(u: Unsupported) -> Self {
        Fallback::Shape(u)
    }
}

impl From<Error> for Fallback {
    fn from(e: Error) -> Self {
        Fallback::Error(e)
    }
}

impl From<crate::error::Located> for Fallback {
    fn from(e: crate::error::Located) -> Self {
        Fallback::Error(e.into())
    }
}

/// Compensates the module that `open` reads (named `file` in messages) a
/// window of `window_lines` lines at a time. The text after the
/// declarations goes to `body` as it is made; the returned prologue (the
/// module header and declarations, with their edits and new declarations)
/// goes before it. `body` is `None` for a check (nothing written). With
/// `opts.records`, the records of each window go to `records` (and the
/// outcome has none). A thermal time line that starts from the program's
/// own mean power (steady, warm-up) takes a first pass over the module
/// (`open` is called twice) that adds it up.
pub fn compensate_streamed<R: BufRead>(
    open: &mut dyn FnMut() -> std::io::Result<R>,
    file: &str,
    robot: &Robot,
    opts: &RapidOptions,
    window_lines: usize,
    body: Option<&mut dyn Write>,
    records: Option<RecordSink>,
) -> std::result::Result<(Streamed, String), Fallback> {
    let mut carry = Carry::default();
    // The routines of later windows are not seen when a window names new
    // data: their names are read first.
    let names = open()
        .and_then(crate::program::rapid::windows::routine_names)
        .map_err(|e| Error::io(file, e))?;
    carry
        .reserved
        .extend(names.iter().map(|n| n.to_ascii_lowercase()));
    if let Some(t) = robot.thermal().filter(|_| first_pass(robot, opts)) {
        let mut first = Carry {
            time_line: Some(ThermalTotals::default()),
            ..Carry::default()
        };
        // The first pass only adds up the joint powers: no records, no
        // annotations, no vibration (the resonance check runs once, in the
        // second pass).
        let first_opts = RapidOptions {
            records: false,
            annotate: false,
            effects: EffectSet {
                dynamic: 0.0,
                ..opts.effects
            },
            ..opts.clone()
        };
        let reader = open().map_err(|e| Error::io(file, e))?;
        pass(
            reader,
            file,
            Some(robot),
            &first_opts,
            window_lines,
            &mut first,
            None,
            None,
        )?;
        let totals = first.time_line.unwrap_or_default();
        carry.thermal_x = Some(totals.start_state(opts.thermal_start, t.time_constant_s));
    }
    let reader = open().map_err(|e| Error::io(file, e))?;
    let done = pass(
        reader,
        file,
        Some(robot),
        opts,
        window_lines,
        &mut carry,
        body,
        records,
    )?;
    super::refuse_left_as_written(&done.0.summary.warnings, file, opts)?;
    Ok(done)
}

/// Whether [`compensate_streamed`] takes a first pass over the module: a
/// thermal time line that starts from the program's own mean power.
pub fn first_pass(robot: &Robot, opts: &RapidOptions) -> bool {
    robot.thermal().is_some()
        && opts.effects.thermal != 0.0
        && opts.thermal_start != ThermalStart::Cold
}

/// Checks the syntax of the module that `reader` reads (named `file` in
/// messages) a window of `window_lines` lines at a time, as `check` without
/// a machine does with the module read whole: every window is parsed,
/// nothing is resolved or solved. The outcome counts the moves.
pub fn check_syntax_streamed<R: BufRead>(
    reader: R,
    file: &str,
    window_lines: usize,
) -> std::result::Result<Streamed, Fallback> {
    let opts = RapidOptions {
        effects: crate::predict::EffectSet::NONE,
        annotate: false,
        format: crate::emit::rapid::Format::default(),
        thermal_start: ThermalStart::Cold,
        records: false,
        strict: false,
        joint_cartesian: false,
        force_table: None,
        uncertainty: None,
    };
    let mut carry = Carry::default();
    let (streamed, _) = pass(
        reader,
        file,
        None,
        &opts,
        window_lines,
        &mut carry,
        None,
        None,
    )?;
    Ok(streamed)
}

/// One pass over the module in `reader`, from the state in `carry`;
/// without a robot, only the windows' syntax (nothing is resolved,
/// compensated or written).
#[allow(clippy::too_many_arguments)]
fn pass<R: BufRead>(
    reader: R,
    file: &str,
    robot: Option<&Robot>,
    opts: &RapidOptions,
    window_lines: usize,
    carry: &mut Carry,
    mut body: Option<&mut dyn Write>,
    mut records: Option<RecordSink>,
) -> std::result::Result<(Streamed, String), Fallback> {
    let mut w = Windows::new(reader, window_lines, WINDOW_BYTES)?;
    let prologue_len = w.prologue().len();
    let mut cut = CutSettings::default();
    if robot.is_some() {
        cut = Directives::parse_lines(w.prologue(), file, 1, cut)?.last();
    }
    let mut decls: Option<(String, Vec<Span>)> = None;
    let mut moves = 0;
    let (mut reparsed, mut routine_bytes) = (0usize, 0usize);
    let mut routine: Option<std::rc::Rc<str>> = None;
    let mut write = |text: &str| -> Result<()> {
        match body.as_deref_mut() {
            Some(out) => out
                .write_all(text.as_bytes())
                .map_err(|e| Error::io(file, e)),
            None => Ok(()),
        }
    };
    while let Some(piece) = w.next_piece()? {
        match piece {
            Piece::Verbatim { text, line } => {
                if robot.is_some() {
                    cut = Directives::parse_lines(&text, file, line, cut)?.last();
                }
                write(&text)?;
            }
            Piece::Window {
                body: lines,
                line,
                header,
                end_word,
            } => {
                let text = w.window_text(&header, &lines, end_word);
                let mut module = parse_module(&text, file)?;
                if module.procs.len() != 1 {
                    return Err(Unsupported("a window is not one routine".into()).into());
                }
                // The window's lines start on line `prologue_lines + 2` of
                // its text and on `line` of the file.
                let shift = line - (w.prologue_lines() + 2);
                for p in &mut module.procs {
                    for s in &mut p.body {
                        match s {
                            Stmt::Move(m) => m.line += shift,
                            Stmt::Decl(d) => d.line += shift,
                            Stmt::Assign(a) => a.line += shift,
                            Stmt::Control { line, .. } | Stmt::Opaque { line, .. } => {
                                *line += shift
                            }
                        }
                    }
                }
                // The parse must see what the scanner saw: every declaration
                // within the prologue, the routine after it, and the same
                // declarations in every window (a multi-line attribute list
                // or string holding a header line fools the line scanner).
                let routine_after = module
                    .procs
                    .first()
                    .is_some_and(|p| p.span.start >= prologue_len);
                if !routine_after || module.decls.iter().any(|d| d.span.end > prologue_len) {
                    return Err(Unsupported(
                        "the declarations do not end where the first routine starts".into(),
                    )
                    .into());
                }
                let spans: Vec<Span> = module.decls.iter().map(|d| d.span.clone()).collect();
                match &decls {
                    None => decls = Some((module.name.clone(), spans)),
                    Some((_, first)) if *first != spans => {
                        return Err(Unsupported(
                            "the declarations read differently in two windows".into(),
                        )
                        .into());
                    }
                    Some(_) => {}
                }
                // Each window parses the declarations again: that may cost
                // at most a quarter of parsing the routines, beyond a start
                // allowance (many short routines after declarations are
                // read whole instead). Windows of the length asked for are
                // the caller's choice; those a routine's end cut short count.
                let per_window = prologue_len + WINDOW_SETUP_BYTES;
                if memchr::memchr_iter(b'\n', lines.as_bytes()).count() < window_lines {
                    reparsed += per_window;
                }
                routine_bytes += lines.len();
                if reparsed > routine_bytes / 4 + 4 * per_window {
                    return Err(Unsupported(
                        "the declarations would be parsed again for many short routines".into(),
                    )
                    .into());
                }
                moves += module.moves().count();
                let Some(robot) = robot else { continue };
                let directives = Directives::parse_lines(&lines, file, line, cut)?;
                cut = directives.last();
                let start = prologue_len + header.len();
                continue_routine(carry, &mut routine, &header);
                let window = ModuleText {
                    module: &module,
                    src: &text,
                    file,
                };
                let edits = compensate_window(window, robot, opts, carry, Some(directives), start)?;
                if let Some(why) = carry.unsupported {
                    return Err(Unsupported(why.into()).into());
                }
                carry.leave_unknown(&module, &text, file);
                write(&edits.apply_in(&text, start..start + lines.len())?)?;
                if let Some(sink) = records.as_deref_mut() {
                    sink(&carry.records)?;
                    carry.records.clear();
                }
            }
        }
    }
    let (name, spans) = decls.ok_or_else(|| Unsupported("no routine body".into()))?;
    let mut edits = std::mem::take(&mut carry.before);
    carry.push_inserts(w.prologue(), &spans, &mut edits);
    let prologue = edits.apply(w.prologue())?;
    let summary = match robot {
        Some(robot) => carry.outcome(robot, file).summary,
        None => Summary {
            moves,
            ..Summary::default()
        },
    };
    let streamed = Streamed {
        summary,
        name,
        decls: spans.len(),
        routines: w.routines(),
        moves,
    };
    Ok((streamed, prologue))
}

/// Before the window of routine `header`: a window of the routine of the
/// window before (`routine`) continues its configuration monitoring, the
/// first window of a routine starts with it on.
fn continue_routine(
    carry: &mut Carry,
    routine: &mut Option<std::rc::Rc<str>>,
    header: &std::rc::Rc<str>,
) {
    let same = routine
        .as_ref()
        .is_some_and(|r| std::rc::Rc::ptr_eq(r, header));
    carry.conf_continued = same.then_some(carry.conf_end);
    *routine = Some(std::rc::Rc::clone(header));
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::predict::EffectSet;
    use crate::program::rapid::windows;

    fn robot() -> Robot {
        let file = crate::machine::MachineFile::bundled("abb-irb1600").unwrap();
        match file.load().unwrap() {
            crate::machine::Machine::Robot(r) => r,
            crate::machine::Machine::Tool(_) => panic!("not a robot"),
        }
    }

    fn streamed(src: &str, robot: &Robot, opts: &RapidOptions, lines: usize) -> Option<String> {
        let mut body = Vec::new();
        let (_, prologue) = compensate_streamed(
            &mut || Ok(src.as_bytes()),
            "t.mod",
            robot,
            opts,
            lines,
            Some(&mut body),
            None,
        )
        .ok()?;
        Some(prologue + std::str::from_utf8(&body).unwrap())
    }

    fn robot_file(path: &str) -> Robot {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(path);
        match crate::machine::Machine::load(&path).unwrap() {
            crate::machine::Machine::Robot(r) => r,
            crate::machine::Machine::Tool(_) => panic!("not a robot"),
        }
    }

    /// Named targets used under two tools (in-place values and `_cN`
    /// copies), `Offs`/`RelTool` targets (`_oN`), an array element, a
    /// circle, a joint move, work objects, directives in a body and
    /// between routines, comments, three routines; CRLF line breaks in
    /// the variant.
    const RICH: &str = r#"MODULE Rich
  PERS tooldata tA := [TRUE,[[0,0,150],[1,0,0,0]],[2,[0,0,70],[1,0,0,0],0.01,0.01,0.004]];
  PERS tooldata tB := [TRUE,[[10,0,200],[1,0,0,0]],[3,[0,0,90],[1,0,0,0],0.01,0.01,0.004]];
  PERS wobjdata wP := [FALSE,TRUE,"",[[600,-200,350],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];
  CONST speeddata vF := [20,30,5000,1000];
  CONST jointtarget jH := [[0,-10,20,0,80,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget p1 := [[750,0,500],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget p2 := [[760,20,480],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget c{2} := [
    [[100,250,0],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],
    [[150,260,0],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]];
  ! POSTPROC MILLING DEPTH=3 WIDTH=1
  PROC main()
    MoveAbsJ jH\NoEOffs, v1000, fine, tA;
    MoveJ p1, v1000, z50, tA;
    MoveL p2, vF, z1, tA;
    MoveL p1, vF, z1, tB;
    ! a comment; MoveL p2
    MoveC p2, p1, vF, z1, tA;
    MoveL Offs(c{1},0,0,-2), vF, fine, tA\WObj:=wP;
    MoveL Offs(c{2},0,0,-2), vF, z1, tA\WObj:=wP;
    ! POSTPROC MILLING DEPTH=5 RPM=18000
    MoveL c{1}, vF, z1, tA\WObj:=wP;
    IF TRUE THEN
      MoveL RelTool(p1,0,0,-20), v100, z10,
        tB;
    ENDIF
    MoveL [[800,-0.5,450],[0,0,1,0],[-1,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]], v100, fine, tA;
    two;
  ENDPROC

  ! POSTPROC MILLING WIDTH=0.5
  LOCAL PROC two()
    MoveL p2, vF, z1, tB;
    MoveL Offs(p2,0,5,0), vF, z1, tB;
    MoveL p1, vF, z1, tA;
  ENDPROC
  TRAP t
    MoveL p2, vF, fine, tA;
  ENDTRAP
ENDMODULE
"#;

    /// Modules compensated a window at a time, windows of every size, read
    /// byte for byte as compensated whole: the sample modules and a module
    /// with every rewriting rule, on both robot files, every effect on
    /// (the thermal time line from a cold, steady or warm start, process
    /// forces), with and without annotations.
    #[test]
    fn windows_of_any_size_give_the_whole_module_result() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("samples");
        let mut modules: Vec<(String, String)> = ["milling.mod", "drilling.mod"]
            .iter()
            .map(|f| (f.to_string(), std::fs::read_to_string(dir.join(f)).unwrap()))
            .collect();
        modules.push(("rich".into(), RICH.to_string()));
        modules.push(("rich crlf".into(), RICH.replace('\n', "\r\n")));
        let robots = [robot(), robot_file("samples/irb1600-milling.yaml")];
        let mut checked = 0;
        for (name, src) in &modules {
            for robot in &robots {
                for (annotate, thermal_start) in [
                    (true, ThermalStart::Cold),
                    (false, ThermalStart::Cold),
                    (true, ThermalStart::Steady),
                    (true, ThermalStart::WarmUpMin(15.0)),
                ] {
                    let opts = RapidOptions {
                        effects: EffectSet::ALL,
                        annotate,
                        records: false,
                        thermal_start,
                        ..RapidOptions::for_robot(robot)
                    };
                    let whole = super::super::compensate_module(src, "t.mod", robot, &opts)
                        .unwrap_or_else(|e| panic!("{name}: {e}"));
                    assert!(whole.summary.moves > 0 && whole.text != *src);
                    if name.starts_with("rich") {
                        // p1/p2 copies under tB, three `Offs`, a `RelTool`.
                        assert!(
                            whole.summary.added >= 5,
                            "{name}: {} added",
                            whole.summary.added
                        );
                        assert!(whole.text.contains("p1_c2") && whole.text.contains("c2_o1"));
                    }
                    let lines = src.lines().count();
                    for n in [1, 2, 3, 7, lines] {
                        let text = streamed(src, robot, &opts, n)
                            .unwrap_or_else(|| panic!("{name}: not streamed"));
                        assert_eq!(text, whole.text, "{name} in windows of {n} lines");
                        checked += 1;
                    }
                }
            }
        }
        assert_eq!(checked, 4 * 2 * 4 * 5);
    }

    fn shape_refused(src: &str, lines: usize) -> bool {
        let robot = robot();
        let opts = RapidOptions::for_robot(&robot);
        matches!(
            compensate_streamed(
                &mut || Ok(src.as_bytes()),
                "t.mod",
                &robot,
                &opts,
                lines,
                None,
                None
            ),
            Err(Fallback::Shape(_))
        )
    }

    /// `MODULE M` and `n` robtarget declarations.
    fn declarations(n: usize) -> String {
        let mut src = String::from("MODULE M\n");
        for k in 0..n {
            src.push_str(&format!(
                "  CONST robtarget p{k} := [[{},0,500],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n",
                700 + k % 50
            ));
        }
        src
    }

    /// A header line the scanner sees inside what the parser reads as
    /// something else (a multi-line attribute list) is refused: the
    /// declarations' edits would land in the wrong place (a new declaration
    /// would be written into the attribute list).
    #[test]
    fn declarations_must_end_where_the_scanner_saw_the_first_routine() {
        let src = "MODULE M(\nTRAP t\n) CONST robtarget q := [[720,-40,420],[0,0,1,0],[-1,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]]; TRAP y\nMoveL Offs(q,1,2,3), v100, z1, tool0;\nENDTRAP\nENDMODULE\n";
        let robot = robot();
        let whole =
            super::super::compensate_module(src, "t.mod", &robot, &RapidOptions::for_robot(&robot))
                .unwrap();
        assert!(whole.text.contains("q_o1"));
        assert!(shape_refused(src, 1));
    }

    /// Long declarations parsed again for each of many short routines are
    /// read whole instead: a window per routine would parse the
    /// declarations once per routine, many times the cost of parsing the
    /// module once.
    #[test]
    fn many_short_routines_after_long_declarations_are_read_whole() {
        let mut src = declarations(800);
        assert!(src.len() >= windows::BIG_PROLOGUE_BYTES);
        let mut few = src.clone();
        let routines = |src: &mut String, n: usize| {
            for k in 0..n {
                src.push_str(&format!(
                    "  PROC r{k}()\n    MoveL p{k}, v100, z1, tool0;\n  ENDPROC\n"
                ));
            }
            src.push_str("ENDMODULE\n");
        };
        routines(&mut src, 300);
        assert!(shape_refused(&src, 1000));
        // Shorter declarations too (16 KB of them, parsed again before each
        // of many one-move routines, still cost far more than one parse),
        // and none.
        for n in [190, 0] {
            let mut short = declarations(n);
            for k in 0..300 {
                let target = match n {
                    0 => "[[700,0,500],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]".to_string(),
                    n => format!("p{}", k % n),
                };
                short.push_str(&format!(
                    "  PROC r{k}()\n    MoveL {target}, v100, z1, tool0;\n  ENDPROC\n"
                ));
            }
            short.push_str("ENDMODULE\n");
            assert!(shape_refused(&short, 1000), "{n} declarations");
        }
        // A few routines after the same declarations are taken.
        routines(&mut few, 3);
        assert!(!shape_refused(&few, 1000));
    }

    /// One long routine after long declarations is taken, in windows made
    /// several times as long as the declarations (so that the guard
    /// against parsing them again does not read it whole).
    #[test]
    fn a_long_routine_after_long_declarations_is_taken() {
        let mut src = declarations(760);
        let prologue = src.len();
        src.push_str("  PROC main()\n");
        for k in 0..20000 {
            src.push_str(&format!("    MoveL p{}, v100, z1, tool0;\n", k % 760));
        }
        src.push_str("  ENDPROC\nENDMODULE\n");
        // Two windows at least, each parsing the declarations again.
        assert!(prologue >= windows::BIG_PROLOGUE_BYTES);
        assert!(src.len() - prologue > windows::PROLOGUE_WINDOWS * prologue);
        let robot = robot();
        let opts = RapidOptions {
            effects: EffectSet::NONE,
            ..RapidOptions::for_robot(&robot)
        };
        let (s, _) = compensate_streamed(
            &mut || Ok(src.as_bytes()),
            "t.mod",
            &robot,
            &opts,
            100,
            None,
            None,
        )
        .unwrap();
        assert_eq!(s.moves, 20000);
    }

    /// The records a report is written from, window by window, are those
    /// of the module compensated whole.
    #[test]
    fn records_go_out_window_by_window_as_whole() {
        let robot = robot_file("samples/irb1600-milling.yaml");
        let opts = RapidOptions {
            effects: EffectSet::ALL,
            records: true,
            ..RapidOptions::for_robot(&robot)
        };
        let whole = super::super::compensate_module(RICH, "t.mod", &robot, &opts).unwrap();
        // A record per compensated move and per reported MoveAbsJ.
        let reported = whole
            .summary
            .warnings
            .iter()
            .filter_map(|w| w.left.as_ref())
            .filter(|a| a.reason == super::super::JOINT_TARGET)
            .count();
        assert_eq!(whole.records.len(), whole.summary.moves + reported);
        for lines in [1, 4, 100] {
            let mut got = Vec::new();
            let mut sink = |r: &[Row]| -> Result<()> {
                got.extend_from_slice(r);
                Ok(())
            };
            let (s, _) = compensate_streamed(
                &mut || Ok(RICH.as_bytes()),
                "t.mod",
                &robot,
                &opts,
                lines,
                None,
                Some(&mut sink),
            )
            .unwrap();
            assert_eq!(s.summary, whole.summary, "windows of {lines} lines");
            assert_eq!(got, whole.records, "windows of {lines} lines");
        }
    }
}
