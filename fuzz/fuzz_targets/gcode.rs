//! Fuzz target: any bytes as a G-code program through the parser and the
//! modal interpreter (what `postproc check` runs). Errors are fine; a panic
//! is a bug.
#![no_main]

use libfuzzer_sys::fuzz_target;
use postproc::program::gcode::{Block, parse_line};
use postproc::program::interp::{Interpreter, Setup};

fuzz_target!(|data: &[u8]| {
    let mut setup = Setup::default();
    setup.axes = [true; 6];
    let mut interp = Interpreter::new(setup, "fuzz.nc");
    let mut block = Block::default();
    for (i, line) in data.split_inclusive(|&b| b == b'\n').enumerate() {
        if parse_line(line, i + 1, "fuzz.nc", &mut block).is_err() {
            return;
        }
        if interp.step(&block, line).is_err() {
            return;
        }
    }
});
