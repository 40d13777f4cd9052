//! The test kit of every crate whose tests start daemons and brokers (issue 44, item 6):
//! `tests/` (the end-to-end crate), the daemon's own integration tests and the fleet
//! tests use it as a dev-dependency.
//!
//! - [`Daemon`]: the one type for a `wlnavd` child process. Its start-up is supervised: a
//!   child that writes nothing and serves nothing for half the start-up limit is named
//!   loudly; under emulation it is stopped and started once more (the only place a child is
//!   ever restarted), natively the test fails ([`daemon`] says why).
//! - [`broker::Broker`]: mosquitto on a free port.
//! - [`controller::Forwarding`]: a controller wrapper that forwards every call of the
//!   daemon's `Controller` trait, for test controllers that change one call.
//! - The shared helpers: [`repo_root`], [`unique_prefix`], [`serial`], [`cost`],
//!   [`binaries`], and [`timing_scale`] (every wall-clock limit of a test is multiplied by
//!   `WLNAV_TIMING_SCALE`).

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::OnceLock;

pub mod broker;
pub mod controller;
pub mod daemon;

/// The one factor for wall-clock limits of every crate's tests (`WLNAV_TIMING_SCALE`;
/// emulation: scripts/cross-check.sh). The file stays at `tests/timing_scale.rs`, where
/// `control`, `shm-ipc` and `examples/` (which cannot depend on this kit) include it too.
#[path = "../../tests/timing_scale.rs"]
pub mod timing_scale;

pub use broker::Broker;
pub use daemon::{emulated, Daemon, DaemonCommand};

/// The repository root (the workspace).
pub fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("test-kit/ has a parent")
        .to_path_buf()
}

/// A service-name prefix no other test or process uses:
/// `wlnav-test/<test>/<pid>/<n>-<ns>` (`n` counts the calls of this process, so two calls
/// in the same nanosecond differ too).
pub fn unique_prefix(test: &str) -> String {
    static N: AtomicU64 = AtomicU64::new(0);
    format!(
        "wlnav-test/{test}/{}/{}-{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed),
        shm_ipc::monotonic_now_ns() % 1_000_000_000_000
    )
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

/// The MPC cost the tests run the daemon with: `WLNAV_E2E_COST` if set, else the trained
/// critic when `critic-weights/avant635/` (the default machine's) holds it, else the
/// quadratic bring-up cost (no weights).
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

/// Paths of the two binaries the tests run.
#[derive(Debug, Clone)]
pub struct Binaries {
    /// `wlnavd`
    pub wlnavd: PathBuf,
    /// `wlnav`
    pub wlnav: PathBuf,
}

/// `wlnavd` and `wlnav` for a test of another package than theirs. Cargo does not expose
/// another package's binaries to a test (`CARGO_BIN_EXE_*` is per package), so this runs
/// `cargo build -p daemon -p wlnav-cli --bins` once per test process, with the test's own
/// profile and target directory, unless both are newer than their sources. Set
/// `WLNAV_E2E_BIN_DIR` to use prebuilt binaries instead (scripts/cross-check.sh: arm64).
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
        // The test executable is target/<profile>/deps/<name>-<hash>.
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
        eprintln!("test kit: building the binaries: {cmd:?}");
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

/// A log file in the temp directory for a child process `what` of this test process.
pub fn log_path(what: &str) -> PathBuf {
    std::env::temp_dir().join(format!(
        "wlnav-test-{}-{}-{}.log",
        what.replace('/', "-"),
        std::process::id(),
        shm_ipc::monotonic_now_ns()
    ))
}

/// The last `lines` lines of the file at `path` (empty if it cannot be read).
pub fn tail(path: &Path, lines: usize) -> String {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let all: Vec<&str> = text.lines().collect();
    all[all.len().saturating_sub(lines)..].join("\n")
}

/// SIGTERM, then SIGKILL after `grace` (times `WLNAV_TIMING_SCALE`); returns whether it
/// exited by itself. The child is reaped either way.
pub fn terminate(child: &mut std::process::Child, grace: std::time::Duration) -> bool {
    if child.try_wait().ok().flatten().is_some() {
        return true;
    }
    // SAFETY: kill(2) on our own unreaped child.
    unsafe {
        libc::kill(child.id() as libc::pid_t, libc::SIGTERM);
    }
    let deadline = std::time::Instant::now() + timing_scale::real(grace);
    while std::time::Instant::now() < deadline {
        if child.try_wait().ok().flatten().is_some() {
            return true;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let _ = child.kill();
    let _ = child.wait();
    false
}

/// Writes `line` to the test process's standard error directly, past the test harness's
/// output capture (which holds `eprintln!` of a passing test back): what a CI log must
/// show even when the test passes (a restarted child).
pub fn loud(line: &str) {
    use std::io::Write;
    let mut err = std::io::stderr().lock();
    let _ = writeln!(err, "{line}");
    let _ = err.flush();
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prefixes_differ_within_one_process() {
        let (a, b) = (unique_prefix("t"), unique_prefix("t"));
        assert_ne!(a, b);
        assert!(a.starts_with(&format!("wlnav-test/t/{}/", std::process::id())));
    }

    #[test]
    fn the_repository_root_holds_the_workspace() {
        assert!(repo_root().join("Cargo.toml").is_file());
        assert!(repo_root().join("tests/timing_scale.rs").is_file());
    }
}
