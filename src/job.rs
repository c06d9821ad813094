//! A G-code job: streams a program through parse → interpret →
//! predict/compensate → emit in bounded chunks.
//!
//! Lines are read in chunks of [`CHUNK_LINES`]; parsing and the modal
//! interpretation run in program order, the per-block prediction and inverse
//! solve run in parallel with rayon (order kept), and the emitter writes the
//! chunk before the next one is read. Memory is bounded by the chunk size,
//! whatever the length of the program.

use std::io::{BufRead, Write};

use rayon::prelude::*;

use crate::compensate::{self, BlockResult, Failure, Settings};
use crate::emit::gcode::{EmitOptions, Emitter};
use crate::error::{Error, Located, Result};
use crate::machine::AxisVec;
use crate::predict::ToolPredictor;
use crate::program::gcode::{Block, parse_line};
use crate::program::interp::{Interpreter, Motion, Plan, PlanKind, Setup, Warning};

/// Lines processed per chunk.
pub const CHUNK_LINES: usize = 4096;

/// Deviation statistics over many blocks with a fixed-size histogram, so the
/// percentile needs no per-block storage.
#[derive(Debug, Clone)]
pub struct DevStats {
    /// Number of values.
    pub count: u64,
    /// Sum of values, mm.
    pub sum: f64,
    /// Largest value, mm.
    pub max: f64,
    /// Line of the largest value.
    pub max_line: usize,
    bins: Vec<u64>,
}

/// Histogram resolution of [`DevStats`], mm.
pub const DEV_BIN_MM: f64 = 1e-5;
const DEV_BINS: usize = 200_000;

impl Default for DevStats {
    fn default() -> Self {
        DevStats {
            count: 0,
            sum: 0.0,
            max: 0.0,
            max_line: 0,
            bins: vec![0; DEV_BINS + 1],
        }
    }
}

impl DevStats {
    /// Adds a value.
    pub fn add(&mut self, v: f64, line: usize) {
        self.count += 1;
        self.sum += v;
        if v > self.max {
            self.max = v;
            self.max_line = line;
        }
        let bin = ((v / DEV_BIN_MM) as usize).min(DEV_BINS);
        self.bins[bin] += 1;
    }

    /// Mean value, mm.
    pub fn mean(&self) -> f64 {
        if self.count == 0 {
            0.0
        } else {
            self.sum / self.count as f64
        }
    }

    /// Percentile `p` in (0, 100] to the histogram resolution (upper bin edge,
    /// capped at the maximum), mm.
    pub fn percentile(&self, p: f64) -> f64 {
        if self.count == 0 {
            return 0.0;
        }
        let want = ((p / 100.0) * self.count as f64).ceil().max(1.0) as u64;
        let mut acc = 0;
        for (i, &n) in self.bins.iter().enumerate() {
            acc += n;
            if acc >= want {
                return ((i + 1) as f64 * DEV_BIN_MM).min(self.max);
            }
        }
        self.max
    }
}

/// What a job did.
#[derive(Debug, Clone, Default)]
pub struct Summary {
    /// Lines read.
    pub lines: usize,
    /// Blocks with words.
    pub blocks: usize,
    /// Moves (rapid, feed, arc, cycle holes).
    pub moves: usize,
    /// Rapid moves.
    pub rapids: usize,
    /// Linear feed moves.
    pub feeds: usize,
    /// Arc moves.
    pub arcs: usize,
    /// Canned-cycle holes.
    pub holes: usize,
    /// Extents of the programmed end points, machine coordinates (min, max).
    pub extents: Option<(AxisVec, AxisVec)>,
    /// Tools used (T numbers made active).
    pub tools: Vec<u32>,
    /// Interpreter warnings.
    pub warnings: Vec<Warning>,
    /// Blocks whose text changed.
    pub changed: usize,
    /// Blocks added by segmentation.
    pub added: usize,
    /// Predicted deviation of the uncompensated program, mm.
    pub deviation: DevStats,
    /// Largest position error left after compensation, mm.
    pub max_residual_mm: f64,
    /// The program is in inches.
    pub inch: bool,
}

/// One per-block row for reports.
#[derive(Debug, Clone)]
pub struct Row {
    /// Source line.
    pub line: usize,
    /// Motion kind label.
    pub motion: &'static str,
    /// Programmed end point, machine coordinates.
    pub commanded: AxisVec,
    /// Compensated end point, machine coordinates.
    pub compensated: AxisVec,
    /// Predicted deviation and breakdown.
    pub result: BlockResult,
}

/// A configured job.
pub struct Job<'m> {
    /// Predictor (machine + effects); `None` only parses and interprets.
    pub predictor: Option<ToolPredictor<'m>>,
    /// Tool table, work offsets and axes.
    pub setup: Setup,
    /// Compensation settings.
    pub settings: Settings,
    /// Output options.
    pub emit: EmitOptions,
    /// Worker threads for the per-block prediction (rayon's global pool when `None`).
    pub pool: Option<&'m rayon::ThreadPool>,
}

fn motion_label(plan: &Plan) -> &'static str {
    match (plan.kind, plan.mv.map(|m| m.motion)) {
        (PlanKind::Cycle { .. }, _) => "cycle",
        (PlanKind::Fixed, _) => "fixed",
        (_, Some(Motion::Rapid)) => "rapid",
        (_, Some(Motion::Linear)) => "feed",
        (_, Some(Motion::ArcCw)) => "arc_cw",
        (_, Some(Motion::ArcCcw)) => "arc_ccw",
        _ => "",
    }
}

impl<'m> Job<'m> {
    /// Runs the job over `input`. With `out`, the (compensated) program is
    /// written; with `rows`, a row per motion block is handed over in order.
    pub fn run<R: BufRead>(
        &self,
        mut input: R,
        file: &str,
        mut out: Option<&mut dyn Write>,
        mut rows: Option<&mut dyn FnMut(Row)>,
    ) -> Result<Summary> {
        let mut interp = Interpreter::new(self.setup.clone(), file);
        let mut emitter = Emitter::new(self.emit);
        let mut summary = Summary::default();
        let mut buf: Vec<u8> = Vec::with_capacity(1 << 20);
        let mut ranges: Vec<(usize, usize)> = Vec::with_capacity(CHUNK_LINES);
        let mut blocks: Vec<Block> = (0..CHUNK_LINES).map(|_| Block::default()).collect();
        let mut plans: Vec<Plan> = Vec::with_capacity(CHUNK_LINES);
        let mut out_buf: Vec<u8> = Vec::with_capacity(1 << 20);
        let mut line_no = 0usize;
        let mut tools: std::collections::BTreeSet<u32> = Default::default();
        let mut clamped = 0u8;
        let mut clamp_warnings: Vec<Warning> = Vec::new();
        let mut eof = false;
        while !eof {
            buf.clear();
            ranges.clear();
            plans.clear();
            while ranges.len() < CHUNK_LINES {
                let start = buf.len();
                let n = input
                    .read_until(b'\n', &mut buf)
                    .map_err(|e| Error::io(file, e))?;
                if n == 0 {
                    eof = true;
                    break;
                }
                ranges.push((start, buf.len()));
            }
            for (i, &(s, e)) in ranges.iter().enumerate() {
                line_no += 1;
                let line = &buf[s..e];
                let block = &mut blocks[i];
                parse_line(line, line_no, file, block)?;
                let plan = interp.step(block, line)?;
                if !block.is_empty() {
                    summary.blocks += 1;
                }
                if let Some(mv) = plan.mv {
                    summary.moves += 1;
                    match (plan.kind, mv.motion) {
                        (PlanKind::Cycle { .. }, _) => summary.holes += 1,
                        (_, Motion::Rapid) => summary.rapids += 1,
                        (_, Motion::Linear) => summary.feeds += 1,
                        _ => summary.arcs += 1,
                    }
                    let (lo, hi) = summary.extents.get_or_insert((mv.end, mv.end));
                    for k in 0..6 {
                        lo[k] = lo[k].min(mv.end[k]);
                        hi[k] = hi[k].max(mv.end[k]);
                    }
                    if mv.tool != 0 {
                        tools.insert(mv.tool);
                    }
                    // Component-error tables are clamped at their ends: say so
                    // once per axis.
                    if let Some(pred) = &self.predictor {
                        let fresh = pred.machine.clamped_axes(&mv.end) & !clamped;
                        for slot in (0..6).filter(|s| fresh & (1 << s) != 0) {
                            let message = format!(
                                "{} axis position {:.3} lies outside its component-error tables; the table end values are used",
                                crate::machine::AXIS_LETTERS[slot] as char,
                                mv.end[slot]
                            );
                            tracing::warn!("{file}:{}: {message}", blocks[i].line_no);
                            clamp_warnings.push(Warning {
                                line: blocks[i].line_no,
                                message,
                                count: 1,
                            });
                        }
                        clamped |= fresh;
                    }
                }
                plans.push(plan);
            }
            summary.lines = line_no;
            let Some(pred) = &self.predictor else {
                if let Some(out) = out.as_deref_mut() {
                    out.write_all(&buf).map_err(|e| Error::io("output", e))?;
                }
                continue;
            };
            // With every effect off the output is the input; a report still
            // wants its rows (of zero deviation).
            let results: Vec<std::result::Result<BlockResult, Failure>> =
                if pred.effects.is_none() && rows.is_none() {
                    Vec::new()
                } else {
                    let work = || {
                        plans
                            .par_iter()
                            .map(|p| compensate::block(pred, p, &self.settings))
                            .collect()
                    };
                    match self.pool {
                        Some(pool) => pool.install(work),
                        None => work(),
                    }
                };
            out_buf.clear();
            for (i, &(s, e)) in ranges.iter().enumerate() {
                let plan = &plans[i];
                let res = match results.get(i) {
                    Some(Ok(r)) => Some(r),
                    Some(Err(f)) => {
                        let ln = blocks[i].line_no;
                        return Err(Error::Unachievable(Located::new(
                            file,
                            ln,
                            1,
                            format!(
                                "{f}: `{}`",
                                String::from_utf8_lossy(crate::program::gcode::strip_eol(
                                    &buf[s..e]
                                ))
                                .trim()
                            ),
                        )));
                    }
                    None => None,
                };
                if let (Some(r), Some(mv)) = (res, plan.mv) {
                    if plan.kind != PlanKind::Pass {
                        let dev = r.deviation.total().norm();
                        summary.deviation.add(dev, blocks[i].line_no);
                        if mv.motion != Motion::Rapid {
                            summary.max_residual_mm = summary.max_residual_mm.max(r.residual_mm);
                        }
                        if let Some(rows) = rows.as_deref_mut() {
                            rows(Row {
                                line: blocks[i].line_no,
                                motion: motion_label(plan),
                                commanded: mv.end,
                                compensated: r.end,
                                result: r.clone(),
                            });
                        }
                    }
                }
                if out.is_some() {
                    emitter.write(
                        &buf[s..e],
                        &blocks[i],
                        plan,
                        if plan.kind == PlanKind::Fixed {
                            None
                        } else {
                            res
                        },
                        &mut out_buf,
                    );
                }
            }
            if let Some(out) = out.as_deref_mut() {
                out.write_all(&out_buf)
                    .map_err(|e| Error::io("output", e))?;
            }
        }
        summary.inch = interp.inch();
        summary.warnings = interp.warnings().to_vec();
        summary.warnings.extend(clamp_warnings);
        summary.tools = tools.into_iter().collect();
        summary.changed = emitter.changed_blocks();
        summary.added = emitter.added_blocks();
        Ok(summary)
    }
}
