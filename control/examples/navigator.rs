//! The global layer on three blocked scenes (a wall, a gap between two walls,
//! an enclosed goal): the route it hands the MPC and how long planning took.
//!
//! With a scenario file, times the first plan of every scenario
//! instead: the smallest of five runs each (the least disturbed by other
//! load on the machine), then median / p90 / p99 / max over the file.
//!
//! ```text
//! cargo run --release -p control --example navigator [-- SCENARIOS.csv]
//! ```

use control::model::{Goal, MachineParams, State};
use control::mpc::MpcSettings;
use control::obstacle::Obstacle;
use control::planner::{NavigatorSettings, PlanJob, PlanKind, PlanReport, RoutePlanner};
use control::weights;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join(weights::DEFAULT_DIR);
    let (critic, actor) = control::networks::load_networks(
        &dir,
        &MachineParams::default(),
        MpcSettings::default().dt,
    )?;
    drop(critic);
    let settings = NavigatorSettings::default();
    let file = std::env::args().nth(1);
    let mut planner = RoutePlanner::new(MachineParams::default(), &settings, Some(actor))?;
    let mut job = PlanJob::new(&MachineParams::default(), &settings.search);

    if let Some(file) = file {
        let set = control::scenario::parse(&std::fs::read_to_string(&file)?, &file)?;
        let mut times = Vec::new();
        let mut searched = Vec::new();
        for sc in &set {
            let mut best = f64::INFINITY;
            for _ in 0..5 {
                let r = plan(&mut planner, &mut job, &sc.start, sc.goal, &sc.obstacles);
                best = best.min(r.duration.as_secs_f64() * 1e3);
                if r.search.expansions > 0 && searched.len() < times.len() + 1 {
                    searched.push(f64::INFINITY);
                }
            }
            times.push(best);
            if let Some(last) = searched.last_mut().filter(|v| v.is_infinite()) {
                *last = best;
            }
        }
        for (name, v) in [("all plans", &mut times), ("searches", &mut searched)] {
            v.sort_by(f64::total_cmp);
            let q = |p: f64| v[((v.len() - 1) as f64 * p).round() as usize];
            println!(
                "{name}: n {} median {:.2} / p90 {:.2} / p99 {:.2} / max {:.2} ms",
                v.len(),
                q(0.5),
                q(0.9),
                q(0.99),
                q(1.0)
            );
        }
        return Ok(());
    }
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
        let r = plan(&mut planner, &mut job, &State::zeros(), goal, obstacles);
        println!(
            "{name:>10}: {:?} in {:.2} ms ({} expansions, {} nodes, {} shots); route:",
            r.outcome,
            r.duration.as_secs_f64() * 1e3,
            r.search.expansions,
            r.search.nodes,
            r.search.shots
        );
        for g in &job.route.targets {
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

/// A goal's first plan from `start`, what the planner thread runs for it.
fn plan(
    planner: &mut RoutePlanner,
    job: &mut PlanJob,
    start: &State,
    goal: Goal,
    obstacles: &[Obstacle],
) -> PlanReport {
    job.request.kind = PlanKind::First;
    job.request.start = *start;
    job.request.goal = goal;
    job.request
        .world
        .set_circles(obstacles)
        .expect("the scenario file's circles were validated when parsed");
    planner.plan(job);
    job.route.report
}
