//! Live obstacles end to end (issue 41, DESIGN §18): the test is the
//! perception, publishing on `{prefix}/v2/obstacles` through shared memory.
//! - an obstacle published in the way of the driving machine stops it when
//!   the set arrives, not at the next tick; telemetry names it; the machine
//!   comes to rest before it and goes on once it is gone;
//! - perception falling silent while the machine moves stops it within the
//!   configured age plus a tick, with the fault in telemetry;
//! - a set the validator rejects is flagged, changes nothing else, and the
//!   loop goes on.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use shm_ipc::{
    fault_flags, IpcConfig, LiveObstacle, LiveObstacleSet, Mode, ObstacleClass, ObstaclePublisher,
};

use crate::common::*;

const T: Duration = Duration::from_secs(60);

/// What the test's perception publishes: nothing (silence), or a set of
/// these obstacles, stamped when sent.
type Shared = Arc<Mutex<Option<Vec<LiveObstacle>>>>;

/// A perception on its own thread: every 20 ms (real, times the timing
/// scale) the set in `shared`, stamped now; [`Perception::publish_now`]
/// sends one at once.
struct Perception {
    publisher: Arc<Mutex<ObstaclePublisher>>,
    shared: Shared,
    seq: Arc<Mutex<u32>>,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

fn publish(publisher: &Mutex<ObstaclePublisher>, seq: &Mutex<u32>, obstacles: &[LiveObstacle]) {
    let now = shm_ipc::monotonic_now_ns();
    let mut n = seq.lock().unwrap();
    *n += 1;
    let mut set = LiveObstacleSet::empty(now, *n);
    for o in obstacles {
        set.push(LiveObstacle {
            timestamp_ns: now,
            ..*o
        })
        .unwrap();
    }
    publisher.lock().unwrap().publish(&set).unwrap();
}

impl Perception {
    fn start(prefix: &str) -> Self {
        let publisher = Arc::new(Mutex::new(
            ObstaclePublisher::new(&IpcConfig::new(prefix.to_owned())).unwrap(),
        ));
        let shared: Shared = Arc::new(Mutex::new(Some(Vec::new())));
        let seq = Arc::new(Mutex::new(0));
        let stop = Arc::new(AtomicBool::new(false));
        let (p, s, q, st) = (publisher.clone(), shared.clone(), seq.clone(), stop.clone());
        let period = timing_scale::real(Duration::from_millis(20));
        let thread = std::thread::spawn(move || {
            while !st.load(Ordering::Relaxed) {
                let set = s.lock().unwrap().clone();
                if let Some(obstacles) = set {
                    publish(&p, &q, &obstacles);
                }
                std::thread::sleep(period);
            }
        });
        Self {
            publisher,
            shared,
            seq,
            stop,
            thread: Some(thread),
        }
    }

    /// From now on publish `set` (`None`: fall silent), the first at once.
    fn set(&self, set: Option<Vec<LiveObstacle>>) {
        *self.shared.lock().unwrap() = set.clone();
        if let Some(obstacles) = set {
            publish(&self.publisher, &self.seq, &obstacles);
        }
    }
}

impl Drop for Perception {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// The simulated machine with the test as its perception (required, as
/// shipped).
fn start_with_perception(name: &str) -> (Running, Perception) {
    let mut config = sim_config(name);
    config.sim.perception.publish = false;
    config.validate().unwrap();
    assert!(config.live.required);
    let running = start(config, None);
    let perception = Perception::start(&running.config.ipc.prefix);
    (running, perception)
}

/// Drives to (14, 0) until it goes faster than 0.9 m/s; the telemetry seen.
fn drive_off(running: &Running) -> Vec<shm_ipc::Telemetry> {
    running.goal(14.0, 0.0, 0.0);
    running.wait_for(T, "driving at 0.9 m/s", |t| {
        mode(t) == Mode::Tracking && t.state.v_f > 0.9
    })
}

fn mode(t: &shm_ipc::Telemetry) -> Mode {
    t.mode().unwrap()
}

#[test]
fn an_obstacle_published_in_the_way_stops_the_machine_when_it_arrives() {
    let (running, perception) = start_with_perception("live-stop");
    drive_off(&running);
    // A person 3 m ahead of the front axle, standing.
    let x = running.sim.snapshot().true_state;
    let person = LiveObstacle::circle(
        7,
        ObstacleClass::Person,
        [x[0] + 3.0 + 0.65 + 0.3, x[1]],
        0.3,
        [0.0, 0.0],
        0,
    );
    let before = running.sim.snapshot().commands.len();
    let published = Instant::now();
    perception.set(Some(vec![person]));
    // The first braking command the machine receives after the publish.
    let mut latency = None;
    while published.elapsed() < timing_scale::real(Duration::from_secs(2)) {
        let log = running.sim.snapshot();
        let braking = log.commands[before.saturating_sub(1)..]
            .windows(2)
            .any(|w| w[1].command.v_cmd < w[0].command.v_cmd - 0.1);
        if braking {
            latency = Some(published.elapsed());
            break;
        }
        std::thread::sleep(Duration::from_micros(500));
    }
    let latency = latency.expect("a stop after the publish");
    eprintln!(
        "publish to the stop frame: {:.1} ms",
        latency.as_secs_f64() * 1e3
    );
    // Telemetry names the person while the machine holds for it.
    let seen = running.wait_for(T, "the protective stop named", |t| {
        t.fault_flags & fault_flags::PROTECTIVE_STOP != 0
            && t.fault_flags & fault_flags::LIVE_NEAR != 0
            && t.live_id == 7
    });
    assert!(seen.iter().all(|t| mode(t) != Mode::Fault));
    let rest = running.wait_for(T, "at rest", |t| t.at_rest == 1);
    let s = rest.last().unwrap().state;
    let gap = (person.x - s.x_f).hypot(person.y - s.y_f) - 0.65 - 0.3;
    assert!(gap > 0.3, "at rest {gap:.2} m from the person");
    // Gone: the goal goes on and is reached.
    perception.set(Some(Vec::new()));
    running.wait_for(T, "the goal reached", |t| {
        t.outcome().ok() == Some(shm_ipc::GoalOutcome::Succeeded)
    });
    drop(perception);
    let report = running.stop();
    // The braking left when the set arrived, between ticks (the loop counts
    // those commands apart from the tick's).
    let s = &report.stats;
    assert!(
        s.protective_stops + s.arrival_slowdowns >= 1,
        "stops {} slow-downs {}",
        s.protective_stops,
        s.arrival_slowdowns
    );
}

#[test]
fn silent_perception_stops_a_moving_machine_and_a_bad_set_is_flagged() {
    let (running, perception) = start_with_perception("live-silent");
    drive_off(&running);
    // A set with a NaN radius: rejected, flagged, the loop goes on driving.
    let mut bad = LiveObstacle::circle(3, ObstacleClass::Unknown, [50.0, 50.0], 1.0, [0.0; 2], 0);
    bad.radius = f64::NAN;
    perception.set(Some(vec![bad]));
    let seen = running.wait_for(T, "the rejected set flagged", |t| {
        t.fault_flags & fault_flags::LIVE_REJECTED != 0
    });
    assert!(seen.iter().all(|t| mode(t) == Mode::Tracking));
    // Good sets again, then silence while it drives.
    perception.set(Some(Vec::new()));
    running.wait_for(T, "driving again", |t| {
        t.state.v_f > 0.6 && t.fault_flags & fault_flags::PERCEPTION_STALE == 0
    });
    perception.set(None);
    let silent_at = running.sim.snapshot().time;
    let seen = running.wait_for(T, "perception stale", |t| {
        t.fault_flags & fault_flags::PERCEPTION_STALE != 0
    });
    let stale = seen.last().unwrap();
    assert!(
        stale.command.v < stale.state.v_f,
        "the stop ramps down: {:?}",
        stale.command
    );
    // Caught within max_age (0.5 s) plus a tick of the last set, on the
    // daemon's clock (the sim log's time), with room for this test's polling
    // under an emulator (the exact bound: control/tests/live.rs).
    let caught = running.sim.snapshot().time;
    assert!(
        caught - silent_at <= 0.5 + 0.2 + 0.5,
        "stale after {:.2} s of silence",
        caught - silent_at
    );
    running.wait_for(T, "at rest", |t| t.at_rest == 1);
    // Sets again: it recovers after the span and drives on.
    perception.set(Some(Vec::new()));
    running.wait_for(T, "driving after recovery", |t| {
        t.state.v_f > 0.3 && t.fault_flags & fault_flags::PERCEPTION_STALE == 0
    });
}
