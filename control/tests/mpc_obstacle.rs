//! Acceptance (4): an obstacle on the straight path to the goal is avoided in
//! closed loop on the simulated machine, with no penetration beyond 5 cm,
//! and the goal is still reached. The trained critic does not exist yet, so
//! the stage cost is a simple attractive quadratic plus distance to the goal.

use control::model::{goal_distance, Goal, MachineParams, State};
use control::mpc::{Mpc, MpcSettings, Obstacle, ObstacleConstraint, QuadraticCost, StepStatus};
use control::{HessianMode, Plant, PlantConfig};

fn attractive() -> QuadraticCost {
    let mut c = QuadraticCost::diagonal([0.2, 0.2, 0.5, 0.1, 0.5, 0.5], [0.5, 0.5]);
    c.q_pos = 2.0;
    c
}

/// Runs 40 s; returns (minimum clearance over the run, final goal distance).
fn drive(
    settings: MpcSettings,
    plant_config: PlantConfig,
    obstacle: Obstacle,
    goal: Goal,
) -> (f64, f64) {
    let p = MachineParams::default();
    let mut mpc = Mpc::new(p, attractive(), None, settings).unwrap();
    mpc.set_goal(goal, &[obstacle]).unwrap();
    let mut plant = Plant::new(p, plant_config, State::zeros()).unwrap();
    let mut min_clearance = f64::INFINITY;
    let mut passed = false;
    for _ in 0..200 {
        let sol = mpc.step(&plant.state()).unwrap();
        assert_eq!(sol.status, StepStatus::Solved, "QP {:?}", sol.qp_status);
        plant.command(sol.command).unwrap();
        // Check the clearance of the real (continuous) path, not just at ticks.
        for _ in 0..10 {
            plant.advance(settings.dt / 10.0);
            let (h, _) = obstacle.clearance(&plant.state());
            min_clearance = min_clearance.min(h);
        }
        passed |= plant.state()[0] > obstacle.x + obstacle.radius;
    }
    assert!(passed, "never got past the obstacle");
    (min_clearance, goal_distance(&plant.state(), &goal))
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
        let (clearance, final_distance) = drive(settings, plant, obstacle, goal);
        eprintln!(
            "{name}: min clearance {clearance:.3} m, final goal distance {final_distance:.3}"
        );
        assert!(
            clearance > -0.05,
            "{name}: penetrated the obstacle by {:.3} m",
            -clearance
        );
        assert!(
            final_distance < 0.3,
            "{name}: ended {final_distance:.3} from the goal"
        );
    }
}
