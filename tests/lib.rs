//! Helpers shared by the end-to-end tests in `tests/tests/`.
//!
//! The tests run the real binaries: `wlnavd --sim` (the daemon with its simulated machine)
//! and `wlnav` (the client CLI), talking over iceoryx2 shared memory. Cargo does not expose
//! another package's binaries to a test (`CARGO_BIN_EXE_*` is per package), so
//! [`binaries`] runs `cargo build -p daemon -p wlnav-cli --bins` once per test process, with
//! the test's own profile and target directory, and returns the paths (a no-op build when
//! they are fresh). Set `WLNAV_E2E_BIN_DIR` to use prebuilt binaries instead.
//!
//! Every daemon gets its own service-name prefix ([`unique_prefix`]), so tests run in
//! parallel, and other people's daemons on the host, never meet.

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;
use std::time::Duration;

use shm_ipc::{Client, IpcConfig, Telemetry, TelemetrySubscriber};
use wlnav_cli::daemon_process::DaemonProcess;

/// The one factor for wall-clock limits of every crate's tests (`WLNAV_TIMING_SCALE`;
/// emulation: scripts/cross-check.sh). [`SimDaemon`] applies it to the daemon's time scale
/// and to its own timeouts; tests apply it to theirs.
pub mod timing_scale;

/// Paths of the two binaries under test.
#[derive(Debug, Clone)]
pub struct Binaries {
    /// `wlnavd`
    pub wlnavd: PathBuf,
    /// `wlnav`
    pub wlnav: PathBuf,
}

/// The repository root (the workspace).
pub fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ has a parent")
        .to_path_buf()
}

/// Builds (once per process) and returns `wlnavd` and `wlnav`.
pub fn binaries() -> &'static Binaries {
    static BINS: OnceLock<Binaries> = OnceLock::new();
    BINS.get_or_init(|| {
        // iceoryx2's "no config file, using defaults" warning is noise in test output.
        shm_ipc::iceoryx2::prelude::set_log_level(shm_ipc::iceoryx2::prelude::LogLevel::Error);
        if let Some(dir) = std::env::var_os("WLNAV_E2E_BIN_DIR") {
            let dir = PathBuf::from(dir);
            return Binaries {
                wlnavd: dir.join("wlnavd"),
                wlnav: dir.join("wlnav"),
            };
        }
        // The test executable is target/<profile>/deps/e2e-<hash>.
        let exe = std::env::current_exe().expect("current exe");
        let profile_dir = exe
            .parent()
            .and_then(Path::parent)
            .expect("test executable under target/<profile>/deps")
            .to_path_buf();
        let target_dir = profile_dir.parent().expect("target dir").to_path_buf();
        let profile = profile_dir
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or("debug")
            .to_owned();
        let bins = Binaries {
            wlnavd: profile_dir.join("wlnavd"),
            wlnav: profile_dir.join("wlnav"),
        };
        // `cargo test --workspace` has already built both (daemon and wlnav-cli have
        // integration tests); a nested build with a different package selection could
        // unify features differently and rebuild half the dependency tree for nothing.
        if fresh(&bins.wlnavd) && fresh(&bins.wlnav) {
            return bins;
        }
        let cargo = std::env::var_os("CARGO").unwrap_or_else(|| OsString::from("cargo"));
        let mut cmd = Command::new(cargo);
        cmd.current_dir(repo_root())
            .args(["build", "-p", "daemon", "-p", "wlnav-cli", "--bins"])
            .env("CARGO_TARGET_DIR", &target_dir);
        match profile.as_str() {
            "debug" => {}
            "release" => {
                cmd.arg("--release");
            }
            other => {
                cmd.args(["--profile", other]);
            }
        }
        eprintln!("e2e: building the binaries: {cmd:?}");
        let status = cmd.status().expect("run cargo build");
        assert!(status.success(), "cargo build of wlnavd and wlnav failed");
        bins
    })
}

/// True if `binary` exists and is newer than every source it is built from (the sources of
/// `daemon`, `shm-ipc`, `cli` and `control`, their manifests and the lock file).
fn fresh(binary: &Path) -> bool {
    let Ok(built) = std::fs::metadata(binary).and_then(|m| m.modified()) else {
        return false;
    };
    let root = repo_root();
    let mut newest = std::time::SystemTime::UNIX_EPOCH;
    let mut stack: Vec<PathBuf> = [
        "daemon/src",
        "daemon/can",
        "daemon/Cargo.toml",
        "shm-ipc/src",
        "shm-ipc/Cargo.toml",
        "cli/src",
        "cli/Cargo.toml",
        "control/src",
        "control/Cargo.toml",
        "Cargo.toml",
        "Cargo.lock",
    ]
    .iter()
    .map(|p| root.join(p))
    .collect();
    while let Some(p) = stack.pop() {
        let Ok(meta) = std::fs::metadata(&p) else {
            continue;
        };
        if meta.is_dir() {
            if let Ok(entries) = std::fs::read_dir(&p) {
                stack.extend(entries.flatten().map(|e| e.path()));
            }
        } else if let Ok(m) = meta.modified() {
            newest = newest.max(m);
        }
    }
    built >= newest
}

/// Serializes the daemon tests of one test binary: on a 2-core machine, several daemons
/// plus a 10,000-goal flood in parallel would measure the machine, not the daemon. Hold
/// the guard for the whole test (a panicking test poisons nothing: the lock is recovered).
pub fn serial() -> std::sync::MutexGuard<'static, ()> {
    static LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());
    LOCK.lock().unwrap_or_else(|p| p.into_inner())
}

/// Time scale the tests run the simulated daemon at: fast, yet with its 0.3 s state
/// timeout still 100 ms of wall time, so scheduling hiccups on a loaded host do not look
/// like a dead CAN bus.
pub const FAST: f64 = 3.0;

/// A prefix no other test or process uses: `wlnav-e2e/<test>/<pid>/<ns>`.
pub fn unique_prefix(test: &str) -> String {
    format!(
        "wlnav-e2e/{test}/{}/{}",
        std::process::id(),
        shm_ipc::monotonic_now_ns() % 1_000_000_000_000
    )
}

/// The MPC cost the tests run the daemon with: `WLNAV_E2E_COST` if set, else the trained
/// critic when `critic-weights/avant635/` (the default machine's) holds it, else the quadratic bring-up cost (no weights).
pub fn cost() -> String {
    if let Ok(c) = std::env::var("WLNAV_E2E_COST") {
        return c;
    }
    let w = repo_root().join("critic-weights/avant635");
    if w.join("critic.safetensors").is_file() && w.join("actor.safetensors").is_file() {
        "critic".into()
    } else {
        "quadratic".into()
    }
}

/// A running `wlnavd --sim` with a client and a telemetry subscription on its prefix.
pub struct SimDaemon {
    /// The process (dropping it sends SIGTERM).
    pub process: DaemonProcess,
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
        let log = std::env::temp_dir().join(format!(
            "wlnav-e2e-{test}-{}-{}.log",
            std::process::id(),
            shm_ipc::monotonic_now_ns()
        ));
        let mut args: Vec<OsString> = vec!["--cost".into(), cost().into()];
        args.extend(extra.iter().map(OsString::from));
        // On a slower CPU the solver's wall-clock budget (also the start-up self-test's) is
        // a timing limit too: wlnavd's default mpc.time_budget, 0.1 s, times the factor, in
        // a configuration of its own (only without one of the test's: a test giving
        // --config sets its own budget).
        if timing_scale::factor() > 1.0 && !extra.contains(&"--config") {
            let budget = log.with_extension("toml");
            std::fs::write(
                &budget,
                format!("[mpc]\ntime_budget = {}\n", timing_scale::secs(0.1)),
            )
            .expect("write the budget configuration");
            args.push("--config".into());
            args.push(budget.into());
        }
        let time_scale = timing_scale::daemon_time_scale(time_scale);
        let scale = (time_scale != 1.0).then_some(time_scale);
        let spawn = || {
            DaemonProcess::spawn_sim(&bins.wlnavd, &prefix, scale, &args, Some(&log))
                .expect("spawn wlnavd")
        };
        let mut process = spawn();
        let config = IpcConfig::new(prefix.clone());
        // The daemon creates the services; the client waits for them. A child that has
        // written nothing and served nothing for `silent` never ran: under qemu-user a fork
        // in a multithreaded emulated process can deadlock the child before it executes
        // wlnavd (CI, 2026-12-04: an empty log after 300 s, the suite's other daemons
        // fine). It is started once more, and said so; natively wlnavd logs within
        // milliseconds.
        let limit = timing_scale::real(Duration::from_secs(60));
        let silent = limit / 2;
        let log_is_empty = || std::fs::metadata(&log).map_or(true, |m| m.len() == 0);
        let client = match process.connect(&config, silent) {
            Ok(c) => c,
            // Only a child still running: one that exited silently crashed, and says so below.
            Err(e) if log_is_empty() && matches!(process.try_wait(), Ok(None)) => {
                eprintln!(
                    "wlnavd (pid {:?}) wrote nothing and served nothing in {silent:?}: stopped \
                     and started again ({e:#})",
                    process.pid()
                );
                drop(process);
                process = spawn();
                match process.connect(&config, limit) {
                    Ok(c) => c,
                    Err(e) => panic!("wlnavd did not start (the second time): {e:#}"),
                }
            }
            Err(_) => match process.connect(&config, limit - silent) {
                Ok(c) => c,
                Err(e) => panic!("wlnavd did not start: {e:#}"),
            },
        };
        let telemetry = client.subscribe_telemetry().expect("subscribe");
        let first =
            match process.wait_ready(&telemetry, timing_scale::real(Duration::from_secs(60))) {
                Ok(t) => t,
                Err(e) => panic!("wlnavd did not start: {e:#}"),
            };
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
    pub fn stop(mut self) {
        let (status, killed) = self
            .process
            .terminate(timing_scale::real(Duration::from_secs(10)))
            .expect("terminate");
        assert!(
            !killed && status.success(),
            "wlnavd did not exit cleanly on SIGTERM ({status}, killed: {killed}); log:\n{}",
            self.process.log_tail(20)
        );
    }
}
