//! Failure handling: a failed QP, a non-finite QP solution, non-finite cost
//! data or a non-finite measurement are reported in the `Solution` and answered
//! with the shifted previous plan; the command stays finite and in bounds.

use std::cell::{Cell, RefCell};
use std::collections::VecDeque;
use std::rc::Rc;

use control::model::{Control, Goal, MachineParams, State};
use control::mpc::{
    ClarabelBackend, FallbackReason, Mpc, MpcError, MpcSettings, Obstacle, QpBackend, QpData,
    QpOutcome, QpStatus, QuadraticCost, Rk4Model, Solution, StageCost, StepStatus,
};
use control::{Derivatives, HessianMode};

#[path = "../../tests/timing_scale.rs"]
mod timing_scale;

#[derive(Clone, Copy, Debug)]
enum Next {
    Fail,
    NanPrimal,
}

/// Clarabel, with scripted failures of upcoming solves.
struct Flaky {
    inner: ClarabelBackend,
    script: Rc<RefCell<VecDeque<Option<Next>>>>,
    nan: Vec<f64>,
    poisoned: bool,
}

impl QpBackend for Flaky {
    fn update(&mut self, data: &QpData) -> Result<(), String> {
        self.inner.update(data)
    }
    fn solve(&mut self) -> QpOutcome {
        let out = self.inner.solve();
        self.poisoned = false;
        match self.script.borrow_mut().pop_front().flatten() {
            None => out,
            Some(Next::Fail) => QpOutcome {
                status: QpStatus::NumericalError,
                ..out
            },
            Some(Next::NanPrimal) => {
                self.nan = vec![f64::NAN; self.inner.primal().len()];
                self.poisoned = true;
                out
            }
        }
    }
    fn primal(&self) -> &[f64] {
        if self.poisoned {
            &self.nan
        } else {
            self.inner.primal()
        }
    }
    fn dual(&self) -> &[f64] {
        self.inner.dual()
    }
}

/// The attractive quadratic, or NaN on demand.
struct Poisonable {
    cost: QuadraticCost,
    nan: Rc<Cell<bool>>,
}

impl StageCost for Poisonable {
    type Workspace = ();
    fn workspace(&self) {}
    fn stage(
        &self,
        ws: &mut (),
        x: &State,
        u: &Control,
        g: &Goal,
        mode: HessianMode,
        out: &mut Derivatives,
    ) {
        self.cost.stage(ws, x, u, g, mode, out);
        if self.nan.get() {
            out.hess[0][0] = f64::NAN;
        }
    }
}

type Script = Rc<RefCell<VecDeque<Option<Next>>>>;

fn build() -> (Mpc<Poisonable, Rk4Model, Flaky>, Script, Rc<Cell<bool>>) {
    let p = MachineParams::default();
    let mut cost = QuadraticCost::diagonal([0.2, 0.2, 0.5, 0.1, 0.5, 0.5], [0.5, 0.5]);
    cost.q_pos = 2.0;
    let nan = Rc::new(Cell::new(false));
    let script: Script = Rc::new(RefCell::new(VecDeque::new()));
    let s2 = script.clone();
    let settings = MpcSettings {
        delay: 0.0,
        // The solver's wall-clock budget is a timing limit (WLNAV_TIMING_SCALE; under qemu
        // the first, cold QP missed the unscaled 0.1 s).
        time_budget: timing_scale::secs(MpcSettings::default().time_budget),
        ..MpcSettings::default()
    };
    let mpc = Mpc::with_parts(
        p,
        Poisonable {
            cost,
            nan: nan.clone(),
        },
        Rk4Model { params: p },
        None,
        settings,
        move |l, d, s| {
            Ok(Flaky {
                inner: ClarabelBackend::new(l, d, s)?,
                script: s2.clone(),
                nan: vec![],
                poisoned: false,
            })
        },
    )
    .unwrap();
    (mpc, script, nan)
}

fn assert_shifted(prev: &Solution, sol: &Solution, reason: FallbackReason) {
    assert_eq!(sol.status, StepStatus::Fallback(reason));
    for k in 1..prev.states.len() - 1 {
        assert_eq!(
            sol.states[k],
            prev.states[k + 1],
            "state {k} is not the shifted plan"
        );
    }
    for k in 0..prev.controls.len() - 1 {
        assert_eq!(sol.controls[k], prev.controls[k + 1]);
    }
    assert_eq!(sol.command.beta_dot, prev.states[2][4]);
    assert_eq!(sol.command.v, prev.states[2][5]);
}

#[test]
fn failures_fall_back_to_the_shifted_plan() {
    let (mut mpc, script, nan) = build();
    let x = State::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.3);
    assert!(matches!(mpc.step(&x, 0.0), Err(MpcError::NoGoal)));
    mpc.set_goal(Goal::new(5.0, 1.0, 0.0), &[]).unwrap();
    let mut prev = mpc.step(&x, 0.0).unwrap().clone();
    assert_eq!(prev.status, StepStatus::Solved);
    let next = |s: &Solution| s.states[1];

    // Both the QP at the shifted plan and the restart fail.
    script
        .borrow_mut()
        .extend([Some(Next::Fail), Some(Next::Fail)]);
    let sol = mpc.step(&next(&prev), 0.0).unwrap().clone();
    assert_shifted(&prev, &sol, FallbackReason::QpFailed);
    assert_eq!(sol.qp_status, QpStatus::NumericalError);
    assert!(sol.restarted);
    prev = sol;

    // Only the first fails: the restart from a roll-out succeeds.
    script.borrow_mut().extend([Some(Next::Fail), None]);
    let sol = mpc.step(&next(&prev), 0.0).unwrap().clone();
    assert_eq!(sol.status, StepStatus::Solved);
    assert!(sol.restarted);
    prev = sol;

    // A non-finite QP solution.
    script
        .borrow_mut()
        .extend([Some(Next::NanPrimal), Some(Next::NanPrimal)]);
    let sol = mpc.step(&next(&prev), 0.0).unwrap().clone();
    assert_shifted(&prev, &sol, FallbackReason::NonFiniteSolution);
    prev = sol;

    // Non-finite cost derivatives.
    nan.set(true);
    let sol = mpc.step(&next(&prev), 0.0).unwrap().clone();
    assert_shifted(&prev, &sol, FallbackReason::NonFiniteData);
    assert_eq!(sol.qp_status, QpStatus::NotRun);
    nan.set(false);
    prev = sol;

    // A non-finite measurement.
    let sol = mpc
        .step(&State::new(f64::NAN, 0.0, 0.0, 0.0, 0.0, 0.0), 0.0)
        .unwrap()
        .clone();
    assert_shifted(&prev, &sol, FallbackReason::NonFiniteState);
    prev = sol;

    // Recovery.
    let sol = mpc.step(&next(&prev), 0.0).unwrap().clone();
    assert_eq!(sol.status, StepStatus::Solved);

    // Without any plan, a non-finite measurement gives a stop command.
    mpc.reset();
    mpc.set_goal(Goal::new(5.0, 1.0, 0.0), &[]).unwrap();
    let sol = mpc.step(&State::from_element(f64::INFINITY), 0.0).unwrap();
    assert_eq!(
        sol.status,
        StepStatus::Fallback(FallbackReason::NonFiniteState)
    );
    assert_eq!((sol.command.beta_dot, sol.command.v), (0.0, 0.0));
}

#[test]
fn bad_goals_and_obstacles_are_rejected() {
    let (mut mpc, _, _) = build();
    assert!(matches!(
        mpc.set_goal(Goal::new(f64::NAN, 0.0, 0.0), &[]),
        Err(MpcError::BadGoal { .. })
    ));
    let many = [Obstacle::new(1.0, 1.0, 0.5); 9];
    assert!(matches!(
        mpc.set_goal(Goal::new(1.0, 0.0, 0.0), &many),
        Err(MpcError::TooManyObstacles { given: 9, max: 8 })
    ));
    let e = mpc.set_goal(
        Goal::new(1.0, 0.0, 0.0),
        &[Obstacle::new(1.0, 1.0, 0.5), Obstacle::new(1.0, 1.0, -1.0)],
    );
    assert!(e.unwrap_err().to_string().contains("obstacle 1"));
    let s = MpcSettings {
        horizon: 0,
        ..MpcSettings::default()
    };
    let e = Mpc::new(
        MachineParams::default(),
        QuadraticCost::diagonal([1.0; 6], [1.0; 2]),
        None,
        s,
    );
    assert!(e.err().unwrap().to_string().contains("`horizon`"));
}
