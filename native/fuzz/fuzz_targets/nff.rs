#![no_main]
//! Arbitrary bytes as an NFF scene; parsed scenes are traced at 4x4 (see the crate docs).

use libfuzzer_sys::fuzz_target;
use ring_tracer_kernel::Format;

fuzz_target!(|data: &[u8]| {
    ring_tracer_fuzz::run(data, Format::Nff);
});
