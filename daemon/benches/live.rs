//! Live obstacles through the real daemon, in real time (issue 41): the
//! figures its acceptance asks for, measured, never asserted in a test.
//!
//! 1. From publish to the first braking frame on the CAN side (a command
//!    0.1 m/s or more below the one before): 20 trials, each with the
//!    machine driving straight at ≥ 0.9 m/s and a person published 3 m
//!    ahead at a different phase of the tick; the median and the maximum
//!    (target ≤ 50 ms and ≤ 100 ms), and the tick's period for scale.
//! 2. A flood of 10,000 sets per second for 10 s while driving: the tick's
//!    compute time (median, p99; target p99 < 5 ms) beside the same run
//!    without the flood.
//!
//! `cargo bench -p daemon --bench live` (about 3 min; the simulated machine,
//! the quadratic cost: no weights; the loop is what is measured).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use shm_ipc::{
    Client, IpcConfig, LiveObstacle, LiveObstacleSet, ObstacleClass, ObstaclePublisher, Pose2,
};
use wlnavd::config::CostKind;
use wlnavd::sim::SimHandle;
use wlnavd::{Config, RunOptions, RunReport, ShutdownHandle};

struct Daemon {
    shutdown: ShutdownHandle,
    thread: std::thread::JoinHandle<Result<RunReport, wlnavd::DaemonError>>,
    sim: SimHandle,
    client: Client,
    publisher: ObstaclePublisher,
}

fn start(name: &str) -> Daemon {
    let mut config = Config::default();
    config.controller.cost = CostKind::Quadratic;
    config.sim.perception.publish = false;
    config.ipc.prefix = format!("wlnav-bench-{name}-{}", std::process::id());
    // The trials drive on along +x, about 4 m each.
    config.ipc.workspace.x_max = 200.0;
    config.validate().expect("the bench's configuration");
    let shutdown = ShutdownHandle::new();
    let (tx, rx) = tokio::sync::oneshot::channel();
    let options = RunOptions {
        controller: None,
        shutdown: shutdown.clone(),
        handle_signals: false,
        sim_handle: Some(tx),
    };
    let prefix = config.ipc.prefix.clone();
    let thread = std::thread::spawn(move || wlnavd::run(config, options));
    let sim = rx.blocking_recv().expect("the simulated machine");
    let ipc = IpcConfig::new(prefix);
    let client = Client::connect(&ipc, Duration::from_secs(10)).expect("a client");
    let publisher = ObstaclePublisher::new(&ipc).expect("the obstacle publisher");
    Daemon {
        shutdown,
        thread,
        sim,
        client,
        publisher,
    }
}

fn set_of(seq: u32, obstacles: &[LiveObstacle]) -> LiveObstacleSet {
    let now = shm_ipc::monotonic_now_ns();
    let mut set = LiveObstacleSet::empty(now, seq);
    for o in obstacles {
        set.push(LiveObstacle {
            timestamp_ns: now,
            ..*o
        })
        .expect("within the capacity");
    }
    set
}

impl Daemon {
    /// Publishes empty sets every 50 ms until `until` holds, on this thread.
    fn perceive_until(&self, seq: &mut u32, mut until: impl FnMut(&Self) -> bool) {
        let t0 = Instant::now();
        while !until(self) {
            *seq += 1;
            self.publisher.publish(&set_of(*seq, &[])).expect("publish");
            std::thread::sleep(Duration::from_millis(50));
            assert!(t0.elapsed() < Duration::from_secs(60), "timed out");
        }
    }

    fn speed(&self) -> f64 {
        self.sim.snapshot().true_state[5]
    }

    /// A goal 12 m further along +x.
    fn goal_ahead(&self, seq: &mut u32) {
        let x = self.sim.snapshot().true_state;
        let goal = Pose2::new(x[0] + 12.0, 0.0, 0.0);
        let t0 = Instant::now();
        loop {
            *seq += 1;
            self.publisher.publish(&set_of(*seq, &[])).expect("publish");
            let last = match self.client.set_goal(goal, &[], Duration::from_secs(1)) {
                Ok(r) if r.is_accepted() => return,
                Ok(r) => r.reason_text().to_string(),
                Err(e) => e.to_string(),
            };
            std::thread::sleep(Duration::from_millis(50));
            assert!(
                t0.elapsed() < Duration::from_secs(30),
                "goal {goal:?} never accepted: {last}"
            );
        }
    }

    fn stop(self) -> RunReport {
        self.shutdown.trigger();
        self.thread
            .join()
            .expect("daemon thread")
            .expect("daemon run")
    }
}

fn quantile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

fn latency() {
    let d = start("latency");
    let mut seq = 0;
    let mut ms = Vec::new();
    for trial in 0..20 {
        d.goal_ahead(&mut seq);
        // Driving straight at speed, so that 3 m ahead is in its way.
        d.perceive_until(&mut seq, |d| {
            let x = d.sim.snapshot().true_state;
            x[5] > 0.9 && x[3].abs() < 0.05 && x[4].abs() < 0.05
        });
        // A different phase of the tick each trial (the tick is 200 ms).
        std::thread::sleep(Duration::from_millis(7 * trial as u64 + 3));
        let x = d.sim.snapshot().true_state;
        let ahead = 3.0 + 0.65 + 0.3;
        let person = LiveObstacle::circle(
            1,
            ObstacleClass::Person,
            [x[0] + ahead * x[2].cos(), x[1] + ahead * x[2].sin()],
            0.3,
            [0.0, 0.0],
            0,
        );
        let before = d.sim.snapshot().commands.len();
        seq += 1;
        let set = set_of(seq, &[person]);
        let published = Instant::now();
        d.publisher.publish(&set).expect("publish");
        let latency = loop {
            let log = d.sim.snapshot();
            let braking = log.commands[before.saturating_sub(1)..]
                .windows(2)
                .any(|w| w[1].command.v_cmd < w[0].command.v_cmd - 0.1);
            if braking {
                break published.elapsed();
            }
            assert!(published.elapsed() < Duration::from_secs(2), "no stop");
            std::thread::sleep(Duration::from_micros(200));
        };
        ms.push(latency.as_secs_f64() * 1e3);
        // The person stays until the machine is at rest, then leaves.
        let t0 = Instant::now();
        while d.speed().abs() > 0.02 {
            seq += 1;
            d.publisher
                .publish(&set_of(seq, &[person]))
                .expect("publish");
            std::thread::sleep(Duration::from_millis(50));
            assert!(t0.elapsed() < Duration::from_secs(20), "never at rest");
        }
        let _ = d.client.cancel(Duration::from_secs(1));
    }
    let report = d.stop();
    let n = ms.len();
    println!(
        "publish -> first stop frame on CAN, {n} trials: median {:.1} ms, max {:.1} ms \
         (target <= 50 / <= 100; the tick is 200 ms); protective stops between ticks {}",
        quantile(&mut ms, 0.5),
        quantile(&mut ms, 1.0),
        report.stats.protective_stops
    );
}

fn drive_for(name: &str, seconds: f64, flood: bool) -> RunReport {
    let d = start(name);
    let mut seq = 0;
    d.goal_ahead(&mut seq);
    let stop = Arc::new(AtomicBool::new(false));
    let flooded = Arc::new(std::sync::atomic::AtomicU64::new(0));
    std::thread::scope(|s| {
        if flood {
            let (stop, flooded, publisher) = (stop.clone(), flooded.clone(), &d.publisher);
            s.spawn(move || {
                // 10,000 sets a second, each fresh and valid (a far circle).
                let far = LiveObstacle::circle(
                    9,
                    ObstacleClass::Unknown,
                    [500.0, 500.0],
                    1.0,
                    [0.0, 0.0],
                    0,
                );
                let mut k = 0u32;
                let t0 = Instant::now();
                while !stop.load(Ordering::Relaxed) {
                    k = k.wrapping_add(1);
                    let _ = publisher.publish(&set_of(k, &[far]));
                    flooded.fetch_add(1, Ordering::Relaxed);
                    let due = t0 + Duration::from_micros(100) * k;
                    if let Some(wait) = due.checked_duration_since(Instant::now()) {
                        std::thread::sleep(wait);
                    }
                }
            });
        } else {
            let (stop, publisher) = (stop.clone(), &d.publisher);
            s.spawn(move || {
                let mut k = 0;
                while !stop.load(Ordering::Relaxed) {
                    k += 1;
                    let _ = publisher.publish(&set_of(k, &[]));
                    std::thread::sleep(Duration::from_millis(50));
                }
            });
        }
        std::thread::sleep(Duration::from_secs_f64(seconds));
        stop.store(true, Ordering::Relaxed);
    });
    let report = d.stop();
    if flood {
        println!(
            "flood: {:.0} sets/s published for {seconds} s",
            flooded.load(Ordering::Relaxed) as f64 / seconds
        );
    }
    report
}

fn flood() {
    let quiet = drive_for("quiet", 10.0, false).stats.tick();
    let flooded = drive_for("flood", 10.0, true).stats.tick();
    println!(
        "tick compute time [ms]: 10 Hz sets median {:.2} p99 {:.2} max {:.2}; \
         flood median {:.2} p99 {:.2} max {:.2} (target p99 < 5)",
        quiet.median * 1e3,
        quiet.p99 * 1e3,
        quiet.max * 1e3,
        flooded.median * 1e3,
        flooded.p99 * 1e3,
        flooded.max * 1e3
    );
}

fn main() {
    // `cargo bench` passes `--bench`; `cargo test --benches` passes nothing
    // and must not run the 3-minute measurement.
    if !std::env::args().any(|a| a == "--bench") {
        return;
    }
    latency();
    flood();
}
