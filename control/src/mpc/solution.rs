//! What one MPC tick returns.

use std::time::Duration;

use crate::model::VelocityCommand;
use crate::model::{Control, State};

use super::qp::QpStatus;

/// Why a tick fell back to the shifted previous plan.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FallbackReason {
    /// The measured (or delay-compensated) state was not finite.
    NonFiniteState,
    /// The cost or dynamics derivatives were not finite.
    NonFiniteData,
    /// The QP was not solved (its status is in [`Solution::qp_status`]).
    QpFailed,
    /// The QP's solution was not finite.
    NonFiniteSolution,
    /// The solved plan puts an axle point inside a circle, deeper than the
    /// tolerance and deeper than the machine already is (DESIGN §14: the
    /// obstacle rows are not to be traded away).
    PlanPenetrates,
}

/// Outcome of a tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum StepStatus {
    /// At least one QP was solved and its step taken.
    #[default]
    Solved,
    /// No QP step was taken: the plan is the previous one shifted by a stage
    /// (or the initial roll-out). The caller decides how long to drive on it.
    Fallback(FallbackReason),
}

/// The result of [`super::Mpc::step`]. Buffers are preallocated by the MPC and
/// overwritten every tick.
#[derive(Debug, Clone, PartialEq)]
pub struct Solution {
    /// (β̇, v_f) of the planned x₁ ([`VelocityCommand::limited`] to the machine's
    /// bounds, divided by the actuator-gain estimate when on); always finite.
    pub command: VelocityCommand,
    pub status: StepStatus,
    /// The delay-compensated initial state x̂ the plan starts from.
    pub initial_state: State,
    /// Planned states x₀..x_N (x₀ = x̂ when solved).
    pub states: Vec<State>,
    /// Planned controls u₀..u_{N−1} [β̈, a_f], inside their bounds.
    pub controls: Vec<Control>,
    /// L(x_N, 0, g) + Σ Δt·L(x_n, u_n, g) at the linearisation point of the
    /// last QP (in RTI: the shifted previous plan), without slack penalties.
    pub cost: f64,
    /// Status of the last QP attempted.
    pub qp_status: QpStatus,
    /// QP interior-point iterations, summed over the tick's SQP iterations.
    pub qp_iterations: u32,
    /// SQP iterations whose QP was solved and step taken.
    pub sqp_iterations: u32,
    /// The first QP at the shifted warm start failed and the tick restarted
    /// from a fresh roll-out (actor or zero controls).
    pub restarted: bool,
    /// ∞-norm of the last SQP step (states and controls), before the step length.
    pub step_norm: f64,
    /// Slacks of the soft state bounds [β, β̇, v_f] of x₁..x_N from the last QP.
    pub state_slacks: Vec<[f64; 3]>,
    /// Obstacle slacks from the last QP, row k = 0..N−1 (x_{k+1}); shared by
    /// all obstacles of the row (the largest violation).
    pub obstacle_slacks: Vec<f64>,
    /// Σ weight × slack of the last QP.
    pub slack_cost: f64,
    /// Largest multiplier sum Σ_{j,a} λ_{k,j,a} of one stage's obstacle rows in
    /// the last QP. The L1 penalty of the shared slack is exact (the QP cannot
    /// trade penetration for cost) while the weight exceeds it: a value equal
    /// to `obstacle_slack_weight` means the penalty was bought, not obeyed.
    pub obstacle_multiplier: f64,
    /// Wall time of the whole tick.
    pub solve_time: Duration,
    /// Part of it spent in the critic's derivatives (the cost blocks).
    pub derivatives_time: Duration,
    /// Part of it spent assembling the rest of the QP (dynamics' Jacobians,
    /// bounds, obstacle rows).
    pub assembly_time: Duration,
    /// Part of it spent in the QP solver (data update and solve).
    pub qp_time: Duration,
}

impl Solution {
    pub(crate) fn new(horizon: usize) -> Self {
        Self {
            command: VelocityCommand::default(),
            status: StepStatus::Solved,
            initial_state: State::zeros(),
            states: vec![State::zeros(); horizon + 1],
            controls: vec![Control::zeros(); horizon],
            cost: 0.0,
            qp_status: QpStatus::NotRun,
            qp_iterations: 0,
            sqp_iterations: 0,
            restarted: false,
            step_norm: 0.0,
            state_slacks: vec![[0.0; 3]; horizon],
            obstacle_slacks: vec![0.0; horizon],
            slack_cost: 0.0,
            obstacle_multiplier: 0.0,
            solve_time: Duration::ZERO,
            derivatives_time: Duration::ZERO,
            assembly_time: Duration::ZERO,
            qp_time: Duration::ZERO,
        }
    }

    /// Largest state-bound slack.
    pub fn max_state_slack(&self) -> f64 {
        self.state_slacks
            .iter()
            .flatten()
            .fold(0.0, |m, &s| m.max(s))
    }

    /// Largest obstacle slack.
    pub fn max_obstacle_slack(&self) -> f64 {
        self.obstacle_slacks.iter().fold(0.0, |m, &s| m.max(s))
    }
}
