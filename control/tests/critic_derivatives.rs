//! Critic gradient and Hessian against central differences of the value, and
//! the Gauss–Newton form against the exact Hessian where Q = 0.

mod common;

use control::encoder::NZ;
use control::mlp::{Layer, Mlp, MlpWorkspace};
use control::model::{Control, Goal, State};
use control::weights::NetworkWeights;
use control::{Critic, CriticWorkspace, Derivatives, HessianMode, TerminalDerivatives};

fn split(z: &[f64; NZ]) -> (State, Control) {
    (State::from_column_slice(&z[..6]), Control::new(z[6], z[7]))
}

fn points() -> Vec<([f64; NZ], Goal)> {
    vec![
        (
            [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            Goal::new(4.5, 0.0, 0.0),
        ),
        (
            [1.0, -2.0, 0.7, 0.3, -0.2, 0.8, 0.4, -0.6],
            Goal::new(-3.0, 6.0, 2.2),
        ),
        (
            [6.0, 2.0, -2.9, -0.6, 0.5, -0.9, -0.5, 1.0],
            Goal::new(6.2, 2.1, 3.0),
        ),
        (
            [-4.0, 5.0, 1.5, 0.65, 0.55, 0.2, 0.1, 0.0],
            Goal::new(0.0, 0.0, -1.0),
        ),
    ]
}

fn rel_err(a: f64, b: f64, scale: f64) -> f64 {
    (a - b).abs() / scale.max(1e-12)
}

#[test]
fn gradient_and_hessian_match_central_differences() {
    for m in [1, 8] {
        let critic = common::random_critic(m, 11 + m as u64);
        let mut ws = CriticWorkspace::new(&critic);
        for (z, g) in points() {
            let (x, u) = split(&z);
            let mut d = Derivatives::default();
            critic.hessian(&mut ws, &x, &u, &g, HessianMode::Exact, &mut d);
            let mut grad = [0.0; NZ];
            let v = critic.value_gradient(&mut ws, &x, &u, &g, &mut grad);
            assert!((v - d.value).abs() <= 1e-14 * v.abs().max(1.0));
            assert!((v - critic.value(&mut ws, &x, &u, &g)).abs() <= 1e-14 * v.abs().max(1.0));

            let grad_scale = grad.iter().fold(0.0_f64, |a, b| a.max(b.abs()));
            let hess_scale = d.hess.iter().flatten().fold(0.0_f64, |a, b| a.max(b.abs()));
            let h = 1e-5;
            for j in 0..NZ {
                let (mut zp, mut zm) = (z, z);
                zp[j] += h;
                zm[j] -= h;
                let (xp, up) = split(&zp);
                let (xm, um) = split(&zm);
                // Gradient vs differences of the value.
                let fd = (critic.value(&mut ws, &xp, &up, &g)
                    - critic.value(&mut ws, &xm, &um, &g))
                    / (2.0 * h);
                assert!(
                    rel_err(grad[j], fd, grad_scale) <= 1e-5,
                    "m={m} ∂L/∂z{j}: {} vs {fd}",
                    grad[j]
                );
                assert!((grad[j] - d.grad[j]).abs() <= 1e-12 * grad_scale.max(1.0));
                // Hessian column vs differences of the gradient.
                let (mut gp, mut gm) = ([0.0; NZ], [0.0; NZ]);
                critic.value_gradient(&mut ws, &xp, &up, &g, &mut gp);
                critic.value_gradient(&mut ws, &xm, &um, &g, &mut gm);
                for i in 0..NZ {
                    let fd = (gp[i] - gm[i]) / (2.0 * h);
                    assert!(
                        rel_err(d.hess[i][j], fd, hess_scale) <= 1e-5,
                        "m={m} ∂²L/∂z{i}∂z{j}: {} vs {fd}",
                        d.hess[i][j]
                    );
                }
            }
            // Symmetry.
            for i in 0..NZ {
                for j in 0..NZ {
                    assert!((d.hess[i][j] - d.hess[j][i]).abs() <= 1e-12 * hess_scale);
                }
            }
        }
    }
}

#[test]
fn terminal_variant_is_the_state_block_at_zero_control() {
    let critic = common::random_critic(4, 5);
    let mut ws = CriticWorkspace::new(&critic);
    for (z, g) in points() {
        let (x, _) = split(&z);
        let mut full = Derivatives::default();
        critic.hessian(
            &mut ws,
            &x,
            &Control::zeros(),
            &g,
            HessianMode::Exact,
            &mut full,
        );
        let mut t = TerminalDerivatives::default();
        critic.terminal_hessian(&mut ws, &x, &g, HessianMode::Exact, &mut t);
        assert_eq!(t.value, full.value);
        assert_eq!(&t.grad[..], &full.grad[..6]);
        for i in 0..6 {
            assert_eq!(&t.hess[i][..], &full.hess[i][..6]);
        }
    }
}

/// Shifts the output bias so that Q(x, u, g) = 0 at the given point.
fn zero_q_at(w: &NetworkWeights, x: &State, u: &Control, g: &Goal) -> Critic {
    let critic = Critic::from_weights(w.clone()).unwrap();
    let mut ws = CriticWorkspace::new(&critic);
    critic.value(&mut ws, x, u, g);
    // Recompute Q with the MLP directly to get the output vector.
    let mut f = [0.0; 9];
    critic.encoder().encode(x, u, g, &mut f);
    let mut mws = MlpWorkspace::new(critic.mlp());
    critic.mlp().forward(&f, &mut mws);
    let mut layers: Vec<Layer> = critic.mlp().layers().to_vec();
    let last = layers.last_mut().unwrap();
    for (b, q) in last.bias.iter_mut().zip(&mws.out) {
        *b -= q;
    }
    let mut w = w.clone();
    w.mlp = Mlp::new(layers).unwrap();
    Critic::from_weights(w).unwrap()
}

#[test]
fn gauss_newton_equals_exact_hessian_where_q_vanishes() {
    let w = common::random_critic_weights(6, 99);
    for (z, g) in points() {
        let (x, u) = split(&z);
        let critic = zero_q_at(&w, &x, &u, &g);
        let mut ws = CriticWorkspace::new(&critic);
        let (mut exact, mut gn) = (Derivatives::default(), Derivatives::default());
        critic.hessian(&mut ws, &x, &u, &g, HessianMode::Exact, &mut exact);
        critic.hessian(&mut ws, &x, &u, &g, HessianMode::GaussNewton, &mut gn);
        assert!(exact.value < 1e-20, "Q was not zeroed: L = {}", exact.value);
        let scale = exact
            .hess
            .iter()
            .flatten()
            .fold(0.0_f64, |a, b| a.max(b.abs()));
        assert!(scale > 1e-6, "degenerate test point");
        for i in 0..NZ {
            for j in 0..NZ {
                assert!((exact.hess[i][j] - gn.hess[i][j]).abs() <= 1e-10 * scale);
            }
        }
        // Away from that point the second-order term is there, so they differ.
        let x2 = x + State::from_element(0.3);
        critic.hessian(&mut ws, &x2, &u, &g, HessianMode::Exact, &mut exact);
        critic.hessian(&mut ws, &x2, &u, &g, HessianMode::GaussNewton, &mut gn);
        let diff = exact
            .hess
            .iter()
            .flatten()
            .zip(gn.hess.iter().flatten())
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(diff > 1e-8);
    }
}

#[test]
fn gauss_newton_is_positive_semidefinite() {
    let critic = common::random_critic(8, 3);
    let mut ws = CriticWorkspace::new(&critic);
    for (z, g) in points() {
        let (x, u) = split(&z);
        let mut d = Derivatives::default();
        critic.hessian(&mut ws, &x, &u, &g, HessianMode::GaussNewton, &mut d);
        let h = nalgebra::SMatrix::<f64, 8, 8>::from_fn(|i, j| d.hess[i][j]);
        let min_eig = h.symmetric_eigenvalues().min();
        assert!(min_eig >= -1e-10 * h.norm(), "min eigenvalue {min_eig}");
    }
}
