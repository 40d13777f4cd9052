//! Planning a route: everything the global layer computes that takes longer
//! than a tick's share (the actor's "is anything in the way?" roll-out, the
//! Hybrid A* search, its goal shot driven again, the retry's approach
//! checks). It runs where a [`super::RouteService`] puts it: on the planner
//! thread in the daemon, charged as simulated delay in `wlnav-sim`; never on
//! the tick thread.
//!
//! A [`PlanJob`] carries the request and the buffers of its answer, and goes
//! back and forth between the navigator and the planner: nothing is allocated
//! after start-up.

use std::time::{Duration, Instant};

use crate::actor::{Actor, ActorWorkspace};
use crate::model::{ix, Goal, MachineParams, State};
use crate::world::World;

use super::hybrid_astar::{self, HybridAStar, SearchStats};
use super::rollout::{roll_out, Arrival};
use super::route::subgoals_from_path;
use super::trajectory::{push_states_as_path, TrajectoryOptimiser, TrajectoryOutcome};
use super::world::CheckedWorld;
use super::{FollowingSettings, NavError, PathPose, PlanOutcome, PlanReport, SearchSettings};

/// How much more of the extra margins a plan gives up than an endpoint inside
/// them lacks [m]: the endpoint then passes its own check with room to spare.
const RELIEF_GAP: f64 = 0.02;

/// What is asked of the planner.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlanKind {
    /// A new goal: the open way if nothing is in the way, else a search.
    First,
    /// A replan after a stall: always a search.
    Replan,
    /// A stall on the goal: the approach pose, then the goal.
    Retry,
}

/// The request: where from, where to, among what.
#[derive(Debug, Clone)]
pub struct PlanRequest {
    /// Counts the navigator's goals: an answer to an older goal is dropped.
    pub goal_seq: u64,
    pub kind: PlanKind,
    /// When `start` was measured [s, the navigator's clock]: the route's age
    /// counts from here.
    pub stamp: f64,
    pub start: State,
    pub goal: Goal,
    /// The world to plan in (the site, the goal's circles within
    /// `SearchSettings::max_obstacles`, the outline).
    pub world: World,
}

/// A planned route: the path (empty in open ground, and for a retry the
/// critic drives) and the targets along it, ending with the goal.
#[derive(Debug, Clone)]
pub struct Route {
    pub report: PlanReport,
    pub path: Vec<PathPose>,
    /// Subgoals along the path, ending with the goal (empty: no route).
    pub targets: Vec<Goal>,
    /// Each target's index in `path` (the goal's is `path.len()`).
    pub target_path_index: Vec<usize>,
    /// The goal shot the path ends with, driven again by the actor (empty
    /// when the path does not end with one, or it does not reach the goal).
    pub shot: Vec<State>,
    /// The path is the actor's roll-out (an open way, or a retry's way to
    /// its approach pose), not the search's: its reversing parts are
    /// followed too (by the rear axle).
    pub rolled_out: bool,
    /// A minimum-time trajectory to the goal (issue 42), its states every
    /// `trajectory_dt`: the MPC tracks it (empty: the path is followed).
    pub trajectory: Vec<State>,
    pub trajectory_dt: f64,
}

impl Route {
    /// Buffers for paths of up to `max_nodes` poses and shots of up to
    /// `shot_range`.
    pub fn with_capacity(s: &SearchSettings) -> Self {
        Self {
            report: PlanReport::default(),
            path: Vec::with_capacity(s.max_nodes),
            targets: Vec::with_capacity(s.max_nodes + 1),
            target_path_index: Vec::with_capacity(s.max_nodes + 1),
            shot: Vec::with_capacity(hybrid_astar::shot_steps(s.shot_range, s.rollout_dt) + 1),
            rolled_out: false,
            trajectory: Vec::with_capacity(crate::mpc::MAX_TRACK_STATES),
            trajectory_dt: 0.0,
        }
    }

    pub fn clear(&mut self) {
        self.report = PlanReport::default();
        self.path.clear();
        self.targets.clear();
        self.target_path_index.clear();
        self.shot.clear();
        self.rolled_out = false;
        self.trajectory.clear();
        self.trajectory_dt = 0.0;
    }

    /// The targets along the path: its subgoals, then `goal`.
    fn set_subgoals(&mut self, goal: Goal, f: &FollowingSettings) {
        subgoals_from_path(
            &self.path,
            goal,
            f.subgoal_spacing,
            f.subgoal_radius,
            &mut self.targets,
            &mut self.target_path_index,
        );
    }

    /// `goal` after the path's end (in place of the last target if the
    /// route is full): the retry's goal after its approach pose.
    fn push_after(&mut self, goal: Goal) {
        if self.targets.len() == self.targets.capacity() {
            self.targets.pop();
            self.target_path_index.pop();
        }
        self.targets.push(goal);
        self.target_path_index.push(self.path.len());
    }

    /// A route that is the goal alone (the open way).
    fn direct(&mut self, goal: Goal) {
        self.clear();
        self.targets.push(goal);
        self.target_path_index.push(0);
    }
}

/// A request and the buffers of its answer.
#[derive(Debug, Clone)]
pub struct PlanJob {
    pub request: PlanRequest,
    pub route: Route,
}

impl PlanJob {
    pub fn new(params: &MachineParams, s: &SearchSettings) -> Self {
        Self {
            request: PlanRequest {
                goal_seq: 0,
                kind: PlanKind::First,
                stamp: 0.0,
                start: State::zeros(),
                goal: Goal::new(0.0, 0.0, 0.0),
                world: World::with_axle_circles(*params, s.max_obstacles),
            },
            route: Route::with_capacity(s),
        }
    }
}

/// The planner: its own world, the search and the actor's roll-outs.
pub struct RoutePlanner {
    params: MachineParams,
    search_settings: SearchSettings,
    following: FollowingSettings,
    approach_distance: f64,
    world: CheckedWorld,
    search: HybridAStar,
    actor: Option<(Actor, ActorWorkspace)>,
    /// The actor's roll-out on the open way (its states, start first).
    open_way: Vec<State>,
    /// Shapes every way among obstacles (searched, or the open way's
    /// roll-out) by time (issue 42); `None`: the path is followed.
    trajectory: Option<Box<dyn TrajectoryOptimiser>>,
}

impl RoutePlanner {
    /// Everything allocated here, once. `actor`: the roll-outs that decide
    /// "is anything in the way?" and the search's goal shots (without it, a
    /// straight corridor and no shots).
    pub fn new(
        params: MachineParams,
        settings: &super::NavigatorSettings,
        actor: Option<Actor>,
    ) -> Result<Self, NavError> {
        settings.validate()?;
        let s = &settings.search;
        Ok(Self {
            params,
            search: HybridAStar::new(params, s),
            world: CheckedWorld::new(params, s.max_obstacles, s.clearance_margin),
            actor: actor.map(|a| {
                let ws = ActorWorkspace::new(&a);
                (a, ws)
            }),
            open_way: Vec::with_capacity(open_way_steps(s) + 1),
            trajectory: None,
            search_settings: s.clone(),
            following: settings.following,
            approach_distance: settings.stall.approach_distance,
        })
    }

    /// Every way among obstacles is shaped by `optimiser` from now on.
    pub fn with_trajectory(mut self, optimiser: Box<dyn TrajectoryOptimiser>) -> Self {
        self.trajectory = Some(optimiser);
        self
    }

    /// Answers `job.request` into `job.route`. Allocation-free (but for a
    /// trajectory optimiser's own).
    pub fn plan(&mut self, job: &mut PlanJob) {
        debug_assert!(
            !super::on_tick_thread(),
            "a route was planned on the tick thread (issue 44: plans run on the planner thread)"
        );
        let t0 = Instant::now();
        let PlanJob { request, route } = job;
        route.clear();
        let mut report = PlanReport {
            outcome: PlanOutcome::NoRoute,
            duration: Duration::ZERO,
            search: SearchStats::default(),
            replan: request.kind != PlanKind::First,
            trajectory: TrajectoryOutcome::NotAsked,
        };
        // The navigator validated the circles when the goal was set.
        self.world.copy_from(&request.world);
        report.outcome = match request.kind {
            PlanKind::First | PlanKind::Replan => {
                let outcome = self.route(request, route, &mut report);
                // Every way among obstacles, searched or open, is shaped by
                // time where an optimiser is given.
                if matches!(outcome, PlanOutcome::Route | PlanOutcome::Direct)
                    && !route.path.is_empty()
                {
                    report.trajectory = self.shape(&request.start, &request.goal, route);
                    if matches!(report.trajectory, TrajectoryOutcome::Shaped { .. }) {
                        route.set_subgoals(request.goal, &self.following);
                    }
                }
                outcome
            }
            PlanKind::Retry => self.retry(&request.start, &request.goal, route, &mut report),
        };
        report.duration = t0.elapsed();
        route.report = report;
    }

    /// Decides direct or not (a replan always searches), searches, writes the
    /// route.
    fn route(
        &mut self,
        req: &PlanRequest,
        route: &mut Route,
        report: &mut PlanReport,
    ) -> PlanOutcome {
        let (start, goal) = (&req.start, req.goal);
        let (margin, endpoints) = self.endpoint_margin(start, &goal);
        let s = &self.search_settings;
        let direct_margin = s.direct_margin.min(endpoints).max(margin);
        let plan_every_goal = s.plan_every_goal;
        self.world.set_margin(direct_margin);
        let open_cost = if self.world.is_empty() {
            Some(0.0)
        } else if req.kind == PlanKind::Replan {
            None
        } else {
            self.open_way_cost(start, &goal)
        };
        self.world.set_margin(margin);
        // Planning every goal, an open way is searched too, and kept (the
        // roll-out's path) unless the search finds a cheaper one.
        if self.world.is_empty() {
            route.direct(goal);
            return PlanOutcome::Direct;
        }
        if open_cost.is_some() && !plan_every_goal {
            self.follow_open_way(goal, route);
            return PlanOutcome::Direct;
        }
        let actor = self.actor.as_mut().map(|(a, ws)| (&*a, ws));
        let (result, stats) = self
            .search
            .search(&self.world, start, &goal, actor, &mut route.path);
        report.search = stats;
        match result {
            Ok(()) if open_cost.is_some_and(|c| stats.cost >= c) => {
                // Planning every goal: the open way is as cheap.
                self.follow_open_way(goal, route);
                PlanOutcome::Direct
            }
            Ok(()) => {
                // The search's nodes are 0.6 m apart: thinned to the spacing.
                route.set_subgoals(goal, &self.following);
                self.trace_shot(&goal, route);
                PlanOutcome::Route
            }
            // Planning every goal: a search that fails (its budget) where the
            // roll-out finds the way open goes direct, as without the search.
            Err(_) if open_cost.is_some() => {
                self.follow_open_way(goal, route);
                PlanOutcome::Direct
            }
            Err(_) => {
                route.clear();
                PlanOutcome::NoRoute
            }
        }
    }

    /// The margin a plan from `start` to `goal` keeps and the most it could
    /// (half the endpoints' slack); sets the relief of the extra margins it
    /// needs ([`CheckedWorld::set_relief`]). Near a pile the start or goal may
    /// already be inside the margin: the plan keeps what the endpoints have
    /// (half of it), never more than asked. An endpoint inside an outline
    /// circle's extra margin (the machine was stopped there) gives up as much
    /// of the extras as it lacks, and a bit.
    fn endpoint_margin(&mut self, start: &State, goal: &Goal) -> (f64, f64) {
        let goal_pose = State::new(goal.x, goal.y, goal.theta, 0.0, 0.0, 0.0);
        let slack = self
            .world
            .state_slack(start)
            .min(self.world.state_slack(&goal_pose));
        self.world
            .set_relief(if slack < 0.0 { RELIEF_GAP - slack } else { 0.0 });
        let endpoints = 0.5 * slack;
        let margin = self
            .search_settings
            .clearance_margin
            .min(endpoints)
            .max(0.0);
        (margin, endpoints)
    }

    /// The route's path (and shot) replaced by the optimiser's trajectory,
    /// where there is one: the MPC tracks it; the path (its poses, thinned)
    /// keeps the subgoals the progress checker and the replans go by.
    fn shape(&mut self, start: &State, goal: &Goal, route: &mut Route) -> TrajectoryOutcome {
        let Some(optimiser) = self.trajectory.as_mut() else {
            return TrajectoryOutcome::NotAsked;
        };
        let dt = match optimiser.optimise(
            &self.world,
            start,
            goal,
            &route.path,
            &route.shot,
            &mut route.trajectory,
        ) {
            Ok(dt) => dt,
            Err(why) => {
                route.trajectory.clear();
                return TrajectoryOutcome::Failed(why);
            }
        };
        route.trajectory_dt = dt;
        route.path.clear();
        route.shot.clear();
        route.rolled_out = true;
        push_states_as_path(
            &route.trajectory,
            self.search_settings.sample_spacing,
            &mut route.path,
        );
        TrajectoryOutcome::Shaped {
            duration: dt * route.trajectory.len().saturating_sub(1) as f64,
        }
    }

    /// The goal shot a path may end with (its last pose outside the search's
    /// goal region), driven again by the actor from the path's end: the
    /// search keeps only where it starts. Empty when it does not reach.
    fn trace_shot(&mut self, goal: &Goal, route: &mut Route) {
        route.shot.clear();
        let s = &self.search_settings;
        let (Some((actor, ws)), Some(p)) = (self.actor.as_mut(), route.path.last()) else {
            return;
        };
        let dist = (p.x - goal.x).hypot(p.y - goal.y);
        if dist <= s.goal_position_tolerance {
            return;
        }
        let start = State::new(p.x, p.y, p.theta, p.beta, 0.0, 0.0);
        let r = roll_out(
            &self.params,
            actor,
            ws,
            &self.world,
            &start,
            goal,
            Arrival::Pose(s.shot_tolerance),
            s.rollout_dt,
            hybrid_astar::shot_steps(dist, s.rollout_dt),
            Some(&mut route.shot),
        );
        if !r.reached {
            route.shot.clear();
        }
    }

    /// The retry after a stall on the goal: route [approach pose, goal], the
    /// approach pose `approach_distance` behind the goal on its heading (a
    /// forward final approach), or ahead of it (a reversing one) when the one
    /// behind or the way to it is blocked. Where the actor's roll-out cannot
    /// reach either (the machine stalled facing away, next to a pile), the
    /// search plans the way to the first free one (at the full distance, else
    /// at half of it). With none: no route (the navigator keeps its own; the
    /// abort window decides).
    fn retry(
        &mut self,
        x: &State,
        goal: &Goal,
        route: &mut Route,
        report: &mut PlanReport,
    ) -> PlanOutcome {
        self.world.set_margin(self.search_settings.clearance_margin);
        self.world.set_relief(0.0);
        route.clear();
        if let Some(a) = retry_approach(self.approach_distance, goal, |a| {
            self.world.is_empty()
                || (self.world.pose_free(a.x, a.y, a.theta, 0.0)
                    && self.open_way_cost(x, a).is_some())
        }) {
            // The roll-out that reached it is the way there (none in open
            // ground: the critic drives).
            self.follow_open_way(a, route);
            route.push_after(*goal);
            return PlanOutcome::Retry;
        }
        // Between piles a pose the full distance off may not be free: half as far.
        let Some(a) = [1.0, 0.5].into_iter().find_map(|k| {
            retry_approach(k * self.approach_distance, goal, |a| {
                self.world.pose_free(a.x, a.y, a.theta, 0.0)
            })
        }) else {
            return PlanOutcome::NoRoute;
        };
        let (margin, _) = self.endpoint_margin(x, &a);
        self.world.set_margin(margin);
        let actor = self.actor.as_mut().map(|(a, ws)| (&*a, ws));
        let (result, stats) = self
            .search
            .search(&self.world, x, &a, actor, &mut route.path);
        report.search = stats;
        if result.is_err() {
            route.clear();
            return PlanOutcome::NoRoute;
        }
        route.set_subgoals(a, &self.following);
        route.push_after(*goal);
        PlanOutcome::Retry
    }

    /// "Is anything in the way?", by measurement: the actor rolled out from
    /// the start (what the MPC's warm start does) keeps the margin all the way,
    /// or, without an actor, a straight corridor of both axle points does.
    /// `None` when something is in the way, else the open way's cost in the
    /// search's units (the roll-out's duration at top speed, ∞ when it keeps
    /// the margin without arriving; without an actor the straight distance).
    fn open_way_cost(&mut self, start: &State, goal: &Goal) -> Option<f64> {
        let s = &self.search_settings;
        self.open_way.clear();
        match self.actor.as_mut() {
            Some((actor, ws)) => {
                self.open_way.push(*start);
                let r = roll_out(
                    &self.params,
                    actor,
                    ws,
                    &self.world,
                    start,
                    goal,
                    Arrival::Pose(s.shot_tolerance),
                    s.rollout_dt,
                    open_way_steps(s),
                    Some(&mut self.open_way),
                );
                if !r.reached {
                    self.open_way.clear();
                }
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

    /// The open way among circles as a route to follow: the path of the
    /// actor's roll-out that found it open (its subgoals, and reversing parts
    /// by the rear axle), not the critic alone. Measured on obstacles200: the
    /// critic left to itself drives elsewhere than the roll-out that was
    /// checked (dock024: the roll-out drives forwards round the piles, the
    /// critic reverses into them) and stalls there. Without a roll-out that
    /// arrived (no actor, or one that keeps the margin without arriving): the
    /// goal alone, as before.
    fn follow_open_way(&mut self, goal: Goal, route: &mut Route) {
        route.direct(goal);
        if self.open_way.len() < 2 {
            return;
        }
        route.clear();
        route.rolled_out = true;
        push_states_as_path(&self.open_way, 0.0, &mut route.path);
        route.set_subgoals(goal, &self.following);
    }
}

/// Steps of the open way's roll-out.
fn open_way_steps(s: &SearchSettings) -> usize {
    (s.direct_horizon / s.rollout_dt).ceil() as usize
}

/// The retry's approach pose: `distance` behind the goal on its heading, else
/// ahead of it, the first that `usable` accepts.
pub(super) fn retry_approach(
    distance: f64,
    goal: &Goal,
    mut usable: impl FnMut(&Goal) -> bool,
) -> Option<Goal> {
    let (sin, cos) = goal.theta.sin_cos();
    [-1.0, 1.0]
        .into_iter()
        .map(|side| {
            Goal::new(
                goal.x + side * distance * cos,
                goal.y + side * distance * sin,
                goal.theta,
            )
        })
        .find(|a| usable(a))
}

/// Both axle points keep the margin at the poses along the straight line
/// from `from` to `to`, `spacing` apart, heading along the line and
/// unarticulated, plus both end poses.
fn straight_corridor_free(world: &CheckedWorld, start: &State, goal: &Goal, spacing: f64) -> bool {
    let from = [start[ix::X], start[ix::Y]];
    let (dx, dy) = (goal.x - from[0], goal.y - from[1]);
    let heading = dy.atan2(dx);
    let n = (dx.hypot(dy) / spacing).ceil().max(1.0) as usize;
    (0..=n).all(|k| {
        let f = k as f64 / n as f64;
        world.pose_free(from[0] + f * dx, from[1] + f * dy, heading, 0.0)
    }) && world.state_free(start)
        && world.pose_free(goal.x, goal.y, goal.theta, 0.0)
}
