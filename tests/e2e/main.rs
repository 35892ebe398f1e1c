//! End-to-end tests: the real `landing-server` on `127.0.0.1:0`, real simulated recordings, and
//! the client SDK and `landing` CLI over loopback gRPC. One binary, a module per topic; most
//! tests go through [`support::check`].

mod support;

mod catalog;
mod cli;
mod detect;
mod errors;
mod eval_catalog;
mod fusion;
mod health_reflection;
mod live_view;
mod malformed;
mod metrics;
mod overload;
mod precision;
mod security;
mod shutdown;
mod stream;
