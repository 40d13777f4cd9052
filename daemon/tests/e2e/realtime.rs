//! Real-time scheduling (`[loop.realtime]`, issue 18): the daemon never fails to start
//! because the system refuses it, and the unit's real-time drop-in is valid.

use std::os::unix::process::CommandExt;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use wlnav_test_kit::repo_root;

use crate::common::{assert_systemd_verifies, budget_toml, timing_scale, unique_prefix};

const BIN: &str = env!("CARGO_BIN_EXE_wlnavd");

/// `wlnavd --sim` with real-time on, in a process that cannot get it: RLIMIT_RTPRIO 0,
/// RLIMIT_MEMLOCK 64 KiB and, when the test runs as root, CAP_SYS_NICE and CAP_IPC_LOCK
/// dropped from the bounding set before exec (so the daemon, still root, lacks them,
/// like the unprivileged `wlnav` user under the unit without its real-time drop-in).
/// It must start, tick and stop normally, and say what was refused and what to change.
#[test]
fn refused_real_time_scheduling_is_a_warning_and_the_daemon_ticks() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("rt.toml");
    let cpu = wlnavd::realtime::allowed_cpus()
        .first()
        .copied()
        .unwrap_or(0);
    std::fs::write(
        &config,
        format!(
            "[loop.realtime]\nenabled = true\npriority = 40\nlock_memory = true\ncpu = {cpu}\n{}",
            budget_toml()
        ),
    )
    .unwrap();
    let prefix = unique_prefix("rt-refused");
    let mut cmd = Command::new(BIN);
    let time_scale = timing_scale::daemon_time_scale(5.0).to_string();
    cmd.args(["--sim", "--cost", "quadratic", "--time-scale", &time_scale])
        .args([
            "--max-ticks",
            "25",
            "--log",
            "terminal",
            "--prefix",
            &prefix,
        ])
        .arg("--config")
        .arg(&config)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    // SAFETY: only async-signal-safe calls (setrlimit, prctl) between fork and exec.
    unsafe {
        cmd.pre_exec(|| {
            let zero = libc::rlimit {
                rlim_cur: 0,
                rlim_max: 0,
            };
            if libc::setrlimit(libc::RLIMIT_RTPRIO, &zero) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            let small = libc::rlimit {
                rlim_cur: 64 * 1024,
                rlim_max: 64 * 1024,
            };
            if libc::setrlimit(libc::RLIMIT_MEMLOCK, &small) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            // Fails with EPERM when not root (no CAP_SETPCAP): then the caps are not
            // ours anyway.
            const CAP_IPC_LOCK: libc::c_ulong = 14;
            const CAP_SYS_NICE: libc::c_ulong = 23;
            libc::prctl(libc::PR_CAPBSET_DROP, CAP_SYS_NICE, 0, 0, 0);
            libc::prctl(libc::PR_CAPBSET_DROP, CAP_IPC_LOCK, 0, 0, 0);
            // Root that could not drop them (no CAP_SETPCAP) would keep them after exec.
            if libc::geteuid() == 0
                && libc::prctl(libc::PR_CAPBSET_READ, CAP_SYS_NICE, 0, 0, 0) == 1
            {
                return Err(std::io::Error::from_raw_os_error(libc::ENOTSUP));
            }
            Ok(())
        });
    }
    let child = match cmd.spawn() {
        Ok(c) => c,
        Err(e) if e.raw_os_error() == Some(libc::ENOTSUP) => {
            eprintln!("SKIPPED: root without CAP_SETPCAP cannot drop CAP_SYS_NICE for the child");
            return;
        }
        Err(e) => panic!("spawn wlnavd: {e}"),
    };
    let started = Instant::now();
    let out = child.wait_with_output().unwrap();
    assert!(started.elapsed() < timing_scale::real(Duration::from_secs(60)));
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "wlnavd failed with real-time refused: {}\n{stderr}",
        out.status
    );
    let ticks: u64 = stdout
        .lines()
        .find_map(|l| l.strip_prefix("ticks "))
        .and_then(|l| l.split(',').next())
        .and_then(|n| n.trim().parse().ok())
        .unwrap_or_else(|| panic!("no tick count in:\n{stdout}"));
    assert!(ticks >= 25, "{ticks} ticks:\n{stdout}");
    // The refusals are warnings that say what to change.
    assert!(
        stderr.contains("SCHED_FIFO priority 40 for the tick thread refused")
            && stderr.contains("LimitRTPRIO=40"),
        "no SCHED_FIFO warning:\n{stderr}"
    );
    assert!(
        stderr.contains("not locking memory") && stderr.contains("LimitMEMLOCK=infinity"),
        "no mlockall warning:\n{stderr}"
    );
    assert!(stderr.contains("normal scheduler"), "{stderr}");
    assert!(!stderr.contains("ERROR"), "{stderr}");
}

/// The shipped real-time drop-in relaxes exactly what the unit forbids, and systemd
/// accepts the unit with it.
#[test]
fn the_real_time_drop_in_is_valid_and_relaxes_the_unit() {
    let root = repo_root();
    let unit = std::fs::read_to_string(root.join("systemd/wlnavd.service")).unwrap();
    let drop_in =
        std::fs::read_to_string(root.join("systemd/wlnavd.service.d/realtime.conf")).unwrap();
    assert!(
        unit.contains("\nRestrictRealtime=yes\n"),
        "the base unit forbids real-time"
    );
    for key in [
        "\nRestrictRealtime=no\n",
        "\nLimitRTPRIO=40\n",
        "\nLimitMEMLOCK=infinity\n",
    ] {
        assert!(drop_in.contains(key), "drop-in lacks {key:?}");
    }
    // The drop-in's priority is the default one.
    assert_eq!(wlnavd::realtime::RealtimeConfig::default().priority, 40);
    assert_systemd_verifies(&unit, &[("realtime.conf", &drop_in)]);
}
