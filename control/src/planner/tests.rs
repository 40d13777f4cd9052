//! Behaviour of the global layer: collision checks of both axles, routes
//! around a wall and through a gap, none for an enclosed goal, the direct
//! case, subgoal switching, replanning and the abort window.

use super::hybrid_astar::primitive_free;
use super::primitives::{build, compose};
use super::*;
use crate::critic::CriticWorkspace;
use crate::goal_check::GoalConflict;
use crate::model::{goal_distance, ix, Control, Goal, MachineParams, State};
use crate::mpc::MpcSettings;
use crate::obstacle::Obstacle;
use crate::obstacle::{footprint_clearance, AxlePoint};
use crate::weights;
use crate::{Actor, Critic};

/// Wall-clock limits are multiplied by `WLNAV_TIMING_SCALE` (default 1; the one factor
/// for emulation, set by scripts/cross-check.sh for the tests under qemu): the shared
/// helper of every crate's tests.
#[path = "../../../tests/timing_scale.rs"]
mod timing_scale;

fn params() -> MachineParams {
    MachineParams::default()
}

/// The default machine's trained networks (`critic-weights/avant635/`).
fn trained() -> (Actor, Critic) {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join(weights::DEFAULT_DIR);
    let (critic, actor) =
        crate::networks::load_networks(&dir, &MachineParams::default(), MpcSettings::default().dt)
            .expect("the committed weights");
    (actor, critic)
}

fn navigator(networks: bool) -> Navigator {
    Navigator::new(
        params(),
        NavigatorSettings::default(),
        networks.then(trained),
    )
    .unwrap()
}

/// With and without the networks (the roll-outs and goal shots).
const COMBINATIONS: [bool; 2] = [false, true];

fn at_rest(x: f64, y: f64, theta: f64) -> State {
    State::new(x, y, theta, 0.0, 0.0, 0.0)
}

fn at_moving(x: f64, y: f64, theta: f64, beta: f64, v: f64) -> State {
    State::new(x, y, theta, beta, 0.0, v)
}

/// A wall across the straight path at x = 4, |y| ≤ 3.2.
fn wall() -> Vec<Obstacle> {
    (-4..=4)
        .map(|k| Obstacle::new(4.0, 0.8 * k as f64, 0.6))
        .collect()
}

/// Two long walls at x = 4 with a gap around y = 2 (2 m between the
/// circles' edges), off the straight line y = 0.
fn gap() -> Vec<Obstacle> {
    let mut v = Vec::new();
    for k in 0..8 {
        let d = 1.5 + 0.8 * k as f64;
        v.push(Obstacle::new(4.0, GAP_Y + d, 0.5));
        v.push(Obstacle::new(4.0, GAP_Y - d, 0.5));
    }
    v
}

const GAP_Y: f64 = 2.0;

/// A closed ring of circles around (8, 0).
fn ring() -> Vec<Obstacle> {
    (0..16)
        .map(|k| {
            let a = k as f64 * std::f64::consts::TAU / 16.0;
            Obstacle::new(8.0 + 2.5 * a.cos(), 2.5 * a.sin(), 0.6)
        })
        .collect()
}

/// Every path pose, and every primitive sample between consecutive poses,
/// keeps both axle points at least `margin` from every circle.
fn assert_path_clear(nav: &Navigator, obstacles: &[Obstacle], margin: f64) {
    let p = params();
    let path = nav.path();
    assert!(!path.is_empty());
    for q in path {
        let s = State::new(q.x, q.y, q.theta, q.beta, 0.0, 0.0);
        let c = footprint_clearance(&p, &s, obstacles);
        assert!(c >= margin - 1e-9, "pose {q:?} clearance {c}");
    }
}

#[test]
fn the_world_sees_an_obstacle_only_the_rear_axle_touches() {
    let p = params();
    let mut world = CheckedWorld::new(p, 4, 0.1);
    let rear = AxlePoint::Rear.position(&p, &at_rest(0.0, 0.0, 0.3));
    world.set(&[Obstacle::new(rear[0], rear[1], 0.2)]).unwrap();
    assert!(!world.pose_free(0.0, 0.0, 0.3, 0.0));
    assert!(!world.state_free(&at_rest(0.0, 0.0, 0.3)));
    // The front axle alone is 1.2 − 0.2 m clear.
    assert!(world.obstacles()[0].clearance_of([0.0, 0.0]) > 0.9);
}

#[test]
fn primitive_checks_catch_the_rear_axle_along_the_arc_and_in_the_swing() {
    let p = params();
    let prims = build(&p, &[0.0, p.beta_max], 0.6, 0.15);
    let straight = prims
        .iter()
        .find(|q| q.beta == 0.0 && q.direction == 1)
        .unwrap();
    let mut world = CheckedWorld::new(p, 4, 0.0);
    // Driving straight ahead 0.6 m, the rear axle passes x = −0.9 (it starts
    // at −1.2); the front axle never comes within a metre of it.
    world.set(&[Obstacle::new(-0.9, 0.0, 0.1)]).unwrap();
    assert!(world.pose_free(0.0, 0.0, 0.0, 0.0), "the start is free");
    for rel in &straight.samples {
        let q = compose(0.0, 0.0, 0.0, rel);
        assert!(world.obstacles()[0].clearance_of([q[0], q[1]]) > 0.9);
    }
    assert!(!primitive_free(&world, &[0.0, 0.0, 0.0], 0.0, straight));

    // Articulating from β = 0 to β_max at rest swings the rear axle to
    // `swung`; a small circle there blocks the primitive from β = 0, but not
    // from a node already articulated (its samples are clear).
    let left = prims
        .iter()
        .find(|q| q.beta == p.beta_max && q.direction == 1)
        .unwrap();
    let swung = AxlePoint::Rear.position(&p, &State::new(0.0, 0.0, 0.0, p.beta_max, 0.0, 0.0));
    world
        .set(&[Obstacle::new(swung[0], swung[1], 0.05)])
        .unwrap();
    assert!(world.pose_free(0.0, 0.0, 0.0, 0.0), "the start is free");
    assert!(primitive_free(&world, &[0.0, 0.0, 0.0], p.beta_max, left));
    assert!(!primitive_free(&world, &[0.0, 0.0, 0.0], 0.0, left));
}

#[test]
fn open_ground_is_direct_from_the_first_tick() {
    for networks in [false, true] {
        let mut nav = navigator(networks);
        let goal = Goal::new(6.0, 3.0, 1.0);
        // No obstacles; without networks also one well off the way (the
        // straight corridor is open: no roll-out to follow).
        let mut worlds = vec![vec![]];
        if !networks {
            worlds.push(vec![Obstacle::new(-5.0, -5.0, 1.0)]);
        }
        for obstacles in worlds {
            nav.set_goal(&at_rest(0.0, 0.0, 0.0), goal, &obstacles, 0.0)
                .unwrap();
            assert_eq!(nav.route(), &[goal]);
            assert!(nav.path().is_empty());
            assert_eq!(nav.last_plan().unwrap().outcome, PlanOutcome::Direct);
            assert_eq!(
                nav.update(&at_rest(0.0, 0.0, 0.0), 0.0),
                NavStep::Drive {
                    target: goal,
                    final_target: true
                }
            );
        }
    }
}

/// The open way among circles is followed along the actor's roll-out that
/// found it open, not left to the critic: from dock024 of obstacles200 the
/// roll-out drives forwards round the piles (the critic alone reverses into
/// them and stalls), from wall008 it reverses past the wall's end (followed
/// by the rear axle). The path starts at the start, keeps the open way's
/// margin, ends at the goal, and its part is the MPC's cost from the first
/// tick.
#[test]
fn the_open_way_among_circles_is_followed_along_the_actors_roll_out() {
    let cases = [
        (
            at_moving(0.0, 0.0, 2.8155, 0.1833, 0.4526),
            Goal::new(5.5582, 6.6696, -0.6948),
            vec![
                Obstacle::new(4.0131, 4.8155, 1.7558),
                Obstacle::new(2.3571, 4.0371, 0.8509),
                Obstacle::new(5.6369, 4.2754, 0.8488),
            ],
            AxlePoint::Front,
        ),
        (
            at_rest(0.0, 0.0, -1.5973),
            Goal::new(-5.5091, 5.0215, 1.2272),
            (0..5)
                .map(|k| {
                    let f = k as f64;
                    Obstacle::new(-1.9519 - 0.5005 * f, 4.1907 - 0.6551 * f, 0.5496)
                })
                .collect(),
            AxlePoint::Rear,
        ),
    ];
    for (start, goal, obstacles, point) in cases {
        let mut nav =
            Navigator::new(params(), NavigatorSettings::default(), Some(trained())).unwrap();
        nav.set_goal(&start, goal, &obstacles, 0.0).unwrap();
        assert_eq!(nav.last_plan().unwrap().outcome, PlanOutcome::Direct);
        let path = nav.path();
        assert!(path.len() > 10, "{} poses", path.len());
        let first = path[0];
        assert_eq!(
            [first.x, first.y, first.theta],
            [start[ix::X], start[ix::Y], start[ix::THETA]]
        );
        let last = path.last().unwrap();
        assert!((last.x - goal.x).hypot(last.y - goal.y) < 0.5, "{last:?}");
        assert_eq!(*nav.route().last().unwrap(), goal);
        assert_path_clear(&nav, &obstacles, nav.settings().search.direct_margin);
        let expected = if point == AxlePoint::Front { 1 } else { -1 };
        assert!(path.iter().all(|p| p.direction == expected), "{point:?}");
        assert!(matches!(nav.update(&start, 0.0), NavStep::Drive { .. }));
        let cost = nav.path_cost().expect("the roll-out's path is the cost");
        assert_eq!(cost.point(), point);
    }
}

#[test]
fn a_wall_is_in_the_way_and_the_route_goes_around_it() {
    for networks in COMBINATIONS {
        let mut nav = navigator(networks);
        let goal = Goal::new(8.0, 0.0, 0.0);
        let obstacles = wall();
        nav.set_goal(&at_rest(0.0, 0.0, 0.0), goal, &obstacles, 0.0)
            .unwrap();
        let report = nav.last_plan().unwrap();
        assert_eq!(report.outcome, PlanOutcome::Route, "networks {networks}");
        assert_path_clear(&nav, &obstacles, nav.settings().search.clearance_margin);
        // Around the wall's end (|y| ≥ 3.2 + 0.6).
        let widest = nav.path().iter().map(|q| q.y.abs()).fold(0.0, f64::max);
        assert!(widest > 3.8, "path stays within |y| ≤ {widest}");
        let route = nav.route().to_vec();
        assert!(route.len() >= 3, "{route:?}");
        assert_eq!(*route.last().unwrap(), goal);
        // Consecutive subgoals are at most an edge / about the spacing apart.
        let s = nav.settings();
        for w in route.windows(2) {
            let d = (w[1].x - w[0].x).hypot(w[1].y - w[0].y);
            assert!(d <= 2.0 * s.following.subgoal_spacing + 1.0, "{d}");
        }
        // The first tick drives to the end of the path's first forward part:
        // a cusp of the path, or the goal, with the path cost leading there.
        match nav.update(&at_rest(0.0, 0.0, 0.0), 0.0) {
            NavStep::Drive {
                target,
                final_target,
            } => {
                let end = path_geometry::direction_end(nav.path(), 0);
                let p = nav.path()[end];
                if final_target {
                    assert_eq!(target, goal);
                    assert_eq!(end + 1, nav.path().len());
                } else {
                    assert_eq!(target, Goal::new(p.x, p.y, p.theta));
                }
                assert!(nav.path_cost().is_some(), "networks {networks}");
            }
            other => panic!("{other:?}"),
        }
    }
}

/// `wall000` of obstacles-tuning100 (moving and articulated at the start,
/// heading away from the way around): the first goal shot found reaches the
/// goal on a wide loop. Searching on after it finds a cheaper way, and never
/// a dearer one.
#[test]
fn searching_on_after_the_first_shot_finds_a_cheaper_way() {
    let start = State::new(0.0, 0.0, -0.2724, -0.4505, 0.0, 0.6874);
    let goal = Goal::new(7.6888, 1.8681, -0.5231);
    let obstacles: Vec<Obstacle> = [
        (4.116, -0.0826),
        (3.7006, 0.5497),
        (3.285, 1.1821),
        (2.8695, 1.8144),
    ]
    .iter()
    .map(|&(x, y)| Obstacle::new(x, y, 0.5044))
    .collect();
    let plan = |refine_expansions: usize| {
        let mut settings = NavigatorSettings::default();
        settings.search.refine_expansions = refine_expansions;
        let mut nav = Navigator::new(params(), settings, Some(trained())).unwrap();
        nav.set_goal(&start, goal, &obstacles, 0.0).unwrap();
        let report = nav.last_plan().unwrap();
        assert_eq!(report.outcome, PlanOutcome::Route);
        assert_path_clear(&nav, &obstacles, nav.settings().search.clearance_margin);
        report.search
    };
    let (first, refined) = (plan(0), plan(1000));
    assert!(first.cost > 0.0);
    assert!(
        refined.cost < 0.9 * first.cost,
        "refined {} m against the first {} m",
        refined.cost,
        first.cost
    );
    assert!(refined.expansions > first.expansions);
    assert!(refined.expansions <= first.expansions + 1000 + 1);
}

/// Planning every goal: `circles004` of obstacles200 (a circle beside the
/// way, the goal's heading needing a loop) has an open way by the actor's
/// roll-out, but the search finds a cheaper one, which is taken; a goal
/// straight ahead with a circle far aside stays direct (the critic alone):
/// the open way is the cheapest.
#[test]
fn planning_every_goal_takes_the_search_only_where_it_is_cheaper() {
    let start = at_rest(0.0, 0.0, 2.0828);
    let goal = Goal::new(-1.0857, 9.3091, -0.7819);
    let beside = [Obstacle::new(-1.0923, 4.4899, 0.6043)];
    let far = [Obstacle::new(6.0, -6.0, 0.6)];
    let outcome = |plan_every_goal: bool, goal: Goal, obstacles: &[Obstacle]| {
        let mut settings = NavigatorSettings::default();
        settings.search.plan_every_goal = plan_every_goal;
        let mut nav = Navigator::new(params(), settings, Some(trained())).unwrap();
        nav.set_goal(&start, goal, obstacles, 0.0).unwrap();
        (
            nav.last_plan().unwrap().outcome,
            nav.last_plan().unwrap().search.expansions > 0,
        )
    };
    assert_eq!(outcome(false, goal, &beside), (PlanOutcome::Direct, false));
    assert_eq!(outcome(true, goal, &beside), (PlanOutcome::Route, true));
    let ahead = Goal::new(-3.0, 7.0, 2.0828);
    assert_eq!(outcome(true, ahead, &far), (PlanOutcome::Direct, true));
}

#[test]
fn a_gap_between_two_walls_is_taken() {
    for networks in COMBINATIONS {
        let mut nav = navigator(networks);
        let goal = Goal::new(8.0, 0.0, 0.0);
        let obstacles = gap();
        nav.set_goal(&at_rest(0.0, 0.0, 0.0), goal, &obstacles, 0.0)
            .unwrap();
        assert_eq!(
            nav.last_plan().unwrap().outcome,
            PlanOutcome::Route,
            "networks {networks}"
        );
        assert_path_clear(&nav, &obstacles, nav.settings().search.clearance_margin);
        // The path, then the last leg to the goal (a goal shot's), crosses
        // x = 4 between the gap's edges at 1 and 3.
        let mut pts: Vec<(f64, f64)> = nav.path().iter().map(|q| (q.x, q.y)).collect();
        pts.push((goal.x, goal.y));
        let crossing = pts
            .windows(2)
            .find(|w| w[0].0 < 4.0 && w[1].0 >= 4.0)
            .unwrap_or_else(|| panic!("networks {networks}: no crossing of x = 4: {pts:?}"));
        let f = (4.0 - crossing[0].0) / (crossing[1].0 - crossing[0].0);
        let y = crossing[0].1 + f * (crossing[1].1 - crossing[0].1);
        assert!(
            (y - GAP_Y).abs() < 1.0,
            "networks {networks} crosses at y {y}: {crossing:?}"
        );
    }
}

#[test]
fn an_enclosed_goal_has_no_route_and_aborts_on_the_first_tick() {
    for networks in COMBINATIONS {
        let mut nav = navigator(networks);
        let goal = Goal::new(8.0, 0.0, 0.0);
        nav.set_goal(&at_rest(0.0, 0.0, 0.0), goal, &ring(), 0.0)
            .unwrap();
        let report = nav.last_plan().unwrap();
        assert_eq!(report.outcome, PlanOutcome::NoRoute);
        assert!(
            report.duration.as_secs_f64() < timing_scale::secs(0.5),
            "{report:?}"
        );
        assert_eq!(
            nav.update(&at_rest(0.0, 0.0, 0.0), 0.0),
            NavStep::Abort(AbortReason::NoRoute)
        );
        // It stays aborted.
        assert_eq!(
            nav.update(&at_rest(0.1, 0.0, 0.0), 0.2),
            NavStep::Abort(AbortReason::NoRoute)
        );
    }
}

#[test]
fn goals_and_starts_in_collision_are_rejected() {
    let mut nav = navigator(false);
    let obstacles = [Obstacle::new(5.0, 0.0, 1.0)];
    // The goal's rear axle (4.8 − 1.2 = 3.6... no: front at 6.5, rear at 5.3) is inside.
    let e = nav
        .set_goal(
            &at_rest(0.0, 0.0, 0.0),
            Goal::new(6.5, 0.0, 0.0),
            &obstacles,
            0.0,
        )
        .unwrap_err();
    assert!(
        matches!(
            e,
            NavError::Collision(GoalConflict::GoalInCollision {
                target: crate::world::Target::Circle(0),
                ..
            })
        ),
        "{e}"
    );
    assert!(e.to_string().contains("goal-in-collision"));
    let e = nav
        .set_goal(
            &at_rest(4.5, 0.0, 0.0),
            Goal::new(9.0, 0.0, 0.0),
            &obstacles,
            0.0,
        )
        .unwrap_err();
    assert!(
        matches!(
            e,
            NavError::Collision(GoalConflict::MachineInCollision {
                target: crate::world::Target::Circle(0),
                ..
            })
        ),
        "{e}"
    );
    assert!(nav.route().is_empty());
    assert_eq!(
        nav.update(&at_rest(0.0, 0.0, 0.0), 0.0),
        NavStep::Abort(AbortReason::NoRoute)
    );
}

#[test]
fn subgoals_are_passed_as_the_machine_follows_the_path_and_the_goal_is_last() {
    let mut nav = navigator(false);
    let goal = Goal::new(8.0, 0.0, 0.0);
    nav.set_goal(&at_rest(0.0, 0.0, 0.0), goal, &wall(), 0.0)
        .unwrap();
    let route = nav.route().to_vec();
    let path = nav.path().to_vec();
    let r = nav.settings().following.subgoal_radius;
    assert!(route.len() >= 3, "{route:?}");
    let mut left = route.len();
    // Driven exactly along the path, one pose per tick: the remaining route
    // only shrinks, a subgoal is passed once the machine is within the
    // radius of it or past it on the path, and the goal is never passed.
    for (i, p) in path.iter().enumerate() {
        let x = State::new(p.x, p.y, p.theta, p.beta, 0.0, 0.5);
        assert!(matches!(
            nav.update(&x, 0.2 * i as f64),
            NavStep::Drive { .. }
        ));
        let remaining = nav.remaining_route();
        assert!(remaining.len() <= left);
        for passed in &route[route.len() - left..route.len() - remaining.len()] {
            let index = route.iter().position(|g| g == passed).unwrap();
            let near = (p.x - passed.x).hypot(p.y - passed.y) < r;
            let behind = path
                .iter()
                .take(i + 1)
                .any(|q| (q.x - passed.x).hypot(q.y - passed.y) < 1e-9);
            assert!(near || behind, "subgoal {index} passed at pose {i}");
        }
        left = remaining.len();
        assert_eq!(*remaining.last().unwrap(), goal);
    }
    assert_eq!(left, 1, "every subgoal passed: {:?}", nav.remaining_route());
}

#[test]
fn standing_still_aborts_after_the_timeout_but_holding_the_goal_does_not() {
    let mut nav = navigator(false);
    let goal = Goal::new(5.0, 0.0, 0.0);
    let x = at_rest(0.0, 0.0, 0.0);
    nav.set_goal(&x, goal, &[], 0.0).unwrap();
    let timeout = nav.settings().stall.progress.timeout;
    let mut k = 0;
    let aborted_at = loop {
        let t = 100.0 + k as f64 * 0.2;
        if let NavStep::Abort(r) = nav.update(&x, t) {
            assert_eq!(r, AbortReason::NoProgress);
            break t - 100.0;
        }
        k += 1;
        assert!(k < 1000);
    };
    assert!((aborted_at - timeout).abs() < 0.2 + 1e-9, "{aborted_at}");
    // Without obstacles there is nothing to replan around.
    assert_eq!(nav.plans(), 1);

    // At the goal, at rest: holding it for a minute is no stall.
    nav.set_goal(&x, goal, &[], 0.0).unwrap();
    let at_goal = at_rest(5.0, 0.02, 0.0);
    for k in 0..300 {
        assert!(matches!(
            nav.update(&at_goal, k as f64 * 0.2),
            NavStep::Drive { .. }
        ));
    }
}

#[test]
fn a_stall_replans_from_the_current_state_then_aborts() {
    let mut nav = navigator(false);
    let s = nav.settings().clone();
    let goal = Goal::new(8.0, 0.0, 0.0);
    // Behind the wall with a route, the machine stuck at some pose off the route.
    nav.set_goal(&at_rest(0.0, 0.0, 0.0), goal, &wall(), 0.0)
        .unwrap();
    assert_eq!(nav.plans(), 1);
    let stuck = at_rest(2.0, -1.0, 0.5);
    let mut first_replan = None;
    let mut aborted = None;
    for k in 0..100 {
        let t = k as f64 * 0.2;
        let step = nav.update(&stuck, t);
        if first_replan.is_none() && nav.plans() == 2 {
            first_replan = Some(t);
            let r = nav.last_plan().unwrap();
            assert!(r.replan);
            assert_eq!(r.outcome, PlanOutcome::Route);
            // The new path starts where the machine is.
            let p0 = nav.path()[0];
            assert_eq!((p0.x, p0.y, p0.theta), (2.0, -1.0, 0.5));
        }
        if let NavStep::Abort(r) = step {
            aborted = Some((t, r));
            break;
        }
    }
    let first = first_replan.expect("a replan");
    assert!(
        (first - s.stall.replan_after).abs() < 0.2 + 1e-9,
        "replan at {first}"
    );
    let (t, r) = aborted.expect("an abort");
    assert_eq!(r, AbortReason::NoProgress);
    // Replans do not extend the window.
    assert!(
        (t - s.stall.progress.timeout).abs() < 0.2 + 1e-9,
        "aborted at {t}"
    );
    assert!(nav.plans() as usize <= 1 + s.stall.max_replans);
}

#[test]
fn the_path_cost_leads_forward_along_the_route_and_the_critic_takes_the_goal() {
    let settings = NavigatorSettings::default();
    let handover = settings.following.handover;
    let mut nav = Navigator::new(params(), settings, None).unwrap();
    let goal = Goal::new(8.0, 0.0, 0.0);
    nav.set_goal(&at_rest(0.0, 0.0, 0.0), goal, &wall(), 0.0)
        .unwrap();
    let path = nav.path().to_vec();
    assert!(path.len() > 10 && path.iter().all(|p| p.direction >= 0));
    let length: f64 = path
        .windows(2)
        .map(|w| (w[1].x - w[0].x).hypot(w[1].y - w[0].y))
        .sum();
    let mut version = nav.cost_version();
    let mut handed_over_at = None;
    let mut hint = 0;
    // The machine driven exactly along the path, one pose per tick.
    for (i, p) in path.iter().enumerate() {
        let x = State::new(p.x, p.y, p.theta, p.beta, 0.0, 0.5);
        // Without networks the search ends in its goal region (no shot): the
        // path's end is the goal's, the target throughout.
        assert_eq!(nav.update(&x, 0.2 * i as f64), drive(goal, true));
        let left: f64 = path[i..]
            .windows(2)
            .map(|w| (w[1].x - w[0].x).hypot(w[1].y - w[0].y))
            .sum();
        match nav.path_cost() {
            Some(cost) => {
                assert!(handed_over_at.is_none(), "the path came back at pose {i}");
                assert!(left > handover - 0.7, "pose {i}: {left:.2} m left");
                // The whole path, and the cost falls along it (its value at
                // the machine is the arc left, priced at a metre's cost).
                assert!((cost.length() - length).abs() < 1e-9 || i > 0);
                // Projected from the last tick's segment, as the MPC does.
                let term = cost.eval(&x, &Control::zeros(), hint);
                hint = term.segment;
                let here = term.value;
                assert!(
                    (here - 3.0 * left).abs() < 1e-6,
                    "pose {i}: {here} vs {left}"
                );
            }
            None => {
                if handed_over_at.is_none() {
                    assert!(nav.cost_version() > version);
                    handed_over_at = Some(left);
                }
            }
        }
        version = nav.cost_version();
    }
    let left = handed_over_at.expect("the critic takes over before the end");
    assert!(
        left <= handover + 1e-9,
        "handed over {left:.2} m before the end"
    );
}

#[test]
fn a_path_that_ends_with_a_goal_shot_is_continued_by_it() {
    let settings = NavigatorSettings::default();
    let tolerance = settings.search.shot_tolerance;
    let mut nav = Navigator::new(params(), settings, Some(trained())).unwrap();
    let goal = Goal::new(8.0, 0.0, 0.0);
    let start = at_rest(0.0, 0.0, 0.0);
    nav.set_goal(&start, goal, &wall(), 0.0).unwrap();
    let end = *nav.path().last().expect("a route around the wall");
    let path_arc: f64 = nav
        .path()
        .windows(2)
        .map(|w| (w[1].x - w[0].x).hypot(w[1].y - w[0].y))
        .sum();
    // The search shot the goal from its last node (it stops short of it).
    assert!((end.x - goal.x).hypot(end.y - goal.y) > 1.0, "{end:?}");
    nav.update(&start, 0.0);
    let cost = nav.path_cost().expect("a path cost");
    // This shot drives forwards to the goal: driven again, it continues the path (a
    // shot that reversed would leave the end open instead, for the critic). The
    // cost runs to the goal, past the path's own end.
    assert!(
        !cost.open_end(),
        "the forward shot was not driven again: the path's end is open"
    );
    // Projected from the last segment (a hint beyond it is clamped).
    let (left, _) = cost.arc_left(
        &State::new(goal.x, goal.y, goal.theta, 0.0, 0.0, 0.0),
        usize::MAX,
    );
    assert!(
        cost.length() > path_arc + 1.0,
        "{} vs {path_arc}",
        cost.length()
    );
    assert!(left.abs() < tolerance + 0.3, "{left}");
}

#[test]
fn the_critics_cost_of_a_metre_is_its_slope_in_the_goal_distance() {
    let (_, critic) = trained();
    let mut ws = CriticWorkspace::new(&critic);
    let per_metre = critic_cost_per_metre(&critic, &mut ws).unwrap();
    // Measured on the published critic: 3.0 (3.0), and
    // about the time to go at cruising speed / 0.22 s per unit (waypoint graph).
    assert!((per_metre - 3.0).abs() < 0.5, "{per_metre}");
    // Independently: the slope straight ahead, 4 to 9 m, is of the same size.
    let mut value = |d: f64| {
        critic.value(
            &mut ws,
            &State::zeros(),
            &Control::zeros(),
            &Goal::new(d, 0.0, 0.0),
        )
    };
    let ahead = (value(9.0) - value(4.0)) / 5.0;
    assert!(
        ahead > 0.5 * per_metre && ahead < 2.0 * per_metre,
        "{ahead} vs {per_metre}"
    );
}

/// A plan may run off the tick thread: the navigator moves between threads.
#[test]
fn the_navigator_is_send() {
    fn send<T: Send>() {}
    send::<Navigator>();
}

#[test]
fn settings_are_validated_by_name() {
    let mut s = NavigatorSettings::default();
    s.stall.replan_after = 12.0;
    let e = Navigator::new(params(), s, None).err().unwrap();
    assert!(e.to_string().contains("replan_after"), "{e}");
    let mut s = NavigatorSettings::default();
    s.search.grid_resolution = 0.5;
    let e = Navigator::new(params(), s, None).err().unwrap();
    assert!(e.to_string().contains("primitive_length"), "{e}");
    let mut s = NavigatorSettings::default();
    s.stall.approach_distance = 0.8;
    let e = Navigator::new(params(), s, None).err().unwrap();
    assert!(e.to_string().contains("approach_distance"), "{e}");
}

/// Beside the goal, at rest, articulated to the limit: the stall of the
/// large loader's critic (`docs/training.md`), d = 0.11 > 0.1.
fn stopped_beside(goal: &Goal) -> State {
    State::new(
        goal.x + 0.03,
        goal.y + 0.02,
        goal.theta + 0.1,
        0.7,
        0.0,
        0.0,
    )
}

fn drive(target: Goal, final_target: bool) -> NavStep {
    NavStep::Drive {
        target,
        final_target,
    }
}

#[test]
fn a_stop_beside_the_goal_is_retried_from_the_approach_pose_behind_it() {
    let mut nav = navigator(false);
    let s = nav.settings().clone();
    let goal = Goal::new(5.0, 0.0, 0.0);
    let behind = Goal::new(5.0 - s.stall.approach_distance, 0.0, 0.0);
    nav.set_goal(&at_rest(0.0, 0.0, 0.0), goal, &[], 0.0)
        .unwrap();
    let stuck = stopped_beside(&goal);
    assert!(goal_distance(&stuck, &goal) > s.stall.reached_tolerance);
    let dt = 0.2;
    let mut t = 0.0;
    // Stopped there: the goal until `replan_after`, then the approach pose.
    while t < s.stall.replan_after - 1e-9 {
        assert_eq!(nav.update(&stuck, t), drive(goal, true), "t {t}");
        t += dt;
    }
    assert_eq!(nav.update(&stuck, t), drive(behind, false));
    let r = nav.last_plan().unwrap();
    assert_eq!((r.outcome, r.replan), (PlanOutcome::Retry, true));
    assert_eq!(nav.route(), &[behind, goal]);
    // Within the subgoal radius of it (driving back): the goal again.
    t += dt;
    let passing = State::new(
        behind.x + 0.9 * s.following.subgoal_radius,
        0.0,
        0.0,
        0.0,
        0.0,
        -0.5,
    );
    assert_eq!(nav.update(&passing, t), drive(goal, true));
    // Stopped beside it once more: the second and last retry; the third
    // stall waits for the abort window.
    let mut retries_at = Vec::new();
    let aborted_at = loop {
        t += dt;
        let plans = nav.plans();
        match nav.update(&stuck, t) {
            NavStep::Abort(r) => {
                assert_eq!(r, AbortReason::NoProgress);
                break t;
            }
            NavStep::Drive { target, .. } if nav.plans() > plans => {
                assert_eq!(target, behind);
                retries_at.push(t);
                // Back past the approach pose and to the goal again.
                t += dt;
                nav.update(&passing, t);
            }
            NavStep::Drive { .. } => {}
            NavStep::Hold => panic!("open ground never holds"),
        }
        assert!(t < 100.0);
    };
    assert_eq!(retries_at.len(), s.stall.max_retries - 1, "{retries_at:?}");
    assert_eq!(nav.plans() as usize, 1 + s.stall.max_retries);
    // Stopped after the last pass, the window runs out: retries are no progress.
    let last_progress = retries_at[0] + 2.0 * dt;
    assert!(
        (aborted_at - last_progress - s.stall.progress.timeout).abs() < dt + 1e-9,
        "aborted at {aborted_at}, last progress {last_progress}"
    );
}

/// Among circles, a machine crawling back and forth beside the goal, which
/// is in sight, is retried from the approach pose: a replan would shoot at
/// the goal and hand back the same route. Without the goal in sight (a
/// circle between), it is replanned.
#[test]
fn a_crawl_beside_the_goal_in_sight_among_circles_is_retried() {
    let goal = Goal::new(5.0, 0.0, 0.0);
    let s = NavigatorSettings::default();
    let behind = Goal::new(5.0 - s.stall.approach_distance, 0.0, 0.0);
    // Away from the straight way and the goal: the start is direct.
    let aside = [Obstacle::new(2.5, 4.0, 0.5)];
    // Between the crawling machine (0.6 m to the goal's left) and the goal.
    let between = [Obstacle::new(5.1, 0.45, 0.12)];
    for (obstacles, retried) in [(&aside, true), (&between, false)] {
        let mut nav = navigator(false);
        nav.set_goal(&at_rest(0.0, 0.0, 0.0), goal, obstacles, 0.0)
            .unwrap();
        let plans = nav.plans();
        let dt = 0.2;
        let mut t = 0.0;
        let mut first_new_plan = None;
        while t < s.stall.replan_after + 2.0 * dt && first_new_plan.is_none() {
            // 0.1 m/s one way, then the other, 0.6 m beside the goal.
            let v = if (t / dt) as i64 % 2 == 0 { 0.1 } else { -0.1 };
            let crawl = State::new(5.0, 0.6, 0.0, 0.7, 0.0, v);
            let step = nav.update(&crawl, t);
            if nav.plans() > plans {
                first_new_plan = Some((step, nav.last_plan().unwrap().outcome));
            }
            t += dt;
        }
        let (step, outcome) = first_new_plan.expect("a stall was handled");
        if retried {
            assert_eq!(outcome, PlanOutcome::Retry);
            assert_eq!(step, drive(behind, false));
        } else {
            assert_ne!(outcome, PlanOutcome::Retry, "{step:?}");
        }
    }
}

#[test]
fn no_retry_while_moving_or_far_from_the_goal() {
    let goal = Goal::new(5.0, 0.0, 0.0);
    let mut moving = stopped_beside(&goal);
    moving[ix::V] = 0.3;
    let s = NavigatorSettings::default();
    let far = at_rest(goal.x - s.stall.approach_distance - 0.1, 0.0, 0.0);
    for x in [moving, far] {
        let mut nav = navigator(false);
        nav.set_goal(&at_rest(0.0, 0.0, 0.0), goal, &[], 0.0)
            .unwrap();
        for k in 0..45 {
            assert_eq!(nav.update(&x, k as f64 * 0.2), drive(goal, true));
        }
        assert_eq!(nav.plans(), 1);
    }
}

#[test]
fn a_retry_approaches_from_ahead_when_behind_is_blocked_then_from_half_as_far_and_not_at_all_when_all_are(
) {
    let s = NavigatorSettings::default();
    let d = s.stall.approach_distance;
    let goal = Goal::new(5.0, 0.0, 0.0);
    let behind = Obstacle::new(goal.x - d, 0.0, 0.5);
    let ahead = Obstacle::new(goal.x + d, 0.0, 0.5);
    // Blocks the pose half as far ahead (its front axle), not the goal.
    let half_ahead = Obstacle::new(goal.x + 0.5 * d + 0.3, 0.0, 0.4);
    let stuck = stopped_beside(&goal);
    for (obstacles, expected) in [
        (vec![behind], Some(Goal::new(goal.x + d, 0.0, 0.0))),
        // Both poses the full distance off blocked: the one half as far ahead,
        // reached by a search (the straight way there is not the machine's).
        (
            vec![behind, ahead],
            Some(Goal::new(goal.x + 0.5 * d, 0.0, 0.0)),
        ),
        (vec![behind, ahead, half_ahead], None),
    ] {
        let mut nav = navigator(false);
        nav.set_goal(&stuck, goal, &obstacles, 0.0).unwrap();
        let mut t = 0.0;
        while nav.plans() == 1 {
            nav.update(&stuck, t);
            t += 0.2;
            assert!(t < s.stall.progress.timeout);
        }
        let r = nav.last_plan().unwrap();
        match expected {
            Some(approach) => {
                assert_eq!(r.outcome, PlanOutcome::Retry, "{obstacles:?}");
                let route = nav.route();
                assert_eq!(route[route.len() - 2..], [approach, goal], "{route:?}");
            }
            None => {
                assert_eq!(r.outcome, PlanOutcome::NoRoute);
                assert_eq!(nav.route(), &[goal]);
            }
        }
    }
}

/// A retry whose approach pose the actor's roll-out reaches follows that
/// roll-out there (its path, reversing parts by the rear axle), then the
/// critic takes the goal.
#[test]
fn a_retry_the_actor_reaches_follows_its_roll_out() {
    let goal = Goal::new(5.0, 0.0, 0.0);
    let d = NavigatorSettings::default().stall.approach_distance;
    let behind = Obstacle::new(goal.x - d, 0.0, 0.5);
    let stuck = stopped_beside(&goal);
    let mut nav = navigator(true);
    nav.set_goal(&stuck, goal, &[behind], 0.0).unwrap();
    let mut t = 0.0;
    while nav.plans() == 1 {
        nav.update(&stuck, t);
        t += 0.2;
        assert!(t < 10.0);
    }
    assert_eq!(nav.last_plan().unwrap().outcome, PlanOutcome::Retry);
    let approach = Goal::new(goal.x + d, 0.0, 0.0);
    let route = nav.route();
    assert_eq!(route[route.len() - 2..], [approach, goal], "{route:?}");
    let path = nav.path();
    assert!(path.len() > 2, "{} poses", path.len());
    assert_eq!([path[0].x, path[0].y], [stuck[ix::X], stuck[ix::Y]]);
    let end = path.last().unwrap();
    assert!(
        (end.x - approach.x).hypot(end.y - approach.y) < 0.5,
        "{end:?}"
    );
}

#[test]
fn a_retry_opens_its_own_abort_window() {
    // Stopped beside the goal and never moving again: the retry at
    // `replan_after`, the abort a whole window after it (the way to the
    // approach pose may first lead away), no second retry (the approach pose
    // is the target, not the goal).
    let mut nav = navigator(false);
    let s = nav.settings().clone();
    let goal = Goal::new(5.0, 0.0, 0.0);
    nav.set_goal(&at_rest(0.0, 0.0, 0.0), goal, &[], 0.0)
        .unwrap();
    let stuck = stopped_beside(&goal);
    let dt = 0.2;
    let (mut retry_at, mut k) = (None, 0);
    let aborted_at = loop {
        let t = k as f64 * dt;
        let step = nav.update(&stuck, t);
        if retry_at.is_none() && nav.plans() == 2 {
            retry_at = Some(t);
        }
        if let NavStep::Abort(r) = step {
            assert_eq!(r, AbortReason::NoProgress);
            break t;
        }
        k += 1;
        assert!(k < 1000);
    };
    let retry_at = retry_at.expect("a retry");
    assert!(
        (retry_at - s.stall.replan_after).abs() < dt + 1e-9,
        "{retry_at}"
    );
    assert!(
        (aborted_at - retry_at - s.stall.progress.timeout).abs() < dt + 1e-9,
        "retry at {retry_at}, aborted at {aborted_at}"
    );
    assert_eq!(nav.plans(), 2);
}

#[test]
fn a_plan_from_inside_the_extra_margins_gives_up_only_what_it_lacks() {
    use super::world::CheckedWorld;
    use crate::site::Outline;
    let p = MachineParams::default();
    let mut w = CheckedWorld::new(p, 4, 0.0);
    let outline = Outline::axle_circles(0.65).unwrap();
    w.set_outline(outline, &[0.3, 0.3]);
    // A pile of 1 m (a wire circle carries the half-width: 1.65 m).
    w.set(&[Obstacle::new(3.0, 0.0, 1.65)]).unwrap();
    // Front axle 0.1 m from the pile's edge (an axle disc of 0.65 m): inside
    // the extra margin of 0.3 m, 0.2 m short of it.
    let near = State::new(3.0 - 1.0 - 0.65 - 0.1, 0.0, 0.0, 0.0, 0.0, 0.0);
    let clearance = w.state_clearance(&near);
    assert!((clearance - 0.1).abs() < 1e-9, "{clearance}");
    let slack = w.state_slack(&near);
    assert!((slack - (clearance - 0.3)).abs() < 1e-9, "{slack}");
    assert!(!w.state_free(&near));
    w.set_relief(-slack - 0.01);
    assert!(!w.state_free(&near), "less relief than it lacks");
    w.set_relief(-slack + 0.01);
    assert!(w.state_free(&near));
    // Relief never gives up the outline itself: a state 5 cm inside the pile
    // stays blocked whatever the relief.
    let inside = State::new(3.0 - 1.0 - 0.65 + 0.05, 0.0, 0.0, 0.0, 0.0, 0.0);
    w.set_relief(10.0);
    assert!(!w.state_free(&inside));
}

#[test]
fn a_replan_that_hands_back_the_goal_alone_is_followed_by_a_retry() {
    // Stopped 1.5 m from the goal, turned away, a post between: not in the
    // search's goal region, the goal not in sight, so the stall replans first. The search
    // from there ends in the goal alone (the route that stalled); the next
    // stall retries from the approach pose instead of replanning again.
    let mut nav = navigator(false);
    let goal = Goal::new(5.0, 0.0, 0.0);
    let stuck = at_rest(3.5, 0.0, 0.5);
    nav.set_goal(&stuck, goal, &[Obstacle::new(4.3, 0.0, 0.25)], 0.0)
        .unwrap();
    let mut outcomes = Vec::new();
    for k in 0..150 {
        let before = nav.plans();
        if let NavStep::Abort(_) = nav.update(&stuck, k as f64 * 0.2) {
            break;
        }
        if nav.plans() > before {
            let r = nav.last_plan().unwrap();
            outcomes.push((r.outcome, r.replan, nav.route().len()));
        }
    }
    let replan = outcomes
        .iter()
        .position(|&(o, replan, n)| o == PlanOutcome::Route && replan && n == 1)
        .unwrap_or_else(|| panic!("no replan giving the goal alone: {outcomes:?}"));
    assert_eq!(
        outcomes.get(replan + 1).map(|o| o.0),
        Some(PlanOutcome::Retry),
        "{outcomes:?}"
    );
}

/// A trajectory optimiser for the tests: the route's path (its poses, then
/// the goal) timed at 1 m/s along its arc, every pose a state; or none.
struct RouteTimed {
    fail: bool,
}

impl TrajectoryOptimiser for RouteTimed {
    fn optimise(
        &mut self,
        _world: &CheckedWorld,
        start: &State,
        goal: &Goal,
        path: &[PathPose],
        _shot: &[State],
        out: &mut Vec<State>,
    ) -> Result<f64, TrajectoryFailure> {
        if self.fail {
            return Err(TrajectoryFailure::NotSolved { status: "test" });
        }
        // Resampled every 0.1 m (0.1 s at 1 m/s) along the poses.
        let mut poses: Vec<[f64; 3]> = vec![[start[ix::X], start[ix::Y], start[ix::THETA]]];
        poses.extend(path.iter().map(|p| [p.x, p.y, p.theta]));
        poses.push([goal.x, goal.y, goal.theta]);
        out.clear();
        for w in poses.windows(2) {
            let d = (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]);
            let n = (d / 0.1).ceil().max(1.0) as usize;
            for k in 0..n {
                let f = k as f64 / n as f64;
                let at = |i: usize| w[0][i] + f * (w[1][i] - w[0][i]);
                out.push(State::new(at(0), at(1), at(2), 0.0, 0.0, 1.0));
            }
        }
        out.push(State::new(goal.x, goal.y, goal.theta, 0.0, 0.0, 0.0));
        Ok(0.1)
    }
}

fn tracking_navigator(fail: bool) -> Navigator {
    let settings = NavigatorSettings::default();
    let planner = RoutePlanner::new(params(), &settings, None)
        .unwrap()
        .with_trajectory(Box::new(RouteTimed { fail }));
    let routes = Box::new(InlineRoutes::new(planner, PlanDelay::Fixed(0.0)));
    Navigator::with_routes(params(), settings, None, routes).unwrap()
}

#[test]
fn a_searched_route_shaped_by_a_trajectory_is_tracked_with_the_machine_then_handed_to_the_critic() {
    let mut nav = tracking_navigator(false);
    let goal = Goal::new(8.0, 0.0, 0.0);
    nav.set_goal(&at_rest(0.0, 0.0, 0.0), goal, &wall(), 0.0)
        .unwrap();
    let report = nav.last_plan().unwrap();
    assert_eq!(report.outcome, PlanOutcome::Route);
    // The report says it was shaped, and how long the trajectory takes (the
    // test optimiser's: 1 m/s along the route, so at least the 8 m).
    let TrajectoryOutcome::Shaped { duration: shaped } = report.trajectory else {
        panic!("{:?}", report.trajectory)
    };
    assert!(shaped > 8.0, "{shaped}");
    // The route's path is the trajectory's (thinned, start to goal): it goes
    // round the wall's end as the search's did.
    let widest = nav.path().iter().map(|q| q.y.abs()).fold(0.0, f64::max);
    assert!(widest > 3.8, "{widest}");
    let end = nav.path().last().copied().unwrap();
    assert!((end.x - goal.x).hypot(end.y - goal.y) < 1e-9);
    // The goal is the MPC's target, the trajectory its cost (no path cost).
    let x0 = at_rest(0.0, 0.0, 0.0);
    assert_eq!(nav.update(&x0, 0.0), drive(goal, true));
    let track = nav.track_cost().expect("the trajectory is tracked").clone();
    assert!(nav.path_cost().is_none());
    assert_eq!(track.time(), 0.0);
    let duration = track.duration();
    assert!((duration - shaped).abs() < 1e-9, "{duration} vs {shaped}");
    // Standing still, the time waits for the machine (the trajectory's
    // first points are further from it than the ones it is at).
    // (Less than `max_track_lag`: later it would follow the route's path.)
    for k in 1..=3 {
        nav.update(&x0, 0.2 * k as f64);
        assert!(nav.track_cost().unwrap().time() <= 0.1 + 1e-9);
    }
    // Driven along the reference, the time keeps up with the machine's
    // place on it (within a sample), never ahead of it.
    let mut now = 0.6;
    let mut t = 0.0;
    while t < duration {
        t = (t + 0.2).min(duration);
        now += 0.2;
        let x = track.reference(t);
        let version = nav.cost_version();
        assert_eq!(nav.update(&x, now), drive(goal, true));
        let on = nav.track_cost().unwrap();
        assert!((on.time() - t).abs() <= 0.1 + 1e-9, "{} vs {t}", on.time());
        assert_eq!(nav.cost_version(), version, "the trajectory set again");
    }
    // At its end, the goal at rest is tracked a little longer, then the
    // critic has the goal.
    let at_goal = at_rest(goal.x, goal.y, goal.theta);
    let version = nav.cost_version();
    let mut handed = None;
    for k in 1..=10 {
        nav.update(&at_goal, now + 0.2 * k as f64);
        if nav.track_cost().is_none() {
            handed = Some(0.2 * k as f64);
            break;
        }
    }
    let after = handed.expect("handed over to the critic");
    assert!((0.8..=1.2).contains(&after), "after {after} s");
    assert!(nav.cost_version() > version);
    assert!(nav.path_cost().is_none());
}

#[test]
fn without_a_trajectory_the_searched_route_is_followed_as_before() {
    let mut shaped = tracking_navigator(true);
    let mut plain = Navigator::new(params(), NavigatorSettings::default(), None).unwrap();
    let goal = Goal::new(8.0, 0.0, 0.0);
    let x0 = at_rest(0.0, 0.0, 0.0);
    for nav in [&mut shaped, &mut plain] {
        nav.set_goal(&x0, goal, &wall(), 0.0).unwrap();
        nav.update(&x0, 0.0);
        assert!(nav.track_cost().is_none());
        assert!(nav.path_cost().is_some());
    }
    assert_eq!(shaped.path(), plain.path());
    assert_eq!(shaped.route(), plain.route());
    // Each report says why: the optimiser failed, or none was asked.
    assert_eq!(
        shaped.last_plan().unwrap().trajectory,
        TrajectoryOutcome::Failed(TrajectoryFailure::NotSolved { status: "test" })
    );
    assert_eq!(
        plain.last_plan().unwrap().trajectory,
        TrajectoryOutcome::NotAsked
    );
}

/// Issue 42: a tracked machine pushed off its trajectory (here 1.5 m
/// sideways, beyond the default 1 m) is planned again from where it is, once
/// `replan_after` has passed since the last plan; within the limit it is not.
#[test]
fn a_machine_far_off_its_trajectory_is_planned_again_from_where_it_is() {
    let st = NavigatorSettings::default().stall;
    let goal = Goal::new(8.0, 0.0, 0.0);
    let x0 = at_rest(0.0, 0.0, 0.0);
    for (offset, replans) in [(0.5, false), (1.5, true)] {
        let mut nav = tracking_navigator(false);
        nav.set_goal(&x0, goal, &wall(), 0.0).unwrap();
        nav.update(&x0, 0.0);
        let track = nav.track_cost().expect("tracked").clone();
        let plans = nav.plans();
        // Along the reference until a replan may come, then off it sideways
        // (the reference's heading, offset to its left).
        let mut now = 0.0;
        let mut t: f64 = 0.0;
        while now < st.replan_after + 0.5 {
            now += 0.2;
            t = (t + 0.2).min(track.duration());
            let mut x = track.reference(t);
            let th = x[ix::THETA];
            if now > st.replan_after {
                x[ix::X] -= offset * th.sin();
                x[ix::Y] += offset * th.cos();
            }
            nav.update(&x, now);
        }
        assert!(nav.plans() >= plans, "plans counted down");
        assert_eq!(
            nav.plans() > plans,
            replans,
            "{offset} m off: plans {} from {plans}",
            nav.plans()
        );
        if replans {
            let last = nav.last_plan().unwrap();
            assert!(last.replan, "{last:?}");
        }
    }
}

/// Issue 42: a machine that does not keep up with its trajectory (held here,
/// as a weaker or later machine falls behind) follows the rest of the route's
/// path once `max_track_lag` behind; until then it tracks.
#[test]
fn a_machine_far_behind_its_trajectory_follows_the_routes_path() {
    let lag = NavigatorSettings::default().stall.max_track_lag;
    let mut nav = tracking_navigator(false);
    let goal = Goal::new(8.0, 0.0, 0.0);
    let x0 = at_rest(0.0, 0.0, 0.0);
    nav.set_goal(&x0, goal, &wall(), 0.0).unwrap();
    nav.update(&x0, 0.0);
    assert!(nav.track_cost().is_some());
    let mut now = 0.0;
    while now < lag - 0.3 {
        now += 0.2;
        nav.update(&x0, now);
        assert!(nav.track_cost().is_some(), "dropped {now} s behind");
    }
    let version = nav.cost_version();
    nav.update(&x0, lag + 0.2);
    assert!(
        nav.track_cost().is_none(),
        "still tracked {} s behind",
        lag + 0.2
    );
    assert!(nav.path_cost().is_some(), "the route's path followed");
    assert!(nav.cost_version() > version);
    // Not set again for the same plan.
    nav.update(&x0, lag + 0.4);
    assert!(nav.track_cost().is_none());
}
