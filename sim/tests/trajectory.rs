//! The trajectory optimiser `wlnav-sim` plans with (issue 42,
//! `trajopt::trajectory`), checked against computations of its own: the model's
//! position rates between the samples, the bounds, the world's whole
//! clearance query (not the NLP's rows), the min-time bound with no margin
//! (a lower bound on its duration) and the route it was warm-started from.

use control::model::{f_continuous, ix, wrap_angle, Control, Goal, MachineParams, State};
use control::obstacle::Obstacle;
use control::planner::world::CheckedWorld;
use control::planner::{
    NavigatorSettings, PlanJob, PlanKind, RoutePlanner, TrajectoryFailure, TrajectoryOptimiser,
};
use control::scenario::{self, Scenario};
use sim::runner::{EvalConfig, Method, Networks};
use trajopt::ocp::{solve_min_time, MinTimeSettings};
use trajopt::trajectory::{IpoptTrajectory, TrajectorySettings};

/// The default settings with time enough for a debug build on a loaded
/// machine: the CPU-time cap (the anytime bound) must not decide a test.
fn generous() -> TrajectorySettings {
    TrajectorySettings {
        max_solve_seconds: 60.0,
        ..TrajectorySettings::default()
    }
}

fn manifest(path: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(path)
}

/// A wall across the straight path at x = 4, |y| ≤ 3.2 (the planner's tests').
fn wall() -> Vec<Obstacle> {
    (-4..=4)
        .map(|k| Obstacle::new(4.0, 0.8 * k as f64, 0.6))
        .collect()
}

#[test]
fn the_trajectory_round_a_wall_follows_the_model_keeps_the_margins_and_beats_its_route() {
    let p = MachineParams::default();
    let settings = NavigatorSettings::default();
    let start = State::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    let goal = Goal::new(8.0, 0.0, 0.0);
    // The searched route, as the planner makes it (no optimiser).
    let mut planner = RoutePlanner::new(p, &settings, None).unwrap();
    let mut job = PlanJob::new(&p, &settings.search);
    job.request.kind = PlanKind::First;
    job.request.start = start;
    job.request.goal = goal;
    job.request.world.set_circles(&wall()).unwrap();
    planner.plan(&mut job);
    let path = job.route.path.clone();
    assert!(path.len() > 10);
    let route_length: f64 = path
        .windows(2)
        .map(|w| (w[1].x - w[0].x).hypot(w[1].y - w[0].y))
        .sum();

    let margin = settings.search.clearance_margin;
    let mut world = CheckedWorld::new(p, 16, margin);
    world.set(&wall()).unwrap();
    let ts = generous();
    let mut optimiser = IpoptTrajectory::new(p, ts);
    let mut out = Vec::with_capacity(4096);
    let dt = optimiser
        .optimise(&world, &start, &goal, &path, &job.route.shot, &mut out)
        .expect("a trajectory round the wall");
    let duration = dt * (out.len() - 1) as f64;

    // From the start to the goal (within the tolerance), at rest there.
    assert_eq!(out[0], start);
    let end = out.last().unwrap();
    let error = (end[ix::X] - goal.x)
        .hypot(end[ix::Y] - goal.y)
        .hypot(wrap_angle(end[ix::THETA] - goal.theta));
    assert!(error <= ts.tolerance + 1e-6, "ends {error} from the goal");
    assert!(end[ix::V].abs() < 1e-6 && end[ix::BETA_DOT].abs() < 1e-6);
    let mut fastest_turn = 0.0f64;
    for (i, x) in out.iter().enumerate() {
        // Within the model's bounds.
        assert!(x[ix::BETA].abs() <= p.beta_max + 1e-6, "state {i}: {x:?}");
        // β̇ within its share of the bound (the tracker's room), but a hair
        // of the cubic between the nodes.
        let rate = ts.beta_dot_fraction * p.beta_dot_max;
        assert!(x[ix::BETA_DOT].abs() <= rate + 1e-3, "state {i}: {x:?}");
        fastest_turn = fastest_turn.max(x[ix::BETA_DOT].abs());
        assert!(x[ix::V].abs() <= p.v_max + 1e-6, "state {i}");
        // The whole world's clearance, not the rows the NLP kept: the
        // route's margin plus the trajectory's own, less 1 cm of slack.
        let c = world.state_clearance(x);
        assert!(c >= margin + ts.margin - 0.0101, "state {i}: clearance {c}");
    }
    // A minimum-time trajectory turns as fast as it may (the share binds).
    let rate = ts.beta_dot_fraction * p.beta_dot_max;
    assert!(
        fastest_turn > 0.98 * rate,
        "fastest β̇ {fastest_turn}, share {rate}"
    );
    // The front axle moves as the model says between samples (trapezoid
    // of the model's position rates; the controls do not enter them).
    for (i, w) in out.windows(2).enumerate() {
        let (f0, f1) = (
            f_continuous(&p, &w[0], &Control::zeros()),
            f_continuous(&p, &w[1], &Control::zeros()),
        );
        for c in [ix::X, ix::Y, ix::THETA] {
            let measured = (w[1][c] - w[0][c]) / dt;
            let model = 0.5 * (f0[c] + f1[c]);
            assert!(
                (measured - model).abs() < 0.03,
                "interval {i}, component {c}: {measured} vs {model}"
            );
        }
    }
    // No faster than the bound without margins; shorter than the route,
    // and faster than the route driven at top speed from rest to rest.
    let scenario = Scenario {
        name: "wall".into(),
        start,
        goal,
        obstacles: wall(),
    };
    let bound = solve_min_time(&p, &scenario, &MinTimeSettings::default(), &[]);
    assert!(bound.plan.is_some());
    assert!(
        duration >= bound.time - 1e-3,
        "{duration} < T* {}",
        bound.time
    );
    let length: f64 = out
        .windows(2)
        .map(|w| (w[1][ix::X] - w[0][ix::X]).hypot(w[1][ix::Y] - w[0][ix::Y]))
        .sum();
    assert!(length < route_length, "{length} m, route {route_length} m");
    let route_time = route_length / p.v_max + p.v_max / p.a_max;
    assert!(duration < route_time, "{duration} s, route {route_time} s");
}

/// A goal facing a wall closer than the route's margin plus the trajectory's
/// own (a bucket at a pile face): the trajectory keeps what the goal leaves
/// (the route's margin, no less) instead of asking the impossible.
#[test]
fn a_goal_nearer_a_wall_than_the_trajectorys_margin_is_still_reached() {
    let p = MachineParams::default();
    let settings = NavigatorSettings::default();
    let margin = settings.search.clearance_margin;
    let ts = generous();
    let wall: Vec<Obstacle> = (-4..=4)
        .map(|k| Obstacle::new(8.0, 0.8 * k as f64, 0.6))
        .collect();
    let start = State::new(0.0, 1.0, 0.0, 0.0, 0.0, 0.0);
    // Half the trajectory's margin beyond the route's.
    let goal = Goal::new(8.0 - 0.6 - margin - 0.5 * ts.margin, 0.0, 0.0);
    let mut planner = RoutePlanner::new(p, &settings, None).unwrap();
    let mut job = PlanJob::new(&p, &settings.search);
    job.request.kind = PlanKind::Replan; // always a search
    job.request.start = start;
    job.request.goal = goal;
    job.request.world.set_circles(&wall).unwrap();
    planner.plan(&mut job);
    assert!(!job.route.path.is_empty() || !job.route.shot.is_empty());

    let mut world = CheckedWorld::new(p, 16, margin);
    world.set(&wall).unwrap();
    let mut optimiser = IpoptTrajectory::new(p, ts);
    let mut out = Vec::with_capacity(4096);
    optimiser
        .optimise(
            &world,
            &start,
            &goal,
            &job.route.path,
            &job.route.shot,
            &mut out,
        )
        .expect("a trajectory to the goal at the wall");
    let end = out.last().unwrap();
    let error = (end[ix::X] - goal.x)
        .hypot(end[ix::Y] - goal.y)
        .hypot(wrap_angle(end[ix::THETA] - goal.theta));
    assert!(error <= ts.tolerance + 1e-6, "ends {error} from the goal");
    for (i, x) in out.iter().enumerate() {
        let c = world.state_clearance(x);
        assert!(c >= margin - 0.0101, "state {i}: clearance {c}");
    }
}

#[test]
fn no_trajectory_where_the_warm_start_is_empty() {
    let p = MachineParams::default();
    let world = CheckedWorld::new(p, 16, 0.15);
    let mut optimiser = IpoptTrajectory::new(p, TrajectorySettings::default());
    let mut out = Vec::with_capacity(16);
    let start = State::zeros();
    let none = optimiser.optimise(
        &world,
        &start,
        &Goal::new(0.0, 0.0, 0.0),
        &[],
        &[],
        &mut out,
    );
    assert_eq!(none, Err(TrajectoryFailure::NoWarmStart));
}

/// In closed loop (the committed networks, the daemon's pilot, plans charged
/// one tick): on three goals of obstacles200 where a searched route is
/// followed well but long (`wall027`, `gap023`) or stalls on the way
/// (`circles029`), the MPC tracking the trajectory reaches each, keeps
/// clear, and is seconds faster than following the route (measured: 4.8,
/// 4.2 and 14.0 s).
#[test]
fn tracking_the_trajectory_is_faster_than_following_the_route() {
    let nets = Networks::load(&manifest("..").join(control::weights::DEFAULT_DIR)).unwrap();
    let names = ["wall027", "gap023", "circles029"];
    let text = std::fs::read_to_string(manifest("scenarios/obstacles200.csv")).unwrap();
    let set: Vec<Scenario> = scenario::parse(&text, "obstacles200.csv")
        .unwrap()
        .into_iter()
        .filter(|s| names.contains(&s.name.as_str()))
        .collect();
    assert_eq!(set.len(), names.len());
    let [followed, tracked] = [false, true].map(|trajectory| {
        let mut cfg = EvalConfig {
            params: nets.machine,
            methods: vec![Method::Mpc],
            navigator: Some(NavigatorSettings {
                trajectory,
                ..Default::default()
            }),
            trajectory: generous(),
            jobs: 2,
            progress: false,
            ..Default::default()
        };
        // Ample: the same QPs whatever the machine's load.
        cfg.mpc.time_budget = 1.0;
        sim::eval::evaluate(&cfg, &nets, &set).unwrap()
    });
    for (f, t) in followed.rows.iter().zip(&tracked.rows) {
        assert!(t.success, "{} not reached tracking", t.name);
        assert!(t.min_clearance.unwrap() > -0.005, "{t:?}");
        let (tf, tt) = (f.t_converge.unwrap_or(f64::INFINITY), t.t_converge.unwrap());
        assert!(tt + 2.0 < tf, "{}: tracked {tt} s, followed {tf} s", t.name);
    }
    // navigation.csv says which plans were shaped: each goal's first plan
    // tracked (the trajectory's duration: about the run's, which enters the
    // goal's tolerance a little before the trajectory's end at rest), none
    // followed.
    let trajectory_cells = |ev: &sim::eval::Evaluation| -> Vec<(String, String)> {
        let csv = sim::eval::navigation_csv(ev).unwrap();
        let mut lines = csv.lines();
        let header: Vec<&str> = lines.next().unwrap().split(',').collect();
        let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
        let (plan, trajectory) = (col("plan"), col("trajectory"));
        lines
            .map(|l| l.split(',').collect::<Vec<_>>())
            .filter(|f| f[plan] == "0")
            .map(|f| (f[0].to_string(), f[trajectory].to_string()))
            .collect()
    };
    let firsts = trajectory_cells(&tracked);
    assert_eq!(firsts.len(), names.len());
    for (name, cell) in firsts {
        let row = tracked.rows.iter().find(|r| r.name == name).unwrap();
        let seconds: f64 = cell.trim_end_matches(" s").parse().unwrap_or(f64::NAN);
        let t = row.t_converge.unwrap();
        assert!(
            seconds > 0.5 * t && seconds < t + 1.0,
            "{name}: {cell}, run {t} s"
        );
    }
    assert!(trajectory_cells(&followed)
        .iter()
        .all(|(_, c)| c.is_empty()));
}
