//! The global layer above the MPC (DESIGN §10, issue 14): when the way to the
//! goal is blocked it finds a collision-free route and hands the MPC a
//! sequence of subgoals, passes through them without stopping, replans when
//! progress stalls, and aborts a goal that makes no progress or has no route.
//!
//! Why: the MPC's horizon is 2 s and its critic knows no obstacles, so behind
//! an obstacle it sits in a local minimum. The critic is goal-conditioned, so
//! a subgoal is just a [`Goal`]; the MPC needs no change.
//!
//! Pieces: [`World`] (the circles, both axle points, a margin), the actor
//! [`rollout`] ("is anything in the way?", goal shots, edge checks), the
//! [`carrot`] (an alternative to subgoals, measured and off), two
//! planners behind [`PlannerKind`] — [`HybridAStar`] over (x, y, θ) with the
//! model's [`primitives`], and [`WaypointGraph`] (a critic-cost graph over
//! waypoints around the circles, after Eysenbach et al., "Search on the
//! Replay Buffer") — the [`smooth`]er of Hybrid A*'s paths, and [`route`]
//! (path → subgoals).
//!
//! Everything is allocated in [`Navigator::new`]; `set_goal` and `update`
//! (including a replan inside `update`) allocate nothing. A plan takes
//! milliseconds (bounded by the expansion and node limits; see
//! `docs/global-layer.md`); `update` without a replan takes microseconds.

pub mod carrot;
pub mod grid;
pub mod hybrid_astar;
pub mod primitives;
mod queue;
pub mod rollout;
pub mod route;
pub mod smooth;
pub mod waypoint_graph;
pub mod world;

use std::time::{Duration, Instant};

pub use hybrid_astar::{HybridAStar, SearchFailure, SearchStats};
pub use waypoint_graph::WaypointGraph;
pub use world::World;

use crate::actor::{Actor, ActorWorkspace};
use crate::critic::{Critic, CriticWorkspace};
use crate::model::{
    goal_distance, ix, wrap_angle, Control, Goal, MachineParams, State, REACH_SPEED,
    SUCCESS_TOLERANCE,
};
use crate::mpc::{
    CostToGo, Dynamics, Mpc, PathCost, PathWeights, QpBackend, StageCost, MAX_PATH_POSES,
};
use crate::obstacle::{footprint_clearance, BadObstacle, Obstacle};
use crate::progress::{ProgressChecker, ProgressSettings};

use grid::{GridFrame, ObstacleHeuristic};
use rollout::{roll_out, Arrival};
use smooth::{PathSmoother, Smoothing};

/// Which planner finds the route when the way is blocked.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlannerKind {
    /// Hybrid A* over (x, y, θ) with motion primitives from the model.
    HybridAStar,
    /// A graph over waypoints around the circles with critic edge costs,
    /// edges checked by actor roll-outs (needs the networks).
    WaypointGraph,
}

impl PlannerKind {
    pub fn name(self) -> &'static str {
        match self {
            PlannerKind::HybridAStar => "hybrid-astar",
            PlannerKind::WaypointGraph => "waypoint-graph",
        }
    }
}

/// What the MPC is given to drive along a planned path (issue 27).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Tracking {
    /// Point subgoals every `subgoal_spacing`, each passed within `subgoal_radius`.
    Subgoals,
    /// A pose on the path `carrot_distance` ahead of the machine's projection
    /// onto it, moved every tick ([`carrot`]); the subgoals remain the
    /// progress markers of the stall logic.
    Carrot,
    /// The goal itself, with a cost-to-go field added to the MPC's cost: the
    /// excess of the distance around the circles over the open distance,
    /// priced at `field_gain` × the critic's cost of a metre ([`CostToGo`];
    /// issue 27's design (b)). The planned path's subgoals remain the
    /// progress markers, passed by projection as with the carrot; after the
    /// first stall the subgoals are the targets (the field knows no heading).
    Field,
    /// Progress along the planned path is the MPC's cost in place of the
    /// critic ([`PathCost`]: arc length left, lateral and heading errors;
    /// issue 27's design (a)), one direction of travel at a time; within
    /// `path_handover` of the next cusp or the path's end the critic drives
    /// to that pose. The subgoals remain the progress markers, passed by
    /// projection as with the carrot.
    Path,
}

impl Tracking {
    pub fn name(self) -> &'static str {
        match self {
            Tracking::Subgoals => "subgoals",
            Tracking::Carrot => "carrot",
            Tracking::Field => "field",
            Tracking::Path => "path",
        }
    }
}

/// Everything the navigator is tuned with; `Default` gives the measured best.
#[derive(Debug, Clone, PartialEq)]
pub struct NavigatorSettings {
    pub planner: PlannerKind,
    /// What the MPC drives to along a planned path. Default `Path` (measured
    /// against the others on obstacles-tuning100 and obstacles200,
    /// `docs/global-layer.md`).
    pub tracking: Tracking,
    /// Arc length of path between the machine's projection and the carrot
    /// [m] (`Tracking::Carrot`). Default 3: beyond what the 2 s horizon covers
    /// at v_max, so the critic does not brake for it.
    pub carrot_distance: f64,
    /// `Tracking::Field`: the field's weight as a multiple of the critic's
    /// cost of a metre (calibrated at construction). Default 1: the critic
    /// plus the field then prices the way around as the critic prices the
    /// open way.
    pub field_gain: f64,
    /// Field tracking: the clearance the field's way keeps from every
    /// circle [m] (the front axle's; at least the route's margin). A wider
    /// way leaves the machine room to turn: the field knows no heading.
    /// Default 0.15 (the route's).
    pub field_margin: f64,
    /// `Tracking::Path`: within this arc length of the next cusp or the
    /// path's end the critic takes over and drives to that pose [m]. Default
    /// 3 (the approach distance: the critic's final approach, as today).
    pub path_handover: f64,
    /// `Tracking::Path`: the prices of the squared lateral error [1/m²], the
    /// heading error (1 − cos) and the squared controls relative to their
    /// bounds, each a multiple of the critic's cost of a metre (the arc
    /// length left is priced at 1 ×). Defaults 4, 3, 0.1.
    pub path_lateral: f64,
    pub path_heading: f64,
    pub path_control: f64,
    /// Sweeps of the path smoother over a Hybrid A* path ([`smooth`]; 0:
    /// the search's path as it is).
    pub smooth_iterations: usize,
    /// The smoother's pull back to the search's path, w_d in [0, 0.4] (0:
    /// straighten as far as the collision check allows). Default 0 sweeps
    /// (measured, no gain: the paths' arcs are already at β_max where they
    /// bend most), w_d 0.1.
    pub smooth_data_weight: f64,
    /// A subgoal is passed (the next one becomes the target) when the front
    /// axle is within this distance of it [m]. Default 1.0: before the MPC
    /// slows down for it.
    pub subgoal_radius: f64,
    /// Distance between subgoals along a planned path [m]. Default 2.5.
    pub subgoal_spacing: f64,
    /// The abort window: no approach to the current target for
    /// `progress.timeout` (default 10 s) → `Abort(NoProgress)`.
    pub progress: ProgressSettings,
    /// Seconds without approach to the current target before a replan from
    /// the current state. Default 4.
    pub replan_after: f64,
    /// Replans per goal. Default 3.
    pub max_replans: usize,
    /// A stall on the goal itself that a replan cannot help (open ground, or
    /// already inside the search's goal region) is retried: the MPC drives to
    /// the approach pose, this far behind the goal on its heading (ahead of it
    /// when that is blocked), then to the goal again, a straight final
    /// approach [m]. Why: a critic can stop beside its goal with the
    /// articulation at its limit (the heading error can then only shrink by
    /// driving, which moves the position; the large loader, `docs/training.md`).
    /// Default 3 (beyond `subgoal_radius`, about a turning radius).
    pub approach_distance: f64,
    /// Retries per goal. Default 2.
    pub max_retries: usize,
    /// Retry (rather than replan) a stall near the goal among circles too when
    /// the goal is in sight: a replan would shoot straight at it and hand
    /// back the route that stalled. Default true.
    pub retry_in_sight: bool,
    /// The stall ladder's second step (issue 27): after a replan that did not
    /// help (the next stall), back up this far along the machine's own recent
    /// track — a way it has just driven, so known to be passable — then
    /// replan from there, keeping out of the stall point [m]. 0 turns the
    /// step off. Default 0: measured at 2.5 (about a body length) on
    /// obstacles200 it gained one goal and lost two or three
    /// (`docs/global-layer.md`, "Following the route").
    pub back_up_distance: f64,
    /// Back-ups per goal. Default 1.
    pub max_back_ups: usize,
    /// Within this pose error of the goal the machine is holding it, not
    /// stalled. Default [`SUCCESS_TOLERANCE`].
    pub reached_tolerance: f64,
    /// Clearance both axle points keep from every (inflated) circle on a
    /// planned route and in the "in the way" test [m]. Default 0.15.
    pub clearance_margin: f64,
    /// Plan every goal among circles, not only those the actor's roll-out
    /// finds blocked: where the roll-out finds the way open, the search's way
    /// is taken only if it is cheaper than the roll-out (its duration at top
    /// speed; the critic alone drives the open way, as without planning).
    /// Without circles the way is direct, as always. Default true (measured:
    /// `docs/global-layer.md`, "Shaping the route").
    pub plan_every_goal: bool,
    /// Clearance the actor's roll-out must keep for "nothing in the way"
    /// [m]: more than the route's, since the MPC does not drive the actor's
    /// path exactly and, without subgoals, may stall at a circle it passes
    /// close by. Default 0.3.
    pub direct_margin: f64,
    /// Half the side of the square the planners search, centred between
    /// start and goal [m]. Default 14.
    pub workspace_half_size: f64,
    /// Side of a grid cell [m]. Default 0.3.
    pub grid_resolution: f64,
    /// Heading bins of the Hybrid A* grid. Default 72 (5°).
    pub heading_bins: usize,
    /// Arc length of a motion primitive [m]. Default 0.6 (leaves its cell).
    pub primitive_length: f64,
    /// Collision samples along a primitive, at most this far apart [m]. Default 0.15.
    pub sample_spacing: f64,
    /// Articulations of the primitives as fractions of β_max (each also
    /// mirrored). Default [0, 0.5, 1].
    pub articulations: Vec<f64>,
    /// Cost factor of reversing. Default 2.
    pub reverse_penalty: f64,
    /// Cost of a cusp (stop, change gear, restart) [m]. Default 2.
    pub direction_change_penalty: f64,
    /// f = g + w h (w > 1 trades optimality for far fewer expansions: on a
    /// wall across the path 92 expansions at 2 against 7 301 at 1). Default 2.
    pub heuristic_weight: f64,
    /// Hybrid A* expansion budget. Default 20 000.
    pub max_expansions: usize,
    /// Hybrid A* node pool. Default 100 000.
    pub max_nodes: usize,
    /// Goal region of the search (position [m], heading [rad]); the MPC does
    /// the last part itself. Defaults 0.5 and 0.35.
    pub goal_position_tolerance: f64,
    pub goal_heading_tolerance: f64,
    /// Goal shots (actor roll-outs to the goal): at most one per this many
    /// expansions, at most `max_shots`, only within `shot_range` [m] and a
    /// line of sight. Defaults 10, 10, 8.
    pub shot_interval: usize,
    pub max_shots: usize,
    pub shot_range: f64,
    /// A roll-out has reached the goal within this pose error. Default 0.2.
    pub shot_tolerance: f64,
    /// Hybrid A*: expansions after the first way to the goal is found (a
    /// shot or the goal region) in search of a cheaper one (0: the first is
    /// taken). Default 1000 (plan time median 4.6 ms, p99 14 ms on
    /// obstacles200, against 1.2 and 9.5 ms taking the first).
    pub refine_expansions: usize,
    /// Step of every roll-out [s]: the actor's own Δt. Default 0.2.
    pub rollout_dt: f64,
    /// Length of the "is anything in the way?" roll-out [s]. Default 30.
    pub direct_horizon: f64,
    /// Circles the navigator takes. Default 32.
    pub max_obstacles: usize,
    /// Waypoint graph: points per circle, their distance beyond radius +
    /// margin [m], neighbours per node and the edge-check budget.
    pub ring_points: usize,
    pub ring_offset: f64,
    pub graph_neighbours: usize,
    pub max_edge_checks: usize,
    /// Waypoint graph: longest edge [m] (the critic was trained on goals up
    /// to 10 m away). Default 6.
    pub graph_edge_length: f64,
}

impl Default for NavigatorSettings {
    fn default() -> Self {
        Self {
            planner: PlannerKind::HybridAStar,
            tracking: Tracking::Path,
            carrot_distance: 3.0,
            field_gain: 1.0,
            field_margin: 0.15,
            path_handover: 3.0,
            path_lateral: 4.0,
            path_heading: 3.0,
            path_control: 0.1,
            smooth_iterations: 0,
            smooth_data_weight: 0.1,
            subgoal_radius: 1.0,
            subgoal_spacing: 2.5,
            progress: ProgressSettings::default(),
            replan_after: 4.0,
            max_replans: 3,
            approach_distance: 3.0,
            max_retries: 2,
            retry_in_sight: true,
            back_up_distance: 0.0,
            max_back_ups: 1,
            reached_tolerance: SUCCESS_TOLERANCE,
            clearance_margin: 0.15,
            plan_every_goal: true,
            direct_margin: 0.3,
            workspace_half_size: 14.0,
            grid_resolution: 0.3,
            heading_bins: 72,
            primitive_length: 0.6,
            sample_spacing: 0.15,
            articulations: vec![0.0, 0.5, 1.0],
            reverse_penalty: 2.0,
            direction_change_penalty: 2.0,
            heuristic_weight: 2.0,
            max_expansions: 20_000,
            max_nodes: 100_000,
            goal_position_tolerance: 0.5,
            goal_heading_tolerance: 0.35,
            shot_interval: 10,
            max_shots: 10,
            shot_range: 8.0,
            shot_tolerance: 0.2,
            refine_expansions: 1000,
            rollout_dt: 0.2,
            direct_horizon: 30.0,
            max_obstacles: 32,
            ring_points: 8,
            ring_offset: 0.4,
            graph_neighbours: 10,
            max_edge_checks: 40,
            graph_edge_length: 6.0,
        }
    }
}

impl NavigatorSettings {
    /// Cells a side of the search grid.
    pub fn grid_cells(&self) -> usize {
        (2.0 * self.workspace_half_size / self.grid_resolution).ceil() as usize
    }

    /// Checks every field once; the error names it.
    pub fn validate(&self) -> Result<(), NavError> {
        let positive = [
            ("subgoal_radius", self.subgoal_radius),
            ("carrot_distance", self.carrot_distance),
            ("field_gain", self.field_gain),
            ("field_margin", self.field_margin),
            ("path_handover", self.path_handover),
            ("subgoal_spacing", self.subgoal_spacing),
            ("progress.timeout", self.progress.timeout),
            ("replan_after", self.replan_after),
            ("approach_distance", self.approach_distance),
            ("reached_tolerance", self.reached_tolerance),
            ("workspace_half_size", self.workspace_half_size),
            ("grid_resolution", self.grid_resolution),
            ("primitive_length", self.primitive_length),
            ("sample_spacing", self.sample_spacing),
            ("reverse_penalty", self.reverse_penalty),
            ("heuristic_weight", self.heuristic_weight),
            ("goal_position_tolerance", self.goal_position_tolerance),
            ("goal_heading_tolerance", self.goal_heading_tolerance),
            ("shot_range", self.shot_range),
            ("shot_tolerance", self.shot_tolerance),
            ("rollout_dt", self.rollout_dt),
            ("direct_horizon", self.direct_horizon),
            ("ring_offset", self.ring_offset),
            ("graph_edge_length", self.graph_edge_length),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(bad(name, "must be finite and > 0", v));
            }
        }
        let non_negative = [
            ("progress.min_approach", self.progress.min_approach),
            ("back_up_distance", self.back_up_distance),
            ("path_lateral", self.path_lateral),
            ("path_heading", self.path_heading),
            ("path_control", self.path_control),
            ("clearance_margin", self.clearance_margin),
            ("direct_margin", self.direct_margin),
            ("direction_change_penalty", self.direction_change_penalty),
        ];
        for (name, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return Err(bad(name, "must be finite and >= 0", v));
            }
        }
        if !(0.0..=0.4).contains(&self.smooth_data_weight) {
            return Err(bad(
                "smooth_data_weight",
                "must be in [0, 0.4] (the smoother's sweeps diverge beyond)",
                self.smooth_data_weight,
            ));
        }
        if self.approach_distance <= self.subgoal_radius {
            return Err(bad(
                "approach_distance",
                "must exceed subgoal_radius (or the approach pose is passed at once)",
                self.approach_distance,
            ));
        }
        if self.replan_after >= self.progress.timeout {
            return Err(bad(
                "replan_after",
                "must be below progress.timeout (a replan comes before the abort)",
                self.replan_after,
            ));
        }
        // The grid must be left by a primitive, or successors land on their parent.
        if self.primitive_length <= self.grid_resolution * std::f64::consts::SQRT_2 {
            return Err(bad(
                "primitive_length",
                "must exceed the cell diagonal (grid_resolution × √2)",
                self.primitive_length,
            ));
        }
        let cells = self.grid_cells();
        if cells > 1024 || self.heading_bins == 0 || self.heading_bins > 360 {
            return Err(bad(
                "grid",
                "needs workspace_half_size / grid_resolution ≤ 512 and 1..=360 heading_bins",
                cells as f64,
            ));
        }
        if self.articulations.is_empty()
            || self
                .articulations
                .iter()
                .any(|a| !(a.is_finite() && (0.0..=1.0).contains(a)))
        {
            return Err(bad(
                "articulations",
                "must be a non-empty list of fractions in [0, 1]",
                f64::NAN,
            ));
        }
        let counts = [
            ("max_expansions", self.max_expansions),
            ("max_nodes", self.max_nodes),
            ("shot_interval", self.shot_interval),
            ("max_obstacles", self.max_obstacles),
            ("ring_points", self.ring_points),
            ("graph_neighbours", self.graph_neighbours),
        ];
        for (name, v) in counts {
            if v == 0 {
                return Err(bad(name, "must be > 0", 0.0));
            }
        }
        Ok(())
    }
}

fn bad(name: &'static str, requirement: &'static str, value: f64) -> NavError {
    NavError::BadSettings {
        name,
        requirement,
        value,
    }
}

/// One pose of a planned path: the front axle's pose, the articulation and
/// the direction of travel that reached it (+1, −1; 0 at a start at rest).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathPose {
    pub x: f64,
    pub y: f64,
    pub theta: f64,
    pub beta: f64,
    pub direction: i8,
}

/// What the MPC should do this tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum NavStep {
    /// Drive to `target`; `final_target` when it is the goal itself.
    Drive { target: Goal, final_target: bool },
    /// Stop: the goal ends aborted.
    Abort(AbortReason),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AbortReason {
    /// No approach to the current target for `progress.timeout`.
    NoProgress,
    /// The planner found no route (reported by the first `update` after the
    /// failed plan; also returned while no goal is set).
    NoRoute,
}

impl AbortReason {
    /// The outcome reason's name in telemetry (DESIGN §10).
    pub fn name(self) -> &'static str {
        match self {
            AbortReason::NoProgress => "no-progress",
            AbortReason::NoRoute => "no-route",
        }
    }
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum NavError {
    /// The goal's footprint or the machine's current one is inside a circle
    /// (the one check of [`crate::goal_check`]).
    #[error(transparent)]
    Collision(#[from] crate::goal_check::GoalConflict),
    #[error("navigator setting `{name}` {requirement} (got {value})")]
    BadSettings {
        name: &'static str,
        requirement: &'static str,
        value: f64,
    },
    #[error("goal must be finite (got x {x}, y {y}, theta {theta})")]
    BadGoal { x: f64, y: f64, theta: f64 },
    #[error("{given} obstacles given, the navigator takes at most {max} (`max_obstacles`)")]
    TooManyObstacles { given: usize, max: usize },
    #[error(transparent)]
    BadObstacle(BadObstacle),
}

/// How the last plan ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlanOutcome {
    /// Nothing in the way: the route is the goal alone.
    Direct,
    /// A route of subgoals.
    Route,
    /// The planner found none.
    NoRoute,
    /// A retry after a stall near the goal: the route is the approach pose,
    /// then the goal (`NavigatorSettings::approach_distance`).
    Retry,
    /// The stall ladder's back-up: the route is a pose on the machine's own
    /// track `back_up_distance` behind it, then a replan from there.
    BackUp,
}

impl PlanOutcome {
    /// The name in reports.
    pub fn name(self) -> &'static str {
        match self {
            PlanOutcome::Direct => "direct",
            PlanOutcome::Route => "route",
            PlanOutcome::NoRoute => "no-route",
            PlanOutcome::Retry => "retry",
            PlanOutcome::BackUp => "back-up",
        }
    }
}

/// What the last plan did and how long it took.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanReport {
    pub outcome: PlanOutcome,
    /// The whole plan: the "in the way" test and the search.
    pub duration: Duration,
    pub search: SearchStats,
    /// A replan from `update` (not a new goal).
    pub replan: bool,
}

struct Networks {
    actor: Actor,
    actor_ws: ActorWorkspace,
    /// The waypoint graph's edge costs.
    critic: Critic,
    critic_ws: CriticWorkspace,
}

enum Planner {
    HybridAStar(Box<HybridAStar>),
    WaypointGraph(Box<WaypointGraph>),
}

/// Seconds per unit of critic cost when the fit fails (measured on the
/// published critic: about 0.22, `docs/global-layer.md`).
const FALLBACK_SECONDS_PER_COST: f64 = 0.22;

/// The critic's cost of a metre when there is no critic or its fit fails
/// (measured on the published critic: 3.0).
const FALLBACK_COST_PER_METRE: f64 = 3.0;

/// The critic's cost of a metre of way to the goal: its mean slope in the
/// goal distance between 3 and 10 m (the range it was trained on), over goals
/// on every side of the machine at rest and every relative heading. The
/// critic is close to proportional to the time to go (`docs/global-layer.md`),
/// so this is its price of a metre at cruising speed.
pub fn critic_cost_per_metre(critic: &Critic, ws: &mut CriticWorkspace) -> Option<f64> {
    let (near, far) = (3.0, 10.0);
    let (mut sum, mut count) = (0.0, 0.0);
    for bearing in [0.0f64, 45.0, 90.0, 135.0, 180.0, 225.0, 270.0, 315.0] {
        for heading in [0.0f64, 90.0, 180.0, 270.0] {
            let (b, h) = (bearing.to_radians(), heading.to_radians());
            let mut value = |d: f64| {
                let g = Goal::new(d * b.cos(), d * b.sin(), h);
                critic.value(ws, &State::zeros(), &Control::zeros(), &g)
            };
            sum += (value(far) - value(near)) / (far - near);
            count += 1.0;
        }
    }
    let slope = sum / count;
    (slope.is_finite() && slope > 0.0).then_some(slope)
}

/// The global layer: built once, then `set_goal` per goal and `update` per tick.
pub struct Navigator {
    params: MachineParams,
    settings: NavigatorSettings,
    world: World,
    networks: Option<Networks>,
    planner: Planner,
    path: Vec<PathPose>,
    smoother: PathSmoother,
    /// The machine's projection onto `path` (`Tracking::Carrot`).
    path_index: usize,
    route: Vec<Goal>,
    /// Each route entry's index in `path` (the goal's is `path.len()`).
    route_path_index: Vec<usize>,
    route_index: usize,
    goal: Option<Goal>,
    checker: ProgressChecker,
    /// The target of the checker's window on the last tick: an approach only
    /// counts on a window that was already running (a replan's new target
    /// restarts the window, which is no progress).
    window_target: Option<Goal>,
    /// Set by `set_goal`: the first `update` starts the clocks.
    clocks_pending: bool,
    last_progress: f64,
    last_replan: f64,
    replans: usize,
    retries: usize,
    back_ups: usize,
    /// The machine's recent front-axle poses (the back-up's way).
    track: Track,
    /// Backing up: replan when the back-up pose is reached.
    backing_up: bool,
    /// Where the front axle stood at the stall that started the back-up: the
    /// replan after it keeps out of there.
    stall_point: Option<[f64; 2]>,
    pending_no_route: bool,
    aborted: Option<AbortReason>,
    last_plan: Option<PlanReport>,
    plans: u64,
    /// `Tracking::Field`: the distance from the goal, and the field written
    /// from it once per plan (empty when none applies).
    field_distance: ObstacleHeuristic,
    field: CostToGo,
    /// The plan count the field was computed at.
    field_plan: Option<u64>,
    /// Counts the changes of the MPC's cost terms (field and path).
    cost_version: u64,
    /// `Tracking::Field` stalled once on this goal: subgoals from then on.
    field_stalled: bool,
    /// The critic's cost of a metre (calibrated at construction).
    cost_per_metre: f64,
    /// `Tracking::Path`: the current forward part of the path, and what it
    /// was made for (plan count, index of its last pose).
    path_cost: PathCost,
    path_key: Option<(u64, usize)>,
    /// Within the handover distance of its end: the critic drives.
    path_handed: bool,
    /// The path cost's segment the machine was last projected onto.
    path_hint: usize,
    /// `Tracking::Path`: the goal shot a path ends with, driven again by the
    /// actor (the search keeps only where it starts), for the plan count
    /// `shot_plan`; unless it reverses, it extends the path cost to the goal.
    shot: Vec<State>,
    shot_plan: Option<u64>,
}

impl Navigator {
    pub fn new(
        params: MachineParams,
        settings: NavigatorSettings,
        networks: Option<(Actor, Critic)>,
    ) -> Result<Self, NavError> {
        params
            .validate()
            .map_err(|_| bad("params", "machine parameters must be valid", f64::NAN))?;
        settings.validate()?;
        let mut networks = networks.map(|(actor, critic)| Networks {
            actor_ws: ActorWorkspace::new(&actor),
            critic_ws: CriticWorkspace::new(&critic),
            actor,
            critic,
        });
        let planner = match (settings.planner, networks.as_mut()) {
            (PlannerKind::HybridAStar, _) => {
                Planner::HybridAStar(Box::new(HybridAStar::new(params, &settings)))
            }
            (PlannerKind::WaypointGraph, Some(n)) => {
                let seconds_per_cost = waypoint_graph::calibrate(
                    &params,
                    &n.actor,
                    &mut n.actor_ws,
                    &n.critic,
                    &mut n.critic_ws,
                    settings.rollout_dt,
                    settings.shot_tolerance,
                )
                .unwrap_or(FALLBACK_SECONDS_PER_COST);
                Planner::WaypointGraph(Box::new(WaypointGraph::new(
                    params,
                    &settings,
                    seconds_per_cost,
                )))
            }
            (PlannerKind::WaypointGraph, None) => {
                return Err(bad(
                    "planner",
                    "waypoint-graph needs the actor and critic",
                    f64::NAN,
                ))
            }
        };
        let cost_per_metre = networks
            .as_mut()
            .and_then(|n| critic_cost_per_metre(&n.critic, &mut n.critic_ws))
            .unwrap_or(FALLBACK_COST_PER_METRE);
        let cells = settings.grid_cells();
        Ok(Self {
            params,
            field_distance: ObstacleHeuristic::new(cells),
            field: CostToGo::with_cells(cells),
            field_plan: None,
            cost_version: 0,
            field_stalled: false,
            cost_per_metre,
            path_cost: PathCost::new(),
            path_key: None,
            path_handed: false,
            path_hint: 0,
            shot: Vec::with_capacity(
                hybrid_astar::shot_steps(settings.shot_range, settings.rollout_dt) + 1,
            ),
            shot_plan: None,
            world: World::new(params, settings.max_obstacles, settings.clearance_margin),
            networks,
            planner,
            path: Vec::with_capacity(settings.max_nodes),
            smoother: PathSmoother::new(MAX_PATH_POSES),
            path_index: 0,
            route: Vec::with_capacity(settings.max_nodes + 1),
            route_path_index: Vec::with_capacity(settings.max_nodes + 1),
            route_index: 0,
            goal: None,
            checker: ProgressChecker::new(settings.progress),
            window_target: None,
            clocks_pending: false,
            last_progress: 0.0,
            last_replan: 0.0,
            replans: 0,
            retries: 0,
            back_ups: 0,
            track: Track::default(),
            backing_up: false,
            stall_point: None,
            pending_no_route: false,
            aborted: None,
            last_plan: None,
            plans: 0,
            settings,
        })
    }

    pub fn settings(&self) -> &NavigatorSettings {
        &self.settings
    }

    /// New goal. Errors: `Collision` (the goal pose's footprint, β = 0,
    /// inside a circle, or a circle containing the machine's current
    /// footprint: [`crate::goal_check::check_goal`]), and malformed input (`BadGoal`, `TooManyObstacles`,
    /// `BadObstacle`). Decides whether the way is blocked; if so plans a
    /// route. A failed plan is not an error here: the goal is accepted and
    /// the first `update` reports `Abort(NoRoute)`.
    pub fn set_goal(
        &mut self,
        start: &State,
        goal: Goal,
        obstacles: &[Obstacle],
    ) -> Result<(), NavError> {
        if !(goal.x.is_finite() && goal.y.is_finite() && goal.theta.is_finite()) {
            return Err(NavError::BadGoal {
                x: goal.x,
                y: goal.y,
                theta: goal.theta,
            });
        }
        self.clear();
        self.world.set(obstacles)?;
        if let Err(conflict) =
            crate::goal_check::check_goal(&self.params, Some(start), &goal, obstacles)
        {
            self.world.clear();
            return Err(conflict.into());
        }
        self.goal = Some(goal);
        self.clocks_pending = true;
        self.plan(start, false);
        Ok(())
    }

    /// Every tick: what the MPC should drive to now. Allocation-free; a
    /// replan (after `replan_after` s without approach) runs inside it.
    pub fn update(&mut self, x: &State, now: f64) -> NavStep {
        if let Some(r) = self.aborted {
            return NavStep::Abort(r);
        }
        let Some(goal) = self.goal else {
            return NavStep::Abort(AbortReason::NoRoute);
        };
        if self.pending_no_route {
            self.aborted = Some(AbortReason::NoRoute);
            return NavStep::Abort(AbortReason::NoRoute);
        }
        if self.clocks_pending {
            self.clocks_pending = false;
            self.last_progress = now;
            self.last_replan = now;
        }
        self.track.record(x);
        if self.backing_up && self.route_index == 0 {
            let b = self.route[0];
            if (x[ix::X] - b.x).hypot(x[ix::Y] - b.y) < BACK_UP_ARRIVAL {
                // Backed up: the ladder's next step is the replan from here,
                // keeping out of the stall point (so it cannot hand back the
                // route that stalled).
                self.backing_up = false;
                self.last_replan = now;
                let keep_out = self
                    .stall_point
                    .take()
                    .map(|p| Obstacle::new(p[0], p[1], KEEP_OUT_RADIUS));
                let kept_out = keep_out.is_some_and(|o| self.keep_out(x, o));
                self.plan(x, true);
                if kept_out {
                    self.world.pop_keep_out();
                }
                self.pending_no_route = false;
            }
        }
        self.advance(x, now);
        let target = self.route[self.route_index];
        self.checker.update(x, &target, now);
        let stalled_for = self.checker.stalled_for(now);
        let final_target = self.route_index + 1 == self.route.len();
        let holding = final_target && goal_distance(x, &goal) < self.settings.reached_tolerance;
        let approached = stalled_for == 0.0 && self.window_target == Some(target);
        self.window_target = Some(target);
        if approached || holding {
            self.last_progress = now;
        }
        if now - self.last_progress >= self.settings.progress.timeout {
            self.aborted = Some(AbortReason::NoProgress);
            return NavStep::Abort(AbortReason::NoProgress);
        }
        let stalled = !holding
            && stalled_for >= self.settings.replan_after
            && now - self.last_replan >= self.settings.replan_after;
        if stalled
            && final_target
            && self.retries < self.settings.max_retries
            && self.stuck_near(x, &goal)
            && (self.world.is_empty()
                || self.in_search_goal_region(x, &goal)
                || (self.settings.retry_in_sight && self.goal_in_sight(x, &goal)))
        {
            self.retries += 1;
            self.last_replan = now;
            // A new manoeuvre that may first lead away (to straighten the
            // machine out): its own window, bounded by `max_retries`.
            self.last_progress = now;
            self.retry(x, &goal);
        } else if stalled
            && !self.world.is_empty()
            && self.replans >= 1
            && !self.backing_up
            && self.back_ups < self.settings.max_back_ups
            && self.back_up(x)
        {
            // The replan did not help: back up along the track (a manoeuvre
            // that leads away first: its own window), then replan there.
            self.back_ups += 1;
            self.last_replan = now;
            self.last_progress = now;
        } else if stalled && !self.world.is_empty() && self.replans < self.settings.max_replans {
            self.replans += 1;
            self.last_replan = now;
            // The field knows no heading: a machine it stalled (pressed
            // against a circle, or without room to turn) goes on by the
            // route's subgoals, which do.
            self.field_stalled = self.settings.tracking == Tracking::Field;
            self.plan(x, true);
            // A failed replan keeps the route it had: the abort window decides.
            self.pending_no_route = false;
            self.advance(x, now);
        }
        let (target, final_target) = self.drive_target(x);
        self.refresh_field(x);
        self.refresh_path(x);
        NavStep::Drive {
            target,
            final_target,
        }
    }

    /// The current subgoal sequence ending with the goal ([goal] when direct;
    /// empty without a goal).
    pub fn route(&self) -> &[Goal] {
        &self.route
    }

    /// The subgoals not yet passed, ending with the goal.
    pub fn remaining_route(&self) -> &[Goal] {
        &self.route[self.route_index.min(self.route.len())..]
    }

    /// The last planned path (empty when direct).
    pub fn path(&self) -> &[PathPose] {
        &self.path
    }

    pub fn goal(&self) -> Option<Goal> {
        self.goal
    }

    /// The last plan's report.
    pub fn last_plan(&self) -> Option<PlanReport> {
        self.last_plan
    }

    /// Plans made since construction (a new report each time it grows).
    pub fn plans(&self) -> u64 {
        self.plans
    }

    /// Forgets the goal and the route.
    pub fn clear(&mut self) {
        self.goal = None;
        self.route.clear();
        self.route_path_index.clear();
        self.path.clear();
        self.path_index = 0;
        self.route_index = 0;
        self.checker = ProgressChecker::new(self.settings.progress);
        self.window_target = None;
        self.clocks_pending = false;
        self.replans = 0;
        self.retries = 0;
        self.back_ups = 0;
        self.backing_up = false;
        self.stall_point = None;
        self.pending_no_route = false;
        self.aborted = None;
        self.field.clear();
        self.field_plan = None;
        self.field_stalled = false;
        self.path_cost.clear();
        self.path_key = None;
        self.path_handed = false;
        self.cost_version += 1;
    }

    /// Passes every subgoal within `subgoal_radius` (never the goal); with a
    /// carrot also every subgoal the projection onto the path has passed (a
    /// carrot may cut a corner at more than the radius from its subgoal).
    fn advance(&mut self, x: &State, now: f64) {
        let s = &self.settings;
        let following = matches!(
            s.tracking,
            Tracking::Carrot | Tracking::Field | Tracking::Path
        ) && !self.path.is_empty();
        if following {
            self.path_index = carrot::project(
                &self.path,
                self.path_index,
                x[ix::X],
                x[ix::Y],
                2.0 * s.carrot_distance,
                s.subgoal_radius,
            );
        }
        while self.route_index + 1 < self.route.len() && !self.backing_up {
            let t = &self.route[self.route_index];
            let near = (x[ix::X] - t.x).hypot(x[ix::Y] - t.y) < s.subgoal_radius;
            let behind = following
                && self
                    .route_path_index
                    .get(self.route_index)
                    .is_some_and(|&i| i < self.path_index);
            if !(near || behind) {
                break;
            }
            self.route_index += 1;
            self.last_progress = now;
        }
    }

    /// What the MPC drives to: the current route entry, or with a carrot the
    /// pose `carrot_distance` ahead on the path (the goal once the carrot
    /// reaches the path's end).
    fn drive_target(&mut self, x: &State) -> (Goal, bool) {
        let last = self.route.len() - 1;
        let s = &self.settings;
        if self.driving_to_goal_in_field() {
            // The field knows the way: the MPC drives to the goal itself.
            return (self.route[last], true);
        }
        if let Some(end) = self.forward_end().filter(|_| self.route_index < last) {
            // The end of this forward drive: a cusp, or the path's end (then
            // the goal). The path cost drives there; the critic, with this
            // target, does the last part.
            if end + 1 < self.path.len() {
                let p = &self.path[end];
                return (Goal::new(p.x, p.y, p.theta), false);
            }
            return (self.route[last], true);
        }
        if s.tracking == Tracking::Carrot && !self.path.is_empty() && self.route_index < last {
            let world = &self.world;
            let k = carrot::carrot(
                &self.path,
                self.path_index,
                s.carrot_distance,
                s.subgoal_radius,
                |p| line_of_sight_free(world, x, p, s.sample_spacing),
            );
            if k + 1 < self.path.len() {
                let p = &self.path[k];
                return (Goal::new(p.x, p.y, p.theta), false);
            }
            // The carrot has reached the path's end: the last leg is the goal's.
            self.route_index = last;
        }
        (self.route[self.route_index], self.route_index == last)
    }

    /// Decides direct or not (unless `force`), plans, writes the route.
    fn plan(&mut self, start: &State, force: bool) {
        let t0 = Instant::now();
        self.backing_up = false;
        let Some(goal) = self.goal else {
            return;
        };
        let s = &self.settings;
        // Near a pile the start or goal may already be inside the margin: the
        // plan keeps what the endpoints have (half of it), never more than asked.
        let goal_pose = State::new(goal.x, goal.y, goal.theta, 0.0, 0.0, 0.0);
        let endpoints = 0.5
            * self
                .world
                .state_clearance(start)
                .min(self.world.state_clearance(&goal_pose));
        let margin = s.clearance_margin.min(endpoints).max(0.0);
        let direct_margin = s.direct_margin.min(endpoints).max(margin);
        let mut report = PlanReport {
            outcome: PlanOutcome::Direct,
            duration: Duration::ZERO,
            search: SearchStats::default(),
            replan: force,
        };
        let plan_every_goal = s.plan_every_goal;
        self.world.set_margin(direct_margin);
        let open_cost = if self.world.is_empty() {
            Some(0.0)
        } else if force {
            None
        } else {
            self.open_way_cost(start, &goal)
        };
        self.world.set_margin(margin);
        // Planning every goal, an open way is searched too, and kept (the
        // critic alone) unless the search finds a cheaper one.
        let direct = self.world.is_empty() || (open_cost.is_some() && !plan_every_goal);
        let mut new_route = true;
        if direct {
            self.path.clear();
        } else {
            let (result, stats) = match (&mut self.planner, self.networks.as_mut()) {
                (Planner::HybridAStar(h), n) => {
                    let actor = n.map(|n| (&n.actor, &mut n.actor_ws));
                    h.search(&self.world, start, &goal, actor, &mut self.path)
                }
                (Planner::WaypointGraph(w), Some(n)) => w.search(
                    &self.world,
                    start,
                    &goal,
                    &n.actor,
                    &mut n.actor_ws,
                    &n.critic,
                    &mut n.critic_ws,
                    &mut self.path,
                ),
                // `new` refuses a waypoint graph without networks.
                (Planner::WaypointGraph(_), None) => {
                    (Err(SearchFailure::Unreachable), SearchStats::default())
                }
            };
            report.search = stats;
            match result {
                Ok(()) if open_cost.is_some_and(|c| stats.cost >= c) => {
                    // Planning every goal: the open way is as cheap.
                    self.path.clear();
                }
                Ok(()) => {
                    report.outcome = PlanOutcome::Route;
                    // A waypoint graph's path is its waypoints, not arcs to smooth.
                    if let Planner::HybridAStar(_) = self.planner {
                        let s = &self.settings;
                        let smoothing = Smoothing {
                            iterations: s.smooth_iterations,
                            data_weight: s.smooth_data_weight,
                            sample_spacing: s.sample_spacing,
                        };
                        self.smoother
                            .smooth(&mut self.path, &self.world, &smoothing);
                    }
                }
                Err(_) => {
                    self.path.clear();
                    // Planning every goal: a search that fails (its budget)
                    // where the roll-out finds the way open goes direct, as it
                    // would have without the search.
                    if open_cost.is_none() {
                        report.outcome = PlanOutcome::NoRoute;
                        self.pending_no_route = true;
                        // A replan that fails keeps the old route, a first plan has [goal].
                        new_route = self.route.is_empty();
                    }
                }
            }
        }
        if new_route {
            if report.outcome == PlanOutcome::Route {
                // Hybrid A*'s nodes are 0.6 m apart: thin them to the
                // spacing. The graph's nodes are each a chosen waypoint.
                let spacing = match self.planner {
                    Planner::HybridAStar(_) => self.settings.subgoal_spacing,
                    Planner::WaypointGraph(_) => 0.0,
                };
                route::subgoals_from_path(
                    &self.path,
                    goal,
                    spacing,
                    self.settings.subgoal_radius,
                    &mut self.route,
                    &mut self.route_path_index,
                );
            } else {
                self.route.clear();
                self.route_path_index.clear();
                self.route.push(goal);
            }
            self.route_index = 0;
            self.path_index = 0;
        }
        report.duration = t0.elapsed();
        self.last_plan = Some(report);
        self.plans += 1;
    }

    /// The goal's cost-to-go field while [`Self::driving_to_goal_in_field`],
    /// over the planning world (its margin and any keep-out circle): computed
    /// once per plan. No field for a direct way, a back-up, a retry or after
    /// the hand-over to subgoals (the critic alone, as in open ground).
    fn refresh_field(&mut self, x: &State) {
        let goal = self.goal.filter(|_| self.driving_to_goal_in_field());
        let Some(goal) = goal else {
            if !self.field.is_empty() {
                self.field.clear();
                self.cost_version += 1;
            }
            self.field_plan = None;
            return;
        };
        if self.field_plan == Some(self.plans) {
            return;
        }
        self.field_plan = Some(self.plans);
        self.cost_version += 1;
        let s = &self.settings;
        // A grid of the search's size, centred between machine and goal.
        let centre = [0.5 * (x[ix::X] + goal.x), 0.5 * (x[ix::Y] + goal.y)];
        let frame = GridFrame::centred(centre, s.grid_resolution, s.grid_cells());
        let margin = self.world.margin();
        self.world.set_margin(s.field_margin.max(margin));
        self.field_distance
            .compute(frame, &self.world, [goal.x, goal.y]);
        self.world.set_margin(margin);
        self.field_distance
            .write_excess(s.field_gain * self.cost_per_metre, &mut self.field);
    }

    /// The path cost while `Tracking::Path` follows a forward part of a
    /// planned path: that part (from the machine's projection to the next
    /// cusp or the path's end, continued by the goal shot a path may end
    /// with), set once per plan and part; empty once the machine is within
    /// `path_handover` of its end (the critic's part), and without a path.
    fn refresh_path(&mut self, x: &State) {
        let goal = self.goal;
        let key = self
            .forward_end()
            .zip(goal)
            .map(|(end, _)| (self.plans, end));
        if key != self.path_key {
            self.path_key = key;
            self.path_handed = false;
            self.path_hint = 0;
            self.cost_version += 1;
            match (key, goal) {
                (Some((_, end)), Some(g)) => self.set_path_cost(end, &g),
                _ => self.path_cost.clear(),
            }
        }
        if self.path_handed || self.path_cost.is_empty() {
            return;
        }
        let (left, segment) = self.path_cost.arc_left(x[ix::X], x[ix::Y], self.path_hint);
        self.path_hint = segment;
        // An open end is where the search's goal shot started: the critic
        // takes over there, where the shot showed the way is open.
        let handover = if self.path_cost.open_end() {
            0.0
        } else {
            self.settings.path_handover
        };
        if left <= handover {
            self.path_handed = true;
            self.path_cost.clear();
            self.cost_version += 1;
        }
    }

    /// The path cost for the forward part ending at pose `end`. A path that
    /// ends where a goal shot starts is continued by the shot (the actor's
    /// way to the goal, driven again); a shot that reverses or cannot be
    /// driven again leaves the path's end open (the critic takes over there).
    fn set_path_cost(&mut self, end: usize, goal: &Goal) {
        let shot = self.shot_ends_path(goal, end);
        if shot {
            self.trace_shot(goal);
        }
        let s = &self.settings;
        let start = carrot::direction_start(&self.path, self.path_index)
            .max(self.path_index.saturating_sub(1));
        let c = self.cost_per_metre;
        let weights = PathWeights {
            per_metre: c,
            lateral: s.path_lateral * c,
            heading: s.path_heading * c,
            control: s.path_control * c,
        };
        let poses = self.path[start..=end].iter().map(|p| [p.x, p.y, p.theta]);
        // A shot that reverses on the way is a manoeuvre for the critic.
        let drivable = shot && !self.shot.is_empty() && !self.shot_reverses();
        let tail: &[State] = if drivable { &self.shot } else { &[] };
        let tail = tail.iter().map(|x| [x[ix::X], x[ix::Y], x[ix::THETA]]);
        let open_end = shot && !drivable;
        self.path_cost
            .set(poses.chain(tail), weights, &self.params, open_end);
    }

    /// Drives the goal shot from the path's end again (once per plan):
    /// `shot` holds its states (none when it does not reach the goal).
    fn trace_shot(&mut self, goal: &Goal) {
        if self.shot_plan == Some(self.plans) {
            return;
        }
        self.shot_plan = Some(self.plans);
        self.shot.clear();
        let (Some(n), Some(p)) = (self.networks.as_mut(), self.path.last()) else {
            return;
        };
        let s = &self.settings;
        let start = State::new(p.x, p.y, p.theta, p.beta, 0.0, 0.0);
        let dist = (p.x - goal.x).hypot(p.y - goal.y);
        let r = roll_out(
            &self.params,
            &n.actor,
            &mut n.actor_ws,
            &self.world,
            &start,
            goal,
            Arrival::Pose(s.shot_tolerance),
            s.rollout_dt,
            hybrid_astar::shot_steps(dist, s.rollout_dt),
            Some(&mut self.shot),
        );
        if !r.reached {
            self.shot.clear();
        }
    }

    /// Whether the shot drives backwards anywhere.
    fn shot_reverses(&self) -> bool {
        self.shot.iter().any(|x| x[ix::V] < -REACH_SPEED)
    }

    /// `Tracking::Path` on a forward part of a planned path: the index of its
    /// last pose. Reversing parts go by the route's subgoals, the critic's
    /// targets: measured, the path cost reversing (the front axle trailing
    /// the rear) can lock the articulation and stall.
    fn forward_end(&self) -> Option<usize> {
        if self.settings.tracking != Tracking::Path || self.path.is_empty() {
            return None;
        }
        let end = carrot::direction_end(&self.path, self.path_index);
        (self.path[end].direction >= 0).then_some(end)
    }

    /// Whether pose `end` of the path is its last and a goal shot starts
    /// there (it is outside the search's goal region).
    fn shot_ends_path(&self, goal: &Goal, end: usize) -> bool {
        let p = &self.path[end];
        end + 1 == self.path.len()
            && (p.x - goal.x).hypot(p.y - goal.y) > self.settings.goal_position_tolerance
    }

    /// `Tracking::Field` on a planned route that has not stalled: the MPC
    /// drives to the goal, the field shows the way.
    fn driving_to_goal_in_field(&self) -> bool {
        self.settings.tracking == Tracking::Field && !self.path.is_empty() && !self.field_stalled
    }

    /// The cost-to-go field the MPC adds to its cost now (`None`: the critic
    /// alone). It changes only when [`Self::cost_version`] does.
    pub fn cost_to_go(&self) -> Option<&CostToGo> {
        (!self.field.is_empty()).then_some(&self.field)
    }

    /// The path whose progress is the MPC's cost now (`None`: the critic).
    /// It changes only when [`Self::cost_version`] does.
    pub fn path_cost(&self) -> Option<&PathCost> {
        (!self.path_cost.is_empty()).then_some(&self.path_cost)
    }

    /// Counts the changes of the MPC's cost terms ([`Self::cost_to_go`],
    /// [`Self::path_cost`]).
    pub fn cost_version(&self) -> u64 {
        self.cost_version
    }

    /// Gives `mpc` the navigator's cost terms if they changed since `seen`
    /// (the last [`Self::cost_version`] given; `None` at first): after every
    /// `update`, so the MPC solves with what the navigator decided.
    pub fn sync_costs<C: StageCost, D: Dynamics, B: QpBackend>(
        &self,
        mpc: &mut Mpc<C, D, B>,
        seen: &mut Option<u64>,
    ) {
        if *seen != Some(self.cost_version) {
            *seen = Some(self.cost_version);
            mpc.set_cost_to_go(self.cost_to_go());
            mpc.set_path_cost(self.path_cost());
        }
    }

    /// Slower than [`STUCK_SPEED`] within `approach_distance` of the goal:
    /// stopped (or crawling) short of it, not manoeuvring towards it (a turn
    /// that first raises the pose error moves faster).
    fn stuck_near(&self, x: &State, goal: &Goal) -> bool {
        x[ix::V].abs() < STUCK_SPEED
            && (x[ix::X] - goal.x).hypot(x[ix::Y] - goal.y) <= self.settings.approach_distance
    }

    /// Whether the straight line from the front axle to the goal keeps the
    /// route's margin: a replan from there shoots straight at the goal and
    /// hands back the route that stalled.
    fn goal_in_sight(&self, x: &State, goal: &Goal) -> bool {
        self.world
            .segment_clear([x[ix::X], x[ix::Y]], [goal.x, goal.y], self.world.margin())
    }

    /// Whether `x` is inside the goal region of the planners' search, where a
    /// replan has nothing left to plan.
    fn in_search_goal_region(&self, x: &State, goal: &Goal) -> bool {
        let s = &self.settings;
        (x[ix::X] - goal.x).hypot(x[ix::Y] - goal.y) <= s.goal_position_tolerance
            && wrap_angle(x[ix::THETA] - goal.theta).abs() <= s.goal_heading_tolerance
    }

    /// The retry after a stall on the goal: route [approach pose, goal], the
    /// approach pose `approach_distance` behind the goal on its heading (a
    /// forward final approach), or ahead of it (a reversing one) when the one
    /// behind or the way to it is blocked. With both blocked the route stays:
    /// the abort window decides.
    fn retry(&mut self, x: &State, goal: &Goal) {
        let t0 = Instant::now();
        self.backing_up = false;
        let d = self.settings.approach_distance;
        let (sin, cos) = goal.theta.sin_cos();
        let approach = [-1.0, 1.0]
            .into_iter()
            .map(|side| Goal::new(goal.x + side * d * cos, goal.y + side * d * sin, goal.theta))
            .find(|a| {
                self.world.is_empty()
                    || (self.world.pose_free(a.x, a.y, a.theta, 0.0)
                        && self.open_way_cost(x, a).is_some())
            });
        let outcome = match approach {
            Some(a) => {
                self.path.clear();
                self.route.clear();
                self.route_path_index.clear();
                self.route.push(a);
                self.route.push(*goal);
                self.route_index = 0;
                PlanOutcome::Retry
            }
            None => PlanOutcome::NoRoute,
        };
        self.last_plan = Some(PlanReport {
            outcome,
            duration: t0.elapsed(),
            search: SearchStats::default(),
            replan: true,
        });
        self.plans += 1;
    }

    /// The ladder's back-up: route [the pose `back_up_distance` back along
    /// the track, goal], if the track reaches that far with the pose clear.
    fn back_up(&mut self, x: &State) -> bool {
        let t0 = Instant::now();
        let d = self.settings.back_up_distance;
        let Some(p) = self.track.back(d).filter(|_| d > 0.0) else {
            return false;
        };
        if !self.world.pose_free(p.x, p.y, p.theta, p.beta)
            || (p.x - x[ix::X]).hypot(p.y - x[ix::Y]) < BACK_UP_ARRIVAL
        {
            return false;
        }
        let Some(goal) = self.goal else {
            return false;
        };
        self.path.clear();
        self.route.clear();
        self.route_path_index.clear();
        self.route.push(Goal::new(p.x, p.y, p.theta));
        self.route.push(goal);
        self.route_index = 0;
        self.backing_up = true;
        self.stall_point = Some([x[ix::X], x[ix::Y]]);
        self.last_plan = Some(PlanReport {
            outcome: PlanOutcome::BackUp,
            duration: t0.elapsed(),
            search: SearchStats::default(),
            replan: true,
        });
        self.plans += 1;
        true
    }

    /// Adds the keep-out circle `o` to the planning world unless the machine
    /// or the goal is within it (then the replan cannot keep out).
    fn keep_out(&mut self, x: &State, o: Obstacle) -> bool {
        let Some(goal) = self.goal else {
            return false;
        };
        let goal_pose = State::new(goal.x, goal.y, goal.theta, 0.0, 0.0, 0.0);
        let clear = |s: &State| {
            footprint_clearance(&self.params, s, &[o]) >= self.settings.clearance_margin
        };
        clear(x) && clear(&goal_pose) && self.world.push_keep_out(o)
    }

    /// "Is anything in the way?", by measurement: the actor rolled out from
    /// the start (what the MPC's warm start does) keeps the margin all the way,
    /// or, without networks, a straight corridor of both axle points does.
    /// `None` when something is in the way, else the open way's cost in the
    /// search's units (the roll-out's duration at top speed, ∞ when it keeps
    /// the margin without arriving; without networks the straight distance).
    fn open_way_cost(&mut self, start: &State, goal: &Goal) -> Option<f64> {
        let s = &self.settings;
        match self.networks.as_mut() {
            Some(n) => {
                let steps = (s.direct_horizon / s.rollout_dt).ceil() as usize;
                let r = roll_out(
                    &self.params,
                    &n.actor,
                    &mut n.actor_ws,
                    &self.world,
                    start,
                    goal,
                    Arrival::Pose(s.shot_tolerance),
                    s.rollout_dt,
                    steps,
                    None,
                );
                match (r.collided, r.reached) {
                    (true, _) => None,
                    (false, true) => Some(r.duration(s.rollout_dt) * self.params.v_max),
                    (false, false) => Some(f64::INFINITY),
                }
            }
            None => straight_corridor_free(&self.world, start, goal, s.sample_spacing)
                .then(|| (start[ix::X] - goal.x).hypot(start[ix::Y] - goal.y)),
        }
    }
}

/// Below this speed, within `approach_distance` of the goal and without
/// approach for `replan_after`, the machine is stuck near the goal [m/s]: not
/// only at rest, as the critic may also crawl back and forth beside it
/// (`wall038` of obstacles200: measured, 0.05 m/s missed it, 0.2 and 0.3 reach
/// it and change no other run; a machine turning towards the goal at speed is
/// not stuck).
const STUCK_SPEED: f64 = 0.2;

/// Within this distance of the back-up pose the machine has backed up [m].
const BACK_UP_ARRIVAL: f64 = 0.5;

/// Radius of the keep-out circle at the stall point for the replan after a
/// back-up [m] (both axle points keep it plus the route's margin).
const KEEP_OUT_RADIUS: f64 = 0.5;

/// The machine's recent front-axle poses, one every [`Track::SPACING`] of
/// travel, newest last; a fixed ring (no allocation) of [`Track::CAPACITY`].
#[derive(Debug, Clone, Copy)]
struct Track {
    poses: [PathPose; Track::CAPACITY],
    /// Index of the newest pose.
    head: usize,
    len: usize,
}

impl Default for Track {
    fn default() -> Self {
        let origin = PathPose {
            x: 0.0,
            y: 0.0,
            theta: 0.0,
            beta: 0.0,
            direction: 0,
        };
        Self {
            poses: [origin; Track::CAPACITY],
            head: 0,
            len: 0,
        }
    }
}

impl Track {
    const CAPACITY: usize = 64;
    const SPACING: f64 = 0.2;

    /// Keeps `x` if it is `SPACING` from the newest pose (or the first).
    fn record(&mut self, x: &State) {
        if self.len > 0 {
            let last = &self.poses[self.head];
            if (x[ix::X] - last.x).hypot(x[ix::Y] - last.y) < Self::SPACING {
                return;
            }
        }
        self.head = (self.head + 1) % Self::CAPACITY;
        self.len = (self.len + 1).min(Self::CAPACITY);
        self.poses[self.head] = PathPose {
            x: x[ix::X],
            y: x[ix::Y],
            theta: x[ix::THETA],
            beta: x[ix::BETA],
            direction: 0,
        };
    }

    /// The first pose at least `distance` of travel back from the newest.
    fn back(&self, distance: f64) -> Option<PathPose> {
        let mut travelled = 0.0;
        let mut k = self.head;
        for _ in 1..self.len {
            let prev = (k + Self::CAPACITY - 1) % Self::CAPACITY;
            let (a, b) = (&self.poses[k], &self.poses[prev]);
            travelled += (a.x - b.x).hypot(a.y - b.y);
            k = prev;
            if travelled >= distance {
                return Some(self.poses[k]);
            }
        }
        None
    }
}

/// Both axle points keep the margin at the poses along the straight line
/// from `from` to `to`, `spacing` apart, heading along the line (against it
/// when `reverse`: the rear axle leads) and unarticulated; the pose at `from`
/// itself only when `with_from`.
fn line_free(
    world: &World,
    from: [f64; 2],
    to: [f64; 2],
    reverse: bool,
    spacing: f64,
    with_from: bool,
) -> bool {
    let (dx, dy) = (to[0] - from[0], to[1] - from[1]);
    let heading = dy.atan2(dx) + if reverse { std::f64::consts::PI } else { 0.0 };
    let n = (dx.hypot(dy) / spacing).ceil().max(1.0) as usize;
    (usize::from(!with_from)..=n).all(|k| {
        let f = k as f64 / n as f64;
        world.pose_free(from[0] + f * dx, from[1] + f * dy, heading, 0.0)
    })
}

/// The carrot's line of sight: the straight line from the machine's front
/// axle to the path pose `p` (the machine's own pose is not tested: it may
/// already be closer than the margin).
fn line_of_sight_free(world: &World, x: &State, p: &PathPose, spacing: f64) -> bool {
    let from = [x[ix::X], x[ix::Y]];
    line_free(world, from, [p.x, p.y], p.direction < 0, spacing, false)
}

/// Both axle points free along the straight line from the start's front axle
/// to the goal's, heading along the line and unarticulated, plus both end poses.
fn straight_corridor_free(world: &World, start: &State, goal: &Goal, spacing: f64) -> bool {
    let from = [start[ix::X], start[ix::Y]];
    line_free(world, from, [goal.x, goal.y], false, spacing, true)
        && world.state_free(start)
        && world.pose_free(goal.x, goal.y, goal.theta, 0.0)
}

#[cfg(test)]
mod tests;
