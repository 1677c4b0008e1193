//! `ssr-agent`: serve the SSR network over gRPC, train it, benchmark it, show model configs, inspect
//! checkpoints (the command line is [`cli`]).

mod allocator;
mod cli;

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    allocator::keep_freed_memory();
    match cli::run(cli::Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!(
                "error: {}",
                ssrdrive_support::error_text::error_text(&error)
            );
            ExitCode::FAILURE
        }
    }
}
