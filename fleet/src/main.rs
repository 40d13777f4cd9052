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
    #[arg(
        long,
        value_name = "HOST:PORT",
        required_unless_present = "check_config"
    )]
    broker: Option<String>,
    /// The manufacturer in topics and headers.
    #[arg(long, required_unless_present = "check_config")]
    manufacturer: Option<String>,
    /// The vehicle's serial number in topics and headers.
    #[arg(long = "serial-number", required_unless_present = "check_config")]
    serial_number: Option<String>,
    /// The daemon's service prefix (wlnavd --prefix).
    #[arg(long, required_unless_present = "check_config")]
    prefix: Option<String>,
    /// Configuration file (TOML; every key optional).
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Check the configuration and the flags given, then exit
    /// (0 = valid) without connecting to anything. The other flags are optional with it.
    #[arg(long)]
    check_config: bool,
}

/// `--broker HOST:PORT` split; the host without IPv6 brackets.
fn broker_address(broker: &str) -> anyhow::Result<(String, u16)> {
    let (host, port) = broker
        .rsplit_once(':')
        .context("--broker must be HOST:PORT")?;
    let port: u16 = port
        .parse()
        .context("--broker: the port must be a number")?;
    let host = host.trim_start_matches('[').trim_end_matches(']');
    anyhow::ensure!(!host.is_empty(), "--broker: empty host");
    Ok((host.to_owned(), port))
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
    let broker = args.broker.as_deref().map(broker_address).transpose()?;
    if let Some(m) = &args.manufacturer {
        topic_level("--manufacturer", m)?;
    }
    if let Some(s) = &args.serial_number {
        topic_level("--serial-number", s)?;
    }
    if let Some(p) = &args.prefix {
        shm_ipc::validate_prefix(p)?;
    }
    let config = match &args.config {
        Some(p) => Config::load(p)?,
        None => Config::default(),
    };
    if args.check_config {
        println!(
            "configuration {} valid: map_id {:?} (the orders' map while wlnavd has no site; \
             with a site, the site's id)",
            args.config
                .as_deref()
                .map_or("(defaults)".into(), |p| p.display().to_string()),
            config.map_id,
        );
        return Ok(());
    }
    // clap requires these without --check-config.
    let ((host, port), manufacturer, serial_number, prefix) =
        match (broker, args.manufacturer, args.serial_number, args.prefix) {
            (Some(b), Some(m), Some(s), Some(p)) => (b, m, s, p),
            _ => unreachable!("clap requires --broker, --manufacturer, --serial-number, --prefix"),
        };
    let options = Options {
        host,
        port,
        identity: Identity {
            manufacturer,
            serial_number,
        },
        prefix,
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
