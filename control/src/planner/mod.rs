//! The global layer above the MPC (DESIGN §10, §15): when the way to the
//! goal is blocked it finds a collision-free route, the MPC follows it
//! (progress along the path is its cost, the critic drives the last part),
//! it replans when progress stalls, and aborts a goal that makes no progress
//! or has no route.
//!
//! Why: the MPC's horizon is 2 s and its critic knows no obstacles, so behind
//! an obstacle it sits in a local minimum.
//!
//! Pieces: [`settings`] (declared once, grouped), [`CheckedWorld`] (the circles,
//! both axle points, a margin), the actor [`rollout`] ("is anything in the
//! way?", goal shots), [`HybridAStar`] over (x, y, θ) with the model's
//! [`primitives`], [`route`] (path → subgoals), [`path_geometry`] (cusps,
//! arc length, the projection), the [`RoutePlanner`] that runs them, the
//! [`RouteService`] that runs it off the tick ([`PlannerThread`] in the
//! daemon, [`InlineRoutes`] in the simulator), and the [`Navigator`], the
//! tick's side.
//!
//! Everything is allocated at construction; `set_goal` and `update` allocate
//! nothing and never search. Measured designs that lost (carrot, cost-to-go
//! field, point subgoals, the path smoother, the back-up ladder, the
//! waypoint graph) are in `docs/decisions.md`.

pub mod grid;
pub mod hybrid_astar;
pub mod navigator;
pub mod path_geometry;
pub mod primitives;
mod queue;
pub mod rollout;
pub mod route;
pub mod route_planner;
pub mod service;
pub mod settings;
pub mod trajectory;
pub mod world;

use std::time::Duration;

pub use hybrid_astar::{HybridAStar, SearchFailure, SearchStats};
pub use navigator::{critic_cost_per_metre, Navigator};
pub use route_planner::{PlanJob, PlanKind, PlanRequest, Route, RoutePlanner};
pub use service::{
    mark_tick_thread, on_tick_thread, InlineRoutes, PlanDelay, PlannerThread, RouteService,
};
pub use settings::{FollowingSettings, NavigatorSettings, SearchSettings, StallSettings};
pub use trajectory::{TrajectoryFailure, TrajectoryOptimiser, TrajectoryOutcome};
pub use world::CheckedWorld;

use crate::model::Goal;
use crate::obstacle::BadObstacle;

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
    /// Hold: the first route is being planned.
    Hold,
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
    #[error("no goal is being driven")]
    NoGoal,
}

/// How the last plan ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlanOutcome {
    /// Nothing in the way: the goal alone in open ground; among circles the
    /// path of the actor's roll-out that found the way open, then the goal.
    Direct,
    /// A route of subgoals.
    Route,
    /// The planner found none.
    NoRoute,
    /// A retry after a stall near the goal: the route is the approach pose
    /// (by the actor's roll-out or a search where one reaches it), then the
    /// goal (`StallSettings::approach_distance`).
    Retry,
}

impl PlanOutcome {
    /// The name in reports.
    pub fn name(self) -> &'static str {
        match self {
            PlanOutcome::Direct => "direct",
            PlanOutcome::Route => "route",
            PlanOutcome::NoRoute => "no-route",
            PlanOutcome::Retry => "retry",
        }
    }
}

/// What the last plan did and how long it took.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanReport {
    pub outcome: PlanOutcome,
    /// The whole plan: the "in the way" test, the search, the shot and the
    /// trajectory.
    pub duration: Duration,
    pub search: SearchStats,
    /// A replan from `update` (not a new goal).
    pub replan: bool,
    /// Whether the route was shaped into a trajectory, or why not.
    pub trajectory: TrajectoryOutcome,
}

impl Default for PlanReport {
    fn default() -> Self {
        Self {
            outcome: PlanOutcome::NoRoute,
            duration: Duration::ZERO,
            search: SearchStats::default(),
            replan: false,
            trajectory: TrajectoryOutcome::NotAsked,
        }
    }
}

#[cfg(test)]
mod tests;
