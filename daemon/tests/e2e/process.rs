//! Tests of the `wlnavd` binary as a process: signals, exit codes, messages,
//! configuration checks, the systemd unit.

use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use shm_ipc::{Mode, Pose2};
use wlnav_test_kit::{repo_root, Daemon, DaemonCommand};
use wlnavd::can::{CandumpReader, DriveMode, VelocityCommandFrame, VELOCITY_COMMAND_ID};

use crate::common::{
    assert_systemd_verifies, budget_toml, time_scale, timing_scale, unique_prefix,
};

const BIN: &str = env!("CARGO_BIN_EXE_wlnavd");

/// Waits for `child` to exit, up to `timeout` times `WLNAV_TIMING_SCALE`.
fn wait_exit(child: &mut Child, timeout: Duration) -> std::process::ExitStatus {
    let timeout = timing_scale::real(timeout);
    let deadline = Instant::now() + timeout;
    loop {
        if let Some(s) = child.try_wait().unwrap() {
            return s;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            panic!("wlnavd did not exit within {timeout:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn sigterm_stops_the_machine_and_the_stop_is_the_last_frame() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("can.log");
    let config = dir.path().join("wlnavd.toml");
    std::fs::write(&config, budget_toml()).unwrap();
    let prefix = unique_prefix("sigterm");
    let command = DaemonCommand::sim(Path::new(BIN), &prefix, "sigterm", Some(time_scale()))
        .args(["--cost", "quadratic", "--log", "terminal"])
        .args(["--config".as_ref(), config.as_os_str()])
        .args(["--can-log".as_ref(), log.as_os_str()]);
    let (mut daemon, client) = Daemon::start(command);
    let telemetry = client.subscribe_telemetry().unwrap();
    let deadline = Instant::now() + timing_scale::real(Duration::from_secs(30));
    loop {
        assert!(Instant::now() < deadline, "goal never accepted");
        if let Ok(r) = client.set_goal(
            Pose2::new(10.0, 0.0, 0.0),
            &[],
            timing_scale::real(Duration::from_secs(1)),
        ) {
            if r.is_accepted() {
                break;
            }
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let deadline = Instant::now() + timing_scale::real(Duration::from_secs(30));
    'driving: loop {
        assert!(Instant::now() < deadline, "never drove");
        while let Some(t) = telemetry.try_recv().unwrap() {
            if t.mode() == Ok(Mode::Tracking) && t.state.v_f > 0.5 {
                break 'driving;
            }
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    let (status, killed) = daemon
        .terminate(timing_scale::real(Duration::from_secs(30)))
        .unwrap();
    assert!(
        !killed && status.success(),
        "exit status {status:?} (killed: {killed}); log:\n{}",
        daemon.log_tail(20)
    );

    let commands: Vec<VelocityCommandFrame> = CandumpReader::open(&log)
        .unwrap()
        .map(|r| r.unwrap().frame)
        .filter(|f| f.id() == VELOCITY_COMMAND_ID)
        .map(|f| VelocityCommandFrame::decode(&f).unwrap())
        .collect();
    assert!(commands.len() > 10);
    let last = commands.last().unwrap();
    assert_eq!(last.mode, DriveMode::Stop, "last frame: {last:?}");
    assert_eq!((last.beta_dot_cmd, last.v_cmd), (0.0, 0.0));
    // Driving before the signal, then a ramp down within a_max, ending in the stop.
    let first_stop = commands
        .iter()
        .position(|c| c.mode == DriveMode::Stop)
        .unwrap();
    assert!(commands[first_stop - 1].mode == DriveMode::Drive);
    let p = control::MachineParams::default();
    // The first stop command brakes from the last command or the machine's
    // own speed, whichever is lower (`control::envelope::stop_command`; a
    // machine still accelerating towards its command lags it); from there the
    // commands fall by at most a tick at a_max.
    for (k, w) in commands[first_stop - 1..].windows(2).enumerate() {
        assert!(w[1].v_cmd.abs() <= w[0].v_cmd.abs() + 1e-4);
        assert!(k == 0 || (w[1].v_cmd - w[0].v_cmd).abs() <= p.a_max * 0.2 + 1e-3);
        assert_eq!(w[1].mode, DriveMode::Stop);
    }
    for c in &commands {
        assert!(c.v_cmd.abs() <= p.v_max + 1e-4 && c.beta_dot_cmd.abs() <= p.beta_dot_max + 1e-4);
    }
}

fn write_networks(dir: &Path, critic: Option<&[u8]>, machine: control::MachineParams) {
    use control::weights::{encode, random_network, FileDtype, NetworkMetadata, NetworkRole};
    for (role, name) in [
        (NetworkRole::Actor, "actor"),
        (NetworkRole::Critic, "critic"),
    ] {
        let mut meta = NetworkMetadata::new(role, 4);
        meta.machine = machine;
        let w = random_network(meta, &[8, 8], 3);
        let bytes = encode(&w.meta, &w.mlp, FileDtype::F32).unwrap();
        let path = dir.join(format!("{name}.safetensors"));
        match (role, critic) {
            (NetworkRole::Critic, Some(raw)) => std::fs::write(path, raw).unwrap(),
            _ => std::fs::write(path, bytes).unwrap(),
        }
    }
    std::fs::write(
        dir.join("wlnavd.toml"),
        "[weights]\ncritic = \"critic.safetensors\"\nactor = \"actor.safetensors\"\n",
    )
    .unwrap();
}

fn run_with_config(dir: &Path, prefix: &str) -> (std::process::ExitStatus, String) {
    let mut child = Command::new(BIN)
        .arg("--config")
        .arg(dir.join("wlnavd.toml"))
        .args(["--sim", "--log", "terminal", "--prefix", prefix])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let status = wait_exit(&mut child, Duration::from_secs(30));
    let mut err = String::new();
    use std::io::Read;
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut err)
        .unwrap();
    (status, err)
}

#[test]
fn corrupt_weights_exit_nonzero_naming_file_and_problem() {
    let dir = tempfile::tempdir().unwrap();
    write_networks(
        dir.path(),
        Some(b"this is not a safetensors file"),
        control::MachineParams::default(),
    );
    let (status, err) = run_with_config(dir.path(), &unique_prefix("corrupt"));
    assert_eq!(status.code(), Some(1), "{err}");
    let critic = dir.path().join("critic.safetensors");
    assert!(err.contains(&critic.display().to_string()), "{err}");
    assert!(err.contains("not a safetensors file"), "{err}");

    // Non-finite values: the tensor is named.
    let dir = tempfile::tempdir().unwrap();
    {
        use control::weights::{encode, random_network, FileDtype, NetworkMetadata, NetworkRole};
        let mut w = random_network(NetworkMetadata::new(NetworkRole::Critic, 4), &[8, 8], 3);
        let mut layers = w.mlp.layers().to_vec();
        layers[1].weight[5] = f64::NAN;
        w.mlp = control::mlp::Mlp::new(layers).unwrap();
        let bytes = encode(&w.meta, &w.mlp, FileDtype::F64).unwrap();
        write_networks(dir.path(), Some(&bytes), control::MachineParams::default());
    }
    let (status, err) = run_with_config(dir.path(), &unique_prefix("nan"));
    assert_eq!(status.code(), Some(1), "{err}");
    assert!(err.contains("critic.safetensors"), "{err}");
    assert!(
        err.contains("layers.1.weight") && err.contains("non-finite"),
        "{err}"
    );
}

#[test]
fn incompatible_weights_exit_nonzero_naming_the_key() {
    let dir = tempfile::tempdir().unwrap();
    let machine = control::MachineParams {
        v_max: 2.0,
        ..Default::default()
    };
    write_networks(dir.path(), None, machine);
    // Without [machine] the daemon drives the machine the weights were trained for.
    let config = dir.path().join("wlnavd.toml");
    let out = Command::new(BIN)
        .arg("--config")
        .arg(&config)
        .arg("--print-config")
        .output()
        .unwrap();
    let printed = String::from_utf8_lossy(&out.stdout);
    assert!(printed.contains("v_max = 2.0"), "{printed}");
    // A configuration that gives another machine is refused.
    let mut text = std::fs::read_to_string(&config).unwrap();
    text.push_str("[machine]\nv_max = 1.0\n");
    std::fs::write(&config, text).unwrap();
    let (status, err) = run_with_config(dir.path(), &unique_prefix("incompatible"));
    assert_eq!(status.code(), Some(1), "{err}");
    assert!(err.contains("actor.safetensors"), "{err}");
    assert!(
        err.contains("machine.v_max") && err.contains("incompatible"),
        "{err}"
    );
}

#[test]
fn check_config_names_the_bad_key() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.toml");
    std::fs::write(&path, "[loop]\nrate_hz = 7\n").unwrap();
    let out = Command::new(BIN)
        .arg("--config")
        .arg(&path)
        .arg("--check-config")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("`loop.rate_hz`"), "{err}");

    std::fs::write(&path, "[can]\nbakend = \"sim\"\n").unwrap();
    let out = Command::new(BIN)
        .arg("--config")
        .arg(&path)
        .arg("--check-config")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("bakend"), "{err}");

    let out = Command::new(BIN)
        .args(["--check-config", "--cost", "quadratic"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn example_config_is_valid() {
    let path = repo_root().join("systemd/wlnavd.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    let c = wlnavd::Config::from_toml(&text, &path.display().to_string()).unwrap();
    assert_eq!(c.can.backend, wlnavd::config::CanBackend::Socketcan);
    // The machine runs what the evaluation measured: the file states the defaults
    // of the MPC and the safety envelope (DESIGN §14), key for key.
    assert_eq!(c.mpc, control::mpc::MpcSettings::default());
    assert_eq!(c.envelope, control::envelope::EnvelopeSettings::default());
}

#[test]
fn systemd_analyze_verify_accepts_the_unit() {
    let unit = std::fs::read_to_string(repo_root().join("systemd/wlnavd.service")).unwrap();
    assert!(unit.contains("ExecStart=/usr/bin/wlnavd "));
    assert_systemd_verifies(&unit, &[]);
    for key in [
        "Type=notify",
        "WatchdogSec=",
        "Restart=on-failure",
        "AF_CAN",
        "ReadWritePaths=/dev/shm /tmp",
        "NoNewPrivileges=yes",
    ] {
        assert!(unit.contains(key), "unit lacks {key}");
    }
}

#[test]
fn a_config_file_without_weights_finds_the_default_weights() {
    // "Every key is optional": a file that leaves out [weights] behaves like no file.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("wlnavd.toml");
    std::fs::write(&path, "[loop]\npose_timeout = 0.5\n").unwrap();
    let out = Command::new(BIN)
        .current_dir(repo_root())
        .arg("--config")
        .arg(&path)
        .arg("--check-config")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn a_flood_of_bad_goals_is_logged_at_a_limited_rate() {
    let prefix = unique_prefix("reject-log");
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("wlnavd.toml");
    std::fs::write(&config, budget_toml()).unwrap();
    let command = DaemonCommand::sim(Path::new(BIN), &prefix, "reject-log", None)
        .args(["--cost", "quadratic", "--log", "terminal"])
        .args(["--config".as_ref(), config.as_os_str()]);
    // Ready (idle) before the flood: a daemon still in its start-up (the solver's
    // self-test) answers no request, and the first would time out on a loaded machine.
    let (mut daemon, client, _telemetry, _first) = Daemon::start_ready(command);
    const N: usize = 500;
    let mut rejected = 0;
    for i in 0..N {
        let bad = Pose2::new(f64::NAN, i as f64, 0.0);
        let r = client
            .set_goal(bad, &[], timing_scale::real(Duration::from_secs(2)))
            .unwrap();
        rejected += usize::from(!r.is_accepted());
    }
    assert_eq!(rejected, N);
    let (status, killed) = daemon
        .terminate(timing_scale::real(Duration::from_secs(30)))
        .unwrap();
    assert!(!killed && status.success(), "{status:?}, killed: {killed}");
    let err = daemon.log_text();
    let lines = err.lines().filter(|l| l.contains("rejected")).count();
    assert!(
        (1..=12).contains(&lines),
        "{lines} log lines about rejected requests for {N} bad goals:\n{}",
        err.lines().take(20).collect::<Vec<_>>().join("\n")
    );
}
