//! An obstacle on the straight path to the goal is avoided in closed loop on
//! the simulated machine by both axle points (DESIGN §10), and the goal is
//! still reached. The stage cost is a simple attractive quadratic plus
//! distance to the goal, so the test does not depend on trained weights.

use control::model::{goal_distance, Goal, MachineParams, State};
use control::mpc::{Mpc, MpcSettings, Obstacle, ObstacleConstraint, QuadraticCost, StepStatus};
use control::obstacle::footprint_clearance;
use control::{HessianMode, Plant, PlantConfig};

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
        plant.advance_observed(settings.dt, |x| {
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
