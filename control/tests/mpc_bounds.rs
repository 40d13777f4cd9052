//! Acceptance (3): planned controls and commands never leave their bounds, and
//! state bounds are only exceeded where the QP pays a slack for it (exact L1
//! penalty), in closed loop on the plant from states that force violations.

mod common;

use control::model::{ix, Goal, MachineParams, State};
use control::mpc::{Mpc, MpcSettings, QuadraticCost, Solution, StageCost, StepStatus};
use control::{HessianMode, Plant, PlantConfig};

/// The solver's wall-clock budget is a timing limit: times `WLNAV_TIMING_SCALE` (the shared
/// helper; emulation: scripts/cross-check.sh).
#[path = "../../tests/timing_scale.rs"]
mod timing_scale;

fn check_tick(p: &MachineParams, s: &MpcSettings, sol: &Solution) -> f64 {
    let umax = p.control_max();
    for (k, u) in sol.controls.iter().enumerate() {
        for i in 0..2 {
            assert!(
                u[i].abs() <= umax[i],
                "control {i} of stage {k} is {} beyond {}",
                u[i],
                umax[i]
            );
        }
    }
    assert!(sol.command.beta_dot.is_finite() && sol.command.v.is_finite());
    assert!(sol.command.beta_dot.abs() <= p.beta_dot_max && sol.command.v.abs() <= p.v_max);
    if sol.status != StepStatus::Solved {
        return 0.0;
    }
    let smax = [p.beta_max, p.beta_dot_max, p.v_max];
    let mut total = 0.0;
    for n in 1..=s.horizon {
        for (c, k) in [ix::BETA, ix::BETA_DOT, ix::V].into_iter().enumerate() {
            let violation = (sol.states[n][k].abs() - smax[c]).max(0.0);
            let slack = sol.state_slacks[n - 1][c];
            assert!(
                violation <= slack + 1e-7,
                "x_{n}[{k}] = {} exceeds its bound {} by {violation:e} with slack {slack:e}",
                sol.states[n][k],
                smax[c]
            );
            total += violation;
        }
    }
    // Paid to the per-component tolerance above (1e-7 each, 3N components).
    let tolerance = s.state_slack_weight * 1e-7 * (3 * s.horizon) as f64;
    assert!(
        sol.slack_cost >= s.state_slack_weight * total - tolerance,
        "slack not paid: {} < {}",
        sol.slack_cost,
        s.state_slack_weight * total
    );
    total
}

fn run<C: StageCost>(mut mpc: Mpc<C>, starts: &[State], goal: Goal, ticks: usize) -> f64 {
    let p = *mpc.params();
    let s = *mpc.settings();
    let mut violations = 0.0;
    for x0 in starts {
        mpc.reset();
        mpc.set_goal(goal, &[]).unwrap();
        let mut plant = Plant::new(p, PlantConfig::ideal(), *x0).unwrap();
        // The first tick starts from the raw (unclamped) state.
        let mut measured = *x0;
        for tick in 0..ticks {
            let now = tick as f64 * s.dt;
            let sol = mpc.step(&measured, now).unwrap();
            assert_eq!(
                sol.status,
                StepStatus::Solved,
                "start {:?} tick {tick}: QP {:?}",
                x0.as_slice(),
                sol.qp_status
            );
            violations += check_tick(&p, &s, sol);
            let cmd = sol.command;
            plant.command(cmd).unwrap();
            mpc.sent(now, cmd);
            plant.advance(s.dt);
            measured = plant.state();
        }
    }
    violations
}

fn starts(p: &MachineParams) -> Vec<State> {
    vec![
        // Articulation swinging out too fast to stop before β_max.
        State::new(0.0, 0.0, 0.0, 0.85 * p.beta_max, p.beta_dot_max, 0.5),
        State::new(0.0, 0.0, 1.0, -0.85 * p.beta_max, -p.beta_dot_max, -0.5),
        // Already beyond the bounds (a measurement outside them).
        State::new(
            1.0,
            2.0,
            -2.0,
            1.05 * p.beta_max,
            1.1 * p.beta_dot_max,
            1.1 * p.v_max,
        ),
        State::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
    ]
}

#[test]
fn control_bounds_hard_state_bounds_paid() {
    let p = MachineParams::default();
    let mut total = 0.0;
    for hessian in [HessianMode::Exact, HessianMode::GaussNewton] {
        let s = MpcSettings {
            horizon: 10,
            hessian,
            delay: 0.0,
            time_budget: timing_scale::secs(MpcSettings::default().time_budget),
            ..MpcSettings::default()
        };
        let critic = common::random_critic(8, 5);
        let actor = common::random_actor(6);
        let mpc = Mpc::new(p, critic, Some(actor), s).unwrap();
        let v = run(mpc, &starts(&p), Goal::new(6.0, -3.0, 2.0), 25);
        eprintln!("{hessian:?}: {v:.3}");
        total += v;
    }
    // A cost that wants to go faster than v_max towards a far goal.
    let mut pull = QuadraticCost::diagonal([1.0, 1.0, 0.0, 0.0, 0.0, 0.0], [0.01, 0.01]);
    pull.q_pos = 5.0;
    let s = MpcSettings {
        horizon: 20,
        delay: 0.0,
        time_budget: timing_scale::secs(MpcSettings::default().time_budget),
        ..MpcSettings::default()
    };
    let mpc = Mpc::new(p, pull, None, s).unwrap();
    total += run(mpc, &starts(&p), Goal::new(40.0, 0.0, 0.0), 25);
    eprintln!("total paid state-bound violation: {total:.3}");
    assert!(
        total > 1e-3,
        "no state bound was ever violated: the test exercised nothing ({total:e})"
    );
}
