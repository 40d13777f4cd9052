//! An obstacle on the straight path to the goal is avoided in closed loop on
//! the simulated machine by both axle points (DESIGN §10), and the goal is
//! still reached. The stage cost is a simple attractive quadratic plus
//! distance to the goal, so the test does not depend on trained weights.

mod common;

use control::model::{goal_distance, Goal, MachineParams, State};
use control::mpc::{Mpc, MpcSettings, Obstacle, ObstacleConstraint, QuadraticCost, StepStatus};
use control::obstacle::footprint_clearance;
use control::{HessianMode, Plant, PlantConfig};

#[path = "../../tests/timing_scale.rs"]
mod timing_scale;

fn attractive() -> QuadraticCost {
    let mut c = QuadraticCost::diagonal([0.2, 0.2, 0.5, 0.1, 0.5, 0.5], [0.5, 0.5]);
    c.q_pos = 2.0;
    c
}

/// Runs `ticks` ticks from `start`; returns (minimum footprint clearance over
/// the run, on the plant's sub-steps, and the final state).
fn drive(
    settings: MpcSettings,
    plant_config: PlantConfig,
    obstacle: Obstacle,
    start: State,
    goal: Goal,
    ticks: usize,
) -> (f64, State) {
    let p = MachineParams::default();
    // The solver's wall-clock budget is a timing limit (WLNAV_TIMING_SCALE; under qemu
    // a QP hit the unscaled 0.1 s: MaxTime, Fallback(QpFailed)).
    let settings = MpcSettings {
        time_budget: timing_scale::secs(settings.time_budget),
        ..settings
    };
    let mut mpc = Mpc::new(p, attractive(), None, settings).unwrap();
    mpc.set_goal(goal, &[obstacle]).unwrap();
    let mut plant = Plant::new(p, plant_config, start).unwrap();
    let mut min_clearance = footprint_clearance(&p, &start, &[obstacle]);
    for tick in 0..ticks {
        let now = tick as f64 * settings.dt;
        let sol = mpc.step(&plant.state(), now).unwrap();
        assert_eq!(sol.status, StepStatus::Solved, "QP {:?}", sol.qp_status);
        let cmd = sol.command;
        plant.command(cmd).unwrap();
        mpc.sent(now, cmd);
        plant.advance_observed(settings.dt, |_, x| {
            min_clearance = min_clearance.min(footprint_clearance(&p, x, &[obstacle]))
        });
    }
    (min_clearance, plant.state())
}

#[test]
fn obstacle_on_the_straight_path_is_avoided() {
    let goal = Goal::new(10.0, 0.0, 0.0);
    // Slightly off the line, so the side to pass on is not a tie.
    let obstacle = Obstacle::new(5.0, 0.1, 1.0);
    let cases = [
        (
            "distance, exact, ideal plant",
            ObstacleConstraint::Distance,
            HessianMode::Exact,
            0.0,
        ),
        (
            "distance, Gauss-Newton, 0.2 s delay",
            ObstacleConstraint::Distance,
            HessianMode::GaussNewton,
            0.2,
        ),
        (
            "CBF, exact, ideal plant",
            ObstacleConstraint::Cbf,
            HessianMode::Exact,
            0.0,
        ),
    ];
    for (name, form, hessian, delay) in cases {
        let settings = MpcSettings {
            horizon: 20,
            hessian,
            obstacle_constraint: form,
            delay,
            ..MpcSettings::default()
        };
        let plant = PlantConfig {
            delay,
            ..PlantConfig::ideal()
        };
        let (clearance, end) = drive(settings, plant, obstacle, State::zeros(), goal, 200);
        let final_distance = goal_distance(&end, &goal);
        eprintln!(
            "{name}: min clearance {clearance:.3} m, final goal distance {final_distance:.3}"
        );
        assert!(
            clearance > -0.005,
            "{name}: penetrated the obstacle by {:.3} m",
            -clearance
        );
        assert!(
            final_distance < 0.3,
            "{name}: ended {final_distance:.3} from the goal"
        );
    }
}

/// The rear axle is kept out too: a goal 0.5 m straight behind, with a circle
/// behind the rear axle that only the rear axle would enter. The MPC backs up
/// until the rear axle is at the circle's edge and no further; a controller
/// that watched the front axle alone would end with the rear axle 0.2 m deep.
#[test]
fn the_rear_axle_stays_out_when_reversing() {
    let p = MachineParams::default();
    let start = State::zeros();
    // Rear axle at (−1.2, 0); the circle's edge at x = −1.5.
    let obstacle = Obstacle::new(-2.0, 0.0, 0.5);
    let goal = Goal::new(-0.5, 0.0, 0.0);
    let settings = MpcSettings::default();
    let (clearance, end) = drive(settings, PlantConfig::ideal(), obstacle, start, goal, 75);
    assert!(
        clearance > -0.005,
        "rear axle entered the circle by {:.3} m",
        -clearance
    );
    // It did reverse towards the goal (as far as the rear axle allows).
    assert!(end[0] < -0.15, "did not back up: x_f {:.3}", end[0]);
    let front_only_end = -0.5 - p.l_f - p.l_r;
    assert!(obstacle.clearance_of([front_only_end, 0.0]) < -0.19);
}

/// Issue 26: the obstacle rows' L1 weight is raised while a QP buys penetration
/// (its slack beyond the margin, its multipliers at the weight) and starts
/// again from the configured one with a new goal. A random critic at N = 40
/// plans through the circles (mpc_alloc sees the discarded plans).
#[test]
fn the_obstacle_weight_rises_while_penetration_is_bought_and_resets_with_a_new_goal() {
    let p = MachineParams::default();
    let obstacles = [Obstacle::new(3.0, 1.0, 0.8), Obstacle::new(2.0, 4.0, 0.5)];
    let settings = MpcSettings {
        horizon: 40,
        hessian: HessianMode::Exact,
        // One QP per tick: the solution's slack is the QP that raised it.
        sqp_iterations: 1,
        time_budget: 10.0,
        ..MpcSettings::default()
    };
    let mut mpc = Mpc::new(
        p,
        common::random_critic(8, 11),
        Some(common::random_actor(12)),
        settings,
    )
    .unwrap();
    assert_eq!(mpc.obstacle_weight(), settings.obstacle_slack_weight);
    mpc.set_goal(Goal::new(4.5, 4.5, 1.0), &obstacles).unwrap();
    let mut plant = Plant::new(p, PlantConfig::default(), State::zeros()).unwrap();
    let mut raised = false;
    for tick in 0..30 {
        let now = tick as f64 * settings.dt;
        let before = mpc.obstacle_weight();
        let sol = mpc.step(&plant.state(), now).unwrap();
        let (slack, multiplier, command) = (
            sol.max_obstacle_slack(),
            sol.obstacle_multiplier,
            sol.command,
        );
        let after = mpc.obstacle_weight();
        if after > before {
            // Raised only when bought, tenfold.
            assert!(slack > settings.obstacle_margin, "slack {slack}");
            assert!(multiplier >= 0.999 * before, "multiplier {multiplier}");
            assert_eq!(after, (10.0 * before).min(1e6));
            raised = true;
        }
        mpc.sent(now, command);
        plant.command(command).unwrap();
        plant.advance(settings.dt);
    }
    assert!(
        raised,
        "the weight never rose (weight {})",
        mpc.obstacle_weight()
    );
    mpc.set_goal(Goal::new(-4.0, 0.0, 0.0), &obstacles).unwrap();
    assert_eq!(mpc.obstacle_weight(), settings.obstacle_slack_weight);
}

/// Issue 30: the QP has rows only for the circles within the horizon's reach.
/// A circle beyond it changes nothing (the same QP as open ground, so the
/// same commands bit for bit); one within it gets rows.
#[test]
fn circles_beyond_reach_get_no_rows_and_change_nothing() {
    let p = MachineParams::default();
    // No time limit: two solves compared bit for bit must not differ by one
    // of them timing out on a loaded (or emulated) machine.
    let settings = MpcSettings {
        time_budget: 1e3,
        ..MpcSettings::default()
    };
    let reach = settings.obstacle_reach(&p);
    let goal = Goal::new(6.0, 0.0, 0.0);
    // Behind the start, its edge 0.5 m beyond reach of the front axle.
    let far = Obstacle::new(-(reach + 0.5 + 1.0), 0.0, 1.0);
    let near = Obstacle::new(0.0, 3.0, 1.0);
    let mut open = Mpc::new(p, attractive(), None, settings).unwrap();
    let mut with_far = Mpc::new(p, attractive(), None, settings).unwrap();
    open.set_goal(goal, &[]).unwrap();
    with_far.set_goal(goal, &[far]).unwrap();
    let x = State::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    for tick in 0..5 {
        let now = tick as f64 * settings.dt;
        let a = open.step(&x, now).unwrap().clone();
        let b = with_far.step(&x, now).unwrap().clone();
        assert_eq!(with_far.layout().n_obs, 0);
        assert_eq!(with_far.active_obstacles().count(), 0);
        assert_eq!(a.command, b.command, "tick {tick}");
        assert_eq!(a.states, b.states, "tick {tick}");
        open.sent(now, a.command);
        with_far.sent(now, b.command);
    }
    // Within reach (and the far one still not): one circle's rows, the near one.
    let mut mpc = Mpc::new(p, attractive(), None, settings).unwrap();
    mpc.set_goal(goal, &[far, near]).unwrap();
    mpc.step(&x, 0.0).unwrap();
    assert_eq!(mpc.layout().n_obs, 1);
    assert_eq!(
        mpc.active_obstacles().copied().collect::<Vec<_>>(),
        vec![near]
    );
    // The reach covers the horizon at 1.25 × top speed and the rear axle.
    assert!(reach >= 1.25 * p.v_max * settings.horizon as f64 * settings.dt + p.l_f + p.l_r);
}
