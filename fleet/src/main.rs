//! `wlnav-fleet`: one loader's VDA 5050 link (see the library docs and README, "Fleet link").

use std::path::PathBuf;

use anyhow::Context;
use clap::Parser;
use wlnav_fleet::bridge::{self, Options};
use wlnav_fleet::config::Config;
use wlnav_fleet::order::Identity;

/// VDA 5050 2.0.0 over MQTT for wlnavd: a fleet manager's orders become the daemon's goals.
#[derive(Debug, Parser)]
#[command(name = "wlnav-fleet", version)]
struct Args {
    /// The MQTT broker, HOST:PORT (e.g. localhost:1883).
    #[arg(long, value_name = "HOST:PORT")]
    broker: String,
    /// The manufacturer in topics and headers.
    #[arg(long)]
    manufacturer: String,
    /// The vehicle's serial number in topics and headers.
    #[arg(long = "serial-number")]
    serial_number: String,
    /// The daemon's service prefix (wlnavd --prefix).
    #[arg(long)]
    prefix: String,
    /// Configuration file (TOML; every key optional).
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
}

/// A topic level: non-empty, without `/`, `+`, `#`.
fn topic_level(what: &str, s: &str) -> anyhow::Result<()> {
    anyhow::ensure!(
        !s.is_empty() && !s.contains(['/', '+', '#']) && s.len() <= 128,
        "{what} {s:?} must be one MQTT topic level: 1-128 characters without / + #"
    );
    Ok(())
}

fn main() -> anyhow::Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info".into()),
        )
        .with_ansi(
            std::env::var_os("NO_COLOR").is_none() && std::env::var_os("JOURNAL_STREAM").is_none(),
        )
        .init();
    shm_ipc::iceoryx2::prelude::set_log_level(shm_ipc::iceoryx2::prelude::LogLevel::Error);
    let args = Args::parse();
    let (host, port) = args
        .broker
        .rsplit_once(':')
        .context("--broker must be HOST:PORT")?;
    let port: u16 = port
        .parse()
        .context("--broker: the port must be a number")?;
    anyhow::ensure!(!host.is_empty(), "--broker: empty host");
    topic_level("--manufacturer", &args.manufacturer)?;
    topic_level("--serial-number", &args.serial_number)?;
    shm_ipc::validate_prefix(&args.prefix)?;
    let config = match &args.config {
        Some(p) => Config::load(p)?,
        None => Config::default(),
    };
    // Fail early on a bad site file.
    config.obstacles()?;
    let options = Options {
        host: host
            .trim_start_matches('[')
            .trim_end_matches(']')
            .to_owned(),
        port,
        identity: Identity {
            manufacturer: args.manufacturer,
            serial_number: args.serial_number,
        },
        prefix: args.prefix,
        config,
    };
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    runtime.block_on(async {
        let shutdown = async {
            let mut term =
                tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())
                    .expect("SIGTERM handler");
            tokio::select! {
                _ = term.recv() => {}
                _ = tokio::signal::ctrl_c() => {}
            }
        };
        bridge::run(options, shutdown).await
    })
}
