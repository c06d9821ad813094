//! Fuzz target: any bytes as an observation file through the contract
//! reader. Errors are fine; a panic is a bug.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = postproc::calibrate::observations::read_observations(data, "fuzz.csv");
});
