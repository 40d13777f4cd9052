//! `wlnav`: the command-line client of `wlnavd` (see the `wlnav_cli` library).

use clap::Parser;

fn main() -> std::process::ExitCode {
    let cli = wlnav_cli::Cli::parse();
    std::process::ExitCode::from(wlnav_cli::run(cli))
}
