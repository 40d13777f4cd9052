//! `wlnavd` as a child process of a test, with its start-up supervised.
//!
//! A child that has written nothing to its log and created none of its services after
//! half the start-up limit ([`START_LIMIT`], times `WLNAV_TIMING_SCALE`) is "silent".
//! Natively wlnavd logs within milliseconds, so a silent child is a start-up hang: the test
//! fails at once, saying so and showing what `/proc` says of the child (its state, the
//! kernel function it waits in, its threads, its executable and whether it ever executed
//! wlnavd: a child still running the test's own command line never got past fork).
//!
//! Under emulation (qemu-user) the same child is stopped and started once more, loudly:
//! a line `wlnav-test-kit: RESTARTED ...` on the test process's standard error, past the
//! harness's output capture, which scripts/cross-check.sh counts. The reason is the
//! emulator's fork of a multithreaded emulated process, which can leave the child
//! deadlocked before it executes wlnavd (CI 2026-12-04: daemon_ipc's wlnavd wrote nothing
//! for 300 s; issue 44: the investigation, README "The Jetson").
//!
//! Emulation is detected on the child itself ([`emulated`]): the kernel's
//! `/proc/<pid>/exe` of a process run by qemu-user is the emulator, whether the child
//! already executed the arm64 wlnavd (binfmt_misc hands it to `qemu-aarch64-static`) or
//! is still the fork of an emulated test. A test process cannot ask this of itself:
//! qemu-user answers `/proc/self/exe` with the emulated program. Nothing needs to be set
//! in the environment, and a native child is never restarted whatever the environment
//! says.

use std::ffi::{OsStr, OsString};
use std::ops::{Deref, DerefMut};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Duration;

use shm_ipc::{Client, IpcConfig, Telemetry, TelemetrySubscriber};
use wlnav_cli::daemon_process::DaemonProcess;

use crate::timing_scale;

/// How long wlnavd may take to create its services, and (separately) to become ready,
/// natively; times `WLNAV_TIMING_SCALE`.
pub const START_LIMIT: Duration = Duration::from_secs(60);

/// How long a stopped daemon may take to exit after SIGTERM before SIGKILL, natively.
pub const STOP_GRACE: Duration = Duration::from_secs(10);

/// Children restarted by this test process (emulation only).
static RESTARTS: AtomicU32 = AtomicU32::new(0);

/// How many silent children this test process restarted (always 0 natively).
pub fn restarts() -> u32 {
    RESTARTS.load(Ordering::Relaxed)
}

/// Whether the process `pid` (a child of this process) runs under qemu-user: its
/// executable, as the kernel sees it, is a `qemu-*` emulator. False if it cannot be read.
pub fn emulated(pid: u32) -> bool {
    std::fs::read_link(format!("/proc/{pid}/exe"))
        .ok()
        .and_then(|p| {
            p.file_name()
                .map(|n| n.to_string_lossy().starts_with("qemu-"))
        })
        .unwrap_or(false)
}

/// What `/proc` says of process `pid`: state, wait channel, thread count, executable and
/// command line (one line).
pub fn describe(pid: u32) -> String {
    let read = |f: &str| std::fs::read_to_string(format!("/proc/{pid}/{f}")).ok();
    let state = read("stat")
        .and_then(|s| {
            // "pid (comm) S ...": the state follows the last ')'.
            s.rsplit_once(')')
                .and_then(|(_, rest)| rest.split_whitespace().next().map(str::to_owned))
        })
        .unwrap_or_else(|| "?".into());
    let wchan = read("wchan").unwrap_or_else(|| "?".into());
    let threads = std::fs::read_dir(format!("/proc/{pid}/task"))
        .map(|d| d.count().to_string())
        .unwrap_or_else(|_| "?".into());
    let exe = std::fs::read_link(format!("/proc/{pid}/exe"))
        .map(|p| p.display().to_string())
        .unwrap_or_else(|_| "?".into());
    let cmdline = read("cmdline")
        .map(|c| c.trim_end_matches('\0').replace('\0', " "))
        .unwrap_or_else(|| "?".into());
    format!(
        "/proc/{pid}: state {state}, wchan {wchan}, {threads} thread(s), exe {exe}, \
         command line {cmdline:?}"
    )
}

/// How to start a daemon: program, arguments, environment, its prefix and its log. It
/// runs in the repository root (where wlnavd finds its default weights, as on a machine
/// it finds them in its working directory), standard input closed, output to the log.
#[derive(Debug, Clone)]
pub struct DaemonCommand {
    /// The program.
    pub binary: PathBuf,
    /// Its arguments.
    pub args: Vec<OsString>,
    /// Extra environment variables.
    pub env: Vec<(OsString, OsString)>,
    /// The prefix it serves (must be among the arguments or in its configuration).
    pub prefix: String,
    /// Where its standard output and error go.
    pub log: PathBuf,
    /// What it is, in messages and the log's name.
    pub what: String,
}

impl DaemonCommand {
    /// `binary` with no arguments yet, serving `prefix`, its log in the temp directory.
    pub fn new(binary: &Path, prefix: &str, what: &str) -> Self {
        Self {
            binary: binary.to_path_buf(),
            args: Vec::new(),
            env: Vec::new(),
            prefix: prefix.to_owned(),
            log: crate::log_path(what),
            what: what.to_owned(),
        }
    }

    /// `wlnavd --sim --prefix P [--time-scale K]`: the built-in simulated machine.
    pub fn sim(binary: &Path, prefix: &str, what: &str, time_scale: Option<f64>) -> Self {
        let mut c = Self::new(binary, prefix, what).args(["--sim", "--prefix", prefix]);
        if let Some(k) = time_scale {
            c = c.args(["--time-scale".to_owned(), k.to_string()]);
        }
        c
    }

    /// Adds arguments.
    pub fn args<I, S>(mut self, args: I) -> Self
    where
        I: IntoIterator<Item = S>,
        S: AsRef<OsStr>,
    {
        self.args
            .extend(args.into_iter().map(|a| a.as_ref().to_owned()));
        self
    }

    /// Adds an environment variable.
    pub fn env(mut self, key: impl AsRef<OsStr>, value: impl AsRef<OsStr>) -> Self {
        self.env
            .push((key.as_ref().to_owned(), value.as_ref().to_owned()));
        self
    }

    fn spawn(&self) -> DaemonProcess {
        let mut cmd = Command::new(&self.binary);
        cmd.args(&self.args).current_dir(crate::repo_root());
        for (k, v) in &self.env {
            cmd.env(k, v);
        }
        DaemonProcess::spawn_command(cmd, &self.prefix, Some(&self.log))
            .unwrap_or_else(|e| panic!("{}: cannot start {:?}: {e:#}", self.what, self.binary))
    }
}

/// A running daemon child (dropping it stops it: SIGTERM, SIGKILL after a grace period).
/// Dereferences to the `wlnav` CLI's [`DaemonProcess`] (log, pid, terminate) that
/// `wlnav demo` uses too.
#[derive(Debug)]
pub struct Daemon {
    process: DaemonProcess,
    command: DaemonCommand,
}

impl Daemon {
    /// Starts the daemon and waits (supervised, see the module) until it has created its
    /// services; returns it with a connected client. Panics, with its log, if it does not.
    pub fn start(command: DaemonCommand) -> (Self, Client) {
        Self::start_within(command, timing_scale::real(START_LIMIT))
    }

    /// [`Daemon::start`] with the start-up limit `limit` (already scaled).
    pub fn start_within(command: DaemonCommand, limit: Duration) -> (Self, Client) {
        let config = IpcConfig::new(command.prefix.clone());
        let silent = limit / 2;
        let mut process = command.spawn();
        let client = match process.connect(&config, silent) {
            Ok(c) => c,
            Err(e) if is_silent(&mut process) => {
                let pid = process.pid().expect("a child");
                let what = describe(pid);
                if !emulated(pid) {
                    panic!(
                        "{} (pid {pid}) wrote nothing and served nothing in {silent:?}: a \
                         start-up hang (natively wlnavd logs within milliseconds; a child \
                         still running this test's command line never executed it). {what} \
                         ({e:#})",
                        command.what
                    );
                }
                let n = RESTARTS.fetch_add(1, Ordering::Relaxed) + 1;
                crate::loud(&format!(
                    "wlnav-test-kit: RESTARTED {} (pid {pid}, emulated): it wrote nothing and \
                     served nothing in {silent:?}; stopped and started once more (restart {n} \
                     of this test process). {what}",
                    command.what
                ));
                let _ = process.terminate(Duration::from_secs(2));
                process = command.spawn();
                match process.connect(&config, limit) {
                    Ok(c) => c,
                    Err(e) => {
                        let pid = process.pid().unwrap_or(0);
                        panic!(
                            "{} did not start the second time either: {e:#}; {}",
                            command.what,
                            describe(pid)
                        )
                    }
                }
            }
            Err(_) => match process.connect(&config, limit - silent) {
                Ok(c) => c,
                Err(e) => {
                    let pid = process.pid().unwrap_or(0);
                    panic!("{} did not start: {e:#}; {}", command.what, describe(pid))
                }
            },
        };
        (Self { process, command }, client)
    }

    /// [`Daemon::start`], then waits until it is ready (telemetry in idle, tracking or
    /// reached); returns the subscription (made before it was ready) and the first ready
    /// sample.
    pub fn start_ready(command: DaemonCommand) -> (Self, Client, TelemetrySubscriber, Telemetry) {
        let (mut d, client) = Self::start(command);
        let telemetry = client.subscribe_telemetry().expect("subscribe");
        let first = d.wait_ready(&telemetry);
        (d, client, telemetry, first)
    }

    /// Waits (up to [`START_LIMIT`], scaled) until the daemon publishes a ready sample.
    pub fn wait_ready(&mut self, telemetry: &TelemetrySubscriber) -> Telemetry {
        match self
            .process
            .wait_ready(telemetry, timing_scale::real(START_LIMIT))
        {
            Ok(t) => t,
            Err(e) => panic!("{} did not become ready: {e:#}", self.command.what),
        }
    }

    /// How it was started.
    pub fn command(&self) -> &DaemonCommand {
        &self.command
    }

    /// Its log file.
    pub fn log(&self) -> &Path {
        &self.command.log
    }

    /// The whole log so far.
    pub fn log_text(&self) -> String {
        std::fs::read_to_string(&self.command.log).unwrap_or_default()
    }

    /// SIGTERM and wait up to [`STOP_GRACE`] (scaled); true if it exited by itself with
    /// status 0.
    pub fn stop_cleanly(&mut self) -> bool {
        match self.process.terminate(timing_scale::real(STOP_GRACE)) {
            Ok((status, killed)) => !killed && status.success(),
            Err(_) => false,
        }
    }

    /// Stops it with SIGTERM and asserts a clean exit (status 0 within the grace period).
    pub fn stop(mut self) {
        let (status, killed) = self
            .process
            .terminate(timing_scale::real(STOP_GRACE))
            .expect("terminate");
        assert!(
            !killed && status.success(),
            "{} did not exit cleanly on SIGTERM ({status}, killed: {killed}); log:\n{}",
            self.command.what,
            self.process.log_tail(20)
        );
    }
}

impl Deref for Daemon {
    type Target = DaemonProcess;
    fn deref(&self) -> &DaemonProcess {
        &self.process
    }
}

impl DerefMut for Daemon {
    fn deref_mut(&mut self) -> &mut DaemonProcess {
        &mut self.process
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        if self.process.pid().is_some() {
            let _ = self
                .process
                .terminate(timing_scale::real(Duration::from_secs(5)));
        }
    }
}

/// Still running, and nothing in its log.
fn is_silent(process: &mut DaemonProcess) -> bool {
    let empty = process.log_path().map_or(true, |p| {
        std::fs::metadata(p).map_or(true, |m| m.len() == 0)
    });
    empty && matches!(process.try_wait(), Ok(None))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A host program is not emulated (the kernel's exe of `sleep` is `sleep`, natively
    /// and beside an emulated test alike), and `describe` shows it.
    #[test]
    fn a_host_child_is_not_emulated() {
        let mut child = Command::new("sleep").arg("5").spawn().expect("sleep");
        let pid = child.id();
        // Until exec the child is this test process; the exe settles within moments.
        let deadline = std::time::Instant::now() + timing_scale::real(Duration::from_secs(5));
        while !describe(pid).contains("exe /usr/bin/sleep")
            && !describe(pid).contains("exe /bin/sleep")
        {
            assert!(std::time::Instant::now() < deadline, "{}", describe(pid));
            std::thread::sleep(Duration::from_millis(5));
        }
        assert!(!emulated(pid), "{}", describe(pid));
        let _ = child.kill();
        let _ = child.wait();
    }

    /// A child that writes nothing and serves nothing fails the start, loudly, after half
    /// the limit, when it is not emulated: `sleep` as the "daemon", a 2 s limit.
    #[test]
    fn a_silent_host_child_fails_the_start() {
        let prefix = crate::unique_prefix("silent");
        let cmd = DaemonCommand::new(Path::new("sleep"), &prefix, "silent-sleep").args(["600"]);
        let limit = timing_scale::real(Duration::from_secs(2));
        let started = std::time::Instant::now();
        let outcome = std::panic::catch_unwind(|| Daemon::start_within(cmd, limit));
        let message = match outcome {
            Ok(_) => panic!("a silent child was accepted"),
            Err(p) => p.downcast_ref::<String>().cloned().unwrap_or_default(),
        };
        assert!(
            message.contains("wrote nothing and served nothing") && message.contains("hang"),
            "{message}"
        );
        assert!(message.contains("sleep 600"), "{message}");
        assert!(started.elapsed() < limit, "{:?}", started.elapsed());
        assert_eq!(restarts(), 0);
    }
}
