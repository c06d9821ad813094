//! Shop programs: a G-code program whose subprograms are followed before it
//! is compensated ([`crate::program::gcode::subprograms`]), written back
//! with its subprograms ([`crate::emit::subprograms`]).
//!
//! A program of at most [`WHOLE_MAX_BYTES`] is read whole and looked at for
//! subprogram calls; one without runs through [`Job::run`] as it is, one
//! with runs as the control runs it (every call in order, each line with
//! its own line number) and is written with the structure it has. A longer
//! program streams through [`Job::run`] (its subprogram calls are refused
//! where they are).
//!
//! A program with corner words (`,C`, `,R`, where the machine file's
//! `corner_words` says the control reads them) is compensated as written
//! (the corner point moves like any other point and the words stay), and
//! the corner the control then makes from the compensated lines is checked
//! ([`check_corners`]): its pieces (the first line up to the first tangent
//! point, the chamfer line or round arc, the next line from the second
//! tangent point) are predicted and held against the pieces the control
//! makes from the programmed lines; a corner that misses by more than the
//! tolerance is warned about with its line and miss.

use std::io::{BufRead, Read, Write};

use nalgebra::Vector3;

use crate::compensate::outcome::{Row, Summary};
use crate::emit::gcode::EmitOptions;
use crate::emit::subprograms::{Outputs, Written};
use crate::error::{Error, Result};
use crate::pipeline::gcode::Job;
use crate::predict::context::MoveContext;
use crate::predict::tool::ToolPredictor;
use crate::program::gcode::subprograms;
use crate::program::interp::{Corner, CornerKind, Move, Warning};

/// Largest program read whole to look for subprograms.
pub const WHOLE_MAX_BYTES: u64 = 64 << 20;

/// [`Job::run`] with the program's subprograms followed: the summary and,
/// for a program with subprograms, what was made of them.
pub fn run(
    job: &Job,
    mut input: Box<dyn BufRead + '_>,
    file: &str,
    out: Option<&mut dyn Write>,
    rows: Option<&mut dyn FnMut(Row)>,
) -> Result<(Summary, Option<Written>)> {
    let mut text = Vec::new();
    (&mut input)
        .take(WHOLE_MAX_BYTES)
        .read_to_end(&mut text)
        .map_err(|e| Error::io(file, e))?;
    if text.len() as u64 == WHOLE_MAX_BYTES {
        let whole = std::io::Cursor::new(text).chain(input);
        return Ok((job.run(whole, file, out, rows)?, None));
    }
    if let Some(e) = crate::program::gcode::dialect::lathe_program(&text, file) {
        return Err(e.into());
    }
    let corners = has_corner_words(&text) && job.predictor.is_some();
    let Some(exp) = subprograms::expand(&text, file)? else {
        let out = match out {
            Some(out) if corners => out,
            out => return Ok((job.run(&text[..], file, out, rows)?, None)),
        };
        let mut bytes = Vec::new();
        let mut summary = job.run(&text[..], file, Some(&mut bytes), rows)?;
        check_corners(job, (&text, None), &bytes, file, &mut summary)?;
        out.write_all(&bytes).map_err(|e| Error::io("output", e))?;
        return Ok((summary, None));
    };
    let (stream, numbers) = exp.stream(&text);
    let mut marks = Vec::with_capacity(numbers.len());
    let Some(out) = out else {
        let mut summary =
            job.run_traced(&stream[..], file, None, rows, Some((&numbers, &mut marks)))?;
        summary.lines = exp.lines.len();
        return Ok((summary, None));
    };
    let mut written = Vec::new();
    let mut summary = job.run_traced(
        &stream[..],
        file,
        Some(&mut written),
        rows,
        Some((&numbers, &mut marks)),
    )?;
    summary.lines = exp.lines.len();
    let out_outputs = Outputs {
        bytes: &written,
        marks: &marks,
    };
    // Calls are compared by their corrections, not by the predicted
    // deviations the annotations write.
    let (compare_bytes, compare_marks);
    let compare = if job.emit.annotate {
        let bare = Job {
            predictor: job.predictor,
            setup: job.setup.clone(),
            settings: job.settings,
            emit: EmitOptions {
                annotate: false,
                ..job.emit
            },
            pool: job.pool,
            travel: job.travel,
        };
        let mut b = Vec::new();
        let mut m = Vec::with_capacity(numbers.len());
        // The same run again: its warnings were given by the run before.
        tracing::subscriber::with_default(tracing::subscriber::NoSubscriber::default(), || {
            bare.run_traced(
                &stream[..],
                file,
                Some(&mut b),
                None,
                Some((&numbers, &mut m)),
            )
        })?;
        (compare_bytes, compare_marks) = (b, m);
        Outputs {
            bytes: &compare_bytes,
            marks: &compare_marks,
        }
    } else {
        out_outputs
    };
    let (bytes, made) = crate::emit::subprograms::write(&exp, &text, compare, out_outputs);
    if corners {
        check_corners(job, (&stream, Some(&numbers)), &bytes, file, &mut summary)?;
    }
    out.write_all(&bytes).map_err(|e| Error::io("output", e))?;
    Ok((summary, Some(made)))
}

/// Whether `text` may hold a corner word (a comma before `C` or `R`; the
/// forward passes of [`check_corners`] read them exactly).
fn has_corner_words(text: &[u8]) -> bool {
    memchr::memchr_iter(b',', text)
        .any(|i| matches!(text.get(i + 1), Some(b'C' | b'c' | b'R' | b'r')))
}

/// Samples of each line piece and of the chamfer or arc piece of a corner
/// at which its predicted path is held against the programmed one.
const CORNER_SAMPLES: usize = 32;

/// A corner as a forward pass reads it: the corner block's line (of the
/// input), its corner, its move and the next move, each with its context.
struct SeenCorner {
    line: usize,
    corner: Corner,
    first: (Move, MoveContext),
    next: Option<(Move, MoveContext)>,
}

/// The corners of a program in the order they run, and the error that
/// ended the pass early, if any: `input` is the stream the interpreter
/// reads with the input line of each of its lines (`None`: its own).
fn corners_of(
    job: &Job,
    input: (&[u8], Option<&[usize]>),
    file: &str,
) -> (Vec<SeenCorner>, Option<Error>) {
    let (bytes, numbers) = input;
    let mut seen: Vec<SeenCorner> = Vec::new();
    let mut waiting = false;
    let done = job.forward(bytes, file, &mut |line, plan, ctx| {
        let Some(mv) = plan.mv else {
            return;
        };
        if waiting {
            if let Some(c) = seen.last_mut() {
                c.next = Some((mv, *ctx));
            }
            waiting = false;
        }
        if let Some(corner) = plan.corner {
            let line = numbers
                .and_then(|n| n.get(line.wrapping_sub(1)).copied())
                .unwrap_or(line);
            seen.push(SeenCorner {
                line,
                corner,
                first: (mv, *ctx),
                next: None,
            });
            waiting = true;
        }
    });
    (seen, done.err())
}

/// Checks the corners the control makes from the compensated program
/// `output` against those it makes from the programmed lines of `input`
/// (see the module comment); each that misses by more than the tolerance
/// is a warning of `summary`.
fn check_corners(
    job: &Job,
    input: (&[u8], Option<&[usize]>),
    output: &[u8],
    file: &str,
    summary: &mut Summary,
) -> Result<()> {
    let Some(pred) = &job.predictor else {
        return Ok(());
    };
    let (programmed, error) = corners_of(job, input, file);
    if let Some(e) = error {
        return Err(e);
    }
    let out_stream;
    let (written, error) = match subprograms::expand(output, "output")? {
        Some(exp) => {
            out_stream = exp.stream(output).0;
            corners_of(job, (&out_stream, None), "output")
        }
        None => corners_of(job, (output, None), "output"),
    };
    // The pass over the output stops at a corner its lines do not make.
    let failed = error.map(|e| (written.len().saturating_sub(1), e));
    let tol = job.settings.tolerance_mm;
    for (k, (p, w)) in programmed.iter().zip(&written).enumerate() {
        let miss = match &failed {
            Some((at, _)) if k >= *at => None,
            _ => corner_miss(pred, p, w),
        };
        let message = match miss {
            Some(m) if m <= tol => continue,
            Some(m) => format!(
                "the {} the control makes from the compensated lines misses its programmed path by {m:.4} mm (tolerance {tol} mm)",
                corner_name(&p.corner)
            ),
            None => format!(
                "the {} could not be checked: the compensated lines do not make it ({})",
                corner_name(&p.corner),
                failed
                    .as_ref()
                    .map_or("no G1 line after it".to_string(), |(_, e)| e.to_string())
            ),
        };
        tracing::warn!("{file}:{}: {message}", p.line);
        summary.warnings.push(Warning {
            line: p.line,
            message,
            count: 1,
            left: None,
        });
    }
    Ok(())
}

/// `chamfer ,C2` or `round ,R5` (mm).
fn corner_name(c: &Corner) -> String {
    match c.kind {
        CornerKind::Chamfer => format!("chamfer of {} mm (`,C`)", c.size_mm),
        CornerKind::Round => format!("round of radius {} mm (`,R`)", c.size_mm),
    }
}

/// One piece of the path a control makes of a corner.
#[derive(Debug, Clone, Copy)]
enum Piece {
    /// A straight line.
    Line(Vector3<f64>, Vector3<f64>),
    /// An arc about `centre` of radius `r` from `centre + r·e1` towards
    /// `centre + r·e2`, through the angle between them.
    Arc {
        centre: Vector3<f64>,
        r: f64,
        e1: Vector3<f64>,
        e2: Vector3<f64>,
        angle: f64,
    },
}

impl Piece {
    /// The point at parameter `s` ∈ [0, 1].
    fn point(&self, s: f64) -> Vector3<f64> {
        match *self {
            Piece::Line(a, b) => a + (b - a) * s,
            Piece::Arc {
                centre,
                r,
                e1,
                e2,
                angle,
            } => {
                let (a, b) = (((1.0 - s) * angle).sin(), (s * angle).sin());
                centre + (e1 * a + e2 * b) * (r / angle.sin())
            }
        }
    }

    /// The distance of `p` from the piece.
    fn distance(&self, p: &Vector3<f64>) -> f64 {
        match *self {
            Piece::Line(a, b) => {
                let d = b - a;
                let t = if d.norm_squared() > 0.0 {
                    ((p - a).dot(&d) / d.norm_squared()).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                (a + d * t - p).norm()
            }
            Piece::Arc {
                centre,
                r,
                e1,
                e2,
                angle,
            } => {
                let n = e1.cross(&e2).normalize();
                let v = p - centre;
                let off = v.dot(&n);
                let inplane = v - n * off;
                let dir = inplane.try_normalize(1e-12);
                let within = dir.is_some_and(|u| {
                    u.dot(&e1).clamp(-1.0, 1.0).acos() <= angle + 1e-12
                        && u.dot(&e2).clamp(-1.0, 1.0).acos() <= angle + 1e-12
                });
                if within {
                    (off * off + (inplane.norm() - r).powi(2)).sqrt()
                } else {
                    (self.point(0.0) - p)
                        .norm()
                        .min((self.point(1.0) - p).norm())
                }
            }
        }
    }
}

/// The three pieces the control makes of the corner at `v` between the
/// line from `a` and the line to `b`: `None` when the lines make no corner
/// of this size (see [`Corner::tangent_distance`]).
fn corner_pieces(
    c: &Corner,
    a: Vector3<f64>,
    v: Vector3<f64>,
    b: Vector3<f64>,
) -> Option<[Piece; 3]> {
    let u1 = (v - a).try_normalize(1e-12)?;
    let u2 = (b - v).try_normalize(1e-12)?;
    let d = c.tangent_distance(&u1, &u2)?;
    if d > (v - a).norm() || d > (b - v).norm() {
        return None;
    }
    let (t1, t2) = (v - u1 * d, v + u2 * d);
    let middle = match c.kind {
        CornerKind::Chamfer => Piece::Line(t1, t2),
        CornerKind::Round => {
            let turn = u1.dot(&u2).clamp(-1.0, 1.0).acos();
            let inward = (u2 - u1).normalize();
            let centre = v + inward * (c.size_mm / (turn / 2.0).cos());
            Piece::Arc {
                centre,
                r: c.size_mm,
                e1: (t1 - centre) / c.size_mm,
                e2: (t2 - centre) / c.size_mm,
                angle: turn,
            }
        }
    };
    Some([Piece::Line(a, t1), middle, Piece::Line(t2, b)])
}

/// The largest distance of the predicted path of the corner the control
/// makes from the written lines `w` from the corner it makes from the
/// programmed lines `p`; `None` when either pair of lines makes no corner.
fn corner_miss(pred: &ToolPredictor, p: &SeenCorner, w: &SeenCorner) -> Option<f64> {
    let pieces = |c: &SeenCorner| {
        let (first, _) = &c.first;
        let (next, _) = c.next.as_ref()?;
        corner_pieces(&c.corner, first.start3(), first.end3(), next.end3())
    };
    let nominal = pieces(p)?;
    let commanded = pieces(w)?;
    let (first, first_ctx) = &w.first;
    let (next, next_ctx) = w.next.as_ref()?;
    let mut dirs = first.dirs;
    let mut worst: f64 = 0.0;
    for (k, piece) in commanded.iter().enumerate() {
        let (mv, ctx) = if k == 2 {
            (next, next_ctx)
        } else {
            (first, first_ctx)
        };
        if k == 2 {
            dirs = next.dirs;
        }
        let at = pred.with_context(*ctx);
        for i in 0..=CORNER_SAMPLES {
            let s = i as f64 / CORNER_SAMPLES as f64;
            let q = piece.point(s);
            // Along the arc each axis moves the way its tangent points.
            let ahead = piece.point((s + 1e-3).min(1.0)) - piece.point((s - 1e-3).max(0.0));
            for (slot, d) in ahead.iter().enumerate() {
                if d.abs() > 1e-12 {
                    dirs[slot] = if *d > 0.0 { 1 } else { -1 };
                }
            }
            let mut cmd = mv.end;
            cmd[..3].copy_from_slice(q.as_slice());
            let tip = at.attained(&cmd, &dirs, mv.tool_len_mm).pos;
            let off = nominal
                .iter()
                .map(|n| n.distance(&tip))
                .fold(f64::INFINITY, f64::min);
            worst = worst.max(off);
        }
    }
    Some(worst)
}
