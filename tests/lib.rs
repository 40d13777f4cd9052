//! Helpers shared by the end-to-end tests in `tests/tests/`.
//!
//! The tests run the real binaries: `wlnavd --sim` (the daemon with its simulated machine)
//! and `wlnav` (the client CLI), talking over iceoryx2 shared memory. What starts them,
//! and the helpers every test crate shares, are the test kit's (`test-kit/`,
//! `wlnav_test_kit`), re-exported here: [`binaries`] (built once per test process, or
//! `WLNAV_E2E_BIN_DIR`), [`unique_prefix`] (every daemon has its own service-name prefix,
//! so tests run in parallel, and other people's daemons on the host, never meet),
//! [`timing_scale`] and the supervised start-up of [`wlnav_test_kit::Daemon`].

use std::ffi::OsString;
use std::time::Duration;

use shm_ipc::{Client, IpcConfig, Telemetry, TelemetrySubscriber};
use wlnav_test_kit::{Daemon, DaemonCommand};

pub use wlnav_test_kit::{
    binaries, cost, repo_root, serial, timing_scale, unique_prefix, Binaries, FAST,
};

/// A running `wlnavd --sim` with a client and a telemetry subscription on its prefix.
pub struct SimDaemon {
    /// The process (dropping it sends SIGTERM).
    pub process: Daemon,
    /// A client on the daemon's prefix.
    pub client: Client,
    /// A telemetry subscription made before the daemon became ready.
    pub telemetry: TelemetrySubscriber,
    /// The IPC settings (prefix).
    pub config: IpcConfig,
    /// The first ready telemetry sample.
    pub first: Telemetry,
}

impl SimDaemon {
    /// Starts `wlnavd --sim --prefix <unique> --time-scale <scale> --cost <cost()>` and waits
    /// until it is ready (idle). On a slower CPU the daemon's clock runs slower by
    /// `WLNAV_TIMING_SCALE` ([`timing_scale::daemon_time_scale`]). Its log goes to a file in the temp directory, shown on
    /// failure.
    pub fn start(test: &str, time_scale: f64) -> Self {
        Self::start_with(test, time_scale, &[])
    }

    /// Like [`SimDaemon::start`], with extra `wlnavd` arguments.
    pub fn start_with(test: &str, time_scale: f64, extra: &[&str]) -> Self {
        let bins = binaries();
        let prefix = unique_prefix(test);
        let mut args: Vec<OsString> = vec!["--cost".into(), cost().into()];
        args.extend(extra.iter().map(OsString::from));
        let time_scale = timing_scale::daemon_time_scale(time_scale);
        let scale = (time_scale != 1.0).then_some(time_scale);
        let mut command = DaemonCommand::sim(&bins.wlnavd, &prefix, test, scale);
        // On a slower CPU the solver's wall-clock budget (also the start-up self-test's) is
        // a timing limit too: wlnavd's default mpc.time_budget, 0.1 s, times the factor, in
        // a configuration of its own (only without one of the test's: a test giving
        // --config sets its own budget).
        if timing_scale::factor() > 1.0 && !extra.contains(&"--config") {
            let budget = command.log.with_extension("toml");
            std::fs::write(
                &budget,
                format!("[mpc]\ntime_budget = {}\n", timing_scale::secs(0.1)),
            )
            .expect("write the budget configuration");
            args.push("--config".into());
            args.push(budget.into());
        }
        command = command.args(args);
        // Supervised: a silent child fails natively and is restarted once only under
        // emulation (wlnav_test_kit::daemon).
        let (process, client, telemetry, first) = Daemon::start_ready(command);
        let config = IpcConfig::new(prefix);
        Self {
            process,
            client,
            telemetry,
            config,
            first,
        }
    }

    /// The prefix.
    pub fn prefix(&self) -> &str {
        &self.config.prefix
    }

    /// The next telemetry sample, panicking after `timeout` (times `WLNAV_TIMING_SCALE`)
    /// without one.
    pub fn next(&self, timeout: Duration) -> Telemetry {
        let timeout = timing_scale::real(timeout);
        match self.telemetry.recv_timeout(timeout).expect("telemetry") {
            Some(t) => t,
            None => panic!(
                "no telemetry within {timeout:?}; daemon log:\n{}",
                self.process.log_tail(20)
            ),
        }
    }

    /// Stops the daemon with SIGTERM and asserts a clean exit.
    pub fn stop(self) {
        self.process.stop();
    }
}
