//! `wlnavd`: parses the command line, loads the configuration, runs the daemon.
//! See `daemon/README.md`.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use wlnavd::config::{CanBackend, Config, CostKind, WeightsConfig};
use wlnavd::logging::{self, LogTarget};
use wlnavd::{RunOptions, ShutdownHandle};

/// The wlnav controller daemon: 5 Hz actor-critic MPC for an articulated wheel loader.
#[derive(Debug, Parser)]
#[command(name = "wlnavd", version)]
struct Args {
    /// Configuration file (TOML). Without it the built-in defaults are used: the
    /// simulated machine, prefix `wlnav`, weights from critic-weights/avant635/.
    #[arg(short, long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Run against the built-in simulated machine (sets can.backend = "sim").
    #[arg(long)]
    sim: bool,
    /// iceoryx2 service-name prefix (overrides ipc.prefix).
    #[arg(long, value_name = "PREFIX")]
    prefix: Option<String>,
    /// Daemon seconds per real second, simulated machine only (overrides sim.time_scale).
    #[arg(long, value_name = "K")]
    time_scale: Option<f64>,
    /// MPC stage cost (overrides controller.cost): the trained critic, or a quadratic
    /// bring-up cost that needs no weights.
    #[arg(long, value_enum, value_name = "COST")]
    cost: Option<CostArg>,
    /// Directory holding critic.safetensors and actor.safetensors (overrides weights.*),
    /// e.g. critic-weights/avant635; they must be for the configured machine and mpc.dt.
    #[arg(long, value_name = "DIR")]
    weights_dir: Option<PathBuf>,
    /// The site file (overrides site.file): a wlnav-site-v1 JSON, or a Nav2 map YAML.
    #[arg(long, value_name = "FILE")]
    site: Option<PathBuf>,
    /// Things that move for the simulated machine's perception (overrides
    /// sim.perception.movers): a movers CSV (DESIGN §18; times after the
    /// daemon's start), published on the live-obstacle service.
    #[arg(long, value_name = "FILE")]
    movers: Option<PathBuf>,
    /// Log every CAN frame to FILE in candump -L format (overrides can.log).
    #[arg(long, value_name = "FILE")]
    can_log: Option<PathBuf>,
    /// Stop the machine and exit after N ticks, printing loop statistics (soak runs).
    #[arg(long, value_name = "N")]
    max_ticks: Option<u64>,
    /// Validate the configuration and the weight files, then exit (0 = valid).
    #[arg(long)]
    check_config: bool,
    /// Print the effective configuration as TOML and exit.
    #[arg(long)]
    print_config: bool,
    /// Where logs go.
    #[arg(long, value_enum, default_value = "auto", value_name = "TARGET")]
    log: LogTarget,
}

#[derive(Debug, Clone, Copy, clap::ValueEnum)]
enum CostArg {
    Critic,
    Quadratic,
}

/// Directories searched for relative weight paths when no configuration file is given.
fn default_bases() -> Vec<PathBuf> {
    let mut bases = Vec::new();
    if let Ok(d) = std::env::current_dir() {
        bases.push(d);
    }
    if let Ok(exe) = std::env::current_exe() {
        // target/{debug,release}/wlnavd → the repository root.
        if let Some(root) = exe
            .parent()
            .and_then(|p| p.parent())
            .and_then(|p| p.parent())
        {
            bases.push(root.to_path_buf());
        }
        // <prefix>/bin/wlnavd → <prefix>/share/wlnav.
        if let Some(prefix) = exe.parent().and_then(|p| p.parent()) {
            bases.push(prefix.join("share/wlnav"));
        }
    }
    bases.push(PathBuf::from("/usr/share/wlnav"));
    bases
}

fn build_config(args: &Args) -> Result<Config, String> {
    let mut config = match &args.config {
        Some(path) => {
            // Paths the file gives are relative to it; the ones it leaves out are found
            // like without a file.
            let mut c = Config::load(path).map_err(|e| e.to_string())?;
            c.resolve_paths(&default_bases());
            c
        }
        None => {
            let mut c = Config::default();
            c.resolve_paths(&default_bases());
            c
        }
    };
    if args.sim {
        config.can.backend = CanBackend::Sim;
    }
    if let Some(p) = &args.prefix {
        config.ipc.prefix = p.clone();
    }
    if let Some(k) = args.time_scale {
        config.sim.time_scale = k;
    }
    if let Some(c) = args.cost {
        config.controller.cost = match c {
            CostArg::Critic => CostKind::Critic,
            CostArg::Quadratic => CostKind::Quadratic,
        };
    }
    if let Some(d) = &args.weights_dir {
        config.weights = WeightsConfig::in_dir(d);
    }
    if let Some(f) = &args.site {
        // Relative to where wlnavd was started, as a shell user expects.
        config.site.file = std::env::current_dir()
            .map(|d| d.join(f))
            .unwrap_or_else(|_| f.clone());
    }
    if let Some(f) = &args.movers {
        config.sim.perception.movers = std::env::current_dir()
            .map(|d| d.join(f))
            .unwrap_or_else(|_| f.clone());
    }
    if let Some(l) = &args.can_log {
        config.can.log = l.clone();
    }
    if let Some(n) = args.max_ticks {
        config.control.max_ticks = n;
    }
    config.adopt_trained_machine();
    // Command-line values are validated like the file's.
    config.validate().map_err(|e| e.to_string())?;
    Ok(config)
}

fn main() -> ExitCode {
    let args = Args::parse();
    let config = match build_config(&args) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("wlnavd: {e}");
            return ExitCode::from(2);
        }
    };
    if args.print_config {
        print!("{}", config.to_toml());
        return ExitCode::SUCCESS;
    }
    if args.check_config {
        if let Some(path) = config.site.path() {
            match wlnavd::site::load(path) {
                Ok(index) => println!("{}", wlnavd::site::describe(&index)),
                Err(e) => {
                    eprintln!("wlnavd: {e}");
                    return ExitCode::from(1);
                }
            }
        }
        return match wlnavd::controller::load_controller(&config) {
            Ok(_) => {
                print!("{}", config.envelope_report());
                println!("wlnavd: configuration, site and weights OK");
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("wlnavd: {e}");
                ExitCode::from(1)
            }
        };
    }
    logging::init(args.log);
    // iceoryx2's own logger warns about its missing optional config file on every
    // start; our own logs report what matters.
    shm_ipc::iceoryx2::prelude::set_log_level(shm_ipc::iceoryx2::prelude::LogLevel::Error);
    let options = RunOptions {
        shutdown: ShutdownHandle::new(),
        handle_signals: true,
        ..Default::default()
    };
    match wlnavd::run(config, options) {
        Ok(report) => {
            if args.max_ticks.is_some() {
                println!("{}", report.summary());
            }
            ExitCode::SUCCESS
        }
        Err(e) => {
            tracing::error!("{e}");
            eprintln!("wlnavd: {e}");
            ExitCode::from(1)
        }
    }
}
