//! Fuzz target `dicom`: see `harness::dicom`.
#![no_main]

#[path = "../harness.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| harness::dicom(data));
