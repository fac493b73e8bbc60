use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    let cli = idrex::cli::Cli::parse();
    idrex::cli::init_tracing(cli.verbose);
    match idrex::cli::run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
