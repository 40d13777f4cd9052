//! `wlnav`: the command-line client of `wlnavd` (see `shm_ipc::cli`).

use clap::Parser;

fn main() -> std::process::ExitCode {
    let cli = shm_ipc::cli::Cli::parse();
    std::process::ExitCode::from(shm_ipc::cli::run(cli))
}
