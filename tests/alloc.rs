//! Hot-path hygiene: heap allocations do not grow with the number of
//! G-code blocks, and by one per RAPID target (its parsed statement, held
//! with the module).
//!
//! The test binary's global allocator counts the allocations (and
//! reallocations) made on the threads that opt in, each into its test's
//! own counter: the test's own thread and the worker threads of a pool
//! built for the test (its start handler opts them in). Other tests running
//! at the same time, these among them, are not counted. A G-code job is run in process on a raster program of `n`
//! and of `2 n` blocks with every effect on; the allocations of the extra
//! `n` blocks, per block, must stay far below one: what allocates is per
//! chunk of 4096 lines or per run of 64 blocks, not per block. RAPID
//! modules of 2000 and 6000 targets are compensated the same way: one
//! allocation per added target (its parsed statement) is left.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::fmt::Write as _;
use std::io::{BufReader, Cursor};
use std::sync::atomic::{AtomicU64, Ordering};

use postproc::compensate::Settings;
use postproc::emit::gcode::EmitOptions;
use postproc::machine::Machine;
use postproc::pipeline::gcode::Job;
use postproc::predict::{EffectSet, ProcessSetup, ToolPredictor};
use postproc::program::interp::Setup;

use crate::common::repo;

/// The system allocator, counting on the threads that opted in.
struct Counting;

thread_local! {
    /// The counter of the test this thread works for, if it counts.
    static COUNTER: Cell<Option<&'static AtomicU64>> = const { Cell::new(None) };
}

fn count() {
    // `try_with`: the allocator also runs while a thread's locals are torn
    // down.
    if let Some(c) = COUNTER.try_with(Cell::get).ok().flatten() {
        c.fetch_add(1, Ordering::Relaxed);
    }
}

// SAFETY: every call is forwarded to `System` with the same arguments; the
// counter has no effect on the memory handed out.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        // SAFETY: the caller's contract is forwarded unchanged.
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        count();
        // SAFETY: as above.
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: as above.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        // SAFETY: as above.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Largest number of allocations per added block: per-run (64 blocks) and
/// per-chunk (4096 lines) buffers give about 1/64 = 0.016; an allocation
/// in every block would give at least 1.
const MAX_ALLOCATIONS_PER_BLOCK: f64 = 0.05;

/// A cutting raster with reversals at every pass (takeup points), a
/// process force and a spindle (thermal source), over several chunks.
fn raster(passes: usize) -> String {
    let mut p = String::from(
        "%\nO2002 (ALLOC)\nG90 G17 G21 G54\nT1 M6\nG43 H1 G0 X0 Y0 Z20\nS6000 M3\n(POSTPROC MILLING DEPTH=2 WIDTH=3)\nG1 Z0 F2000\n",
    );
    let mut y = 0.0f64;
    for n in 0..passes {
        let x = if n % 2 == 0 { 400.0 } else { 0.0 };
        let _ = writeln!(p, "X{x:.3} Y{y:.3}");
        y += 0.01;
        let _ = writeln!(p, "Y{y:.3}");
    }
    p.push_str("M30\n%\n");
    p
}

/// What `f` returns, and the allocations counted into `counter` while it
/// ran (on this thread and on those of [`counting_pool`]`(counter)`).
fn counted<T>(counter: &'static AtomicU64, f: impl FnOnce() -> T) -> (T, u64) {
    COUNTER.with(|c| c.set(Some(counter)));
    let before = counter.load(Ordering::Relaxed);
    let value = f();
    let after = counter.load(Ordering::Relaxed);
    COUNTER.with(|c| c.set(None));
    (value, after - before)
}

/// Two worker threads whose allocations are counted into `counter`.
fn counting_pool(counter: &'static AtomicU64) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .start_handler(move |_| COUNTER.with(|c| c.set(Some(counter))))
        .build()
        .unwrap()
}

/// The counter of the G-code test.
static GCODE_ALLOCATIONS: AtomicU64 = AtomicU64::new(0);

/// The counter of the RAPID test.
static RAPID_ALLOCATIONS: AtomicU64 = AtomicU64::new(0);

/// Allocations counted while compensating `program`, and its blocks.
fn allocations(job: &Job, program: &str) -> (u64, usize) {
    // The output buffer is sized up front: its growth is not the engine's.
    let mut sink: Vec<u8> = Vec::with_capacity(program.len() * 16);
    let input = BufReader::new(Cursor::new(program.as_bytes()));
    let (summary, n) = counted(&GCODE_ALLOCATIONS, || {
        job.run(input, "alloc.nc", Some(&mut sink), None)
    });
    let summary = summary.expect("the job runs");
    assert!(summary.changed > 0, "the program was compensated");
    assert!(sink.len() <= program.len() * 16, "the sink did not grow");
    (n, summary.blocks)
}

#[test]
fn gcode_compensation_does_not_allocate_per_block() {
    let text = std::fs::read_to_string(repo("machines/afm-r1000.yaml")).unwrap();
    let Ok(Machine::Tool(machine)) = Machine::from_yaml_str(&text, "afm-r1000.yaml") else {
        panic!("afm-r1000.yaml is not a machine tool")
    };
    let setup = Setup::for_machine(&machine);
    let process = ProcessSetup::for_machine(&machine);
    assert!(process.force.is_some(), "the example has a force model");
    let pool = counting_pool(&GCODE_ALLOCATIONS);
    let job = Job {
        predictor: Some(ToolPredictor::new(&machine, EffectSet::default()).with_process(&process)),
        setup,
        settings: Settings::default(),
        emit: EmitOptions {
            decimals_mm: Some(4),
            decimals_deg: None,
            annotate: true,
        },
        pool: Some(&pool),
        travel: None,
    };
    // Warm up (lazy statics, the pool's own buffers), then n and 2n blocks.
    allocations(&job, &raster(1000));
    let (a1, b1) = allocations(&job, &raster(10_000));
    let (a2, b2) = allocations(&job, &raster(20_000));
    assert!(b2 > b1 + 19_000, "{b1} and {b2} blocks");
    let per_block = a2.saturating_sub(a1) as f64 / (b2 - b1) as f64;
    assert!(
        per_block < MAX_ALLOCATIONS_PER_BLOCK,
        "{a1} allocations for {b1} blocks, {a2} for {b2}: {per_block:.3} per added block"
    );
}

/// Largest number of allocations per added RAPID target. The module is
/// held whole: each parsed move is one allocation (boxed, because moves
/// held inline would make the statement list large and its growth costs
/// more than the boxes). The edits' texts share one growing buffer and
/// the argument texts (`v200`, `z1`, `tSpindle`) are shared, so nothing
/// else grows with the targets. What the parallel passes allocate depends
/// on how rayon happens to split them (each split makes its own caches):
/// up to about 0.05 per added target either way. The test's module gives
/// 1.0–1.1 per added target; one allocated string per edit would add
/// about two more and fail the bound.
const MAX_ALLOCATIONS_PER_TARGET: f64 = 1.25;

#[test]
fn rapid_compensation_allocates_a_bounded_number_of_times_per_target() {
    use postproc::pipeline::rapid::{RapidOptions, compensate_module};
    let text = std::fs::read_to_string(repo("machines/abb-irb1600.yaml")).unwrap();
    let Ok(Machine::Robot(robot)) = Machine::from_yaml_str(&text, "abb-irb1600.yaml") else {
        panic!("abb-irb1600.yaml is not a robot")
    };
    let module = |n: usize| {
        let mut m = String::from(
            "MODULE Bench\n  PERS tooldata tSpindle := [TRUE,[[0,0,150],[1,0,0,0]],[2,[0,0,70],[1,0,0,0],0.01,0.01,0.004]];\n  PROC main()\n",
        );
        for i in 0..n {
            let x = 650.0 + (i % 40) as f64 * 5.0;
            let y = 50.0 + (i / 40 % 50) as f64 * 2.0;
            let _ = writeln!(
                m,
                "    MoveL [[{x:.1},{y:.1},300.0],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],v200,z1,tSpindle;"
            );
        }
        m.push_str("  ENDPROC\nENDMODULE\n");
        m
    };
    let pool = counting_pool(&RAPID_ALLOCATIONS);
    // Every effect on, annotated, no report records.
    let opts = RapidOptions {
        records: false,
        ..RapidOptions::for_robot(&robot)
    };
    let count = |n: usize| {
        let src = module(n);
        let (r, allocations) = counted(&RAPID_ALLOCATIONS, || {
            pool.install(|| compensate_module(&src, "bench.mod", &robot, &opts))
        });
        let r = r.expect("the module compensates");
        assert_eq!(r.summary.moves, n);
        allocations
    };
    count(200);
    let (a1, a2) = (count(2000), count(6000));
    let per_target = a2.saturating_sub(a1) as f64 / 4000.0;
    assert!(
        per_target < MAX_ALLOCATIONS_PER_TARGET,
        "{a1} allocations for 2000 targets, {a2} for 6000: {per_target:.3} per added target"
    );
}
