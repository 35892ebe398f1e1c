//! `landing`: the command line of the rooftop landing-site service. See `landing --help`.

use std::process::ExitCode;

fn main() -> ExitCode {
    let runtime = match tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
    {
        Ok(r) => r,
        Err(e) => {
            eprintln!("landing: cannot start the async runtime: {e}");
            return ExitCode::from(landing_cli::exit::ERROR);
        }
    };
    let mut stdout = std::io::stdout();
    let code = runtime.block_on(landing_cli::run(std::env::args_os(), &mut stdout));
    ExitCode::from(code)
}
