#![no_main]
// see verdant::harness::gltf for what runs and which promises it checks
libfuzzer_sys::fuzz_target!(|data: &[u8]| verdant::harness::gltf(data));
