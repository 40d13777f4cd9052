//! The `wlnav` command-line client: talk to `wlnavd` over shared memory.
//!
//! The binary (`src/main.rs`) only parses arguments and calls [`run`]; everything else
//! lives here so tests reach it. Subcommands:
//!
//! | command | what it does | exit code |
//! |---|---|---|
//! | `goal X Y HEADING [--obstacle x,y,r]... [--wait]` | send a goal, print the daemon's accept/reject and reason; with `--wait` follow telemetry until the goal's outcome | 0 accepted (succeeded with `--wait`), 1 rejected, 4 no daemon; with `--wait`: 3 aborted, 5 cancelled, 6 preempted, 7 no outcome within `--timeout`, 4 the daemon's telemetry stopped, 130 Ctrl-C |
//! | `cancel`, `stop`, `resume` | drop the goal / controlled stop that latches (`stop` uses the reserved stop service: it gets through when every goal client slot is taken) / release the stop | 0, 1 rejected, 4 no daemon |
//! | `watch [--table] [--count N]` | one line per tick, or a table | 0, 4 no telemetry, 130 Ctrl-C |
//! | `record FILE.mcap [--duration S] [--ticks N]` | telemetry to MCAP (JSON schema, `json` messages: opens in Foxglove) | 0, 130 Ctrl-C (the file is finished either way) |
//! | `demo` | start `wlnavd --sim`, drive a loading cycle, print times, write an SVG | 0 all legs reached, 3 a leg failed, 4 daemon trouble |
//! | `obstacles publish FILE\|- [--rate HZ] [--once] [--duration S]` | publish live obstacle sets from JSON Lines (one set per line) as perception would, each stamped when sent ([`obstacles`]) | 0 done, 1 a bad line (named, nothing published for it), 4 no daemon or another publisher holds the service, 130 Ctrl-C |
//!
//! Usage errors (bad numbers, NaN, malformed `--obstacle`) exit with 2 and name the
//! argument. The global `--prefix` selects the daemon (`wlnavd --prefix`).

pub mod args;
pub mod commands;
pub mod daemon_process;
pub mod demo;
pub mod follow;
pub mod obstacles;
pub mod plot;
pub mod record;
pub mod signal;
pub mod view;

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};

use shm_ipc::Obstacle;
use shm_ipc::{IpcConfig, DEFAULT_PREFIX};

/// Process exit codes of `wlnav` (documented in `--help` and the README).
pub mod exit {
    use super::follow::GoalStatus;
    use shm_ipc::GoalOutcome;

    /// Success: accepted, succeeded, finished.
    pub const OK: u8 = 0;
    /// The daemon rejected the request.
    pub const REJECTED: u8 = 1;
    /// Bad command line (clap's code).
    pub const USAGE: u8 = 2;
    /// The goal was aborted (no-progress, no-route, goal-in-collision, fault, shutdown), or
    /// a demo leg was not reached.
    pub const ABORTED: u8 = 3;
    /// No daemon, no telemetry (the daemon went away), a transport or file error.
    pub const ERROR: u8 = 4;
    /// The goal was cancelled (cancel or stop request).
    pub const CANCELLED: u8 = 5;
    /// A newer goal preempted the goal.
    pub const PREEMPTED: u8 = 6;
    /// No outcome within the time limit (`--timeout`); the goal may still be active.
    pub const TIMED_OUT: u8 = 7;
    /// Interrupted by Ctrl-C / SIGTERM while waiting.
    pub const INTERRUPTED: u8 = 130;

    /// The exit code of `goal --wait` for a final status.
    pub fn for_status(status: &GoalStatus) -> u8 {
        match status {
            GoalStatus::Ended(o) => match o.outcome {
                GoalOutcome::Succeeded => OK,
                GoalOutcome::Cancelled => CANCELLED,
                GoalOutcome::Preempted => PREEMPTED,
                GoalOutcome::Aborted | GoalOutcome::None => ABORTED,
            },
            GoalStatus::NoTelemetry(_) => ERROR,
            GoalStatus::TimedOut(_) | GoalStatus::Pending | GoalStatus::Active => TIMED_OUT,
        }
    }
}

const AFTER_HELP: &str = "\
Exit codes: 0 ok (goal accepted, or succeeded with --wait), 1 rejected by the daemon,
2 bad command line, 3 goal aborted (with --wait; demo: a leg not reached), 4 no daemon,
no telemetry or another error, 5 goal cancelled, 6 goal preempted by a newer one,
7 no outcome within --timeout, 130 interrupted.

Angles are radians unless --deg is given; lengths metres; the pose is the front axle's.";

/// `wlnav`: goals, stop and telemetry for the wlnavd wheel-loader controller.
#[derive(Debug, Parser)]
#[command(name = "wlnav", version, about, after_help = AFTER_HELP)]
pub struct Cli {
    /// Service-name prefix of the daemon (as given to `wlnavd --prefix`) [default: wlnav;
    /// `demo` picks a unique one]
    #[arg(long, global = true, value_parser = args::parse_prefix)]
    pub prefix: Option<String>,

    /// What to do
    #[command(subcommand)]
    pub command: Command,
}

impl Cli {
    /// The IPC settings for the chosen prefix (default `wlnav`).
    pub fn ipc_config(&self) -> IpcConfig {
        IpcConfig::new(
            self.prefix
                .clone()
                .unwrap_or_else(|| DEFAULT_PREFIX.to_owned()),
        )
    }
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Send a goal pose; prints the daemon's accept or reject and its reason
    #[command(allow_negative_numbers = true)]
    Goal(GoalArgs),
    /// Drop the current goal and come to a controlled stop
    Cancel(RequestArgs),
    /// Controlled stop now; latches (goals are rejected) until `resume`
    Stop(RequestArgs),
    /// Release an operator stop: goals are accepted again
    Resume(RequestArgs),
    /// The daemon's site (DESIGN §17)
    #[command(subcommand)]
    Site(SiteCommand),
    /// One telemetry sample: mode, goal, faults, and the site in force
    Status(StatusArgs),
    /// Show telemetry live, one line per tick (or a table with --table)
    Watch(WatchArgs),
    /// Record telemetry to an MCAP file (JSON schema; opens in Foxglove)
    Record(RecordArgs),
    /// Start wlnavd with its simulated machine and drive a loading cycle
    Demo(demo::DemoArgs),
    /// Live obstacles (DESIGN §18): publish sets as a perception stack would
    #[command(subcommand)]
    Obstacles(ObstaclesCommand),
}

/// `wlnav obstacles …`.
#[derive(Debug, Subcommand)]
pub enum ObstaclesCommand {
    /// Publish live obstacle sets from JSON Lines (a FILE, or `-` for standard input)
    #[command(after_help = OBSTACLES_PUBLISH_HELP)]
    Publish(ObstaclesPublishArgs),
}

const OBSTACLES_PUBLISH_HELP: &str = "\
One set per line, e.g.
  {\"obstacles\":[{\"id\":1,\"class\":\"person\",\"circle\":{\"x\":3.0,\"y\":0.0,\"radius\":0.4},\"velocity\":[0.0,1.4]},
                 {\"id\":2,\"polygon\":[[0,0],[2,0],[2,1],[0,1]]}]}
`id` and one of `circle` (x, y, radius: the physical radius [m]) or `polygon` (3 to 8
[x, y] vertices [m], convex, either winding) are required; `class` (unknown, person,
vehicle, machine, static; default unknown) and `velocity` ([vx, vy] m/s, default 0) are
optional; unknown fields are errors; blank lines are skipped. `{\"obstacles\":[]}` says
\"nothing is there\".

Timing: the sets are published in turn, one every 1/RATE s, each stamped when it is
sent (CLOCK_MONOTONIC; the set and all its obstacles). After the last set the last set is
published again at the same rate, with fresh stamps (the daemon stops the machine when
the newest set grows old), until --duration has passed since the first set or Ctrl-C;
with --once the command ends after the last set instead. --duration ends the run early
too, in the middle of the input.

Checks: every line is checked with the daemon's own rules (finite numbers, positive
radius, convex polygons, unique ids, …). A FILE is checked whole before anything is
published: a bad line publishes nothing. Standard input is read as it comes (a quiet
pipe repeats the last set): a bad line ends the run there, after the lines before it.

Exit codes: 0 done, 1 a bad line (its number and the rule are named), 4 no daemon (after
--connect-timeout), another process already publishes obstacles (it is named), or an
I/O error, 130 interrupted.";

/// `wlnav obstacles publish`.
#[derive(Debug, Clone, Args)]
pub struct ObstaclesPublishArgs {
    /// JSON Lines input, one set per line; `-` reads standard input
    #[arg(value_name = "FILE|-")]
    pub file: String,
    /// Sets per second
    #[arg(long, default_value_t = 10.0, value_parser = args::parse_rate)]
    pub rate: f64,
    /// End after the last set of the input instead of repeating it
    #[arg(long)]
    pub once: bool,
    /// End this many seconds after the first set (wall clock); default: at the end of
    /// the input with --once, else at Ctrl-C
    #[arg(long, value_parser = args::parse_seconds)]
    pub duration: Option<f64>,
    /// How long to wait for the daemon to create the obstacle service [s]
    #[arg(long, default_value_t = 5.0, value_parser = args::parse_seconds)]
    pub connect_timeout: f64,
}

/// `wlnav goal`.
#[derive(Debug, Clone, Args)]
pub struct GoalArgs {
    /// Goal x of the front axle [m]
    #[arg(value_parser = args::parse_x, allow_hyphen_values = true)]
    pub x: f64,
    /// Goal y of the front axle [m]
    #[arg(value_parser = args::parse_y, allow_hyphen_values = true)]
    pub y: f64,
    /// Goal heading of the front body [rad, or degrees with --deg], counter-clockwise
    #[arg(value_parser = args::parse_heading, allow_hyphen_values = true)]
    pub heading: f64,
    /// HEADING is in degrees
    #[arg(long)]
    pub deg: bool,
    /// Circular obstacle `x,y,r` [m], radius already inflated by the machine's; up to 8
    #[arg(long = "obstacle", value_name = "x,y,r", value_parser = args::parse_obstacle,
          allow_hyphen_values = true)]
    pub obstacles: Vec<Obstacle>,
    /// Follow telemetry until the daemon reports the goal's outcome; the exit code says
    /// which (0 succeeded, 3 aborted, 5 cancelled, 6 preempted)
    #[arg(long)]
    pub wait: bool,
    /// With --wait: give up after this many seconds (wall clock; exit code 7)
    #[arg(long, default_value_t = 120.0, value_parser = args::parse_seconds)]
    pub timeout: f64,
    /// How long to wait for the daemon's reply [s]
    #[arg(long, default_value_t = 2.0, value_parser = args::parse_seconds)]
    pub reply_timeout: f64,
}

/// `wlnav site …`.
#[derive(Debug, Subcommand)]
pub enum SiteCommand {
    /// Reload the daemon's site file: swapped at a tick boundary; a broken file is
    /// rejected with what is wrong and the old site stays
    Reload(RequestArgs),
}

/// `wlnav status`.
#[derive(Debug, Clone, Args)]
pub struct StatusArgs {
    /// Give up if no telemetry arrives for this long [s]
    #[arg(long, default_value_t = 3.0, value_parser = args::parse_seconds)]
    pub timeout: f64,
}

/// The requests without arguments.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SimpleRequest {
    /// `wlnav cancel`
    Cancel,
    /// `wlnav stop`
    Stop,
    /// `wlnav resume`
    Resume,
    /// `wlnav site reload`
    ReloadSite,
}

impl SimpleRequest {
    /// The subcommand's name.
    pub fn name(self) -> &'static str {
        match self {
            Self::Cancel => "cancel",
            Self::Stop => "stop",
            Self::Resume => "resume",
            Self::ReloadSite => "site reload",
        }
    }
}

/// `wlnav cancel` / `wlnav stop` / `wlnav resume`.
#[derive(Debug, Clone, Args)]
pub struct RequestArgs {
    /// How long to wait for the daemon's reply [s]
    #[arg(long, default_value_t = 2.0, value_parser = args::parse_seconds)]
    pub reply_timeout: f64,
}

/// `wlnav watch`.
#[derive(Debug, Clone, Args)]
pub struct WatchArgs {
    /// Aligned table (header repeated every 20 rows) instead of one long line per tick
    #[arg(long)]
    pub table: bool,
    /// Stop after this many ticks
    #[arg(long)]
    pub count: Option<u64>,
    /// Give up if no telemetry arrives for this long [s]
    #[arg(long, default_value_t = 10.0, value_parser = args::parse_seconds)]
    pub silence_timeout: f64,
}

/// `wlnav record`.
#[derive(Debug, Clone, Args)]
pub struct RecordArgs {
    /// Output file (MCAP); overwritten if it exists
    pub file: PathBuf,
    /// Stop after this many seconds (wall clock); default: until Ctrl-C
    #[arg(long, value_parser = args::parse_seconds)]
    pub duration: Option<f64>,
    /// Stop after this many ticks
    #[arg(long)]
    pub ticks: Option<u64>,
}

/// Runs a parsed command line; returns the process exit code.
pub fn run(cli: Cli) -> u8 {
    // iceoryx2 warns on stderr when it has no config file; a CLI user cannot act on that.
    shm_ipc::iceoryx2::prelude::set_log_level(shm_ipc::iceoryx2::prelude::LogLevel::Error);
    signal::install();
    let result = match &cli.command {
        Command::Goal(a) => commands::goal(&cli, a),
        Command::Cancel(a) => commands::simple_request(&cli, a, SimpleRequest::Cancel),
        Command::Stop(a) => commands::simple_request(&cli, a, SimpleRequest::Stop),
        Command::Resume(a) => commands::simple_request(&cli, a, SimpleRequest::Resume),
        Command::Site(SiteCommand::Reload(a)) => {
            commands::simple_request(&cli, a, SimpleRequest::ReloadSite)
        }
        Command::Status(a) => commands::status(&cli, a),
        Command::Watch(a) => commands::watch(&cli, a),
        Command::Record(a) => record::run(&cli, a),
        Command::Demo(a) => demo::run(&cli, a),
        Command::Obstacles(ObstaclesCommand::Publish(a)) => obstacles::publish(&cli, a),
    };
    match result {
        Ok(code) => code,
        // Ctrl-C during a wait is an interruption, not an error (whatever the wait
        // reported).
        Err(_) if signal::requested() => exit::INTERRUPTED,
        Err(e) => {
            eprintln!("wlnav: error: {e:#}");
            exit::ERROR
        }
    }
}
