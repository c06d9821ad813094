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

use std::io::{BufRead, Read, Write};

use crate::compensate::outcome::{Row, Summary};
use crate::emit::gcode::EmitOptions;
use crate::emit::subprograms::{Outputs, Written};
use crate::error::{Error, Result};
use crate::pipeline::gcode::Job;
use crate::program::gcode::subprograms;

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
    let Some(exp) = subprograms::expand(&text, file)? else {
        return Ok((job.run(&text[..], file, out, rows)?, None));
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
    out.write_all(&bytes).map_err(|e| Error::io("output", e))?;
    Ok((summary, Some(made)))
}
