#![no_main]
//! Fuzz target `log_mat_v73`: see `fuzz/src/targets.rs`.

#[path = "../src/targets.rs"]
#[allow(dead_code)]
mod targets;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    targets::let_caught_panics_unwind();
    targets::log_mat_v73(data);
});
