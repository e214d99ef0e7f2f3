//! cargo-fuzz target: the whole repair on a small mesh built from the bytes (a grid
//! with faces removed and vertices moved, or a free triangle soup); the result must
//! validate and keep the input vertices bit-exact. See fuzz/README.md.
#![no_main]

#[path = "../common.rs"]
mod common;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    common::check_repair(data);
});
