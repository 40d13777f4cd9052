//! A goal client: sends one goal (with an obstacle on the straight way, so the daemon's
//! global layer routes around it) and waits for its outcome.
//!
//! ```sh
//! wlnavd --sim --prefix demo &
//! cargo run --release -p wlnav-examples --bin goal-client -- --prefix demo
//! ```
//!
//! Exit status 0 when the goal ends `succeeded`, 1 on any other outcome or error.
//! Its timeouts are multiplied by `WLNAV_TIMING_SCALE` when set (a slower CPU, e.g. the
//! arm64 daemon under qemu in `scripts/cross-check.sh`; `tests/timing_scale.rs`).

use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use shm_ipc::{Client, GoalOutcome, IpcConfig, Obstacle, Pose2};

#[path = "../tests/timing_scale.rs"]
mod timing_scale;
use timing_scale::real;

fn main() -> Result<()> {
    let prefix = prefix_arg()?;
    let config = IpcConfig::new(prefix.clone());
    // The daemon may still be starting: wait for its services.
    let client = Client::connect(&config, real(Duration::from_secs(20)))
        .with_context(|| format!("no wlnavd on prefix `{prefix}`"))?;
    let telemetry = client.subscribe_telemetry()?;

    // 6 m ahead, a circle of 0.6 m (the machine's half-width included) in between.
    let goal = Pose2::new(6.0, 0.0, 0.0);
    let obstacles = [Obstacle::new(3.0, 0.0, 0.6)];
    // Goals are refused until the daemon has its first pose and machine state.
    let deadline = Instant::now() + real(Duration::from_secs(20));
    let request_id = loop {
        let reply = client.set_goal(goal, &obstacles, real(Duration::from_secs(2)))?;
        if reply.is_accepted() {
            break reply.request_id;
        }
        if Instant::now() > deadline {
            bail!("goal rejected: {}", reply.reason_text());
        }
        std::thread::sleep(Duration::from_millis(200));
    };
    println!(
        "goal {request_id} accepted: ({}, {}, {})",
        goal.x, goal.y, goal.heading
    );

    // Every tick's telemetry; the goal's outcome is reported once, with its request id.
    let timeout = real(Duration::from_secs(90));
    let deadline = Instant::now() + timeout;
    let mut last_print = Instant::now();
    while Instant::now() < deadline {
        let Some(t) = telemetry.recv_timeout(Duration::from_secs(1))? else {
            continue;
        };
        if t.outcome_request_id == request_id {
            let outcome = t
                .outcome()
                .map_err(|c| anyhow::anyhow!("unknown outcome {c}"))?;
            println!(
                "goal {request_id}: {} ({})",
                outcome.name(),
                t.outcome_text()
            );
            return if outcome == GoalOutcome::Succeeded {
                Ok(())
            } else {
                bail!("goal ended {}", outcome.name())
            };
        }
        if last_print.elapsed() > Duration::from_secs(1) {
            last_print = Instant::now();
            let s = &t.state;
            let via = match t.active_subgoal() {
                Some(g) => format!(", via subgoal ({:.1}, {:.1})", g.x, g.y),
                None => String::new(),
            };
            println!(
                "at ({:.2}, {:.2}) {:.2} m/s, error {:.2} m{via}",
                s.x_f, s.y_f, s.v_f, t.pose_error_xy
            );
        }
    }
    bail!("no outcome within {timeout:?}")
}

/// `--prefix P` (default `wlnav`, the daemon's).
fn prefix_arg() -> Result<String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.as_slice() {
        [] => Ok("wlnav".into()),
        [flag, p] if flag == "--prefix" => Ok(p.clone()),
        _ => bail!("usage: goal-client [--prefix P]"),
    }
}
