//! Fuzz target `label_image`: see `harness::label_image`.
#![no_main]

#[path = "../harness.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| harness::label_image(data));
