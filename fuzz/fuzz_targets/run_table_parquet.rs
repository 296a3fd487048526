#![no_main]
//! Fuzz target `run_table_parquet`: see `fuzz/src/targets.rs`.

#[path = "../src/targets.rs"]
#[allow(dead_code)]
mod targets;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    targets::let_caught_panics_unwind();
    targets::run_table_parquet(data);
});
