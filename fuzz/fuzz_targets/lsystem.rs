#![no_main]
// see verdant::harness::lsystem for what runs and which promises it checks
libfuzzer_sys::fuzz_target!(|data: &[u8]| verdant::harness::lsystem(data));
