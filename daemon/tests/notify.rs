//! The sd_notify protocol against a fake `NOTIFY_SOCKET`: READY=1 once (after the
//! first solve), then WATCHDOG=1 on every healthy tick, none while the control loop
//! is stalled, and again once it recovers. Its own test binary: it sets the
//! process-wide NOTIFY_SOCKET.

#[path = "e2e/common.rs"]
mod common;

use std::os::unix::net::UnixDatagram;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use common::*;
use control::mpc::Mpc;
use control::State;
use shm_ipc::Mode;
use wlnav_test_kit::controller::{Forwarding, Hooks};
use wlnavd::controller::{
    quadratic_cost, Controller, ControllerError, ControllerFactory, PilotController, Step,
};

/// Hooks that stall (sleep in `step`) once when asked, recording when; every other call
/// reaches the MPC (the kit's wrapper forwards it).
struct Stalling {
    stall: Arc<AtomicBool>,
    window: Arc<Mutex<Option<(Instant, Instant)>>>,
}

const STALL: Duration = Duration::from_millis(1500);

impl Hooks for Stalling {
    fn step<'a>(
        &'a mut self,
        inner: &'a mut dyn Controller,
        state: &State,
        now: f64,
        tick_start: Instant,
    ) -> Result<Step<'a>, ControllerError> {
        if self.stall.swap(false, Ordering::SeqCst) {
            let start = Instant::now();
            std::thread::sleep(STALL);
            *self.window.lock().unwrap() = Some((start, Instant::now()));
        }
        inner.step(state, now, tick_start)
    }
}

#[test]
fn ready_then_watchdog_on_healthy_ticks_only() {
    let dir = tempfile::tempdir().unwrap();
    let sock_path = dir.path().join("notify.sock");
    let sock = UnixDatagram::bind(&sock_path).unwrap();
    sock.set_read_timeout(Some(Duration::from_millis(50)))
        .unwrap();
    // The only test in this binary: no other thread reads the environment.
    std::env::set_var("NOTIFY_SOCKET", &sock_path);

    let messages: Arc<Mutex<Vec<(Instant, String)>>> = Arc::default();
    let done = Arc::new(AtomicBool::new(false));
    let collector = {
        let (messages, done) = (messages.clone(), done.clone());
        std::thread::spawn(move || {
            let mut buf = [0u8; 4096];
            while !done.load(Ordering::SeqCst) {
                if let Ok(n) = sock.recv(&mut buf) {
                    let text = String::from_utf8_lossy(&buf[..n]).into_owned();
                    messages.lock().unwrap().push((Instant::now(), text));
                }
            }
        })
    };

    let config = sim_config("notify");
    let (machine, settings) = (config.machine, config.mpc);
    let stall = Arc::new(AtomicBool::new(false));
    let window = Arc::new(Mutex::new(None));
    let (s, w) = (stall.clone(), window.clone());
    let pilot_config = config.clone();
    let factory: ControllerFactory = Box::new(move || {
        let mpc = Mpc::new(machine, quadratic_cost(), None, settings)
            .map_err(|e| ControllerError(e.to_string()))?;
        Ok(Box::new(Forwarding::new(
            Box::new(PilotController::without_navigator(mpc, &pilot_config)?),
            Stalling {
                stall: s,
                window: w,
            },
        )) as Box<dyn Controller>)
    });
    let d = start(config, Some(factory));
    d.goal(10.0, 0.0, 0.0);
    d.wait_for(Duration::from_secs(30), "tracking", |t| {
        t.mode() == Ok(Mode::Tracking)
    });
    std::thread::sleep(timing_scale::real(Duration::from_millis(500)));
    stall.store(true, Ordering::SeqCst);
    let deadline = Instant::now() + timing_scale::real(Duration::from_secs(20));
    while window.lock().unwrap().is_none() {
        assert!(Instant::now() < deadline, "the loop never stalled");
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(timing_scale::real(Duration::from_millis(1000)));
    let report = d.stop();
    done.store(true, Ordering::SeqCst);
    collector.join().unwrap();

    let messages = messages.lock().unwrap().clone();
    let (stall_start, stall_end) = window.lock().unwrap().unwrap();
    let is_watchdog = |m: &str| m.lines().any(|l| l == "WATCHDOG=1");
    // READY=1 exactly once, before any WATCHDOG=1.
    let ready: Vec<usize> = messages
        .iter()
        .enumerate()
        .filter(|(_, (_, m))| m.lines().any(|l| l == "READY=1"))
        .map(|(i, _)| i)
        .collect();
    assert_eq!(ready.len(), 1, "{messages:?}");
    let first_watchdog = messages.iter().position(|(_, m)| is_watchdog(m)).unwrap();
    assert!(ready[0] < first_watchdog);
    assert!(messages[ready[0]].1.contains("STATUS="));

    let watchdogs: Vec<Instant> = messages
        .iter()
        .filter(|(_, m)| is_watchdog(m))
        .map(|(t, _)| *t)
        .collect();
    // None while stalled.
    let during: Vec<_> = watchdogs
        .iter()
        .filter(|t| **t > stall_start + Duration::from_millis(5) && **t < stall_end)
        .collect();
    assert!(
        during.is_empty(),
        "{} WATCHDOG=1 while stalled",
        during.len()
    );
    // Before and after the stall: one per healthy tick (period 50 ms real at scale 4).
    let period = Duration::from_secs_f64(0.2 / time_scale());
    let before = watchdogs.iter().filter(|t| **t < stall_start).count();
    let window_after = timing_scale::real(Duration::from_millis(900));
    let after = watchdogs
        .iter()
        .filter(|t| **t > stall_end && **t < stall_end + window_after)
        .count();
    assert!(before >= 10, "only {before} watchdogs before the stall");
    let expected_after = (window_after.as_secs_f64() / period.as_secs_f64()) as usize;
    assert!(
        after + 3 >= expected_after,
        "{after} watchdogs in 0.9 s after the stall, expected about {expected_after}"
    );
    // Every healthy tick sent exactly one: ticks minus the overrun ones (the stall).
    let healthy = report.stats.ticks - report.stats.overruns;
    let n = watchdogs.len() as u64;
    assert!(
        n <= report.stats.ticks && n + 3 >= healthy,
        "{n} watchdogs for {healthy} healthy ticks of {}",
        report.stats.ticks
    );
    assert!(
        report.stats.overruns >= 1,
        "the stall was not counted as an overrun"
    );
    // STATUS= carried the modes.
    assert!(messages.iter().any(|(_, m)| m.contains("STATUS=tracking")));
}
