//! What the control loop needs from a controller, and the MPC behind it.
//!
//! The loop talks to a [`Controller`]: set a goal, step from the measured state,
//! reset. [`MpcController`] wraps `control::mpc::Mpc` (critic or quadratic cost)
//! and, when configured, the global layer above it (`control::planner::Navigator`,
//! DESIGN §10): the navigator picks the target each tick (a subgoal of its route or
//! the goal), the MPC drives to it, and a goal without a route or without progress
//! ends as [`Step::Abort`]. Tests plug in their own controllers (one that fails on
//! demand, one that stalls) without touching the loop.
//!
//! Loading ([`load_controller`]) reads and validates the weight files before the
//! loop starts: corrupt or incompatible weights stop start-up with an error that
//! names the file and the problem.

use std::time::Duration;

use control::mpc::{Mpc, MpcSettings, Obstacle, QuadraticCost, StageCost, StepStatus};
use control::planner::{self, NavStep, Navigator, NavigatorSettings};
use control::weights::{self, NetworkRole};
use control::{Actor, Critic, Goal, MachineParams, State, VelocityCommand};
use shm_ipc::{Pose2, Telemetry};
use thiserror::Error;

use crate::config::{Config, CostKind};
use crate::ipc::wire_state;

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
    pub command: VelocityCommand,
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
    /// The subgoal driven to, when it is not the goal itself (global layer).
    pub subgoal: Option<Goal>,
    /// The global route not yet passed, ending with the goal (empty without a global
    /// layer).
    pub route: &'a [Goal],
}

impl Plan<'_> {
    /// Puts the plan on the tick's telemetry: solver figures, the planned
    /// trajectory, the subgoal and the remaining route.
    pub fn fill_telemetry(&self, t: &mut Telemetry) {
        if let Some(s) = self.subgoal {
            t.subgoal_active = 1;
            t.subgoal = Pose2::new(s.x, s.y, s.theta);
        }
        let mut route = [Pose2::new(0.0, 0.0, 0.0); shm_ipc::MAX_ROUTE];
        let n = self.route.len().min(shm_ipc::MAX_ROUTE);
        for (dst, g) in route.iter_mut().zip(self.route) {
            *dst = Pose2::new(g.x, g.y, g.theta);
        }
        t.set_route(&route[..n]);
        t.solve_time_us = self.solve_time.as_secs_f64() * 1e6;
        t.cost = self.cost;
        t.qp_iterations = self.qp_iterations;
        t.sqp_iterations = self.sqp_iterations;
        let mut traj = [shm_ipc::MachineState::ZERO; shm_ipc::MAX_TRAJECTORY];
        let n = self.states.len().min(shm_ipc::MAX_TRAJECTORY);
        for (dst, s) in traj.iter_mut().zip(self.states) {
            *dst = wire_state(s);
        }
        t.set_trajectory(&traj[..n]);
    }
}

/// What one controller step decided.
#[derive(Debug, Clone, Copy)]
pub enum Step<'a> {
    /// Drive: send the plan's command.
    Drive(Plan<'a>),
    /// The global layer ended the goal (no route, or no progress towards its
    /// target); the loop ends it as aborted and brings the machine to rest.
    Abort(planner::AbortReason),
}

/// A failed step (no usable plan at all).
#[derive(Debug, Clone, Error)]
#[error("{0}")]
pub struct ControllerError(pub String);

/// The controller as the daemon's loop uses it. Implementations are built on the
/// control thread (they need not be `Send`).
pub trait Controller {
    /// Sets the goal and obstacles, seen from the measured state `start` (the global
    /// layer plans its route here); the next `step` drives towards it.
    fn set_goal(
        &mut self,
        start: &State,
        goal: Goal,
        obstacles: &[Obstacle],
    ) -> Result<(), ControllerError>;
    /// Forgets goal and plan (before a new goal), not the commands sent: they
    /// still act on the machine.
    fn reset(&mut self);
    /// One control period from the state measured at time `now` [s, the daemon's
    /// clock] (called once per tick while tracking).
    fn step(&mut self, state: &State, now: f64) -> Result<Step<'_>, ControllerError>;
    /// The command sent to the machine at `now`, whoever decided it (the step's
    /// command, a stop ramp, a hold): every tick, so the delay compensation
    /// works with what the machine was told on the real clock.
    fn sent(&mut self, now: f64, command: VelocityCommand);
    /// The actuator delay the controller compensates now [s] (its online
    /// estimate), if it has one: the safety envelope assumes the longer of it
    /// and the configured delay.
    fn compensated_delay(&self) -> Option<f64> {
        None
    }

    /// The actuator-gain estimates (β̇, v_f), if it has them: the envelope's
    /// assumption check compares them with `actuator_gain_max` (issue 43).
    fn actuator_gains(&self) -> Option<[f64; 2]> {
        None
    }
}

/// Builds the controller on the control thread.
pub type ControllerFactory =
    Box<dyn FnOnce() -> Result<Box<dyn Controller>, ControllerError> + Send>;

/// The actor-critic MPC (or the MPC with a quadratic cost), with the global layer
/// above it when one is configured.
pub struct MpcController<C: StageCost> {
    mpc: Mpc<C>,
    navigator: Option<Navigator>,
    /// The navigator's cost terms' version the MPC has (issue 27).
    costs_seen: Option<u64>,
}

impl<C: StageCost> MpcController<C> {
    /// Wraps a built MPC, without a global layer.
    pub fn new(mpc: Mpc<C>) -> Self {
        Self {
            mpc,
            navigator: None,
            costs_seen: None,
        }
    }

    /// Wraps a built MPC under a navigator (allocated here, once: set_goal and
    /// step allocate nothing).
    pub fn with_navigator(mut mpc: Mpc<C>, navigator: Navigator) -> Self {
        mpc.reserve_cost_to_go(navigator.settings().grid_cells());
        Self {
            mpc,
            navigator: Some(navigator),
            costs_seen: None,
        }
    }
}

fn err(e: impl std::fmt::Display) -> ControllerError {
    ControllerError(e.to_string())
}

impl<C: StageCost> Controller for MpcController<C> {
    fn set_goal(
        &mut self,
        start: &State,
        goal: Goal,
        obstacles: &[Obstacle],
    ) -> Result<(), ControllerError> {
        // The first target starts from an actor roll-out (`set_goal`); later ones
        // (subgoal switches, replans) keep the collision-free plan (`retarget`).
        let first = match &mut self.navigator {
            Some(nav) => {
                nav.set_goal(start, goal, obstacles).map_err(err)?;
                nav.route().first().copied().unwrap_or(goal)
            }
            None => goal,
        };
        self.mpc.set_goal(first, obstacles).map_err(err)
    }

    fn reset(&mut self) {
        self.mpc.clear_goal();
        if let Some(nav) = &mut self.navigator {
            nav.clear();
        }
    }

    fn step(&mut self, state: &State, now: f64) -> Result<Step<'_>, ControllerError> {
        let mut subgoal = None;
        if let Some(nav) = &mut self.navigator {
            match nav.update(state, now) {
                NavStep::Drive {
                    target,
                    final_target,
                } => {
                    if self.mpc.goal() != Some(target) {
                        self.mpc.retarget(target).map_err(err)?;
                    }
                    // The MPC's copies of the field and the path, as `wlnav-sim eval`.
                    nav.sync_costs(&mut self.mpc, &mut self.costs_seen);
                    subgoal = (!final_target).then_some(target);
                }
                NavStep::Abort(reason) => return Ok(Step::Abort(reason)),
            }
        }
        let route = self
            .navigator
            .as_ref()
            .map_or(&[][..], |nav| nav.remaining_route());
        let s = self.mpc.step(state, now).map_err(err)?;
        Ok(Step::Drive(Plan {
            command: s.command,
            status: match s.status {
                StepStatus::Solved => PlanStatus::Solved,
                StepStatus::Fallback(_) => PlanStatus::Fallback,
            },
            states: &s.states,
            cost: s.cost,
            qp_iterations: s.qp_iterations,
            sqp_iterations: s.sqp_iterations,
            solve_time: s.solve_time,
            subgoal,
            route,
        }))
    }

    fn sent(&mut self, now: f64, command: VelocityCommand) {
        self.mpc.sent(now, command);
    }

    fn compensated_delay(&self) -> Option<f64> {
        Some(self.mpc.compensated_delay())
    }

    fn actuator_gains(&self) -> Option<[f64; 2]> {
        Some(self.mpc.actuator_gains())
    }
}

/// Start-up failures: each names the file or setting and the problem.
#[derive(Debug, Error)]
pub enum LoadError {
    /// The weight file cannot be read, is not valid weights, or is not for this
    /// machine and Δt ([`weights::load_for`]).
    #[error(transparent)]
    Weights(#[from] weights::WeightsError),
    /// The MPC could not be built.
    #[error("MPC: {0}")]
    Mpc(String),
    /// The global layer could not be built.
    #[error("controller.planner: {0}")]
    Navigator(String),
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
    let settings: MpcSettings = config.mpc_settings();
    // The quadratic bring-up cost runs without any network (the actor was trained
    // for the critic's cost).
    let actor = if config.weights.actor.as_os_str().is_empty()
        || config.controller.cost == CostKind::Quadratic
    {
        None
    } else {
        let w = weights::load_for(
            &config.weights.actor,
            NetworkRole::Actor,
            &machine,
            settings.dt,
        )?;
        Some(Actor::from_weights(w)?)
    };
    let nav_settings = config.navigator_settings();
    match config.controller.cost {
        CostKind::Critic => {
            let w = weights::load_for(
                &config.weights.critic,
                NetworkRole::Critic,
                &machine,
                settings.dt,
            )?;
            let critic = Critic::from_weights(w)?;
            let networks = actor.clone().map(|a| (a, critic.clone()));
            // Built here too, so a bad setting fails start-up, then rebuilt on the
            // control thread (the MPC need not be `Send`).
            Mpc::new(machine, critic.clone(), actor.clone(), settings)
                .map_err(|e| LoadError::Mpc(e.to_string()))?;
            if let Some(s) = &nav_settings {
                build_navigator(machine, s, networks.clone())?;
            }
            Ok(Box::new(move || {
                let mpc = Mpc::new(machine, critic, actor, settings).map_err(err)?;
                controller(mpc, machine, nav_settings, networks)
            }))
        }
        CostKind::Quadratic => {
            if let Some(s) = &nav_settings {
                build_navigator(machine, s, None)?;
            }
            Ok(Box::new(move || {
                let mpc = Mpc::new(machine, quadratic_cost(), actor, settings).map_err(err)?;
                controller(mpc, machine, nav_settings, None)
            }))
        }
    }
}

fn build_navigator(
    machine: MachineParams,
    settings: &NavigatorSettings,
    networks: Option<(Actor, Critic)>,
) -> Result<Navigator, LoadError> {
    Navigator::new(machine, settings.clone(), networks)
        .map_err(|e| LoadError::Navigator(e.to_string()))
}

/// The MPC, under the navigator when one is configured.
fn controller<C: StageCost + 'static>(
    mpc: Mpc<C>,
    machine: MachineParams,
    nav_settings: Option<NavigatorSettings>,
    networks: Option<(Actor, Critic)>,
) -> Result<Box<dyn Controller>, ControllerError> {
    Ok(match nav_settings {
        Some(s) => {
            let nav = build_navigator(machine, &s, networks).map_err(err)?;
            Box::new(MpcController::with_navigator(mpc, nav))
        }
        None => Box::new(MpcController::new(mpc)),
    })
}

/// The start-up self-test: a first solve from rest towards a goal 3 m ahead must
/// succeed with a finite command before the daemon reports READY=1.
pub fn first_solve(c: &mut dyn Controller) -> Result<Duration, ControllerError> {
    c.reset();
    c.set_goal(&State::zeros(), Goal::new(3.0, 0.0, 0.0), &[])?;
    let result = match c.step(&State::zeros(), 0.0) {
        Ok(Step::Drive(plan)) if plan.status == PlanStatus::Solved && plan.command.is_finite() => {
            Ok(plan.solve_time)
        }
        Ok(Step::Drive(plan)) => Err(ControllerError(format!(
            "first solve did not succeed (status {:?}, command {:?})",
            plan.status, plan.command
        ))),
        Ok(Step::Abort(reason)) => Err(ControllerError(format!(
            "first solve: the global layer aborted an open-ground goal ({})",
            reason.name()
        ))),
        Err(e) => Err(e),
    };
    c.reset();
    result
}
