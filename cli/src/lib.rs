//! `landing`: the command line of the rooftop landing-site service, callable in-process
//! ([`run`]) so that tests drive it as a user would.
//!
//! Every subcommand talks to a real server through the SDK (`landing-client`) and reads files
//! through their owner (`landing-recording`): `info`, `detect` (a recorded frame or a PLY scan),
//! `replay` (a recording as one stream, optionally written back as MCAP), `loadtest`, `render`
//! (the sites over the camera image and from above, [`render`]), `eval` (the evaluation of
//! `landing-eval` against simulator ground truth), `sites` (the fleet's catalog near a place) and
//! `catalog import` (candidate roofs into the catalog's store, [`catalog`]). Exit codes are in
//! [`exit`].
//!
//! ```
//! # #[tokio::main(flavor = "current_thread")] async fn main() {
//! let mut out = Vec::new();
//! let code = landing_cli::run(["landing", "--version"], &mut out).await;
//! assert_eq!(code, landing_cli::exit::OK);
//! assert!(String::from_utf8(out).unwrap().starts_with("landing "));
//! # }
//! ```

#![forbid(unsafe_code)]

pub mod args;
pub mod catalog;
pub mod commands;
pub mod eval;
pub mod loadtest;
pub mod render;

pub use args::{CliError, exit};
pub use commands::{Cli, execute, run};
