//! What the control loop needs from a controller, and the pilot behind it.
//!
//! The loop talks to a [`Controller`]: set a goal, step from the measured state,
//! reset. [`PilotController`] wraps `control::pilot::Pilot` — the MPC (critic or
//! quadratic cost), the global layer above it when configured (its routes planned
//! on a planner thread, never in the tick) and the safety envelope — the same
//! composition `wlnav-sim` runs. A goal without a route or without progress ends
//! as [`Step::Abort`]. Tests plug in their own controllers (one that fails on
//! demand, one that stalls) without touching the loop.
//!
//! Loading ([`load_controller`]) reads and validates the weight files before the
//! loop starts: corrupt or incompatible weights stop start-up with an error that
//! names the file and the problem.

use std::time::{Duration, Instant};

use control::assumption_check::{Decision, Finding};
use control::envelope::Guarded;
use control::live::LiveSet;
use control::mpc::{Mpc, MpcSettings, QuadraticCost, StageCost, StepStatus};
use control::pilot::{LiveStatus, Pilot, PilotDecision};
use control::planner::{self, Navigator, NavigatorSettings, PlannerThread, RoutePlanner};
use control::site::{Outline, SiteIndex};
use control::weights::{self, NetworkRole};
use control::{Actor, Critic, Goal, MachineParams, Obstacle, State, VelocityCommand};
use shm_ipc::{Pose2, Telemetry};
use std::sync::Arc;
use thiserror::Error;
use trajopt::trajectory::{IpoptTrajectory, TrajectorySettings};

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
    /// Holding (at rest) while the global layer plans the goal's first route.
    Holding,
}

/// One step's result. `states` is x₀..x_N of the plan.
#[derive(Debug, Clone, Copy)]
pub struct Plan<'a> {
    /// (β̇, v_f) to send now (after the safety envelope).
    pub command: VelocityCommand,
    /// What the controller proposed before the envelope.
    pub proposed: VelocityCommand,
    /// Solved, fallback or holding.
    pub status: PlanStatus,
    /// The safety envelope's verdict on the proposal (`None`: the controller
    /// has no envelope of its own; the loop's stop rules still apply).
    pub guarded: Option<Guarded>,
    /// Planned states x₀..x_N (empty while holding).
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
    /// The last route plan's wall time, on the planner thread.
    pub plan_time: Duration,
    /// A route plan was taken this step (its time is `plan_time`).
    pub new_plan: bool,
    /// How old the route followed was when it arrived [s].
    pub route_age: f64,
    /// The envelope's assumptions the machine has broken so far (bit
    /// `Assumption as usize`), and the one the envelope was widened to this
    /// tick, if any (issue 43).
    pub assumptions_broken: u8,
    pub widened: Option<Finding>,
    /// What the live obstacles did to this step (DESIGN §18).
    pub live: Option<LiveStatus>,
}

impl Plan<'_> {
    /// Puts the plan on the tick's telemetry: solver figures, the planned
    /// trajectory, the subgoal, the remaining route and the plan's time and age.
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
        t.plan_time_us = self.plan_time.as_secs_f64() * 1e6;
        t.route_age_s = self.route_age;
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
    /// The machine broke an assumption of the safety envelope beyond what it
    /// may be widened to: a fault; the loop latches it, aborts the goal with
    /// the finding in its reason and brings the machine to rest.
    AssumptionBroken { finding: Finding, broken: u8 },
}

/// A failed step (no usable plan at all).
#[derive(Debug, Clone, Error)]
#[error("{0}")]
pub struct ControllerError(pub String);

/// The controller as the daemon's loop uses it. Implementations are built on the
/// control thread (they need not be `Send`).
pub trait Controller {
    /// Sets the goal and obstacles, seen from the state `start` measured at `now`;
    /// the next `step` drives towards it (the global layer plans its route off the
    /// tick).
    fn set_goal(
        &mut self,
        start: &State,
        goal: Goal,
        obstacles: &[Obstacle],
        now: f64,
    ) -> Result<(), ControllerError>;
    /// Forgets goal and plan (before a new goal), not the commands sent: they
    /// still act on the machine.
    fn reset(&mut self);
    /// One control period from the state measured at time `now` [s, the daemon's
    /// clock] (called once per tick while tracking); `tick_start` is when the
    /// tick began (the solver's time budget counts from it).
    fn step(
        &mut self,
        state: &State,
        now: f64,
        tick_start: Instant,
    ) -> Result<Step<'_>, ControllerError>;
    /// The command sent to the machine at `now`, whoever decided it (the step's
    /// command, a stop ramp, a hold): every tick, so the delay compensation
    /// works with what the machine was told on the real clock.
    fn sent(&mut self, now: f64, command: VelocityCommand);
    /// The actuator delay the controller compensates now [s] (its online
    /// estimate), if it has one.
    fn compensated_delay(&self) -> Option<f64> {
        None
    }
    /// The site every layer keeps off from the next step on (DESIGN §17;
    /// called between ticks, a swap at a tick boundary; `None`: the goals'
    /// circles only).
    fn set_site(&mut self, site: Option<Arc<SiteIndex>>);

    /// Whether a route plan is being computed off the tick right now (an
    /// answer waiting to be taken does not count). The loop never waits on
    /// it; a test that must not depend on the planner thread's speed waits
    /// for it to fall before the next step (sim/tests/daemon_wiring.rs).
    fn planner_working(&self) -> bool {
        false
    }

    /// The newest live-obstacle set (validated, stamps on the daemon's
    /// clock): the envelope keeps its stop fields from now on.
    fn set_live(&mut self, _set: &LiveSet) {}

    /// The check when a set arrives between ticks: `Some` with the stop to
    /// send at once if the command last sent, from the state `x` measured at
    /// `now`, would enter a live obstacle's stop field.
    fn check_live(&mut self, _x: &State, _now: f64) -> Option<Guarded> {
        None
    }
}

/// Builds the controller on the control thread.
pub type ControllerFactory =
    Box<dyn FnOnce() -> Result<Box<dyn Controller>, ControllerError> + Send>;

/// The pilot (MPC, global layer, envelope) as the loop's controller.
pub struct PilotController<C: StageCost> {
    pilot: Pilot<C>,
}

impl<C: StageCost> PilotController<C> {
    pub fn new(pilot: Pilot<C>) -> Self {
        Self { pilot }
    }

    /// The MPC alone under the envelope of `config` (no global layer): for tests.
    pub fn without_navigator(mpc: Mpc<C>, config: &Config) -> Result<Self, ControllerError> {
        let mut pilot = Pilot::new(
            config.machine,
            mpc,
            None,
            config.envelope,
            config.control.progress(),
        )
        .map_err(err)?;
        pilot.set_outline(config.outline.outline().map_err(err)?);
        Ok(Self::new(pilot))
    }
}

fn err(e: impl std::fmt::Display) -> ControllerError {
    ControllerError(e.to_string())
}

impl<C: StageCost> Controller for PilotController<C> {
    fn set_goal(
        &mut self,
        start: &State,
        goal: Goal,
        obstacles: &[Obstacle],
        now: f64,
    ) -> Result<(), ControllerError> {
        self.pilot
            .set_goal(start, goal, obstacles, now)
            .map_err(err)
    }

    fn reset(&mut self) {
        self.pilot.reset();
    }

    fn set_site(&mut self, site: Option<Arc<SiteIndex>>) {
        self.pilot.set_site(site);
    }

    fn step(
        &mut self,
        state: &State,
        now: f64,
        tick_start: Instant,
    ) -> Result<Step<'_>, ControllerError> {
        let p = match self.pilot.step(state, now, tick_start).map_err(err)? {
            PilotDecision::Abort(reason) => return Ok(Step::Abort(reason)),
            PilotDecision::Stop { finding, broken } => {
                return Ok(Step::AssumptionBroken { finding, broken })
            }
            PilotDecision::Drive(p) => p,
        };
        if let (true, Some(r)) = (p.new_plan, p.last_plan) {
            tracing::info!(
                "plan: {} in {:.0} ms, trajectory {}",
                r.outcome.name(),
                r.duration.as_secs_f64() * 1e3,
                r.trajectory
            );
        }
        let status = match p.solution.map(|s| s.status) {
            None => PlanStatus::Holding,
            Some(StepStatus::Solved) => PlanStatus::Solved,
            Some(StepStatus::Fallback(_)) => PlanStatus::Fallback,
        };
        Ok(Step::Drive(Plan {
            command: p.command,
            proposed: p.proposed,
            status,
            guarded: Some(p.guarded),
            states: p.solution.map_or(&[][..], |s| &s.states),
            cost: p.solution.map_or(f64::NAN, |s| s.cost),
            qp_iterations: p.solution.map_or(0, |s| s.qp_iterations),
            sqp_iterations: p.solution.map_or(0, |s| s.sqp_iterations),
            solve_time: p.solution.map_or(Duration::ZERO, |s| s.solve_time),
            subgoal: p.subgoal,
            route: p.route,
            plan_time: p.last_plan.map_or(Duration::ZERO, |r| r.duration),
            new_plan: p.new_plan,
            route_age: p.route_age,
            assumptions_broken: p.assumptions.broken,
            widened: p
                .assumptions
                .finding
                .filter(|_| p.assumptions.decision == Decision::Widen),
            live: p.live,
        }))
    }

    fn sent(&mut self, now: f64, command: VelocityCommand) {
        self.pilot.sent(now, command);
    }

    fn compensated_delay(&self) -> Option<f64> {
        Some(self.pilot.compensated_delay())
    }

    fn planner_working(&self) -> bool {
        self.pilot.navigator().is_some_and(|n| n.planner_working())
    }

    fn set_live(&mut self, set: &LiveSet) {
        self.pilot.set_live(set);
    }

    fn check_live(&mut self, x: &State, now: f64) -> Option<Guarded> {
        self.pilot.check_live(x, now)
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
    /// `[outline]` is not a valid outline.
    #[error("{0}")]
    Outline(String),
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
    let parts = ControllerParts {
        machine,
        navigator: config.navigator_settings(),
        trajectory: config.trajectory,
        envelope: config.envelope,
        progress: config.control.progress(),
        outline: config
            .outline
            .outline()
            .map_err(|e| LoadError::Outline(e.to_string()))?,
        live: config.live,
    };
    if let Some(s) = &parts.navigator {
        s.validate()
            .map_err(|e| LoadError::Navigator(e.to_string()))?;
    }
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
            Ok(Box::new(move || {
                let mpc = Mpc::new(machine, critic, actor, settings).map_err(err)?;
                controller(mpc, &parts, networks)
            }))
        }
        CostKind::Quadratic => Ok(Box::new(move || {
            let mpc = Mpc::new(machine, quadratic_cost(), actor, settings).map_err(err)?;
            controller(mpc, &parts, None)
        })),
    }
}

/// The global layer for `machine`: a navigator whose routes are planned on a
/// planner thread of their own (`networks`: the actor's roll-outs and shots, the
/// critic's cost of a metre), shaped there into min-time trajectories where the
/// settings ask for them.
fn build_navigator(
    machine: MachineParams,
    settings: &NavigatorSettings,
    trajectory: TrajectorySettings,
    networks: Option<(Actor, Critic)>,
) -> Result<Navigator, LoadError> {
    let fail = |e: &dyn std::fmt::Display| LoadError::Navigator(e.to_string());
    let (actor, critic) = match networks {
        Some((a, c)) => (Some(a), Some(c)),
        None => (None, None),
    };
    let mut planner = RoutePlanner::new(machine, settings, actor).map_err(|e| fail(&e))?;
    if settings.trajectory {
        let optimiser = IpoptTrajectory::new(machine, trajectory);
        planner = planner.with_trajectory(Box::new(optimiser));
    }
    let thread = PlannerThread::spawn(planner).map_err(|e| fail(&e))?;
    Navigator::with_routes(machine, settings.clone(), critic.as_ref(), Box::new(thread))
        .map_err(|e| fail(&e))
}

/// The pilot: the MPC, under the navigator when one is configured, and the envelope.
fn controller<C: StageCost + 'static>(
    mpc: Mpc<C>,
    config: &ControllerParts,
    networks: Option<(Actor, Critic)>,
) -> Result<Box<dyn Controller>, ControllerError> {
    let navigator = match &config.navigator {
        Some(s) => {
            Some(build_navigator(config.machine, s, config.trajectory, networks).map_err(err)?)
        }
        None => None,
    };
    let mut pilot = Pilot::new(
        config.machine,
        mpc,
        navigator,
        config.envelope,
        config.progress,
    )
    .map_err(err)?;
    pilot.set_outline(config.outline.clone());
    pilot.enable_live(config.live).map_err(err)?;
    Ok(Box::new(PilotController::new(pilot)))
}

/// What the control thread builds the pilot from.
#[derive(Clone)]
struct ControllerParts {
    machine: MachineParams,
    navigator: Option<NavigatorSettings>,
    trajectory: TrajectorySettings,
    envelope: control::envelope::EnvelopeSettings,
    progress: control::progress::ProgressSettings,
    outline: Outline,
    live: control::live::LiveSettings,
}

/// The start-up self-test: a first solve from rest towards a goal 3 m ahead must
/// succeed with a finite command before the daemon reports READY=1.
pub fn first_solve(c: &mut dyn Controller) -> Result<Duration, ControllerError> {
    c.reset();
    c.set_goal(&State::zeros(), Goal::new(3.0, 0.0, 0.0), &[], 0.0)?;
    let result = match c.step(&State::zeros(), 0.0, Instant::now()) {
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
        Ok(Step::AssumptionBroken { finding, .. }) => {
            Err(ControllerError(format!("first solve: {finding}")))
        }
        Err(e) => Err(e),
    };
    c.reset();
    result
}
