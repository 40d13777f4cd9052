//! wlnavd, the controller daemon: configuration, CAN, the simulated machine, the
//! 5 Hz control loop with its safety logic, goals and telemetry over iceoryx2,
//! systemd integration. `main.rs` only parses arguments and calls [`daemon::run`].
//!
//! Modules, in data-flow order: [`config`] → [`controller`] (weights, MPC) →
//! [`can`] (codec, buses) / [`sim`] (simulated machine) → [`can_io`] (CAN task) →
//! [`ipc`] (goal server) → [`goal_lifecycle`] (accept, reject, outcomes) →
//! [`control_loop`] (the tick; [`realtime`] scheduling of its thread) → [`notify`] (systemd) →
//! [`daemon`] (wiring). See `daemon/README.md` for the command line and the
//! configuration keys.

pub mod can;
pub mod can_io;
pub mod clock;
pub mod config;
pub mod control_loop;
pub mod controller;
pub mod daemon;
pub mod goal_lifecycle;
pub mod ipc;
pub mod live_input;
pub mod log_limit;
pub mod logging;
pub mod notify;
pub mod pose_gate;
pub mod realtime;
pub mod safety;
pub mod sim;
pub mod site;
pub mod stats;

pub use config::Config;
pub use daemon::{run, DaemonError, RunOptions, RunReport, ShutdownHandle};
