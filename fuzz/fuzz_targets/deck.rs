//! Fuzz target `deck`: see `harness::deck`.
#![no_main]

#[path = "../harness.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| harness::deck(data));
