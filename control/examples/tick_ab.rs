//! The MPC tick (`Mpc::step`: delay compensation, critic derivatives, QP
//! assembly and solve, output) timed on the bench's closed loop with 0, 2 or 8
//! circles, written against the API that older commits have too, so that an
//! old and a new build can be run alternately in one session (issue 30):
//!
//! ```text
//! cargo run --release -p control --example tick_ab -- ROUNDS [TICKS [N/HESSIAN/CIRCLES ...]]
//! ```
//!
//! Prints one CSV line per (round, horizon, Hessian, circles): the median and
//! p99 of TICKS ticks (default 300) after 20 warm-up ticks, and the mean QP
//! time and QP iterations per tick. The machine restarts from the origin every
//! 150 ticks. Cases (e.g. `20/Exact/2`) select some; default all 18. Under
//! `valgrind --tool=callgrind` (instructions, not seconds: unaffected by other
//! jobs) the difference between two TICKS counts is the ticks' own cost.
//!
//! `WLNAV_QP_SOLVER=riccati` (or `clarabel`) picks the QP solver in builds
//! that have `MpcSettings::qp_solver` (issue 30); it is set through serde so
//! that this file still builds at older commits, which reject it at run time.

use std::time::Instant;

use control::model::{MachineParams, State};
use control::mpc::{Mpc, MpcSettings, Obstacle};
use control::{Critic, HessianMode, Plant, PlantConfig};

#[path = "../benches/workload/mod.rs"]
mod workload;
use workload::{CIRCLES, GOAL};

/// The circles of a case: none, the bench's two, or all eight.
fn circles(n: usize) -> Vec<Obstacle> {
    CIRCLES[..n].to_vec()
}

fn critic() -> (Critic, control::Actor) {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join(control::weights::DEFAULT_DIR);
    control::networks::load_networks(&dir, &MachineParams::default(), MpcSettings::default().dt)
        .unwrap_or_else(|e| panic!("the committed networks: {e}"))
}

/// `settings` with `WLNAV_QP_SOLVER`'s solver, if set (through serde: see above).
fn with_solver(settings: MpcSettings) -> MpcSettings {
    let Ok(solver) = std::env::var("WLNAV_QP_SOLVER") else {
        return settings;
    };
    let mut v = serde_json::to_value(settings).expect("settings serialise");
    v["qp_solver"] = serde_json::Value::String(solver.clone());
    serde_json::from_value(v)
        .unwrap_or_else(|e| panic!("WLNAV_QP_SOLVER={solver}: not in this build ({e})"))
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let rounds: usize = args
        .first()
        .map_or(Ok(1), |s| s.parse())
        .unwrap_or_else(|e| panic!("ROUNDS: {e}"));
    let measured: usize = args
        .get(1)
        .map_or(Ok(300), |s| s.parse())
        .unwrap_or_else(|e| panic!("TICKS: {e}"));
    let cases = &args[args.len().min(2)..];
    let p = MachineParams::default();
    let (critic, actor) = critic();
    println!(
        "round,horizon,hessian,circles,tick_median_ms,tick_p99_ms,qp_mean_ms,qp_iterations_mean"
    );
    for round in 0..rounds {
        for horizon in [10, 20, 40] {
            for hessian in [HessianMode::Exact, HessianMode::GaussNewton] {
                for n in [0, 2, 8] {
                    let case = format!("{horizon}/{hessian:?}/{n}");
                    if !cases.is_empty() && !cases.contains(&case) {
                        continue;
                    }
                    let settings = with_solver(MpcSettings {
                        horizon,
                        hessian,
                        // No time limit: a loaded machine (or callgrind, ~50× slower)
                        // must not turn QPs into time-outs and change the work done.
                        time_budget: 1e3,
                        ..MpcSettings::default()
                    });
                    let obstacles = circles(n);
                    let mut mpc = Mpc::new(p, critic.clone(), Some(actor.clone()), settings)
                        .expect("valid settings");
                    let mut plant =
                        Plant::new(p, PlantConfig::default(), State::zeros()).expect("valid plant");
                    mpc.set_goal(GOAL, &obstacles).expect("valid goal");
                    let (mut ticks, mut qp_s, mut qp_it) = (Vec::new(), 0.0, 0u64);
                    for k in 0..20 + measured {
                        if k % 150 == 0 {
                            mpc.reset();
                            mpc.set_goal(GOAL, &obstacles).expect("valid goal");
                            plant = Plant::new(p, PlantConfig::default(), State::zeros())
                                .expect("valid plant");
                        }
                        let now = k as f64 * settings.dt;
                        let x = plant.state();
                        let start = Instant::now();
                        let sol = mpc.step(&x, now).expect("goal set");
                        let elapsed = start.elapsed().as_secs_f64() * 1e3;
                        let cmd = sol.command;
                        if k >= 20 {
                            ticks.push(elapsed);
                            qp_s += sol.qp_time.as_secs_f64();
                            qp_it += u64::from(sol.qp_iterations);
                        }
                        mpc.sent(now, cmd);
                        plant.command(cmd).expect("finite command");
                        plant.advance(settings.dt);
                    }
                    ticks.sort_by(f64::total_cmp);
                    let m = ticks.len();
                    println!(
                        "{round},{horizon},{hessian:?},{n},{:.3},{:.3},{:.3},{:.1}",
                        ticks[m / 2],
                        ticks[(m * 99) / 100],
                        qp_s * 1e3 / m as f64,
                        qp_it as f64 / m as f64
                    );
                }
            }
        }
    }
}
