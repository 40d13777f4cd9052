//! A stop nobody can crowd out (issue 26, item 4; DESIGN §11, §14), through the real
//! binaries: another local process squats on the stop service, holding every client slot
//! or every notifier, while the machine drives. `wlnav stop` must exit 0 and the machine
//! must be stopping within two control ticks of the daemon's answer (telemetry), and the
//! detour printed on stderr names the squatter (pid and executable). A process that
//! created the goal service with the documented settings and a server before the daemon
//! started is named in the daemon's refusal.
//!
//! The squatter is this test binary run again as a child (`squat_helper`), using
//! iceoryx2 directly, as a third-party client would.

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use e2e::{binaries, SimDaemon};
use shm_ipc::{fault_flags, Mode, ServiceNames, Telemetry};

/// What the squatter takes.
const WHAT_ENV: &str = "WLNAV_SQUAT_WHAT";
const PREFIX_ENV: &str = "WLNAV_SQUAT_PREFIX";

/// Helper process for the tests below (run as a child of this test binary): on the
/// services of `WLNAV_SQUAT_PREFIX` takes what `WLNAV_SQUAT_WHAT` says, prints `held N`,
/// then sleeps until killed.
/// * `stop-clients`: every client slot of `P/v2/stop` (asks for 20; 16 exist);
/// * `stop-notifiers`: every notifier of the `P/v2/stop` event service (asks for 80);
/// * `goal-server`: creates `P/v2/goal` with the documented settings and a server.
#[test]
#[ignore = "helper process for the squatting tests of this file"]
fn squat_helper() {
    use shm_ipc::iceoryx2::prelude::*;
    // Run only as the squatter of the tests below, which set both variables: run by hand
    // (`--ignored`, `--include-ignored`) without them it fails, saying so, rather than
    // passing without having squatted on anything.
    let (Ok(prefix), Ok(what)) = (std::env::var(PREFIX_ENV), std::env::var(WHAT_ENV)) else {
        panic!(
            "squat_helper is the squatting process of this file's tests, started by them \
             with {PREFIX_ENV} and {WHAT_ENV} set; it is not a test of its own (run the \
             suite without --ignored/--include-ignored, or skip it: --skip squat_helper)"
        );
    };
    set_log_level(LogLevel::Fatal);
    let names = ServiceNames::new(&prefix).unwrap();
    let node = NodeBuilder::new()
        .name(&NodeName::new("squatter").unwrap())
        .create::<ipc::Service>()
        .unwrap();
    let mut held_clients = Vec::new();
    let mut held_notifiers = Vec::new();
    let mut held_server = Vec::new();
    let mut services = Vec::new();
    match what.as_str() {
        "stop-clients" => {
            let service = node
                .service_builder(&ServiceName::new(&names.stop).unwrap())
                .request_response::<shm_ipc::GoalRequest, shm_ipc::GoalReply>()
                .open()
                .unwrap();
            for _ in 0..20 {
                if let Ok(c) = service.client_builder().create() {
                    held_clients.push(c);
                }
            }
            println!("held {}", held_clients.len());
            services.push(service);
        }
        "stop-notifiers" => {
            let service = node
                .service_builder(&ServiceName::new(&names.stop).unwrap())
                .event()
                .open()
                .unwrap();
            for _ in 0..80 {
                if let Ok(n) = service.notifier_builder().create() {
                    held_notifiers.push(n);
                }
            }
            println!("held {}", held_notifiers.len());
            drop(service);
        }
        "goal-server" => {
            let service = node
                .service_builder(&ServiceName::new(&names.goal).unwrap())
                .request_response::<shm_ipc::GoalRequest, shm_ipc::GoalReply>()
                .max_servers(shm_ipc::qos::GOAL_MAX_SERVERS)
                .max_clients(shm_ipc::qos::GOAL_MAX_CLIENTS)
                .max_active_requests_per_client(shm_ipc::qos::GOAL_MAX_ACTIVE_REQUESTS_PER_CLIENT)
                .max_nodes(shm_ipc::qos::MAX_NODES)
                .open_or_create()
                .unwrap();
            held_server.push(service.server_builder().create().unwrap());
            println!("held 1");
            services.push(service);
        }
        other => panic!("unknown squat {other:?}"),
    }
    std::thread::sleep(Duration::from_secs(120));
}

/// The squatter process; killed when dropped.
struct Squatter {
    child: Child,
    held: usize,
}

impl Squatter {
    fn spawn(prefix: &str, what: &str) -> Self {
        let mut child = Command::new(std::env::current_exe().unwrap())
            .args(["--ignored", "--exact", "squat_helper", "--nocapture"])
            .env(PREFIX_ENV, prefix)
            .env(WHAT_ENV, what)
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("spawn the squatter");
        // Read on a thread of its own, so that a squatter that never reports (a silent
        // child) fails the test after a limit instead of blocking it.
        let out = child.stdout.take().unwrap();
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(out).lines() {
                let Ok(line) = line else { break };
                if let Some(n) = line.strip_prefix("held ") {
                    let _ = tx.send(n.trim().parse::<usize>().ok());
                    return;
                }
            }
        });
        let limit = e2e::timing_scale::real(Duration::from_secs(60));
        let held = match rx.recv_timeout(limit) {
            Ok(Some(n)) => n,
            other => {
                let what_proc = wlnav_test_kit::daemon::describe(child.id());
                let _ = child.kill();
                let _ = child.wait();
                panic!(
                    "the squatter ({what}) did not report what it holds within {limit:?} \
                     ({other:?}); {what_proc}"
                )
            }
        };
        Self { child, held }
    }

    fn pid(&self) -> u32 {
        self.child.id()
    }
}

impl Drop for Squatter {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The file name of this test binary: the squatter's executable. Under an emulator (the
/// arm64 check, binfmt_misc and qemu) the holder is named by this path with the emulator
/// after it (shm-ipc's holders), so the name is found there too.
fn own_exe_name() -> String {
    std::env::current_exe()
        .unwrap()
        .file_name()
        .unwrap()
        .to_string_lossy()
        .into_owned()
}

fn text(o: &std::process::Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// Drives towards (8, 0) until the machine moves at > 0.3 m/s; returns that sample's tick.
fn drive(d: &SimDaemon) -> u64 {
    let p = d.prefix().to_owned();
    let o = Command::new(&binaries().wlnav)
        .args(["--prefix", &p, "goal", "8", "0", "0"])
        .output()
        .expect("run wlnav");
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let deadline = Instant::now() + e2e::timing_scale::real(Duration::from_secs(30));
    loop {
        let t = d.next(Duration::from_secs(3));
        if t.mode() == Ok(Mode::Tracking) && t.state.v_f > 0.3 {
            return t.tick;
        }
        assert!(Instant::now() < deadline, "never drove: {t:?}");
    }
}

/// A sample of a machine brought to a controlled stop by the operator: the stop latched,
/// no goal, mode stopping (the command ramping down at the braking limits) or already
/// idle.
fn stopping(t: &Telemetry) -> bool {
    t.fault_flags & fault_flags::STOP_REQUESTED != 0
        && t.goal_active == 0
        && matches!(t.mode(), Ok(Mode::Stopping) | Ok(Mode::Idle))
}

/// Runs `wlnav stop` while the machine drives and checks the acceptance: exit 0, the
/// machine stopping within two ticks of the newest tick when `wlnav stop` returned, at
/// rest later. Returns the stop's stderr.
fn stop_gets_through(d: &SimDaemon, driving_tick: u64) -> String {
    let p = d.prefix().to_owned();
    // The newest tick before the stop.
    let before = d
        .telemetry
        .latest()
        .expect("telemetry")
        .map_or(driving_tick, |t| t.tick);
    let sent = Instant::now();
    let o = Command::new(&binaries().wlnav)
        .args(["--prefix", &p, "stop"])
        .output()
        .expect("run wlnav stop");
    let took = sent.elapsed();
    assert_eq!(o.status.code(), Some(0), "wlnav stop: {}", text(&o));
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("stop: accepted"),
        "{}",
        text(&o)
    );
    // Every sample published so far, oldest first: the newest is the tick current when
    // the reply had arrived (or later).
    let mut seen = Vec::new();
    while let Some(t) = d.telemetry.try_recv().expect("telemetry") {
        seen.push(t);
    }
    let at_reply = match seen.last() {
        Some(t) => t.tick,
        None => d.next(Duration::from_secs(2)).tick,
    };
    let first_stopping = match seen.iter().find(|t| stopping(t)) {
        Some(t) => *t,
        None => {
            let deadline = Instant::now() + e2e::timing_scale::real(Duration::from_secs(5));
            loop {
                let t = d.next(Duration::from_secs(2));
                if stopping(&t) {
                    break t;
                }
                assert!(Instant::now() < deadline, "never stopping: {t:?}");
            }
        }
    };
    eprintln!(
        "wlnav stop took {:.0} ms; newest tick before {before}, at the reply {at_reply}, \
         first stopping tick {} (mode {:?}, v_cmd {:.3}, v {:.3})",
        took.as_secs_f64() * 1e3,
        first_stopping.tick,
        first_stopping.mode(),
        first_stopping.command.v,
        first_stopping.state.v_f
    );
    assert!(
        first_stopping.tick <= at_reply + 2,
        "stopping only at tick {}, the reply came at tick {at_reply}",
        first_stopping.tick
    );
    // And it really comes to rest, the stop latched.
    let deadline = Instant::now() + e2e::timing_scale::real(Duration::from_secs(15));
    loop {
        let t = d.next(Duration::from_secs(2));
        if t.goal_active == 0 && t.command.v == 0.0 && t.state.v_f.abs() < 0.05 {
            assert_ne!(t.fault_flags & fault_flags::STOP_REQUESTED, 0, "{t:?}");
            break;
        }
        assert!(Instant::now() < deadline, "not coming to rest: {t:?}");
    }
    let stderr = String::from_utf8_lossy(&o.stderr).into_owned();
    eprintln!("wlnav stop stderr:\n{stderr}");
    stderr
}

#[test]
fn a_process_holding_every_stop_client_slot_cannot_keep_a_stop_out() {
    let _serial = e2e::serial();
    let d = SimDaemon::start("stop-slots", 1.0);
    let driving = drive(&d);
    let squatter = Squatter::spawn(d.prefix(), "stop-clients");
    assert_eq!(
        squatter.held,
        shm_ipc::qos::STOP_MAX_CLIENTS,
        "the squatter must hold every stop client slot"
    );
    let stderr = stop_gets_through(&d, driving);
    // The detour names the squatter.
    for needle in [
        "sending the stop on the goal service".to_owned(),
        "all 16 client slots are taken".to_owned(),
        format!("pid {}", squatter.pid()),
        own_exe_name(),
    ] {
        assert!(stderr.contains(&needle), "{needle:?} missing in: {stderr}");
    }
    drop(squatter);
    d.stop();
}

#[test]
fn a_process_holding_every_stop_notifier_cannot_keep_a_stop_out() {
    let _serial = e2e::serial();
    let d = SimDaemon::start("stop-notifiers", 1.0);
    let driving = drive(&d);
    let squatter = Squatter::spawn(d.prefix(), "stop-notifiers");
    // The daemon holds one notifier on that service (its replies), the squatter the rest.
    assert_eq!(
        squatter.held,
        shm_ipc::qos::EVENT_MAX_PORTS - 1,
        "the squatter must hold every free stop notifier"
    );
    let stderr = stop_gets_through(&d, driving);
    for needle in [
        "all 64 notifier slots are taken".to_owned(),
        format!("pid {}", squatter.pid()),
        own_exe_name(),
    ] {
        assert!(stderr.contains(&needle), "{needle:?} missing in: {stderr}");
    }
    drop(squatter);
    d.stop();
}

#[test]
fn a_process_serving_the_goal_service_first_is_named_in_the_refusal() {
    let _serial = e2e::serial();
    let prefix = e2e::unique_prefix("goal-squat");
    let squatter = Squatter::spawn(&prefix, "goal-server");
    let mut child = Command::new(&binaries().wlnavd)
        .args(["--sim", "--prefix", &prefix, "--cost", "quadratic"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn wlnavd");
    let deadline = Instant::now() + e2e::timing_scale::real(Duration::from_secs(60));
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            panic!("wlnavd did not refuse to start within 60 s");
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let o = child.wait_with_output().unwrap();
    let out = text(&o);
    eprintln!("wlnavd: {out}");
    assert!(
        !status.success(),
        "wlnavd started on a squatted prefix: {out}"
    );
    let goal = ServiceNames::new(&prefix).unwrap().goal;
    for needle in [
        "another daemon already serves".to_owned(),
        goal,
        "node \"squatter\"".to_owned(),
        format!("pid {}", squatter.pid()),
        own_exe_name(),
    ] {
        assert!(out.contains(&needle), "{needle:?} missing in: {out}");
    }
}
