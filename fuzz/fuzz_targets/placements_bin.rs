#![no_main]
// see verdant::harness::placements_bin for what runs and which promises it checks
libfuzzer_sys::fuzz_target!(|data: &[u8]| verdant::harness::placements_bin(data));
