//! The global layer on three blocked scenes (a wall, a gap between two walls,
//! an enclosed goal): the route it hands the MPC and how long planning took.
//!
//! ```text
//! cargo run --release -p control --example navigator [-- waypoint-graph]
//! ```

use control::model::{Goal, MachineParams, State};
use control::obstacle::Obstacle;
use control::planner::{Navigator, NavigatorSettings, PlannerKind};
use control::weights::decode;
use control::{Actor, Critic};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let planner = match std::env::args().nth(1).as_deref() {
        Some("waypoint-graph") => PlannerKind::WaypointGraph,
        _ => PlannerKind::HybridAStar,
    };
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../critic-weights/");
    let read = |name: &str| -> Result<_, Box<dyn std::error::Error>> {
        let path = format!("{dir}{name}");
        Ok(decode(&std::fs::read(&path)?, &path)?)
    };
    let networks = (
        Actor::from_weights(read("actor.safetensors")?)?,
        Critic::from_weights(read("critic.safetensors")?)?,
    );
    let mut settings = NavigatorSettings {
        planner,
        ..NavigatorSettings::default()
    };
    if let Some(w) = std::env::args().nth(2).and_then(|w| w.parse().ok()) {
        settings.heuristic_weight = w;
    }
    let mut nav = Navigator::new(MachineParams::default(), settings, Some(networks))?;
    let wall: Vec<Obstacle> = (-4..=4)
        .map(|k| Obstacle::new(4.0, 0.8 * k as f64, 0.6))
        .collect();
    let mut gap = Vec::new();
    for k in 0..4 {
        let d = 1.5 + 0.8 * k as f64;
        gap.push(Obstacle::new(4.0, 2.0 + d, 0.5));
        gap.push(Obstacle::new(4.0, 2.0 - d, 0.5));
    }
    let ring: Vec<Obstacle> = (0..16)
        .map(|k| {
            let a = k as f64 * std::f64::consts::TAU / 16.0;
            Obstacle::new(8.0 + 2.5 * a.cos(), 2.5 * a.sin(), 0.6)
        })
        .collect();
    let one = vec![Obstacle::new(4.0, 0.2, 0.9)];
    let goal = Goal::new(8.0, 0.0, 0.0);
    for (name, obstacles) in [
        ("one circle", &one),
        ("wall", &wall),
        ("gap", &gap),
        ("ring", &ring),
    ] {
        nav.set_goal(&State::zeros(), goal, obstacles)?;
        let r = nav.last_plan().expect("set_goal plans");
        println!(
            "{name:>10}: {:?} in {:.2} ms ({} expansions, {} nodes, {} shots); route:",
            r.outcome,
            r.duration.as_secs_f64() * 1e3,
            r.search.expansions,
            r.search.nodes,
            r.search.shots
        );
        for g in nav.route() {
            println!(
                "            ({:6.2}, {:6.2}, {:6.1}°)",
                g.x,
                g.y,
                g.theta.to_degrees()
            );
        }
    }
    Ok(())
}
