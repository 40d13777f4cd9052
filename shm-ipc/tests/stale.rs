//! Stale-node clean-up: a daemon process killed with SIGKILL leaves its iceoryx2 node (and
//! its goal server slot) behind; the next daemon on the same prefix must clean it up and
//! start. The child is this test binary re-run in helper mode.

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::time::Duration;

use shm_ipc::iceoryx2::config::Config;
use shm_ipc::iceoryx2::node::{Node, NodeState, NodeView};
use shm_ipc::iceoryx2::prelude::CallbackProgression;
use shm_ipc::{validate_prefix, DaemonEndpoint, IpcConfig, IpcError, IpcService, ServiceNames};

const CHILD_ENV: &str = "WLNAV_SHM_IPC_STALE_CHILD_PREFIX";

/// Helper mode: serve the prefix given in the environment until killed. Ignored (and a
/// no-op) unless started by `crashed_daemon_is_cleaned_up`.
#[test]
#[ignore = "helper process for crashed_daemon_is_cleaned_up"]
fn stale_child_helper() {
    let Ok(prefix) = std::env::var(CHILD_ENV) else {
        return;
    };
    let _ep = DaemonEndpoint::new(&IpcConfig::new(prefix)).expect("child daemon");
    println!("READY");
    std::thread::sleep(Duration::from_secs(60));
}

#[test]
fn crashed_daemon_is_cleaned_up() {
    let prefix = format!(
        "wlnav-test/{}/stale/{}",
        std::process::id(),
        shm_ipc::monotonic_now_ns()
    );
    let mut child = Command::new(std::env::current_exe().expect("test exe"))
        .args(["--exact", "stale_child_helper", "--ignored", "--nocapture"])
        .env(CHILD_ENV, &prefix)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("spawn child");
    let stdout = child.stdout.take().expect("stdout");
    let ready = BufReader::new(stdout)
        .lines()
        .map_while(Result::ok)
        .any(|l| l.contains("READY"));
    assert!(ready, "child daemon did not start");

    // While the child lives, its prefix is taken.
    let config = IpcConfig::new(prefix);
    assert!(matches!(
        DaemonEndpoint::new(&config),
        Err(IpcError::AlreadyServed { .. })
    ));

    let child_pid = child.id();
    child.kill().expect("kill child"); // SIGKILL: no destructors run
    child.wait().expect("reap child");

    // The dead node is cleaned up (by us, or by a concurrent process that got there first)
    // and the goal server slot is free again.
    let ep = DaemonEndpoint::new(&config).expect("daemon after crash");
    eprintln!("clean-up report: {:?}", ep.cleanup_report());
    let mut child_nodes_left = 0;
    Node::<IpcService>::list(Config::global_config(), |state| {
        if let NodeState::Dead(view) = &state {
            if view
                .details()
                .as_ref()
                .is_some_and(|d| d.process_id().value() as u32 == child_pid)
            {
                child_nodes_left += 1;
            }
        }
        CallbackProgression::Continue
    })
    .expect("list nodes");
    assert_eq!(child_nodes_left, 0);
}

#[test]
fn service_names_and_prefix_rules() {
    let names = ServiceNames::new("wlnav").expect("default");
    assert_eq!(names.goal, "wlnav/v2/goal");
    assert_eq!(names.pose, "wlnav/v2/pose");
    assert_eq!(names.telemetry, "wlnav/v2/telemetry");
    assert_eq!(IpcConfig::default().prefix, "wlnav");
    assert!(validate_prefix("site-3/loader_1.b").is_ok());
    for bad in [
        "",
        "/abs",
        "trail/",
        "a//b",
        "has space",
        "ünï",
        &"x".repeat(129),
    ] {
        assert!(
            matches!(validate_prefix(bad), Err(IpcError::InvalidPrefix { .. })),
            "{bad:?}"
        );
    }
    assert!(matches!(
        DaemonEndpoint::new(&IpcConfig::new("bad prefix")),
        Err(IpcError::InvalidPrefix { .. })
    ));
}
