//! The `poseboard` binary.

use clap::Parser;

fn main() -> std::process::ExitCode {
    match server::cli::run(server::cli::Cli::parse()) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
