//! cargo-fuzz target: the Obj reader on arbitrary bytes (no panic, no hang; a mesh
//! read is checked and, when small, repaired). See fuzz/README.md.
#![no_main]

#[path = "../common.rs"]
mod common;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    common::check_read(holefill::io::Format::Obj, data);
});
