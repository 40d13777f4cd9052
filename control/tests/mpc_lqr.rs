//! Acceptance (1): with linear dynamics and a quadratic cost, the MPC's QP
//! solution is the discrete-time LQR solution of the same finite-horizon
//! problem, computed here independently by the backward Riccati recursion.

/// The solver's wall-clock budget is a timing limit: times `WLNAV_TIMING_SCALE` (the shared
/// helper; emulation: scripts/cross-check.sh).
#[path = "../../tests/timing_scale.rs"]
mod timing_scale;

use control::model::{Control, ControlJacobian, Goal, MachineParams, State, StateJacobian};
use control::mpc::{ClarabelBackend, LinearDynamics, Mpc, MpcSettings, QuadraticCost, StepStatus};
use nalgebra::{SMatrix, SVector};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

type M6 = SMatrix<f64, 6, 6>;
type M2 = SMatrix<f64, 2, 2>;

/// Bounds so wide that no constraint is active (β must stay below 90°).
fn wide_params() -> MachineParams {
    MachineParams {
        beta_max: 1.5,
        beta_dot_max: 1e3,
        v_max: 1e3,
        beta_ddot_max: 1e3,
        a_max: 1e3,
        ..MachineParams::default()
    }
}

fn system(seed: u64) -> (LinearDynamics, QuadraticCost) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let a = M6::identity() + M6::from_fn(|_, _| rng.gen_range(-0.1..0.1));
    let b = ControlJacobian::from_fn(|_, _| rng.gen_range(-0.3..0.3));
    // Symmetric positive definite Q, R with couplings.
    let lq = M6::from_fn(|_, _| rng.gen_range(-0.5..0.5));
    let q = lq * lq.transpose() + M6::identity() * 0.5;
    let lr = M2::from_fn(|_, _| rng.gen_range(-0.5..0.5));
    let r = lr * lr.transpose() + M2::identity() * 0.2;
    let cost = QuadraticCost { q, r, q_pos: 0.0 };
    (
        LinearDynamics {
            a: StateJacobian::from(a),
            b,
        },
        cost,
    )
}

/// Finite-horizon LQR for Σ_{n<N} Δt (xᵀQx + uᵀRu) + x_Nᵀ Q x_N (the MPC's
/// Σ Δt·L(x_n, u_n) + L(x_N, 0) with L = xᵀQx + uᵀRu), rolled out from x₀.
fn riccati(
    dy: &LinearDynamics,
    cost: &QuadraticCost,
    dt: f64,
    n: usize,
    x0: &State,
) -> (Vec<State>, Vec<Control>) {
    let (a, b) = (dy.a, dy.b);
    let (qs, rs) = (cost.q * dt, cost.r * dt);
    let mut p = cost.q;
    let mut gains = vec![SMatrix::<f64, 2, 6>::zeros(); n];
    for k in (0..n).rev() {
        let s = rs + b.transpose() * p * b;
        let kk = s.try_inverse().unwrap() * b.transpose() * p * a;
        p = qs + a.transpose() * p * (a - b * kk);
        p = 0.5 * (p + p.transpose());
        gains[k] = kk;
    }
    let mut xs = vec![*x0];
    let mut us = Vec::new();
    for k in 0..n {
        let u: SVector<f64, 2> = -gains[k] * xs[k];
        us.push(u);
        xs.push(a * xs[k] + b * u);
    }
    (xs, us)
}

fn check(horizon: usize, seed: u64) {
    let (dy, cost) = system(seed);
    let settings = MpcSettings {
        horizon,
        levenberg_marquardt: 0.0,
        delay: 0.0,
        qp_tolerance: 1e-11,
        time_budget: timing_scale::secs(MpcSettings::default().time_budget),
        ..MpcSettings::default()
    };
    let params = wide_params();
    let mut mpc = Mpc::with_parts(params, cost, dy, None, settings, ClarabelBackend::new).unwrap();
    mpc.set_goal(Goal::new(0.0, 0.0, 0.0), &[]).unwrap();
    let mut x0 = State::new(0.8, -0.5, 0.3, 0.2, -0.1, 0.4);
    // LQR is linear in x₀: scale it so the soft bound |β| ≤ 1.5 stays inactive.
    let (xs, _) = riccati(&dy, &cost, settings.dt, horizon, &x0);
    let bmax = xs.iter().map(|x| x[3].abs()).fold(0.0, f64::max);
    x0 *= (1.0 / bmax).min(1.0);
    // Two ticks: from the hold roll-out, then from the shifted warm start.
    for tick in 0..2 {
        let sol = mpc.step(&x0, tick as f64 * settings.dt).unwrap().clone();
        assert_eq!(
            sol.status,
            StepStatus::Solved,
            "N={horizon} tick {tick}: {:?}",
            sol.qp_status
        );
        let (xs, us) = riccati(&dy, &cost, settings.dt, horizon, &x0);
        let mut worst: f64 = 0.0;
        for k in 0..horizon {
            worst = worst.max((sol.controls[k] - us[k]).amax());
            worst = worst.max((sol.states[k + 1] - xs[k + 1]).amax());
        }
        eprintln!(
            "N={horizon} tick {tick}: worst {worst:e} qp it {}",
            sol.qp_iterations
        );
        assert!(
            worst < 1e-6,
            "N={horizon} tick {tick}: QP vs Riccati differ by {worst:e}"
        );
        assert!(sol.max_state_slack() < 1e-8 && sol.max_obstacle_slack() < 1e-8);
        assert!(
            (sol.command.beta_dot - xs[1][4]).abs() < 1e-6
                && (sol.command.v - xs[1][5]).abs() < 1e-6
        );
        x0 = xs[1];
    }
}

#[test]
fn qp_equals_riccati_lqr() {
    check(10, 1);
    check(20, 2);
    check(40, 3);
}
