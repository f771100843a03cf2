//! Fuzz target `measured_csv`: see `harness::measured_csv`.
#![no_main]

#[path = "../harness.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| harness::measured_csv(data));
