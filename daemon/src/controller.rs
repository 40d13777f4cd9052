//! What the control loop needs from a controller, and the MPC behind it.
//!
//! The loop talks to a [`Controller`]: set a goal, step from the measured state,
//! reset. [`MpcController`] wraps `control::mpc::Mpc` (critic or quadratic cost);
//! tests plug in their own controllers (one that fails on demand, one that stalls)
//! without touching the loop.
//!
//! Loading ([`load_controller`]) reads and validates the weight files before the
//! loop starts: corrupt or incompatible weights stop start-up with an error that
//! names the file and the problem.

use std::path::Path;
use std::time::Duration;

use control::mpc::{Mpc, MpcSettings, Obstacle, QuadraticCost, StageCost, StepStatus};
use control::weights::{self, NetworkRole, NetworkWeights};
use control::{Actor, Critic, Goal, MachineParams, State};
use thiserror::Error;

use crate::config::{Config, CostKind};

/// Outcome of one controller step as the loop sees it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlanStatus {
    /// A fresh solution.
    Solved,
    /// The controller could not solve and returned its shifted previous plan; the
    /// command is still usable for a short while.
    Fallback,
}

/// One step's result. `states` is x₀..x_N of the plan.
#[derive(Debug, Clone, Copy)]
pub struct Plan<'a> {
    /// (β̇, v_f) to send now.
    pub command: [f64; 2],
    /// Solved or fallback.
    pub status: PlanStatus,
    /// Planned states x₀..x_N.
    pub states: &'a [State],
    /// Optimal cost (NaN if unknown).
    pub cost: f64,
    /// QP iterations this step.
    pub qp_iterations: u32,
    /// SQP iterations this step.
    pub sqp_iterations: u32,
    /// Wall time of the step.
    pub solve_time: Duration,
}

/// A failed step (no usable plan at all).
#[derive(Debug, Clone, Error)]
#[error("{0}")]
pub struct ControllerError(pub String);

/// The controller as the daemon's loop uses it. Implementations are built on the
/// control thread (they need not be `Send`).
pub trait Controller {
    /// Sets the goal and obstacles; the next `step` plans towards it.
    fn set_goal(&mut self, goal: Goal, obstacles: &[Obstacle]) -> Result<(), ControllerError>;
    /// Forgets goal, plan and command history (after a stop, before a new start).
    fn reset(&mut self);
    /// One control period from the measured state (called once per tick while
    /// tracking, its command sent).
    fn step(&mut self, state: &State) -> Result<Plan<'_>, ControllerError>;
}

/// Builds the controller on the control thread.
pub type ControllerFactory =
    Box<dyn FnOnce() -> Result<Box<dyn Controller>, ControllerError> + Send>;

/// The actor-critic MPC (or the MPC with a quadratic cost).
pub struct MpcController<C: StageCost> {
    mpc: Mpc<C>,
}

impl<C: StageCost> MpcController<C> {
    /// Wraps a built MPC.
    pub fn new(mpc: Mpc<C>) -> Self {
        Self { mpc }
    }
}

impl<C: StageCost> Controller for MpcController<C> {
    fn set_goal(&mut self, goal: Goal, obstacles: &[Obstacle]) -> Result<(), ControllerError> {
        self.mpc
            .set_goal(goal, obstacles)
            .map_err(|e| ControllerError(e.to_string()))
    }

    fn reset(&mut self) {
        self.mpc.reset();
    }

    fn step(&mut self, state: &State) -> Result<Plan<'_>, ControllerError> {
        let s = self
            .mpc
            .step(state)
            .map_err(|e| ControllerError(e.to_string()))?;
        Ok(Plan {
            command: [s.command.beta_dot, s.command.v],
            status: match s.status {
                StepStatus::Solved => PlanStatus::Solved,
                StepStatus::Fallback(_) => PlanStatus::Fallback,
            },
            states: &s.states,
            cost: s.cost,
            qp_iterations: s.qp_iterations,
            sqp_iterations: s.sqp_iterations,
            solve_time: s.solve_time,
        })
    }
}

/// Start-up failures: each names the file or setting and the problem.
#[derive(Debug, Error)]
pub enum LoadError {
    /// The weight file could not be read.
    #[error("weights file {path}: cannot read: {source}")]
    Read {
        /// The file.
        path: String,
        /// The OS error.
        source: std::io::Error,
    },
    /// The file is not valid weights, or not for this machine.
    #[error(transparent)]
    Weights(#[from] weights::WeightsError),
    /// The MPC could not be built.
    #[error("MPC: {0}")]
    Mpc(String),
}

/// Reads and validates one network file: format, shapes, finiteness, role, and
/// compatibility with the configured machine and Δt.
pub fn load_network(
    path: &Path,
    role: NetworkRole,
    machine: &MachineParams,
    dt: f64,
) -> Result<NetworkWeights, LoadError> {
    let name = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|source| LoadError::Read {
        path: name.clone(),
        source,
    })?;
    let w = weights::decode(&bytes, &name)?;
    if w.meta.role != role {
        return Err(weights::WeightsError::new(
            &name,
            weights::WeightsProblem::WrongRole {
                expected: role,
                found: w.meta.role,
            },
        )
        .into());
    }
    w.meta
        .check_compatible(machine, dt)
        .map_err(|p| weights::WeightsError::new(&name, p))?;
    Ok(w)
}

/// The quadratic bring-up cost: position, heading and a constant pull towards the
/// goal, small penalties on articulation, rates and controls.
pub fn quadratic_cost() -> QuadraticCost {
    let mut c = QuadraticCost::diagonal([2.0, 2.0, 1.0, 0.2, 0.2, 0.5], [0.5, 0.5]);
    c.q_pos = 2.0;
    c
}

/// Loads what the configuration names (weights are read here, on the calling
/// thread, so errors surface before anything starts) and returns a factory that
/// builds the MPC on the control thread.
pub fn load_controller(config: &Config) -> Result<ControllerFactory, LoadError> {
    let machine = config.machine;
    let settings: MpcSettings = config.mpc;
    // The quadratic bring-up cost runs without any network (the actor was trained
    // for the critic's cost).
    let actor = if config.weights.actor.as_os_str().is_empty()
        || config.controller.cost == CostKind::Quadratic
    {
        None
    } else {
        let w = load_network(
            &config.weights.actor,
            NetworkRole::Actor,
            &machine,
            settings.dt,
        )?;
        Some(Actor::from_weights(w)?)
    };
    match config.controller.cost {
        CostKind::Critic => {
            let w = load_network(
                &config.weights.critic,
                NetworkRole::Critic,
                &machine,
                settings.dt,
            )?;
            let critic = Critic::from_weights(w)?;
            // Built here too, so a bad setting fails start-up, then rebuilt on the
            // control thread (the MPC need not be `Send`).
            Mpc::new(machine, critic.clone(), actor.clone(), settings)
                .map_err(|e| LoadError::Mpc(e.to_string()))?;
            Ok(Box::new(move || {
                let mpc = Mpc::new(machine, critic, actor, settings)
                    .map_err(|e| ControllerError(e.to_string()))?;
                Ok(Box::new(MpcController::new(mpc)) as Box<dyn Controller>)
            }))
        }
        CostKind::Quadratic => Ok(Box::new(move || {
            let mpc = Mpc::new(machine, quadratic_cost(), actor, settings)
                .map_err(|e| ControllerError(e.to_string()))?;
            Ok(Box::new(MpcController::new(mpc)) as Box<dyn Controller>)
        })),
    }
}

/// The start-up self-test: a first solve from rest towards a goal 3 m ahead must
/// succeed with a finite command before the daemon reports READY=1.
pub fn first_solve(c: &mut dyn Controller) -> Result<Duration, ControllerError> {
    c.reset();
    c.set_goal(Goal::new(3.0, 0.0, 0.0), &[])?;
    let result = match c.step(&State::zeros()) {
        Ok(plan)
            if plan.status == PlanStatus::Solved && plan.command.iter().all(|v| v.is_finite()) =>
        {
            Ok(plan.solve_time)
        }
        Ok(plan) => Err(ControllerError(format!(
            "first solve did not succeed (status {:?}, command {:?})",
            plan.status, plan.command
        ))),
        Err(e) => Err(e),
    };
    c.reset();
    result
}
