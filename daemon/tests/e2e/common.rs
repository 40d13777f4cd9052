//! Harness: run the daemon in-process against the simulated machine in
//! accelerated time, talk to it through the real iceoryx2 services.

#![allow(dead_code)]

use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use control::MachineParams;
use shm_ipc::{
    Client, GoalReply, GoalRequest, IpcConfig, Obstacle, Pose2, Telemetry, TelemetrySubscriber,
};
use wlnavd::can::DriveMode;
use wlnavd::config::{Config, CostKind};
use wlnavd::controller::ControllerFactory;
use wlnavd::sim::{SimHandle, SimLog};
use wlnavd::{DaemonError, RunOptions, RunReport, ShutdownHandle};

/// Time scale of the e2e tests: 1 real second = 4 daemon seconds (the MPC's solve
/// time, unscaled, must fit in 50 ms of real time even on a busy 2-core machine). On a
/// slower CPU divided by `WLNAV_TIMING_SCALE`: [`time_scale`].
pub const TIME_SCALE: f64 = 4.0;

/// The one factor for wall-clock limits (`WLNAV_TIMING_SCALE`; emulation), and a service
/// prefix no other test (or process) uses: the test kit's.
pub use wlnav_test_kit::{timing_scale, unique_prefix};

/// The daemon's time scale on this CPU: [`TIME_SCALE`] / `WLNAV_TIMING_SCALE`.
pub fn time_scale() -> f64 {
    timing_scale::daemon_time_scale(TIME_SCALE)
}

/// `[mpc] time_budget` for a `wlnavd` started as a process (a `--config` file, or a section
/// appended to one): the default solver budget, also the start-up self-test's, times
/// `WLNAV_TIMING_SCALE`, as [`sim_config`] does in process. Under qemu the unscaled 0.1 s
/// failed the self-test (the daemon exited 1) on a loaded machine.
pub fn budget_toml() -> String {
    format!(
        "\n[mpc]\ntime_budget = {:?}\n",
        timing_scale::secs(Config::default().mpc.time_budget)
    )
}

/// Simulated machine, quadratic MPC (no weights), accelerated time.
pub fn sim_config(name: &str) -> Config {
    let mut c = Config::default();
    c.controller.cost = CostKind::Quadratic;
    c.sim.time_scale = time_scale();
    // The solver's wall-clock budget (also the start-up self-test's) is a timing limit:
    // under qemu two daemons starting at once missed the unscaled 0.1 s and never served.
    c.mpc.time_budget = timing_scale::secs(c.mpc.time_budget);
    c.ipc.prefix = unique_prefix(name);
    c.validate().unwrap();
    c
}

pub struct Running {
    pub shutdown: ShutdownHandle,
    pub thread: Option<std::thread::JoinHandle<Result<RunReport, DaemonError>>>,
    pub sim: SimHandle,
    pub client: Client,
    pub telemetry: TelemetrySubscriber,
    pub config: Config,
}

/// Starts the daemon on its own thread and connects a client.
/// `config` driven by the committed networks of `dir` (a path from the
/// repository's root, e.g. [`control::weights::DEFAULT_DIR`]), with the
/// machine they were trained for.
pub fn with_committed_weights(mut config: Config, dir: &str) -> Config {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    config.controller.cost = CostKind::Critic;
    config.weights = wlnavd::config::WeightsConfig::in_dir(&root.join(dir));
    config.adopt_trained_machine();
    config
}

pub fn start(config: Config, controller: Option<ControllerFactory>) -> Running {
    let shutdown = ShutdownHandle::new();
    let (tx, rx) = tokio::sync::oneshot::channel();
    let options = RunOptions {
        controller,
        shutdown: shutdown.clone(),
        handle_signals: false,
        sim_handle: Some(tx),
    };
    let cfg = config.clone();
    let thread = std::thread::spawn(move || wlnavd::run(cfg, options));
    let sim = rx
        .blocking_recv()
        .expect("daemon started its simulated machine");
    let client = Client::new(&IpcConfig::new(config.ipc.prefix.clone())).unwrap();
    let telemetry = client.subscribe_telemetry().unwrap();
    Running {
        shutdown,
        thread: Some(thread),
        sim,
        client,
        telemetry,
        config,
    }
}

impl Running {
    /// Sends a goal until the daemon accepts it (it rejects goals until its first
    /// pose and machine state arrived).
    pub fn goal(&self, x: f64, y: f64, heading: f64) {
        let deadline = Instant::now() + timing_scale::real(Duration::from_secs(20));
        loop {
            match self
                .client
                .set_goal(Pose2::new(x, y, heading), &[], Duration::from_secs(2))
            {
                Ok(r) if r.is_accepted() => return,
                Ok(r) => assert!(
                    Instant::now() < deadline,
                    "goal rejected: {}",
                    r.reason_text()
                ),
                Err(e) => assert!(Instant::now() < deadline, "goal: {e}"),
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// Sends one goal request (waiting until the daemon has seen its first data, when it
    /// still rejects everything as not ready); its id and the reply.
    pub fn request_goal(&self, goal: Pose2, obstacles: &[Obstacle]) -> (u64, GoalReply) {
        let deadline = Instant::now() + timing_scale::real(Duration::from_secs(20));
        loop {
            let id = self.client.next_request_id();
            let req = GoalRequest::set_goal(id, goal, obstacles).expect("≤ 8 obstacles");
            let reply = self
                .client
                .request(&req, Duration::from_secs(2))
                .expect("reply");
            let starting = !reply.is_accepted()
                && reply.reason_text().contains("stale")
                && Instant::now() < deadline;
            if !starting {
                return (id, reply);
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// Like [`Running::wait_for`], appending every sample seen to `log` (so a test can
    /// check the whole run afterwards); returns the matching sample.
    pub fn record_until(
        &self,
        log: &mut Vec<Telemetry>,
        timeout: Duration,
        what: &str,
        pred: impl FnMut(&Telemetry) -> bool,
    ) -> Telemetry {
        let seen = self.wait_for(timeout, what, pred);
        let last = *seen.last().expect("a sample");
        log.extend(seen);
        last
    }

    /// Telemetry samples until `pred` holds (returns all samples seen, the matching
    /// one last) or the real-time `timeout` (times `WLNAV_TIMING_SCALE`) passes (panics).
    pub fn wait_for(
        &self,
        timeout: Duration,
        what: &str,
        mut pred: impl FnMut(&Telemetry) -> bool,
    ) -> Vec<Telemetry> {
        let deadline = Instant::now() + timing_scale::real(timeout);
        let mut seen = Vec::new();
        loop {
            while let Some(t) = self.telemetry.try_recv().unwrap() {
                seen.push(t);
                if pred(&t) {
                    return seen;
                }
            }
            if Instant::now() > deadline {
                let last = seen
                    .last()
                    .map(|t| (t.tick, t.mode, t.fault_flags, t.state));
                panic!("timed out waiting for {what}; last telemetry {last:?}");
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// Controlled stop and exit; the run's report.
    pub fn stop(mut self) -> RunReport {
        self.shutdown.trigger();
        let report = self
            .thread
            .take()
            .unwrap()
            .join()
            .expect("daemon thread")
            .expect("daemon run");
        check_commands(&report, &self.config.machine);
        report
    }
}

impl Drop for Running {
    fn drop(&mut self) {
        self.shutdown.trigger();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Every command the machine received is finite and inside the configured bounds,
/// and the guard never had to step in.
pub fn check_commands(report: &RunReport, p: &MachineParams) {
    let log = report.sim.as_ref().expect("sim log");
    assert!(!log.commands.is_empty(), "no command received");
    for c in &log.commands {
        let v = &c.command;
        assert!(
            v.beta_dot_cmd.abs() <= p.beta_dot_max + 1e-4 && v.v_cmd.abs() <= p.v_max + 1e-4,
            "command out of bounds at t = {:.2}: {v:?}",
            c.time
        );
    }
    assert_eq!(
        report.commands_clamped, 0,
        "the last-line guard had to clamp"
    );
    assert_eq!(
        log.rejected_commands, 0,
        "the machine rejected command frames"
    );
}

/// After the first command at or after `from` with a stopping mode: the speeds
/// ramp down monotonically within the acceleration limits and reach zero. A
/// stop command is one tick of braking from the last command or from the
/// machine's own velocity, whichever is nearer zero
/// (`control::envelope::stop_command`): a step larger than a tick of the
/// limit is allowed only down to a tick's braking from the machine's speed
/// (the measured state the daemon used is older than the frame: 0.1 of slack).
pub fn check_ramp_down(log: &SimLog, from: usize, p: &MachineParams, dt: f64) {
    let cmds = &log.commands[from..];
    let mut prev = (cmds[0].command.beta_dot_cmd, cmds[0].command.v_cmd);
    let mut reached_zero = prev == (0.0, 0.0);
    for c in &cmds[1..] {
        let now = (c.command.beta_dot_cmd, c.command.v_cmd);
        let (beta_dot, v) = c.velocity;
        assert!(
            now.1.abs() <= prev.1.abs() + 1e-4,
            "speed grew while stopping: {prev:?} -> {now:?}"
        );
        assert!(
            (now.1 - prev.1).abs() <= p.a_max * dt + 1e-3
                || now.1.abs() >= v.abs() - p.a_max * dt - 0.1,
            "deceleration above a_max: {prev:?} -> {now:?} at machine speed {v}"
        );
        assert!(
            (now.0 - prev.0).abs() <= p.beta_ddot_max * dt + 1e-3
                || now.0.abs() >= beta_dot.abs() - p.beta_ddot_max * dt - 0.1,
            "articulation rate change above beta_ddot_max: {prev:?} -> {now:?} at machine rate {beta_dot}"
        );
        assert_ne!(
            c.command.mode,
            DriveMode::Drive,
            "drive command while stopping"
        );
        reached_zero |= now == (0.0, 0.0);
        prev = now;
    }
    assert!(reached_zero, "commands never reached zero: last {prev:?}");
}

/// Index of the first command received at or after daemon time `t` with `mode`.
pub fn first_command(log: &SimLog, t: f64, mode: DriveMode) -> Option<usize> {
    log.commands
        .iter()
        .position(|c| c.time >= t && c.command.mode == mode)
}

/// The samples of `log` that report an outcome.
pub fn outcome_samples(log: &[Telemetry]) -> Vec<&Telemetry> {
    log.iter().filter(|t| t.outcome != 0).collect()
}

/// Asserts that `log` holds every tick between its first and last sample (so an
/// outcome missing from it was never published, not merely unseen).
pub fn assert_every_tick(log: &[Telemetry]) {
    for w in log.windows(2) {
        assert_eq!(
            w[1].tick,
            w[0].tick + 1,
            "telemetry lost between ticks {} and {}",
            w[0].tick,
            w[1].tick
        );
    }
}

/// Asserts that each of `accepted` has exactly one outcome in `log`, that nothing else
/// has one, and that the outcomes are numbered 1, 2, … without gaps or repeats. Returns
/// the outcome sample of each accepted id, in the order given.
pub fn assert_each_ends_once<'a>(log: &'a [Telemetry], accepted: &[u64]) -> Vec<&'a Telemetry> {
    assert_every_tick(log);
    let outcomes = outcome_samples(log);
    for w in outcomes.windows(2) {
        assert_eq!(
            w[1].outcome_seq,
            w[0].outcome_seq + 1,
            "outcome numbers not consecutive: {} then {}",
            w[0].outcome_seq,
            w[1].outcome_seq
        );
    }
    for t in &outcomes {
        assert!(
            accepted.contains(&t.outcome_request_id),
            "outcome for request {} that was never accepted: {}",
            t.outcome_request_id,
            t.outcome_text()
        );
    }
    accepted
        .iter()
        .map(|id| {
            let mine: Vec<&&Telemetry> = outcomes
                .iter()
                .filter(|t| t.outcome_request_id == *id)
                .collect();
            assert_eq!(
                mine.len(),
                1,
                "goal {id}: {} outcome reports ({:?})",
                mine.len(),
                mine.iter()
                    .map(|t| (t.tick, t.outcome, t.outcome_text()))
                    .collect::<Vec<_>>()
            );
            *mine[0]
        })
        .collect()
}

/// A ring of 8 overlapping circles of radius `r` on a circle of radius `ring` around
/// (x, y): a goal at the centre is enclosed.
pub fn ring(x: f64, y: f64, ring: f64, r: f64) -> Vec<Obstacle> {
    (0..8)
        .map(|k| {
            let a = k as f64 * std::f64::consts::FRAC_PI_4;
            Obstacle::new(x + ring * a.cos(), y + ring * a.sin(), r)
        })
        .collect()
}

/// Simulated machine without its built-in localization: the test publishes the poses
/// (the pose service admits one publisher).
pub fn sim_config_external_pose(name: &str) -> Config {
    let mut c = sim_config(name);
    c.sim.publish_pose = false;
    c.validate().unwrap();
    c
}

/// The simulated machine's true pose as a pose estimate stamped `now_ns`.
pub fn true_pose(log: &SimLog, now_ns: u64) -> shm_ipc::PoseEstimate {
    let x = log.true_state;
    shm_ipc::PoseEstimate::new(now_ns, 0, Pose2::new(x[0], x[1], x[2]))
}

/// What an external localization publishes for one sample: the true pose (from the
/// simulated machine), a substitute, or nothing.
pub enum Sample {
    /// Publish this estimate.
    Publish(shm_ipc::PoseEstimate),
    /// Publish nothing this time.
    Skip,
}

/// An external localization on its own thread: every 20 ms (real, times
/// `WLNAV_TIMING_SCALE`: the same period in daemon time as natively, as the daemon's clock
/// is slowed by the factor) it asks `f` what to publish, given the simulated machine's log
/// (true pose, daemon time) and the current `CLOCK_MONOTONIC` time, and publishes it on the
/// daemon's pose service through shared memory. (Unscaled under qemu, 5x the samples per
/// daemon second: enough for the pose gate of that time to re-anchor on a source jumping
/// every 0.5 s within one tick, and `pose_jumping_10_m_every_half_second_stops_the_machine`
/// stopped 2.6 s after the last good pose instead of within 1.2 s. Since then recovery
/// needs consistent samples spanning the pose timeout, whatever the rate: pose_gate.rs.)
pub struct Localization {
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Localization {
    pub fn start(
        prefix: &str,
        sim: SimHandle,
        mut f: impl FnMut(&SimLog, u64) -> Sample + Send + 'static,
    ) -> Self {
        let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let config = IpcConfig::new(prefix.to_owned());
        let client = Client::new(&config).expect("localization client");
        let s = stop.clone();
        let period = timing_scale::real(Duration::from_millis(20));
        let thread = std::thread::spawn(move || {
            while !s.load(Ordering::Relaxed) {
                let log = sim.snapshot();
                if let Sample::Publish(p) = f(&log, shm_ipc::monotonic_now_ns()) {
                    client.publish_pose(&p).expect("publish pose");
                }
                std::thread::sleep(period);
            }
        });
        Self {
            stop,
            thread: Some(thread),
        }
    }
}

impl Drop for Localization {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// [`sim_config`] with a given prefix.
pub fn sim_config_with_prefix(prefix: &str) -> Config {
    let mut c = sim_config("with-prefix");
    c.ipc.prefix = prefix.to_owned();
    c
}

/// `systemd-analyze verify` of `unit` (the repository's unit text) with its `drop_ins`
/// (file name, text) in `wlnavd.service.d/`, `/usr/bin/wlnavd` pointed at the binary under
/// test (verify checks that it exists). Asserts success and no warning about the unit.
/// Returns false (skipped) when systemd-analyze is missing, which CI does not allow.
pub fn assert_systemd_verifies(unit: &str, drop_ins: &[(&str, &str)]) -> bool {
    let tool = ["/usr/bin/systemd-analyze", "/bin/systemd-analyze"]
        .into_iter()
        .find(|p| std::path::Path::new(p).exists());
    let Some(tool) = tool else {
        let ci = std::env::var("CI")
            .map(|v| v == "true" || v == "1")
            .unwrap_or(false);
        assert!(
            !ci,
            "systemd-analyze missing under CI: add `systemd` to scripts/apt-packages.txt"
        );
        eprintln!("SKIPPED: systemd-analyze not installed (apt-get install systemd)");
        return false;
    };
    let dir = tempfile::tempdir().unwrap();
    let copy = dir.path().join("wlnavd.service");
    let bin = env!("CARGO_BIN_EXE_wlnavd");
    std::fs::write(&copy, unit.replace("/usr/bin/wlnavd", bin)).unwrap();
    if !drop_ins.is_empty() {
        std::fs::create_dir(dir.path().join("wlnavd.service.d")).unwrap();
        for (name, text) in drop_ins {
            std::fs::write(dir.path().join("wlnavd.service.d").join(name), text).unwrap();
        }
    }
    let out = std::process::Command::new(tool)
        .arg("verify")
        .arg(&copy)
        .output()
        .unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        out.status.success(),
        "systemd-analyze verify failed:\n{text}"
    );
    assert!(!text.contains("wlnavd.service:"), "warnings:\n{text}");
    true
}
