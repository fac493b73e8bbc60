//! The `idrex` binary: the command line over the library. Unsafe code is denied but for
//! restoring SIGPIPE's default.
#![deny(unsafe_code)]
use std::process::ExitCode;

use clap::Parser;

#[allow(unsafe_code)]
unsafe extern "C" {
    fn signal(signum: i32, handler: usize) -> usize;
}

#[allow(unsafe_code)] // signal(2)
fn main() -> ExitCode {
    // Die quietly on a closed pipe (`idrex logs show F | head`), as Unix tools do, instead of
    // panicking in println!. SIGPIPE = 13, SIG_DFL = 0 on Linux.
    // SAFETY: restoring the default disposition of a signal, before any thread starts.
    unsafe { signal(13, 0) };
    let cli = idrex::cli::Cli::parse();
    if let Err(e) = idrex::kernels::gemm::Kernel::from_env() {
        eprintln!("error: {e}");
        return ExitCode::FAILURE;
    }
    idrex::cli::init_tracing(cli.verbose);
    match idrex::cli::run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
