//! Fuzz target: any bytes as an ABB RAPID module through the parser. Errors
//! are fine; a panic is a bug.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = postproc::program::rapid::parse_module_bytes(data, "fuzz.mod");
});
