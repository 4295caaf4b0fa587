#![no_main]
// see verdant::harness::placements for what runs and which promises it checks
libfuzzer_sys::fuzz_target!(|data: &[u8]| verdant::harness::placements(data));
