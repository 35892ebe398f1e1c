//! Recording reading: any bytes as an MCAP recording give frames or an error, never a panic.
#![no_main]

use std::sync::Once;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // `read_bytes` turns a panic of the mcap crate into an error (it has one: RELIABILITY.md),
    // but libfuzzer-sys's panic hook aborts at the panic itself, before `catch_unwind` returns.
    // A silent hook lets `read_bytes` keep its promise; a panic that escapes it still reaches
    // libfuzzer-sys's own `catch_unwind` and counts as a crash.
    static QUIET: Once = Once::new();
    QUIET.call_once(|| std::panic::set_hook(Box::new(|_| {})));
    let _ = landing_recording::read_bytes(data);
});
