//! A counting global allocator proves the critic and actor kernels allocate
//! nothing after their workspaces are built. One test in this binary, so no
//! other test thread allocates while we count.

mod common;

use control::encoder::NZ;
use control::model::{rk4_step_with_jacobians, Control, Goal, MachineParams, State};
use control::{ActorWorkspace, CriticWorkspace, Derivatives, HessianMode, TerminalDerivatives};

#[global_allocator]
static GLOBAL: common::CountingAllocator = common::CountingAllocator;

#[test]
fn kernels_do_not_allocate() {
    let critic = common::random_critic(8, 21);
    let actor = common::random_actor(22);
    let mut cws = CriticWorkspace::new(&critic);
    let mut aws = ActorWorkspace::new(&actor);
    let mut d = Derivatives::default();
    let mut t = TerminalDerivatives::default();
    let mut grad = [0.0; NZ];
    let p = MachineParams::default();
    let g = Goal::new(4.5, 4.5, 1.0);

    let before = common::allocations();
    let mut sink = 0.0;
    for k in 0..1000 {
        let x = State::new(0.01 * k as f64, 0.0, 0.2, 0.1, 0.0, 0.5);
        let u = Control::new(0.1, -0.1);
        sink += critic.value(&mut cws, &x, &u, &g);
        sink += critic.value_gradient(&mut cws, &x, &u, &g, &mut grad);
        critic.hessian(&mut cws, &x, &u, &g, HessianMode::Exact, &mut d);
        sink += d.hess[2][2];
        critic.hessian(&mut cws, &x, &u, &g, HessianMode::GaussNewton, &mut d);
        critic.terminal_hessian(&mut cws, &x, &g, HessianMode::Exact, &mut t);
        sink += actor.action(&mut aws, &x, &g)[0];
        sink += rk4_step_with_jacobians(&p, &x, &u, 0.2).1[(0, 2)];
    }
    let after = common::allocations();
    assert!(sink.is_finite());
    assert_eq!(
        after - before,
        0,
        "{} heap allocations in 1,000 kernel calls",
        after - before
    );
}
