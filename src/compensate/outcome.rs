//! What a compensation run found, per move and in total: the result types
//! that the pipelines fill and the report and summary writers read.
//!
//! Every pipeline fills one [`Summary`] and one [`Row`] per block or motion
//! instruction (a robot move's own part in [`RobotMove`]); a robot module
//! read whole comes back [`Compensated`]: its text, summary and rows.
//! [`DevStats`] keeps the deviation statistics of both without per-block
//! storage.

use crate::compensate::BlockResult;
use crate::machine::AxisVec;
use crate::machine::tool::thermal::Powers;
use crate::predict::Breakdown;
use crate::predict::Wrench;
use crate::program::interp::Warning;

/// The lines a compensated program has beyond its input's, by why they
/// were added.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct AddedLines {
    /// After a takeup point: the move that continues from it (the block's
    /// own line goes to the takeup point), or the move onto one at a
    /// reversal inside an arc.
    pub takeups: usize,
    /// Arcs cut where an axis of their plane reverses, or halved where one
    /// arc cannot follow the correction: the arc lines after the first.
    pub arcs: usize,
    /// Parts of arcs that no arc fits, written as straight chords.
    pub chords: usize,
    /// Straight moves split where the predicted error bends beyond the
    /// tolerance.
    pub splits: usize,
}

/// Deviation statistics over many blocks with a fixed-size histogram, so the
/// percentile needs no per-block storage for values up to 2 mm; the rare
/// larger values are kept exactly. Used by the job summary and the reports.
#[derive(Debug, Clone, PartialEq)]
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
    /// Values beyond the histogram, kept exactly (rare on machine tools,
    /// bounded by the module size on robots).
    large: Vec<f64>,
}

/// The blocks of a program with a written piece predicted beyond the
/// tolerance from the programmed path.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Beyond {
    /// How many blocks.
    pub count: usize,
    /// The largest distance, mm.
    pub max_mm: f64,
    /// Line of the largest distance (0 when none).
    pub max_line: usize,
}

impl Beyond {
    /// Counts a block with a piece `miss_mm` from the path at `line`.
    pub fn add(&mut self, miss_mm: f64, line: usize) {
        self.count += 1;
        if miss_mm > self.max_mm {
            self.max_mm = miss_mm;
            self.max_line = line;
        }
    }
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
            bins: vec![0; DEV_BINS],
            large: Vec::new(),
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
        match self.bins.get_mut((v / DEV_BIN_MM) as usize) {
            Some(b) => *b += 1,
            None => self.large.push(v),
        }
    }

    /// Mean value, mm.
    pub fn mean(&self) -> f64 {
        if self.count == 0 {
            0.0
        } else {
            self.sum / self.count as f64
        }
    }

    /// Percentile `p` in (0, 100], mm: the upper edge of the histogram bin
    /// that holds it (capped at the maximum), or the exact value beyond the
    /// histogram.
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
        let mut large = self.large.clone();
        large.sort_by(f64::total_cmp);
        let k = (want - acc).saturating_sub(1) as usize;
        large.get(k).or(large.last()).copied().unwrap_or(self.max)
    }
}

/// What a job did. A robot run fills `moves` (the motion instructions
/// compensated), `added` (declarations added), `deviation` and `warnings`.
#[derive(Debug, Clone, Default, PartialEq)]
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
    /// What the run warns about, in order (the interpreter's, the job's:
    /// clamped tables, resonances): the one diagnostics channel of every
    /// pipeline.
    pub warnings: Vec<Warning>,
    /// Blocks whose text changed.
    pub changed: usize,
    /// Blocks added by segmentation.
    pub added: usize,
    /// The added blocks by why they were added.
    pub added_by: AddedLines,
    /// Predicted deviation of the uncompensated program, mm.
    pub deviation: DevStats,
    /// The same over the cutting moves only (feeds, arcs and cycle holes;
    /// not rapids, not moves to machine-defined places such as G28), mm.
    pub cutting: DevStats,
    /// Largest position error left after compensation, mm.
    pub max_residual_mm: f64,
    /// Line of the largest position error left (0 when none).
    pub max_residual_line: usize,
    /// Blocks with a written piece predicted beyond the tolerance from the
    /// programmed path (each also warned about with its line), with the
    /// largest such distance, mm.
    pub beyond: Beyond,
    /// The program is in inches.
    pub inch: bool,
    /// Duration of the program on its time line, s (0 when no process
    /// effect is active).
    pub duration_s: f64,
    /// Mean power of the heat sources (spindle, X, Y, Z drives), W.
    pub mean_power_w: Powers,
}

/// One per-block row for reports: the one record of every pipeline. A
/// robot move fills `line`, `motion` (its instruction), `commanded` (its
/// programmed TCP position, world frame, mm) and `robot`; a G-code block
/// everything but `robot`.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    /// Source line.
    pub line: usize,
    /// Motion kind label (a robot's instruction: `MoveL`, `MoveC`, …).
    pub motion: &'static str,
    /// Programmed start point, machine coordinates.
    pub start: AxisVec,
    /// Programmed end point, machine coordinates.
    pub commanded: AxisVec,
    /// Arc geometry of a G2/G3 move (for the report's picture).
    pub arc: Option<crate::program::interp::ArcGeom>,
    /// Compensated end point, machine coordinates.
    pub compensated: AxisVec,
    /// Predicted deviation and breakdown.
    pub result: BlockResult,
    /// A robot move's own part.
    pub robot: Option<RobotMove>,
}

/// What a robot run predicted for one motion instruction beyond what
/// every [`Row`] holds: the robot's part of its report row.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobotMove {
    /// Programmed circle point of a `MoveC`, world frame, mm.
    pub via_mm: Option<[f64; 3]>,
    /// Predicted deviation of the uncompensated target, by effect.
    pub deviation: Breakdown,
    /// Process wrench acting during the move, if any.
    pub wrench: Option<Wrench>,
    /// Estimated duration of the move, s (0 when unknown).
    pub duration_s: f64,
    /// Mean motor power per joint during the move, W.
    pub power_w: [f64; 6],
    /// Effective (thermal) power per joint at the end of the move, W.
    pub thermal_power_w: [f64; 6],
    /// Joints of the programmed target, rad, where the run has them (the
    /// report's U of the move is taken there).
    pub q_rad: Option<[f64; 6]>,
}

/// A program compensated in memory (a robot module read whole): its
/// text, what the run did, and its report rows when they were asked for.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Compensated {
    /// The rewritten program text.
    pub text: String,
    /// What the run did.
    pub summary: Summary,
    /// One row per motion instruction, in source order.
    pub records: Vec<Row>,
}
