//! End-to-end tests of the rooftop landing-site service: the real server (`landing-server`) on
//! `127.0.0.1:0`, frames simulated by `landing-sim` and written as real MCAP recordings, driven
//! through the client SDK (`landing-client`) and the `landing` command line (`landing-cli`). No mocks.
//!
//! The tests are one binary, `tests/e2e/main.rs`, with a module per topic (detect, stream,
//! errors, overload, shutdown, security, health and reflection, cli); `e2e/support.rs` holds the
//! server and scene helpers that most tests go through. Run them with
//! `cargo test -p landing-e2e`. This library itself is empty.
//!
//! ```
//! // The test binary is `e2e`; this crate exports nothing.
//! assert_eq!(env!("CARGO_PKG_NAME"), "landing-e2e");
//! ```

#![forbid(unsafe_code)]
