//! The baseline and min-time NLPs: exact derivatives against finite
//! differences, and solutions that do what they claim.

use control::model::{goal_distance, ix, Goal, MachineParams, State};
use control::scenario::{Obstacle, Scenario};
use sim::nlp::{finite_difference_check, HessianKind};
use sim::ocp::{self, BaselineSettings, MinTimeSettings};

fn scenario(goal: Goal, obstacles: Vec<Obstacle>) -> Scenario {
    Scenario {
        name: "t".into(),
        start: State::zeros(),
        goal,
        obstacles,
    }
}

/// A point that is neither feasible nor trivial: every derivative term is exercised.
fn wiggly_point(n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| 0.3 * ((i as f64) * 0.7).sin() + 0.05 * (i % 5) as f64)
        .collect()
}

#[test]
fn baseline_and_min_time_gradients_match_finite_differences() {
    let p = MachineParams::default();
    let sc = scenario(Goal::new(3.0, 1.0, 2.5), vec![Obstacle::new(1.0, 0.2, 0.4)]);
    let s = BaselineSettings {
        horizon: 2.0,
        ..Default::default()
    };
    let mut nlp = ocp::baseline_nlp(&p, &sc, &s, 2.5);
    let z = wiggly_point(sim::ipopt::Nlp::n(&nlp));
    let (eg, ej) = finite_difference_check(&mut nlp, &z);
    assert!(eg < 1e-6, "baseline objective gradient error {eg}");
    assert!(ej < 1e-6, "baseline constraint Jacobian error {ej}");

    let s = MinTimeSettings {
        intervals: 6,
        ..Default::default()
    };
    let mut nlp = ocp::min_time_nlp(&p, &sc, &s, 2.5);
    let mut z = wiggly_point(sim::ipopt::Nlp::n(&nlp));
    *z.last_mut().unwrap() = 3.0;
    let (eg, ej) = finite_difference_check(&mut nlp, &z);
    assert!(eg < 1e-6, "min-time objective gradient error {eg}");
    assert!(ej < 1e-6, "min-time constraint Jacobian error {ej}");
}

#[test]
fn baseline_straight_ahead_is_feasible_and_ends_at_rest_at_the_goal() {
    let p = MachineParams::default();
    let goal = Goal::new(4.5, 0.0, 0.0);
    let sc = scenario(goal, vec![]);
    let plan = ocp::solve_baseline(&p, &sc, &BaselineSettings::default());
    assert!(plan.status.success(), "{}", plan.status.name());
    assert!(plan.violation < 1e-6, "violation {}", plan.violation);
    let last = plan.states.last().unwrap();
    assert!(goal_distance(last, &goal) < 1e-6);
    assert!(
        last[ix::V].abs() < 1e-9 && last[ix::BETA_DOT].abs() < 1e-9 && last[ix::BETA].abs() < 1e-9
    );
    for x in &plan.states {
        assert!(x[ix::V].abs() <= p.v_max + 1e-7 && x[ix::BETA].abs() <= p.beta_max + 1e-7);
    }
    // Replayed on the RK4 model its controls reach the goal.
    let traj = ocp::replay(&p, &sc.start, &plan.controls, plan.dt, 30.0);
    let t = traj
        .iter()
        .position(|x| goal_distance(x, &goal) < 0.1)
        .expect("replay converges");
    let t = t as f64 * 0.2;
    eprintln!(
        "baseline straight 4.5 m: converges at {t:.1} s, solved in {:?}",
        plan.solve_time
    );
    assert!(t > 4.5 && t < 25.0);
    assert!(goal_distance(traj.last().unwrap(), &goal) < 0.02);
}

#[test]
fn min_time_straight_ahead_is_close_to_the_bang_bang_time() {
    let p = MachineParams::default();
    let goal = Goal::new(4.5, 0.0, 0.0);
    let sc = scenario(goal, vec![]);
    let r = ocp::solve_min_time(&p, &sc, &MinTimeSettings::default(), &[]);
    // Accelerate at 1 m/s² to 1 m/s (0.5 m in 1 s), cruise: reach 4.4 m at 4.9 s.
    eprintln!(
        "min-time straight 4.5 m: {:.3} s in {:?} ({} attempts)",
        r.time, r.solve_time, r.attempts
    );
    assert!((r.time - 4.9).abs() < 0.05, "T* = {}", r.time);
    let _ = HessianKind::Lbfgs;
}
