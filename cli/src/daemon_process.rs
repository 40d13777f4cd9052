//! Starting and stopping a `wlnavd` child process: used by `wlnav demo` and the end-to-end
//! tests. The daemon is found next to the running executable (where `cargo build` puts both
//! binaries), then on `PATH`; it gets its own service-name prefix and is stopped with SIGTERM
//! (its controlled-stop path), SIGKILL only if it does not exit in time.

use std::ffi::OsString;
use std::fs::File;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use anyhow::{bail, Context};

use shm_ipc::TelemetrySubscriber;
use shm_ipc::{Mode, Telemetry};

/// Name of the daemon binary.
pub const WLNAVD: &str = "wlnavd";

/// Finds `wlnavd`: `explicit` if given, else next to the current executable (also one
/// level up, for test executables under `target/<profile>/deps/`), else on `PATH`.
pub fn locate_wlnavd(explicit: Option<&Path>) -> anyhow::Result<PathBuf> {
    if let Some(p) = explicit {
        if p.is_file() {
            return Ok(p.to_path_buf());
        }
        bail!("{} does not exist or is not a file", p.display());
    }
    let exe = std::env::current_exe().context("cannot find the current executable")?;
    let mut tried = Vec::new();
    if let Some(dir) = exe.parent() {
        for d in [Some(dir), dir.parent()].into_iter().flatten() {
            let candidate = d.join(WLNAVD);
            if candidate.is_file() {
                return Ok(candidate);
            }
            tried.push(d.display().to_string());
        }
    }
    if let Some(path) = std::env::var_os("PATH") {
        for d in std::env::split_paths(&path) {
            let candidate = d.join(WLNAVD);
            if candidate.is_file() {
                return Ok(candidate);
            }
        }
    }
    bail!(
        "{WLNAVD} not found next to {} (looked in {}) nor on PATH; build it with \
         `cargo build --release -p daemon` (or `-p daemon` without --release for a debug build)",
        exe.display(),
        tried.join(", ")
    )
}

/// A unique service-name prefix for a private daemon: `{base}-{pid}-{ns}`.
pub fn unique_prefix(base: &str) -> String {
    format!(
        "{base}-{}-{}",
        std::process::id(),
        shm_ipc::monotonic_now_ns() % 1_000_000_000_000
    )
}

/// A running `wlnavd` child. Dropping it stops the daemon (SIGTERM, then SIGKILL).
#[derive(Debug)]
pub struct DaemonProcess {
    child: Option<Child>,
    prefix: String,
    log: Option<PathBuf>,
    binary: PathBuf,
}

impl DaemonProcess {
    /// Starts `binary` with `args` (which must include the prefix the caller will use).
    /// Standard output and error go to `log` if given (created/truncated), else are
    /// inherited.
    pub fn spawn(
        binary: &Path,
        args: &[OsString],
        prefix: &str,
        log: Option<&Path>,
    ) -> anyhow::Result<Self> {
        let mut cmd = Command::new(binary);
        cmd.args(args);
        Self::spawn_command(cmd, prefix, log)
    }

    /// Starts `cmd` (its program, arguments, environment and working directory as the
    /// caller set them; the arguments must include the prefix the caller will use), like
    /// [`DaemonProcess::spawn`]: standard input closed, output to `log` if given.
    pub fn spawn_command(
        mut cmd: Command,
        prefix: &str,
        log: Option<&Path>,
    ) -> anyhow::Result<Self> {
        let binary = PathBuf::from(cmd.get_program());
        cmd.stdin(Stdio::null());
        if let Some(log) = log {
            let out = File::create(log)
                .with_context(|| format!("cannot create the daemon log {}", log.display()))?;
            let err = out.try_clone()?;
            // A log file, not a terminal: no colour escapes (tracing-subscriber honours it).
            cmd.stdout(out).stderr(err).env("NO_COLOR", "1");
        }
        let child = cmd
            .spawn()
            .with_context(|| format!("cannot start {}", binary.display()))?;
        Ok(Self {
            child: Some(child),
            prefix: prefix.to_owned(),
            log: log.map(Path::to_path_buf),
            binary,
        })
    }

    /// `wlnavd --sim --prefix P [--time-scale F] [extra...]`: the built-in simulated
    /// machine, no configuration file.
    pub fn spawn_sim(
        binary: &Path,
        prefix: &str,
        time_scale: Option<f64>,
        extra: &[OsString],
        log: Option<&Path>,
    ) -> anyhow::Result<Self> {
        let mut args: Vec<OsString> = vec!["--sim".into(), "--prefix".into(), prefix.into()];
        if let Some(scale) = time_scale {
            args.push("--time-scale".into());
            args.push(scale.to_string().into());
        }
        args.extend(extra.iter().cloned());
        Self::spawn(binary, &args, prefix, log)
    }

    /// The prefix the daemon serves.
    pub fn prefix(&self) -> &str {
        &self.prefix
    }

    /// The daemon's log file, if its output is captured.
    pub fn log_path(&self) -> Option<&Path> {
        self.log.as_deref()
    }

    /// The binary started.
    pub fn binary(&self) -> &Path {
        &self.binary
    }

    /// The process id.
    pub fn pid(&self) -> Option<u32> {
        self.child.as_ref().map(Child::id)
    }

    /// The exit status if the daemon has already exited.
    pub fn try_wait(&mut self) -> anyhow::Result<Option<ExitStatus>> {
        match self.child.as_mut() {
            Some(c) => Ok(c.try_wait()?),
            None => Ok(None),
        }
    }

    /// The last `lines` lines of the captured log (empty if not captured).
    pub fn log_tail(&self, lines: usize) -> String {
        let Some(path) = &self.log else {
            return String::new();
        };
        let text = std::fs::read_to_string(path).unwrap_or_default();
        let all: Vec<&str> = text.lines().collect();
        all[all.len().saturating_sub(lines)..].join("\n")
    }

    /// Connects a client once the daemon has created its services (a client never creates
    /// them), or fails if the daemon exits, Ctrl-C arrives or `timeout` passes.
    pub fn connect(
        &mut self,
        config: &shm_ipc::IpcConfig,
        timeout: Duration,
    ) -> anyhow::Result<shm_ipc::Client> {
        let start = Instant::now();
        let mut config = config.clone();
        loop {
            match shm_ipc::Client::new(&config) {
                Ok(c) => return Ok(c),
                Err(shm_ipc::IpcError::NotServed { service }) => {
                    if let Some(status) = self.try_wait()? {
                        bail!(
                            "{} exited during start-up ({status}){}",
                            self.binary.display(),
                            self.log_hint()
                        );
                    }
                    if super::signal::requested() {
                        bail!("interrupted while waiting for the daemon");
                    }
                    if start.elapsed() >= timeout {
                        bail!(
                            "{} did not create {service:?} within {:.0} s{}",
                            self.binary.display(),
                            timeout.as_secs_f64(),
                            self.log_hint()
                        );
                    }
                    config.cleanup_stale_nodes = false;
                    std::thread::sleep(Duration::from_millis(20));
                }
                Err(e) => return Err(e.into()),
            }
        }
    }

    /// Waits until the daemon publishes telemetry in a driving-ready mode (idle, tracking or
    /// reached: weights loaded, first solve done, pose and machine state fresh), or fails if
    /// it exits or `timeout` passes. Returns the first such sample.
    pub fn wait_ready(
        &mut self,
        sub: &TelemetrySubscriber,
        timeout: Duration,
    ) -> anyhow::Result<Telemetry> {
        let start = Instant::now();
        let mut last: Option<Telemetry> = None;
        loop {
            if let Some(status) = self.try_wait()? {
                bail!(
                    "{} exited during start-up ({status}){}",
                    self.binary.display(),
                    self.log_hint()
                );
            }
            if super::signal::requested() {
                bail!("interrupted while waiting for the daemon");
            }
            if let Some(t) = sub.recv_timeout(Duration::from_millis(100))? {
                if matches!(t.mode(), Ok(Mode::Idle | Mode::Tracking | Mode::Reached)) {
                    return Ok(t);
                }
                last = Some(t);
            }
            if start.elapsed() >= timeout {
                let seen = match &last {
                    Some(t) => format!(
                        "last telemetry: tick {}, mode {}, faults {}",
                        t.tick,
                        super::view::mode_name(t.mode),
                        super::view::fault_text(t.fault_flags)
                    ),
                    None => "no telemetry at all".to_owned(),
                };
                bail!(
                    "{} did not become ready (idle) within {:.0} s ({seen}){}",
                    self.binary.display(),
                    timeout.as_secs_f64(),
                    self.log_hint()
                );
            }
        }
    }

    fn log_hint(&self) -> String {
        match &self.log {
            Some(p) => format!(
                "; its log ({}) ends with:\n{}",
                p.display(),
                self.log_tail(15)
            ),
            None => String::new(),
        }
    }

    /// Sends SIGTERM and waits up to `grace` for the exit; SIGKILL after that. Returns the
    /// exit status and whether SIGKILL was needed.
    pub fn terminate(&mut self, grace: Duration) -> anyhow::Result<(ExitStatus, bool)> {
        let Some(mut child) = self.child.take() else {
            bail!("the daemon was already stopped");
        };
        if let Some(status) = child.try_wait()? {
            return Ok((status, false));
        }
        let pid = child.id() as libc::pid_t;
        // SAFETY: plain kill(2) on our own child's pid, which has not been reaped yet, so the
        // pid cannot have been reused.
        unsafe {
            libc::kill(pid, libc::SIGTERM);
        }
        let deadline = Instant::now() + grace;
        while Instant::now() < deadline {
            if let Some(status) = child.try_wait()? {
                return Ok((status, false));
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        child.kill()?;
        Ok((child.wait()?, true))
    }
}

impl Drop for DaemonProcess {
    fn drop(&mut self) {
        if self.child.is_some() {
            let _ = self.terminate(Duration::from_secs(5));
        }
    }
}
