//! The goal-conditioned actor-critic MPC (DESIGN §5, paper §IV-E, eq. 17–22),
//! solved by SQP with real-time iterations (SQP-RTI).
//!
//! Each tick: propagate the measured state over the actuator delay
//! ([`crate::delay`]), shift the previous plan by one stage (new last control
//! from the actor, or zero), build one QP at that point (second-order Taylor
//! model of the critic cost, eq. 20–21, Hessian blocks made positive
//! semidefinite; linearised RK4 dynamics; hard control bounds; soft state and
//! obstacle constraints with exact L1 slacks, so the QP is always feasible),
//! solve it (by default with the Riccati interior point over the stages,
//! [`RiccatiBackend`]; Clarabel is the reference it is tested against), and
//! return (β̇, v_f) of the planned x₁ (the caller
//! reports what it actually sent through [`Mpc::sent`], which the delay
//! compensation and the online estimates use). Optionally a few more SQP
//! iterations run within the time budget.
//!
//! The parts talk through small traits so tests can swap them:
//! [`StageCost`] (the critic, or [`QuadraticCost`]), [`Dynamics`] ([`Rk4Model`],
//! or [`LinearDynamics`]) and [`QpBackend`] ([`ClarabelBackend`], or
//! [`RiccatiBackend`], the interior point over the stages; [`QpSolverBackend`]
//! picks one by `MpcSettings::qp_solver`).
//!
//! Files: `settings` (settings and errors), `layout` (variables, rows, sparsity
//! pattern), `cost`, `dynamics`, `constraints`, `qp` (solver backend),
//! `riccati` (the structure-exploiting backend), `sqp`
//! (one tick), `solution` (what a tick returns).
//!
//! Rows that exist (issue 30): the QP constrains only the circles within the
//! horizon's reach of the machine ([`reachable_obstacles`]). One QP (layout,
//! values, solver) per count of such circles, 0 to `max_obstacles`, is built
//! at start-up; a tick uses the one of its count, so no zero rows are
//! factored, open ground pays nothing for obstacles, and a change of the set
//! needs no symbolic factorisation in the tick.
//!
//! Allocation: nothing in a tick allocates, except inside Clarabel's `solve`
//! when Clarabel is the QP solver (its timers; counted in `tests/mpc_alloc.rs`).

// Index loops over small fixed-size blocks read like the math.
#![allow(clippy::needless_range_loop)]

pub mod constraints;
pub mod cost;
pub mod dynamics;
pub mod layout;
pub mod live_rows;
pub mod path_cost;
pub mod qp;
pub mod riccati;
pub mod settings;
pub mod solution;
mod sqp;
pub mod track_cost;

pub use constraints::Obstacle;
pub use cost::{QuadraticCost, StageCost};
pub use dynamics::{Dynamics, LinearDynamics, Rk4Model};
pub use layout::QpLayout;
pub use live_rows::LiveRows;
pub use path_cost::{PathCost, PathWeights, MAX_PATH_POSES};
pub use qp::{ClarabelBackend, QpBackend, QpData, QpOutcome, QpSolverBackend, QpStatus};
pub use riccati::RiccatiBackend;
pub use settings::{MpcError, MpcSettings, ObstacleConstraint, QpSolver, MAX_OBSTACLES};
pub use solution::{FallbackReason, Solution, StepStatus};
pub use track_cost::{TrackCost, TrackWeights, MAX_TRACK_STATES};

use crate::actor::{Actor, ActorWorkspace};
use crate::delay::DelayCompensator;
use crate::delay_estimate::DelayEstimator;
use crate::gain::GainEstimator;
use crate::live::{LiveSet, LiveSettings};
use crate::model::{Control, Goal, MachineParams, State, VelocityCommand};
use crate::site::index::Near;
use crate::site::outline::Outline;
use crate::site::SiteIndex;
use crate::world::{RowPair, World};
use std::sync::Arc;

/// The MPC: built once, then `set_goal` and `step` every tick.
pub struct Mpc<C: StageCost, D: Dynamics = Rk4Model, B: QpBackend = QpSolverBackend> {
    params: MachineParams,
    settings: MpcSettings,
    cost: C,
    cost_ws: C::Workspace,
    dynamics: D,
    actor: Option<(Actor, ActorWorkspace)>,
    /// `qps[n]`: the QP with rows for n circles, n = 0..=max_obstacles.
    qps: Vec<Qp<B>>,
    /// The circles within reach at this tick (the rows of `qps[n_active]`).
    /// The goal's circles within reach this tick (indices into the world's).
    active: [usize; MAX_OBSTACLES],
    n_reach: usize,
    /// The QP this tick uses (`qps[n_active]`, its `n_obs`).
    n_active: usize,
    delay: DelayCompensator,
    /// Online actuator-gain estimate ([`crate::gain`]), used when
    /// `settings.gain_estimation`.
    gain: GainEstimator,
    /// Online delay estimate ([`crate::delay_estimate`]), used when
    /// `settings.delay_estimation`.
    delay_estimate: DelayEstimator,
    goal: Option<Goal>,
    /// While set, the cost of every stage and the terminal cost instead of
    /// the critic: progress along the navigator's path ([`PathCost`]).
    path_cost: PathCost,
    /// The path segment the last tick's x̂ was projected onto.
    path_hint: usize,
    /// While set, the cost of every stage and the terminal cost instead of
    /// the path's and the critic's: the navigator's trajectory ([`TrackCost`]).
    track_cost: TrackCost,
    /// The site, the goal's circles and the outline (DESIGN §17).
    world: World,
    /// Each row k's (outline circle, target) pairs: `rows[k · row_stride ..]`,
    /// `row_len[k]` of them (DESIGN §17: the nearest, a bounded count).
    rows: Vec<RowPair>,
    row_len: Vec<usize>,
    near: Vec<Near>,
    /// Live obstacles the rows keep off (`None`: not configured).
    live: Option<LiveRows>,
    /// The plan, which is also the next linearisation point once shifted.
    xs: Vec<State>,
    us: Vec<Control>,
    /// The shifted plan, kept while a restart from a roll-out is tried.
    backup_xs: Vec<State>,
    backup_us: Vec<Control>,
    /// False until a plan exists for the current goal.
    has_plan: bool,
    /// The state measured at the last step and its time (the delay estimate
    /// predicts the next measurement from it once the command is sent).
    measured: Option<(f64, State)>,
    /// The obstacle rows' L1 weight in force: `settings.obstacle_slack_weight`,
    /// raised while the QP buys penetration (sqp.rs, `raise_obstacle_weight`).
    obstacle_weight: f64,
    solution: Solution,
}

/// One QP: its layout, its values and the solver built on them.
struct Qp<B> {
    layout: QpLayout,
    data: QpData,
    backend: B,
}

/// The goal's circles a plan over the horizon can come near, in their given
/// order: those whose edge is within `reach` of the front axle at `x`, where
/// `reach` covers the horizon at the top speed (soft bounds included), the
/// outline's extent beyond the front axle and the largest margin. Writes
/// their indices to `out` and returns how many.
pub fn reachable_obstacles(
    settings: &MpcSettings,
    world: &World,
    x: &State,
    out: &mut [usize; MAX_OBSTACLES],
) -> usize {
    let params = world.params();
    let reach = plan_reach(settings, world);
    let q = crate::obstacle::AxlePoint::Front.position(params, x);
    let mut n = 0;
    for (j, o) in world.circles().iter().enumerate() {
        // A non-finite pose keeps every circle: the tick falls back anyway.
        if !(o.clearance_of(q) > reach) && n < MAX_OBSTACLES {
            out[n] = j;
            n += 1;
        }
    }
    n
}

/// How far from x̂'s front axle a plan's outline can reach, margin
/// included ([`reachable_obstacles`]).
fn plan_reach(settings: &MpcSettings, world: &World) -> f64 {
    let params = world.params();
    settings.obstacle_reach(params) + outline_extent_beyond_axles(world, params)
}

/// How much farther from the front axle the outline reaches than the
/// default's rear axle circle (0 for the default outline).
fn outline_extent_beyond_axles(world: &World, p: &MachineParams) -> f64 {
    let o = world.outline();
    let far = (0..o.len())
        .map(|i| o.lever_arm(i, p) + o.circles()[i].radius)
        .fold(0.0, f64::max);
    (far - (p.l_f + p.l_r + o.half_width())).max(0.0)
}

fn check_goal_finite(goal: &Goal) -> Result<(), MpcError> {
    if goal.x.is_finite() && goal.y.is_finite() && goal.theta.is_finite() {
        Ok(())
    } else {
        Err(MpcError::BadGoal {
            x: goal.x,
            y: goal.y,
            theta: goal.theta,
        })
    }
}

/// Rows per stage: two per circle slot (`QpLayout`'s front and rear rows of
/// a slot take any two (outline circle, target) pairs).
fn row_stride(settings: &MpcSettings) -> usize {
    layout::AXLE_POINTS * settings.max_obstacles
}

impl<C: StageCost> Mpc<C> {
    /// The MPC with the RK4 model and the QP solver `settings.qp_solver`.
    pub fn new(
        params: MachineParams,
        cost: C,
        actor: Option<Actor>,
        settings: MpcSettings,
    ) -> Result<Self, MpcError> {
        Self::with_parts(
            params,
            cost,
            Rk4Model { params },
            actor,
            settings,
            QpSolverBackend::new,
        )
    }
}

impl<C: StageCost, D: Dynamics, B: QpBackend> Mpc<C, D, B> {
    /// The MPC with any dynamics and QP backend; `make_backend` receives the
    /// layout, nominal QP values (for the solver's scaling) and the settings.
    pub fn with_parts(
        params: MachineParams,
        cost: C,
        dynamics: D,
        actor: Option<Actor>,
        settings: MpcSettings,
        mut make_backend: impl FnMut(&QpLayout, &QpData, &MpcSettings) -> Result<B, MpcError>,
    ) -> Result<Self, MpcError> {
        params.validate()?;
        settings.validate()?;
        let n = settings.horizon;
        let qps = (0..=settings.max_obstacles)
            .map(|n_obs| {
                let layout = QpLayout::new(n, n_obs, settings.obstacle_constraint);
                let data = nominal_data(&layout, &params, &settings, &dynamics);
                let backend = make_backend(&layout, &data, &settings)?;
                Ok(Qp {
                    layout,
                    data,
                    backend,
                })
            })
            .collect::<Result<Vec<_>, MpcError>>()?;
        let mut delay =
            DelayCompensator::new(params, settings.delay, settings.dt).map_err(|_| {
                MpcError::Setting {
                    name: "delay",
                    requirement: "must be finite and >= 0",
                    value: settings.delay.to_string(),
                }
            })?;
        let delay_estimate = DelayEstimator::new(params, settings.delay, settings.dt);
        delay.reserve_for(delay_estimate.max_delay());
        let cost_ws = cost.workspace();
        let actor = actor.map(|a| {
            let ws = ActorWorkspace::new(&a);
            (a, ws)
        });
        Ok(Self {
            params,
            settings,
            cost,
            cost_ws,
            dynamics,
            actor,
            qps,
            active: [0; MAX_OBSTACLES],
            n_reach: 0,
            n_active: 0,
            delay,
            gain: GainEstimator::new(params, settings.delay, settings.dt),
            delay_estimate,
            goal: None,
            path_cost: PathCost::new(),
            path_hint: 0,
            track_cost: TrackCost::new(),
            world: World::with_axle_circles(params, settings.max_obstacles),
            rows: vec![RowPair::default(); n * row_stride(&settings)],
            row_len: vec![0; n],
            near: vec![Near::default(); row_stride(&settings)],
            live: None,
            xs: vec![State::zeros(); n + 1],
            us: vec![Control::zeros(); n],
            backup_xs: vec![State::zeros(); n + 1],
            backup_us: vec![Control::zeros(); n],
            has_plan: false,
            obstacle_weight: settings.obstacle_slack_weight,
            measured: None,
            solution: Solution::new(n),
        })
    }

    pub fn settings(&self) -> &MpcSettings {
        &self.settings
    }

    pub fn params(&self) -> &MachineParams {
        &self.params
    }

    /// The layout of the QP in use (the last tick's circles within reach).
    pub fn layout(&self) -> &QpLayout {
        &self.qps[self.n_active].layout
    }

    pub fn goal(&self) -> Option<Goal> {
        self.goal
    }

    /// The goal's circles (wire radii).
    pub fn obstacles(&self) -> &[Obstacle] {
        self.world.circles()
    }

    /// The site, the goal's circles and the outline the rows are built from.
    pub fn world(&self) -> &World {
        &self.world
    }

    /// The site every goal's rows include from the next tick (`None`: the
    /// goal's circles only). No allocation.
    pub fn set_site(&mut self, site: Option<Arc<SiteIndex>>) {
        self.world.set_site(site);
    }

    /// The machine's outline, each circle's margin `extra[i]` beyond its
    /// body's (`obstacle_margin` or `obstacle_margin_rear`): the envelope's
    /// per-circle margins less its per-body ones, so that the MPC plans
    /// outside what the envelope guards.
    pub fn set_outline(&mut self, outline: Outline, extra: &[f64]) {
        self.world.set_outline(outline);
        self.world.set_extra_margins(extra);
    }

    /// Keeps live obstacles off from now on, with rows predicted to each
    /// stage's time ([`LiveRows`]).
    pub fn enable_live(&mut self, settings: LiveSettings) {
        self.live = Some(LiveRows::new(settings, self.settings.dt));
    }

    /// The newest live set, its stamps on the clock of [`Self::step`]'s
    /// `now` (ignored unless [`Self::enable_live`]). No allocation.
    pub fn set_live(&mut self, set: &LiveSet) {
        if let Some(l) = &mut self.live {
            l.set_obstacles(set);
        }
    }

    /// Each outline circle's margin to a live obstacle beyond the stop
    /// field's reach: the envelope's (`margins`, one per circle), to which
    /// the rows add [`live_rows::PLAN_MARGIN`], so that its plan keeps out
    /// of what the envelope stops for.
    pub fn set_live_margins(&mut self, margins: &[f64]) {
        if let Some(l) = &mut self.live {
            l.set_margins(margins);
        }
    }

    /// The live obstacles' rows (`None`: not configured).
    pub fn live_rows(&self) -> Option<&LiveRows> {
        self.live.as_ref()
    }

    /// The last tick's result.
    pub fn solution(&self) -> &Solution {
        &self.solution
    }

    /// The values of the last QP built (for diagnostics and tests).
    pub fn qp_data(&self) -> &QpData {
        &self.qps[self.n_active].data
    }

    /// The QP backend in use (e.g. to read multipliers in tests).
    pub fn backend(&self) -> &B {
        &self.qps[self.n_active].backend
    }

    /// Every QP backend, one per count of circles within reach (0 first).
    pub fn backends(&self) -> impl Iterator<Item = &B> {
        self.qps.iter().map(|qp| &qp.backend)
    }

    /// The goal's circles the last tick's QP constrained (those within reach).
    pub fn active_obstacles(&self) -> impl Iterator<Item = &Obstacle> + '_ {
        self.active[..self.n_reach]
            .iter()
            .map(|&j| &self.world.circles()[j])
    }

    /// Forgets the goal and the plan, and keeps the command history: the
    /// commands sent in the last delay window still act on the machine (a new
    /// goal while driving, or a start after a stop ramp).
    pub fn clear_goal(&mut self) {
        self.goal = None;
        self.path_cost.clear();
        self.track_cost.clear();
        self.world.clear_circles();
        self.has_plan = false;
        self.set_obstacle_weight(self.settings.obstacle_slack_weight);
    }

    /// Forgets the goal, the plan and the command history: for a new machine
    /// (e.g. the simulator's next scenario), not for a new goal of the same one.
    pub fn reset(&mut self) {
        self.clear_goal();
        self.measured = None;
        self.delay.reset();
        self.gain.reset();
        self.delay_estimate.reset();
    }

    /// Records the command actually sent to the machine at `now` [s, the clock
    /// of [`Self::step`]]: the delay compensation and the online estimates
    /// work with what the machine was told, whoever decided it (the MPC's own
    /// command, a stop ramp, a hold). Call it once per command sent, in time
    /// order.
    pub fn sent(&mut self, now: f64, command: VelocityCommand) {
        // With the gain estimate, the machine is expected to achieve gain × sent.
        let achieved = if self.settings.gain_estimation {
            self.gain.record(command)
        } else {
            command
        };
        self.delay.record(now, achieved);
        if self.settings.delay_estimation {
            let measured = self.measured.filter(|(t, _)| *t == now).map(|(_, x)| x);
            self.delay_estimate.record(now, measured.as_ref(), achieved);
        }
    }

    /// The delay compensated now [s]: the configured one, or its online estimate.
    pub fn compensated_delay(&self) -> f64 {
        self.delay.delay()
    }

    /// The actuator-gain estimates (β̇, v_f) (1 until estimated, or when off).
    pub fn actuator_gains(&self) -> [f64; 2] {
        self.gain.gains()
    }

    /// Sets the goal and the obstacles (at most `max_obstacles`, radii already
    /// inflated by the machine's). A goal different from the current one makes
    /// the next tick start from an actor roll-out; the same goal with new
    /// obstacles keeps the warm start.
    pub fn set_goal(&mut self, goal: Goal, obstacles: &[Obstacle]) -> Result<(), MpcError> {
        check_goal_finite(&goal)?;
        if obstacles.len() > self.settings.max_obstacles {
            return Err(MpcError::TooManyObstacles {
                given: obstacles.len(),
                max: self.settings.max_obstacles,
            });
        }
        for (i, o) in obstacles.iter().enumerate() {
            o.validate(i)?;
        }
        self.world
            .set_circles(obstacles)
            .expect("validated against the same capacity");
        self.set_target(goal);
        Ok(())
    }

    /// The goal itself; a new one starts from an actor roll-out.
    fn set_target(&mut self, goal: Goal) {
        if self.goal != Some(goal) {
            self.has_plan = false;
            self.set_obstacle_weight(self.settings.obstacle_slack_weight);
        }
        self.goal = Some(goal);
    }

    /// Moves the target to `goal` and keeps the plan as the next warm start:
    /// for the global layer's subgoals (DESIGN §10), where the plan towards
    /// the previous subgoal is collision-free and an actor roll-out towards
    /// the new one (which knows no obstacles) may run through a circle: one
    /// real-time iteration from such a point can leave the plan inside it.
    /// Without a goal yet this is [`Self::set_goal`] with no obstacles change.
    pub fn retarget(&mut self, goal: Goal) -> Result<(), MpcError> {
        let keep = self.has_plan && self.goal.is_some();
        let weight = self.obstacle_weight;
        check_goal_finite(&goal)?;
        self.set_target(goal);
        self.has_plan = keep;
        self.set_obstacle_weight(weight);
        Ok(())
    }

    /// Sets the path whose progress is the cost from the next tick on, in
    /// place of the critic (`None`: the critic again). Allocation-free.
    pub fn set_path_cost(&mut self, path: Option<&PathCost>) {
        match path {
            Some(p) => self.path_cost.copy_from(p),
            None => self.path_cost.clear(),
        }
        self.path_hint = 0;
    }

    /// Sets the trajectory tracked from the next tick on, in place of the
    /// path and the critic (`None`: those again). Allocation-free.
    pub fn set_track_cost(&mut self, track: Option<&TrackCost>) {
        match track {
            Some(t) => self.track_cost.copy_from(t),
            None => self.track_cost.clear(),
        }
    }

    /// The first stage's time on the tracked trajectory (the navigator's,
    /// every tick).
    pub fn set_track_time(&mut self, t: f64) {
        self.track_cost.set_time(t);
    }

    /// The path cost in use (empty: the critic).
    pub fn path_cost(&self) -> &PathCost {
        &self.path_cost
    }

    /// The obstacle rows' L1 weight in force (DESIGN §14).
    pub fn obstacle_weight(&self) -> f64 {
        self.obstacle_weight
    }
}

/// QP values at a nominal point (identity cost blocks, the dynamics' Jacobians
/// at half the top speed, unit obstacle gradients), from which the solver's
/// equilibration is computed once. The pattern is complete: every entry that
/// can change is present, zeros included.
fn nominal_data<D: Dynamics>(
    layout: &QpLayout,
    params: &MachineParams,
    settings: &MpcSettings,
    dynamics: &D,
) -> QpData {
    let mut data = QpData {
        p: vec![0.0; layout.p.nnz()],
        q: vec![0.0; layout.n_var],
        a: layout.a_constant.clone(),
        b: vec![0.0; layout.n_eq + layout.n_ineq],
    };
    for block in &layout.p_stage {
        for i in 0..layout::NZ {
            data.p[block[i][i]] = 1.0;
        }
    }
    for i in 0..layout::NX {
        data.p[layout.p_terminal[i][i]] = 1.0;
    }
    sqp::fill_slack_costs(layout, settings, &mut data.q);
    let mut x = State::zeros();
    x[crate::model::ix::V] = 0.5 * params.v_max;
    let (_, a, b) = dynamics.step_with_jacobians(&x, &Control::zeros(), settings.dt);
    for n in 0..layout.horizon {
        for i in 0..layout::NX {
            for j in 0..layout::NX {
                data.a[layout.a_dyn_x[n][i][j]] = -a[(i, j)];
            }
            for j in 0..layout::NU {
                data.a[layout.a_dyn_u[n][i][j]] = -b[(i, j)];
            }
        }
    }
    let xs = vec![x; layout.horizon + 1];
    let us = vec![Control::zeros(); layout.horizon];
    constraints::fill_bounds(layout, params, &xs, &us, &mut data.b);
    for k in 0..layout.horizon {
        for j in 0..layout.n_obs {
            for a in 0..layout::AXLE_POINTS {
                data.b[layout.row_obstacle(k, j, a)] = 1.0;
            }
        }
    }
    data
}
