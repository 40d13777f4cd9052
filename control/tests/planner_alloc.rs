//! The navigator allocates nothing after construction: not in `set_goal`
//! (which plans), not in `update` (which may replan). One test in this binary,
//! so no other test thread allocates while we count.

mod common;

use control::model::{Goal, MachineParams, State};
use control::mpc::MpcSettings;
use control::obstacle::Obstacle;
use control::planner::{NavStep, Navigator, NavigatorSettings, PlanOutcome, PlannerKind, Tracking};
use control::weights;
use control::{Actor, Critic};

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

#[test]
fn set_goal_and_update_do_not_allocate() {
    let wall: Vec<Obstacle> = (-4..=4)
        .map(|k| Obstacle::new(4.0, 0.8 * k as f64, 0.6))
        .collect();
    let goal = Goal::new(8.0, 0.0, 0.0);
    let start = State::zeros();
    for kind in [PlannerKind::HybridAStar, PlannerKind::WaypointGraph] {
        for networks in [false, true] {
            if kind == PlannerKind::WaypointGraph && !networks {
                continue;
            }
            // The path smoother on too (off by default): it smooths in place.
            let settings = NavigatorSettings {
                planner: kind,
                smooth_iterations: 30,
                ..NavigatorSettings::default()
            };
            let nets = networks.then(trained);
            let mut nav = Navigator::new(MachineParams::default(), settings, nets).unwrap();
            let before = common::allocations();
            nav.set_goal(&start, goal, &wall).unwrap();
            let planned = nav.last_plan().unwrap().outcome;
            let mut steps = 0;
            // Standing still behind the wall: replans, then the abort.
            for k in 0..60 {
                if let NavStep::Abort(_) = nav.update(&start, k as f64 * 0.2) {
                    break;
                }
                steps += 1;
            }
            let replans = nav.plans();
            // Open ground: direct.
            nav.set_goal(&start, goal, &[]).unwrap();
            for k in 0..50 {
                let x = State::new(0.1 * k as f64, 0.0, 0.0, 0.0, 0.0, 0.5);
                nav.update(&x, k as f64 * 0.2);
            }
            let after = common::allocations();
            assert_eq!(planned, PlanOutcome::Route, "{kind:?} networks {networks}");
            assert!(replans >= 2, "no replan happened");
            assert!(steps > 10);
            assert_eq!(
                after - before,
                0,
                "{} allocations ({kind:?}, networks {networks})",
                after - before
            );
        }
    }
    // The carrot and the stall ladder's back-up with its keep-out replan
    // (both off by default): drive along a track, stand, back up, replan.
    let settings = NavigatorSettings {
        tracking: Tracking::Carrot,
        back_up_distance: 2.5,
        ..NavigatorSettings::default()
    };
    let mut nav = Navigator::new(MachineParams::default(), settings, Some(trained())).unwrap();
    let before = common::allocations();
    nav.set_goal(&State::new(-3.0, -1.0, 0.0, 0.0, 0.0, 0.0), goal, &wall)
        .unwrap();
    let mut t = 0.0;
    for k in 0..=20 {
        let x = State::new(-3.0 + 0.25 * k as f64, -1.0, 0.0, 0.0, 1.0, 0.0);
        nav.update(&x, t);
        t += 0.2;
    }
    let (mut stuck, mut backed_up) = (State::new(2.0, -1.0, 0.0, 0.0, 0.0, 0.0), false);
    while t < 40.0 {
        if let NavStep::Abort(_) = nav.update(&stuck, t) {
            break;
        }
        if !backed_up && nav.last_plan().map(|r| r.outcome) == Some(PlanOutcome::BackUp) {
            backed_up = true;
            // Arrive at the back-up pose: the keep-out replan.
            stuck = State::new(nav.route()[0].x, nav.route()[0].y, 0.0, 0.0, 0.0, 0.0);
        }
        t += 0.2;
    }
    let after = common::allocations();
    assert!(backed_up, "no back-up happened");
    assert_eq!(
        after - before,
        0,
        "{} allocations (carrot, back-up)",
        after - before
    );
    // The cost-to-go field and the path cost (issue 27): computed inside
    // `update` (the path cost with the goal shot driven again), and copied
    // into an MPC as wlnav-sim and wlnavd do.
    let (critic, actor) = {
        let (a, c) = trained();
        (c, a)
    };
    let mut mpc = control::mpc::Mpc::new(
        MachineParams::default(),
        critic,
        Some(actor),
        MpcSettings::default(),
    )
    .unwrap();
    mpc.reserve_cost_to_go(NavigatorSettings::default().grid_cells());
    for tracking in [Tracking::Field, Tracking::Path] {
        let settings = NavigatorSettings {
            tracking,
            ..NavigatorSettings::default()
        };
        let mut nav = Navigator::new(MachineParams::default(), settings, Some(trained())).unwrap();
        let before = common::allocations();
        nav.set_goal(&start, goal, &wall).unwrap();
        let (mut costs, mut versions, mut seen) = (0, 0, None);
        for k in 0..80 {
            // Around the wall's lower end, then on to the goal.
            let x = State::new(0.1 * k as f64, -0.05 * k as f64, 0.0, 0.0, 0.0, 0.5);
            nav.update(&x, k as f64 * 0.2);
            costs += usize::from(nav.cost_to_go().is_some() || nav.path_cost().is_some());
            let version = seen;
            nav.sync_costs(&mut mpc, &mut seen);
            versions += usize::from(seen != version);
        }
        let after = common::allocations();
        assert!(
            costs > 0 && versions >= 2,
            "{tracking:?}: {costs} {versions}"
        );
        assert_eq!(
            after - before,
            0,
            "{} allocations ({tracking:?})",
            after - before
        );
    }
}
