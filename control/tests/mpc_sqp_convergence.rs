//! Acceptance (2): SQP iterated to convergence on a small nonlinear problem
//! (RK4 wheel-loader model, N = 5, active control bounds) reaches the optimum
//! found by an independent method: projected Newton on the single-shooting
//! problem with finite-difference derivatives. The KKT conditions of the
//! reduced problem are checked at the MPC's solution with finite differences.

use control::model::{rk4_step, Control, Goal, MachineParams, State};
use control::mpc::{Mpc, MpcSettings, QuadraticCost, StageCost, StepStatus};
use control::{Derivatives, HessianMode};
use nalgebra::{DMatrix, DVector};

const N: usize = 5;
const DT: f64 = 0.2;

/// Wide state bounds (never active), the real control bounds (active).
fn params() -> MachineParams {
    MachineParams {
        beta_max: 1.4,
        beta_dot_max: 10.0,
        v_max: 10.0,
        ..MachineParams::default()
    }
}

fn cost() -> QuadraticCost {
    let mut c = QuadraticCost::diagonal([1.0, 1.0, 0.3, 0.2, 0.1, 0.1], [0.5, 0.05]);
    c.q_pos = 0.5;
    c
}

fn x0() -> State {
    State::new(0.0, 0.0, 0.2, 0.1, 0.0, 0.3)
}

fn goal() -> Goal {
    Goal::new(3.0, 1.0, 0.6)
}

/// Single-shooting objective J(u) = Σ Δt L(x_n, u_n) + L(x_N, 0).
fn objective(u: &[f64]) -> f64 {
    let (p, c, g) = (params(), cost(), goal());
    let mut x = x0();
    let mut d = Derivatives::default();
    let mut j = 0.0;
    for k in 0..N {
        let uk = Control::new(u[2 * k], u[2 * k + 1]);
        c.stage(&mut (), &x, &uk, &g, HessianMode::Exact, &mut d);
        j += DT * d.value;
        x = rk4_step(&p, &x, &uk, DT);
    }
    c.stage(
        &mut (),
        &x,
        &Control::zeros(),
        &g,
        HessianMode::Exact,
        &mut d,
    );
    j + d.value
}

fn fd_gradient(u: &[f64], h: f64) -> DVector<f64> {
    DVector::from_fn(u.len(), |i, _| {
        let (mut up, mut um) = (u.to_vec(), u.to_vec());
        up[i] += h;
        um[i] -= h;
        (objective(&up) - objective(&um)) / (2.0 * h)
    })
}

fn fd_hessian(u: &[f64]) -> DMatrix<f64> {
    let h = 1e-4;
    let mut m = DMatrix::zeros(u.len(), u.len());
    for j in 0..u.len() {
        let (mut up, mut um) = (u.to_vec(), u.to_vec());
        up[j] += h;
        um[j] -= h;
        let col = (fd_gradient(&up, 1e-6) - fd_gradient(&um, 1e-6)) / (2.0 * h);
        m.set_column(j, &col);
    }
    0.5 * (&m + m.transpose())
}

fn upper(i: usize) -> f64 {
    let p = params();
    if i % 2 == 0 {
        p.beta_ddot_max
    } else {
        p.a_max
    }
}

/// Components held at a bound by the sign of the gradient (the KKT active set).
fn active(u: &[f64], g: &DVector<f64>, tol: f64) -> Vec<bool> {
    (0..u.len())
        .map(|i| (u[i] >= upper(i) - tol && g[i] < 0.0) || (u[i] <= -upper(i) + tol && g[i] > 0.0))
        .collect()
}

/// Projected Newton with finite-difference derivatives and backtracking.
fn independent_solve() -> Vec<f64> {
    let mut u = vec![0.0; 2 * N];
    for _ in 0..200 {
        let g = fd_gradient(&u, 1e-6);
        let act = active(&u, &g, 1e-10);
        let free: Vec<usize> = (0..u.len()).filter(|&i| !act[i]).collect();
        let pg = free.iter().map(|&i| g[i].abs()).fold(0.0, f64::max);
        if pg < 1e-9 {
            break;
        }
        let h = fd_hessian(&u);
        let hf = DMatrix::from_fn(free.len(), free.len(), |a, b| h[(free[a], free[b])]);
        let gf = DVector::from_fn(free.len(), |a, _| g[free[a]]);
        let df = match hf.clone().cholesky() {
            Some(ch) => -ch.solve(&gf),
            None => -gf.clone(),
        };
        let j0 = objective(&u);
        let mut alpha = 1.0;
        loop {
            let mut trial = u.clone();
            for (a, &i) in free.iter().enumerate() {
                trial[i] = (u[i] + alpha * df[a]).clamp(-upper(i), upper(i));
            }
            if objective(&trial) < j0 || alpha < 1e-8 {
                u = trial;
                break;
            }
            alpha *= 0.5;
        }
    }
    u
}

#[test]
fn sqp_converges_to_the_independent_optimum() {
    for mode in [HessianMode::Exact, HessianMode::GaussNewton] {
        let settings = MpcSettings {
            horizon: N,
            dt: DT,
            hessian: mode,
            delay: 0.0,
            sqp_iterations: 200,
            sqp_tolerance: 1e-11,
            levenberg_marquardt: 0.0,
            qp_tolerance: 1e-11,
            time_budget: 10.0,
            max_obstacles: 0,
            ..MpcSettings::default()
        };
        let mut mpc = Mpc::new(params(), cost(), None, settings).unwrap();
        mpc.set_goal(goal(), &[]).unwrap();
        let sol = mpc.step(&x0(), 0.0).unwrap().clone();
        assert_eq!(sol.status, StepStatus::Solved);
        assert!(
            sol.step_norm < 1e-11,
            "SQP did not converge: step {:e} after {}",
            sol.step_norm,
            sol.sqp_iterations
        );
        assert!(sol.sqp_iterations > 2, "the problem should be nonlinear");

        // The plan is dynamically consistent.
        let mut x = x0();
        for k in 0..N {
            x = rk4_step(&params(), &x, &sol.controls[k], DT);
            assert!((x - sol.states[k + 1]).amax() < 1e-9, "defect at stage {k}");
        }

        // KKT of min J(u) s.t. |u| ≤ u_max, by finite differences: zero gradient
        // on free components, gradient pushing outwards on bound ones.
        let u: Vec<f64> = sol.controls.iter().flat_map(|c| [c[0], c[1]]).collect();
        let g = fd_gradient(&u, 1e-6);
        let mut n_active = 0;
        for i in 0..u.len() {
            let at_upper = u[i] >= upper(i) - 1e-7;
            let at_lower = u[i] <= -upper(i) + 1e-7;
            if at_upper {
                n_active += 1;
                assert!(
                    g[i] < 1e-6,
                    "u[{i}] at its upper bound but ∂J/∂u = {}",
                    g[i]
                );
            } else if at_lower {
                n_active += 1;
                assert!(
                    g[i] > -1e-6,
                    "u[{i}] at its lower bound but ∂J/∂u = {}",
                    g[i]
                );
            } else {
                assert!(g[i].abs() < 1e-6, "u[{i}] free but ∂J/∂u = {}", g[i]);
            }
        }
        assert!(n_active >= 1, "the test needs an active control bound");
        // Second-order: positive definite reduced Hessian on the free components.
        let h = fd_hessian(&u);
        let free: Vec<usize> = (0..u.len())
            .filter(|&i| u[i].abs() < upper(i) - 1e-7)
            .collect();
        let hf = DMatrix::from_fn(free.len(), free.len(), |a, b| h[(free[a], free[b])]);
        assert!(hf.symmetric_eigenvalues().min() > 0.0);

        // Same optimum as the independent solve.
        let reference = independent_solve();
        let diff = u
            .iter()
            .zip(&reference)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        eprintln!(
            "{mode:?}: {} SQP iterations, {n_active} active bounds, |u − u_ref| = {diff:e}",
            sol.sqp_iterations
        );
        assert!(
            diff < 1e-6,
            "SQP and independent optimum differ by {diff:e}"
        );
        assert!((sol.cost - objective(&u)).abs() < 1e-9);
    }
}
