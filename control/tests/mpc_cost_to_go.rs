//! The cost-to-go field (issue 27) enters the MPC's QP as Δt·∇(w·φ) on the
//! front-axle position of every stage and ∇(w·φ) at the terminal stage,
//! checked against the field's own gradient; and it steers: a field rising in
//! +y bends the plan towards −y.

use control::model::{Goal, MachineParams, State};
use control::mpc::{CostToGo, Mpc, MpcSettings, QuadraticCost};

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
