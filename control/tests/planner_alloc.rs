//! The global layer allocates nothing after construction: not in `set_goal`,
//! not in `update` (which asks for replans), not in the planner (inline or on
//! its thread), and the pilot's tick (navigator, MPC with the path cost,
//! envelope) neither. One test in this binary, so no other test thread
//! allocates while we count.

mod common;

use std::time::Instant;

use control::envelope::EnvelopeSettings;
use control::model::{Goal, MachineParams, State};
use control::mpc::{Mpc, MpcSettings};
use control::obstacle::Obstacle;
use control::pilot::{Pilot, PilotDecision};
use control::planner::world::CheckedWorld;
use control::planner::{
    InlineRoutes, NavStep, Navigator, NavigatorSettings, PathPose, PlanDelay, PlanOutcome,
    PlannerThread, RoutePlanner, RouteService, TrajectoryFailure, TrajectoryOptimiser,
};
use control::weights;
use control::{Actor, Critic, VelocityCommand};

#[global_allocator]
static GLOBAL: common::CountingAllocator = common::CountingAllocator;

/// The trained networks (a random actor never drives into the wall, so
/// nothing would be in its way).
fn trained() -> (Actor, Critic) {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join(weights::DEFAULT_DIR);
    let (critic, actor) = control::networks::load_networks(
        &dir,
        &MachineParams::default(),
        MpcSettings::default().dt,
    )
    .expect("the committed weights");
    (actor, critic)
}

fn navigator(routes: &str, networks: bool) -> Navigator {
    let p = MachineParams::default();
    let s = NavigatorSettings::default();
    let (actor, critic) = match networks.then(trained) {
        Some((a, c)) => (Some(a), Some(c)),
        None => (None, None),
    };
    let planner = RoutePlanner::new(p, &s, actor).unwrap();
    let service: Box<dyn RouteService> = match routes {
        "thread" => Box::new(PlannerThread::spawn(planner).unwrap()),
        "delayed" => Box::new(InlineRoutes::new(planner, PlanDelay::Fixed(0.2))),
        _ => Box::new(InlineRoutes::new(planner, PlanDelay::Fixed(0.0))),
    };
    Navigator::with_routes(p, s, critic.as_ref(), service).unwrap()
}

#[test]
fn the_global_layer_and_the_pilot_do_not_allocate() {
    let wall: Vec<Obstacle> = (-4..=4)
        .map(|k| Obstacle::new(4.0, 0.8 * k as f64, 0.6))
        .collect();
    let goal = Goal::new(8.0, 0.0, 0.0);
    let start = State::zeros();
    for routes in ["inline", "delayed", "thread"] {
        for networks in [false, true] {
            let mut nav = navigator(routes, networks);
            let before = common::allocations();
            nav.set_goal(&start, goal, &wall, 0.0).unwrap();
            let mut steps = 0;
            // Standing still behind the wall: the route, replans, then the abort.
            for k in 0..60 {
                if let NavStep::Abort(_) = nav.update(&start, k as f64 * 0.2) {
                    break;
                }
                if routes == "thread" {
                    // The rest of the tick: the planner thread's plan finishes
                    // in it (the tick never waits for it; a wait on the thread,
                    // not a fixed sleep, so that a slow machine — qemu — sees
                    // the same ticks).
                    let t0 = std::time::Instant::now();
                    while nav.planner_working() && t0.elapsed().as_secs() < 60 {
                        std::thread::sleep(std::time::Duration::from_millis(1));
                    }
                }
                steps += 1;
            }
            let planned = nav.plans();
            // Open ground: direct, no plan asked.
            nav.set_goal(&start, goal, &[], 0.0).unwrap();
            for k in 0..50 {
                let x = State::new(0.1 * k as f64, 0.0, 0.0, 0.0, 0.0, 0.5);
                nav.update(&x, k as f64 * 0.2);
            }
            let after = common::allocations();
            assert!(planned >= 3, "{routes}: only {planned} plans taken");
            assert!(steps > 10, "{routes}: aborted after {steps} ticks");
            assert_eq!(
                after - before,
                0,
                "{} allocations ({routes}, networks {networks})",
                after - before
            );
        }
    }

    // The pilot: around the wall's lower end with the path cost copied into
    // the MPC, every proposal checked by the envelope.
    let (actor, critic) = trained();
    let p = MachineParams::default();
    let mpc = Mpc::new(p, critic.clone(), Some(actor), MpcSettings::default()).unwrap();
    let nav = navigator("delayed", true);
    let mut pilot = Pilot::new(
        p,
        mpc,
        Some(nav),
        EnvelopeSettings::default(),
        Default::default(),
    )
    .unwrap();
    // The MPC takes 8 circles (the wire's limit).
    let wall = &wall[1..8];
    let before = common::allocations();
    pilot.set_goal(&start, goal, wall, 0.0).unwrap();
    let (mut held, mut followed) = (0, 0);
    for k in 0..80 {
        let now = k as f64 * 0.2;
        let x = State::new(0.1 * k as f64, -0.05 * k as f64, 0.0, 0.0, 0.0, 0.5);
        let command = match pilot.step(&x, now, Instant::now()).unwrap() {
            PilotDecision::Drive(s) => {
                held += usize::from(s.solution.is_none());
                followed += usize::from(s.route.len() > 1);
                s.command
            }
            PilotDecision::Abort(_) | PilotDecision::Stop { .. } => VelocityCommand::ZERO,
        };
        pilot.sent(now, command);
    }
    let after = common::allocations();
    let nav = pilot.navigator().unwrap();
    assert_eq!(held, 1, "held for the one tick the route takes");
    assert!(followed > 0);
    assert_eq!(
        nav.last_plan().map(|r| r.outcome),
        Some(PlanOutcome::Route),
        "the wall is planned around"
    );
    assert_eq!(after - before, 0, "{} allocations (pilot)", after - before);

    // The pilot tracking a trajectory (issue 42): the route shaped by an
    // optimiser that allocates nothing itself (the searched path timed at
    // 1 m/s), the trajectory copied into the MPC and its time every tick.
    struct Timed;
    impl TrajectoryOptimiser for Timed {
        fn optimise(
            &mut self,
            _: &CheckedWorld,
            _: &State,
            _: &Goal,
            path: &[PathPose],
            _: &[State],
            out: &mut Vec<State>,
        ) -> Result<f64, TrajectoryFailure> {
            out.clear();
            for q in path.iter().take(out.capacity()) {
                let v = if q.direction < 0 { -1.0 } else { 1.0 };
                out.push(State::new(q.x, q.y, q.theta, q.beta, 0.0, v));
            }
            // The search's sample spacing (0.15 m) at 1 m/s.
            Ok(0.15)
        }
    }
    let s = NavigatorSettings::default();
    let planner = RoutePlanner::new(p, &s, Some(trained().0))
        .unwrap()
        .with_trajectory(Box::new(Timed));
    let routes = Box::new(InlineRoutes::new(planner, PlanDelay::Fixed(0.2)));
    let nav = Navigator::with_routes(p, s, Some(&critic), routes).unwrap();
    let mpc = Mpc::new(p, critic.clone(), Some(trained().0), MpcSettings::default()).unwrap();
    let mut pilot = Pilot::new(
        p,
        mpc,
        Some(nav),
        EnvelopeSettings::default(),
        Default::default(),
    )
    .unwrap();
    let before = common::allocations();
    pilot.set_goal(&start, goal, wall, 0.0).unwrap();
    let mut tracked = 0;
    for k in 0..80 {
        let now = k as f64 * 0.2;
        let x = State::new(0.1 * k as f64, -0.05 * k as f64, 0.0, 0.0, 0.0, 0.5);
        let command = match pilot.step(&x, now, Instant::now()).unwrap() {
            PilotDecision::Drive(s) => s.command,
            PilotDecision::Abort(_) | PilotDecision::Stop { .. } => VelocityCommand::ZERO,
        };
        tracked += usize::from(pilot.navigator().unwrap().track_cost().is_some());
        pilot.sent(now, command);
    }
    let after = common::allocations();
    assert!(tracked > 10, "tracked {tracked} ticks");
    assert_eq!(
        after - before,
        0,
        "{} allocations (pilot tracking)",
        after - before
    );

    // The pilot in the ≥ 500-feature site with the Avant 635's outline (DESIGN
    // §17): rows from the site's index, the envelope through it, the route
    // planned in it; a reload (another index) swapped in mid-goal. Free poses
    // are found before counting.
    let pit = std::sync::Arc::new(control::site::SiteIndex::new(
        control::site::Site::parse(
            control::site::generate::large_pit(40, 520)
                .to_json()
                .as_bytes(),
        )
        .unwrap(),
    ));
    let reloaded = std::sync::Arc::new((*pit).clone());
    let mut world = control::world::World::new(p, control::site::Outline::avant635(), 0);
    world.set_site(Some(pit.clone()));
    let b = pit.site().bounds().aabb();
    let free = |x: f64, y: f64| world.clearance(&State::new(x, y, 0.0, 0.0, 0.0, 0.0)) > 2.0;
    let (x0, y0) = (0..400)
        .map(|k| {
            (
                b.min[0] + 5.0 + (k % 20) as f64 * 3.0,
                b.min[1] + 5.0 + (k / 20) as f64 * 3.0,
            )
        })
        .find(|&(x, y)| free(x, y) && free(x + 10.0, y))
        .expect("a free pose in the pit");
    let mpc = Mpc::new(p, critic.clone(), Some(trained().0), MpcSettings::default()).unwrap();
    let mut pilot = Pilot::new(
        p,
        mpc,
        Some(navigator("delayed", true)),
        EnvelopeSettings::default(),
        Default::default(),
    )
    .unwrap();
    pilot.set_outline(control::site::Outline::avant635());
    pilot.set_site(Some(pit.clone()));
    let start = State::new(x0, y0, 0.0, 0.0, 0.0, 0.0);
    let before = common::allocations();
    pilot
        .set_goal(&start, Goal::new(x0 + 10.0, y0, 0.0), &[], 0.0)
        .unwrap();
    let mut drove = 0;
    for k in 0..60 {
        if k == 30 {
            pilot.set_site(Some(reloaded.clone()));
        }
        let now = k as f64 * 0.2;
        let x = State::new(x0 + 0.1 * k as f64, y0, 0.0, 0.0, 0.0, 0.5);
        let command = match pilot.step(&x, now, Instant::now()).unwrap() {
            PilotDecision::Drive(s) => {
                drove += usize::from(s.solution.is_some());
                s.command
            }
            PilotDecision::Abort(_) | PilotDecision::Stop { .. } => VelocityCommand::ZERO,
        };
        pilot.sent(now, command);
    }
    let after = common::allocations();
    assert!(drove > 50, "drove {drove} ticks");
    assert_eq!(
        after - before,
        0,
        "{} allocations (pilot in the pit)",
        after - before
    );

    // The pilot with 128 live obstacles (DESIGN §18): a set taken every
    // tick and checked on arrival between ticks, the slow-down field, the
    // hold after a protective stop, the MPC's live rows, and a standing one
    // planned round. For 20 ticks they are beside the way at the ticks (set
    // 0: in reach of the MPC's rows) and in it between them (set 1), then
    // in it at the ticks as well (the hold, and what stands is planned
    // round); every other one stands.
    use control::live::{LiveClass, LiveObstacle, LiveSet, LiveSettings, LiveShape};
    let sets: Vec<LiveSet> = (0..2)
        .map(|j| {
            let obstacles: Vec<LiveObstacle> = (0..128)
                .map(|i| {
                    let off = if j == 0 { 9.0 } else { 0.0 };
                    let (x, y) = (
                        2.0 + 0.5 * (i % 16) as f64,
                        off - 6.0 + 1.5 * (i / 16) as f64,
                    );
                    let shape = if i % 2 == 0 {
                        LiveShape::circle([x, y], 0.3).unwrap()
                    } else {
                        LiveShape::polygon(&[[x, y], [x + 0.4, y], [x + 0.4, y + 0.3]]).unwrap()
                    };
                    // Other tracks in each set (ids 0.., 1000..): none teleports.
                    LiveObstacle::new(
                        i + 1000 * j as u32,
                        LiveClass::Person,
                        shape,
                        [0.0, 0.5 * (i % 2) as f64],
                        0.0,
                    )
                    .unwrap()
                })
                .collect();
            let mut set = LiveSet::new();
            set.set(0.0, &obstacles).unwrap();
            set
        })
        .collect();
    let mpc = Mpc::new(p, critic, Some(trained().0), MpcSettings::default()).unwrap();
    let mut pilot = Pilot::new(
        p,
        mpc,
        Some(navigator("delayed", true)),
        EnvelopeSettings::default(),
        Default::default(),
    )
    .unwrap();
    pilot
        .enable_live(LiveSettings {
            replan_after: 1.0,
            ..LiveSettings::default()
        })
        .unwrap();
    let start = State::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    let mut fresh = LiveSet::new();
    // A copy of `sets[j]` seen at `t`: fresh, the obstacles moving on.
    let restamp = |fresh: &mut LiveSet, j: usize, t: f64| {
        fresh.start(t).unwrap();
        for o in sets[j].obstacles() {
            fresh.push(LiveObstacle { stamp: t, ..*o }).unwrap();
        }
    };
    let before = common::allocations();
    pilot
        .set_goal(&start, Goal::new(12.0, 0.0, 0.0), &[], 0.0)
        .unwrap();
    let (mut stopped, mut ticks, mut rows) = (0, 0, 0);
    for k in 0..40 {
        let now = k as f64 * 0.2;
        let x = State::new(0.05 * k as f64, 0.0, 0.0, 0.0, 0.0, 0.5);
        restamp(&mut fresh, usize::from(k >= 20), now);
        pilot.set_live(&fresh);
        let command = match pilot.step(&x, now, Instant::now()).unwrap() {
            PilotDecision::Drive(s) => {
                ticks += usize::from(s.live.is_some());
                s.command
            }
            PilotDecision::Abort(_) | PilotDecision::Stop { .. } => VelocityCommand::ZERO,
        };
        pilot.sent(now, command);
        rows += usize::from(
            pilot
                .mpc()
                .live_rows()
                .is_some_and(|r| !r.near().is_empty()),
        );
        restamp(&mut fresh, 1, now + 0.1);
        pilot.set_live(&fresh);
        if let Some(g) = pilot.check_live(&x, now + 0.1) {
            stopped += 1;
            pilot.sent(now + 0.1, g.command);
        }
    }
    let after = common::allocations();
    assert_eq!(ticks, 40);
    assert!(stopped > 0, "the obstacles are in the way");
    assert!(rows > 20, "the MPC's live rows at {rows} ticks");
    let plans = pilot.navigator().map_or(0, |n| n.plans());
    assert!(plans >= 2, "planned round what stands: {plans} plans");
    assert_eq!(
        after - before,
        0,
        "{} allocations (pilot with live obstacles)",
        after - before
    );
}
