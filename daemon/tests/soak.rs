//! Soak/benchmark: the loop runs for many ticks against the simulated machine in
//! accelerated time, driving back and forth between two goals, and reports tick
//! start jitter (median, p99, max), solve time and resident memory at start and
//! end; memory must not grow.
//!
//! The short run (1,000 ticks) is part of the suite; the full 10,000-tick run is
//! `cargo test -p daemon --release --test soak -- --ignored --nocapture`
//! (or `wlnavd --sim --cost quadratic --time-scale 20 --max-ticks 10000`
//! with goals from `wlnav`).

#[path = "e2e/common.rs"]
mod common;

use std::time::{Duration, Instant};

use common::*;
use shm_ipc::Pose2;

fn soak(ticks: u64, time_scale: f64) {
    // On a slower CPU (WLNAV_TIMING_SCALE) the daemon's clock runs slower by that factor.
    let time_scale = timing_scale::daemon_time_scale(time_scale);
    let mut config = sim_config("soak");
    config.sim.time_scale = time_scale;
    config.control.max_ticks = ticks;
    let d = start(config.clone(), None);
    d.goal(5.0, 0.0, 0.0);
    // Alternate goals every 15 daemon seconds until the daemon stops by itself.
    let leg = Duration::from_secs_f64(15.0 / time_scale);
    let goals = [Pose2::new(0.0, 0.0, 0.0), Pose2::new(5.0, 0.0, 0.0)];
    let mut i = 0;
    let mut next = Instant::now() + leg;
    let mut report = None;
    let mut d = Some(d);
    while report.is_none() {
        std::thread::sleep(Duration::from_millis(20));
        let running = d.as_mut().unwrap();
        if running.thread.as_ref().unwrap().is_finished() {
            let r = running.thread.take().unwrap().join().unwrap().unwrap();
            report = Some(r);
            break;
        }
        if Instant::now() > next {
            let _ = running
                .client
                .set_goal(goals[i % 2], &[], Duration::from_secs(1));
            i += 1;
            next += leg;
        }
    }
    drop(d);
    let report = report.unwrap();
    println!(
        "soak: {ticks} ticks at time scale {time_scale}\n{}",
        report.summary()
    );
    check_commands(&report, &config.machine);
    assert!(report.stats.ticks >= ticks);
    assert!(report.stats.solve().count > 0, "the MPC never ran");
    let (start, end) = report.rss;
    let (start, end) = (start.unwrap(), end.unwrap());
    assert!(
        end <= start + 1024 * 1024,
        "resident memory grew from {start} to {end} bytes"
    );
    // Timing: on a loaded 2-core machine a few late ticks are tolerated, not many.
    assert!(
        report.stats.overruns * 100 <= ticks,
        "{} overruns in {ticks} ticks",
        report.stats.overruns
    );
}

#[test]
fn soak_1000_ticks() {
    soak(1000, 10.0);
}

#[test]
#[ignore = "long: 10,000 ticks (about 100 s); run with --ignored"]
fn soak_10000_ticks() {
    soak(10_000, 20.0);
}
