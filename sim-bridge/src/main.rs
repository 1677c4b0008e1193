//! The `sim-bridge` command line: evaluate agents on route sets, generate the bundled towns and
//! routes, inspect route sets, and benchmark the simulator.

#![forbid(unsafe_code)]

mod cli;

use clap::Parser;

fn main() -> std::process::ExitCode {
    let args = cli::Cli::parse();
    cli::init_logging(args.verbose);
    match cli::run(args) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", ssrdrive_support::error_text::error_text(&e));
            std::process::ExitCode::FAILURE
        }
    }
}
