//! The navigator's cost terms in the MPC (issue 27).
//!
//! The cost-to-go field enters the QP as Δt·∇(w·φ) on the front-axle
//! position of every stage and ∇(w·φ) at the terminal stage, checked against
//! the field's own gradient; and it steers: a field rising in +y bends the
//! plan towards −y.
//!
//! The path cost (design (a)) replaces the stage and terminal costs while it
//! is set: the QP's gradient on every stage is Δt × the path term's (the
//! terminal's 1 ×), independently of the cost it replaces (a quadratic cost
//! pulling elsewhere); and it steers: the plan follows the path's bend
//! instead of heading for the goal.

use control::model::{Control, Goal, MachineParams, State};
use control::mpc::{CostToGo, Mpc, MpcSettings, PathCost, PathWeights, QuadraticCost};

fn mpc() -> Mpc<QuadraticCost> {
    let cost = QuadraticCost::diagonal([1.0, 1.0, 0.5, 0.1, 0.1, 0.1], [0.1, 0.1]);
    let settings = MpcSettings {
        delay: 0.0,
        time_budget: 10.0,
        ..MpcSettings::default()
    };
    let mut mpc = Mpc::new(MachineParams::default(), cost, None, settings).unwrap();
    mpc.reserve_cost_to_go(40);
    mpc.set_goal(Goal::new(6.0, 0.0, 0.0), &[]).unwrap();
    mpc
}

/// w·φ = 3 + 0.7·y − 0.2·x over a 40 × 40 grid of 0.5 m around the machine.
fn tilted_field() -> CostToGo {
    let mut f = CostToGo::with_cells(40);
    let (origin, res) = ([-10.0, -10.0], 0.5);
    f.fill(origin, res, 40, |i, j| {
        let (x, y) = (origin[0] + res * i as f64, origin[1] + res * j as f64);
        3.0 + 0.7 * y - 0.2 * x
    });
    f
}

#[test]
fn the_field_gradient_enters_every_stage_and_the_terminal_cost() {
    let x0 = State::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.5);
    let mut plain = mpc();
    plain.step(&x0, 0.0).unwrap();
    let q_plain = plain.qp_data().q.clone();
    let mut with = mpc();
    let field = tilted_field();
    with.set_cost_to_go(Some(&field));
    assert_eq!(with.cost_to_go(), &field);
    with.step(&x0, 0.0).unwrap();
    let q_with = with.qp_data().q.clone();
    let (layout, dt, n) = (with.layout(), with.settings().dt, with.settings().horizon);
    // The first QP is built at the same linearisation point in both (the
    // hold roll-out from x0), so the difference is the field's gradient.
    for k in 0..=n {
        let scale = if k < n { dt } else { 1.0 };
        let g = [-0.2, 0.7];
        for (c, gc) in g.iter().enumerate() {
            let d = q_with[layout.x(k) + c] - q_plain[layout.x(k) + c];
            assert!(
                (d - scale * gc).abs() < 1e-9,
                "stage {k} component {c}: {d} vs {}",
                scale * gc
            );
        }
        for c in 2..6 {
            let d = q_with[layout.x(k) + c] - q_plain[layout.x(k) + c];
            assert!(d.abs() < 1e-12, "stage {k} component {c}: {d}");
        }
    }
    // It steers: lower y is cheaper, so the plan ends further to −y.
    let y_end = |m: &Mpc<QuadraticCost>| m.solution().states[n][1];
    assert!(
        y_end(&with) < y_end(&plain) - 0.01,
        "{} vs {}",
        y_end(&with),
        y_end(&plain)
    );
    // Removing the field restores the plain QP.
    with.set_cost_to_go(None);
    assert!(with.cost_to_go().is_empty());
    with.clear_goal();
    with.set_goal(Goal::new(6.0, 0.0, 0.0), &[]).unwrap();
    let mut again = mpc();
    with.step(&x0, 0.2).unwrap();
    again.step(&x0, 0.2).unwrap();
    assert_eq!(with.qp_data().q, again.qp_data().q);
}

/// An arc of radius 5 m from the origin, heading 0, turning left (+y); the
/// goal of `mpc()` is straight ahead.
fn bending_path() -> PathCost {
    let mut p = PathCost::new();
    let poses = (0..=20).map(|k| {
        let a = 0.06 * k as f64;
        [5.0 * a.sin(), 5.0 * (1.0 - a.cos()), a]
    });
    let weights = PathWeights {
        per_metre: 3.0,
        lateral: 12.0,
        heading: 9.0,
        control: 0.3,
    };
    p.set(poses, weights, &MachineParams::default(), false);
    p
}

#[test]
fn the_path_term_is_the_cost_of_every_stage_and_the_terminal() {
    let x0 = State::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.5);
    let path = bending_path();
    let mut m = mpc();
    m.set_path_cost(Some(&path));
    assert_eq!(m.path_cost(), &path);
    m.step(&x0, 0.0).unwrap();
    let (layout, dt, n) = (m.layout(), m.settings().dt, m.settings().horizon);
    let q = &m.qp_data().q;
    // The first QP is built at the hold roll-out from x0 (no actor): stage k
    // at x0 moved k·Δt·v along x with zero controls.
    let mut hint = 0;
    for k in 0..=n {
        let x = State::new(0.5 * dt * k as f64, 0.0, 0.0, 0.0, 0.0, 0.5);
        let term = path.eval(&x, &Control::zeros(), hint);
        hint = term.segment;
        let scale = if k < n { dt } else { 1.0 };
        for c in 0..3 {
            let d = q[layout.x(k) + c];
            assert!(
                (d - scale * term.grad_pose[c]).abs() < 1e-9,
                "stage {k} component {c}: {d} vs {}",
                scale * term.grad_pose[c]
            );
        }
        for c in 3..6 {
            assert_eq!(q[layout.x(k) + c], 0.0, "stage {k} component {c}");
        }
    }
    // It steers: after a few ticks the plan bends to +y with the path (the
    // quadratic cost alone keeps it on y = 0, towards the goal).
    let mut plain = mpc();
    let (mut x, mut x_plain) = (x0, x0);
    for t in 0..10 {
        m.step(&x, 0.2 * t as f64).unwrap();
        plain.step(&x_plain, 0.2 * t as f64).unwrap();
        x = m.solution().states[1];
        x_plain = plain.solution().states[1];
    }
    let y_end = |m: &Mpc<QuadraticCost>| m.solution().states[n][1];
    assert!(y_end(&m) > 0.3, "{}", y_end(&m));
    assert!(y_end(&plain).abs() < 0.05, "{}", y_end(&plain));
    // Removed, the cost is the critic's again.
    m.set_path_cost(None);
    assert!(m.path_cost().is_empty());
}
