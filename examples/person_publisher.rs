//! A perception stand-in: publishes live obstacles to wlnavd (DESIGN §18), as a
//! perception stack on the machine would: a person walking across the machine's way at
//! 1.4 m/s, 4 m ahead, from 5 m on its right to 5 m on its left, one set every 100 ms.
//!
//! ```sh
//! wlnavd --sim --prefix demo --config examples/external-perception.toml &
//! cargo run --release -p wlnav-examples --bin person-publisher -- --prefix demo
//! ```
//!
//! What a perception must do, and this program does: one publisher per daemon (a second
//! is refused, naming the first), the complete current set every time (a set replaces
//! the previous one), stamped with `CLOCK_MONOTONIC` when measured, at a steady rate, and
//! an empty set when nothing is seen (silence would make the set stale, and a stale set
//! stops a moving machine). Each set is checked with the daemon's own
//! `LiveObstacleValidator` before it goes out.
//!
//! Exits 0 once the person has crossed (about 7 s) and an empty set is published; 1 on
//! any error. Its timeouts (not the rate) are multiplied by `WLNAV_TIMING_SCALE` when set
//! (`tests/timing_scale.rs`).

use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use shm_ipc::{
    monotonic_now_ns, IpcConfig, LiveObstacle, LiveObstacleSet, LiveObstacleValidator,
    ObstacleClass, ObstaclePublisher,
};

#[path = "../tests/timing_scale.rs"]
mod timing_scale;
use timing_scale::real;

/// Sets per second.
const RATE_HZ: f64 = 10.0;
/// Walking speed [m/s], along +y.
const SPEED: f64 = 1.4;
/// The person's physical radius [m] (the daemon adds the machine's outline).
const RADIUS: f64 = 0.3;
/// Where the person walks: x = 4 m, from y = −5 m to y = +5 m.
const X: f64 = 4.0;
const Y_START: f64 = -5.0;
const Y_END: f64 = 5.0;
/// The person's track id.
const PERSON_ID: u32 = 1;

fn main() -> Result<()> {
    let prefix = prefix_arg()?;
    // The daemon creates the service; it may still be starting.
    let publisher = ObstaclePublisher::connect(
        &IpcConfig::new(prefix.clone()),
        real(Duration::from_secs(20)),
    )
    .with_context(|| format!("cannot publish obstacles to wlnavd on prefix `{prefix}`"))?;
    let validator = LiveObstacleValidator::default();
    let period = Duration::from_secs_f64(1.0 / RATE_HZ);
    let start = Instant::now();
    let crossing = (Y_END - Y_START) / SPEED;
    let mut sequence = 0u32;
    loop {
        // Where the person is now: dead-reckoned here, measured by a real perception.
        let t = start.elapsed().as_secs_f64();
        let stamp = monotonic_now_ns();
        let mut set = LiveObstacleSet::empty(stamp, sequence);
        if t <= crossing {
            let y = Y_START + SPEED * t;
            set.push(LiveObstacle::circle(
                PERSON_ID,
                ObstacleClass::Person,
                [X, y],
                RADIUS,
                [0.0, SPEED],
                stamp,
            ))?;
            if sequence % 10 == 0 {
                println!("t {t:4.1} s: person at ({X:.1}, {y:5.2}) m");
            }
        }
        if let Err(why) = validator.validate(&set, monotonic_now_ns()) {
            bail!("set {sequence} would be rejected ({}): {why}", why.rule());
        }
        publisher.publish(&set)?;
        sequence += 1;
        if set.as_slice().is_empty() {
            println!("the person has crossed: {sequence} sets published, the last one empty");
            return Ok(());
        }
        // Absolute deadlines: a steady rate whatever a publish costs.
        std::thread::sleep((start + period * sequence).saturating_duration_since(Instant::now()));
    }
}

/// `--prefix P` (default `wlnav`, the daemon's).
fn prefix_arg() -> Result<String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.as_slice() {
        [] => Ok("wlnav".into()),
        [flag, p] if flag == "--prefix" => Ok(p.clone()),
        _ => bail!("usage: person-publisher [--prefix P]"),
    }
}
