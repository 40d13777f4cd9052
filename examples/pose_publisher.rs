//! A localization stand-in: publishes pose estimates to wlnavd, as a localization
//! module on the machine would.
//!
//! It knows the start pose and dead-reckons from the machine state the daemon reports
//! in its telemetry (articulation β, its rate β̇ and the front speed v_f, from CAN),
//! with the front-axle kinematics of DESIGN §2:
//! ẋ_f = v cos θ, ẏ_f = v sin θ, θ̇ = (v sin β + L_r β̇) / (L_f cos β + L_r).
//! A real module would fuse GNSS, lidar and this odometry; what wlnavd needs from it is
//! the same: front-axle pose, heading, a monotonic timestamp taken when the pose was
//! valid, at 10–50 Hz, from one publisher.
//!
//! ```sh
//! wlnavd --sim --prefix demo --config examples/external-pose.toml &   # sim.publish_pose = false
//! cargo run --release -p wlnav-examples --bin pose-publisher -- --prefix demo
//! ```
//!
//! It sends one goal 3 m ahead and exits 0 once the daemon has taken its poses through
//! the whole drive (no stale or rejected pose, the goal succeeded); 1 otherwise. Its
//! timeouts (not the pose rate) are multiplied by `WLNAV_TIMING_SCALE` when set (a slower
//! CPU, e.g. the arm64 daemon under qemu in `scripts/cross-check.sh`;
//! `tests/timing_scale.rs`).

use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use shm_ipc::{fault_flags, monotonic_now_ns, Client, GoalOutcome, IpcConfig, Pose2, PoseEstimate};

#[path = "../tests/timing_scale.rs"]
mod timing_scale;
use timing_scale::real;

/// The Avant 635's axle distances from the joint [m] (`[machine]` l_f, l_r).
const L_F: f64 = 0.6;
const L_R: f64 = 0.6;
/// Poses per second.
const RATE_HZ: f64 = 20.0;

fn main() -> Result<()> {
    let prefix = prefix_arg()?;
    let client = Client::connect(
        &IpcConfig::new(prefix.clone()),
        real(Duration::from_secs(20)),
    )
    .with_context(|| format!("no wlnavd on prefix `{prefix}`"))?;
    let telemetry = client.subscribe_telemetry()?;

    // The simulated machine starts at the origin (`sim.initial_state`).
    let (mut x, mut y, mut theta) = (0.0_f64, 0.0_f64, 0.0_f64);
    let (mut beta, mut beta_dot, mut v) = (0.0_f64, 0.0_f64, 0.0_f64);
    let mut sequence = 0u32;
    let mut request_id = None;
    let mut pose_faults = 0u32;
    let period = Duration::from_secs_f64(1.0 / RATE_HZ);
    let timeout = real(Duration::from_secs(60));
    let start = Instant::now();
    let mut last = Instant::now();
    while start.elapsed() < timeout {
        // Odometry: integrate over the time since the last pose.
        let now = Instant::now();
        let dt = (now - last).as_secs_f64();
        last = now;
        let theta_dot = (v * beta.sin() + L_R * beta_dot) / (L_F * beta.cos() + L_R);
        x += v * theta.cos() * dt;
        y += v * theta.sin() * dt;
        theta += theta_dot * dt;
        let stamp = monotonic_now_ns();
        client.publish_pose(&PoseEstimate::new(stamp, sequence, Pose2::new(x, y, theta)))?;
        sequence = sequence.wrapping_add(1);

        // The newest machine state, and what the daemon made of our poses.
        while let Some(t) = telemetry.try_recv()? {
            if t.state.beta.is_finite() && t.state.v_f.is_finite() {
                (beta, beta_dot, v) = (t.state.beta, t.state.beta_dot, t.state.v_f);
            }
            let faults = t.fault_flags & (fault_flags::POSE_STALE | fault_flags::POSE_REJECTED);
            if request_id.is_some() && faults != 0 {
                pose_faults += 1;
            }
            if Some(t.outcome_request_id) == request_id {
                let outcome = t
                    .outcome()
                    .map_err(|c| anyhow::anyhow!("unknown outcome {c}"))?;
                println!(
                    "goal: {} ({}); pose at ({x:.2}, {y:.2}, {theta:.2})",
                    outcome.name(),
                    t.outcome_text()
                );
                if outcome != GoalOutcome::Succeeded {
                    bail!("goal ended {}", outcome.name());
                }
                if pose_faults > 0 {
                    bail!("{pose_faults} ticks flagged the poses stale or rejected");
                }
                println!("{sequence} poses published, all taken");
                return Ok(());
            }
        }
        // Once the daemon has a pose, drive somewhere.
        if request_id.is_none() && sequence % 10 == 0 {
            let reply =
                client.set_goal(Pose2::new(3.0, 0.0, 0.0), &[], real(Duration::from_secs(1)))?;
            if reply.is_accepted() {
                println!("goal {} accepted", reply.request_id);
                request_id = Some(reply.request_id);
            }
        }
        std::thread::sleep(period.saturating_sub(now.elapsed()));
    }
    bail!("no outcome within {timeout:?}")
}

/// `--prefix P` (default `wlnav`, the daemon's).
fn prefix_arg() -> Result<String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.as_slice() {
        [] => Ok("wlnav".into()),
        [flag, p] if flag == "--prefix" => Ok(p.clone()),
        _ => bail!("usage: pose-publisher [--prefix P]"),
    }
}
