//! Critic/actor kernels and the model step on the paper's layer sizes
//! (48, 96, 144, 96, 48), with the training default of m = 16 critic outputs.
//! `cargo bench -p control --bench kernels`; figures go into the README.

use std::hint::black_box;

use control::encoder::NZ;
use control::mlp::PAPER_HIDDEN;
use control::model::{rk4_step_with_jacobians, Control, Goal, MachineParams, State};
use control::weights::{random_network, NetworkMetadata, NetworkRole};
use control::{Actor, ActorWorkspace, Critic, CriticWorkspace, Derivatives, HessianMode};
use criterion::{criterion_group, criterion_main, Criterion};

fn kernels(c: &mut Criterion) {
    let critic = Critic::from_weights(random_network(
        NetworkMetadata::new(NetworkRole::Critic, 16),
        &PAPER_HIDDEN,
        1,
    ))
    .expect("valid critic");
    let actor = Actor::from_weights(random_network(
        NetworkMetadata::new(NetworkRole::Actor, 4),
        &PAPER_HIDDEN,
        2,
    ))
    .expect("valid actor");
    let mut cws = CriticWorkspace::new(&critic);
    let mut aws = ActorWorkspace::new(&actor);
    let x = State::new(1.0, -2.0, 0.7, 0.3, -0.2, 0.8);
    let u = Control::new(0.2, -0.4);
    let g = Goal::new(4.5, 4.5, 1.0);
    let p = MachineParams::default();
    let mut d = Derivatives::default();
    let mut grad = [0.0; NZ];

    let mut group = c.benchmark_group("kernels");
    group.bench_function("critic value", |b| {
        b.iter(|| critic.value(&mut cws, black_box(&x), &u, &g))
    });
    group.bench_function("critic value+gradient", |b| {
        b.iter(|| critic.value_gradient(&mut cws, black_box(&x), &u, &g, &mut grad))
    });
    group.bench_function("critic value+gradient+Hessian (exact)", |b| {
        b.iter(|| critic.hessian(&mut cws, black_box(&x), &u, &g, HessianMode::Exact, &mut d))
    });
    group.bench_function("critic Gauss-Newton", |b| {
        b.iter(|| {
            critic.hessian(
                &mut cws,
                black_box(&x),
                &u,
                &g,
                HessianMode::GaussNewton,
                &mut d,
            )
        })
    });
    group.bench_function("actor action", |b| {
        b.iter(|| actor.action(&mut aws, black_box(&x), &g))
    });
    group.bench_function("RK4 step with Jacobians", |b| {
        b.iter(|| rk4_step_with_jacobians(&p, black_box(&x), &u, 0.2))
    });
    group.finish();
}

criterion_group!(benches, kernels);
criterion_main!(benches);
