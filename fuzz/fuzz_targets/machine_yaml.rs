//! Fuzz target: any text as a machine file through the strict loader and
//! validation. Errors are fine; a panic is a bug.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = postproc::machine::Machine::from_yaml_str(text, "fuzz.yaml");
    }
});
