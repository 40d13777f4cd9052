//! Acceptance: a real, independently written VDA 5050 master drives the bridge through
//! mosquitto. vda-5050-lib 1.4.0's `MasterController` (npm; fleet/master/) runs, for two
//! machines at once (two `wlnavd --sim`, two bridges, one broker): a 3-node order node by
//! node, an order update, cancel, and pause/resume; it validates every state,
//! visualization, connection and factsheet it receives against the official schemas.
//!
//! Needs Node.js and npm (on the machine); the packages are installed from
//! fleet/master/package-lock.json with `npm ci` on first use.

mod common;

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::*;

#[test]
fn vda_5050_lib_master_drives_two_machines() {
    let _g = serial();
    let master_dir = repo_root().join("fleet/master");
    npm_ci(&master_dir);
    let broker = Broker::start();
    let (p1, p2) = (unique_prefix("master-a"), unique_prefix("master-b"));
    let _d1 = start_daemon(&p1);
    let _d2 = start_daemon(&p2);
    let mut b1 = start_bridge(&broker.addr(), "L1", &p1, None);
    let mut b2 = start_bridge(&broker.addr(), "L2", &p2, None);

    let log = std::env::temp_dir().join(format!("wlnav-fleet-master-{}.log", std::process::id()));
    let out = std::fs::File::create(&log).unwrap();
    let mut child = Command::new("node")
        .arg(master_dir.join("master.mjs"))
        .args([
            "--broker",
            &broker.addr(),
            "--manufacturer",
            MANUFACTURER,
            "--serials",
            "L1,L2",
            "--schemas",
        ])
        .arg(repo_root().join("fleet/schemas"))
        .stdin(Stdio::null())
        .stdout(out.try_clone().unwrap())
        .stderr(out)
        .spawn()
        .unwrap_or_else(|e| panic!("node: {e}: Node.js is needed for the VDA 5050 master test"));
    let deadline = Instant::now() + timing_scale::real(Duration::from_secs(300));
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break Some(s);
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    let output = std::fs::read_to_string(&log).unwrap_or_default();
    eprintln!("{output}");
    assert!(
        status.is_some_and(|s| s.success()),
        "the master failed ({status:?}):\n{output}\nbridge L1:\n{}\nbridge L2:\n{}",
        b1.log_tail(30),
        b2.log_tail(30)
    );
    assert!(b1.is_running() && b2.is_running());
    assert!(b1.terminate(Duration::from_secs(10)));
    assert!(b2.terminate(Duration::from_secs(10)));
}
