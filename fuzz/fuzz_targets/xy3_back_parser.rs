#![no_main]
//! Placeholder, replaced by the codec work.
libfuzzer_sys::fuzz_target!(|_data: &[u8]| {});
