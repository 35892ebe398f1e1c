//! `landing-server`: `serve`, `check-config` and the offline `detect`. See `landing_server::cli`.

fn main() -> std::process::ExitCode {
    landing_server::cli_main()
}
